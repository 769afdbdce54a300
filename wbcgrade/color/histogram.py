"""RGB histograms over the encoded [0, 1]^3 colour cube.

Bins sit on ``linspace(0, 1, n)`` per axis (the core's grid convention). Each
colour is spread over its 8 neighbouring bins with trilinear weights ("soft
binning"), so the histogram varies smoothly with the colours and a colour is
recovered exactly as the weighted mean of its bins' positions.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from wbcgrade.color.io.cache import (
    command_cache,
    default_cache_dir,
    entry_path,
    file_key,
    read_entry,
    write_entry,
)
from wbcgrade.color.options import DEFAULT_FLOOR, DEFAULT_MAX_PIXELS
from wbcgrade.core import resample_grid
from wbcgrade.errors import InputError

__all__ = [
    "soft_histogram",
    "image_histogram",
    "resample_histogram",
    "add_floor",
    "grid_points",
    "to_sparse",
    "from_sparse",
    "stack_from_sparse",
    "Deferred",
    "deferred_field",
    "deferred_shape",
    "HistogramCache",
    "default_cache_dir",
    "PaletteSum",
    "pooled_histogram",
    "DEFAULT_FLOOR",
    "DEFAULT_MAX_PIXELS",
]

#: DEFAULT_FLOOR: fraction of the total mass spread uniformly over all bins before
#: fitting. Real photo histograms are sparse; the KL loss needs a target > 0
#: everywhere and the Sinkhorn scalings stay in range when no bin is exactly empty.
#: 1e-4 of the mass (the paper's floor for shapes) changes no visible colour.
#: DEFAULT_MAX_PIXELS: photos larger than this are subsampled (regular stride)
#: before binning. Both are the options' defaults (wbcgrade.color.options).


def grid_points(bins: int) -> np.ndarray:
    """(bins^3, 3) positions of the bins in C order (R slowest, B fastest)."""
    axis = np.linspace(0.0, 1.0, bins)
    r, g, b = np.meshgrid(axis, axis, axis, indexing="ij")
    return np.stack([r.ravel(), g.ravel(), b.ravel()], axis=1)


def soft_histogram(colors: np.ndarray, bins: int, weights: np.ndarray | None = None) -> np.ndarray:
    """Trilinear (soft) histogram of colours.

    Parameters
    ----------
    colors : (N, 3) float, values in [0, 1] (clipped).
    bins : bins per axis, >= 2.
    weights : (N,) non-negative per-colour mass (e.g. alpha), default 1.

    Returns
    -------
    (bins, bins, bins) float64 histogram summing to 1.
    """
    if bins < 2:
        raise InputError("bins must be at least 2")
    colors = np.asarray(colors, dtype=np.float64).reshape(-1, 3)
    if weights is None:
        weights = np.ones(len(colors))
    weights = np.asarray(weights, dtype=np.float64).ravel()
    total = weights.sum()
    if len(colors) == 0 or not total > 0:
        raise InputError("no pixels to build a histogram from (empty or fully transparent image)")
    pos = np.clip(colors, 0.0, 1.0) * (bins - 1)
    base = np.minimum(pos.astype(np.int64), bins - 2)
    frac = pos - base
    hist = np.zeros(bins ** 3)
    for dr in (0, 1):
        wr = frac[:, 0] if dr else 1.0 - frac[:, 0]
        for dg in (0, 1):
            wg = wr * (frac[:, 1] if dg else 1.0 - frac[:, 1])
            for db in (0, 1):
                w = wg * (frac[:, 2] if db else 1.0 - frac[:, 2]) * weights
                index = ((base[:, 0] + dr) * bins + base[:, 1] + dg) * bins + base[:, 2] + db
                hist += np.bincount(index, weights=w, minlength=bins ** 3)
    hist /= hist.sum()
    return hist.reshape(bins, bins, bins)


def image_histogram(rgb: np.ndarray, bins: int, alpha: np.ndarray | None = None,
                    max_pixels: int = DEFAULT_MAX_PIXELS) -> np.ndarray:
    """Soft histogram of an (H, W, 3) encoded image, from a subsampled copy if large.

    Subsampling takes every k-th pixel in both directions (k chosen so that at
    most ``max_pixels`` remain): it keeps the photo's actual colours, whereas
    averaging down would invent mixtures. Alpha, when given (H, W), weights
    each pixel so transparent areas do not count.

    Returns
    -------
    (bins, bins, bins) float64 histogram summing to 1.
    """
    height, width = rgb.shape[:2]
    step = max(1, int(np.ceil(np.sqrt(height * width / max_pixels))))
    sub = rgb[::step, ::step].reshape(-1, 3)
    weights = None if alpha is None else np.clip(alpha[::step, ::step].ravel(), 0.0, 1.0)
    return soft_histogram(sub, bins, weights)


def resample_histogram(hist: np.ndarray, bins: int) -> np.ndarray:
    """Re-bin an (n, n, n) histogram onto a (bins, bins, bins) grid, normalised to sum 1.

    :func:`wbcgrade.core.resample_grid`: soft binning (the adjoint of trilinear
    interpolation: mass and mean colour kept) to a coarser grid, the density
    interpolated to a finer one. The histogram itself when ``bins == n``.
    """
    return hist if hist.shape[0] == bins else resample_grid(hist, (bins,) * 3, mass=1.0)


def add_floor(hist: np.ndarray, floor: float = DEFAULT_FLOOR) -> np.ndarray:
    """Mix a histogram with the uniform one: ``(1 - floor) h / sum(h) + floor / N``."""
    hist = np.asarray(hist, dtype=np.float64)
    hist = hist / hist.sum()
    if floor <= 0:
        return hist
    return (1.0 - floor) * hist + floor / hist.size


def to_sparse(hist: np.ndarray, threshold: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices (int32) and float32 values of the bins above ``threshold`` (renormalised)."""
    flat = np.asarray(hist, dtype=np.float64).ravel()
    index = np.flatnonzero(flat > threshold)
    values = flat[index]
    values = values / values.sum()
    return index.astype(np.int32), values.astype(np.float32)


