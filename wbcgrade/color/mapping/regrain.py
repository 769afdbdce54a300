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

import hashlib

import numpy as np

from wbcgrade.color.mapping.remap import (
    apply_color_map,
    apply_lut_in_place,
    block_means_mapped,
    has_lut_library,
    identity_map,
    lut_processor,
)
from wbcgrade.color.options import DEFAULT_REGRAIN_EPS, DEFAULT_REGRAIN_RADIUS
from wbcgrade.core import compiled, compiled_preferred, in_bands, num_threads, numpy_first

__all__ = ["regrain", "regrain_map", "map_gain_prior", "load_kernels", "kernels_needed",
           "solved_subsampled", "moves_nothing", "DEFAULT_REGRAIN_RADIUS",
           "DEFAULT_REGRAIN_EPS"]

#: Coefficients are solved on at most this many pixels and interpolated back.
_MAX_SOLVE_PIXELS = 1_500_000


#: Per-pixel quantities whose window means give the local model: the guide I (3), the
#: change d (3), the guide's products I_a I_c (a <= c: 6) and the cross products I_a d_c (9).
_N_MOMENTS = 21

#: Solve grids of fewer pixels than this are filtered with numpy or scipy.ndimage
#: (:func:`_uniform_filter`: the numbers the grade always gave there), larger ones with
#: OpenCV's box filter (:func:`_uniform_filter_cv2`: the same means to float32 rounding,
#: several times faster; it replaced compiled kernels whose first call cost numba's
#: start on a photo solved at full size: docs/performance.md).
_NUMPY_SOLVE_PIXELS = 400_000


def _coefficients(guide: np.ndarray, change: np.ndarray, radius: int, eps: float,
                  prior: np.ndarray | None = None, precise: bool = True) -> np.ndarray:
    """(H, W, 12) float32 box-averaged coefficients of the local model
    ``change = A^T guide + b``: ``A[a, c]`` at ``3 a + c``, then ``b``. ``prior``: (n, n,
    n, 9) what each window's ``A`` is pulled towards, read at its mean colour (None: 0).
    ``precise`` False: solved in float32 (:func:`_window_models_numpy`)."""
    guide = np.ascontiguousarray(guide, dtype=np.float32)
    change = np.ascontiguousarray(change, dtype=np.float32)
    small = guide.shape[0] * guide.shape[1] < _NUMPY_SOLVE_PIXELS
    box = _box_numpy if small else _box_cv2
    pull = None
    if prior is not None:  # each window's A0 at its mean colour (the moments' first three)
        centre = box(guide, int(radius))
        pull = np.concatenate([_read_prior(centre, np.ascontiguousarray(
            prior[..., 3 * a:3 * a + 3], dtype=np.float32), precise) for a in range(3)],
            axis=-1)
    models = _window_models_numpy(guide, change, int(radius), float(eps), pull,
                                  None if small else _uniform_filter_cv2, precise)
    return box(models, int(radius))


def _read_prior(colors: np.ndarray, table: np.ndarray, precise: bool) -> np.ndarray:
    """``apply_color_map(colors, table)``; not ``precise`` (a subsampled solve, in float32),
    by OpenColorIO's LUT processor where it is installed (the same trilinear lookup to
    float32 rounding: a megapixel grid's three lookups in 0.04 s, where the numpy twin
    takes 0.5 s and the kernel numba's start)."""
    processor = None if precise else lut_processor(table)
    if processor is None:
        return apply_color_map(colors, table)
    out = np.empty(colors.shape, np.float32)
    apply_lut_in_place(processor, np.ascontiguousarray(colors, dtype=np.float32), out=out)
    return out


