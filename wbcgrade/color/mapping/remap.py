"""Apply a colour map (a 3-D lookup table on the bin grid) to every pixel.

A colour map is an (n, n, n, 3) array: entry [i, j, k] is the new colour of
the bin at (i, j, k) / (n - 1). Pixels between bins are moved by trilinear
interpolation of the map, in one fused numba pass on every core (about twenty times
scipy's map_coordinates: docs/benchmarks.md).
"""

from __future__ import annotations

import numpy as np

from wbcgrade.color.colorspace import REC709_LUMA, SYCC_LUMA
from wbcgrade.core import compiled, in_bands, numpy_first

__all__ = ["apply_color_map", "resample_lattice", "interpolate_lattice", "block_means_mapped",
           "lut_processor", "identity_map", "blend_map", "keep_lightness",
           "monotone_lightness", "TONE_LUMA", "monochrome_toning",
           "to_monochrome", "monochrome_map"]


@compiled(inline="always", cache=True)
def _mapped(table, x0, x1, x2, strength, out) -> None:  # pragma: no cover - compiled
    """``out[c]``: the colour (x0, x1, x2) moved through the map (trilinear), blended
    with itself by ``strength``; the one lookup both remap kernels inline."""
    n = table.shape[0]
    scale = n - 1
    r = min(max(x0, 0.0), 1.0) * scale
    g = min(max(x1, 0.0), 1.0) * scale
    b = min(max(x2, 0.0), 1.0) * scale
    i = min(int(r), n - 2)
    j = min(int(g), n - 2)
    k = min(int(b), n - 2)
    fr = r - i
    fg = g - j
    fb = b - k
    for c in range(3):
        c00 = table[i, j, k, c] * (1 - fb) + table[i, j, k + 1, c] * fb
        c01 = table[i, j + 1, k, c] * (1 - fb) + table[i, j + 1, k + 1, c] * fb
        c10 = table[i + 1, j, k, c] * (1 - fb) + table[i + 1, j, k + 1, c] * fb
        c11 = table[i + 1, j + 1, k, c] * (1 - fb) + table[i + 1, j + 1, k + 1, c] * fb
        c0 = c00 * (1 - fg) + c01 * fg
        c1 = c10 * (1 - fg) + c11 * fg
        value = c0 * (1 - fr) + c1 * fr
        x = x0 if c == 0 else (x1 if c == 1 else x2)
        x = min(max(x, 0.0), 1.0)
        out[c] = (1 - strength) * x + strength * value


@compiled(nogil=True, cache=True, fastmath=False)
def _trilinear(colors: np.ndarray, table: np.ndarray, strength: float, out: np.ndarray,
               lo: int, hi: int) -> None:  # pragma: no cover - compiled
    """Colours lo:hi of (N, 3) ``colors`` through the map into ``out`` (one band of
    :func:`wbcgrade.core.in_bands`)."""
    for p in range(lo, hi):
        _mapped(table, colors[p, 0], colors[p, 1], colors[p, 2], strength, out[p])


@compiled(nogil=True, cache=True, fastmath=False)
def _block_means_mapped(colors: np.ndarray, table: np.ndarray, strength: float,
                        step: int, out: np.ndarray, source_means: np.ndarray,
                        lo: int, hi: int) -> None:  # pragma: no cover - compiled
    """Block rows lo:hi of the mean of every step x step block of an (H, W, 3) image
    moved through the map, into ``out`` (h, w, 3) (zeros on entry).

    Bit for bit ``regrain._downsample(apply_color_map(colors, table, strength), step)``
    (the same lookup as ``_trilinear``, the block sums in the same order, partial edge
    blocks dropped) without the full-size graded image. ``source_means`` (h, w, 3), when
    it has that shape, receives the blocks' means of ``colors`` themselves in the same pass
    (bit for bit ``regrain._downsample(colors, step)``; zeros on entry); a (0, 0, 3)
    array otherwise.
    """
    h, w = out.shape[0], out.shape[1]
    both = source_means.shape[0] == h and source_means.shape[1] == w and h > 0 and w > 0
    inv = 1.0 / (step * step)
    mapped = np.empty(3, np.float32)
    for bi in range(lo, hi):
        for di in range(step):
            row = bi * step + di
            for bj in range(w):
                for dj in range(step):
                    col = bj * step + dj
                    _mapped(table, colors[row, col, 0], colors[row, col, 1],
                            colors[row, col, 2], strength, mapped)
                    for c in range(3):
                        out[bi, bj, c] += mapped[c]
                    if both:
                        for c in range(3):
                            source_means[bi, bj, c] += colors[row, col, c]
        for bj in range(w):
            for c in range(3):
                out[bi, bj, c] *= inv
            if both:
                for c in range(3):
                    source_means[bi, bj, c] *= inv