def from_sparse(index: np.ndarray, values: np.ndarray, bins: int) -> np.ndarray:
    """Dense (bins, bins, bins) float64 histogram from :func:`to_sparse` output."""
    hist = np.zeros(bins ** 3)
    hist[index] = values
    return (hist / hist.sum()).reshape(bins, bins, bins)


def _fill_sparse(row: np.ndarray, index: np.ndarray, values: np.ndarray) -> None:
    """Write :func:`from_sparse` of ``(index, values)`` into a zeroed flat float64 ``row``
    (the same numbers: the same scatter, sum and division, with no new arrays)."""
    row[index] = values
    row /= row.sum()


def stack_from_sparse(parts: Sequence[np.ndarray | tuple[np.ndarray, np.ndarray]],
                      bins: int) -> np.ndarray:
    """(S, bins, bins, bins) float64: each part a dense histogram, or the ``(index, values)``
    of :func:`to_sparse` made dense as :func:`from_sparse` makes it, written into one
    array (no per-histogram arrays, no stacking copy)."""
    out = np.zeros((len(parts), bins ** 3))
    for row, part in zip(out, parts):
        if isinstance(part, tuple):
            _fill_sparse(row, *part)
        else:
            row[:] = np.asarray(part).ravel()
    return out.reshape(len(parts), bins, bins, bins)


class Deferred:
    """An array made when it is first read, through a :class:`deferred_field`: ``make(*args)``
    gives it; its ``shape`` is known before. Pickled or copied, it is the array itself."""

    __slots__ = ("shape", "_make", "_args")

    def __init__(self, shape: tuple[int, ...], make: Callable[..., np.ndarray], *args) -> None:
        self.shape = tuple(int(n) for n in shape)
        self._make, self._args = make, args

    def make(self) -> np.ndarray:
        return self._make(*self._args)

    def __reduce__(self):
        return (np.asarray, (self.make(),))


class deferred_field:  # noqa: N801 - used as a descriptor, like property
    """A dataclass field that may be given a :class:`Deferred`: made, once, when first
    read (an array given is kept as it is). :func:`deferred_shape` says its shape
    without making it. The field has no default."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = f"_deferred_{name}"

    def __get__(self, obj, owner=None):
        if obj is None:  # the class's attribute: no default (dataclasses reads this)
            raise AttributeError(self.slot)
        value = obj.__dict__[self.slot]
        if isinstance(value, Deferred):
            value = obj.__dict__[self.slot] = value.make()
        return value

    def __set__(self, obj, value) -> None:
        obj.__dict__[self.slot] = value


def deferred_shape(obj, name: str) -> tuple[int, ...]:
    """The shape of ``obj``'s :class:`deferred_field` ``name``, made or not."""
    return tuple(np.shape(obj.__dict__[f"_deferred_{name}"]))


