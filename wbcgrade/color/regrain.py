"""Regrain: give the graded colours back the input's grain, edges and texture.

A colour map moves every pixel of one colour the same way, so wherever it
stretches a narrow range of colours (a sky, a dark forest) it multiplies the
sensor noise and the JPEG block steps by its local gain. Pitié, Kokaram and
Dahyot (2007) fix this in the image domain: keep the input's gradients while
taking the graded colours. This module does it with an edge-aware local
linear model (the guided filter of He, Sun and Tang 2010, with the input as
guide): in every window of radius r the change ``graded - input`` is
replaced by its best affine function of the input colour,

    out = input + A(x) input + b(x)

with ``A = (Cov(I) + eps Id)^-1 Cov(I, d)`` and ``b`` the matching offset,
averaged over the windows that hold each pixel. Where the input only varies
by noise (variance << eps), ``A -> 0`` and the window gets the mean change:
the grain keeps its input amplitude and no block or speckle is amplified.
Where the input has real structure, ``A`` reproduces the map's local
contrast, so edges and the style's contrast survive without halos (the
model follows the input's colour edges); across edges fainter than about
sqrt(eps) the change is blended over one window. Large images are solved on a
subsampled copy and ``A, b`` are interpolated back (the fast guided filter,
He and Sun 2015), so 16 megapixels cost about one pass over the pixels.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy import ndimage

from wbcgrade.color.options import DEFAULT_REGRAIN_EPS, DEFAULT_REGRAIN_RADIUS
from wbcgrade.color.remap import apply_color_map, block_means_mapped
from wbcgrade.core._jit import compiled

__all__ = ["regrain", "regrain_map", "DEFAULT_REGRAIN_RADIUS", "DEFAULT_REGRAIN_EPS"]

#: Coefficients are solved on at most this many pixels and interpolated back.
_MAX_SOLVE_PIXELS = 1_500_000


def _box(x: np.ndarray, radius: int) -> np.ndarray:
    return ndimage.uniform_filter(x, size=(2 * radius + 1, 2 * radius + 1), mode="reflect")


def _coefficients(guide: np.ndarray, change: np.ndarray, radius: int,
                  eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Box-averaged (H, W, 3, 3) A and (H, W, 3) b of the local model change = A^T guide + b."""
    h, w = guide.shape[:2]
    mean_i = np.stack([_box(guide[..., c], radius) for c in range(3)], axis=-1)
    mean_d = np.stack([_box(change[..., c], radius) for c in range(3)], axis=-1)
    # Symmetric 3x3 covariance of the guide (+ eps), inverted in closed form.
    def cov(a, c, x, mean_x):
        return _box(guide[..., a] * x[..., c], radius) - mean_i[..., a] * mean_x[..., c]

    s00, s01, s02 = cov(0, 0, guide, mean_i) + eps, cov(0, 1, guide, mean_i), \
        cov(0, 2, guide, mean_i)
    s11, s12, s22 = cov(1, 1, guide, mean_i) + eps, cov(1, 2, guide, mean_i), \
        cov(2, 2, guide, mean_i) + eps
    i00, i01, i02 = s11 * s22 - s12 * s12, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
    i11, i12, i22 = s00 * s22 - s02 * s02, s01 * s02 - s00 * s12, s00 * s11 - s01 * s01
    det = s00 * i00 + s01 * i01 + s02 * i02
    inverse = [[i00, i01, i02], [i01, i11, i12], [i02, i12, i22]]
    cross = [[cov(a, c, change, mean_d) for c in range(3)] for a in range(3)]
    A = np.empty((h, w, 3, 3), np.float32)
    for a in range(3):
        for c in range(3):
            A[..., a, c] = (inverse[a][0] * cross[0][c] + inverse[a][1] * cross[1][c]
                            + inverse[a][2] * cross[2][c]) / det
    b = mean_d - np.einsum("hwac,hwa->hwc", A, mean_i)
    for a in range(3):
        for c in range(3):
            A[..., a, c] = _box(A[..., a, c], radius)
    b = np.stack([_box(b[..., c], radius) for c in range(3)], axis=-1)
    return A, b


@compiled(parallel=True, cache=True)
def _apply_upsampled(source: np.ndarray, A: np.ndarray, b: np.ndarray, step: float,
                     out: np.ndarray) -> None:
    """``out = clip(source + A(x)^T source + b(x))`` with ``A, b`` bilinearly interpolated
    from the coarse grid: each output row first blends its two coarse rows (12
    coefficients a node), then each pixel blends two nodes of that row."""
    h, w = source.shape[:2]
    lh, lw = A.shape[:2]
    for y in numba.prange(h):
        fy = min(max((y + 0.5) / step - 0.5, 0.0), lh - 1.0)
        y0 = min(int(fy), lh - 2) if lh > 1 else 0
        ty = fy - y0
        y1 = min(y0 + 1, lh - 1)
        row = np.empty((lw, 12))  # this output row's coefficients at the coarse columns
        for x in range(lw):
            for a in range(3):
                for c in range(3):
                    row[x, 3 * a + c] = (1 - ty) * A[y0, x, a, c] + ty * A[y1, x, a, c]
            for c in range(3):
                row[x, 9 + c] = (1 - ty) * b[y0, x, c] + ty * b[y1, x, c]
        for x in range(w):
            fx = min(max((x + 0.5) / step - 0.5, 0.0), lw - 1.0)
            x0 = min(int(fx), lw - 2) if lw > 1 else 0
            tx = fx - x0
            x1 = min(x0 + 1, lw - 1)
            s0 = source[y, x, 0]
            s1 = source[y, x, 1]
            s2 = source[y, x, 2]
            for c in range(3):
                value = source[y, x, c] + (1 - tx) * row[x0, 9 + c] + tx * row[x1, 9 + c]
                value += ((1 - tx) * row[x0, c] + tx * row[x1, c]) * s0
                value += ((1 - tx) * row[x0, 3 + c] + tx * row[x1, 3 + c]) * s1
                value += ((1 - tx) * row[x0, 6 + c] + tx * row[x1, 6 + c]) * s2
                out[y, x, c] = min(max(value, 0.0), 1.0)


