"""The barycenter's scaling-domain backend: plain kernel products, fused passes.

Fast, and checked: it raises :class:`Unsafe` as soon as a scaling under- or
overflows where mass sits, and the solver (:mod:`wbcgrade.core.barycenter`)
moves to the exact log domain (:mod:`wbcgrade.core._barycenter_log`). Both
backends run the same recursions (the module docstring of ``barycenter``)
and share :class:`Iterate`.
"""

from __future__ import annotations

from dataclasses import dataclass
from threading import Lock

import numpy as np
from numpy.typing import NDArray

from wbcgrade.core import _kernels
from wbcgrade.core._cpu import parallel_map
from wbcgrade.core.geometry import PARALLEL_BINS as _PARALLEL_BINS
from wbcgrade.core.geometry import Geometry

#: Mass the scaling domain may drop where a kernel product underflows to 0,
#: relative to the barycenter's largest bin, before the log domain takes over.
_UNDERFLOW_TOLERANCE = 1e-12


class Unsafe(Exception):
    """The scaling domain cannot represent this computation (internal signal)."""


@dataclass
class Iterate:
    """What one forward iteration computes, kept for its reverse step."""

    Kb: NDArray  # K b(l-1)            (scaling) or log K b (log domain)
    a: NDArray  # p / K b(l-1)        (scaling) or log a
    phi: NDArray  # K a               (scaling) or log phi
    log_phi: NDArray  # log phi
    P: NDArray  # barycenter P(l), float64, (*batch, *shape)
    log_P: NDArray | None = None  # log P(l) (log domain only)


def weighted_sum(weights: NDArray, stack: NDArray) -> NDArray:
    """sum_s w_s stack_s, skipping zero weights (so 0 * -inf never appears)."""
    nonzero = np.flatnonzero(weights)
    if len(nonzero) == len(weights):
        return np.tensordot(weights, stack, axes=1)
    return np.tensordot(weights[nonzero], stack[nonzero], axes=1)


