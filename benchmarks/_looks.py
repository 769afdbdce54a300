"""Looks with a ground truth for ``benchmarks/look.py``.

A look maps an sRGB-encoded float image (H, W, 3) in [0, 1] to another one in
[0, 1], pixel by pixel (a global colour map, as a LUT or a colourist's grade
is). Two are real Look Modification Transforms (ACES LMTs in CLF) shipped
inside the ``colour-clf-io`` package and applied exactly with OpenColorIO;
the others are defined here in a few lines each.

The LMTs expect scene-linear ACES2065-1 and return it. The photo's
sRGB-encoded Rec.709 values are converted with the ACES config built into
OpenColorIO (``ocio://default``: "sRGB Encoded Rec.709 (sRGB)" ->
"ACES2065-1"), the LMT is applied (``FileTransform``), and the result is
converted back the same way and clipped to [0, 1]. (Going through the
inverse of the ACES 2.0 output transform instead puts near-white highlights
at scene values the LMTs were not built for: the Kodak LMT then paints cyan
blobs into clouds and a ring round the sun.)

Add a look: write ``def my_look(rgb) -> rgb`` and one line in ``LOOKS``.

Two groups: :data:`TUNED_LOOKS`, the six looks the defaults were chosen on
(the benchmark's default), and :data:`HELD_OUT_LOOKS`, looks no default was
chosen on (``--looks held-out``): a real LUT shipped inside colour-science and
five grades of other families (a cool matte CDL, cross-processing curves,
sepia toning, day for night, a pastel high key). A change chosen on the tuned
looks should hold on the held-out ones; where it does not, it was tuned to
those six looks, not to looks in general.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Look", "LOOKS", "TUNED_LOOKS", "HELD_OUT_LOOKS", "FILM_LOOKS", "FILM_TUNED_LOOKS",
           "FILM_HELD_OUT_LOOKS", "MONOCHROME_LOOKS", "asc_cdl", "rec709_luma"]

SRGB = "sRGB Encoded Rec.709 (sRGB)"
ACES = "ACES2065-1"


@dataclass(frozen=True)
class Look:
    """A named look and where it comes from.

    ``apply``: (H, W, 3) sRGB-encoded float in [0, 1] -> same shape in [0, 1].
    ``source()``: package / version / path for a shipped look, parameters for
    one defined here (written to results.json).
    """

    name: str
    apply: Callable[[np.ndarray], np.ndarray]
    description: str
    source: Callable[[], dict]


def rec709_luma(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) -> (...): 0.2126 R + 0.7152 G + 0.0722 B (ASC CDL saturation weights)."""
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def saturate(rgb: np.ndarray, amount: float) -> np.ndarray:
    """Scale the distance from Rec.709 luma by ``amount``."""
    y = rec709_luma(rgb)[..., None]
    return y + amount * (rgb - y)


def asc_cdl(rgb: np.ndarray, slope, offset, power, saturation: float) -> np.ndarray:
    """ASC CDL v1.2: out = clamp(in * slope + offset)^power, then saturation about Rec.709 luma.

    Same as OpenColorIO's ``CDLTransform`` (style ASC, clamping).
    """
    out = np.clip(rgb * np.asarray(slope) + np.asarray(offset), 0.0, 1.0) ** np.asarray(power)
    return np.clip(saturate(out, saturation), 0.0, 1.0)


def smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


# --------------------------------------------------------------------------- looks defined here

CDL_WARM = {"slope": (1.10, 1.00, 0.84), "offset": (0.015, 0.0, -0.02),
            "power": (0.95, 1.0, 1.12), "saturation": 0.85}


def cdl_warm(rgb: np.ndarray) -> np.ndarray:
    """A warm, slightly muted ASC CDL grade (tungsten-golden highlights, yellow-brown mids)."""
    return asc_cdl(rgb, **CDL_WARM)


TEAL_ORANGE = {"shadow_tint": (-0.07, 0.03, 0.08), "highlight_tint": (0.08, 0.02, -0.08),
               "contrast": 1.2, "saturation": 1.15}


def teal_orange(rgb: np.ndarray) -> np.ndarray:
    """Split toning: shadows pushed to teal, highlights to orange, more contrast and colour."""
    p = TEAL_ORANGE
    y = rec709_luma(rgb)[..., None]
    shadows = (1.0 - smoothstep(y / 0.6)) ** 1.5
    highlights = smoothstep((y - 0.35) / 0.65)
    out = rgb + shadows * np.asarray(p["shadow_tint"]) \
        + highlights * np.asarray(p["highlight_tint"])
    out = 0.5 + (out - 0.5) * p["contrast"]
    return np.clip(saturate(np.clip(out, 0.0, 1.0), p["saturation"]), 0.0, 1.0)