@compiled(parallel=True, cache=True)
def _downsample(x: np.ndarray, step: int) -> np.ndarray:
    """Mean of every step x step block of an (H, W, C) image (partial edge blocks dropped)."""
    h, w, c = x.shape[0] // step, x.shape[1] // step, x.shape[2]
    out = np.zeros((h, w, c), np.float32)
    scale = 1.0 / (step * step)
    for i in numba.prange(h):
        for di in range(step):
            row = i * step + di
            for j in range(w):
                for dj in range(step):
                    for k in range(c):
                        out[i, j, k] += x[row, j * step + dj, k]
        for j in range(w):
            for k in range(c):
                out[i, j, k] *= scale
    return out


def regrain(source: np.ndarray, graded: np.ndarray, radius: float = DEFAULT_REGRAIN_RADIUS,
            eps: float = DEFAULT_REGRAIN_EPS) -> np.ndarray:
    """Graded colours with the input's grain and edges (edge-aware local linear model).

    Parameters
    ----------
    source : (H, W, 3) input colours, encoded, in [0, 1].
    graded : (H, W, 3) the same pixels through the colour map.
    radius : window radius as a fraction of the long side (>= 1 pixel is used).
    eps : regulariser, squared encoded units (larger: more of the input's
        detail kept as is, less of the map's local contrast).

    Returns
    -------
    (H, W, 3) float32 in [0, 1].
    """
    if source.shape != graded.shape or source.ndim != 3 or source.shape[2] != 3:
        raise ValueError("source and graded must be the same (H, W, 3) shape")
    if not (radius > 0 and eps > 0):
        raise ValueError("radius and eps must be positive")
    h, w = source.shape[:2]
    source = np.ascontiguousarray(source, dtype=np.float32)
    graded = np.ascontiguousarray(graded, dtype=np.float32)
    step = _step(h, w)
    if step == 1:
        pixels = max(1, int(round(radius * max(h, w))))
        A, b = _coefficients(source, graded - source, pixels, eps)
        out = source + np.einsum("hwac,hwa->hwc", A, source) + b
        return np.clip(out, 0.0, 1.0)
    small = _downsample(source, step)
    change = _downsample(graded, step) - small
    return _regrain_upsampled(source, small, change, step, radius, eps)


def regrain_map(source: np.ndarray, color_map: np.ndarray, strength: float = 1.0,
                radius: float = DEFAULT_REGRAIN_RADIUS,
                eps: float = DEFAULT_REGRAIN_EPS) -> np.ndarray:
    """``regrain(source, apply_color_map(source, color_map, strength), radius, eps)``.

    The same numbers; on large images (solved on a subsampled copy) the
    graded image is only needed block-averaged, so the colour map and the
    block means are one pass (:func:`wbcgrade.color.remap.block_means_mapped`)
    and the full-size graded image is never made (a pass and ~12 bytes a
    pixel saved).
    """
    if source.ndim != 3 or source.shape[2] != 3:
        raise ValueError("source must be an (H, W, 3) image")
    if not (radius > 0 and eps > 0):
        raise ValueError("radius and eps must be positive")
    h, w = source.shape[:2]
    step = _step(h, w)
    if step == 1:
        return regrain(source, apply_color_map(source, color_map, strength), radius, eps)
    source = np.ascontiguousarray(source, dtype=np.float32)
    small = _downsample(source, step)
    change = block_means_mapped(source, color_map, strength, step) - small
    return _regrain_upsampled(source, small, change, step, radius, eps)


def _step(h: int, w: int) -> int:
    """Subsampling step of the coefficients' solve (1: full resolution)."""
    return max(1, int(np.ceil(np.sqrt(h * w / _MAX_SOLVE_PIXELS))))


def _regrain_upsampled(source: np.ndarray, small: np.ndarray, change: np.ndarray, step: int,
                       radius: float, eps: float) -> np.ndarray:
    h, w = source.shape[:2]
    pixels = max(1, int(round(radius * max(h, w) / step)))
    A, b = _coefficients(small, change, pixels, eps)
    out = np.empty_like(source)
    _apply_upsampled(source, np.ascontiguousarray(A), np.ascontiguousarray(b), float(step), out)
    return out
