"""Click options shared by the commands that grade photos (``apply``, ``batch``, ``report``).

One list of options, names, defaults and help for ``apply``, ``batch``,
``report`` and ``video``. Each maps to one field of the colour library's
option groups (:data:`FLAGS`: ``--bins`` is ``transfer.bins``, ``--relax``
``transfer.relaxation``, ...); their defaults are read from the groups'
fields (``wbcgrade.color.options``, light: no numpy), and the options are
made and validated once, by :func:`take_grading_options`, whose errors name
the flag. Options whose defaults live in heavy modules are built the first
time a command needs its parameters (its own ``--help``, or a run):
:func:`grading_options` leaves a placeholder that :class:`LazyOptionsCommand`
expands (:func:`lazy_options` does the same for any option).
"""

from __future__ import annotations

import click

from wbcgrade.cli.option_table import (
    HISTOGRAMS,
    LOOK,
    PALETTE,
    click_options,
    flag_error,
    flag_of,
    names_in,
    option,
)

#: The grading options' parameter names, in the order ``--help`` shows them (rows of
#: :data:`wbcgrade.cli.option_table.OPTIONS`).
GRADING_NAMES = ("style_dir", "preset", "mode", "natural", "bins", "fit_bins", "loss", "width",
                 "gamma", "transfer_width", "n_iter", "max_iter", "weights_text", "strength",
                 "relaxation", "map_size", "smoothness", "stiffness", "monotone", "regrain",
                 "regrain_radius", "regrain_eps", "preserve_luminance", "no_cache",
                 "cache_dir", "max_image_pixels")


def table_options(*names: str, **changes):
    """Decorator: the options of the table's rows named (built now, in that order);
    ``changes`` replace fields of the rows (a command's own ``help``)."""
    def decorate(function):
        for decorator in reversed(click_options(*names, **changes)):
            function = decorator(function)
        return function

    return decorate


def _options() -> list:
    """The grading options (click decorators), in the order ``--help`` shows them."""
    return click_options(*GRADING_NAMES)


def _space_options() -> list:
    """``--input-space`` and ``--working-space`` (colour management, OpenColorIO)."""
    return click_options(*_SPACE_KEYS)


def lut_format_option() -> list:
    """``--lut-format cube|clf`` (default: the ``--lut`` file's ending), for
    :func:`lazy_options`."""
    return click_options("lut_format")


def look_option() -> list:
    """``--look FILE``: apply a saved grade, no fit; ``--originals DIR``: learn the look of
    the style photos from the originals of some of them (for :func:`lazy_options`)."""
    return click_options("look_path", "originals_dir")


def write_options() -> list:
    """``--quality`` and ``--bit-depth`` (how outputs are encoded), for :func:`lazy_options`."""
    return click_options("quality", "bit_depth")


def check_photo(photo: str, missing: str = "no such file") -> None:
    """InputError ``PHOTO: missing`` for an input that does not exist (as the library
    says it), before the command imports numpy and the core: a mistake is answered
    at once."""
    from pathlib import Path

    from wbcgrade.errors import InputError

    if not Path(photo).exists():
        raise InputError(f"{photo}: {missing}")


def take_write_options(kwargs: dict):
    """Pop ``--quality`` and ``--bit-depth`` -> :class:`wbcgrade.color.io.images.WriteOptions`."""
    from wbcgrade.color.io.images import WriteOptions

    return WriteOptions(quality=kwargs.pop("quality", None),
                        bit_depth=kwargs.pop("bit_depth", None))