def _box_cv2(x: np.ndarray, radius: int) -> np.ndarray:
    """:func:`_box_numpy` with OpenCV's box filter (:func:`_uniform_filter_cv2`) on the
    channels as they lie (up to 12 at a time: no planes copied out and back), in bands of
    rows on every core when the image is tall enough (each band filtered with the radius
    of rows beyond it: OpenCV sums each row's window alone, so the numbers are those of
    one call, bit for bit)."""
    x = np.ascontiguousarray(x, dtype=np.float32)
    if x.size == 0:
        return np.empty_like(x)
    if x.shape[2] <= 12:
        out = np.empty_like(x)
        h = x.shape[0]
        parts = min(num_threads(), h // (8 * (2 * radius + 1)))
        if parts <= 1:
            _uniform_filter_cv2(x, 2 * radius + 1, out)
            return out
        edges = np.linspace(0, h, parts + 1).astype(int)

        def band(part: int) -> None:  # rows and the radius beyond: the same sums
            lo, hi = edges[part], edges[part + 1]
            top, bottom = max(lo - radius, 0), min(hi + radius, h)
            means = np.empty((bottom - top, *x.shape[1:]), np.float32)
            _uniform_filter_cv2(x[top:bottom], 2 * radius + 1, means)
            out[lo:hi] = means[lo - top:hi - top]

        _threaded(band, parts)  # (OpenCV's box filter runs on one core)
        return out
    return np.concatenate([_box_cv2(x[..., k:k + 12], radius)
                           for k in range(0, x.shape[2], 12)], axis=-1)


def _box_numpy(x: np.ndarray, radius: int) -> np.ndarray:
    """(H, W, K) float32 means of every channel over (2 radius + 1)^2 windows, mirrored at
    the borders (``d c b a | a b c d``): scipy.ndimage's reflect-mode uniform filter
    (float64 running sums; :func:`_uniform_filter`), one channel a plane, on as many
    threads as numba uses."""
    x = np.ascontiguousarray(x, dtype=np.float32)
    out = np.empty_like(x)
    if x.size == 0:
        return out
    planes = np.ascontiguousarray(np.moveaxis(x, -1, 0))
    means = np.empty_like(planes)

    def window_mean(k: int) -> None:
        _uniform_filter(planes[k], 2 * radius + 1, means[k])

    _threaded(window_mean, x.shape[2])
    out[...] = np.moveaxis(means, 0, -1)
    return out


def _window_models_numpy(guide: np.ndarray, change: np.ndarray, radius: int,
                         eps: float, prior: np.ndarray | None = None,
                         filtered=None, precise: bool = True) -> np.ndarray:
    """(H, W, 12) float32 each window's A and b: ``A = (Cov(I) + eps Id)^-1 (Cov(I, d) +
    eps A0)`` (``A[a, c]`` at ``3 a + c``; ``A0`` the (H, W, 9) ``prior``, None: 0) and
    ``b = mean(d) - A^T mean(I)``, from the window means of the 21 moments (the guide I,
    the change d, their products) by :func:`_box_numpy`'s filter or ``filtered`` (same
    arguments: :func:`_uniform_filter_cv2`), solved in closed form (float64; ``precise``
    False: in float32, the precision of the window means themselves, where ``eps`` keeps
    the covariances far from singular: :data:`_FLOAT32_SOLVE_EPS`) in bands of a few
    rows, on as many threads as numba uses. Nothing to compile."""
    filtered = filtered or _uniform_filter
    h, w = guide.shape[:2]
    out = np.empty((h, w, 12), np.float32)
    if h == 0 or w == 0:
        return out
    solved = np.float64 if precise or eps < _FLOAT32_SOLVE_EPS else np.float32
    if filtered is _uniform_filter_cv2:  # bands of rows, their moments made there
        _window_models_banded(guide, change, radius, eps, prior, solved, out)
        return out
    g = np.moveaxis(np.asarray(guide, dtype=np.float32), -1, 0)
    d = np.moveaxis(np.asarray(change, dtype=np.float32), -1, 0)
    first = (g[0], g[1], g[2], d[0], d[1], d[2])
    pairs = [(a, c) for a in range(3) for c in range(a, 3)]
    pairs += [(a, 3 + c) for a in range(3) for c in range(3)]
    means = np.empty((_N_MOMENTS, h, w), np.float32)  # one plane a moment

    def window_mean(k: int) -> None:
        plane = first[k] if k < 6 else np.multiply(first[pairs[k - 6][0]],
                                                   first[pairs[k - 6][1]])
        filtered(np.ascontiguousarray(plane), 2 * radius + 1, means[k])

    _threaded(window_mean, _N_MOMENTS)
    parts = max(1, min(num_threads(), h // _SOLVE_ROWS))
    edges = np.linspace(0, h, parts + 1).astype(int)

    def solve(part: int) -> None:  # bands of a few rows: their float64 planes stay in cache
        for start in range(edges[part], edges[part + 1], _SOLVE_ROWS):
            stop = min(start + _SOLVE_ROWS, edges[part + 1])
            _solve_band(means[:, start:stop].astype(solved, copy=False), eps, out[start:stop],
                        None if prior is None else prior[start:stop])

    _threaded(solve, parts)
    return out


def _window_models_banded(guide: np.ndarray, change: np.ndarray, radius: int, eps: float,
                          prior: np.ndarray | None, solved: type, out: np.ndarray) -> None:
    """:func:`_window_models_numpy` with OpenCV's box filter, band by band of
    :data:`_MOMENT_ROWS` rows (the bands of each core in turn): a band's 21 moments are
    made and filtered on its rows and the radius of rows beyond (OpenCV sums each row's
    window alone: the numbers of whole planes, bit for bit), then solved there. No
    full-size plane of moments (a 1-megapixel grid's 84 MB, fresh pages each time), and a
    band's planes stay in the cache between the products, the filter and the solve."""
    h, w = guide.shape[:2]
    guide = np.ascontiguousarray(guide, dtype=np.float32)
    change = np.ascontiguousarray(change, dtype=np.float32)
    size = 2 * radius + 1
    pairs = [(a, c) for a in range(3) for c in range(a, 3)]
    pairs += [(a, 3 + c) for a in range(3) for c in range(3)]
    rows = min(_MOMENT_ROWS, h)
    parts = max(1, min(num_threads(), -(-h // rows)))
    edges = np.linspace(0, -(-h // rows), parts + 1).astype(int) * rows

    def models(part: int) -> None:
        span = min(rows + 2 * radius, h)
        planes = np.empty((6, span, w), np.float32)  # the band's guide and change
        product = np.empty((span, w), np.float32)
        filtered = np.empty((span, w), np.float32)
        means = np.empty((_N_MOMENTS, rows, w), np.float32)
        for lo in range(edges[part], min(edges[part + 1], h), rows):
            hi = min(lo + rows, h)
            top, bottom = max(lo - radius, 0), min(hi + radius, h)
            n = bottom - top
            for k in range(3):
                planes[k, :n] = guide[top:bottom, :, k]
                planes[3 + k, :n] = change[top:bottom, :, k]
            for k in range(_N_MOMENTS):
                if k < 6:
                    plane = planes[k, :n]
                else:
                    a, c = pairs[k - 6]
                    plane = np.multiply(planes[a, :n], planes[c, :n], out=product[:n])
                _uniform_filter_cv2(plane, size, filtered[:n])
                means[k, :hi - lo] = filtered[lo - top:hi - top]
            for start in range(lo, hi, _SOLVE_ROWS):  # (8 rows: their planes in the cache)
                stop = min(start + _SOLVE_ROWS, hi)
                _solve_band(means[:, start - lo:stop - lo].astype(solved, copy=False), eps,
                            out[start:stop], None if prior is None else prior[start:stop])

    _threaded(models, parts)


#: Rows of one band of :func:`_window_models_banded` (a 1-megapixel grid's band: 21
#: planes of 64 rows, 7 MB; its filter reads the radius of rows beyond it as well).
_MOMENT_ROWS = 64


#: The least ``eps`` a solve in float32 is allowed (``precise`` False): each window's
#: covariance then has eigenvalues of at least 1e-3, its determinant at least 1e-9, far
#: above float32's rounding of the window means it is made of (the default 0.04: within
#: 3e-7 of the float64 solve on the 16-megapixel photo's coefficients).
_FLOAT32_SOLVE_EPS = 1e-3

#: Rows of one band of the window models' closed-form solve (:func:`_solve_band`): 8 rows
#: of a 1-megapixel grid's 21 float64 planes stay in the cache (64 rows: 1.8x the time).
_SOLVE_ROWS = 8


#: Plane pixels the numpy twin of the box filter filters in a process before scipy.ndimage
#: is imported (about four small photos' regrain: then a batch pays the import once).
_TWIN_FILTER_PIXELS = 20_000_000
_twin_filtered = 0


def _uniform_filter(plane: np.ndarray, size: int, out: np.ndarray) -> None:
    """``scipy.ndimage.uniform_filter(plane, size, mode="reflect", output=out)`` for a 2-D
    float32 ``plane``: scipy's own when scipy.ndimage is loaded already (or the twin has
    filtered :data:`_TWIN_FILTER_PIXELS`), else its numpy twin
    (:func:`_uniform_filter_numpy`, the same numbers; importing scipy.ndimage costs a
    small photo's grade more than its filters)."""
    import sys

    global _twin_filtered
    if "scipy.ndimage" not in sys.modules and not compiled_preferred() \
            and _twin_filtered + plane.size <= _TWIN_FILTER_PIXELS:
        _twin_filtered += plane.size
        out[...] = _uniform_filter_numpy(plane, size)
        return
    from scipy import ndimage

    ndimage.uniform_filter(plane, size=size, mode="reflect", output=out)


def _uniform_filter_cv2(plane: np.ndarray, size: int, out: np.ndarray) -> None:
    """:func:`_uniform_filter` by OpenCV's box filter (``BORDER_REFLECT`` is scipy's
    "reflect", mirrored again where the window is wider than the plane): the same means
    to float32 rounding (within 6e-8 here), several times faster; it releases the
    interpreter lock. A (H, W, K) ``plane`` (K <= 12) is filtered channel by channel in
    one call."""
    import cv2

    cv2.boxFilter(np.ascontiguousarray(plane, dtype=np.float32), -1, (size, size), dst=out,
                  normalize=True, borderType=cv2.BORDER_REFLECT)


def _uniform_filter_numpy(plane: np.ndarray, size: int) -> np.ndarray:
    """scipy.ndimage's reflect-mode ``uniform_filter`` of a 2-D float32 plane, bit for bit:
    along each axis in turn, each line extended by reflection (``d c b a | a b c d | d c
    b a``), a running float64 sum (the first window's sum, then ``+ entering - leaving``)
    divided by ``size``, rounded to float32 between the axes."""
    x = plane
    before = size // 2
    after = size - before - 1
    for axis in (0, 1):
        lines = np.moveaxis(x, axis, -1).astype(np.float64)
        n = lines.shape[-1]
        padded = np.pad(lines, ((0, 0), (before, after)), mode="symmetric")
        sums = np.empty(lines.shape, np.float64)
        sums[:, 0] = np.add.accumulate(padded[:, :size], axis=1)[:, -1]  # in order
        sums[:, 1:] = padded[:, size:size + n - 1] - padded[:, :n - 1]
        np.add.accumulate(sums, axis=1, out=sums)
        sums /= size
        x = np.moveaxis(sums.astype(np.float32), -1, axis)
    return x


def _threaded(task, n: int) -> None:
    """``task(k)`` for k in range(n), on as many threads as numba uses (numpy and
    scipy.ndimage release the GIL in their loops)."""
    threads = min(n, num_threads())
    if threads <= 1:
        for k in range(n):
            task(k)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(threads) as pool:
        for done in [pool.submit(task, k) for k in range(n)]:
            done.result()


def _solve_band(m: np.ndarray, eps: float, band: np.ndarray,
                prior: np.ndarray | None = None) -> None:
    """:func:`_solve_window` on a band of (21, rows, W) float64 window means, into the
    (rows, W, 12) ``band`` of the output (``prior``: the band's (rows, W, 9) ``A0``)."""
    mg, md = m[0:3], m[3:6]
    s00 = m[6] - mg[0] * mg[0] + eps
    s01 = m[7] - mg[0] * mg[1]
    s02 = m[8] - mg[0] * mg[2]
    s11 = m[9] - mg[1] * mg[1] + eps
    s12 = m[10] - mg[1] * mg[2]
    s22 = m[11] - mg[2] * mg[2] + eps
    i00 = s11 * s22 - s12 * s12
    i01 = s02 * s12 - s01 * s22
    i02 = s01 * s12 - s02 * s11
    i11 = s00 * s22 - s02 * s02
    i12 = s01 * s02 - s00 * s12
    i22 = s00 * s11 - s01 * s01
    scale = 1.0 / (s00 * i00 + s01 * i01 + s02 * i02)
    inverse = ((i00, i01, i02), (i01, i11, i12), (i02, i12, i22))
    for c in range(3):
        cross = [m[12 + 3 * b + c] - mg[b] * md[c] for b in range(3)]
        if prior is not None:
            cross = [cross[b] + eps * prior[..., 3 * b + c] for b in range(3)]
        offset = md[c].copy()
        for a in range(3):
            row = inverse[a]
            value = ((row[0] * cross[0] + row[1] * cross[1] + row[2] * cross[2])
                     * scale).astype(np.float32)
            band[:, :, 3 * a + c] = value
            offset -= value * mg[a]
        band[:, :, 9 + c] = offset


@compiled(nogil=True, cache=True)
def _apply_rows(source: np.ndarray, coefficients: np.ndarray, step: float, left: np.ndarray,
                right: np.ndarray, weight: np.ndarray, out: np.ndarray, lo: int,
                hi: int) -> None:  # pragma: no cover - compiled
    """Rows lo:hi of :func:`_apply_upsampled` (the columns' nodes and weights given)."""
    lh, lw = coefficients.shape[:2]
    w = source.shape[1]
    one = np.float32(1.0)
    zero = np.float32(0.0)
    row = np.empty((lw, 12), np.float32)  # this output row's coefficients, coarse columns
    for y in range(lo, hi):
        fy = min(max((y + 0.5) / step - 0.5, 0.0), lh - 1.0)
        y0 = min(int(fy), lh - 2) if lh > 1 else 0
        ty = np.float32(fy - y0)
        y1 = min(y0 + 1, lh - 1)
        for x in range(lw):
            for k in range(12):
                row[x, k] = (one - ty) * coefficients[y0, x, k] + ty * coefficients[y1, x, k]
        for x in range(w):
            x0 = left[x]
            x1 = right[x]
            tx = weight[x]
            s0 = source[y, x, 0]
            s1 = source[y, x, 1]
            s2 = source[y, x, 2]
            for c in range(3):
                value = (one - tx) * (row[x0, 9 + c] + row[x0, c] * s0 + row[x0, 3 + c] * s1
                                      + row[x0, 6 + c] * s2) \
                    + tx * (row[x1, 9 + c] + row[x1, c] * s0 + row[x1, 3 + c] * s1
                            + row[x1, 6 + c] * s2)
                out[y, x, c] = min(max(source[y, x, c] + value, zero), one)


def _apply_upsampled(source: np.ndarray, coefficients: np.ndarray, step: float,
                     out: np.ndarray, twin: bool = True) -> None:
    """``out = clip(source + A(x)^T source + b(x))`` with the (lh, lw, 12) ``A, b`` of
    :func:`_coefficients` bilinearly interpolated from the coarse grid (pixel centres,
    edges clamped): each output row first blends its two coarse rows, then each pixel
    blends two nodes of that row (the column weights are the same for every row)."""
    w = source.shape[1]
    lw = coefficients.shape[1]
    fx = np.minimum(np.maximum((np.arange(w) + 0.5) / step - 0.5, 0.0), lw - 1.0)
    left = np.minimum(fx.astype(np.int64), lw - 2) if lw > 1 else np.zeros(w, np.int64)
    right = np.minimum(left + 1, lw - 1)
    weight = (fx - left).astype(np.float32)
    pixels = source.shape[0] * w
    same = step == 1.0 and coefficients.shape[:2] == source.shape[:2]
    if twin and same and numpy_first(_apply_rows, pixels, _MAX_SOLVE_PIXELS):
        _apply_same_grid(source, coefficients, out)
        return
    if twin and not same and pixels > _NUMPY_APPLY_PIXELS and float(step).is_integer():
        _apply_upsampled_cv2(source, coefficients, int(step), out)
        return
    if twin and numpy_first(_apply_rows, pixels, _NUMPY_APPLY_PIXELS):
        _apply_rows_numpy(source, coefficients, float(step), left, right, weight, out)
        return
    in_bands(_apply_rows, source.shape[0], source, coefficients, float(step), left, right,
             weight, out)


def _apply_upsampled_cv2(source: np.ndarray, coefficients: np.ndarray, step: int,
                         out: np.ndarray) -> None:
    """``_apply_rows`` with OpenCV, for a whole ``step``: band by band (on every core), each
    output channel's four coefficients (``A[:, c]`` plus the identity's column, and
    ``b[c]``) bilinearly resized from the band's coarse rows (pixel centres, edges
    replicated: the kernel's clamped interpolation; rows and columns past the coarse
    grid's last node take that node's, as the kernel's clamp gives them), multiplied by
    the pixels' ``(r, g, b, 1)`` and summed (an area resize of the four products, the
    coefficients scaled by 4 beforehand: exact). The kernel's numbers to
    float32 rounding (the coefficients are interpolated before they are applied: within
    1e-6), no compiled kernel to load, buffers reused band to band (fresh pages cost
    more than the arithmetic); ``out`` may be ``source``."""
    import cv2

    h, w = source.shape[:2]
    lh, lw = coefficients.shape[:2]
    if h == 0 or w == 0:
        return
    groups = []  # per output channel c: A[0, c], A[1, c], A[2, c] (+ identity), b[c],
    by_channel = np.asarray(coefficients, dtype=np.float32).reshape(lh, lw, 4, 3)
    for c in range(3):  # times 4 (exact): the four products' mean is then their sum
        group = np.multiply(by_channel[..., c], np.float32(4.0))  # ((x + 1) 4 is 4 x + 4)
        group[..., c] += np.float32(4.0)
        groups.append(group)
    inside_w = min(w, lw * step)  # columns past the last node repeat it
    inside_h = min(h, lh * step)  # rows too
    rows = max(1, _BAND_ROWS // step) * step
    last = [cv2.resize(g[lh - 1:lh], (lw * step, 1), interpolation=cv2.INTER_LINEAR)
            .reshape(1, lw * step, 4)[:, :inside_w] for g in groups]

    def apply(part: int) -> None:
        coarse = [np.empty(((rows // step + 3) * step, lw * step, 4), np.float32)
                  for _ in range(3)]
        pixels = np.empty((rows, inside_w, 4), np.float32)
        product = np.empty((rows, inside_w, 4), np.float32)
        planes = [np.empty((rows, inside_w), np.float32) for _ in range(3)]
        merged = np.empty((rows, inside_w, 3), np.float32)

        def band(y0: int, y1: int, ups: list[np.ndarray]) -> None:
            r = y1 - y0
            colors = source[y0:y1]
            with_one = pixels[:r]
            cv2.cvtColor(colors[:, :inside_w], cv2.COLOR_RGB2RGBA, dst=with_one)
            for c in range(3):  # the four products summed: their mean (area resize)
                cv2.multiply(ups[c], with_one, dst=product[:r])
                cv2.resize(product[:r].reshape(r, 4 * inside_w), (inside_w, r),
                           dst=planes[c][:r], interpolation=cv2.INTER_AREA)
            cv2.merge([plane[:r] for plane in planes], dst=merged[:r])
            if inside_w < w:  # past the last node's column: its coefficients
                tail = colors[:, inside_w:].astype(np.float32)
                value = np.stack([(np.einsum("rxa,ra->rx", tail, up[:, -1, :3])
                                   + up[:, -1, 3:4]) * np.float32(0.25) for up in ups],
                                 axis=-1)
                np.clip(value, np.float32(0.0), np.float32(1.0), out=out[y0:y1, inside_w:])
            np.clip(merged[:r], np.float32(0.0), np.float32(1.0), out=out[y0:y1, :inside_w])

        for y0 in range(edges[part], edges[part + 1], rows):
            y1 = min(y0 + rows, edges[part + 1])
            inside = min(y1, inside_h)
            if inside > y0:  # resized from the band's coarse rows, one above and below
                c0, c1 = max(y0 // step - 1, 0), min(-(-inside // step) + 1, lh)
                ups = []
                for group, buffer in zip(groups, coarse):
                    up = buffer[:(c1 - c0) * step]
                    cv2.resize(group[c0:c1], (lw * step, (c1 - c0) * step), dst=up,
                               interpolation=cv2.INTER_LINEAR)
                    ups.append(up[y0 - c0 * step:inside - c0 * step, :inside_w])
                band(y0, inside, ups)
            if y1 > inside:  # past the last node's row: its coefficients
                start = max(y0, inside)
                band(start, y1, [np.ascontiguousarray(np.broadcast_to(
                    row, (y1 - start, inside_w, 4))) for row in last])

    parts = max(1, min(num_threads(), h // rows))
    edges = (np.linspace(0, h // rows, parts + 1).astype(int) * rows)
    edges[-1] = h
    _threaded(apply, parts)


#: Pixels up to which :func:`_apply_upsampled` runs its numpy twin while ``_apply_rows``
#: has not run in the process (see :func:`wbcgrade.core.numpy_first`); on the pixels' own
#: grid (a photo solved at full size) its cheaper twin :func:`_apply_same_grid`, up to
#: :data:`_MAX_SOLVE_PIXELS`.
_NUMPY_APPLY_PIXELS = 400_000


def _apply_same_grid(source: np.ndarray, coefficients: np.ndarray, out: np.ndarray) -> None:
    """``_apply_rows`` at step 1 (the coefficients on the pixels' own grid) with numpy,
    bit for bit: the interpolation weights are then 0 and 1, so each pixel takes its own
    node's ``A, b`` (``1 a + 0 b`` is ``a``), in the kernel's float32 order; ``out`` may
    be ``source``."""
    graded = np.empty(source.shape, np.float32)
    s0, s1, s2 = source[..., 0], source[..., 1], source[..., 2]
    for c in range(3):
        value = coefficients[..., 9 + c] + coefficients[..., c] * s0
        value += coefficients[..., 3 + c] * s1
        value += coefficients[..., 6 + c] * s2
        np.add(source[..., c], value, out=graded[..., c])
    np.clip(graded, np.float32(0.0), np.float32(1.0), out=out)


def _apply_rows_numpy(source: np.ndarray, coefficients: np.ndarray, step: float,
                      left: np.ndarray, right: np.ndarray, weight: np.ndarray,
                      out: np.ndarray) -> None:
    """``_apply_rows`` over every row with numpy, bit for bit (float32 arithmetic in the
    kernel's order); ``out`` may be ``source``."""
    h = source.shape[0]
    lh = coefficients.shape[0]
    fy = np.minimum(np.maximum((np.arange(h) + 0.5) / step - 0.5, 0.0), lh - 1.0)
    y0 = np.minimum(fy.astype(np.int64), lh - 2) if lh > 1 else np.zeros(h, np.int64)
    ty = (fy - y0).astype(np.float32)[:, None, None]
    y1 = np.minimum(y0 + 1, lh - 1)
    one = np.float32(1.0)
    rows = (one - ty) * coefficients[y0] + ty * coefficients[y1]  # (h, lw, 12)
    tx = weight[None, :]
    s0, s1, s2 = source[..., 0], source[..., 1], source[..., 2]
    at0, at1 = rows[:, left], rows[:, right]  # (h, w, 12)
    graded = np.empty(source.shape, np.float32)
    for c in range(3):
        value = (one - tx) * (at0[..., 9 + c] + at0[..., c] * s0 + at0[..., 3 + c] * s1
                              + at0[..., 6 + c] * s2) \
            + tx * (at1[..., 9 + c] + at1[..., c] * s0 + at1[..., 3 + c] * s1
                    + at1[..., 6 + c] * s2)
        graded[..., c] = source[..., c] + value
    np.clip(graded, np.float32(0.0), one, out=out)


def _downsample(x: np.ndarray, step: int) -> np.ndarray:
    """Mean of every step x step block of an (H, W, C) image (partial edge blocks dropped):
    OpenCV's area resize by a whole factor (float32 sums, no compiled kernel to load)."""
    import cv2

    x = np.ascontiguousarray(x, dtype=np.float32)
    h, w = x.shape[0] // step, x.shape[1] // step
    if h == 0 or w == 0:
        return np.zeros((h, w, x.shape[2]), np.float32)
    if step == 1:
        return x.copy()
    out = np.empty((h, w, x.shape[2]), np.float32)
    rows = max(1, _BAND_ROWS // step)

    def means(part: int) -> None:
        for lo in range(edges[part], edges[part + 1], rows):
            hi = min(lo + rows, edges[part + 1])
            band = x[lo * step:hi * step, :w * step]
            out[lo:hi] = cv2.resize(band, (w, hi - lo), interpolation=cv2.INTER_AREA
                                    ).reshape(hi - lo, w, x.shape[2])
    parts = max(1, min(num_threads(), h // rows))
    edges = np.linspace(0, h, parts + 1).astype(int)
    _threaded(means, parts)
    return out


#: Full-size rows a band of the subsampled regrain's passes holds (its pixels' colours and
#: the band's coefficients stay in the CPU's cache).
_BAND_ROWS = 32


def _block_means(source: np.ndarray, color_map: np.ndarray, strength: float,
                 step: int) -> tuple[np.ndarray, np.ndarray]:
    """(mapped, source) block means of ``source`` moved through the map and of ``source``
    itself (``block_means_mapped(..., with_source=True)``): with OpenColorIO's LUT
    processor (:func:`~wbcgrade.color.mapping.remap.lut_processor`) and OpenCV's area
    resize, band by band on every core, the kernel's numbers to float32 rounding and no
    compiled kernel to load (numba's start costs a 16-megapixel grade about 0.6 s of
    CPU); the compiled kernel without the ``opencolorio`` package."""
    processor = lut_processor(color_map, strength)
    if processor is None:
        return block_means_mapped(source, color_map, strength, step, with_source=True)
    import cv2

    h, w = source.shape[0] // step, source.shape[1] // step
    mapped = np.zeros((h, w, 3), np.float32)
    small = np.zeros((h, w, 3), np.float32)
    if h == 0 or w == 0:
        return mapped, small
    rows = max(1, _BAND_ROWS // step)

    whole = source.shape[1] == w * step and source.dtype == np.float32 \
        and source.flags.c_contiguous  # (bands of whole rows: mapped from where they are)

    def means(part: int) -> None:
        buffer = np.empty((rows * step, w * step, 3), np.float32)
        for lo in range(edges[part], edges[part + 1], rows):
            hi = min(lo + rows, edges[part + 1])
            band = buffer[:(hi - lo) * step]
            colors = source[lo * step:hi * step, :w * step]
            cv2.resize(colors, (w, hi - lo), dst=small[lo:hi], interpolation=cv2.INTER_AREA)
            if whole:
                apply_lut_in_place(processor, colors, out=band)
            else:
                band[...] = colors
                apply_lut_in_place(processor, band)
            cv2.resize(band, (w, hi - lo), dst=mapped[lo:hi], interpolation=cv2.INTER_AREA)
    parts = max(1, min(num_threads(), h // rows))
    edges = np.linspace(0, h, parts + 1).astype(int)
    _threaded(means, parts)
    return mapped, small


def regrain(source: np.ndarray, graded: np.ndarray, radius: float = DEFAULT_REGRAIN_RADIUS,
            eps: float = DEFAULT_REGRAIN_EPS, out: np.ndarray | None = None) -> np.ndarray:
    """Graded colours with the input's grain and edges (edge-aware local linear model).

    Parameters
    ----------
    source : (H, W, 3) input colours, encoded, in [0, 1].
    graded : (H, W, 3) the same pixels through the colour map.
    radius : window radius as a fraction of the long side (>= 1 pixel is used).
    eps : regulariser, squared encoded units (larger: more of the input's
        detail kept as is, less of the map's local contrast).
    out : optional (H, W, 3) float32 C-contiguous array the result is written
        into (it may be ``source`` itself: every pixel is read before it is
        written), instead of a new one.

    Returns
    -------
    (H, W, 3) float32 in [0, 1] (``out`` when given).
    """
    if source.shape != graded.shape or source.ndim != 3 or source.shape[2] != 3:
        raise ValueError("source and graded must be the same (H, W, 3) shape")
    if not (radius > 0 and eps > 0):
        raise ValueError("radius and eps must be positive")
    h, w = source.shape[:2]
    out = _output(source, out)
    source = np.ascontiguousarray(source, dtype=np.float32)
    graded = np.ascontiguousarray(graded, dtype=np.float32)
    step = _step(h, w)
    if step == 1:
        pixels = _window(radius, max(h, w))
        _apply_upsampled(source, _coefficients(source, graded - source, pixels, eps), 1.0, out)
        return out
    small = _downsample(source, step)
    change = _downsample(graded, step) - small
    return _regrain_upsampled(source, small, change, step, radius, eps, out)


def regrain_map(source: np.ndarray, color_map: np.ndarray, strength: float = 1.0,
                radius: float = DEFAULT_REGRAIN_RADIUS, eps: float = DEFAULT_REGRAIN_EPS,
                out: np.ndarray | None = None, follow: float = 0.0) -> np.ndarray:
    """``regrain(source, apply_color_map(source, color_map, strength), radius, eps, out)``.

    The same numbers (``follow`` 0); on large images (solved on a subsampled copy) the
    graded image is only needed block-averaged, so the colour map and the
    block means (of the input too) are one pass
    (:func:`wbcgrade.color.mapping.remap.block_means_mapped`) and the full-size graded
    image is never made (two passes and ~12 bytes a pixel saved).

    ``follow``: in [0, 1], how far the input's grain (variations under sqrt(eps)) follows
    the map's local gain where the map lowers contrast or saturation (a flat, faded or
    lifted-black look flattens the texture too; :func:`map_gain_prior` scaled by it);
    where the map raises them it keeps the input's amplitude. 0: always the input's.
    """
    if source.ndim != 3 or source.shape[2] != 3:
        raise ValueError("source must be an (H, W, 3) image")
    if not (radius > 0 and eps > 0):
        raise ValueError("radius and eps must be positive")
    h, w = source.shape[:2]
    step = _step(h, w)
    if not 0.0 <= follow <= 1.0:
        raise ValueError("follow must be in [0, 1]")
    if moves_nothing(color_map, strength):  # no change to regrain: the colours, in the cube
        out = _output(source, out)
        np.clip(source, np.float32(0.0), np.float32(1.0), out=out)
        return out
    if step == 1 and not follow:
        return regrain(source, apply_color_map(source, color_map, strength), radius, eps, out)
    out = _output(source, out)
    source = np.ascontiguousarray(source, dtype=np.float32)
    if step == 1:
        small, change = source, apply_color_map(source, color_map, strength) - source
    else:
        mapped, small = _block_means(source, color_map, strength, step)
        change = mapped - small
    prior = float(follow) * map_gain_prior(color_map, strength) if follow else None
    return _regrain_upsampled(source, small, change, step, radius, eps, out, prior)


def moves_nothing(color_map: np.ndarray, strength: float = 1.0) -> bool:
    """Whether a colour map at ``strength`` leaves every colour where it is: strength 0, or
    the map is the identity lattice itself (:func:`~wbcgrade.color.mapping.remap.identity_map`
    in its own float type, node for node; a look the style photos do not share is one).
    Its regrain is then the colours themselves, clipped to the cube (``d = 0``: every
    window's ``A`` and ``b`` are 0), which :func:`regrain_map` returns without the passes
    over the pixels whose float rounding would only add noise under 1e-8."""
    table = np.asarray(color_map)
    if table.ndim != 4 or table.shape[3] != 3 or table.dtype.kind != "f" \
            or len(set(table.shape[:3])) != 1 or table.shape[0] < 2:
        return False  # (not a map: the regrain says what is wrong with it)
    return strength == 0.0 or bool(np.array_equal(table, identity_map(table.shape[0],
                                                                      table.dtype)))


def solved_subsampled(pixels: int) -> bool:
    """Whether :func:`regrain_map` solves a photo of ``pixels`` pixels on a subsampled copy
    (over 1.5 megapixels)."""
    return _step(1, pixels) > 1


def kernels_needed() -> bool:
    """Whether a photo solved on a subsampled copy runs a compiled kernel: its map's block
    means do without the ``opencolorio`` package (:func:`_block_means`); everything else
    it runs is OpenCV's and numpy's."""
    return not has_lut_library()


def load_kernels(pixels: int) -> bool:
    """Load the compiled kernel :func:`regrain_map` runs on a photo of ``pixels`` pixels
    solved on a subsampled copy (over 1.5 megapixels) without the ``opencolorio`` package
    (:func:`kernels_needed`), by running it on a few pixels through the same wrapper (the
    same argument types: the signature numba's cache holds; a first run after install
    compiles it here). False, loading nothing, for a smaller photo (its solve may run
    numpy's twins) or where OpenColorIO maps the colours.

    What a command grading a large photo starts in a thread before decoding it
    (:func:`wbcgrade.photos.workflow.grade_photo`): importing numba and loading its
    first kernel is about 0.7 s of Python, most of it while the decoder and the scene
    matching hold no interpreter lock.
    """
    if not solved_subsampled(pixels) or not kernels_needed():
        return False
    colors = np.full((4, 4, 3), 0.5, np.float32)
    table = np.zeros((2, 2, 2, 3), np.float32)
    block_means_mapped(colors, table, 1.0, 2, with_source=True)
    return True


#: The last few maps' priors (:func:`map_gain_prior`), by a digest of the map and strength.
_PRIORS: dict[tuple, np.ndarray] = {}


def map_gain_prior(color_map: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """(n, n, n, 9) float32: at every node of an (n, n, n, 3) colour map (blended with the
    identity at ``strength``), the local model a window of pure noise falls back to, laid
    out as the regrain's ``A`` (``A[a, c]`` at ``3 a + c``): the map's Jacobian with every
    gain above 1 cut to 1 (its singular values; the directions kept), minus the identity.
    Where the map lowers contrast or saturation, detail follows it; where it raises them,
    detail keeps the input's amplitude (no grain or block step amplified)."""
    table = np.asarray(color_map, dtype=np.float64)
    if not np.isfinite(table).all():
        raise ValueError("the colour map holds NaN or infinite values")
    key = (hashlib.sha1(np.ascontiguousarray(table).tobytes()).hexdigest(), table.shape,
           float(strength))
    if key in _PRIORS:
        return _PRIORS[key]
    n = table.shape[0]
    axis = np.linspace(0.0, 1.0, n)
    identity = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1)
    mapped = (1.0 - strength) * identity + strength * table
    jacobian = np.stack(np.gradient(mapped, axis, axis, axis, axis=(0, 1, 2)), axis=-1)
    u, s, vt = np.linalg.svd(jacobian)  # jacobian[..., out, in]
    capped = np.einsum("...ij,...j,...jk->...ik", u, np.minimum(s, 1.0), vt)
    prior = np.swapaxes(capped, -1, -2) - np.eye(3)  # [in a, out c]
    prior = np.ascontiguousarray(prior.reshape(n, n, n, 9), dtype=np.float32)
    prior.setflags(write=False)
    if len(_PRIORS) >= 8:  # (a batch grades many photos with one preset's map)
        _PRIORS.pop(next(iter(_PRIORS)))
    _PRIORS[key] = prior
    return prior


def _window(radius: float, side: float) -> int:
    """The window radius in pixels of a line of ``side`` pixels: at least 1, at most the
    line itself (a larger window is the whole, mirrored photo; its summing loops would
    only run longer: ``radius=1e9`` ran for hours in compiled code, deaf to Ctrl-C)."""
    return max(1, min(int(round(min(radius, 1.0) * side)), int(np.ceil(side))))


def _step(h: int, w: int) -> int:
    """Subsampling step of the coefficients' solve (1: full resolution)."""
    return max(1, int(np.ceil(np.sqrt(h * w / _MAX_SOLVE_PIXELS))))


def _output(source: np.ndarray, out: np.ndarray | None) -> np.ndarray:
    """The array a regrain writes into: ``out`` checked, or a new one like ``source``."""
    if out is None:
        return np.empty(source.shape, np.float32)
    if out.shape != source.shape or out.dtype != np.float32 or not out.flags.c_contiguous \
            or not out.flags.writeable:
        raise ValueError("out must be a writeable C-contiguous float32 array of the "
                         "source's shape")
    return out


def _regrain_upsampled(source: np.ndarray, small: np.ndarray, change: np.ndarray, step: int,
                       radius: float, eps: float, out: np.ndarray,
                       prior: np.ndarray | None = None) -> np.ndarray:
    h, w = source.shape[:2]
    pixels = _window(radius, max(h, w) / step)
    # on a subsampled copy, solved in float32: its coefficients are interpolated in float32
    coefficients = _coefficients(small, change, pixels, eps, prior, precise=step == 1)
    _apply_upsampled(source, coefficients, float(step), out)
    return out
