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
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Look", "LOOKS", "asc_cdl", "rec709_luma"]

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


# --------------------------------------------------------------------------- shipped LMTs


def _package_file(package: str, relative: str) -> tuple[Path, str]:
    """(absolute path, version) of a data file inside an installed package."""
    import importlib
    from importlib.metadata import version

    module = importlib.import_module(package.replace("-", "_"))
    path = Path(module.__file__).parent / relative
    if not path.is_file():
        raise SystemExit(f"{package} has no {relative} (pip install {package})")
    return path, version(package)


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


def ocio_look(package: str, relative: str):
    """A look applying a CLF / .cube file inside ``package`` between sRGB and ACES2065-1."""

    def apply(rgb: np.ndarray) -> np.ndarray:
        pixels = np.ascontiguousarray(rgb, dtype=np.float32).copy()
        _ocio_processor(package, relative).applyRGB(pixels)
        return np.clip(pixels.astype(np.float64), 0.0, 1.0)

    return apply


def _shipped(name: str, package: str, relative: str, description: str) -> Look:
    def source() -> dict:
        import PyOpenColorIO as ocio

        try:
            _, pkg_version = _package_file(package, relative)
        except SystemExit:
            pkg_version = "not installed"
        config = ocio.Config.CreateFromFile("ocio://default").getName()
        return {"package": package, "version": pkg_version, "path": relative,
                "applied_with": f"PyOpenColorIO {ocio.__version__} FileTransform; "
                                f"ocio://default ({config}): {SRGB} -> {ACES} -> file -> "
                                f"{SRGB}; clipped to [0, 1]"}

    return Look(name, ocio_look(package, relative), description, source)


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
    ]
}