def take_look(ctx: click.Context, look_path: str | None, kwargs: dict, options):
    """The saved grade of ``--look`` (a Grade), or None; the grading flags given on the command
    line that a look takes (``--strength``, the regrain flags) apply to it.

    Called after :func:`take_grading_options` (``options`` its result); ``kwargs`` are the
    command's remaining parameters. ``--style``/``--preset`` with ``--look`` is an OptionError.
    ``--originals DIR`` (popped from ``kwargs``) learns the look of the ``--style`` photos
    from the originals of some of them (:func:`wbcgrade.color.grade.look_files.learned_grade`),
    applied as a LUT from ``look learn`` would be.
    """
    originals = kwargs.pop("originals_dir", None)
    if look_path is None and originals is None:
        return None
    from dataclasses import replace

    from click.core import ParameterSource

    from wbcgrade.errors import OptionError

    def given(name: str) -> bool:
        return ctx.get_parameter_source(name) == ParameterSource.COMMANDLINE

    if originals is not None:
        if look_path is not None:
            raise OptionError("--originals learns the look; --look applies a saved one: "
                              "give one of them", "--originals")
        style_dir = ctx.params.get("style_dir")
        if style_dir is None or given("preset"):
            raise OptionError("--originals pairs with the style photos: give --style DIR "
                              "(the edited photos) beside it", "--originals")
        if ctx.params.get("mode") == "palette":
            raise OptionError("--originals learns the look; --mode palette fits palettes",
                              "--originals")
        look = _learned_look(style_dir, originals, options)
    else:
        from wbcgrade.color.grade.saved_grade import load_look

        for name, flag in (("style_dir", "--style"), ("preset", "--preset")):
            if given(name):
                raise OptionError(f"--look replaces {flag}: give one of them", "--look")
        look = load_look(look_path, options.spaces.working)
    is_json = look.saved is not None and look.saved.is_json
    regrain_given = any(given(n) for n in ("regrain", "regrain_radius", "regrain_eps"))
    changes = {}
    if regrain_given or not is_json:
        changes["regrain"] = options.regrain.settings
    if given("strength"):
        from wbcgrade.color.grade.grading import strengthened

        changes["color_map"], changes["strength"] = strengthened(look.color_map,
                                                                 options.map.strength)
    return replace(look, **changes) if changes else look


def _learned_look(style_dir: str, originals: str, options):
    """The look ``look learn ORIGINALS STYLE_DIR`` learns, as a grade (progress on the
    terminal, a warning per file left out)."""
    from wbcgrade.cli._progress import learn_progress
    from wbcgrade.color.grade.look_files import learned_grade

    with learn_progress("learning the look") as (progress, warn):
        grade, result = learned_grade(originals, style_dir,
                                      working_space=options.spaces.working, warn=warn,
                                      progress=progress)
    # (how far it is followed: the grade's own line); on stderr: standard output may be
    # the report's JSON
    for words in (result.coverage_words(), result.original_to_add_words()):
        if words:
            click.echo(f"learned look: {words}", err=True)
    return grade


def set_max_image_pixels(ctx: click.Context, param: click.Parameter, value: int | None):
    import sys

    if value is None and "wbcgrade.color.io.images" not in sys.modules:
        return value  # not given, and no limit set yet: nothing to undo (and no numpy loaded)
    from wbcgrade.color.io.images import set_max_image_pixels

    set_max_image_pixels(value)  # None: back to $WBCGRADE_MAX_IMAGE_PIXELS or the default
    return value


#: Options whose parameter is the flat name of an option field (wbcgrade.color.options).
_PLAIN_KEYS = tuple(name for name in GRADING_NAMES if option(name).json == name)
GRADING_KEYS = tuple(name for name in GRADING_NAMES if name != "max_image_pixels")
#: Options of :data:`space_options` (fields ``spaces.input`` and ``spaces.working``).
_SPACE_KEYS = ("input_space", "working_space")
#: Options that steer the palette fit and transport only (parameter name -> flag): the
#: look grade (``--mode look``, the default) and a saved grade (``--look``) never use them.
PALETTE_ONLY = {name: option(name).flag for name in names_in(PALETTE)}
#: Options of the look grade only (parameter name -> flag).
LOOK_ONLY = {name: option(name).flag for name in names_in(LOOK)}

#: Option field (``group.field``) or library setting -> the flag that sets it.
FLAGS = flag_of


class _Deferred:
    """Stands in a command's parameter list for options built later by ``factory()``."""

    def __init__(self, factory) -> None:
        self.factory = factory

    def build(self) -> list[click.Parameter]:
        def holder() -> None:
            """Collects the options' parameters."""

        for decorator in reversed(self.factory()):
            holder = decorator(holder)
        return list(reversed(holder.__click_params__))


#: ``--help`` sections: (title, parameter names), in order; options not named go under
#: "Other options".
OPTION_GROUPS = (
    ("Where the grade comes from", ("style_dir", "preset", "look_path", "originals_dir",
                                    "mode", "strength",
                                    "look_strength")),
    ("Look grade (--mode look, the default)", tuple(LOOK_ONLY)),
    ("Colour map and finish (both modes)",
     ("map_size", "monotone", "preserve_luminance", "regrain", "regrain_radius",
      "regrain_eps")),
    ("Palette fit (--mode palette only)", tuple(PALETTE_ONLY)),
    ("Histograms", names_in(HISTOGRAMS)),
    ("Colour spaces", _SPACE_KEYS),
    ("Outputs", ("output", "output_dir", "out_dir", "report_dir", "lut", "lut_size",
                 "lut_format", "save_grade", "quality", "bit_depth", "overwrite", "as_json")),
)


