"""Geometries: where the bins sit and how the Gibbs kernel ``K = exp(-C / gamma)`` acts.

A geometry is the only object that knows how to apply its kernel; solvers
never look inside it (the OTT-JAX split). Two kinds share one interface:

- :class:`GridGeometry`: bins on a regular grid with points at
  ``linspace(0, 1, n)`` on each axis and squared Euclidean cost. The kernel is
  separable, so applying it costs one small matrix product per axis.
- :class:`DenseGeometry`: an explicit ``(N, N)`` cost matrix (for example
  squared geodesic distances on a sphere).

Both apply the kernel in the scaling domain (``apply``, fast) and in the log
domain (``log_apply``, exact for any dynamic range), and both are symmetric,
which the reverse pass of the barycenter relies on. On grids the log-domain
product is itself made of BLAS products of shifted lines, checked and
repaired where underflow could matter (:func:`_shifted_log_product`); the
dense geometry computes a log-sum-exp per entry.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from wbcgrade.core._cpu import fast_cpu, parallel_map
from wbcgrade.core._jit import compiled

__all__ = ["Geometry", "GridGeometry", "DenseGeometry", "refine_grid", "resample_grid",
           "binning_matrix"]


@compiled(parallel=True, cache=True, nogil=True)
def _logsumexp_product(log_kernel, values, out):  # pragma: no cover - compiled
    """out[p, i, q] = log sum_j exp(log_kernel[i, j] + values[p, j, q]), exactly.

    Each output is shifted by its own maximum, so nothing under- or overflows
    whatever the range of ``values`` (``-inf`` entries stand for zeros).
    """
    n_batch, n_in, n_right = values.shape
    n_out = log_kernel.shape[0]
    for p in numba.prange(n_batch):
        peak = np.empty(n_right)
        total = np.empty(n_right)
        for i in range(n_out):
            peak[:] = -np.inf
            for j in range(n_in):
                lk = log_kernel[i, j]
                for q in range(n_right):
                    v = lk + values[p, j, q]
                    if v > peak[q]:
                        peak[q] = v
            total[:] = 0.0
            for j in range(n_in):
                lk = log_kernel[i, j]
                for q in range(n_right):
                    if peak[q] > -np.inf:
                        total[q] += np.exp(lk + values[p, j, q] - peak[q])
            for q in range(n_right):
                if peak[q] == -np.inf:
                    out[p, i, q] = -np.inf
                else:
                    out[p, i, q] = peak[q] + np.log(total[q])


@compiled(nogil=True, cache=True)
def _repair_entries(log_kernel, values, signs, signed, mask, out, out_signs):  # pragma: no cover
    """``out[p, i, q] = log |sum_j s_j exp(log_kernel[i, j] + values[p, j, q])|`` where ``mask``.

    ``s_j = signs[p, j, q]`` when ``signed`` (then the sign of the sum goes to
    ``out_signs``), else 1. The per-entry log-sum-exp of
    :func:`_logsumexp_product`, shifted by each entry's own peak; the last
    resort of :func:`_shifted_log_product`.
    """
    n_batch, n_out, n_right = mask.shape
    n_in = values.shape[1]
    for p in range(n_batch):
        for i in range(n_out):
            for q in range(n_right):
                if not mask[p, i, q]:
                    continue
                peak = -np.inf
                for j in range(n_in):
                    v = log_kernel[i, j] + values[p, j, q]
                    if v > peak:
                        peak = v
                total = 0.0
                if peak > -np.inf:
                    for j in range(n_in):
                        v = log_kernel[i, j] + values[p, j, q] - peak
                        if v > -50.0:  # below e^-50 of the peak: nothing in float64
                            total += np.exp(v) * (signs[p, j, q] if signed else 1.0)
                out[p, i, q] = peak + np.log(np.abs(total)) if total != 0.0 else -np.inf
                if signed:
                    out_signs[p, i, q] = np.sign(total)


@compiled(nogil=True, cache=True)
def _block_pass(values, signs, signed, low, block_shift, block_kernel, block_size, out,
                out_signs, still, floor):  # pragma: no cover - compiled
    """Pass 2 of :func:`_shifted_log_product` on the line blocks where ``low`` is set.

    ``block_shift[b, j] = max_{i in block b} log K_ij``, ``block_kernel[b, r, j]
    = exp(log K_{lo+r, j} - block_shift[b, j])`` (0 below ``tiny``). Sets
    ``still`` where the result is below ``floor`` (left for pass 3). Returns
    the number of results recomputed.
    """
    n_batch, n, n_right = values.shape
    n_blocks = block_shift.shape[0]
    acc = np.empty(block_size)
    count = 0
    for p in range(n_batch):
        for b in range(n_blocks):
            lo = b * block_size
            hi = min(lo + block_size, n)
            for q in range(n_right):
                flagged = False
                for i in range(lo, hi):
                    flagged |= low[p, i, q]
                if not flagged:
                    continue
                m = -np.inf
                for j in range(n):
                    v = values[p, j, q] + block_shift[b, j]
                    m = v if v > m else m
                acc[:] = 0.0
                for j in range(n):
                    v = values[p, j, q] + block_shift[b, j] - m
                    if v > -745.0:
                        e = np.exp(v)
                        if signed:
                            e *= signs[p, j, q]
                        for r in range(hi - lo):
                            acc[r] += block_kernel[b, r, j] * e
                for r in range(hi - lo):
                    a = np.abs(acc[r])
                    out[p, lo + r, q] = m + np.log(a)
                    still[p, lo + r, q] = a < floor
                    if signed:
                        out_signs[p, lo + r, q] = np.sign(acc[r])
                count += hi - lo
    return count


#: Output rows per block of the second, per-block shifted pass (see below).
_BLOCK = 8


class _AxisKernel:
    """One axis's kernel in the forms the shifted log-domain product uses.

    ``kernel``: ``exp(log_kernel)``, entries below the smallest normal number
    ``tiny`` set to 0. For each block ``I`` of ``_BLOCK`` output rows,
    ``block_shift[I, j] = max_{i in I} log_kernel[i, j]`` and
    ``block_kernel[I] = exp(log_kernel[I, :] - block_shift[I])`` (entries in
    [0, 1], below ``tiny`` set to 0; rows past the end of the axis are 0).
    """

    def __init__(self, log_kernel: NDArray):
        tiny = np.finfo(np.float64).tiny
        self.log_kernel = np.ascontiguousarray(log_kernel, dtype=np.float64)
        self.kernel = np.exp(self.log_kernel)
        self.kernel[self.kernel < tiny] = 0.0
        n = log_kernel.shape[0]
        n_blocks = -(-n // _BLOCK)
        self.block_shift = np.empty((n_blocks, n))
        self.block_kernel = np.zeros((n_blocks, _BLOCK, n))
        for b in range(n_blocks):
            rows = self.log_kernel[b * _BLOCK : (b + 1) * _BLOCK]
            self.block_shift[b] = rows.max(axis=0)
            k = np.exp(rows - self.block_shift[b])
            k[k < tiny] = 0.0
            self.block_kernel[b, : len(rows)] = k


_NO_SIGNS = np.ones((1, 1, 1))


def _shifted_log_product(
    axis: _AxisKernel,
    values: NDArray,
    out: NDArray,
    signs: NDArray | None = None,
    out_signs: NDArray | None = None,
    needed: NDArray | None = None,
) -> int:
    """``out = log(K exp(values))`` along axis 1 of ``(before, n, after)`` arrays, exactly.

    ``needed`` (bool, broadcastable to the output): only these results must be
    exact; the others keep the first pass's value (possibly ``-inf``).

    With ``signs`` (+1, -1 or 0, same shape), the product of signed values
    ``signs * exp(values)``: ``out = log |K x|`` and ``out_signs = sign(K x)``.

    Pass 1: each line (fixed ``before`` and ``after`` index) is shifted by its
    maximum, so its values become scalings in (0, 1] and one matrix product
    (BLAS) combines them (lines that are all ``-inf`` are skipped). A result
    is exact to rounding when it stands clear of the terms that could have
    been dropped: kernel entries truncated below the smallest normal number
    ``tiny``, scalings and products that under- or flushed to zero; each such
    term is below ``tiny`` (at most ``2 n`` of them), so results above
    ``floor = 2 n tiny / 1e-15`` are kept.

    Pass 2, where a result fell below ``floor`` (far from its line's maximum:
    sparse histograms, steep scalings): each block ``I`` of 8 output rows of
    that line gets its own shift, ``m_I = max_j (values_j + max_{i in I} log
    K_ij)``, applied with the block kernel ``exp(log K_ij - max_{i in I} log
    K_ij)``, again a sum of terms in [0, 1]. For an output ``i`` in ``I`` the
    largest term is at least ``exp(-(14 d + 49) / w)`` relative to ``m_I``
    (``d`` the distance in bins to its argmax, ``w = gamma`` in squared bins):
    about e^-400 on a 128-bin axis with a 1.5-bin kernel, far above ``floor``.

    Pass 3: whatever is still below ``floor`` is recomputed entry by entry
    (:func:`_repair_entries`). Returns the number of results passes 2-3 redid.
    """
    before, n, after = values.shape
    tiny = np.finfo(np.float64).tiny
    floor = 2.0 * n * tiny / 1e-15
    shift = values.max(axis=1)  # (before, after)
    live = shift > -np.inf
    n_live = int(np.count_nonzero(live))
    signed = signs is not None
    with np.errstate(divide="ignore"):
        if n_live < 0.5 * live.size:  # sparse: only the lines that hold mass
            out[...] = -np.inf
            if signed:
                out_signs[...] = 0.0
            if n_live == 0:
                return 0
            lines = values.transpose(0, 2, 1)[live]  # (lines, n)
            lines -= shift[live][:, None]
            np.exp(lines, out=lines)
            if signed:
                lines *= signs.transpose(0, 2, 1)[live]
            scaled = lines @ axis.kernel.T
            del lines
            if signed:
                out_signs.transpose(0, 2, 1)[live] = np.sign(scaled)
                np.abs(scaled, out=scaled)
            low_lines = scaled < floor
            np.log(scaled, out=scaled)
            scaled += shift[live][:, None]
            out.transpose(0, 2, 1)[live] = scaled
            low = np.zeros(values.shape, dtype=bool)
            low.transpose(0, 2, 1)[live] = low_lines
        else:
            shift0 = np.where(live, shift, 0.0)
            scaled_in = values - shift0[:, None, :]
            np.exp(scaled_in, out=scaled_in)
            if signed:
                scaled_in *= signs
            if after == 1:
                scaled = (scaled_in.reshape(before, n) @ axis.kernel.T).reshape(before, n, 1)
            else:
                scaled = np.matmul(axis.kernel, scaled_in)
            del scaled_in
            if signed:
                np.sign(scaled, out=out_signs)
                np.abs(scaled, out=scaled)
            low = scaled < floor
            low &= live[:, None, :]
            np.log(scaled, out=out)
            out += shift0[:, None, :]
            del scaled
        if needed is not None:
            low &= needed
        if not low.any():
            return 0
        still = np.zeros_like(low)
        sign_arg = signs if signed else _NO_SIGNS
        out_sign_arg = out_signs if signed else _NO_SIGNS
        repaired = _block_pass(values, sign_arg, signed, low, axis.block_shift,
                               axis.block_kernel, _BLOCK, out, out_sign_arg, still, floor)
    still &= low
    if still.any():
        _repair_entries(axis.log_kernel, values, sign_arg, signed, still, out, out_sign_arg)
    return repaired


def _output(out: NDArray | None, like: NDArray) -> NDArray:
    """``out`` checked to be a C-contiguous float64 array shaped like ``like``, or a new one."""
    if out is None:
        return np.empty_like(like)
    if out.shape != like.shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError("out must be a C-contiguous float64 array of the values' shape")
    return out


def _gibbs(cost: NDArray, gamma: float, dtype: np.dtype) -> NDArray:
    """exp(-cost / gamma) in ``dtype``, with entries that would be denormal set to 0.

    Denormal operands make matrix products an order of magnitude slower on
    common CPUs; entries below the smallest normal number carry no usable mass.
    """
    kernel = np.exp(-np.asarray(cost, dtype=np.float64) / gamma)
    kernel[kernel < np.finfo(dtype).tiny] = 0.0
    return np.ascontiguousarray(kernel, dtype=dtype)


def _check_gamma(gamma: float) -> float:
    gamma = float(gamma)
    if not np.isfinite(gamma) or gamma <= 0:
        raise ValueError(f"gamma must be a positive finite number, got {gamma!r}")
    return gamma


#: Histograms smaller than this are computed in one thread: below ~50^3 bins the
#: threads' overhead costs more than they save (a 32^3 gradient with S = 10:
#: 0.67 s in one thread, 0.91 s in two).
PARALLEL_BINS = 1 << 17


def _apply_in_parallel(geometry: Geometry, values: NDArray, apply_block) -> NDArray:
    """Run ``apply_block(block, out)`` over the leading histograms, split across threads."""
    geometry._check_values(values)
    x = np.ascontiguousarray(values, dtype=geometry.dtype)
    lead = int(np.prod(x.shape[: x.ndim - geometry.ndim]))
    flat = x.reshape(lead, *geometry.shape)
    out = np.empty_like(flat)

    def work(lo: int, hi: int) -> None:
        apply_block(flat[lo:hi], out[lo:hi])

    with fast_cpu():
        if lead >= 2 and geometry.size >= PARALLEL_BINS:
            parallel_map(work, lead)
        else:
            work(0, lead)
    return out.reshape(x.shape)


class Geometry(ABC):
    """Bins, their ground cost, and the Gibbs kernel ``K = exp(-C / gamma)``.

    Attributes
    ----------
    shape : tuple of int
        Shape of one histogram on this geometry.
    gamma : float
        Entropic regularisation.
    dtype : numpy.dtype
        Precision of the scaling-domain kernel products.
    """

    shape: tuple[int, ...]
    gamma: float
    dtype: np.dtype

    @property
    def ndim(self) -> int:
        """Number of axes of one histogram."""
        return len(self.shape)

    @property
    def size(self) -> int:
        """Number of bins N."""
        return int(np.prod(self.shape))

    @property
    @abstractmethod
    def log_apply_work(self) -> int:
        """Kernel entries one ``log_apply`` visits per histogram (its cost)."""

    @property
    @abstractmethod
    def points(self) -> NDArray | None:
        """Bin coordinates, ``(N, d)`` in C order, or None when unknown."""

    @abstractmethod
    def apply(self, values: NDArray) -> NDArray:
        """Kernel product ``K x`` over the last ``ndim`` axes.

        Parameters
        ----------
        values : ndarray, shape (..., *shape)

        Returns
        -------
        ndarray, shape (..., *shape), in ``self.dtype``
        """

    def apply_into(self, block: NDArray, out: NDArray) -> None:
        """``out = K block`` for a block ``(k, *shape)``, in the calling thread.

        Solvers that spread independent histograms over their own threads call
        this; the default forwards to :meth:`apply`. ``out`` has the block's
        shape and ``self.dtype``.
        """
        out[...] = self.apply(block)

    @abstractmethod
    def log_apply(self, log_values: NDArray) -> NDArray:
        """Log-domain kernel product ``log(K exp(f))`` over the last ``ndim`` axes.

        Exact for any range of ``f`` (float64); ``-inf`` entries stand for zeros.

        Parameters
        ----------
        log_values : ndarray, shape (..., *shape)

        Returns
        -------
        ndarray, shape (..., *shape), float64
        """

    @abstractmethod
    def cost_matrix(self) -> NDArray:
        """The full ``(N, N)`` cost matrix (for tests and small problems only)."""

    def kernel_matrix(self) -> NDArray:
        """The full ``(N, N)`` Gibbs kernel (for tests and small problems only)."""
        return _gibbs(self.cost_matrix(), self.gamma, self.dtype)

    def with_dtype(self, dtype: np.dtype | type) -> Geometry:
        """The same geometry computing in another precision."""
        raise NotImplementedError

    def _check_values(self, values: NDArray) -> None:
        if values.ndim < self.ndim or tuple(values.shape[values.ndim - self.ndim :]) != self.shape:
            raise ValueError(
                f"array of shape {values.shape} does not end with the geometry's shape {self.shape}"
            )


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
        self._axis_kernels = [_AxisKernel(lk) for lk in self._log_kernels]
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
        """K x for a contiguous block of histograms ``(m, *shape)``, written into ``out``."""
        last, m = self.ndim - 1, block.shape[0]
        for axis, kernel in enumerate(self.kernels):
            before = m * int(np.prod(self.shape[:axis]))
            n, after = self.shape[axis], int(np.prod(self.shape[axis + 1 :]))
            if axis == last:  # after == 1: one product with the transposed kernel
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
    _log_apply_rate = 2.0e9

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

    def _signed_log_apply(self, log_abs: NDArray, signs: NDArray) -> tuple[NDArray, NDArray]:
        """``log |K x|`` and ``sign(K x)`` for ``x = signs * exp(log_abs)``, exactly (float64).

        Used by the reverse pass, whose adjoints change sign: one signed
        product instead of one for each sign's part.
        """
        return self._shifted_log_apply(log_abs, signs)

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
                repairs[k] = self._log_apply_one(
                    flat[k], out[k], None if signs is None else flat_signs[k],
                    None if signs is None else out_signs_flat[k])

        with fast_cpu():
            if lead >= 2 and self.size >= PARALLEL_BINS:
                parallel_map(work, lead)
            else:
                work(0, lead)
        self.last_log_repairs = int(repairs.sum())
        return result, out_signs

    def _log_apply_one(self, values: NDArray, out: NDArray, signs: NDArray | None = None,
                       out_signs: NDArray | None = None, needed: NDArray | None = None) -> int:
        """``log_apply`` of one histogram ``values`` (``self.shape``) into ``out``.

        ``needed`` (bool, ``self.shape``): only these results must be exact (the
        others are left unspecified, possibly ``-inf``); each axis's product then
        repairs only the intermediate results that reach a needed one.
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
            repairs += _shifted_log_product(
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
            _logsumexp_product(log_kernel, out.reshape(before, n, after), result)
            out = result.reshape(full_shape)
        return out


class DenseGeometry(Geometry):
    """Bins with an explicit symmetric ``(N, N)`` cost matrix.

    Parameters
    ----------
    cost : array_like, shape (N, N)
        Symmetric, non-negative ground cost (e.g. squared geodesic distances).
    gamma : float
        Entropic regularisation.
    points : array_like, shape (N, d), optional
        Coordinates of the bins, used by the barycentric projection.
    dtype : numpy dtype, default float64
    """

    def __init__(
        self,
        cost: ArrayLike,
        gamma: float,
        points: ArrayLike | None = None,
        dtype: np.dtype | type = np.float64,
    ):
        cost = np.array(cost, dtype=np.float64)
        if cost.ndim != 2 or cost.shape[0] != cost.shape[1] or cost.shape[0] < 1:
            raise ValueError(f"cost must be a square (N, N) matrix, got shape {cost.shape}")
        if not np.all(np.isfinite(cost)):
            raise ValueError("cost matrix contains NaN or inf")
        if np.any(cost < 0):
            raise ValueError("cost matrix must be non-negative")
        if not np.allclose(cost, cost.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(cost).max())):
            raise ValueError("cost matrix must be symmetric")
        self.gamma = _check_gamma(gamma)
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.float32, np.float64):
            raise ValueError(f"dtype must be float32 or float64, got {self.dtype}")
        self.cost = 0.5 * (cost + cost.T)
        self.shape = (cost.shape[0],)
        self._points = None if points is None else np.asarray(points, dtype=np.float64)
        if self._points is not None and (
            self._points.ndim != 2 or self._points.shape[0] != cost.shape[0]
        ):
            raise ValueError(f"points must have shape (N, d) with N={cost.shape[0]}")
        self._log_kernel = np.ascontiguousarray(-self.cost / self.gamma)
        self.kernel = _gibbs(self.cost, self.gamma, self.dtype)

    def __repr__(self) -> str:
        return f"DenseGeometry(N={self.size}, gamma={self.gamma:.4g}, dtype={self.dtype.name})"

    @property
    def log_apply_work(self) -> int:
        return self.size * self.size

    @property
    def points(self) -> NDArray | None:
        return self._points

    def with_dtype(self, dtype: np.dtype | type) -> DenseGeometry:
        return DenseGeometry(self.cost, self.gamma, self._points, dtype)

    def cost_matrix(self) -> NDArray:
        return self.cost.copy()

    def apply_into(self, block: NDArray, out: NDArray) -> None:
        np.matmul(block.reshape(-1, self.size), self.kernel, out=out.reshape(-1, self.size))

    def apply(self, values: NDArray) -> NDArray:
        return _apply_in_parallel(self, values, self.apply_into)

    def log_apply(self, log_values: NDArray) -> NDArray:
        self._check_values(log_values)
        flat = np.ascontiguousarray(log_values, dtype=np.float64).reshape(-1, self.size, 1)
        out = np.empty_like(flat)
        _logsumexp_product(self._log_kernel, flat, out)
        return out.reshape(log_values.shape)