class HistogramCache:
    """On-disk cache of style-photo histograms.

    Keyed by the file's absolute path, modification time, size, the number of
    bins, the subsampling limit and the colour spaces (``space``: the
    OpenColorIO config and the working space the colours were converted into),
    so an edited photo is re-read. Entries are small sparse ``.npz`` files at the
    top of the cache folder, each beside the histogram re-binned onto the grids a
    grade asks for (:meth:`get_resampled`, keyed the same way and the grid)
    (:mod:`wbcgrade.color.io.cache`: a damaged entry is rebuilt, one that cannot be
    written is one warning; caching never makes a run fail).
    """

    VERSION = 1

    def __init__(self, folder: str | os.PathLike | None = None, enabled: bool = True):
        """``folder`` None: the command's (``cache.command_cache``: its cache folder, else
        the default), and off when the command turned caching off."""
        if folder is None:
            folder, on = command_cache()
            enabled = enabled and on
        self.folder = Path(folder)
        self.enabled = enabled

    def _key(self, path: Path, bins: int, max_pixels: int, space: str = "",
             at: int | None = None) -> Path:
        text = (f"{self.VERSION}|{file_key(path)}|{bins}|{max_pixels}"
                + (f"|{space}" if space else "") + (f"|at {at}" if at is not None else ""))
        return entry_path(self.folder, "", text)

    def get(self, path: Path, bins: int, max_pixels: int = DEFAULT_MAX_PIXELS,
            space: str = "") -> np.ndarray | None:
        """The cached histogram (bins, bins, bins), or None."""
        sparse = self.get_sparse(path, bins, max_pixels, space)
        return None if sparse is None else from_sparse(*sparse, bins)

    def get_sparse(self, path: Path, bins: int, max_pixels: int = DEFAULT_MAX_PIXELS,
                   space: str = "") -> tuple[np.ndarray, np.ndarray] | None:
        """The cached histogram as :func:`from_sparse` takes it, ``(index, values)``, or
        None."""
        if not self.enabled:
            return None
        try:
            data = read_entry(self._key(path, bins, max_pixels, space))
            index, values = data["index"], data["values"]
            if (index.ndim != 1 or index.shape != values.shape or not len(index)
                    or index.min() < 0 or index.max() >= bins ** 3):
                return None
            return index, values
        except Exception:  # noqa: BLE001 - any damage is a miss: computed again, rewritten
            return None

    def get_resampled(self, path: Path, bins: int, at: int,
                      max_pixels: int = DEFAULT_MAX_PIXELS,
                      space: str = "") -> np.ndarray | None:
        """The cached :func:`resample_histogram` of the photo's histogram on ``bins``
        onto ``at`` bins (at, at, at), or None. Keyed as the histogram is (the photo's
        path, time and size, the settings), so an edited photo is resampled again."""
        if not self.enabled:
            return None
        try:
            data = read_entry(self._key(path, bins, max_pixels, space, at))
            hist = data["hist"]
            return hist if hist.shape == (at,) * 3 and hist.dtype == np.float64 else None
        except Exception:  # noqa: BLE001 - any damage is a miss
            return None

    def put_resampled(self, path: Path, bins: int, at: int, hist: np.ndarray,
                      max_pixels: int = DEFAULT_MAX_PIXELS, space: str = "") -> None:
        """Store what :meth:`get_resampled` gives back (failures are logged, not raised)."""
        if not self.enabled:
            return
        try:
            target = self._key(path, bins, max_pixels, space, at)
        except OSError:  # the photo is gone
            return
        write_entry(target, hist=np.asarray(hist, dtype=np.float64))

    def put(self, path: Path, bins: int, hist: np.ndarray,
            max_pixels: int = DEFAULT_MAX_PIXELS, space: str = "") -> np.ndarray:
        """Store a histogram (failures are logged, not raised) -> the histogram as stored.

        Use the returned histogram: it is what :meth:`get` gives back later (values
        kept in float32), so a first run and the runs that read the cache compute
        the same things (a set's look, keyed by its histograms, is found again).
        """
        return from_sparse(*self.put_sparse(path, bins, hist, max_pixels, space), bins)

    def put_sparse(self, path: Path, bins: int, hist: np.ndarray,
                   max_pixels: int = DEFAULT_MAX_PIXELS,
                   space: str = "") -> tuple[np.ndarray, np.ndarray]:
        """:meth:`put`, the histogram as stored given back as :meth:`get_sparse` gives it:
        ``(index, values)``, which :func:`from_sparse` makes what :meth:`get` returns."""
        index, values = to_sparse(hist)
        if self.enabled:
            try:
                target = self._key(path, bins, max_pixels, space)
            except OSError:  # the photo is gone: nothing to key its entry by
                return index, values
            write_entry(target, compress=True, index=index, values=values)
        return index, values


class PaletteSum:
    """Running sum of normalised histograms whose result does not depend on their order.

    The palette of a series (a batch's ``consistent`` grade, a video shot): every
    photo counts once whatever its size. Each histogram is rounded to fixed
    point (2^-40 of its mass) and summed in int64, so photos may arrive in
    any order (process pool, Dask) and the pooled palette, hence the series
    grade, is bit-for-bit the same.

    >>> import numpy as np
    >>> pool = PaletteSum()
    >>> pool.add(np.array([3.0, 1.0])); pool.add(np.array([0.0, 5.0]))
    >>> pool.result().tolist()
    [0.375, 0.625]
    """

    _ONE = float(2 ** 40)

    def __init__(self) -> None:
        self.total: np.ndarray | None = None
        self.count = 0

    def add(self, hist: np.ndarray) -> None:
        """Add a histogram (normalised here: every photo counts once)."""
        fixed = np.rint(np.asarray(hist, dtype=np.float64) / hist.sum() * self._ONE)
        fixed = fixed.astype(np.int64)
        self.total = fixed if self.total is None else self.total + fixed
        self.count += 1

    def result(self) -> np.ndarray:
        """The pooled histogram, summing to 1."""
        if self.total is None:
            raise ValueError("no histograms to pool")
        return self.total / self.total.sum()


def pooled_histogram(histograms: list[np.ndarray]) -> np.ndarray:
    """The palette of a series: the photos' normalised histograms summed, normalised."""
    pool = PaletteSum()
    for hist in histograms:
        pool.add(hist)
    return pool.result()