BLEACH_BYPASS = {"mix": 0.8, "saturation": 0.45}


def bleach_bypass(rgb: np.ndarray) -> np.ndarray:
    """Bleach bypass: the image overlaid on its own luma (hard contrast), then desaturated."""
    y = rec709_luma(rgb)[..., None]
    overlay = np.where(y < 0.5, 2.0 * rgb * y, 1.0 - 2.0 * (1.0 - rgb) * (1.0 - y))
    out = rgb + BLEACH_BYPASS["mix"] * (overlay - rgb)
    return np.clip(saturate(out, BLEACH_BYPASS["saturation"]), 0.0, 1.0)


FADED_FILM = {"black": (0.07, 0.10, 0.13), "white": (0.96, 0.93, 0.84), "curve": 0.35,
              "saturation": 0.7}


def faded_film(rgb: np.ndarray) -> np.ndarray:
    """Faded print: mild S-curve, lifted blue-green blacks, cream highlights, less colour."""
    p = FADED_FILM
    x = np.clip(rgb, 0.0, 1.0)
    curved = (1.0 - p["curve"]) * x + p["curve"] * smoothstep(x)
    black, white = np.asarray(p["black"]), np.asarray(p["white"])
    out = black + (white - black) * curved
    return np.clip(saturate(out, p["saturation"]), 0.0, 1.0)


# --------------------------------------------------------------------------- held-out looks

COOL_MATTE = {"slope": (0.92, 0.98, 1.08), "offset": (0.045, 0.05, 0.065),
              "power": (1.08, 1.04, 0.95), "saturation": 0.8}


def cool_matte(rgb: np.ndarray) -> np.ndarray:
    """A cool ASC CDL grade with matte (lifted) blacks and less colour."""
    return asc_cdl(rgb, **COOL_MATTE)


CROSS_PROCESS = {"red_contrast": 0.6, "green_gamma": 0.85, "blue_black": 0.12,
                 "blue_white": 0.8, "saturation": 1.1}


def cross_process(rgb: np.ndarray) -> np.ndarray:
    """Cross-processed slide film: a hard red S-curve, brighter greens, blue with lifted
    blacks and held-down whites (yellow-green highlights, blue shadows)."""
    p = CROSS_PROCESS
    x = np.clip(rgb, 0.0, 1.0)
    red = (1.0 - p["red_contrast"]) * x[..., 0] + p["red_contrast"] * smoothstep(x[..., 0])
    green = x[..., 1] ** p["green_gamma"]
    blue = p["blue_black"] + (p["blue_white"] - p["blue_black"]) * x[..., 2]
    out = np.stack([red, green, blue], axis=-1)
    return np.clip(saturate(out, p["saturation"]), 0.0, 1.0)


SEPIA = {"saturation": 0.15, "shadow": (0.95, 0.9, 0.8), "highlight": (1.05, 0.98, 0.86),
         "mix": 0.85}


def sepia(rgb: np.ndarray) -> np.ndarray:
    """Sepia toning: nearly monochrome, brown shadows, cream highlights, a trace of colour."""
    p = SEPIA
    y = rec709_luma(rgb)[..., None]
    tint = np.asarray(p["shadow"]) + (np.asarray(p["highlight"]) - np.asarray(p["shadow"])) * y
    toned = y * tint
    out = p["mix"] * toned + (1.0 - p["mix"]) * saturate(rgb, p["saturation"])
    return np.clip(out, 0.0, 1.0)


DAY_FOR_NIGHT = {"exposure": 0.55, "gamma": 1.15, "tint": (0.8, 0.95, 1.25), "saturation": 0.5}


def day_for_night(rgb: np.ndarray) -> np.ndarray:
    """Day for night: darker, more contrast in the mids, blue moonlight, little colour."""
    p = DAY_FOR_NIGHT
    x = np.clip(rgb, 0.0, 1.0) ** p["gamma"] * p["exposure"]
    out = saturate(x, p["saturation"]) * np.asarray(p["tint"])
    return np.clip(out, 0.0, 1.0)


PASTEL = {"lift": 0.12, "gain": 0.95, "tint": (1.02, 0.97, 1.03), "saturation": 0.75}


