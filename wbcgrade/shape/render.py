"""Pictures of volumes with numpy only: shaded depth renders and intensity projections.

Shapes are drawn as the surface ``{volume > level}`` seen along a grid axis
(orthographic ray casting on the voxel grid, sub-voxel depth by linear
interpolation, Lambertian shading from the depth map's normals). Volumes
such as MRIs are drawn as maximum-intensity projections. A contact sheet puts
one column per volume and one row per view, with a label above each column.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, replace

import numpy as np

from wbcgrade import _publish
from wbcgrade.errors import InputError

log = logging.getLogger(__name__)

VIEWS = ((2, "side"), (0, "front"), (1, "top"))
"""(axis looked along, name): x to the right and y up in the side view."""

_LIGHT = np.array([-0.4, 0.5, 0.77])
_LIGHT = _LIGHT / np.linalg.norm(_LIGHT)


@dataclass(frozen=True)
class Panel:
    """One column of a contact sheet.

    volume : (X, Y, Z) array.
    label : text drawn above the column.
    level : iso-level for a surface render; None draws a maximum-intensity projection.
    color : RGB in [0, 1] of the lit surface.
    highlight : optional (X, Y, Z) bool mask; surface points inside it are
        drawn in ``highlight_color``.
    highlight_color : RGB in [0, 1] of the highlighted surface (default red).
    """

    volume: np.ndarray
    label: str
    level: float | None = None
    color: tuple[float, float, float] = (0.85, 0.85, 0.85)
    highlight: np.ndarray | None = None
    highlight_color: tuple[float, float, float] = (0.95, 0.3, 0.25)


def _view(volume: np.ndarray, axis: int) -> np.ndarray:
    """Volume reoriented so the view ray runs along axis 0 and the image is (rows, cols).

    Rows go top to bottom (the image's vertical axis points up in the world).
    """
    if axis == 2:  # look along -z: x right, y up
        view = np.transpose(volume, (2, 1, 0))[::-1, ::-1, :]
    elif axis == 0:  # look along +x: z right, y up
        view = volume[:, ::-1, :]
    else:  # look down -y: x right, z down
        view = np.transpose(volume, (1, 2, 0))[::-1, :, :]
    return view


def render_surface(
    volume: np.ndarray,
    level: float,
    axis: int,
    color=(0.85, 0.85, 0.85),
    highlight: np.ndarray | None = None,
    highlight_color=(0.95, 0.3, 0.25),
) -> np.ndarray:
    """Shaded render of ``{volume > level}`` looking along ``axis``; surface points
    inside the ``highlight`` mask are drawn in ``highlight_color``.

    Returns
    -------
    (H, W, 3) float32 RGB image in [0, 1] (background black).
    """
    view = _view(np.asarray(volume, dtype=np.float64), axis)
    mask = view > level
    hit = mask.any(axis=0)
    first = np.argmax(mask, axis=0)  # first voxel above level along the ray
    rows, cols = np.indices(first.shape)
    value_in = view[first, rows, cols]
    value_out = view[np.maximum(first - 1, 0), rows, cols]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(first > 0, (value_in - level) / (value_in - value_out), 0.0)
    depth = first - np.clip(np.nan_to_num(frac), 0.0, 1.0)
    depth = np.where(hit, depth, depth[hit].max() + 1.0 if hit.any() else 0.0)
    grad_r, grad_c = np.gradient(depth)
    normal = np.stack([grad_c, -grad_r, np.ones_like(depth)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    # Light in (right, up, towards viewer) coordinates.
    shade = 0.25 + 0.75 * np.clip(normal @ np.array([_LIGHT[0], _LIGHT[1], _LIGHT[2]]), 0, 1)
    span = max(float(np.ptp(depth[hit])), 1.0) if hit.any() else 1.0
    fog = 1.0 - 0.35 * (depth - (depth[hit].min() if hit.any() else 0.0)) / span
    intensity = np.where(hit, shade * fog, 0.0)
    rgb = intensity[..., None] * np.asarray(color, dtype=np.float64)
    if highlight is not None:
        marked = _view(np.asarray(highlight, bool), axis)[first, rows, cols] & hit
        rgb[marked] = intensity[marked, None] * np.asarray(highlight_color, dtype=np.float64)
    return np.clip(rgb, 0, 1).astype(np.float32)


def render_projection(volume: np.ndarray, axis: int) -> np.ndarray:
    """Maximum-intensity projection along ``axis``, (H, W, 3) float32 in [0, 1]."""
    view = _view(np.asarray(volume, dtype=np.float64), axis)
    image = view.max(axis=0)
    peak = float(image.max())
    image = image / peak if peak > 0 else image
    return np.repeat(image[..., None], 3, axis=-1).astype(np.float32)


def contact_sheet(panels: list[Panel], tile: int = 160) -> np.ndarray:
    """One column per panel, one row per view in :data:`VIEWS`, labels on top.

    Returns
    -------
    (H, W, 3) float32 RGB image in [0, 1].
    """
    from skimage.transform import resize

    if not panels:
        raise InputError("nothing to render")
    panels = _crop_to_content(panels)
    label_height = 22
    gap = 4
    n_cols, n_rows = len(panels), len(VIEWS)
    height = label_height + n_rows * (tile + gap) + gap
    width = n_cols * (tile + gap) + gap
    sheet = np.full((height, width, 3), 0.12, dtype=np.float32)
    for column, panel in enumerate(panels):
        x0 = gap + column * (tile + gap)
        for row, (axis, _) in enumerate(VIEWS):
            if panel.level is None:
                image = render_projection(panel.volume, axis)
            else:
                image = render_surface(
                    panel.volume, panel.level, axis, panel.color, panel.highlight,
                    panel.highlight_color,
                )
            scale = tile / max(image.shape[:2])
            shape = (max(1, round(image.shape[0] * scale)), max(1, round(image.shape[1] * scale)))
            image = resize(image, (*shape, 3), order=1, anti_aliasing=False)
            y0 = label_height + gap + row * (tile + gap) + (tile - shape[0]) // 2
            xx = x0 + (tile - shape[1]) // 2
            sheet[y0 : y0 + shape[0], xx : xx + shape[1]] = image
    labels = [(gap + c * (tile + gap) + 2, p.label) for c, p in enumerate(panels)]
    return _draw_labels(sheet, labels)


def _crop_to_content(panels: list[Panel], pad: int = 2) -> list[Panel]:
    """Crop panels to the union of their drawn content, so the views fill the tiles.

    Panels whose volumes have the same shape (one frame) are cropped to one
    box, so they keep their relative size and position.
    """
    cropped = list(panels)
    for shape in {np.shape(p.volume) for p in panels}:
        group = [i for i, p in enumerate(panels) if np.shape(p.volume) == shape]
        lo, hi = np.array(shape), np.zeros(3, dtype=int)
        for i in group:
            panel = panels[i]
            volume = np.asarray(panel.volume)
            threshold = panel.level if panel.level is not None else 0.02 * float(volume.max())
            occupied = np.argwhere(volume > threshold)
            if occupied.size:
                lo = np.minimum(lo, occupied.min(axis=0))
                hi = np.maximum(hi, occupied.max(axis=0) + 1)
        if np.any(hi <= lo):
            continue
        lo, hi = np.maximum(lo - pad, 0), np.minimum(hi + pad, np.array(shape))
        box = tuple(slice(int(a), int(b)) for a, b in zip(lo, hi, strict=True))
        for i in group:
            p = panels[i]
            cropped[i] = replace(
                p, volume=np.asarray(p.volume)[box],
                highlight=None if p.highlight is None else np.asarray(p.highlight)[box])
    return cropped


def _draw_labels(sheet: np.ndarray, labels: list[tuple[int, str]]) -> np.ndarray:
    """Draw text labels along the top with OpenImageIO's default font (skipped if absent)."""
    import OpenImageIO as oiio

    height, width = sheet.shape[:2]
    buf = oiio.ImageBuf(oiio.ImageSpec(width, height, 3, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(0, width, 0, height, 0, 1, 0, 3), np.ascontiguousarray(sheet))
    for x, text in labels:
        if not oiio.ImageBufAlgo.render_text(buf, x, 16, text, 13, "", (1.0, 1.0, 1.0)):
            log.info("labels not drawn: %s", buf.geterror())
            return sheet
    return np.asarray(buf.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(height, width, 3)


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W, 3) float image in [0, 1] as an 8-bit PNG, atomically.

    See :func:`wbcgrade._publish.write_png`.
    """
    _publish.write_png(path, np.asarray(image, dtype=np.float64))
