"""Pictures of BRDFs: a sphere lit by one directional light, rendered with numpy.

``render_sphere`` shades an orthographic view of a unit sphere: for each pixel
with normal ``n`` the local frame is (t, b, n) with the tangent ``t`` along the
sphere's parallels (``t = normalize(y x n)``, so anisotropic highlights follow
the lines of latitude), the viewer looks along -z, and the radiance is
``f(l_local, v_local) * max(<n, l>, 0)`` for a unit-irradiance light from
``light``. Sampled BRDFs are evaluated with ``sampled.interpolate``.

``comparison_image`` tone-maps several renderings with one exposure (set by
the first, the reference), encodes them as sRGB, puts them side by side and
writes a caption under each with Pillow's built-in bitmap font (no caption is
drawn if Pillow is missing; the values are printed by the command anyway).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from wbcgrade import _publish
from wbcgrade.brdf.sampled import interpolate

DEFAULT_LIGHT = (-0.45, 0.55, 0.70)
"""Direction towards the light (world frame, viewer along +z): upper left, in front."""


def render_sphere(
    values: np.ndarray,
    directions: np.ndarray,
    size: int = 192,
    light: tuple[float, float, float] = DEFAULT_LIGHT,
) -> np.ndarray:
    """Linear RGB radiance of a sphere made of a sampled BRDF.

    Parameters
    ----------
    values : ndarray, shape (N, N, 3)
    directions : ndarray, shape (N, 3)
    size : int
        Image width and height in pixels.
    light : (3,) floats
        Direction towards the light in the world frame.

    Returns
    -------
    image : ndarray, shape (size, size, 3), float64
        Zero outside the sphere and where the light or the viewer is below the
        local horizon.
    """
    coordinates = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(coordinates, -coordinates)
    inside = x * x + y * y < 1.0
    normal = np.stack([x[inside], y[inside], np.sqrt(1.0 - x[inside] ** 2 - y[inside] ** 2)], -1)
    tangent = np.cross(np.array([0.0, 1.0, 0.0]), normal)
    length = np.linalg.norm(tangent, axis=-1, keepdims=True)
    tangent = np.where(length > 1e-9, tangent / np.maximum(length, 1e-12), [1.0, 0.0, 0.0])
    bitangent = np.cross(normal, tangent)
    to_light = np.asarray(light, dtype=np.float64)
    to_light = to_light / np.linalg.norm(to_light)
    to_viewer = np.array([0.0, 0.0, 1.0])

    def local(v: np.ndarray) -> np.ndarray:
        return np.stack([tangent @ v, bitangent @ v, normal @ v], -1)

    light_local, view_local = local(to_light), local(to_viewer)
    lit = (light_local[:, 2] > 0) & (view_local[:, 2] > 0)
    radiance = np.zeros((len(normal), 3))
    if lit.any():
        brdf = interpolate(values, directions, light_local[lit], view_local[lit])
        radiance[lit] = brdf * light_local[lit, 2:3]
    image = np.zeros((size, size, 3))
    image[inside] = radiance
    return image


def tone_map(image: np.ndarray, exposure: float) -> np.ndarray:
    """sRGB-encoded uint8 image from linear radiance times ``exposure`` (clipped to [0, 1]).

    Uses the IEC 61966-2-1 sRGB transfer function (as ``colour.cctf_encoding``).
    """
    linear = np.clip(np.asarray(image, dtype=np.float64) * exposure, 0.0, 1.0)
    encoded = np.where(linear <= 0.0031308, 12.92 * linear,
                       1.055 * np.power(linear, 1.0 / 2.4) - 0.055)
    return np.round(np.clip(encoded, 0.0, 1.0) * 255.0).astype(np.uint8)


def reference_exposure(image: np.ndarray, percentile: float = 99.0) -> float:
    """Exposure mapping the ``percentile`` of the lit pixels' maxima to 0.8."""
    peak = np.max(image, axis=-1)
    lit = peak[peak > 0]
    level = float(np.percentile(lit, percentile)) if lit.size else 1.0
    return 0.8 / level if level > 0 else 1.0


def _caption(panel: np.ndarray, lines: list[str]) -> np.ndarray:
    try:
        from PIL import Image, ImageDraw, ImageFont
    except ImportError:  # pragma: no cover - Pillow ships with scikit-image
        return panel
    picture = Image.fromarray(panel)
    draw = ImageDraw.Draw(picture)
    font = ImageFont.load_default()
    top = panel.shape[0] - 14 * len(lines) - 4
    for i, line in enumerate(lines):
        draw.text((4, top + 14 * i), line, fill=(235, 235, 235), font=font)
    return np.asarray(picture)


def comparison_image(
    renderings: list[np.ndarray], captions: list[list[str]], caption_lines: int = 4
) -> np.ndarray:
    """Renderings side by side with captions underneath.

    Parameters
    ----------
    renderings : list of ndarray, shape (H, W, 3)
        Linear radiance; the first (the reference) sets the exposure for all.
    captions : list of list of str
        Lines under each rendering.
    caption_lines : int
        Height of the caption band, in lines.

    Returns
    -------
    image : ndarray, shape (H + band, n * W, 3), uint8
    """
    exposure = reference_exposure(renderings[0])
    band = 14 * caption_lines + 8
    panels = []
    for image, lines in zip(renderings, captions, strict=True):
        height, width = image.shape[:2]
        y, x = np.mgrid[0:height, 0:width]
        outside = ((x + 0.5) / width * 2 - 1) ** 2 + ((y + 0.5) / height * 2 - 1) ** 2 >= 1.0
        panel = np.full((height + band, width, 3), 24, dtype=np.uint8)
        panel[:height] = tone_map(image, exposure)
        panel[:height][outside] = 56  # grey backdrop shows the unlit side's silhouette
        panels.append(_caption(panel, lines[:caption_lines]))
    return np.concatenate(panels, axis=1)


def write_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an 8-bit RGB image (H, W, 3) uint8 as PNG, atomically (``wbcgrade._publish``)."""
    return _publish.write_png(path, np.asarray(image, dtype=np.uint8))
