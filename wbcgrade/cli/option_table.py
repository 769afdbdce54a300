"""The one table of the command-line options (``apply``, ``batch``, ``report``, ``video``,
``look``, ``preset``, ``explore``, ``brdf``, ``shape``).

Each row (:class:`Option`) holds what the command line, the JSON records and the
error messages need of one option: the click parameter name, the flag, the
library field it sets (whose errors name it: ``transfer.bins``), the key under
which records write it (:meth:`wbcgrade.color.options.GradeOptions.flat`), the
click type, the default (read from the library field unless given), the help
and the ``--help`` section. A command may reword a row's help for itself
(``click_options(name, help=...)``) where the meaning is the same; an option
whose meaning differs has its own row (``look_strength``). The click options
(:func:`click_options`), the
flag of a field (:data:`flag_of`), the grading keys and the palette-only and
look-only sets are derived from it; nothing else spells these names.

Light: importing this module imports click only; defaults that live in heavy
modules are named (``"wbcgrade.color.defaults:DEFAULT_LUT_SIZE"``) and read when the
options are built.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from importlib import import_module
from pathlib import Path

import click

from wbcgrade.errors import OptionError

__all__ = ["Option", "OPTIONS", "FIELD_DEFAULT", "option", "click_options", "flag_of",
           "flag_error", "flag_text", "names_in", "json_keys"]


#: The largest magnitude a number option takes (each is checked to its own range later).
MAX_OPTION_MAGNITUDE = 1e9


class FiniteFloat(click.ParamType):
    """A float option: a finite number of magnitude at most :data:`MAX_OPTION_MAGNITUDE`
    (``nan``, ``inf`` and ``1e300`` are usage errors before anything is computed)."""

    name = "float"

    def convert(self, value, param, ctx):
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not abs(number) <= MAX_OPTION_MAGNITUDE:  # (NaN fails this too)
            # one line, exit 2, as the library's
            flag = max(getattr(param, "opts", None) or [str(value)], key=len)
            raise OptionError(f"{flag}: {value} is not a finite number (at most "
                              f"{MAX_OPTION_MAGNITUDE:g} in size)", flag)
        return number


#: The float type of the table's rows.
FINITE_FLOAT = FiniteFloat()

#: ``Option.default``: the default is the library field's (``GradeOptions`` flat name).
FIELD_DEFAULT = object()

#: ``--help`` sections of the rows (OPTION_GROUPS in grading_options adds the titles).
SOURCE, LOOK, MAP, PALETTE, SPACES, OUTPUTS, HISTOGRAMS, OTHER = (
    "source", "look", "map", "palette", "spaces", "outputs", "histograms", "other")


@dataclass(frozen=True)
class Option:
    """One command-line option.

    Attributes
    ----------
    name : the click parameter name (the command function's argument).
    flag : the flag as users type it (``"--relax"``); errors about ``field`` name it.
    decls : click's declarations when not just ``flag`` (``"--monotone/--no-monotone"``).
    field : the library setting it sets, as the library's errors name it
        (``"transfer.relaxation"``, ``"lut_size"``), or None.
    json : the key under which records and ``--json`` write it (a
        :meth:`GradeOptions.flat` name), or None.
    type : the click type (or a ``"module:attr"`` name of one, read when built).
    default : :data:`FIELD_DEFAULT` (the field's default), a value, or a
        ``"module:attr"`` name (with ``lazy_default``).
    help : the help text; ``{default}`` is replaced by ``help_default`` (a
        ``"module:attr"`` name).
    section : the ``--help`` section; PALETTE: options that steer the palette
        fit only, LOOK: the look grade's only.
    case_sensitive : whether a choice (a ``"module:attr"`` list of names) is.
    eager : processed before the other options (an option that prints and exits).
    upper : a ``"module:attr"`` name of the upper bound of the ``click.IntRange`` type,
        read when built.
    """

    name: str
    flag: str
    help: str
    field: str | None = None
    json: str | None = None
    type: object = None
    default: object = None
    lazy_default: bool = False
    help_default: str | None = None
    decls: tuple[str, ...] = ()
    metavar: str | None = None
    show_default: bool = False
    is_flag: bool = False
    multiple: bool = False
    expose_value: bool = True
    required: bool = False
    hidden: bool = False
    callback: str | None = None
    section: str = OTHER
    case_sensitive: bool = True
    upper: str | None = None
    eager: bool = False

    def build(self):
        """The click.option decorator of this row."""
        kind = _resolve(self.type) if isinstance(self.type, str) else self.type
        if isinstance(kind, (tuple, list, dict)):  # the names a library module lists
            kind = click.Choice(tuple(kind), case_sensitive=self.case_sensitive)
        if self.upper is not None:
            kind = click.IntRange(kind.min, _resolve(self.upper))
        default = self.default_value()
        extra = {}
        if kind is not None:
            extra["type"] = kind
        if self.metavar is not None:
            extra["metavar"] = self.metavar
        if self.is_flag:
            extra["is_flag"] = True
        if self.multiple:
            extra["multiple"] = True
        if self.callback is not None:
            extra["callback"] = _resolve(self.callback)
        if not self.expose_value:
            extra["expose_value"] = False
        if self.required:  # no default: click 8.2+ takes an explicit None as a value given
            extra["required"] = True
        else:
            extra["default"] = default
        if self.hidden:
            extra["hidden"] = True
        if self.eager:
            extra["is_eager"] = True
        text = self.help
        if self.help_default is not None:
            shown = _resolve(self.help_default)
            text = text.replace("{default}", f"{shown:_}" if isinstance(shown, int)
                                else str(shown))
        return click.option(*(self.decls or (self.flag,)), self.name,
                            show_default=self.show_default, help=text, **extra)

    def default_value(self):
        """The default: the library field's, a named constant's, or the row's own."""
        if self.default is FIELD_DEFAULT:
            return _field_defaults()[self.json]
        if self.lazy_default:
            return _resolve(self.default)
        return self.default


@cache
def _field_defaults() -> dict:
    """The library fields' defaults by flat name (read once)."""
    from wbcgrade.color.options import flat_defaults

    return flat_defaults()


def _resolve(name: str):
    """``"module:attr"`` -> that attribute."""
    module, attr = name.split(":")
    return getattr(import_module(module), attr)


_PATH = click.Path(path_type=str)
_FILE = click.Path(dir_okay=False, path_type=str)
_FOLDER = click.Path(file_okay=False, path_type=str)
_FILE_PATH = click.Path(dir_okay=False, path_type=Path)
_BRDF = "wbcgrade.brdf.defaults:"
_SHAPE = "wbcgrade.shape.defaults:"
_MAX_L = "wbcgrade.limits:MAX_BARYCENTER_ITERATIONS"

#: Every option of the grading commands, in the order ``--help`` shows them.
OPTIONS: tuple[Option, ...] = (
    # where the grade comes from
    Option("style_dir", "--style", "Folder of style photos (non-images are skipped).",
           field="style_dir", type=_PATH, section=SOURCE),
    Option("preset", "--preset", "Shipped preset name (see `wbcgrade preset list`) or a "
           "preset .npz file.", field="preset", metavar="NAME_OR_FILE", section=SOURCE),
    Option("mode", "--mode", "look: apply the look the styles share (and their own scene's, "
           "when one of them shows the photo's scene); palette: move the photo's colours onto "
           "the closest blend of the style palettes.", field="map.builder", json="mode",
           type="wbcgrade.color.options:MODES", default=FIELD_DEFAULT, show_default=True,
           section=SOURCE),
    Option("natural", "--natural", "The look's content model: a preset (.npz) of ungraded "
           "photos, a folder of six or more of your own ungraded photos (beside the shipped "
           "palettes), or 'shipped' [default: the shipped palettes of 300+ photos; in batch, "
           "with the photos being graded when six or more lie directly in IN_DIR].",
           field="map.natural", json="natural", type=_PATH,
           metavar="PRESET|DIR", section=LOOK),
    # the palette fit and transport
    Option("weights_text", "--weights", "Use these style weights and skip the fit (order: "
           "sorted file names of --style DIR, or the preset's order shown by `preset list`).",
           field="fit.weights", json="weights", metavar="A,B,C", section=PALETTE),
    Option("relaxation", "--relax", "Unbalanced transport: palette colours the photo has no "
           "use for may be left out, at a KL cost of RHO each (a small RHO such as 0.05 leaves "
           "out more; a large one keeps nearly all) [default: none left out, balanced "
           "transport].", field="transfer.relaxation", json="relaxation", type=FINITE_FLOAT,
           default=FIELD_DEFAULT, metavar="RHO", section=PALETTE),
    # the colour map and its finish
    Option("loss", "--loss", "Fit loss between the barycenter and the photo's histogram.",
           field="fit.loss", json="loss", type="wbcgrade.color.options:LOSSES",
           default=FIELD_DEFAULT, show_default=True, section=PALETTE),
    Option("bins", "--bins", "Bins per axis of the photo's histogram and the transport plan "
           "(the paper's 128; 64 or 32 are faster and coarser).", field="transfer.bins",
           json="bins", type=int, default=FIELD_DEFAULT, show_default=True, section=PALETTE),
    Option("fit_bins", "--fit-bins", "Bins per axis of the grid the weights are fitted on.",
           field="fit.bins", json="fit_bins", type=int, default=FIELD_DEFAULT,
           show_default=True, section=PALETTE),
    Option("width", "--width", "Fit kernel width in bins of the fit grid.", field="fit.width",
           json="width", type=FINITE_FLOAT, default=FIELD_DEFAULT, show_default=True,
           section=PALETTE),
    Option("gamma", "--gamma", "Fit entropic regularisation gamma (overrides --width).",
           field="fit.gamma", json="gamma", type=FINITE_FLOAT, section=PALETTE),
    Option("transfer_width", "--transfer-width", "Kernel width in bins of the transfer grid "
           "[default: max(1, (bins-1)/31)].", field="transfer.width", json="transfer_width",
           type=FINITE_FLOAT, section=PALETTE),
    Option("n_iter", "--iterations", "Barycenter iterations.", field="fit.n_iter",
           json="n_iter", type=int, default=FIELD_DEFAULT, show_default=True, section=PALETTE),
    Option("max_iter", "--max-iter", "L-BFGS iterations of the fit at most.",
           field="fit.max_iter", json="max_iter", type=int, default=FIELD_DEFAULT,
           show_default=True, section=PALETTE),
    Option("strength", "--strength", "How much of the grade: 0 none, 1 in full; up to 4 makes "
           "a faint grade stronger.", field="map.strength",
           json="strength", type=FINITE_FLOAT, default=FIELD_DEFAULT, show_default=True,
           section=SOURCE),
    Option("map_size", "--map-size", "Nodes per axis of the smooth colour map (the grade is "
           "this LUT).", field="map.size", json="map_size", type=int, default=FIELD_DEFAULT,
           show_default=True, section=MAP),
    Option("smoothness", "--smoothness", "Curvature penalty of the smooth colour map (0 with "
           "--stiffness 0: the raw transport map, the paper's).", field="map.smoothness",
           json="smoothness", type=FINITE_FLOAT, default=FIELD_DEFAULT, show_default=True,
           section=PALETTE),
    Option("stiffness", "--stiffness", "First-difference penalty of the colour map (holds its "
           "local gain near 1: less noise amplification, less contrast change).",
           field="map.stiffness", json="stiffness", type=FINITE_FLOAT, default=FIELD_DEFAULT,
           show_default=True, section=PALETTE),
    Option("monotone", "--monotone", "Keep the order of lightness: the map's output luma never "
           "decreases when an input channel increases (no reversed steps in flat areas; a "
           "preset's own look is applied as it was made).", field="map.monotone",
           json="monotone", decls=("--monotone/--no-monotone",), default=FIELD_DEFAULT,
           show_default=True, section=MAP),
    Option("regrain", "--regrain", "Keep the input's grain and edges (edge-aware local linear "
           "model; off: every pixel goes exactly through the LUT).", field="regrain.enabled",
           json="regrain", decls=("--regrain/--no-regrain",), default=FIELD_DEFAULT,
           show_default=True, section=MAP),
    Option("regrain_radius", "--regrain-radius", "Regrain window radius, fraction of the long "
           "side.", field="regrain.radius", json="regrain_radius", type=FINITE_FLOAT,
           default=FIELD_DEFAULT, show_default=True, section=MAP),
    Option("regrain_eps", "--regrain-eps", "Regrain: input variations below about sqrt(eps) "
           "(encoded units) are kept as grain.", field="regrain.eps", json="regrain_eps",
           type=FINITE_FLOAT, default=FIELD_DEFAULT, show_default=True, section=MAP),
    Option("preserve_luminance", "--preserve-luminance", "Change hue and chroma only; keep "
           "each colour's lightness (Oklab).", field="map.preserve_luminance",
           json="preserve_luminance", is_flag=True, default=False, section=MAP),
    # help: the default --help of a long command shows its common options only
    Option("help_all", "--help-all", "Show every option, by what it steers, and exit.",
           is_flag=True, default=False, expose_value=False, eager=True,
           callback="wbcgrade.cli.grading_options:show_all_help"),
    # caches and limits
    Option("no_cache", "--no-cache", "Do not read or write cached style histograms.",
           is_flag=True, default=False),
    Option("cache_dir", "--cache-dir", "Style histogram cache [default: $WBCGRADE_CACHE_DIR or "
           "~/.cache/wbcgrade].", type=_FOLDER),
    Option("max_image_pixels", "--max-image-pixels", "Refuse images with more pixels than "
           "this, read from the header before decoding [default: $WBCGRADE_MAX_IMAGE_PIXELS "
           "or {default}].", field="max_image_pixels", type=click.IntRange(min=1),
           help_default="wbcgrade.color.defaults:DEFAULT_MAX_IMAGE_PIXELS",
           expose_value=False, callback="wbcgrade.cli.grading_options:set_max_image_pixels",
           metavar="N"),
    # colour spaces
    Option("input_space", "--input-space", "Colour space of the photos (an OpenColorIO name, "
           "alias or role, or srgb, display-p3, adobe-rgb, linear-rec709, acescg, acescct; "
           "case ignored) [default: what the file says (ICC profile, EXR chromaticities), else "
           "sRGB for 8/16-bit and Linear Rec.709 for float files].", field="spaces.input",
           json="input_space", metavar="NAME", section=SPACES),
    Option("working_space", "--working-space", "Colour space whose unit cube the histograms, "
           "the transport and the colour map live in, e.g. acescct [default: sRGB-encoded "
           "Rec.709]. Config: $OCIO, else OpenColorIO's built-in ocio://default.",
           field="spaces.working", json="working_space", metavar="NAME", section=SPACES),
    # outputs
    Option("lut_size", "--lut-size", "Nodes per axis of the LUT.", field="lut_size",
           type=int, default="wbcgrade.color.defaults:DEFAULT_LUT_SIZE", lazy_default=True,
           show_default=True, section=OUTPUTS),
    Option("lut_format", "--lut-format", "LUT file format: .cube (Resolve/Adobe; with a 1D "
           "shaper for a logarithmic working space) or .clf (Academy/ASC Common LUT Format; "
           "needs the opencolorio package) [default: the --lut file's ending].",
           field="lut_format", type=click.Choice(["cube", "clf"]), section=OUTPUTS),
    Option("look_path", "--look", "Apply a saved grade instead of fitting one: the JSON "
           "written by `apply --save-grade FILE` (regrain as it was) or a 3-D LUT (.cube from "
           "--lut, .clf, ...; regrained unless --no-regrain). Replaces --style/--preset; the "
           "fit options are not used.", field="look", type=_PATH, metavar="FILE",
           section=SOURCE),
    Option("originals_dir", "--originals", "Folder of the originals of some of the --style "
           "photos (paired by file name as `look learn` pairs them; raw originals and "
           "resized or cropped exports included): the look is learned from those pairs, "
           "and the style photos without an original correct it where the pairs show "
           "little. One hand-edited photo with its original is worth more than a folder "
           "of edits alone.", field="originals", type=_FOLDER, metavar="DIR",
           section=SOURCE),
    Option("quality", "--quality", "JPEG/WebP quality 1-100 [default: a JPEG photo's own "
           "quality, else 95 for JPEG; the encoder's for WebP].", field="quality",
           type=click.IntRange(1, 100), metavar="N", section=OUTPUTS),
    Option("bit_depth", "--bit-depth", "Bits per channel of the output (where its format holds "
           "them: JPEG 8; PNG 8/16; TIFF 8/16/float; EXR 16 = half, float) [default: the "
           "input's; raw photos 16, float in EXR].", field="bit_depth",
           type=click.Choice(["8", "16", "float"]), section=OUTPUTS),
    Option("report_dir", "--report", "Also write a report into this folder.",
           field="report_dir", type=_FOLDER, section=OUTPUTS),
    Option("lut", "--lut", "Also write the grade as a 3-D LUT.", field="lut", type=_FILE,
           section=OUTPUTS),
    Option("overwrite", "--overwrite", "Replace existing output files.", field="overwrite",
           is_flag=True, default=False, section=OUTPUTS),
    Option("output", "--output", "Output file [default: <stem>_graded.<ext> beside the input].",
           field="output", decls=("-o", "--output"), type=_FILE, section=OUTPUTS),
    Option("out_dir", "--output-dir", "Output folder.", field="out_dir",
           decls=("-o", "--output-dir"), type=_FOLDER, section=OUTPUTS),
    Option("as_json", "--json", "Print the result as JSON.", is_flag=True, default=False,
           section=OUTPUTS),
    Option("save_grade", "--save-grade", "Also write the grade itself to FILE (JSON), which "
           "--look FILE applies again with no fit.", field="save_grade", type=_FILE,
           metavar="FILE", section=OUTPUTS),
    # batch and video
    Option("recursive", "--recursive", "Descend into sub-folders.", field="recursive",
           decls=("-r", "--recursive"), is_flag=True, default=False),
    Option("consistent", "--consistent", "One grade for the whole series.",
           field="consistent", is_flag=True, default=False),
    Option("force_alias", "--force", "Deprecated alias of --overwrite.", is_flag=True,
           default=False, hidden=True),
    Option("jobs", "--jobs", "Grade photos in N local processes.", field="jobs",
           decls=("-j", "--jobs"), type=int, default=1, show_default=True),
    Option("scheduler", "--scheduler", "Send the photos to a Dask distributed scheduler (needs "
           "wbcgrade[dask]).", field="scheduler", metavar="ADDRESS"),
    Option("per_shot", "--per-shot", "Detect cuts and fit one grade per shot (blended over "
           "--blend-frames at each cut) instead of one grade for the whole clip.",
           field="per_shot", is_flag=True, default=False),
    Option("sample_every", "--sample-every", "Seconds between the frames sampled for the fit.",
           field="sample_every", type=FINITE_FLOAT,
           default="wbcgrade.video.defaults:DEFAULT_SAMPLE_EVERY", lazy_default=True,
           show_default=True, metavar="SECONDS"),
    Option("cut_threshold", "--cut-threshold", "--per-shot: colour change between consecutive "
           "frames (0-1) that starts a new shot.", field="cut_threshold", type=FINITE_FLOAT,
           default="wbcgrade.video.defaults:DEFAULT_CUT_THRESHOLD", lazy_default=True,
           show_default=True),
    Option("blend_frames", "--blend-frames", "--per-shot: frames over which the grade changes "
           "at a cut (0: switch).", field="blend", type=int,
           default="wbcgrade.video.defaults:DEFAULT_BLEND", lazy_default=True,
           show_default=True),
    Option("codec", "--codec", "Video encoder: x264/x265 (CRF), prores (ProRes 422 HQ, .mov), "
           "ffv1 (lossless, .mkv). Other streams are copied.", field="codec",
           type="wbcgrade.video.defaults:CODECS",
           default="wbcgrade.video.defaults:DEFAULT_CODEC", lazy_default=True,
           show_default=True),
    Option("crf", "--crf", "x264/x265 constant rate factor (lower: better, larger).",
           field="crf", type=int, default="wbcgrade.video.defaults:DEFAULT_CRF",
           lazy_default=True, show_default=True),
    # look extract: a scale of the look found, at most 2, default its reliability (apply's
    # --strength blends a grade made at its own strength, up to 4)
    Option("look_strength", "--strength", "Scale of the extracted look [default: how far the "
           "two halves of the set agree on it; a preset's own look: all of it].",
           field="strength", type=click.FloatRange(0.0, 2.0), section=SOURCE),
    # preset build: the preset's own histograms
    Option("preset_bins", "--bins", "Bins per axis of the stored histograms (apply re-bins "
           "them as needed).", field="bins", type=int, default=32, show_default=True,
           section=HISTOGRAMS),
    Option("preset_width", "--width", "Kernel width (bins) recorded with the preset.",
           field="width", type=FINITE_FLOAT,
           default="wbcgrade.color.defaults:DEFAULT_PRESET_WIDTH",
           lazy_default=True, show_default=True, section=HISTOGRAMS),
    Option("description", "--description", "One line shown by `preset list`.",
           field="description", default=""),
    Option("compact", "--compact", "Store 16-bit bins (about half the file; for hundreds of "
           "photos).", field="compact", is_flag=True, default=False),
    # explore
    Option("presets", "--preset", "Shipped preset name (see `wbcgrade preset list`) or a "
           "preset .npz file; repeat it to offer more in the page's preset picker (the page "
           "opens on the first; every shipped preset is offered too).", multiple=True,
           metavar="NAME_OR_FILE", section=SOURCE),
    Option("save_dir", "--save-dir", "Folder the page's \"Save the graded photo\" writes into "
           "(new files <stem>_explore_<n>.<ext>, never replacing one) [default: the photo's "
           "folder].", field="save_dir", type=_FOLDER, section=OUTPUTS),
    Option("port", "--port", "Port on 127.0.0.1 (0: any free port).", field="port",
           type=click.IntRange(0, 65535), default=0, show_default=True),
    Option("no_browser", "--no-browser", "Do not open a browser; print the address only.",
           is_flag=True, default=False),
    # brdf
    Option("png", "--png", "Comparison picture [default: OUTPUT with .png].", field="png",
           type=_FILE),
    Option("materials", "--material", "Write these materials instead (repeatable; see --list).",
           field="material", multiple=True, metavar="NAME"),
    Option("folder", "--output", "Folder to write the database into (created if needed).",
           decls=("-o", "--output"), type=click.Path(file_okay=False)),
    Option("count", "--count", "Number of materials (the first of the built-in catalogue).",
           type=click.IntRange(1, 64), default=6, show_default=True),
    Option("list_only", "--list", "List the material names and exit.", is_flag=True,
           default=False),
    Option("directions", "--directions", "Hemisphere sampling size N.",
           type=click.IntRange(8, 2000), default=_BRDF + "DEFAULT_DIRECTIONS",
           lazy_default=True, show_default=True),
    # brdf fit (its --loss, --width, --iterations and --max-iter are not the grading ones)
    Option("brdf_database", "--database", "Folder of BRDF files (.binary MERL or .npz "
           "sampled).", type=click.Path(file_okay=False), required=True),
    Option("keeps", "--keep", "Keep only this random fraction of the measurements (simulated "
           "sparse acquisition); repeat for several fits side by side, e.g. --keep 0.25 "
           "--keep 0.1 --keep 0.05 (the paper's Figure 6).",
           type=click.FloatRange(0.0, 1.0, min_open=True), multiple=True),
    Option("seed", "--seed", "Seed of the decimation.", default=0, show_default=True),
    Option("no_png", "--no-png", "Do not render the comparison picture.", is_flag=True,
           default=False),
    Option("compare", "--compare", "With --keep, also fit the full measurement for "
           "comparison.", decls=("--compare/--no-compare",), default=True, show_default=True),
    Option("brdf_loss", "--loss", "Fit loss: sinkhorn-divergence is the entropic Wasserstein "
           "loss without its entropic bias; wasserstein is the paper's (biased: it favours "
           "blurry BRDFs); quadratic is the fastest.", type=_BRDF + "BRDF_LOSSES",
           default=_BRDF + "DEFAULT_LOSS", lazy_default=True, show_default=True),
    Option("fit_directions", "--fit-directions", "Incoming directions (well spread) whose rows "
           "fit the weights; 0 = all N.", type=click.IntRange(0, 2000),
           default=_BRDF + "DEFAULT_FIT_DIRECTIONS", lazy_default=True, show_default=True),
    Option("brdf_width", "--width", "Kernel width in sample spacings (sets gamma).",
           type=click.FloatRange(0.1, 20.0), default=_BRDF + "DEFAULT_WIDTH",
           lazy_default=True, show_default=True),
    Option("brdf_n_iter", "--iterations", "Barycenter iterations L (--n-iter: its former "
           "name).", decls=("--iterations", "--n-iter"), type=click.IntRange(1), upper=_MAX_L,
           default=_BRDF + "DEFAULT_N_ITER", lazy_default=True, show_default=True),
    Option("brdf_max_iter", "--max-iter", "L-BFGS iterations at most.",
           type=click.IntRange(1, 1000), default=_BRDF + "DEFAULT_MAX_ITER", lazy_default=True,
           show_default=True),
    Option("tol", "--tol", "Stop when an L-BFGS iteration lowers the energy (1 at uniform "
           "weights) by less than this.", type=click.FloatRange(0, 1),
           default=_BRDF + "DEFAULT_TOL", lazy_default=True, show_default=True),
    # shape complete and project (--width, --iterations, --max-iter, --loss, --jobs their own)
    Option("shape_database", "--database", "Database files or folders (repeat the option for "
           "several).", decls=("--database", "-d"), multiple=True, required=True),
    Option("resolution", "--resolution", "Voxels along the largest axis.",
           decls=("--resolution", "-n"), type=click.IntRange(min=8),
           default=_SHAPE + "DEFAULT_RESOLUTION", lazy_default=True, show_default=True),
    Option("missing", "--missing", "Fraction of the input's volume that is missing (complete: "
           "estimated where the input is placed when not given; project: 0).",
           type=click.FloatRange(0.0, 0.95)),
    Option("euclidean", "--euclidean", "Fit a linear mixture of the database instead (for "
           "comparison).", is_flag=True, default=False),
    Option("shape_width", "--width", "Kernel standard deviation in voxels (default 1 at 64^3, "
           "scaled).", type=click.FloatRange(0.5, 1000.0)),
    Option("shape_iterations", "--iterations", "Barycenter iterations L.",
           type=click.IntRange(1), upper=_MAX_L, default=_SHAPE + "DEFAULT_N_ITER",
           lazy_default=True, show_default=True),
    Option("shape_max_iter", "--max-iter", "Optimiser iterations at most.",
           type=click.IntRange(min=1), default=_SHAPE + "DEFAULT_MAX_ITER", lazy_default=True,
           show_default=True),
    Option("coarse", "--coarse", "Fit on a half-size grid first (grids of 32 voxels or more).",
           decls=("--coarse/--no-coarse",), default=True, show_default=True),
    Option("top", "--top", "Database shapes shown in the picture.", type=click.IntRange(min=0),
           default=3, show_default=True),
    Option("quiet", "--quiet", "No progress bar.", decls=("--quiet", "-q"), is_flag=True,
           default=False),
    Option("shape_loss", "--loss", "kl_reverse = KL(input|barycenter); kl = the paper's "
           "KL(barycenter|input).", type=_SHAPE + "LOSS_NAMES", case_sensitive=False,
           default=_SHAPE + "DEFAULT_LOSS", lazy_default=True, show_default=True),
    Option("observed_only", "--observed-only", "Compare the input's voxels only, leaving the "
           "barycenter free where the input is missing (kl_reverse, kl, quadratic, l1), or "
           "every voxel.", decls=("--observed-only/--all-voxels",), default=True,
           show_default=True),
    Option("align", "--align", "Align every mesh on its principal axes first, picking the "
           "axes' signs that overlap the input most, and fit a rotation when placing the input "
           "(for databases of unaligned meshes).", is_flag=True, default=False),
    Option("volume_path", "--volume", "Fitted density (.npy; default beside -o).",
           type=_FILE_PATH),
    Option("smooth", "--smooth", "Taubin smoothing passes on the surface.",
           type=click.IntRange(min=0), default=10, show_default=True),
    Option("shape_jobs", "--jobs", "Worker processes voxelising the database meshes.",
           decls=("--jobs", "-j"), type=click.IntRange(min=1), default=1, show_default=True),
)

_BY_NAME = {row.name: row for row in OPTIONS}


def option(name: str) -> Option:
    """The row whose parameter is ``name``."""
    return _BY_NAME[name]


def click_options(*names: str, **changes) -> list:
    """The click.option decorators of the rows named, in that order; ``changes`` replace
    fields of a single row (e.g. a command's own ``help``)."""
    from dataclasses import replace

    rows = [option(name) for name in names]
    if changes:
        rows = [replace(row, **changes) for row in rows]
    return [row.build() for row in rows]


#: Library field (``group.field``, or a library setting's name) -> the flag that sets it.
flag_of: dict[str, str] = {row.field: row.flag for row in OPTIONS if row.field is not None}


def flag_error(error):
    """An OptionError naming library settings -> the same error naming their flags
    (:meth:`wbcgrade.errors.InputError.worded` through :data:`flag_of`); an error whose
    setting has no flag is left as it is."""
    flag = flag_of.get(getattr(error, "option", None))
    if flag is None:
        return error
    return OptionError(flag_text(error), flag, path=getattr(error, "path", None))


def flag_text(error) -> str:
    """The message of a library error with the settings it names (``error.option``,
    ``.also``, ``.fields``) written as their flags (:data:`flag_of`); a warning's text
    (:class:`wbcgrade.errors.Worded`) the same way."""
    worded = getattr(error, "worded", None)
    return str(error) if worded is None else worded(flag_of)


def names_in(section: str) -> tuple[str, ...]:
    """The parameter names of the rows of one ``--help`` section, in table order."""
    return tuple(row.name for row in OPTIONS if row.section == section)


def json_keys() -> dict[str, str]:
    """Parameter name -> the key records write it under (rows with a JSON key)."""
    return {row.name: row.json for row in OPTIONS if row.json is not None}