def block_means_mapped(rgb: np.ndarray, color_map: np.ndarray, strength: float,
                       step: int, with_source: bool = False):
    """Block means (``step`` x ``step``, partial edge blocks dropped) of an (H, W, 3)
    image moved through a colour map: ``apply_color_map`` then the block means, in
    one pass and without the full-size result (the same float32 numbers).

    With ``with_source``, a pair: those means and the block means of ``rgb`` itself
    (float32, as ``regrain._downsample``), read in the same pass.
    """
    if color_map.ndim != 4 or color_map.shape[3] != 3 or len(set(color_map.shape[:3])) != 1 \
            or color_map.shape[0] < 2:  # n < 2: the interpolation would read past the table
        raise ValueError("color_map must be (n, n, n, 3) with n >= 2")
    if rgb.ndim != 3 or rgb.shape[2] != 3 or step < 1:
        raise ValueError("rgb must be (H, W, 3) and step >= 1")
    colors = np.ascontiguousarray(rgb, dtype=np.float32)
    table = np.ascontiguousarray(color_map, dtype=np.float32)
    shape = (colors.shape[0] // step, colors.shape[1] // step, 3) if with_source else (0, 0, 3)
    source_means = np.zeros(shape, np.float32)
    h, w = colors.shape[0] // step, colors.shape[1] // step
    mapped = np.zeros((h, w, 3), np.float32)
    in_bands(_block_means_mapped, h, colors, table, np.float32(strength), int(step), mapped,
             source_means, min_band=1)
    return (mapped, source_means) if with_source else mapped


#: Nodes per axis OpenColorIO's 3-D LUT holds at most (``Lut3DTransform``).
_OCIO_MAX_NODES = 129


def has_lut_library() -> bool:
    """Whether :func:`lut_processor` can apply colour maps (the ``opencolorio`` package is
    installed), found without importing it."""
    from importlib.util import find_spec

    return find_spec("PyOpenColorIO") is not None


def lut_processor(color_map: np.ndarray, strength: float = 1.0):
    """OpenColorIO's CPU processor of a colour map at ``strength``: a ``Lut3DTransform``
    with trilinear interpolation, :func:`apply_color_map`'s numbers to float32 rounding
    (within 4e-7; ``(1 - t) x + t T(x)`` is the map blended with the identity at its
    nodes, which trilinear interpolation reproduces). Colours are clipped to the cube
    as the kernel clips them, NaN becomes 0. ``processor.apply(PackedImageDesc)`` grades
    float32 RGB pixels in place, without the interpreter lock (about 14 ns a pixel on one
    core: faster than the compiled kernel, and nothing to load). None without the
    ``opencolorio`` package, or for a map OpenColorIO cannot hold (over 129 nodes)."""
    if color_map.ndim != 4 or color_map.shape[3] != 3 or len(set(color_map.shape[:3])) != 1 \
            or color_map.shape[0] < 2:
        raise ValueError("color_map must be (n, n, n, 3) with n >= 2")
    if not 0.0 <= strength <= 1.0:
        raise ValueError("strength must be in [0, 1]")
    if color_map.shape[0] > _OCIO_MAX_NODES:
        return None
    try:
        import PyOpenColorIO as ocio
    except ImportError:
        return None
    table = np.asarray(color_map, dtype=np.float32)
    if strength != 1.0:
        table = blend_map(table, float(np.float32(strength)))
    lut = ocio.Lut3DTransform()
    lut.setGridSize(table.shape[0])
    lut.setData(np.ascontiguousarray(table, dtype=np.float32).ravel())
    lut.setInterpolation(ocio.INTERP_LINEAR)
    return ocio.Config.CreateRaw().getProcessor(lut).getDefaultCPUProcessor()


def apply_lut_in_place(processor, rgb: np.ndarray, out: np.ndarray | None = None) -> None:
    """Grade a C-contiguous float32 (H, W, 3) image with a :func:`lut_processor`, in place
    or into ``out`` (the same shape and kind; OpenColorIO works a row at a time: pass
    bands of rows, not one long row)."""
    import PyOpenColorIO as ocio

    for array in (rgb, rgb if out is None else out):
        if array.ndim != 3 or array.shape[2] != 3 or array.dtype != np.float32 \
                or not array.flags.c_contiguous or array.shape != rgb.shape:
            raise ValueError("rgb and out must be C-contiguous float32 (H, W, 3) arrays")
    if not rgb.size:
        return
    source = ocio.PackedImageDesc(rgb, rgb.shape[1], rgb.shape[0], 3)
    if out is None:
        processor.apply(source)
    else:
        processor.apply(source, ocio.PackedImageDesc(out, out.shape[1], out.shape[0], 3))


def resample_lattice(lattice: np.ndarray, size: int) -> np.ndarray:
    """An (n, n, n, C) lattice read trilinearly at a (size, size, size) grid -> float32.

    The lattice-to-lattice reader (a preset's look at the map size, the explorer's
    maps at its LUT size). At lattice nodes trilinear interpolation is separable: a
    (size, n) linear interpolation along each axis in turn, in float64 (a millisecond,
    where a pass over the size^3 nodes as pixels takes tens). The lattice itself when
    ``n == size``. LUT export samples with :func:`apply_color_map` instead, so that a
    LUT holds what the pixels get.
    """
    n = lattice.shape[0]
    if n == size:
        return np.asarray(lattice, dtype=np.float32)
    position = np.linspace(0.0, n - 1.0, size)
    low = np.minimum(position.astype(np.int64), n - 2)
    frac = position - low
    weights = np.zeros((size, n))
    weights[np.arange(size), low] = 1.0 - frac
    weights[np.arange(size), low + 1] += frac
    out = np.einsum("ai,ijkc->ajkc", weights, np.asarray(lattice, dtype=np.float64))
    out = np.einsum("bj,ajkc->abkc", weights, out)
    out = np.einsum("ck,abkd->abcd", weights, out)
    return out.astype(np.float32)


def interpolate_lattice(values: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """(n, n, n, C) lattice values read trilinearly at (N, 3) colours in [0, 1] -> (N, C)
    float64 (the fits' reader: any number of channels, float64 throughout; pixels go
    through :func:`apply_color_map`)."""
    from scipy.ndimage import map_coordinates

    n = values.shape[0]
    coords = (np.clip(colors, 0.0, 1.0) * (n - 1)).T
    return np.stack([map_coordinates(values[..., c], coords, order=1, mode="nearest")
                     for c in range(values.shape[-1])], axis=1)


def identity_map(bins: int, dtype=np.float32) -> np.ndarray:
    """(bins, bins, bins, 3) map sending every bin to its own colour."""
    axis = np.linspace(0.0, 1.0, bins, dtype=dtype)
    return np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1)


def blend_map(color_map: np.ndarray, strength: float) -> np.ndarray:
    """``(1 - t) x + t T(x)`` on the grid: the map at strength t (``map.strength``)."""
    return (1.0 - strength) * identity_map(color_map.shape[0], color_map.dtype) \
        + strength * color_map


def apply_color_map(rgb: np.ndarray, color_map: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """Move every pixel through a colour map by trilinear interpolation.

    Parameters
    ----------
    rgb : (..., 3) float, encoded colours in [0, 1] (clipped).
    color_map : (n, n, n, 3) new colour of each grid bin, n >= 2.
    strength : t in [0, 1]; result is (1 - t) x + t T(x).

    Returns
    -------
    (..., 3) float32 array, values in [0, 1] when the map's are.
    """
    if color_map.ndim != 4 or color_map.shape[3] != 3 or len(set(color_map.shape[:3])) != 1 \
            or color_map.shape[0] < 2:  # n < 2: the interpolation would read past the table
        raise ValueError("color_map must be (n, n, n, 3) with n >= 2")
    if not 0.0 <= strength <= 1.0:
        raise ValueError("strength must be in [0, 1]")
    shape = rgb.shape
    colors = np.ascontiguousarray(rgb, dtype=np.float32).reshape(-1, 3)
    table = np.ascontiguousarray(color_map, dtype=np.float32)
    if numpy_first(_trilinear, colors.shape[0], _NUMPY_PIXELS) and np.isfinite(colors).all():
        return _trilinear_numpy(colors, table, strength).reshape(shape)
    out = np.empty_like(colors)
    in_bands(_trilinear, colors.shape[0], colors, table, np.float32(strength), out,
             min_band=4096)
    return out.reshape(shape)


#: Colours up to which :func:`apply_color_map` runs its numpy twin while ``_trilinear`` has
#: not run in the process: a photo solved at full size (up to 1.5 megapixels) is graded
#: before numba's compiler would have loaded (docs/benchmarks.md).
_NUMPY_PIXELS = 1_500_000


def _trilinear_numpy(colors: np.ndarray, table: np.ndarray, strength: float) -> np.ndarray:
    """``_trilinear`` with numpy, bit for bit (float64 arithmetic in the kernel's order,
    rounded to float32 once), for finite (N, 3) float32 ``colors``; in chunks that stay
    in the CPU's cache."""
    out = np.empty(colors.shape, np.float32)
    for start in range(0, colors.shape[0], 16384):
        out[start:start + 16384] = _trilinear_chunk(colors[start:start + 16384], table,
                                                    strength)
    return out


def _trilinear_chunk(colors: np.ndarray, table: np.ndarray, strength: float) -> np.ndarray:
    n = table.shape[0]
    x = np.clip(colors.astype(np.float64), 0.0, 1.0)
    position = x * (n - 1)
    index = np.minimum(position.astype(np.int64), n - 2)
    frac = position - index
    fr, fg, fb = frac[:, 0:1], frac[:, 1:2], frac[:, 2:3]
    flat = table.reshape(-1, 3)
    base = (index[:, 0] * n + index[:, 1]) * n + index[:, 2]

    def node(di: int, dj: int, dk: int) -> np.ndarray:
        return flat[base + ((di * n + dj) * n + dk)].astype(np.float64)

    c00 = node(0, 0, 0) * (1 - fb) + node(0, 0, 1) * fb
    c01 = node(0, 1, 0) * (1 - fb) + node(0, 1, 1) * fb
    c10 = node(1, 0, 0) * (1 - fb) + node(1, 0, 1) * fb
    c11 = node(1, 1, 0) * (1 - fb) + node(1, 1, 1) * fb
    c0 = c00 * (1 - fg) + c01 * fg
    c1 = c10 * (1 - fg) + c11 * fg
    value = c0 * (1 - fr) + c1 * fr
    t = float(np.float32(strength))
    return ((1 - t) * x + t * value).astype(np.float32)


def keep_lightness(color_map: np.ndarray, encoding) -> np.ndarray:
    """A colour map that keeps each input colour's Oklab lightness (``map.preserve_luminance``).

    Every node's output takes the hue and chroma (Oklab a, b) of the map and
    the lightness L of the node's own colour, both computed in the working
    space's own terms (``encoding.to_oklab``: its decoding and primaries);
    colours outside the working space's unit cube are clipped onto it.

    Parameters
    ----------
    color_map : (n, n, n, 3) working-space colours in [0, 1].
    encoding : the grade's :class:`wbcgrade.color.colorspace.ColorEncoding`.

    Returns
    -------
    (n, n, n, 3) float32 in [0, 1].
    """
    source = encoding.to_oklab(identity_map(color_map.shape[0], np.float64))
    mapped = encoding.to_oklab(np.asarray(color_map, dtype=np.float64))
    mapped[..., 0] = source[..., 0]
    return encoding.from_oklab(mapped)


def monotone_lightness(color_map: np.ndarray,
                       luma_weights: np.ndarray | None = None) -> np.ndarray:
    """A colour map whose output luma never decreases when an input channel increases.

    Where a transport map is not monotone in lightness, two neighbouring
    colours of a flat area swap their order of brightness after grading (the
    8x8 JPEG blocks of a sky turn into a checkerboard of reversed steps). The
    output luma ``Y(x) = w . T(x)`` of the lattice is replaced, along each
    axis in turn, by the mean of its running maximum from below and its
    running minimum from above (both non-decreasing, and each pass keeps the
    earlier axes' order), and every node's colour is moved by the change
    along grey (the hue and chroma differences between channels are kept);
    where that would leave the cube, the part a clipped channel cannot take
    goes to the channels that still have room, so every node reaches its
    target luma and the order holds at the cube's faces too.

    Parameters
    ----------
    color_map : (n, n, n, 3) working-space colours in [0, 1].
    luma_weights : (3,) the working encoding's luma weights, summing to 1
        (default sRGB's, :data:`wbcgrade.color.colorspace.SYCC_LUMA`; other working
        spaces have their own, ``ColorEncoding.luma_weights``).

    Returns
    -------
    (n, n, n, 3) float32 in [0, 1].
    """
    weights = np.asarray(SYCC_LUMA if luma_weights is None else luma_weights, np.float64)
    table = np.asarray(color_map, dtype=np.float64)
    luma = table @ weights
    target = luma.copy()
    for axis in range(3):
        rising = np.maximum.accumulate(target, axis=axis)
        falling = np.flip(np.minimum.accumulate(np.flip(target, axis=axis), axis=axis),
                          axis=axis)
        target = 0.5 * (rising + falling)
    out = np.clip(table + (target - luma)[..., None], 0.0, 1.0)
    for _ in range(3):  # each pass saturates at least one more channel of a node
        remaining = target - out @ weights
        room = np.where(remaining[..., None] > 0, out < 1.0, out > 0.0)
        share = room @ weights
        movable = (np.abs(remaining) > 1e-12) & (share > 0)
        if not movable.any():
            break
        step = np.where(movable, remaining / np.where(movable, share, 1.0), 0.0)
        out = np.clip(out + step[..., None] * room, 0.0, 1.0)
    return out.astype(np.float32)


#: Luma of the look family (Rec.709 weights on encoded values) that toning is a function of
#: (the same weights as :data:`wbcgrade.color.look.statistics.LUMA`; imported from the
#: colour space here, as the look package imports this module).
TONE_LUMA = np.array(REC709_LUMA)


def monochrome_toning(color_map: np.ndarray, tol: float = 2e-3
                      ) -> tuple[np.ndarray, np.ndarray] | None:
    """The toning of a black-and-white (or toned) colour map, None for a colour one.

    A map is monochrome when every node's output is ``Y + t(Y)``: its luma plus
    a tint that depends on that luma alone (zero for black and white), read
    off the map's grey axis. Returns (lumas (m,) increasing, tints (m, 3)).
    """
    table = np.asarray(color_map, dtype=np.float64)
    m = table.shape[0]
    grey = table[np.arange(m), np.arange(m), np.arange(m)]
    lumas = grey @ TONE_LUMA
    order = np.argsort(lumas, kind="stable")
    lumas, tints = lumas[order], grey[order] - lumas[order, None]
    flat = table.reshape(-1, 3)
    y = flat @ TONE_LUMA
    expected = y[:, None] + np.stack([np.interp(y, lumas, tints[:, c]) for c in range(3)], 1)
    if float(np.max(np.abs(flat - expected))) > tol:
        return None
    return lumas, tints


def to_monochrome(rgb: np.ndarray, toning: tuple[np.ndarray, np.ndarray],
                  out: np.ndarray | None = None) -> np.ndarray:
    """Colours (..., 3) -> their luma plus the toning's tint at that luma (float32, clipped
    to [0, 1]); ``out`` may be ``rgb`` itself."""
    lumas, tints = toning
    flat = np.asarray(rgb, dtype=np.float32).reshape(-1, 3)
    result = np.empty(flat.shape, np.float32) if out is None else out.reshape(-1, 3)
    step = 1 << 20
    for start in range(0, len(flat), step):
        part = flat[start:start + step].astype(np.float64)
        y = np.clip(part @ TONE_LUMA, 0.0, 1.0)
        toned = y[:, None] + np.stack([np.interp(y, lumas, tints[:, c]) for c in range(3)], 1)
        result[start:start + step] = np.clip(toned, 0.0, 1.0)
    return result.reshape(np.shape(rgb))


def monochrome_map(color_map: np.ndarray) -> np.ndarray:
    """The colour map made exactly black and white (or toned): every node's output
    becomes its luma plus the tint the map gives grey of that luma. (n, n, n, 3) float32."""
    table = np.asarray(color_map, dtype=np.float64)
    m = table.shape[0]
    grey = table[np.arange(m), np.arange(m), np.arange(m)]
    lumas = grey @ TONE_LUMA
    order = np.argsort(lumas, kind="stable")
    toning = (lumas[order], grey[order] - lumas[order, None])
    return to_monochrome(table.astype(np.float32), toning)
