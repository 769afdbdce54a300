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


def _options() -> list:
    """The grading options (click decorators), in the order ``--help`` shows them."""
    from types import SimpleNamespace

    from wbcgrade.color.imageio import DEFAULT_MAX_IMAGE_PIXELS
    from wbcgrade.color.options import LOSSES, MODES, flat_defaults

    _DEFAULTS = SimpleNamespace(**flat_defaults())
    _OPTIONS = [
        click.option("--style", "style_dir", type=click.Path(path_type=str), default=None,
                     help="Folder of style photos (non-images are skipped)."),
        click.option("--preset", default=None, metavar="NAME_OR_FILE",
                     help="Shipped preset name (see `wbcgrade preset list`) or a preset .npz "
                          "file."),
        click.option("--mode", type=click.Choice(MODES), default=_DEFAULTS.mode,
                     show_default=True,
                     help="look: apply the look the styles share (and their own scene's, when "
                          "one of them shows the photo's scene); palette: move the photo's "
                          "colours onto the closest blend of the style palettes."),
        click.option("--natural", type=click.Path(path_type=str), default=None,
                     metavar="PRESET|DIR",
                     help="The look's content model: a preset (.npz) of ungraded photos, or "
                          "a folder of your own ungraded photos [default: the shipped "
                          "palettes of 300+ photos]."),
        click.option("--bins", type=int, default=_DEFAULTS.bins, show_default=True,
                     help="Bins per axis of the photo's histogram and the transport plan (the "
                          "paper's 128; 64 or 32 are faster and coarser)."),
        click.option("--fit-bins", type=int, default=_DEFAULTS.fit_bins, show_default=True,
                     help="Bins per axis of the grid the weights are fitted on."),
        click.option("--loss", type=click.Choice(LOSSES), default=_DEFAULTS.loss, show_default=True,
                     help="Fit loss between the barycenter and the photo's histogram."),
        click.option("--width", type=float, default=_DEFAULTS.width, show_default=True,
                     help="Fit kernel width in bins of the fit grid."),
        click.option("--gamma", type=float, default=None,
                     help="Fit entropic regularisation gamma (overrides --width)."),
        click.option("--transfer-width", type=float, default=None,
                     help="Kernel width in bins of the transfer grid [default: max(1, "
                          "(bins-1)/31)]."),
        click.option("--iterations", "n_iter", type=int, default=_DEFAULTS.n_iter,
                     show_default=True, help="Barycenter iterations."),
        click.option("--max-iter", type=int, default=_DEFAULTS.max_iter, show_default=True,
                     help="L-BFGS iterations of the fit at most."),
        click.option("--weights", "weights_text", default=None, metavar="A,B,C",
                     help="Use these style weights and skip the fit (order: sorted file names of "
                          "--style DIR, or the preset's order shown by `preset list`)."),
        click.option("--strength", type=float, default=1.0, show_default=True,
                     help="How much of the grade: 0 none, 1 in full (x -> (1-t) x + t T(x)); "
                          "up to 4 makes a faint grade stronger."),
        click.option("--relax", "relaxation", type=float, default=_DEFAULTS.relaxation,
                     metavar="RHO", help="Unbalanced transport: palette colours the photo has "
                     "no use for may be left out, at a KL cost of RHO each (a small RHO such "
                     "as 0.05 leaves out more; a large one keeps nearly all) [default: none "
                     "left out, balanced transport]."),
        click.option("--map-size", type=int, default=_DEFAULTS.map_size, show_default=True,
                     help="Nodes per axis of the smooth colour map (the grade is this LUT)."),
        click.option("--smoothness", type=float, default=_DEFAULTS.smoothness, show_default=True,
                     help="Curvature penalty of the smooth colour map (0 with --stiffness 0: "
                          "the raw transport map, the paper's)."),
        click.option("--stiffness", type=float, default=_DEFAULTS.stiffness, show_default=True,
                     help="First-difference penalty of the colour map (holds its local gain "
                          "near 1: less noise amplification, less contrast change)."),
        click.option("--monotone/--no-monotone", default=_DEFAULTS.monotone, show_default=True,
                     help="Keep the order of lightness: the map's output luma never decreases "
                          "when an input channel increases (no reversed steps in flat areas; "
                          "a preset's own look is applied as it was made)."),
        click.option("--regrain/--no-regrain", default=_DEFAULTS.regrain, show_default=True,
                     help="Keep the input's grain and edges (edge-aware local linear model; "
                          "off: every pixel goes exactly through the LUT)."),
        click.option("--regrain-radius", type=float, default=_DEFAULTS.regrain_radius,
                     show_default=True, help="Regrain window radius, fraction of the long side."),
        click.option("--regrain-eps", type=float, default=_DEFAULTS.regrain_eps,
                     show_default=True, help="Regrain: input variations below about "
                     "sqrt(eps) (encoded units) are kept as grain."),
        click.option("--preserve-luminance", is_flag=True,
                     help="Change hue and chroma only; keep each colour's lightness (Oklab)."),
        click.option("--no-cache", is_flag=True,
                     help="Do not read or write cached style histograms."),
        click.option("--cache-dir", type=click.Path(file_okay=False, path_type=str), default=None,
                     help="Style histogram cache [default: $WBCGRADE_CACHE_DIR or "
                          "~/.cache/wbcgrade]."),
    ]
    #: ``--max-image-pixels N``: raise (or lower) the decompression-bomb limit of this run.
    max_image_pixels_option = click.option(
        "--max-image-pixels", type=click.IntRange(min=1), default=None, expose_value=False,
        callback=_set_max_image_pixels, metavar="N",
        help=f"Refuse images with more pixels than this, read from the header before "
             f"decoding [default: $WBCGRADE_MAX_IMAGE_PIXELS or {DEFAULT_MAX_IMAGE_PIXELS:_}].")
    _OPTIONS.append(max_image_pixels_option)
    return _OPTIONS


