"""Log-sum kernels: exact log-domain products ``log(K exp(f))`` along one axis.

Compiled loops (numba) and the shifted BLAS product of the grid geometry
(:func:`shifted_log_product`): a plain matrix product of lines shifted by
their maximum, checked, with the few results that underflow could spoil
recomputed per block and then per entry. Used by :mod:`.grid` (per axis)
and :mod:`.dense` (:func:`logsumexp_product` on the whole matrix).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from wbcgrade.core._jit import compiled

if TYPE_CHECKING:  # numba.prange: numba is given to the kernels when they are first made
    import numba

__all__ = ["logsumexp_product", "AxisKernel", "shifted_log_product"]


@compiled(parallel=True, cache=True, nogil=True)
def logsumexp_product(log_kernel, values, out):  # pragma: no cover - compiled
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
    :func:`logsumexp_product`, shifted by each entry's own peak; the last
    resort of :func:`shifted_log_product`.
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
    """Pass 2 of :func:`shifted_log_product` on the line blocks where ``low`` is set.

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


class AxisKernel:
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


def shifted_log_product(
    axis: AxisKernel,
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