def pastel(rgb: np.ndarray) -> np.ndarray:
    """Pastel high key: lifted, low contrast, a faint magenta cast, softer colour."""
    p = PASTEL
    x = p["lift"] + (p["gain"] - p["lift"]) * np.clip(rgb, 0.0, 1.0)
    out = saturate(x * np.asarray(p["tint"]), p["saturation"])
    return np.clip(out, 0.0, 1.0)


# --------------------------------------------------------------------------- shipped LMTs


# Photographers' looks of the kinds sold as presets (``--looks photographer``): defined
# here with their own formulas, not with the library's generator of edits
# (wbcgrade/color/look/edits.py), from which the grade's prior over looks is learned.
PHOTOGRAPHER = {
    "muted-cool": {"saturation": 0.45, "contrast": 1.25, "shadow": (-0.05, 0.01, 0.06)},
    "faded-warm": {"black": 0.09, "white": 0.93, "warm": (1.06, 1.0, 0.9), "saturation": 0.8},
    "punchy": {"contrast": 1.35, "saturation": 1.4},
    "split-tone": {"shadow": (-0.07, 0.02, 0.07), "highlight": (0.07, 0.01, -0.07),
                   "contrast": 1.1},
}


def _linear_contrast(rgb: np.ndarray, amount: float) -> np.ndarray:
    """Contrast about mid grey on luma, chroma kept."""
    luma = rec709_luma(rgb)[..., None]
    return np.clip(rgb + (amount - 1.0) * (luma - 0.5), 0.0, 1.0)


def _split(rgb: np.ndarray, shadow, highlight) -> np.ndarray:
    luma = rec709_luma(rgb)[..., None]
    dark = smoothstep(np.clip(1.0 - 2.0 * luma, 0.0, 1.0))
    bright = smoothstep(np.clip(2.0 * luma - 1.0, 0.0, 1.0))
    return np.clip(rgb + dark * np.asarray(shadow) + bright * np.asarray(highlight), 0.0, 1.0)


def muted_cool(rgb: np.ndarray) -> np.ndarray:
    """Muted and cool: colour at 0.45, contrast x1.25, teal shadows."""
    p = PHOTOGRAPHER["muted-cool"]
    out = saturate(_linear_contrast(rgb, p["contrast"]), p["saturation"])
    return _split(out, p["shadow"], (0.0, 0.0, 0.0))


def faded_warm(rgb: np.ndarray) -> np.ndarray:
    """Faded and warm: lifted blacks, lowered whites, warm balance, less colour."""
    p = PHOTOGRAPHER["faded-warm"]
    out = np.clip(np.asarray(rgb, np.float64) * np.asarray(p["warm"]), 0.0, 1.0)
    out = saturate(out, p["saturation"])
    return np.clip(p["black"] + (p["white"] - p["black"]) * out, 0.0, 1.0)


def punchy(rgb: np.ndarray) -> np.ndarray:
    """Punchy: more contrast and more colour."""
    p = PHOTOGRAPHER["punchy"]
    return saturate(_linear_contrast(rgb, p["contrast"]), p["saturation"])


def split_tone(rgb: np.ndarray) -> np.ndarray:
    """Split toning: teal shadows, orange highlights, a little contrast."""
    p = PHOTOGRAPHER["split-tone"]
    return _split(_linear_contrast(rgb, p["contrast"]), p["shadow"], p["highlight"])


def _package_file(package: str, relative: str) -> tuple[Path, str]:
    """(absolute path, version) of a data file inside an installed package."""
    import importlib
    from importlib.metadata import version

    distribution = {"colour": "colour-science"}.get(package, package)
    module = importlib.import_module(package.replace("-", "_"))
    path = Path(module.__file__).parent / relative
    if not path.is_file():
        raise SystemExit(f"{package} has no {relative} (pip install {distribution})")
    return path, version(distribution)


@functools.cache
def _ocio_processor(package: str, relative: str):
    import PyOpenColorIO as ocio

    path, _ = _package_file(package, relative)
    config = ocio.Config.CreateFromFile("ocio://default")
    group = ocio.GroupTransform()
    group.appendTransform(ocio.ColorSpaceTransform(src=SRGB, dst=ACES))
    group.appendTransform(ocio.FileTransform(src=str(path), interpolation=ocio.INTERP_BEST))
    group.appendTransform(ocio.ColorSpaceTransform(src=ACES, dst=SRGB))
    return config.getProcessor(group).getDefaultCPUProcessor()


