"""Colour spaces: names, what a file says, the one conversion engine, and the encoding
of a grade (:class:`ColorEncoding`).

Everything goes through OpenImageIO's built-in OpenColorIO
(``ImageBufAlgo.colorconvert``, :func:`convert`) with the config named by
``$OCIO``, else the library's built-in ``ocio://default`` (the ACES "CG"
config). Space names are resolved through the config's own names, aliases
and roles, and through a few short aliases of ours (``srgb``,
``display-p3``, ``adobe-rgb``, ``acescg``, ``acescct``, ``linear-rec709``,
...), case-insensitively, so that the code does not depend on one release's
spelling.

A :class:`ColorEncoding` names the space of the pixels (``input``) and the
space whose unit cube the histograms, the transport and the colour map live
in (``working``); every conversion goes through one engine,
OpenColorIO (:func:`convert`). The default pair
(an sRGB photo graded in sRGB-encoded Rec.709, or a Linear Rec.709 EXR
graded there) is one instance like any other.

A photo goes there and back as follows (:meth:`ColorEncoding.encode`,
:meth:`ColorEncoding.decode`):

1. float pixels (EXR, float TIFF) are converted into the working space's
   *linear partner* (Linear Rec.709 for sRGB, ACEScg for ACEScct/ACEScc,
   Linear P3-D65 for sRGB-encoded P3, ...); a pixel whose largest channel m
   exceeds the partner's *peak* (the linear value the working space encodes
   as 1: 1.0 for sRGB, ~222.9 for ACEScct) is divided by m / peak and
   multiplied back after grading: highlights keep their intensity, only
   their colour is graded. Integer pixels are converted directly;
2. what is still outside [0, 1] in the working space (out-of-gamut colours,
   negative values) is carried as a residual: the grade sees the clipped
   colour and the residual is added back to its result, so an identity
   grade returns every pixel unchanged;
3. after grading the same steps run backwards, into the *input* space: the
   written file keeps its space, its ICC profile and its metadata.

The encoding also says what lightness means in the working space, for the
map's finishing steps: :meth:`~ColorEncoding.to_oklab` (Oklab through the
working space's own decoding and primaries, D65) and
:attr:`~ColorEncoding.luma_weights` (the working encoding's luma).

>>> import numpy as np
>>> from wbcgrade.color.colorspace import ColorEncoding
>>> srgb = ColorEncoding.of()                     # sRGB pixels in sRGB-encoded Rec.709
>>> encoded, state = srgb.encode(np.array([[[0.2, 0.5, 0.9]]], np.float32))
>>> np.allclose(srgb.decode(encoded, state), [[[0.2, 0.5, 0.9]]])
True
>>> cct = ColorEncoding.of("acescg", "acescct")   # linear ACEScg pixels, graded in ACEScct
>>> hot = np.array([[[4.0, 2.0, 1.0]]], np.float32)
>>> encoded, state = cct.encode(hot, float_values=True)
>>> bool(np.all((encoded > 0) & (encoded < 1)))     # 4.0 is inside ACEScct's cube
True
>>> np.allclose(cct.decode(encoded, state), hot, rtol=1e-4)
True
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from wbcgrade.color._colour import colour_science
from wbcgrade.color.io.cache import default_cache_dir
from wbcgrade.color.io.raw import RAW_WORKING_SPACE
from wbcgrade.errors import InputError, OptionError, Worded, first_line

__all__ = [
    "DEFAULT_CONFIG",
    "SHORT_ALIASES",
    "config_path",
    "config_info",
    "config_line",
    "space_names",
    "resolve_space",
    "canonical",
    "default_working_space",
    "detect_input_space",
    "convert",
    "linear_partner",
    "is_logarithmic",
    "peak",
    "ColorEncoding",
    "WorkingState",
    "SYCC_LUMA",
    "REC709_LUMA",
]

#: The config used when ``$OCIO`` is not set: OpenColorIO's built-in default.
DEFAULT_CONFIG = "ocio://default"

#: Our short names -> candidate names in the config (first found wins; the
#: candidates cover the spellings of the ACES configs OpenColorIO 2.2-2.6 ship).
SHORT_ALIASES: dict[str, tuple[str, ...]] = {
    "srgb": ("sRGB Encoded Rec.709 (sRGB)", "srgb_tx", "srgb_texture", "sRGB - Texture",
             "Utility - sRGB - Texture"),
    "linear-rec709": ("Linear Rec.709 (sRGB)", "lin_rec709_srgb", "lin_rec709", "lin_srgb",
                      "Utility - Linear - sRGB"),
    "display-p3": ("sRGB Encoded P3-D65", "srgb_encoded_p3d65", "srgb_displayp3",
                   "srgb_p3d65"),
    "linear-p3": ("Linear P3-D65", "lin_p3d65", "lin_displayp3"),
    "adobe-rgb": ("Gamma 2.2 Encoded AdobeRGB", "g22_encoded_adobergb", "adobergb"),
    "linear-adobe-rgb": ("Linear AdobeRGB", "lin_adobergb"),
    "linear-rec2020": ("Linear Rec.2020", "lin_rec2020"),
    "acescg": ("ACEScg", "lin_ap1", "ACES - ACEScg"),
    "acescct": ("ACEScct", "acescct_ap1", "ACES - ACEScct"),
    "acescc": ("ACEScc", "acescc_ap1", "ACES - ACEScc"),
    "aces2065-1": ("ACES2065-1", "aces2065_1", "lin_ap0", "ACES - ACES2065-1"),
}

#: More spellings of the short names (compared with case, spaces and punctuation removed).
_SPELLINGS = {
    "srgb": "srgb", "srgbrec709": "srgb", "rec709srgb": "srgb",
    "linear": "linear-rec709", "linearrec709": "linear-rec709", "linrec709": "linear-rec709",
    "linearsrgb": "linear-rec709", "linsrgb": "linear-rec709",
    "displayp3": "display-p3", "p3": "display-p3", "dcip3": "display-p3", "p3d65": "display-p3",
    "linearp3": "linear-p3", "linearp3d65": "linear-p3", "lindisplayp3": "linear-p3",
    "adobergb": "adobe-rgb", "adobergb1998": "adobe-rgb",
    "linearadobergb": "linear-adobe-rgb",
    "linearrec2020": "linear-rec2020", "linrec2020": "linear-rec2020",
    "acescg": "acescg", "acescct": "acescct", "acescc": "acescc",
    "aces": "aces2065-1", "aces20651": "aces2065-1", "ap0": "aces2065-1",
}

#: Working space (short name) -> its linear partner (short name): where the
#: exposure rule for values above the working space's range divides.
_LINEAR_PARTNER = {
    "srgb": "linear-rec709", "linear-rec709": "linear-rec709",
    "display-p3": "linear-p3", "linear-p3": "linear-p3",
    "adobe-rgb": "linear-adobe-rgb", "linear-adobe-rgb": "linear-adobe-rgb",
    "linear-rec2020": "linear-rec2020",
    "acescg": "acescg", "acescct": "acescg", "acescc": "acescg",
    "aces2065-1": "aces2065-1",
}
_LOGARITHMIC = ("acescct", "acescc")

#: EXR ``chromaticities`` (rx, ry, gx, gy, bx, by, wx, wy) -> linear space (short name).
_CHROMATICITIES = {
    "linear-rec709": (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290),
    "acescg": (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767),
    "aces2065-1": (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767),
    "linear-p3": (0.680, 0.320, 0.265, 0.690, 0.150, 0.060, 0.3127, 0.3290),
    "linear-rec2020": (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290),
    "linear-adobe-rgb": (0.64, 0.33, 0.21, 0.71, 0.15, 0.06, 0.3127, 0.3290),
}

#: ICC profile descriptions (lower case, searched in order) -> short name.
_ICC_DESCRIPTIONS = (("display p3", "display-p3"), ("p3", "display-p3"),
                     ("adobe rgb", "adobe-rgb"), ("adobergb", "adobe-rgb"),
                     ("srgb", "srgb"))


def _squash(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.lower())


def config_path() -> str:
    """The OpenColorIO config in use: ``$OCIO`` when set, else ``ocio://default``."""
    return os.environ.get("OCIO", "").strip() or DEFAULT_CONFIG


