"""Regular grids with a separable Gaussian kernel (:class:`GridGeometry`)."""

from __future__ import annotations

import math
import threading
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from wbcgrade.core._cpu import fast_cpu, parallel_map
from wbcgrade.core.geometry.base import (
    PARALLEL_BINS,
    Geometry,
    _apply_in_parallel,
    _check_gamma,
    _gibbs,
    _output,
)
from wbcgrade.core.geometry.logsum import AxisKernel, logsumexp_product, shifted_log_product

__all__ = ["GridGeometry"]

#: Largest scratch array (bytes) a thread keeps between kernel products; larger
#: products allocate theirs each time (a 64^3 stack of ten histograms is 21 MB).
_SCRATCH_BYTES = 32 << 20
_scratch_arrays = threading.local()


def _scratch(size: int, dtype: np.dtype) -> NDArray:
    """A flat array of ``size`` entries for this thread's intermediate products."""
    dtype = np.dtype(dtype)
    if size * dtype.itemsize > _SCRATCH_BYTES:
        return np.empty(size, dtype)
    kept = getattr(_scratch_arrays, dtype.char, None)
    if kept is None or kept.size < size:
        kept = np.empty(size, dtype)
        setattr(_scratch_arrays, dtype.char, kept)
    return kept[:size]


class GridGeometry(Geometry):
    """Regular grid on ``[0, 1]^d`` with squared Euclidean cost and a separable kernel.

    Points sit at ``linspace(0, 1, n)`` on each axis (POT's convention for
    ``convolutional_barycenter2d``), and ``K = exp(-|x - y|^2 / gamma)`` factors
    into one ``(n, n)`` kernel per axis.

    Parameters
    ----------
    shape : tuple of int
        Number of bins on each axis, e.g. ``(128, 128, 128)``.
    gamma : float
        Entropic regularisation (``gamma = 2 sigma^2`` for a Gaussian of
        standard deviation sigma, in the units of the unit cube).
    dtype : numpy dtype, default float64
        Precision of ``apply``. float32 halves the cost but only suits wide
        kernels on coarse grids; the barycenter falls back to float64 by itself
        when float32 cannot represent the computation.
    """

    def __init__(
        self, shape: int | tuple[int, ...], gamma: float, dtype: np.dtype | type = np.float64
    ):
        shape = (int(shape),) if np.isscalar(shape) else tuple(int(n) for n in shape)
        if not shape or any(n < 2 for n in shape):
            raise ValueError(f"grid shape must have at least 2 bins on each axis, got {shape}")
        self.shape = shape
        self.gamma = _check_gamma(gamma)
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.float32, np.float64):
            raise ValueError(f"dtype must be float32 or float64, got {self.dtype}")
        self.axes = [np.linspace(0.0, 1.0, n) for n in shape]
        costs = [np.subtract.outer(x, x) ** 2 for x in self.axes]
        self._log_kernels = [-c / self.gamma for c in costs]
        self.kernels = [_gibbs(c, self.gamma, self.dtype) for c in costs]
        self._axis_kernels = [AxisKernel(lk) for lk in self._log_kernels]
        #: (bins before, bins of, bins after) each axis within one histogram, and whether
        #: the axis is the last: ``apply_into``'s views (no ``np.prod`` per product).
        self._axis_views = [(math.prod(shape[:axis]), n, math.prod(shape[axis + 1:]),
                             axis == len(shape) - 1, kernel)
                            for axis, (n, kernel) in enumerate(zip(shape, self.kernels))]
        #: Entries the last ``log_apply`` recomputed one by one (see ``log_apply``).
        self.last_log_repairs = 0

    @classmethod
    def with_width(
        cls, shape: int | tuple[int, ...], width: float, dtype: np.dtype | type = np.float64
    ) -> GridGeometry:
        """Grid whose kernel is a Gaussian of standard deviation ``width`` bins.

        ``gamma = 2 (width / (n - 1))^2`` with n the largest axis length.
        """
        shape = (int(shape),) if np.isscalar(shape) else tuple(int(n) for n in shape)
        if not np.isfinite(width) or width <= 0:
            raise ValueError(f"kernel width must be positive, got {width!r}")
        return cls(shape, 2.0 * (float(width) / (max(shape) - 1)) ** 2, dtype)

    @property
    def width(self) -> float:
        """Standard deviation of the Gaussian kernel in bins of the largest axis."""
        return float(np.sqrt(self.gamma / 2.0) * (max(self.shape) - 1))

    def __repr__(self) -> str:
        return f"GridGeometry(shape={self.shape}, gamma={self.gamma:.4g}, dtype={self.dtype.name})"

    @property
    def log_apply_work(self) -> int:
        return self.size * sum(self.shape)

    @cached_property
    def points(self) -> NDArray:
        grids = np.meshgrid(*self.axes, indexing="ij")
        return np.stack([g.ravel() for g in grids], axis=1)

    def with_dtype(self, dtype: np.dtype | type) -> GridGeometry:
        return GridGeometry(self.shape, self.gamma, dtype)

    def cost_matrix(self) -> NDArray:
        pts = self.points
        return ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)

    def _split(self, values: NDArray, axis: int) -> tuple[int, int, int]:
        """(before, n, after) sizes to view ``values`` as 3-D around grid ``axis``."""
        lead = values.ndim - self.ndim
        before = int(np.prod(values.shape[: lead + axis]))
        after = int(np.prod(self.shape[axis + 1 :]))
        return before, self.shape[axis], after

    def apply_into(self, block: NDArray, out: NDArray) -> None:
        """K x for a contiguous block of histograms ``(m, *shape)``, written into ``out``.

        The axis products alternate between ``out`` and one scratch array of this
        thread (kept for the next call when it is at most ``_SCRATCH_BYTES``): the
        same BLAS products as allocating each intermediate, without a fresh array
        (and its page faults) per axis.
        """
        m = block.shape[0]
        views = self._axis_views
        if len(views) > 1 and np.may_share_memory(block, out):
            self._apply_into_allocating(block, out)
            return
        scratch = _scratch(out.size, out.dtype) if len(views) > 1 else out
        # the last axis lands in out: walking back, every other axis before it in scratch
        targets = [out if (len(views) - 1 - axis) % 2 == 0 else scratch
                   for axis in range(len(views))]
        source = block
        for (before, n, after, last, kernel), target in zip(views, targets):
            before *= m
            if last:  # after == 1: one product with the transposed kernel
                np.matmul(source.reshape(before, n), kernel.T, out=target.reshape(before, n))
            else:
                np.matmul(kernel, source.reshape(before, n, after),
                          out=target.reshape(before, n, after))
            source = target

    def _apply_into_allocating(self, block: NDArray, out: NDArray) -> None:
        """:meth:`apply_into` when ``out`` may overlap ``block``: fresh intermediates."""
        m = block.shape[0]
        for before, n, after, last, kernel in self._axis_views:
            before *= m
            if last:  # after == 1: one product with the transposed kernel
                np.matmul(block.reshape(before, n), kernel.T, out=out.reshape(before, n))
            else:
                block = np.matmul(kernel, block.reshape(before, n, after))

    def apply(self, values: NDArray) -> NDArray:
        self._check_values(values)
        if values.size == self.size and self.ndim >= 2 and self.size >= PARALLEL_BINS:
            return self._apply_one(values)
        return _apply_in_parallel(self, values, self.apply_into)

    @cached_property
    def _trailing(self) -> GridGeometry:
        """The grid without its first axis (same gamma, hence the same kernels)."""
        return GridGeometry(self.shape[1:], self.gamma, self.dtype)

    def _apply_one(self, values: NDArray) -> NDArray:
        """K x for one large histogram, split over threads: rows of the first axis's
        product, then slices for the other axes."""
        n = self.shape[0]
        x = np.ascontiguousarray(values, dtype=self.dtype).reshape(n, -1)
        first, out = np.empty_like(x), np.empty_like(x)
        kernel, rest = self.kernels[0], self._trailing

        def first_axis(lo: int, hi: int) -> None:
            np.matmul(kernel[lo:hi], x, out=first[lo:hi])

        def other_axes(lo: int, hi: int) -> None:
            block = first[lo:hi].reshape(hi - lo, *rest.shape)
            rest.apply_into(block, out[lo:hi].reshape(hi - lo, *rest.shape))

        with fast_cpu():
            parallel_map(first_axis, n)
            parallel_map(other_axes, n)
        return out.reshape(values.shape)

    #: Kernel entries per second and core of the shifted log-domain product,
    #: used by the barycenter solver to estimate the log domain's cost before
    #: running it. Calibrated on the 128^3 gradient with ten photo histograms
    #: (1.5-bin kernel): ~4800 products of 8e8 entries in 29 CPU-minutes
    #: (0.36 s each; the second pass redoing ~30% of the results), rounded down.
    log_apply_rate = 2.0e9
    #: One histogram's log product is a few BLAS products: solvers run each
    #: histogram's recursion in its own thread (:meth:`log_apply_one`).
    log_per_histogram = True
    is_grid = True

    def with_grid(self, shape: tuple[int, ...], gamma: float) -> GridGeometry:
        """A grid of another ``shape`` and ``gamma``, in the same precision."""
        return GridGeometry(shape, gamma, self.dtype)

    def separable_factors(self) -> list[tuple[NDArray, NDArray]]:
        """Each axis's kernel (in ``self.dtype``) and its points ``linspace(0, 1, n)``."""
        return list(zip(self.kernels, self.axes))

    def log_apply(self, log_values: NDArray) -> NDArray:
        """Log-domain kernel product, one axis at a time, each line shifted by its maximum.

        Each 1-D product is a plain matrix product of ``exp(f - max f)`` (BLAS),
        followed by ``log`` and the shift; the few results that come out so
        small that dropped (underflowed) terms could matter are recomputed
        with an exact per-entry log-sum-exp, so the result is exact to rounding
        whatever the range of ``f`` (as :meth:`_log_apply_direct`, 30-100x
        faster when few entries need repair). Histograms are spread over the
        core's threads.
        """
        return self._shifted_log_apply(log_values, None)[0]

    def log_apply_into(self, log_values: NDArray, out: NDArray) -> NDArray:
        """:meth:`log_apply` into ``out``, which may be ``log_values`` (computed in place)."""
        return self._shifted_log_apply(log_values, None, out)[0]

    def signed_log_apply(self, log_abs: NDArray, signs: NDArray, out: NDArray | None = None,
                         out_signs: NDArray | None = None) -> tuple[NDArray, NDArray]:
        """``log |K x|`` and ``sign(K x)`` for ``x = signs * exp(log_abs)``, exactly (float64).

        Used by the reverse pass, whose adjoints change sign: one signed
        product instead of one for each sign's part. ``out`` and ``out_signs``
        may be the inputs themselves.
        """
        return self._shifted_log_apply(log_abs, signs, out, out_signs)

    def _shifted_log_apply(self, log_values: NDArray, signs: NDArray | None,
                           out: NDArray | None = None, out_signs: NDArray | None = None):
        """The shifted log-domain product, optionally into ``out`` (and ``out_signs``).

        ``out`` may be ``log_values`` itself (and ``out_signs`` ``signs``): each
        histogram is read whole by the first axis's product before the last
        axis's product writes its result, so the product can run in place
        (the log-domain barycenter saves whole states of memory that way).
        """
        self._check_values(log_values)
        x = np.ascontiguousarray(log_values, dtype=np.float64)
        lead = int(np.prod(x.shape[: x.ndim - self.ndim]))
        flat = x.reshape(lead, *self.shape)
        result = _output(out, x)
        out = result.reshape(flat.shape)
        flat_signs = out_signs_flat = None
        if signs is not None:
            flat_signs = np.ascontiguousarray(signs, dtype=np.float64).reshape(flat.shape)
            out_signs = _output(out_signs, x)
            out_signs_flat = out_signs.reshape(flat.shape)
        repairs = np.zeros(lead, dtype=np.int64)

        def work(lo: int, hi: int) -> None:
            for k in range(lo, hi):
                repairs[k] = self.log_apply_one(
                    flat[k], out[k], None if signs is None else flat_signs[k],
                    None if signs is None else out_signs_flat[k])

        with fast_cpu():
            if lead >= 2 and self.size >= PARALLEL_BINS:
                parallel_map(work, lead)
            else:
                work(0, lead)
        self.last_log_repairs = int(repairs.sum())
        return result, out_signs

    def log_apply_one(self, values: NDArray, out: NDArray, signs: NDArray | None = None,
                      out_signs: NDArray | None = None, needed: NDArray | None = None) -> int:
        """``log_apply`` of one histogram ``values`` (``self.shape``) into ``out``.

        ``needed`` (bool, ``self.shape``): only these results must be exact (the
        others are left unspecified, possibly ``-inf``); each axis's product then
        repairs only the intermediate results that reach a needed one. Returns
        the number of results the second and third passes recomputed.
        """
        current, current_signs, repairs = values, signs, 0
        for axis in range(self.ndim):
            before = int(np.prod(self.shape[:axis]))
            n, after = self.shape[axis], int(np.prod(self.shape[axis + 1 :]))
            reach = None
            if needed is not None:  # the later axes mix along axes > axis only
                reach = needed.reshape(before, n, after).any(axis=2, keepdims=True)
            last = axis == self.ndim - 1
            # one axis (a 1-D grid) in place: the product reads its input after writing
            direct = last and not np.may_share_memory(out, current)
            target = out if direct else np.empty(self.shape)
            target_signs = None
            if signs is not None:
                target_signs = out_signs if direct else np.empty(self.shape)
            lines = (before, n, after)
            repairs += shifted_log_product(
                self._axis_kernels[axis], current.reshape(lines), target.reshape(lines),
                None if signs is None else current_signs.reshape(lines),
                None if signs is None else target_signs.reshape(lines), reach)
            current, current_signs = target, target_signs
        if current is not out:
            out[...] = current
            if signs is not None:
                out_signs[...] = current_signs
        return repairs

    def _log_apply_direct(self, log_values: NDArray) -> NDArray:
        """The reference log-domain product: a log-sum-exp for every entry (slow, exact)."""
        self._check_values(log_values)
        out = np.ascontiguousarray(log_values, dtype=np.float64)
        full_shape = out.shape
        for axis, log_kernel in enumerate(self._log_kernels):
            before, n, after = self._split(out, axis)
            result = np.empty((before, n, after))
            logsumexp_product(log_kernel, out.reshape(before, n, after), result)
            out = result.reshape(full_shape)
        return out