def _space_options() -> list:
    """``--input-space`` and ``--working-space`` (colour management, OpenColorIO)."""
    return [
        click.option("--input-space", default=None, metavar="NAME",
                     help="Colour space of the photos (an OpenColorIO name, alias or role, or "
                          "srgb, display-p3, adobe-rgb, linear-rec709, acescg, acescct; case "
                          "ignored) [default: what the file says (ICC profile, EXR "
                          "chromaticities), else sRGB for 8/16-bit and Linear Rec.709 for "
                          "float files]."),
        click.option("--working-space", default=None, metavar="NAME",
                     help="Colour space whose unit cube the histograms, the transport and the "
                          "colour map live in, e.g. acescct [default: sRGB-encoded Rec.709]. "
                          "Config: $OCIO, else OpenColorIO's built-in ocio://default."),
    ]


def lut_format_option() -> list:
    """``--lut-format cube|clf`` (default: the ``--lut`` file's ending), for
    :func:`lazy_options`."""
    return [click.option("--lut-format", type=click.Choice(["cube", "clf"]), default=None,
                         help="LUT file format: .cube (Resolve/Adobe; with a 1D shaper for a "
                              "logarithmic working space) or .clf (Academy/ASC Common LUT "
                              "Format; needs the opencolorio package) [default: the --lut "
                              "file's ending].")]


def look_option() -> list:
    """``--look FILE``: apply a saved grade, no fit (for :func:`lazy_options`)."""
    return [click.option("--look", "look_path", type=click.Path(dir_okay=False, path_type=str),
                         default=None, metavar="FILE",
                         help="Apply a saved grade instead of fitting one: the JSON written "
                              "by `apply --save-grade FILE` (regrain as it was) or a 3-D LUT "
                              "(.cube from --lut, .clf, ...; regrained unless --no-regrain). "
                              "Replaces --style/--preset; the fit options are not used.")]


def write_options() -> list:
    """``--quality`` and ``--bit-depth`` (how outputs are encoded), for :func:`lazy_options`."""
    return [
        click.option("--quality", type=click.IntRange(1, 100), default=None, metavar="N",
                     help="JPEG/WebP quality 1-100 [default: the encoder's, 98 for JPEG; "
                          "90 gives about the size of a typical camera JPEG]."),
        click.option("--bit-depth", type=click.Choice(["8", "16", "float"]), default=None,
                     help="Bits per channel of the output (where its format holds them: JPEG "
                          "8; PNG 8/16; TIFF 8/16/float; EXR 16 = half, float) [default: the "
                          "input's; raw photos 16, float in EXR]."),
    ]


