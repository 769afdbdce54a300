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

from wbcgrade.color.remap import apply_color_map, block_means_mapped
from wbcgrade.core._jit import compiled

__all__ = ["regrain", "regrain_map", "DEFAULT_REGRAIN_RADIUS", "DEFAULT_REGRAIN_EPS"]

#: Window radius as a fraction of the image's long side (5 px at 1024 px).
DEFAULT_REGRAIN_RADIUS = 1.0 / 200.0
#: Regulariser in squared encoded units: input variations well below sqrt(eps) = 0.2
#: (most grain, JPEG blocks, gentle gradients) keep their input amplitude.
DEFAULT_REGRAIN_EPS = 0.2 ** 2
#: Coefficients are solved on at most this many pixels and interpolated back.
_MAX_SOLVE_PIXELS = 1_500_000


@compiled(cache=True)
def _reflect(i: int, n: int) -> int:  # pragma: no cover - compiled
    """Index ``i`` of a line of ``n`` extended by mirroring (d c b a | a b c d | d c b a)."""
    if 0 <= i < n:
        return i
    i = i % (2 * n)
    return 2 * n - 1 - i if i >= n else i


@compiled(parallel=True, cache=True)
def _box_mean(x: np.ndarray, radius: int) -> np.ndarray:  # pragma: no cover - compiled
    """Mean of each channel of an (H, W, K) array over (2 radius + 1)^2 windows, edges
    mirrored (scipy.ndimage.uniform_filter's "reflect"): running sums along the rows,
    then running sums down the columns (float64 sums)."""
    h, w, k = x.shape
    rows = np.empty((h, w * k), np.float32)
    for y in numba.prange(h):
        acc = np.zeros(k)
        for dx in range(-radius, radius + 1):
            xx = _reflect(dx, w)
            for c in range(k):
                acc[c] += x[y, xx, c]
        for xo in range(w):
            for c in range(k):
                rows[y, xo * k + c] = acc[c]
            leaving, entering = _reflect(xo - radius, w), _reflect(xo + radius + 1, w)
            for c in range(k):
                acc[c] += x[y, entering, c] - x[y, leaving, c]
    out = np.empty((h, w * k), np.float32)
    scale = 1.0 / ((2 * radius + 1) * (2 * radius + 1))
    width = w * k
    chunk = 256
    for part in numba.prange((width + chunk - 1) // chunk):
        lo = part * chunk
        hi = min(lo + chunk, width)
        acc2 = np.zeros(hi - lo)
        for dy in range(-radius, radius + 1):
            yy = _reflect(dy, h)
            for j in range(lo, hi):
                acc2[j - lo] += rows[yy, j]
        for y in range(h):
            for j in range(lo, hi):
                out[y, j] = acc2[j - lo] * scale
            leaving, entering = _reflect(y - radius, h), _reflect(y + radius + 1, h)
            for j in range(lo, hi):
                acc2[j - lo] += rows[entering, j] - rows[leaving, j]
    return out.reshape(h, w, k)


@compiled(parallel=True, cache=True)
def _moments(guide: np.ndarray, change: np.ndarray) -> np.ndarray:  # pragma: no cover
    """(H, W, 21): guide (3), change (3), guide_a guide_c (a <= c: 6), guide_a change_c (9)."""
    h, w = guide.shape[:2]
    out = np.empty((h, w, 21), np.float32)
    for y in numba.prange(h):
        for x in range(w):
            for c in range(3):
                out[y, x, c] = guide[y, x, c]
                out[y, x, 3 + c] = change[y, x, c]
            m = 6
            for a in range(3):
                for c in range(a, 3):
                    out[y, x, m] = guide[y, x, a] * guide[y, x, c]
                    m += 1
            for a in range(3):
                for c in range(3):
                    out[y, x, 12 + 3 * a + c] = guide[y, x, a] * change[y, x, c]
    return out


@compiled(parallel=True, cache=True)
def _local_models(means: np.ndarray, eps: float) -> np.ndarray:  # pragma: no cover
    """Per window: A = (Cov(I) + eps Id)^-1 Cov(I, d) (9) and b = mean(d) - A^T mean(I) (3)."""
    h, w = means.shape[:2]
    out = np.empty((h, w, 12), np.float32)
    for y in numba.prange(h):
        for x in range(w):
            m = means[y, x]
            i0, i1, i2 = m[0], m[1], m[2]
            s00 = m[6] - i0 * i0 + eps
            s01 = m[7] - i0 * i1
            s02 = m[8] - i0 * i2
            s11 = m[9] - i1 * i1 + eps
            s12 = m[10] - i1 * i2
            s22 = m[11] - i2 * i2 + eps
            v00, v01, v02 = s11 * s22 - s12 * s12, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
            v11, v12, v22 = s00 * s22 - s02 * s02, s01 * s02 - s00 * s12, s00 * s11 - s01 * s01
            det = s00 * v00 + s01 * v01 + s02 * v02
            for c in range(3):
                d = m[3 + c]
                x0 = m[12 + c] - i0 * d
                x1 = m[15 + c] - i1 * d
                x2 = m[18 + c] - i2 * d
                a0 = (v00 * x0 + v01 * x1 + v02 * x2) / det
                a1 = (v01 * x0 + v11 * x1 + v12 * x2) / det
                a2 = (v02 * x0 + v12 * x1 + v22 * x2) / det
                out[y, x, c] = a0
                out[y, x, 3 + c] = a1
                out[y, x, 6 + c] = a2
                out[y, x, 9 + c] = d - (a0 * i0 + a1 * i1 + a2 * i2)
    return out


def _coefficients(guide: np.ndarray, change: np.ndarray, radius: int,
                  eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Box-averaged (H, W, 3, 3) A and (H, W, 3) b of the local model change = A^T guide + b."""
    h, w = guide.shape[:2]
    guide = np.ascontiguousarray(guide, dtype=np.float32)
    change = np.ascontiguousarray(change, dtype=np.float32)
    means = _box_mean(_moments(guide, change), int(radius))
    smooth = _box_mean(_local_models(means, float(eps)), int(radius))
    A = np.ascontiguousarray(smooth[..., :9].reshape(h, w, 3, 3))
    return A, np.ascontiguousarray(smooth[..., 9:])


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
