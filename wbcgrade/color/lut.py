"""Export a colour map as a 3-D LUT (.cube through colour-science, or CLF).

The written file is a standard Resolve/Adobe ``.cube`` (``LUT_3D_SIZE``,
domain [0, 1], red varying fastest), read by colour-science's ``read_LUT``,
DaVinci Resolve and ffmpeg's ``lut3d`` filter. Its input is the encoded
colour the grade works in: the working space (default sRGB-encoded
Rec.709: the pixel values of 8/16-bit sRGB photos; for float EXR input,
sRGB-encoded values of the linear pixels clipped to [0, 1]), and so is its
output. :func:`write_grade_lut` names both spaces and the OpenColorIO config
in the header comments. When the working space is logarithmic (ACEScct,
ACEScc) the ``.cube`` is Resolve's shaper form: a 1D shaper
(``LUT_1D_INPUT_RANGE``) takes the linear partner (ACEScg) into the working
space, then the 3D LUT grades; it expects linear ACEScg and produces
ACEScct. The CLF (Academy/ASC Common LUT Format, written by the
``opencolorio`` package: ``pip install 'wbcgrade[ocio]'``) holds the same
operators, its shaper a half-float-domain 1D LUT (exact at every half value).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from wbcgrade._publish import atomic_path
from wbcgrade.color.imageio import check_output_path
from wbcgrade.color.remap import apply_color_map, identity_map
from wbcgrade.errors import InputError

__all__ = ["color_map_to_lut", "write_cube", "read_cube", "write_grade_lut", "lut_header",
           "shaper_table", "check_lut_path", "check_clf_support", "DEFAULT_LUT_SIZE", "LUT_FORMATS",
           "SHAPER_SIZE"]

DEFAULT_LUT_SIZE = 33
#: ``--lut-format`` choices and the file name ending each needs.
LUT_FORMATS = {"cube": ".cube", "clf": ".clf"}
#: Entries of the ``.cube`` shaper (sampled evenly over its input range, as
#: Resolve reads it; see :func:`shaper_table` for its accuracy).
SHAPER_SIZE = 65536


def color_map_to_lut(color_map: np.ndarray, size: int = DEFAULT_LUT_SIZE,
                     strength: float = 1.0) -> np.ndarray:
    """Sample a colour map (n, n, n, 3) at a (size, size, size) grid -> (size, size, size, 3).

    The LUT entries are the map's trilinear interpolation at the LUT nodes
    (blended with the identity by ``strength``), so applying the LUT with
    trilinear interpolation approximates the grade to the LUT's resolution.
    """
    if not 2 <= size <= 256:
        raise InputError("LUT size must be between 2 and 256")
    nodes = identity_map(size)
    return np.clip(apply_color_map(nodes, color_map, strength), 0.0, 1.0)


def write_cube(path: str | os.PathLike, table: np.ndarray, title: str = "wbcgrade",
               comments: list[str] | None = None, overwrite: bool = False) -> Path:
    """Write a (size, size, size, 3) table, indexed [r, g, b], as a .cube file (atomically)."""
    from wbcgrade.color._colour import colour

    path = Path(path)
    if path.suffix.lower() != ".cube":
        raise InputError(f"{path}: LUT file name must end in .cube")
    check_output_path(path, overwrite=overwrite)
    lut = colour.LUT3D(table=np.asarray(table, dtype=np.float64), name=title,
                       domain=np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]),
                       size=table.shape[0], comments=comments or [])
    with atomic_path(path, suffix=".cube", overwrite=overwrite) as tmp:
        colour.write_LUT(lut, tmp, decimals=6, method="Resolve Cube")
    return path


def read_cube(path: str | os.PathLike):
    """Read a .cube file with colour-science (returns a ``colour.LUT3D``)."""
    from wbcgrade.color._colour import colour

    return colour.read_LUT(str(path))


def check_lut_path(path: str | os.PathLike, lut_format: str = "cube") -> Path:
    """``path`` as a Path when its ending suits ``lut_format`` (else InputError)."""
    path = Path(path)
    if lut_format not in LUT_FORMATS:
        raise InputError(f"--lut-format must be one of {', '.join(LUT_FORMATS)}")
    suffix = LUT_FORMATS[lut_format]
    if path.suffix.lower() != suffix:
        raise InputError(f"{path}: LUT file name must end in {suffix} (--lut-format "
                         f"{lut_format})")
    return path


def shaper_table(spaces, size: int = SHAPER_SIZE) -> tuple[np.ndarray, tuple[float, float]]:
    """The 1D shaper of a logarithmic working space, sampled for a ``.cube``.

    Returns ``(table (size,) float64, (low, high))``: ``table[i]`` is the
    working-space value of the linear grey ``low + i (high - low) / (size -
    1)``; ``low`` and ``high`` are the linear values the working space
    encodes as 0 and 1 (ACEScct: about -0.0069 and 222.9), so the shaper
    covers exactly the 3D LUT's input cube.
    """
    from wbcgrade.color.colorspace import convert

    high = float(spaces.peak)
    ramp = -np.geomspace(1e-6, 1.0, 2049)[::-1]  # the low end: the grey encoded as 0
    enc = convert(np.repeat(ramp[:, None], 3, axis=1), spaces.linear, spaces.working)[:, 0]
    below = np.flatnonzero(enc <= 0.0)
    low = float(ramp[below[-1]]) if len(below) else float(ramp[0])
    grey = np.linspace(low, high, size)
    table = convert(np.repeat(grey[:, None], 3, axis=1), spaces.linear, spaces.working)[:, 0]
    return np.clip(table.astype(np.float64), 0.0, 1.0), (low, high)


def lut_header(spaces, shaper: bool) -> list[str]:
    """Comment lines naming the spaces a LUT expects and produces, and the config."""
    from wbcgrade.color.colorspace import config_info

    info = config_info()
    expects = (f"{spaces.linear} (linear; the 1D shaper encodes it as {spaces.working})"
               if shaper else f"{spaces.working} (values in [0, 1])")
    return [f"input space: {expects}",
            f"output space: {spaces.working}",
            f"OpenColorIO config: {info['ocio_config']} (OpenColorIO {info['ocio_version']})"]


def write_grade_lut(path: str | os.PathLike, color_map: np.ndarray, spaces,
                    size: int = DEFAULT_LUT_SIZE, strength: float = 1.0,
                    lut_format: str = "cube", title: str = "wbcgrade",
                    comments: list[str] | None = None, overwrite: bool = False,
                    cube_writer=None) -> Path:
    """Write a grade's colour map as a LUT whose header names its spaces.

    Parameters
    ----------
    color_map : (m, m, m, 3) the grade's map (working-space colours).
    spaces : :class:`wbcgrade.color.colorspace.Spaces` of the grade.
    lut_format : "cube" (colour-science) or "clf" (the ``opencolorio`` package).
    cube_writer : what writes a plain ``.cube`` (default :func:`write_cube`).

    A logarithmic working space (ACEScct, ACEScc) gets a shaper: the LUT
    expects the linear partner (ACEScg) and produces the working space.
    """
    from wbcgrade.color.colorspace import is_logarithmic

    path = check_lut_path(path, lut_format)
    check_output_path(path, overwrite=overwrite)
    table = color_map_to_lut(color_map, size, strength)
    shaper = is_logarithmic(spaces.working)
    notes = list(comments or []) + lut_header(spaces, shaper)
    if lut_format == "clf":
        return _write_clf(path, table, spaces, shaper, title, notes, overwrite)
    if not shaper:
        return (cube_writer or write_cube)(path, table, title=title, comments=notes,
                                           overwrite=overwrite)
    from wbcgrade.color._colour import colour

    curve, (low, high) = shaper_table(spaces)
    sequence = colour.LUTSequence(
        colour.LUT3x1D(table=np.repeat(curve[:, None], 3, axis=1), name=title,
                       domain=np.array([[low] * 3, [high] * 3]), comments=notes),
        colour.LUT3D(table=np.asarray(table, dtype=np.float64), name="grade",
                     domain=np.array([[0.0] * 3, [1.0] * 3]), size=table.shape[0]))
    with atomic_path(path, suffix=".cube", overwrite=overwrite) as tmp:
        colour.write_LUT(sequence, tmp, decimals=7, method="Resolve Cube")
    return path


def check_clf_support():
    """The ``PyOpenColorIO`` module, or InputError saying how to install it."""
    try:
        import PyOpenColorIO as ocio
    except ImportError:
        raise InputError("--lut-format clf needs the opencolorio package: "
                         "pip install 'wbcgrade[ocio]' (or: pip install opencolorio)") from None
    return ocio


def _write_clf(path: Path, table: np.ndarray, spaces, shaper: bool, title: str,
               notes: list[str], overwrite: bool) -> Path:
    ocio = check_clf_support()
    from wbcgrade.color.colorspace import convert

    group = ocio.GroupTransform()
    metadata = group.getFormatMetadata()
    metadata.setName(title)
    metadata.setID(title)
    for note in notes:
        metadata.addChildElement("Description", note)
    if shaper:  # every half-float value: exact wherever a half is
        halves = np.arange(65536, dtype=np.uint16).view(np.float16).astype(np.float32)
        finite = np.isfinite(halves)
        values = np.zeros(65536, dtype=np.float32)
        values[finite] = convert(np.repeat(halves[finite, None], 3, axis=1), spaces.linear,
                                 spaces.working)[:, 0]
        values[~finite & (halves > 0)] = values[finite].max()
        values[~finite & ~(halves > 0)] = values[finite].min()
        curve = ocio.Lut1DTransform()
        curve.setInputHalfDomain(True)
        curve.setLength(65536)
        curve.setData(np.ascontiguousarray(np.repeat(values[:, None], 3, axis=1)).ravel())
        group.appendTransform(curve)
    size = table.shape[0]
    cube = ocio.Lut3DTransform()
    cube.setGridSize(size)
    # OpenColorIO orders 3D LUT entries with blue varying fastest: [r, g, b] in C order.
    cube.setData(np.ascontiguousarray(table, dtype=np.float32).ravel())
    group.appendTransform(cube)
    text = group.write(formatName="Academy/ASC Common LUT Format",
                       config=ocio.Config.CreateRaw())
    with atomic_path(path, suffix=".clf", overwrite=overwrite) as tmp, \
            open(tmp, "w", encoding="utf-8") as handle:
        handle.write(text)
    return path