@functools.lru_cache(maxsize=4)
def _config(path: str):
    import OpenImageIO as oiio

    config = oiio.ColorConfig(path)
    if config.configname() == "built-in" and path != "built-in":
        # OpenImageIO falls back to a minimal config of its own, which would turn
        # every space name into "unknown colour space"
        why = first_line(config.geterror(), "no reason given").replace("Error: ", "")
        source = "$OCIO" if path == os.environ.get("OCIO", "").strip() else "the config"
        raise InputError(f"OpenColorIO config {path} ({source}) could not be read ({why}); "
                         "fix it, or unset OCIO to use the built-in ocio://default")
    names = list(config.getColorSpaceNames())
    if not names:
        raise InputError(f"OpenColorIO config {path!r} could not be read or lists no colour "
                         f"spaces ({config.geterror().strip() or 'check $OCIO'})")
    return config


@functools.lru_cache(maxsize=4)
def _lookup(path: str) -> dict[str, str]:
    """Squashed spelling -> config colour space name, for every name, alias and role."""
    config = _config(path)
    names = list(config.getColorSpaceNames())
    table: dict[str, str] = {}
    for role in config.getRoles():
        target = config.getColorSpaceNameByRole(role)
        if target in names:
            table.setdefault(_squash(role), target)
    for name in names:
        for alias in config.getAliases(name):
            table[_squash(alias)] = name
    for name in names:
        table[_squash(name)] = name
    for short, candidates in SHORT_ALIASES.items():
        for candidate in candidates:
            found = table.get(_squash(candidate))
            if found is not None:
                table[_squash(short)] = found
                break
    for spelling, short in _SPELLINGS.items():
        if _squash(short) in table:
            table[spelling] = table[_squash(short)]
    return table