def take_write_options(kwargs: dict):
    """Pop ``--quality`` and ``--bit-depth`` -> :class:`wbcgrade.color.imageio.WriteOptions`."""
    from wbcgrade.color.imageio import WriteOptions

    return WriteOptions(quality=kwargs.pop("quality", None),
                        bit_depth=kwargs.pop("bit_depth", None))


def take_look(ctx: click.Context, look_path: str | None, kwargs: dict, options):
    """The saved grade of ``--look`` (a Grade), or None; the grading flags given on the command
    line that a look takes (``--strength``, the regrain flags) apply to it.

    Called after :func:`take_grading_options` (``options`` its result); ``kwargs`` are the
    command's remaining parameters. ``--style``/``--preset`` with ``--look`` is an OptionError.
    """
    if look_path is None:
        return None
    from dataclasses import replace

    from click.core import ParameterSource

    from wbcgrade.color.saved_look import load_look
    from wbcgrade.errors import OptionError

    def given(name: str) -> bool:
        return ctx.get_parameter_source(name) == ParameterSource.COMMANDLINE

    for name, flag in (("style_dir", "--style"), ("preset", "--preset")):
        if given(name):
            raise OptionError(f"--look replaces {flag}: give one of them", "--look")
    look = load_look(look_path, options.spaces.working)
    is_json = dict(look.info).get("saved_look", {}).get("kind") == "json"
    regrain_given = any(given(n) for n in ("regrain", "regrain_radius", "regrain_eps"))
    changes = {}
    if regrain_given or not is_json:
        changes["regrain"] = options.regrain.settings
    if given("strength"):
        from wbcgrade.color.grading import strengthened

        changes["color_map"], changes["strength"] = strengthened(look.color_map,
                                                                 options.map.strength)
    return replace(look, **changes) if changes else look


def _set_max_image_pixels(ctx: click.Context, param: click.Parameter, value: int | None):
    from wbcgrade.color.imageio import set_max_image_pixels

    set_max_image_pixels(value)  # None: back to $WBCGRADE_MAX_IMAGE_PIXELS or the default
    return value


#: Options whose parameter is the flat name of an option field (wbcgrade.color.options).
_PLAIN_KEYS = ("bins", "fit_bins", "loss", "width", "gamma", "transfer_width", "n_iter",
               "max_iter", "strength", "relaxation", "map_size", "smoothness", "stiffness",
               "monotone", "regrain", "regrain_radius", "regrain_eps", "preserve_luminance",
               "mode", "natural")
GRADING_KEYS = ("style_dir", "preset", "weights_text", "no_cache", "cache_dir") + _PLAIN_KEYS
#: Options of :data:`space_options` (fields ``spaces.input`` and ``spaces.working``).
_SPACE_KEYS = ("input_space", "working_space")
#: Options that steer the palette fit and transport only (parameter name -> flag): the
#: look grade (``--mode look``, the default) and a saved grade (``--look``) never use them.
PALETTE_ONLY = {"weights_text": "--weights", "relaxation": "--relax", "loss": "--loss",
                "bins": "--bins", "fit_bins": "--fit-bins", "width": "--width",
                "gamma": "--gamma", "transfer_width": "--transfer-width",
                "n_iter": "--iterations", "max_iter": "--max-iter",
                "smoothness": "--smoothness", "stiffness": "--stiffness"}
#: Options of the look grade only (parameter name -> flag).
LOOK_ONLY = {"natural": "--natural"}

#: Option field (``group.field``) or library setting -> the flag that sets it.
FLAGS = {
    "fit.bins": "--fit-bins", "fit.loss": "--loss", "fit.width": "--width",
    "fit.gamma": "--gamma", "fit.n_iter": "--iterations", "fit.max_iter": "--max-iter",
    "fit.weights": "--weights", "transfer.bins": "--bins", "transfer.width": "--transfer-width",
    "transfer.relaxation": "--relax", "map.size": "--map-size", "map.smoothness": "--smoothness",
    "map.stiffness": "--stiffness", "map.strength": "--strength", "map.builder": "--mode",
    "map.natural": "--natural",
    "regrain.radius": "--regrain-radius", "regrain.eps": "--regrain-eps",
    "spaces.input": "--input-space", "spaces.working": "--working-space",
    "lut_size": "--lut-size", "jobs": "--jobs", "codec": "--codec", "crf": "--crf",
    "blend": "--blend-frames", "sample_every": "--sample-every",
    "cut_threshold": "--cut-threshold",
}