def refine_grid(values: ArrayLike, shape: tuple[int, ...]) -> NDArray:
    """Values of a *function* on a regular grid, interpolated (multilinearly) on another grid.

    For masses (histograms, densities) use :func:`resample_grid`, which keeps
    the total mass; this one keeps the values (a constant stays that constant).
    Both grids span the same box with points at ``linspace(0, 1, n)`` on each
    axis (:class:`GridGeometry`'s convention), so corner points coincide.
    Used to carry log-scalings from a coarse grid to a finer one as a warm
    start; ``-inf`` entries (vanished scalings) become the smallest finite value.

    Parameters
    ----------
    values : array_like, shape (..., *coarse_shape)
    shape : tuple of int
        The new grid's shape (same number of axes as ``coarse_shape``).

    Returns
    -------
    ndarray, shape (..., *shape), float64
    """
    x = np.array(values, dtype=np.float64)
    d = len(shape)
    if x.ndim < d or any(n < 2 for n in x.shape[x.ndim - d :]) or any(n < 2 for n in shape):
        raise ValueError(f"cannot refine an array of shape {x.shape} to {shape}")
    finite = np.isfinite(x)
    if not finite.all():
        x[~finite] = x[finite].min() if finite.any() else 0.0
    return np.ascontiguousarray(_interpolate(x, shape))


