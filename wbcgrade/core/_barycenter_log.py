"""The barycenter's log-domain backend: exact whatever the range of the scalings.

Used when the scaling domain (:mod:`wbcgrade.core._barycenter_scaling`)
cannot represent the computation. On grids the products are the shifted BLAS
products of :class:`~wbcgrade.core.geometry.GridGeometry`, run in place where
possible; other geometries use their public ``log_apply``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wbcgrade.core._barycenter_scaling import Iterate, weighted_sum
from wbcgrade.core._cpu import parallel_map
from wbcgrade.core.geometry import PARALLEL_BINS, Geometry
from wbcgrade.errors import NumericalError


class LogBackend:
    """Log-domain recursions: exact whatever the range of the scalings (slower)."""

    def __init__(self, H: NDArray, weights: NDArray, geometry: Geometry):
        self.geometry = geometry
        with np.errstate(divide="ignore"):
            self.log_H = np.log(H)
        self.weights = weights
        self.S = H.shape[0]
        self.M = int(np.prod(H.shape[1:]))  # bins of one histogram, batch included
        self.N = geometry.size
        self.batch = self.M // self.N
        self.items = self.S * self.batch
        # Grids: each histogram's whole recursion (products and element-wise
        # work) runs in one thread, histograms spread over the core's threads.
        self.per_item = geometry.log_per_histogram
        # K b matters only where its histogram has mass (a = p / K b is 0 elsewhere):
        # there only are its products repaired to full precision.
        self.support = H > 0 if self.per_item else None

    # ------------------------------------------------------------ helpers
    def _rows(self, x: NDArray) -> NDArray:
        return x.reshape(self.items, *self.geometry.shape)

    def _over_items(self, work) -> None:
        if self.items >= 2 and self.N >= PARALLEL_BINS:
            parallel_map(work, self.items)
        else:
            work(0, self.items)

    def _over_bins(self, work) -> None:
        if self.M >= PARALLEL_BINS:
            parallel_map(work, self.M)
        else:
            work(0, self.M)

    def _combine(self, log_phi: NDArray) -> tuple[NDArray, NDArray]:
        """``log P = sum_s w_s log phi_s`` and ``P``, split over bins."""
        log_P = np.empty(self.log_H.shape[1:])
        flat_P, flat_phi = log_P.reshape(-1), log_phi.reshape(self.S, -1)
        nonzero = np.flatnonzero(self.weights)
        w = self.weights[nonzero]

        def work(lo: int, hi: int) -> None:
            np.dot(w, flat_phi[nonzero, lo:hi], out=flat_P[lo:hi])

        self._over_bins(work)
        if not np.all(np.isfinite(log_P)):
            raise NumericalError("the log-domain barycenter is not finite")
        return log_P, np.exp(log_P)

    def _scalings(self, log_P: NDArray, log_phi: NDArray, out: NDArray | None) -> NDArray:
        """``log b = log P - log phi`` for every histogram (into ``out``), split over bins."""
        out = np.empty_like(log_phi) if out is None else out
        flat_P = log_P.reshape(-1)
        flat_phi, flat_out = log_phi.reshape(self.S, -1), out.reshape(self.S, -1)

        def work(lo: int, hi: int) -> None:
            np.subtract(flat_P[lo:hi], flat_phi[:, lo:hi], out=flat_out[:, lo:hi])

        self._over_bins(work)
        return out

    def initial(self) -> NDArray:
        return np.zeros_like(self.log_H)

    def from_log(self, log_b: NDArray) -> NDArray:
        return np.array(log_b, dtype=np.float64)

    def to_log(self, log_b: NDArray) -> NDArray:
        return log_b

    def _apply_in_place(self, log_values: NDArray) -> NDArray:
        """``log_apply`` written over its input (in place where the geometry can: grids)."""
        return self.geometry.log_apply_into(log_values, log_values)

    def step(self, log_b: NDArray, need_next: bool = True,
             keep: bool = True) -> tuple[NDArray, Iterate]:
        """One iteration in logs. ``keep=False``: only ``P`` and the next scalings are
        wanted, so ``log K b`` is not kept and the next scalings overwrite
        ``log phi``. ``log a`` is never kept (``log H - log K b``: the adjoint
        recomputes it)."""
        if not self.per_item:
            return self._step_whole(log_b, need_next, keep)
        geom = self.geometry
        log_Kb = np.empty_like(self.log_H) if keep else None
        log_phi = np.empty_like(self.log_H)
        b_rows, H_rows, phi_rows = self._rows(log_b), self._rows(self.log_H), self._rows(log_phi)
        Kb_rows = None if log_Kb is None else self._rows(log_Kb)
        support = self._rows(self.support)

        def work(lo: int, hi: int) -> None:
            scratch = np.empty(geom.shape)
            for k in range(lo, hi):
                kb = scratch if Kb_rows is None else Kb_rows[k]
                geom.log_apply_one(b_rows[k], kb, needed=support[k])
                np.copyto(kb, 0.0, where=~support[k])  # unspecified there: finite, unused
                np.subtract(H_rows[k], kb, out=scratch)  # log a
                geom.log_apply_one(scratch, phi_rows[k])

        self._over_items(work)
        log_P, P = self._combine(log_phi)
        if not keep:
            log_b_next = self._scalings(log_P, log_phi, log_phi) if need_next else None
            return log_b_next, Iterate(None, None, None, None, P, log_P)
        log_b_next = self._scalings(log_P, log_phi, None) if need_next else None
        return log_b_next, Iterate(log_Kb, None, log_phi, log_phi, P, log_P)

    def _step_whole(self, log_b: NDArray, need_next: bool, keep: bool):
        """:meth:`step` for geometries with only the public ``log_apply``."""
        log_Kb = self.geometry.log_apply(log_b)
        log_a = np.subtract(self.log_H, log_Kb, out=None if keep else log_Kb)
        log_phi = self.geometry.log_apply(log_a)
        log_P = weighted_sum(self.weights, log_phi)
        if not np.all(np.isfinite(log_P)):
            raise NumericalError("the log-domain barycenter is not finite")
        P = np.exp(log_P)
        log_b_next = log_P - log_phi if need_next else None
        return log_b_next, Iterate(log_Kb if keep else None, None, log_phi, log_phi, P, log_P)

    record_arrays = 2

    def compact(self, it: Iterate) -> Iterate:
        """What a recorded iteration keeps: log K b, log phi and P (log a is recomputed)."""
        return Iterate(it.Kb, None, it.phi, it.log_phi, it.P, it.log_P)

    def previous(self, it: Iterate) -> NDArray:
        return it.log_P - it.phi

    def release(self, it: Iterate) -> None:
        """The reverse pass is done with ``it`` (nothing is reused here)."""

    def recycle(self, stack: NDArray | None) -> None:
        """The caller is done with ``stack`` (nothing is reused here)."""

    def sum_histograms(self, r: NDArray) -> NDArray:
        return r.sum(axis=0)

    def adjoint(
        self, it: Iterate, log_b_prev: NDArray, g: NDArray, r: NDArray | None, need_r: bool
    ) -> tuple[NDArray, NDArray | None]:
        """Same adjoint as the scaling backend, in logs with signs carried beside them.

        On grids each histogram's reverse step runs in one thread (one signed
        product per kernel application, in place); other geometries carry the
        positive and negative parts through their public ``log_apply``
        separately (twice the products).
        """
        log_phi = it.log_phi
        if not np.all(np.isfinite(log_phi)):
            vanished = ~np.isfinite(log_phi)
            if np.any(vanished & (g != 0)):
                raise NumericalError("phi vanishes where the gradient needs log phi")
            log_phi = np.where(vanished, 0.0, log_phi)
        grad = np.tensordot(log_phi, g, axes=g.ndim)
        if not need_r:
            return grad, None
        geom = self.geometry
        if self.per_item:
            return grad, self._adjoint_items(it, log_b_prev, g, r)
        u = self.weights.reshape((-1,) + (1,) * g.ndim) * g
        if r is not None:
            u -= r
        r_next = np.zeros_like(u)
        with np.errstate(divide="ignore"):
            for sign in (1.0, -1.0):
                part = np.log(np.clip(sign * u, 0.0, None)) - it.phi
                log_a = self.log_H - it.Kb if it.a is None else it.a
                part = geom.log_apply(part) + log_a - it.Kb
                part = geom.log_apply(part) + log_b_prev
                r_next -= sign * np.exp(part)
        return grad, r_next

    def _adjoint_items(self, it: Iterate, log_b_prev: NDArray, g: NDArray,
                       r: NDArray | None) -> NDArray:
        """The next ``r`` on a grid, histogram by histogram, written over ``r``.

        ``u = w_s g - r_s`` is carried as ``log |u|`` beside its signs through
        ``K(u / phi)``, times ``a / K b``, through ``K`` again, times ``b``.
        """
        geom = self.geometry
        r_next = np.empty_like(self.log_H) if r is None else r
        rows = self._rows
        out_rows, phi_rows, Kb_rows = rows(r_next), rows(it.phi), rows(it.Kb)
        H_rows, b_rows, support = rows(self.log_H), rows(log_b_prev), rows(self.support)
        a_rows = None if it.a is None else rows(it.a)
        r_rows = None if r is None else out_rows
        g_rows = g.reshape(self.batch, *geom.shape)

        def work(lo: int, hi: int) -> None:
            signs = np.empty(geom.shape)
            with np.errstate(divide="ignore"):
                for k in range(lo, hi):
                    part = out_rows[k]  # r's row when r is given: u = w g - r in place
                    np.multiply(g_rows[k % self.batch], self.weights[k // self.batch],
                                out=signs)
                    if r_rows is None:
                        part[...] = signs
                    else:
                        np.subtract(signs, part, out=part)
                    np.sign(part, out=signs)
                    np.abs(part, out=part)
                    np.log(part, out=part)
                    part -= phi_rows[k]
                    # times a = 0 off the support next: only the support must be exact
                    geom.log_apply_one(part, part, signs, signs, needed=support[k])
                    if a_rows is None:  # log a = log H - log K b, not kept
                        part += H_rows[k]
                        part -= Kb_rows[k]
                    else:
                        part += a_rows[k]
                    part -= Kb_rows[k]
                    geom.log_apply_one(part, part, signs, signs)
                    part += b_rows[k]
                    np.exp(part, out=part)
                    part *= signs
                    np.negative(part, out=part)

        self._over_items(work)
        return r_next