@functools.cache
def _ocio_file_processor(package: str, relative: str):
    """A LUT file applied to sRGB-encoded values as they are (a LUT made for them)."""
    import PyOpenColorIO as ocio

    path, _ = _package_file(package, relative)
    config = ocio.Config.CreateFromFile("ocio://default")
    transform = ocio.FileTransform(src=str(path), interpolation=ocio.INTERP_BEST)
    return config.getProcessor(transform).getDefaultCPUProcessor()


def ocio_look(package: str, relative: str, through_aces: bool = True):
    """A look applying a CLF / .cube file inside ``package``: between sRGB and
    ACES2065-1 (an LMT), or ``through_aces`` False on the sRGB-encoded values."""

    def apply(rgb: np.ndarray) -> np.ndarray:
        pixels = np.ascontiguousarray(rgb, dtype=np.float32).copy()
        processor = (_ocio_processor if through_aces else _ocio_file_processor)(package,
                                                                                 relative)
        processor.applyRGB(pixels)
        return np.clip(pixels.astype(np.float64), 0.0, 1.0)

    return apply


def _shipped(name: str, package: str, relative: str, description: str,
             through_aces: bool = True) -> Look:
    def source() -> dict:
        import PyOpenColorIO as ocio

        try:
            _, pkg_version = _package_file(package, relative)
        except SystemExit:
            pkg_version = "not installed"
        config = ocio.Config.CreateFromFile("ocio://default").getName()
        way = (f"ocio://default ({config}): {SRGB} -> {ACES} -> file -> {SRGB}"
               if through_aces else "on the sRGB-encoded values")
        return {"package": package, "version": pkg_version, "path": relative,
                "applied_with": f"PyOpenColorIO {ocio.__version__} FileTransform; "
                                f"{way}; clipped to [0, 1]"}

    return Look(name, ocio_look(package, relative, through_aces), description, source)


#: Real film looks (Hald CLUTs of the RawTherapee Film Simulation Collection, CC BY-SA
#: 4.0), kept beside the clone in ``../shared/data/looks`` (development material, never
#: shipped): file stem -> look name.
FILM_FOLDER = Path(__file__).resolve().parents[2] / "shared" / "data" / "looks"
_FILM_FILES = {
    "velvia": "fuji_velvia_50", "provia": "fuji_provia_100f", "fuji-400h": "fuji_400h",
    "ektar": "kodak_ektar_100", "portra-160nc": "kodak_portra_160_nc",
    "elite-chrome": "kodak_elite_chrome_200", "precisa": "agfa_precisa_100",
    "polachrome": "polaroid_polachrome", "redscale": "lomography_redscale_100",
    "bleach-bypass-2": "bleach_bypass_2", "smokey": "smokey", "crisp-winter": "crisp_winter",
    "late-sunset": "late_sunset", "night-from-day": "night_from_day",
    "tri-x": "kodak_tri_x_400", "delta-100": "ilford_delta_100",
}


@functools.cache
def _hald_lattice(stem: str) -> np.ndarray:
    """A level-8 Hald CLUT as a (64, 64, 64, 3) float64 lattice indexed [b, g, r]."""
    import OpenImageIO as oiio

    path = FILM_FOLDER / f"{stem}.png"
    buf = oiio.ImageBuf(str(path))
    if buf.has_error or buf.spec().width != 512:
        raise SystemExit(f"cannot read the film look {path} (a clone beside ../shared?)")
    return buf.get_pixels(oiio.FLOAT)[..., :3].astype(np.float64).reshape(64, 64, 64, 3)


def hald_look(stem: str):
    """A film look from its Hald CLUT, applied trilinearly to the sRGB-encoded values."""

    def apply(rgb: np.ndarray) -> np.ndarray:
        from scipy import ndimage

        lattice = _hald_lattice(stem)
        pos = np.clip(np.asarray(rgb, np.float64), 0.0, 1.0).reshape(-1, 3) * 63.0
        coords = np.stack([pos[:, 2], pos[:, 1], pos[:, 0]])  # [b, g, r]
        out = np.stack([ndimage.map_coordinates(lattice[..., c], coords, order=1,
                                                mode="nearest") for c in range(3)], axis=-1)
        return np.clip(out, 0.0, 1.0).reshape(np.shape(rgb))

    return apply