def _interpolate(x: NDArray, shape: tuple[int, ...]) -> NDArray:
    """``x`` (..., *grid) linearly interpolated onto ``shape`` (corners aligned), float64.

    One gather-and-blend pass per axis whose length changes; an axis of one
    point is constant along that axis (repeated).
    """
    lead = x.ndim - len(shape)
    for k, n_out in enumerate(shape):
        axis, n_in = lead + k, x.shape[lead + k]
        if n_in == n_out:
            continue
        if n_in == 1:
            x = np.repeat(x, n_out, axis=axis)
            continue
        # New point i sits at i (n_in - 1) / (n_out - 1) of the old grid, between
        # old points base and base + 1.
        pos = np.arange(n_out) * ((n_in - 1) / (n_out - 1))
        base = np.minimum(pos.astype(np.int64), n_in - 2)
        frac = (pos - base).reshape([-1 if a == axis else 1 for a in range(x.ndim)])
        x = np.take(x, base, axis=axis) * (1.0 - frac) + np.take(x, base + 1, axis=axis) * frac
    return x


def binning_matrix(n: int, m: int) -> NDArray:
    """``(m, n)``: how the masses at ``n`` grid points split over the two nearest of ``m``.

    Points at ``linspace(0, 1, n)`` and ``linspace(0, 1, m)``. Each column holds
    the linear-interpolation weights of one old point between its two
    neighbours on the new grid (it sums to 1): the matrix is the transpose
    (adjoint) of linear interpolation from the ``m``-point grid to the
    ``n``-point one, so it keeps the total mass and the mean position.
    """
    if m == 1:
        return np.ones((1, n))
    pos = np.linspace(0.0, 1.0, n) * (m - 1)
    base = np.minimum(pos.astype(np.int64), m - 2)
    frac = pos - base
    matrix = np.zeros((m, n))
    matrix[base, np.arange(n)] += 1.0 - frac
    matrix[base + 1, np.arange(n)] += frac
    return matrix