def space_names() -> list[str]:
    """The colour space names of the config in use (its order)."""
    return list(_config(config_path()).getColorSpaceNames())


def canonical(short: str) -> str | None:
    """The config's name for one of :data:`SHORT_ALIASES`, or None when it has none."""
    return _lookup(config_path()).get(_squash(short))


def resolve_space(name: str, option: str = "spaces.working",
                  path: str | os.PathLike | None = None) -> str:
    """A colour space name, alias or role -> the config's colour space name.

    Case, spaces and punctuation do not matter (``ACEScct``, ``acescct``,
    ``display-p3``, ``Display P3``, ``lin_rec709``). Raises OptionError
    (one line, naming the setting ``option``, after ``path`` when the name was read
    from a file, and listing the valid names) otherwise.
    """
    text = str(name).strip()
    found = _lookup(config_path()).get(_squash(text)) if text else None
    if found is None:
        shorts = ", ".join(s for s in SHORT_ALIASES if canonical(s))
        head = "" if path is None else f"{path}: "
        raise OptionError(
            f"{head}{{{option}}}: unknown colour space {name!r} in OpenColorIO config "
            f"{config_path()} (valid: {', '.join(space_names())}; or {shorts})", option,
            path=path)
    return found


def _short_of(space: str) -> str | None:
    for short in SHORT_ALIASES:
        if canonical(short) == space:
            return short
    return None


def default_working_space() -> str:
    """The working space of today's behaviour: sRGB-encoded Rec.709."""
    found = canonical("srgb")
    if found is None:
        raise InputError(f"OpenColorIO config {config_path()} has no sRGB-encoded Rec.709 "
                         "space; name one with {spaces.working}", fields=("spaces.working",))
    return found


def linear_partner(space: str) -> str:
    """The linear space whose values ``space`` encodes (ACEScg for ACEScct; itself if linear).

    Spaces we do not know fall back to the config's ``scene_linear`` role.
    """
    short = _short_of(space)
    if short is not None and canonical(_LINEAR_PARTNER[short]) is not None:
        return canonical(_LINEAR_PARTNER[short])
    return _lookup(config_path()).get("scenelinear", space)


def is_logarithmic(space: str) -> bool:
    """Whether ``space`` is a logarithmic encoding (ACEScct, ACEScc)."""
    return _short_of(space) in _LOGARITHMIC