#: The options a short ``--help`` shows (parameter names): where the look comes from, how
#: much of it, and where the results go; ``--help-all`` shows every option.
COMMON_OPTIONS = ("style_dir", "preset", "look_path", "originals_dir", "mode", "strength",
                  "look_strength", "output", "output_dir", "out_dir", "recursive",
                  "consistent", "jobs", "per_shot", "report_dir", "lut", "save_grade",
                  "quality", "overwrite", "as_json")
#: A command with more options than this shows only :data:`COMMON_OPTIONS` by default.
SHORT_HELP_ABOVE = 24


def show_all_help(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    """``--help-all``: the command's whole help (every option, by section), then exit."""
    if not value or ctx.resilient_parsing:
        return
    ctx.meta["wbcgrade.help_all"] = True
    click.echo(ctx.get_help(), color=ctx.color)
    ctx.exit()


class LazyOptionsCommand(click.Command):
    """A click command whose deferred options are built when its parameters are first used.

    Listing the command (``wbcgrade --help``) needs only its name and help
    text; its options, parsing and ``--help`` expand the placeholders left by
    :func:`lazy_options` in place, in their order. ``--help-all`` lists every option
    in sections by what they steer (:data:`OPTION_GROUPS`); ``--help`` does the same for
    a command with few options, and otherwise shows the first two paragraphs of the help
    text and the common options (:data:`COMMON_OPTIONS`), so that it fits on a screen.
    """

    def get_params(self, ctx: click.Context) -> list[click.Parameter]:
        params = super().get_params(ctx)
        if not any(p.name == "help_all" for p in params):
            from wbcgrade.cli.option_table import click_options

            def holder() -> None:
                """Collects the option."""

            click_options("help_all")[0](holder)
            params.insert(len(params) - 1, holder.__click_params__[0])  # before --help
        return params

    def _short(self, ctx: click.Context) -> bool:
        """Whether ``--help`` shows the short form (a long command, --help-all not given)."""
        if ctx.meta.get("wbcgrade.help_all"):
            return False
        count = sum(1 for p in self.get_params(ctx) if isinstance(p, click.Option)
                    and not p.hidden)
        return count > SHORT_HELP_ABOVE

    def format_help_text(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        if not self._short(ctx) or not self.help:
            super().format_help_text(ctx, formatter)
            return
        import inspect

        paragraphs = inspect.cleandoc(self.help).split("\n\n")
        formatter.write_paragraph()
        with formatter.indentation():
            for number, text in enumerate(paragraphs[:2]):
                if number:
                    formatter.write_paragraph()
                formatter.write_text(text)

    @property
    def params(self) -> list[click.Parameter]:
        params = self.__dict__["_params"]
        if any(isinstance(p, _Deferred) for p in params):
            expanded = []
            for p in params:
                expanded.extend(p.build() if isinstance(p, _Deferred) else [p])
            params[:] = expanded
        return params

    def format_options(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        records = {}
        for param in self.get_params(ctx):
            record = param.get_help_record(ctx)
            if record is not None:
                records[param.name] = record
        if self._short(ctx):
            rows = [records.pop(name) for name in COMMON_OPTIONS if name in records]
            rows += [records.pop(name) for name in ("help_all", "help") if name in records]
            with formatter.section("Common options"):
                formatter.write_dl(rows)
            formatter.write_paragraph()
            formatter.write_text(f"{len(records)} more options (the look's content model, "
                                 "the colour map and its finish, the palette fit, colour "
                                 "spaces, LUT and output settings, caches): --help-all.")
            return
        has_mode = "mode" in records
        for title, names in (*OPTION_GROUPS, ("Other options", tuple(records))):
            rows = [records.pop(name) for name in names if name in records]
            if rows:
                if not has_mode and title.startswith("Look grade"):
                    title = "The look's content model"
                with formatter.section(title):
                    formatter.write_dl(rows)

    @params.setter
    def params(self, value: list[click.Parameter]) -> None:
        self.__dict__["_params"] = value


def table_rows(*names: str, **changes):
    """Decorator: the table's rows named, built when the command's parameters are first
    used (rows whose defaults live in heavy modules); the command must be a
    :class:`LazyOptionsCommand`. ``changes`` as for :func:`table_options`."""
    return lazy_options(lambda: click_options(*names, **changes))


def lazy_options(factory):
    """Decorator: the options ``factory()`` returns (click.option decorators), built late.

    For options whose defaults live in heavy modules. The command must be a
    :class:`LazyOptionsCommand` (``@click.command(cls=LazyOptionsCommand)``).
    """
    def decorate(function):
        if not hasattr(function, "__click_params__"):
            function.__click_params__ = []
        function.__click_params__.append(_Deferred(factory))
        return function

    return decorate


#: Decorator adding the grading options of ``apply`` to a LazyOptionsCommand.
grading_options = lazy_options(_options)

#: Decorator adding ``--input-space`` and ``--working-space`` to a LazyOptionsCommand.
space_options = lazy_options(_space_options)


def grading_options_except(*names: str):
    """Decorator: the grading options but those whose parameter is named in ``names``
    (e.g. ``video``, whose grade is a LUT, has no regrain options)."""
    def factory() -> list:
        kept = []
        for decorator in _options():
            def holder() -> None:
                """Reads the option's parameter name."""

            if decorator(holder).__click_params__[0].name not in names:
                kept.append(decorator)
        return kept

    return lazy_options(factory)


def lut_size_option() -> list:
    """``--lut-size`` (default: the colour library's LUT size), for :func:`lazy_options`."""
    return click_options("lut_size")



def given_flags() -> set[str]:
    """The parameter names given on the command line of the running click command."""
    from click.core import ParameterSource

    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return set()
    return {name for name in ctx.params
            if ctx.get_parameter_source(name) == ParameterSource.COMMANDLINE}


def check_mode_options(mode: str, given: set[str], saved_look: bool = False) -> None:
    """OptionError (one line) for an option given on the command line that the grade
    would not use: a palette-fit option without ``--mode palette`` (``--weights``
    would otherwise switch to a palette grade unannounced), ``--natural`` with it,
    and any fit option with a saved grade (``saved_look``)."""
    from wbcgrade.errors import OptionError

    for name, flag in PALETTE_ONLY.items():
        if name not in given:
            continue
        if saved_look:
            raise OptionError(f"{flag} steers the palette fit; --look applies a saved grade "
                              "as it is, with no fit", flag)
        if mode != "palette":
            what = ("sets the weights of a palette blend" if name == "weights_text"
                    else "steers the palette fit")
            raise OptionError(f"{flag} {what}, which the look grade (--mode {mode}) does not "
                              "use: add --mode palette", flag)
    for name, flag in LOOK_ONLY.items():
        if name in given and mode == "palette":
            raise OptionError(f"{flag} is the look grade's content model; --mode palette "
                              "does not use it", flag)


def take_grading_options(kwargs: dict, photo: str | None = None) -> tuple:
    """Pop the grading options from a command's kwargs -> (GradeOptions, StyleSource).

    The options are made (and validated) here, once for the run; an option
    out of range is an OptionError naming its flag. ``--input-space`` and
    ``--working-space`` (:data:`space_options`) are taken when the command
    has them and resolved here (an unknown name is an OptionError naming the
    valid ones, before any work). ``photo``: the command's PHOTO, checked
    (:func:`check_photo`) once the options are valid, before numpy loads.
    """
    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.weights import parse_weights
    from wbcgrade.errors import OptionError

    values = {key: kwargs.pop(key) for key in GRADING_KEYS}
    ctx = click.get_current_context(silent=True)
    saved_look = ctx is not None and (ctx.params.get("look_path") is not None
                                      or ctx.params.get("originals_dir") is not None)
    check_mode_options(values["mode"], given_flags(), saved_look)
    spaces = {key: kwargs.pop(key, None) for key in _SPACE_KEYS}
    if any(spaces.values()):
        from wbcgrade.color.colorspace import resolve_space

        spaces = {key: resolve_space(value, option(key).field) if value else None
                  for key, value in spaces.items()}
    text = values["weights_text"]
    try:
        options = GradeOptions(**{key: values[key] for key in _PLAIN_KEYS},
                               weights=parse_weights(text) if text else None, **spaces)
    except OptionError as exc:
        raise flag_error(exc) from None
    if photo is not None:
        check_photo(photo)
    if values["preset"] is not None and values["style_dir"] is None and not saved_look:
        from wbcgrade.color.io.preset_names import resolve_preset

        resolve_preset(values["preset"])  # an unknown name, answered before numpy loads
    # numpy and OpenImageIO load here, once the options and PHOTO are known to be valid
    from wbcgrade.color.histogram import HistogramCache
    from wbcgrade.color.io.cache import set_command_cache
    from wbcgrade.color.presets import StyleSource

    set_command_cache(values["cache_dir"], not values["no_cache"])  # --natural DIR's too
    cache = HistogramCache(values["cache_dir"], enabled=not values["no_cache"])
    return options, StyleSource(values["style_dir"], values["preset"], cache)
