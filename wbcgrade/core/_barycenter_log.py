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
from wbcgrade.core.geometry import Geometry
from wbcgrade.errors import NumericalError


class LogBackend:
    """Log-domain recursions: exact whatever the range of the scalings (slower)."""

    def __init__(self, H: NDArray, weights: NDArray, geometry: Geometry):
        self.geometry = geometry
        with np.errstate(divide="ignore"):
            self.log_H = np.log(H)
        self.weights = weights

    def initial(self) -> NDArray:
        return np.zeros_like(self.log_H)

    def from_log(self, log_b: NDArray) -> NDArray:
        return np.array(log_b, dtype=np.float64)

    def to_log(self, log_b: NDArray) -> NDArray:
        return log_b

    def _apply_in_place(self, log_values: NDArray) -> NDArray:
        """``log_apply`` written over its input where the geometry can (grids)."""
        in_place = getattr(self.geometry, "_shifted_log_apply", None)
        if in_place is None:
            return self.geometry.log_apply(log_values)
        return in_place(log_values, None, out=log_values)[0]

    def step(self, log_b: NDArray, need_next: bool = True,
             keep: bool = True) -> tuple[NDArray, Iterate]:
        """One iteration in logs. ``keep=False``: only ``P`` and the next scalings are
        wanted, so ``log K b`` and ``log phi`` are overwritten as they go (three
        states of memory at the peak instead of five). ``log a`` is never kept
        (``log H - log K b``: the adjoint recomputes it)."""
        log_Kb = self.geometry.log_apply(log_b)
        log_a = np.subtract(self.log_H, log_Kb, out=None if keep else log_Kb)
        log_phi = self._apply_in_place(log_a)
        log_P = weighted_sum(self.weights, log_phi)
        if not np.all(np.isfinite(log_P)):
            raise NumericalError("the log-domain barycenter is not finite")
        P = np.exp(log_P)
        if not keep:
            log_b_next = np.subtract(log_P, log_phi, out=log_phi) if need_next else None
            return log_b_next, Iterate(None, None, None, None, P, log_P)
        log_b_next = log_P - log_phi if need_next else None
        return log_b_next, Iterate(log_Kb, None, log_phi, log_phi, P, log_P)

    record_arrays = 2

    def compact(self, it: Iterate) -> Iterate:
        """What a recorded iteration keeps: log K b, log phi and P (log a is recomputed)."""
        return Iterate(it.Kb, None, it.phi, it.log_phi, it.P, it.log_P)

    def previous(self, it: Iterate) -> NDArray:
        return it.log_P - it.phi

    def sum_histograms(self, r: NDArray) -> NDArray:
        return r.sum(axis=0)

    def adjoint(
        self, it: Iterate, log_b_prev: NDArray, g: NDArray, r: NDArray | None, need_r: bool
    ) -> tuple[NDArray, NDArray | None]:
        """Same adjoint as the scaling backend, in logs with signs carried beside them.

        Geometries with a signed log-domain product (``_signed_log_apply``:
        grids) apply it once per kernel product; others carry the positive
        and negative parts through separately (twice the products).
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
        if getattr(geom, "_signed_log_apply", None) is not None:
            # One signed product per kernel application, in place: u = w g - r is
            # written over r (not needed after this step), then carried as
            # log |.| beside its signs through both products.
            if r is None:
                u = np.empty_like(it.phi)
                for s, w_s in enumerate(self.weights):
                    np.multiply(g, w_s, out=u[s])
            else:
                u = np.negative(r, out=r)
                for s, w_s in enumerate(self.weights):
                    u[s] += w_s * g
            signs = np.sign(u)
            part = np.abs(u, out=u)
            with np.errstate(divide="ignore"):
                np.log(part, out=part)
            part -= it.phi
            geom._shifted_log_apply(part, signs, out=part, out_signs=signs)
            if it.a is None:  # log a = log H - log K b, not kept
                part += self.log_H
                part -= it.Kb
            else:
                part += it.a
            part -= it.Kb
            geom._shifted_log_apply(part, signs, out=part, out_signs=signs)
            part += log_b_prev
            np.exp(part, out=part)
            part *= signs
            np.negative(part, out=part)
            return grad, part
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