def flag_error(error):
    """An OptionError naming a library field -> the same error naming its flag."""
    from wbcgrade.errors import OptionError

    flag = FLAGS.get(getattr(error, "option", None))
    if flag is None:
        return error
    return OptionError(str(error).replace(error.option, flag, 1), flag)


class _Deferred:
    """Stands in a command's parameter list for options built later by ``factory()``."""

    def __init__(self, factory) -> None:
        self.factory = factory

    def build(self) -> list[click.Parameter]:
        def holder() -> None:
            """Collects the options' parameters."""

        for option in reversed(self.factory()):
            holder = option(holder)
        return list(reversed(holder.__click_params__))


#: ``--help`` sections: (title, parameter names), in order; options not named go under
#: "Other options".
OPTION_GROUPS = (
    ("Where the grade comes from", ("style_dir", "preset", "look_path", "mode", "strength")),
    ("Look grade (--mode look, the default)", tuple(LOOK_ONLY)),
    ("Colour map and finish (both modes)",
     ("map_size", "monotone", "preserve_luminance", "regrain", "regrain_radius",
      "regrain_eps")),
    ("Palette fit (--mode palette only)", tuple(PALETTE_ONLY)),
    ("Colour spaces", _SPACE_KEYS),
    ("Outputs", ("output", "output_dir", "out_dir", "report_dir", "lut", "lut_size",
                 "lut_format", "save_grade", "quality", "bit_depth", "overwrite", "as_json")),
)


class LazyOptionsCommand(click.Command):
    """A click command whose deferred options are built when its parameters are first used.

    Listing the command (``wbcgrade --help``) needs only its name and help
    text; its options, parsing and ``--help`` expand the placeholders left by
    :func:`lazy_options` in place, in their order. ``--help`` lists the options
    in sections by what they steer (:data:`OPTION_GROUPS`).
    """

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
        for title, names in (*OPTION_GROUPS, ("Other options", tuple(records))):
            rows = [records.pop(name) for name in names if name in records]
            if rows:
                with formatter.section(title):
                    formatter.write_dl(rows)

    @params.setter
    def params(self, value: list[click.Parameter]) -> None:
        self.__dict__["_params"] = value


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
        for option in _options():
            def holder() -> None:
                """Reads the option's parameter name."""

            if option(holder).__click_params__[0].name not in names:
                kept.append(option)
        return kept

    return lazy_options(factory)


def lut_size_option() -> list:
    """``--lut-size`` (default: the colour library's LUT size), for :func:`lazy_options`."""
    from wbcgrade.color.lut import DEFAULT_LUT_SIZE

    return [click.option("--lut-size", type=int, default=DEFAULT_LUT_SIZE, show_default=True,
                         help="Nodes per axis of the LUT.")]



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


def take_grading_options(kwargs: dict) -> tuple:
    """Pop the grading options from a command's kwargs -> (GradeOptions, StyleSource).

    The options are made (and validated) here, once for the run; an option
    out of range is an OptionError naming its flag. ``--input-space`` and
    ``--working-space`` (:data:`space_options`) are taken when the command
    has them and resolved here (an unknown name is an OptionError naming the
    valid ones, before any work).
    """
    from wbcgrade.color.histogram import HistogramCache
    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.presets import StyleSource
    from wbcgrade.color.weights import parse_weights
    from wbcgrade.errors import OptionError

    values = {key: kwargs.pop(key) for key in GRADING_KEYS}
    ctx = click.get_current_context(silent=True)
    saved_look = ctx is not None and ctx.params.get("look_path") is not None
    check_mode_options(values["mode"], given_flags(), saved_look)
    spaces = {key: kwargs.pop(key, None) for key in _SPACE_KEYS}
    if any(spaces.values()):
        from wbcgrade.color.colorspace import resolve_space

        spaces = {key: resolve_space(value, "--" + key.replace("_", "-")) if value else None
                  for key, value in spaces.items()}
    text = values["weights_text"]
    try:
        options = GradeOptions(**{key: values[key] for key in _PLAIN_KEYS},
                               weights=parse_weights(text) if text else None, **spaces)
    except OptionError as exc:
        raise flag_error(exc) from None
    cache = HistogramCache(values["cache_dir"], enabled=not values["no_cache"])
    return options, StyleSource(values["style_dir"], values["preset"], cache)