def resample_grid(values: ArrayLike, shape: tuple[int, ...], mass: float | None = None) -> NDArray:
    """Masses (histograms, densities) on a regular grid, re-binned onto a grid of another shape.

    For values of a *function* use :func:`refine_grid`; this one keeps the
    total mass. Both grids span the same box with points at ``linspace(0, 1,
    n)`` on each axis (corners aligned); any number of axes, each coarsened
    or refined independently:

    - along an axis that gets coarser, each old point's mass is split between
      its two nearest new points with linear-interpolation weights
      (:func:`binning_matrix`, the adjoint of linear interpolation): the total
      mass and the mean position are kept exactly (to rounding);
    - along an axis that gets finer, the density is interpolated linearly
      (moving the masses themselves would leave empty bins between them).

    The result is then clipped at 0 and rescaled to the total ``mass``.

    Parameters
    ----------
    values : array_like, shape (..., *old_shape)
        Non-negative, finite; leading axes hold independent histograms.
    shape : tuple of int
        The new grid's shape (as many axes as ``old_shape``, each >= 1).
    mass : float, optional
        Total mass of each resampled histogram; default each input's own total
        (``mass=1.0`` normalises). A histogram whose shape does not change is
        returned as a float64 copy, rescaled only when ``mass`` is given.

    Returns
    -------
    ndarray, shape (..., *shape), float64
    """
    x = np.asarray(values, dtype=np.float64)
    shape = tuple(int(n) for n in shape)
    d = len(shape)
    if d == 0 or x.ndim < d or any(n < 1 for n in shape) or 0 in x.shape[x.ndim - d:]:
        raise ValueError(f"cannot resample an array of shape {x.shape} to the grid {shape}")
    if not np.all(np.isfinite(x)) or np.any(x < 0):
        raise ValueError("resample_grid takes finite, non-negative masses")
    if mass is not None and not (np.isfinite(mass) and mass >= 0):
        raise ValueError(f"mass must be a non-negative number, got {mass!r}")
    if x.ndim == d:  # as computed: its memory order fixes the rounding of later sums
        return _resample_one(x, shape, mass)
    lead = x.shape[: x.ndim - d]
    flat = x.reshape(-1, *x.shape[x.ndim - d:])
    return np.stack([_resample_one(h, shape, mass) for h in flat]).reshape(*lead, *shape)


def _resample_one(hist: NDArray, shape: tuple[int, ...], mass: float | None) -> NDArray:
    """:func:`resample_grid` of one histogram (its checks done)."""
    total = float(hist.sum()) if mass is None else float(mass)
    if hist.shape == shape:
        if mass is None:
            return hist.copy()
        out = hist
    else:
        out = hist
        for axis, (n, m) in enumerate(zip(hist.shape, shape)):
            if m < n:  # coarser: soft-bin the masses (separable: one matrix per axis)
                out = np.moveaxis(np.tensordot(binning_matrix(n, m), out, axes=(1, axis)), 0,
                                  axis)
        if any(m > n for n, m in zip(out.shape, shape)):  # finer: interpolate the density
            out = _interpolate(out, shape)
        out = np.clip(out, 0.0, None)
    current = out.sum()
    if current == 0:
        if total == 0:
            return np.zeros(shape)
        raise ValueError("cannot give an empty histogram a positive mass")
    return out / current * total