def _film(name: str) -> Look:
    stem = _FILM_FILES[name]
    return Look(name, hald_look(stem), f"film look: {stem} (RawTherapee Film Simulation "
                "Collection, CC BY-SA 4.0, Hald CLUT level 8)",
                lambda: {"file": f"../shared/data/looks/{stem}.png",
                         "collection": "RawTherapee Film Simulation Collection 2015-09-20",
                         "licence": "CC BY-SA 4.0", "applied_with": "trilinear, sRGB-encoded"})


def _defined_here(name: str, apply, description: str, params: dict) -> Look:
    return Look(name, apply, description, lambda: {"defined_in": "benchmarks/_looks.py",
                                                    **params})


LOOKS: dict[str, Look] = {
    look.name: look for look in [
        _shipped("kodak2383", "colour-clf-io",
                 "tests/resources/LMT Kodak 2383 Print Emulation.xml",
                 "ACES LMT: Kodak 2383 print film emulation (Blackmagic, CLF)"),
        _shipped("arri-k1s1", "colour-clf-io",
                 "tests/resources/LMT_ARRI_K1S1_709_EI800_v3.xml",
                 "ACES LMT: ARRI K1S1 Rec.709 look at EI 800 (CLF)"),
        _defined_here("cdl-warm", cdl_warm, "ASC CDL: warm, slightly muted",
                      CDL_WARM),
        _defined_here("teal-orange", teal_orange, "split toning: teal shadows, orange highlights",
                      TEAL_ORANGE),
        _defined_here("bleach-bypass", bleach_bypass, "bleach bypass: luma overlay, desaturated",
                      BLEACH_BYPASS),
        _defined_here("faded-film", faded_film, "faded print: lifted tinted blacks, cream whites",
                      FADED_FILM),
        # held out: no default was chosen on these
        _shipped("colour-correct", "colour",
                 "io/luts/tests/resources/resolve_cube/Colour_Correct.cube",
                 "a colour-correction 3D LUT (Resolve .cube, colour-science's resources)",
                 through_aces=False),
        _defined_here("cool-matte", cool_matte, "ASC CDL: cool, matte blacks, muted",
                      COOL_MATTE),
        _defined_here("cross-process", cross_process,
                      "cross-processed film: red S-curve, bright greens, lifted blue blacks",
                      CROSS_PROCESS),
        _defined_here("sepia", sepia, "sepia toning: near monochrome, brown to cream", SEPIA),
        _defined_here("day-for-night", day_for_night, "day for night: dark, blue, desaturated",
                      DAY_FOR_NIGHT),
        _defined_here("pastel", pastel, "pastel high key: lifted, low contrast, soft colour",
                      PASTEL),
        # photographers' looks
        _defined_here("muted-cool", muted_cool, "muted, cool, teal shadows",
                      PHOTOGRAPHER["muted-cool"]),
        _defined_here("faded-warm", faded_warm, "faded and warm", PHOTOGRAPHER["faded-warm"]),
        _defined_here("punchy", punchy, "more contrast and colour", PHOTOGRAPHER["punchy"]),
        _defined_here("split-tone", split_tone, "teal shadows, orange highlights",
                      PHOTOGRAPHER["split-tone"]),
        # real film looks (Hald CLUTs)
        *[_film(name) for name in _FILM_FILES],
    ]
}

#: The looks the defaults were chosen on (the benchmark's default set).
TUNED_LOOKS = ["kodak2383", "arri-k1s1", "cdl-warm", "teal-orange", "bleach-bypass",
               "faded-film"]
#: The real film looks (``--looks film``); two are black and white.
FILM_LOOKS = list(_FILM_FILES)
#: Film looks no setting was chosen on (``--looks film-held-out``): one black and white
#: film, two colour negative stocks, an instant film, a redscale and a creative look.
FILM_HELD_OUT_LOOKS = ["portra-160nc", "fuji-400h", "polachrome", "redscale", "smokey",
                       "delta-100"]
#: Film looks settings may be chosen on (``--looks film-tuned``).
FILM_TUNED_LOOKS = [name for name in FILM_LOOKS if name not in FILM_HELD_OUT_LOOKS]
#: Photographers' looks (``--looks photographer``): no setting was chosen on them.
PHOTOGRAPHER_LOOKS = list(PHOTOGRAPHER)
#: Looks whose output is black and white.
MONOCHROME_LOOKS = ["tri-x", "delta-100"]
#: Looks no default was chosen on (``--looks held-out``; the film looks apart).
HELD_OUT_LOOKS = [name for name in LOOKS if name not in TUNED_LOOKS and name not in FILM_LOOKS
                  and name not in PHOTOGRAPHER_LOOKS]