class ScalingBackend:
    """Plain kernel products; raises ``Unsafe`` when the numbers leave its range.

    Histograms are processed as ``items = S * batch`` independent rows of
    ``N`` bins: kernel products and the fused element-wise passes of one row
    are independent, so rows are spread over the core's threads; the passes
    that mix histograms (the weighted log-sum) are split over bins instead.
    Each recorded iteration keeps ``K b`` and ``phi`` (two stacks) and ``P``.
    """

    record_arrays = 2

    def __init__(self, H: NDArray, weights: NDArray, geometry: Geometry):
        self.geometry = geometry
        self.dtype = geometry.dtype
        self.H = np.ascontiguousarray(H, dtype=self.dtype)
        if np.count_nonzero(self.H) != np.count_nonzero(H):
            raise Unsafe("histogram entries underflow in this precision")
        self.weights = weights
        self.shape = H.shape
        self.S = H.shape[0]
        self.N = geometry.size
        self.M = int(np.prod(H.shape[1:]))  # bins of one histogram, batch included
        self.batch = self.M // self.N
        self.items = self.S * self.batch
        self.item_weights = np.repeat(weights, self.batch)
        if self.dtype == np.float32:
            self.log_low, self.log_high = np.log(1e-30), np.log(1e30)
            self.high = 1e30
        else:
            self.log_low, self.log_high = -np.inf, np.inf
            self.high = np.inf
        self.limit = self.dtype.type(np.inf)
        #: stacks reused from step to step (what an iteration needs only while it runs)
        self._buffers: dict[str, NDArray] = {}
        #: stacks of iterations the reverse pass is done with (:meth:`release`), reused
        #: by the next recorded step
        self._spare: list[NDArray] = []

    # ------------------------------------------------------------ helpers
    def _rows(self, x: NDArray) -> NDArray:
        return x.reshape(self.items, self.N)

    def _blocks(self, x: NDArray) -> NDArray:
        return x.reshape(self.items, *self.geometry.shape)

    def _product(self, source: NDArray, target: NDArray, lo: int, hi: int) -> None:
        self.geometry.apply_into(self._blocks(source)[lo:hi], self._blocks(target)[lo:hi])

    def _buffer(self, name: str) -> NDArray:
        """A stack (the histograms' shape) this backend reuses: its contents last only
        until the next step or adjoint writes it (no fresh pages each iteration)."""
        buffer = self._buffers.get(name)
        if buffer is None:
            buffer = self._buffers[name] = np.empty_like(self.H)
        return buffer

    def _fresh(self) -> NDArray:
        """A stack for an iteration that may be recorded: a released one, else new."""
        return self._spare.pop() if self._spare else np.empty_like(self.H)

    def release(self, it: Iterate) -> None:
        """The reverse pass is done with ``it``: its ``K b`` and ``phi`` may be reused."""
        for stack in (it.Kb, it.phi):
            self.recycle(stack)

    def recycle(self, stack: NDArray | None) -> None:
        """``stack`` (an iterate's array or scalings this backend made) is no longer used
        by its caller: a later step may write into it. Buffers and arrays already spare
        are left alone."""
        if stack is None or stack.shape != self.H.shape or stack.dtype != self.H.dtype \
                or any(stack is b for b in self._buffers.values()) \
                or any(stack is b for b in self._spare):
            return
        self._spare.append(stack)

    def _over_items(self, work) -> None:
        if self.items >= 2 and self.N >= _PARALLEL_BINS:
            parallel_map(work, self.items)
        else:
            work(0, self.items)

    def _over_bins(self, work) -> None:
        if self.M >= _PARALLEL_BINS:
            parallel_map(work, self.M)
        else:
            work(0, self.M)

    def initial(self) -> NDArray:
        return np.ones_like(self.H)

    def from_log(self, log_b: NDArray) -> NDArray:
        """Scalings from their logs (a warm start), raising Unsafe out of range."""
        with np.errstate(over="ignore", under="ignore"):
            b = np.exp(log_b).astype(self.dtype)
        if not np.all(np.isfinite(b)):
            raise Unsafe("the warm start leaves this precision's range")
        return b

    def to_log(self, b: NDArray) -> NDArray:
        with np.errstate(divide="ignore"):
            return np.log(b, dtype=np.float64)

    def scalings(self, P: NDArray, phi: NDArray) -> NDArray:
        """``b = P / phi`` (0 where phi vanished), raising Unsafe on overflow."""
        b = self._fresh()
        P_flat = P.reshape(-1).astype(self.dtype)
        phi_flat, b_flat = phi.reshape(self.S, self.M), b.reshape(self.S, -1)
        overflow = np.zeros(1, dtype=np.int64)
        lock = Lock()

        def work(lo: int, hi: int) -> None:
            bad = _kernels.divide_rows(P_flat, phi_flat, b_flat, lo, hi, self.limit)
            with lock:
                overflow[0] += bad

        self._over_bins(work)
        if overflow[0]:
            raise Unsafe("scalings overflow")
        return b

    # ------------------------------------------------------------ forward
    def step(self, b: NDArray, need_next: bool = True,
             keep: bool = True) -> tuple[NDArray | None, Iterate]:
        """One iteration: next scalings (None unless ``need_next``) and what it computed.

        ``keep=False``: only ``P`` and the next scalings are wanted, so ``K b`` and
        ``phi`` are written into stacks the next step reuses; ``a`` and ``log phi``
        always are (the returned iterate's ``a`` and ``log_phi`` last until the next
        step or adjoint; :meth:`compact` drops them).
        """
        if keep:
            Kb, phi = self._fresh(), self._fresh()
        else:
            Kb, phi = self._buffer("Kb"), self._buffer("phi")
        a, log_phi = self._buffer("a"), self._buffer("log_phi")
        lost = np.zeros(self.items, dtype=np.int64)
        H_rows, Kb_rows, a_rows = self._rows(self.H), self._rows(Kb), self._rows(a)

        def per_item(lo: int, hi: int) -> None:
            self._product(b, Kb, lo, hi)
            for j in range(lo, hi):
                lost[j] = _kernels.ratio(H_rows[j], Kb_rows[j], a_rows[j], self.high)
            self._product(a, phi, lo, hi)
            with np.errstate(divide="ignore"):
                np.log(self._rows(phi)[lo:hi], out=self._rows(log_phi)[lo:hi])

        self._over_items(per_item)
        if lost.any():
            raise Unsafe("K b vanishes or the scalings leave the range where a histogram has mass")

        log_P = np.empty(self.M)
        lp_rows = log_phi.reshape(self.S, self.M)
        stats = []
        lock = Lock()

        def per_bins(lo: int, hi: int) -> None:
            result = _kernels.weighted_log_sum(lp_rows, self.weights, log_P, lo, hi,
                                               self.log_low, self.log_high)
            with lock:
                stats.append(result)

        self._over_bins(per_bins)
        vanished = sum(v for v, _ in stats)
        outside = sum(o for _, o in stats)
        log_P = log_P.reshape(self.shape[1:])
        if vanished and self.dtype == np.float32 or outside:
            raise Unsafe("scalings leave the float32 range")
        if vanished:
            self._check_dropped_mass(log_phi.astype(np.float64), log_P, a)
        P = np.exp(log_P)
        it = Iterate(Kb, a, phi, log_phi, P)
        if not need_next:
            return None, it
        return self.scalings(P, phi), it

    def _check_dropped_mass(self, log_phi: NDArray, log_P: NDArray, a: NDArray) -> None:
        """Where a kernel product underflowed, P is bounded above; the bound must be negligible.

        A vanished ``phi_j = sum_i K_ji a_i`` only lost terms below the smallest
        normal number: truncated kernel entries (each < tiny, times ``a_i``) and
        flushed products (each < tiny), so ``phi_j < tiny * (sum_i a_i + N)``.
        """
        geom = self.geometry
        axes = tuple(range(a.ndim - geom.ndim, a.ndim))
        mass = a.sum(axis=axes, keepdims=True, dtype=np.float64) + geom.size
        ceiling = np.log(np.finfo(np.float64).tiny) + np.log(mass)
        vanished = ~np.isfinite(log_phi)
        bound = weighted_sum(self.weights, np.where(vanished, ceiling, log_phi))
        where = vanished.any(axis=0)
        finite = log_P[np.isfinite(log_P)]
        if finite.size == 0:
            raise Unsafe("the barycenter vanishes everywhere")
        if bound[where].max() > finite.max() + np.log(_UNDERFLOW_TOLERANCE):
            raise Unsafe("a kernel product underflows where the barycenter has mass")

    def compact(self, it: Iterate) -> Iterate:
        """What a recorded iteration keeps: K b, phi and P (a and log phi are recomputed)."""
        return Iterate(it.Kb, None, it.phi, None, it.P)

    def previous(self, it: Iterate) -> NDArray:
        """The scalings b an iteration produced (its successor's input)."""
        return self.scalings(it.P, it.phi)

    # ------------------------------------------------------------ reverse
    def sum_histograms(self, r: NDArray) -> NDArray:
        """``sum_s r_s``, shape (*batch, *shape)."""
        g = np.empty(self.shape[1:])
        r_rows, g_flat = r.reshape(self.S, self.M), g.reshape(-1)

        def work(lo: int, hi: int) -> None:
            np.sum(r_rows[:, lo:hi], axis=0, out=g_flat[lo:hi])

        self._over_bins(work)
        return g

    def adjoint(
        self, it: Iterate, b_prev: NDArray, g: NDArray, r: NDArray | None, need_r: bool
    ) -> tuple[NDArray, NDArray | None]:
        """One reverse step: (d/dw of this iteration (S,), next ``r`` or None).

        ``g`` (*batch, *shape) is the adjoint of log P(l) and ``r`` (S, ...) the
        part of each ``w_s g`` not yet propagated (None at the last iteration).
        """
        g_rows = g.reshape(self.batch, self.N)
        x, y_all = self._buffer("x"), self._buffer("y")
        # r and r_next alternate between two stacks: r is read here, r_next written
        r_next = None
        if need_r:
            name = "r1" if r is not None and r is self._buffers.get("r0") else "r0"
            r_next = self._buffers.get(name)
            if r_next is None:
                r_next = self._buffers[name] = np.empty(self.shape)
        grad = np.zeros(self.items)
        unsafe = np.zeros(self.items, dtype=np.int64)
        empty = np.empty(0)
        rows = self._rows
        H_rows, Kb_rows, phi_rows, x_rows = rows(self.H), rows(it.Kb), rows(it.phi), rows(x)
        r_rows = None if r is None else r.reshape(self.items, self.N)
        b_rows = rows(b_prev)
        log_phi = it.log_phi

        def per_item(lo: int, hi: int) -> None:
            if log_phi is None:
                with np.errstate(divide="ignore"):
                    logs = np.log(phi_rows[lo:hi])
            else:
                logs = rows(log_phi)[lo:hi]
            for j in range(lo, hi):
                gj = g_rows[j % self.batch]
                grad[j], unsafe[j] = _kernels.dot_log(logs[j - lo], gj)
                if need_r:
                    rj = empty if r_rows is None else r_rows[j]
                    _kernels.reverse_in(self.item_weights[j], gj, rj, phi_rows[j], x_rows[j])
            if not need_r:
                return
            y = self._blocks(y_all)[lo:hi]
            self.geometry.apply_into(self._blocks(x)[lo:hi], y)
            y_rows = y.reshape(hi - lo, self.N)
            for j in range(lo, hi):
                _kernels.reverse_mid(y_rows[j - lo], H_rows[j], Kb_rows[j])
            self.geometry.apply_into(y, self._blocks(x)[lo:hi])  # v = K y, into x
            out_rows = r_next.reshape(self.items, self.N)
            for j in range(lo, hi):
                unsafe[j] += _kernels.reverse_out(x_rows[j], b_rows[j], out_rows[j])

        self._over_items(per_item)
        if unsafe.any():
            raise Unsafe("phi vanishes where the gradient needs log phi, or the reverse overflows")
        return grad.reshape(self.S, self.batch).sum(axis=1), r_next
