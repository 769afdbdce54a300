"""Export a colour map as a 3-D LUT (.cube) through colour-science.

The written file is a standard Resolve/Adobe ``.cube`` (``LUT_3D_SIZE``,
domain [0, 1], red varying fastest), read by colour-science's ``read_LUT``,
DaVinci Resolve and ffmpeg's ``lut3d`` filter. Its input is the encoded
colour the grade works in (the pixel values of 8/16-bit photos; for float
EXR input, sRGB-encoded values of the linear pixels clipped to [0, 1]).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from wbcgrade._publish import atomic_path
from wbcgrade.color.imageio import check_output_path
from wbcgrade.color.remap import apply_color_map, identity_map
from wbcgrade.errors import InputError

__all__ = ["color_map_to_lut", "write_cube", "read_cube", "DEFAULT_LUT_SIZE"]

DEFAULT_LUT_SIZE = 33


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