def convert(rgb: np.ndarray, source: str, target: str) -> np.ndarray:
    """Convert colours between two colour spaces of the config (OpenColorIO via OpenImageIO).

    Parameters
    ----------
    rgb : (..., 3) float colours in ``source``.
    source, target : config colour space names (:func:`resolve_space`).

    Returns
    -------
    (..., 3) float32 in ``target`` (values are not clipped). Runs on the
    calling thread only (OpenImageIO's thread pool is never started: the
    JPEG writer may fork, see ``imageio._encode_in_child``).
    """
    rgb = np.asarray(rgb, dtype=np.float32)
    if source == target:
        return rgb.copy()
    import OpenImageIO as oiio

    shape = rgb.shape
    flat = np.ascontiguousarray(rgb.reshape(1, -1, 3) if rgb.ndim != 3 else rgb)
    buf = oiio.ImageBuf(flat)
    out = oiio.ImageBufAlgo.colorconvert(buf, source, target, False, "", "", config_path(),
                                         oiio.ROI.All, 1)
    if out.has_error:
        raise InputError(f"colour conversion {source!r} -> {target!r} failed "
                         f"({out.geterror().strip().splitlines()[0]})")
    return np.asarray(out.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(shape)


def peak(linear: str, working: str) -> float:
    """The largest grey value of ``linear`` that ``working`` encodes at or below 1
    (1.0 for sRGB; about 222.9 for ACEScct over ACEScg)."""
    return _peak(linear, working, config_path())


@functools.lru_cache(maxsize=32)
def _peak(linear: str, working: str, path: str) -> float:
    """:func:`peak`, kept in the wbcgrade cache folder (``peaks.json``) once searched: the
    search costs four conversions (a tenth of a second of every grade's start); the
    same number comes back, whatever the folder holds for other configs or releases."""
    key = _peak_key(linear, working, path)
    saved = _saved_peaks()
    if isinstance(saved.get(key), float):
        return saved[key]
    value = _search_peak(linear, working)
    _save_peak(key, value)
    return value


def _peak_key(linear: str, working: str, path: str) -> str:
    """What a saved peak depends on: the spaces, the config (a file's size and time), the
    OpenImageIO and OpenColorIO releases."""
    import OpenImageIO as oiio

    try:
        stat = os.stat(path)
        stamp = f"{stat.st_size}:{stat.st_mtime_ns}"
    except (OSError, ValueError):  # a built-in config (ocio://...)
        stamp = ""
    return "|".join((linear, working, path, stamp, getattr(oiio, "VERSION_STRING", ""),
                     oiio.get_string_attribute("opencolorio_version")))


def _peaks_file():
    return default_cache_dir() / "peaks.json"


def _saved_peaks() -> dict:
    import json

    try:
        saved = json.loads(_peaks_file().read_text(encoding="utf-8"))
    except (OSError, ValueError):  # none yet, unreadable or damaged: searched again
        return {}
    return saved if isinstance(saved, dict) else {}


def _save_peak(key: str, value: float) -> None:
    """Add one peak to ``peaks.json`` (written atomically; a failure only costs a search)."""
    import json
    import tempfile

    path = _peaks_file()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        saved = {**_saved_peaks(), key: value}
        fd, temporary = tempfile.mkstemp(prefix=".peaks.", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(saved, f)
            os.replace(temporary, path)
        except BaseException:
            os.unlink(temporary)
            raise
    except OSError:
        pass


def _search_peak(linear: str, working: str) -> float:
    def encodes_inside(values: np.ndarray) -> np.ndarray:
        grey = np.repeat(np.asarray(values, dtype=np.float64)[:, None], 3, axis=1)
        return convert(grey, linear, working).max(axis=1) <= 1.0 + 1e-6

    ramp = np.geomspace(1e-3, 1e5, 4097)  # a coarse ramp, then finer ramps between two samples
    inside = np.flatnonzero(encodes_inside(ramp))
    if len(inside) == 0:
        return 1.0
    if inside[-1] == len(ramp) - 1:
        return float(ramp[-1])
    low, high = float(ramp[inside[-1]]), float(ramp[inside[-1] + 1])
    for _ in range(3):  # each ramp, one conversion, narrows the step 4096 times (not 40 halvings)
        ramp = np.linspace(low, high, 4097)
        inside = np.flatnonzero(encodes_inside(ramp))
        if len(inside) == 0:
            break
        low, high = float(ramp[inside[-1]]), float(ramp[min(inside[-1] + 1, len(ramp) - 1)])
    return low


def detect_input_space(image) -> tuple[str, str]:
    """The colour space a decoded photo says it is in -> (config name, where it came from).

    8/16-bit files: the ICC profile's description (sRGB, Display P3, Adobe
    RGB (1998)), else sRGB. Float files (EXR): the ``chromaticities``
    attribute (Rec.709, ACES AP1/AP0, P3-D65, Rec.2020, Adobe RGB
    primaries: the linear space with those primaries), else a
    ``colorInteropID`` or ``oiio:ColorSpace`` the config knows, else Linear
    Rec.709.
    """
    spec = image.spec
    table = _lookup(config_path())
    if not image.is_float:
        # OpenImageIO decodes the profile's description tag (ICC v2 'desc', v4 'mluc').
        text = spec.get_string_attribute("ICCProfile:profile_description", "").strip()
        if spec.getattribute("ICCProfile") is not None:
            for key, short in _ICC_DESCRIPTIONS:
                if key in text.lower() and canonical(short):
                    return canonical(short), f"ICC profile {text!r}"
            if text:
                return default_working_space(), f"ICC profile {text!r} not recognised: sRGB assumed"
        return default_working_space(), "8/16-bit file without a known profile: sRGB"
    chroma = spec.getattribute("chromaticities")
    if chroma is not None and len(tuple(chroma)) == 8:
        values = np.asarray(tuple(chroma), dtype=np.float64)
        for short, ref in _CHROMATICITIES.items():
            if np.max(np.abs(values - np.asarray(ref))) < 2e-3 and canonical(short):
                return canonical(short), "EXR chromaticities"
    for name in ("colorInteropID", "oiio:ColorSpace"):
        value = spec.get_string_attribute(name, "")
        if value and table.get(_squash(value)):
            return table[_squash(value)], f"{name} {value!r}"
    return canonical("linear-rec709") or default_working_space(), \
        "float file without colour metadata: Linear Rec.709"


def config_info() -> dict:
    """The config in use and the library versions, for JSON and reports.

    ``ocio_config_name`` is the config's own name (e.g. the built-in
    ``cg-config-v2.2.0_aces-v1.3_ocio-v2.4``) when the ``opencolorio`` package
    of the same OpenColorIO release as OpenImageIO's can read it, else the
    config's path or URI.
    """
    import OpenImageIO as oiio

    version = oiio.get_string_attribute("opencolorio_version")
    return {"ocio_config": config_path(),
            "ocio_config_name": _config_name(config_path(), version),
            "ocio_version": version,
            "openimageio_version": getattr(oiio, "VERSION_STRING", "")}


def config_line() -> str:
    """The config in use and OpenColorIO's version, as a LUT's header names them."""
    import OpenImageIO as oiio

    return (f"OpenColorIO config: {config_path()} "
            f"(OpenColorIO {oiio.get_string_attribute('opencolorio_version')})")


@functools.lru_cache(maxsize=4)
def _config_name(path: str, version: str) -> str:
    try:
        import PyOpenColorIO as ocio
    except ImportError:
        return path
    if ocio.__version__.split(".")[:2] != version.split(".")[:2]:
        return path  # another release's built-in configs: not the one OpenImageIO uses
    try:
        return ocio.Config.CreateFromFile(path).getName() or path
    except Exception:  # noqa: BLE001 - any failure: the path is still a true name
        return path


# ------------------------------------------------------------------ the encoding of a grade
#: Luma of sRGB-encoded values: sYCC's (IEC 61966-2-1), BT.601's weights, as
#: 8-bit JPEG files store their Y'CbCr. The one definition: remap's lightness
#: order, the grey of written files, the scene and pair matchers' 8-bit lightness.
SYCC_LUMA = (0.299, 0.587, 0.114)
#: The Rec.709 primaries' weights (BT.709): of linear values their luminance (the grey
#: of scene-linear pixels), of encoded ones the look family's luma (look.statistics.LUMA).
REC709_LUMA = (0.2126, 0.7152, 0.0722)


@dataclass
class WorkingState:
    """What :meth:`ColorEncoding.decode` needs to undo one :meth:`ColorEncoding.encode`.

    ``scale`` (H, W, 1): the exposure factor (>= 1) of float pixels above the
    peak, or None; ``residual`` (H, W, 3): the working-space colours outside
    [0, 1], or None.
    """

    scale: np.ndarray | None = None
    residual: np.ndarray | None = None


#: ``ColorEncoding.source`` of an input space the caller named: the setting that names it.
GIVEN_INPUT = Worded("{spaces.input}", ("spaces.input",))


@dataclass(frozen=True)
class ColorEncoding:
    """Pixels of one colour space (``input``) graded in another's unit cube (``working``).

    Attributes
    ----------
    input : config name of the pixels' space.
    working : config name of the working space.
    linear : the working space's linear partner (where the exposure rule divides).
    peak : the largest grey value of ``linear`` that ``working`` encodes at or below 1.
    source : where ``input`` came from (the setting ``spaces.input``, "ICC profile ...",
        "default"; :meth:`named` writes the setting as a caller names it).
    config : the OpenColorIO config.
    """

    input: str
    working: str
    linear: str
    peak: float
    source: str = "given"
    config: str = ""

    # ------------------------------------------------------------------ making one

    @classmethod
    def of(cls, input_space: str | None = None, working_space: str | None = None,
           float_values: bool = False, source: str | None = None) -> ColorEncoding:
        """The encoding of named spaces (names, aliases or roles; OptionError if unknown).

        ``input_space`` None: sRGB, or Linear Rec.709 with ``float_values``;
        ``working_space`` None: sRGB-encoded Rec.709.
        """
        if input_space:
            space, where = resolve_space(input_space, "spaces.input"), GIVEN_INPUT
        elif float_values:
            space, where = canonical("linear-rec709") or default_working_space(), "default"
        else:
            space, where = default_working_space(), "default"
        return cls._make(space, source or where, working_space)

    @classmethod
    def for_image(cls, image, input_space: str | None = None,
                  working_space: str | None = None) -> ColorEncoding:
        """The encoding of a decoded photo (``input_space`` None: what the file says;
        ``working_space`` None: ACEScct for a raw photo, else sRGB-encoded Rec.709)."""
        if working_space is None and image.format_name == "raw":
            working_space = RAW_WORKING_SPACE
        if input_space:
            return cls.of(input_space, working_space)
        space, where = detect_input_space(image)
        return cls._make(space, where, working_space)

    @classmethod
    def _make(cls, input_space: str, source: str, working_space: str | None) -> ColorEncoding:
        working = (resolve_space(working_space, "spaces.working") if working_space
                   else default_working_space())
        linear = linear_partner(working)
        return cls(input_space, working, linear, peak(linear, working), source, config_path())

    def named(self, names: Mapping[str, str] | None) -> ColorEncoding:
        """The same encoding with a setting its ``source`` names written as ``names`` says
        (setting -> the caller's name: the command line passes its flags)."""
        if names is None or not isinstance(self.source, Worded):
            return self
        return replace(self, source=self.source.worded(names))

    def within_working(self) -> ColorEncoding:
        """The encoding whose pixels are already working-space colours (a LUT's own domain)."""
        return ColorEncoding(self.working, self.working, self.linear, self.peak,
                             "working space", self.config)

    # -------------------------------------------------------------- there and back

    def encode(self, rgb: np.ndarray,
               float_values: bool = False) -> tuple[np.ndarray, WorkingState]:
        """Pixel values of the input space -> colours in the working space's unit cube.

        Parameters
        ----------
        rgb : (..., 3) float pixel values (integer files scaled to [0, 1]).
        float_values : the pixels are scene-linear floats (the exposure rule
            applies above the peak).

        Returns
        -------
        encoded : (..., 3) float32 in [0, 1] (``rgb`` itself when it is already
            there in the working space: read it, do not write to it)
        state : for :meth:`decode`.
        """
        rgb = np.asarray(rgb, dtype=np.float32)
        scale = None
        if float_values:
            linear = convert(rgb, self.input, self.linear)
            top = linear.max(axis=-1, keepdims=True) / np.float32(self.peak)
            if np.any(top > 1.0):
                scale = np.maximum(top, 1.0).astype(np.float32)
                linear /= scale
            working = convert(linear, self.linear, self.working)
        elif self.input == self.working:
            working = rgb  # no conversion, no copy (the result is never written to)
        else:
            working = convert(rgb, self.input, self.working)
        if working.size and float(working.min()) >= 0.0 and float(working.max()) <= 1.0:
            return working, WorkingState(scale, None)  # inside the cube: nothing to carry
        encoded = np.clip(working, 0.0, 1.0)
        residual = working - encoded
        if not np.any(residual):
            residual = None
        return encoded.astype(np.float32, copy=False), WorkingState(scale, residual)

    def decode(self, graded: np.ndarray, state: WorkingState) -> np.ndarray:
        """Inverse of :meth:`encode`: graded working colours -> input-space pixel values.

        Float outputs keep values above 1 (the exposure factor is multiplied
        back in the linear partner); integer outputs are clipped by the writer.
        When the photo is graded in its own space, ``graded`` (float32) itself is
        returned, not a copy (as :meth:`encode` returns its input).
        """
        working = np.asarray(graded, dtype=np.float32)
        if state.residual is not None:
            working = working + state.residual
        if state.scale is None:
            if self.input == self.working:
                return working  # no conversion, no copy (a 16 MP copy: 0.1-0.4 s)
            return convert(working, self.working, self.input)
        linear = convert(working, self.working, self.linear) * state.scale
        return convert(linear, self.linear, self.input)

    def to_display(self, rgb: np.ndarray, working: bool = False) -> np.ndarray:
        """Colours for a picture on screen: sRGB-encoded Rec.709, clipped to [0, 1].

        ``rgb`` (..., 3) in the input space, or with ``working`` in the
        working space (e.g. a palette of the grade's histograms).
        """
        source = self.working if working else self.input
        return np.clip(convert(rgb, source, default_working_space()), 0.0, 1.0)

    # --------------------------------------------------- lightness in working terms

    @property
    def logarithmic(self) -> bool:
        """Whether the working space is a logarithmic encoding (ACEScct, ACEScc)."""
        return is_logarithmic(self.working)

    @property
    def luma_weights(self) -> np.ndarray:
        """(3,) weights of the working encoding's luma ``Y' = w . rgb``.

        sRGB-encoded Rec.709: sYCC's (BT.601, :data:`SYCC_LUMA`); any other
        working space: the luminance of its own primaries (the Y row of its
        linear partner's RGB -> XYZ matrix), applied to its encoded values.
        """
        return np.array(_luma_weights(self.working, self.linear, self.config))

    def to_oklab(self, colors: np.ndarray) -> np.ndarray:
        """Working-space colours (..., 3) -> Oklab (L, a, b), float64.

        Decoded into the linear partner, then to CIE XYZ (D65) through Linear
        Rec.709 (OpenColorIO's chromatic adaptation for other white points).
        """
        colour = colour_science()

        linear = convert(np.clip(colors, 0.0, 1.0), self.working, self.linear)
        xyz = np.asarray(linear, dtype=np.float64) @ _to_xyz(self.linear, self.config).T
        return colour.XYZ_to_Oklab(xyz)

    def from_oklab(self, lab: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_oklab`, clipped to the working space's unit cube (float32)."""
        colour = colour_science()

        xyz = colour.Oklab_to_XYZ(np.asarray(lab, dtype=np.float64))
        linear = xyz @ np.linalg.inv(_to_xyz(self.linear, self.config)).T
        working = convert(linear, self.linear, self.working)
        return np.clip(working, 0.0, 1.0).astype(np.float32)

    def as_dict(self) -> dict:
        """JSON-friendly description (config, OpenColorIO version, spaces)."""
        return {**config_info(), "input_space": self.input, "input_space_from": str(self.source),
                "working_space": self.working, "linear_space": self.linear,
                "peak": round(self.peak, 4)}


@functools.lru_cache(maxsize=16)
def _to_xyz(linear: str, config: str) -> np.ndarray:
    """(3, 3) matrix: colours of the linear space ``linear`` -> CIE XYZ (D65)."""
    colour = colour_science()

    rec709 = canonical("linear-rec709")
    if rec709 is None:
        raise InputError(f"OpenColorIO config {config} has no Linear Rec.709 space: lightness "
                         "cannot be computed in the working space's terms")
    to_rec709 = convert(np.eye(3), linear, rec709).astype(np.float64).T  # columns: primaries
    return colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ @ to_rec709


@functools.lru_cache(maxsize=16)
def _luma_weights(working: str, linear: str, config: str) -> tuple[float, float, float]:
    if working == default_working_space():
        return SYCC_LUMA
    if canonical("linear-rec709") is None:
        return SYCC_LUMA  # no way to read the primaries: the sRGB convention
    row = _to_xyz(linear, config)[1]
    return tuple(float(v) for v in row / row.sum())
