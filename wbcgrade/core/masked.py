"""Losses that only see the kept entries of each row (sparse measurements, e.g. BRDFs).

A decimated measurement keeps a few outgoing directions per incoming direction
(about 29 of 288 at ``--keep 0.1``). ``masked_loss`` restricts each row of the
barycenter to its kept entries, renormalises it, and compares it with the
measurement restricted the same way. The comparison runs on the kept entries
only: each row is gathered into a short array of its ``m`` kept directions
(``m`` = the largest count over the rows; shorter rows are padded with
massless copies of one of their directions), and transport losses see a
:class:`RowSubsetGeometry` that holds one small ``(m, m)`` kernel per row.
Since the restricted histograms have no mass outside the kept entries, this is
exactly the transport problem on the full sampling, at ``(m / N)^2`` of the
cost of its kernel products (about 1% at ``--keep 0.1``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wbcgrade.core.geometry import Geometry
from wbcgrade.core.losses import Loss, get_loss
from wbcgrade.errors import InputError


class RowSubsetGeometry(Geometry):
    """One small dense geometry per row: row ``r``'s bins are directions ``index[r]``.

    Histograms on it have shape ``(B, m)`` (optionally with more leading axes):
    the second-to-last axis is the row and selects the kernel. Only what the
    core's Sinkhorn and transport losses use is provided (``apply``,
    ``log_apply``, ``gamma``, ``shape``).

    Parameters
    ----------
    cost : ndarray, shape (N, N)
        Cost of the full sampling.
    gamma : float
    index : ndarray of int, shape (B, m)
        The directions of each row (padding repeats one of the row's own).
    """

    def __init__(self, cost: NDArray, gamma: float, index: NDArray):
        self.gamma = float(gamma)
        self.dtype = np.dtype(np.float64)
        self.index = np.asarray(index, dtype=np.int64)
        self.shape = (self.index.shape[-1],)
        rows = self.index[:, :, None], self.index[:, None, :]
        self._cost = np.asarray(cost, dtype=np.float64)[rows]  # (B, m, m)
        self._log_kernel = -self._cost / self.gamma
        kernel = np.exp(self._log_kernel)
        kernel[kernel < np.finfo(np.float64).tiny] = 0.0  # denormals slow products down
        self.kernel = kernel

    @property
    def log_apply_work(self) -> int:
        return self.size * self.size

    @property
    def points(self) -> None:
        return None

    def _check_rows(self, values: NDArray) -> None:
        if values.ndim < 2 or values.shape[-2:] != self.index.shape:
            raise ValueError(f"values must end with (rows, m) = {self.index.shape}, "
                             f"got {values.shape}")

    def apply(self, values: NDArray) -> NDArray:
        """``K_r x_r`` for every row ``r``; values of shape ``(..., B, m)``."""
        self._check_rows(values)
        x = np.asarray(values, dtype=np.float64)
        return np.matmul(self.kernel, x[..., None])[..., 0]

    def log_apply(self, log_values: NDArray) -> NDArray:
        """``log(K_r exp(f_r))`` for every row, exact for any range of ``f``."""
        self._check_rows(log_values)
        terms = self._log_kernel + np.asarray(log_values, dtype=np.float64)[..., None, :]
        peak = terms.max(axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            safe = np.where(np.isfinite(peak), peak, 0.0)
            return (np.log(np.exp(terms - safe).sum(axis=-1, keepdims=True)) + safe)[..., 0]

    def cost_matrix(self) -> NDArray:
        raise NotImplementedError("a RowSubsetGeometry has one cost matrix per row")


def _row_index(mask: NDArray) -> tuple[NDArray, NDArray]:
    """Kept entries of each row of a ``(B, N)`` mask, padded: ``index, valid`` of shape (B, m)."""
    counts = mask.sum(axis=-1)
    m = int(counts.max())
    # Stable sort puts each row's kept entries first, in order.
    order = np.argsort(~mask, axis=-1, kind="stable")[:, :m]
    valid = np.arange(m)[None, :] < counts[:, None]
    index = np.where(valid, order, order[:, :1])
    return index, valid


def masked_loss(loss: str | Loss, mask: NDArray) -> Loss:
    """A loss that only sees the kept entries of each row.

    ``L_mask(P, q) = L(P_k / |P_k|, q_k)`` with ``P_k`` the kept entries of each
    row of ``P`` and ``|P_k|`` their sum; ``q`` must already be restricted to
    the kept entries (zero elsewhere) and normalised. The base loss runs on the
    kept entries only (a :class:`RowSubsetGeometry`; on the full geometry, with
    zeros, when some row keeps more than half the entries). The gradient
    ``mask * (g - <g, P_k/|P_k|>) / |P_k|``, with ``g`` the base loss's
    gradient, is exact for the restriction and the renormalisation.

    Parameters
    ----------
    loss : str or Loss
        The base loss (looked up once: a stateful loss keeps its warm starts
        for the life of the returned loss).
    mask : ndarray of bool, shape (*batch, N)
        Kept entries; every row must keep at least one.

    Returns
    -------
    Loss
    """
    base = get_loss(loss)
    mask = np.asarray(mask, dtype=bool)
    if not mask.any(axis=-1).all():
        raise InputError("every row of a masked loss must keep at least one entry")
    batch, n = mask.shape[:-1], mask.shape[-1]
    flat_mask = mask.reshape(-1, n)
    index, valid = _row_index(flat_mask)
    rows = np.arange(len(index))[:, None]
    # Past half the directions, per-row kernels cost more than the shared one.
    dense = index.shape[1] > n // 2
    if dense:
        valid = flat_mask
    cache: dict[str, object] = {}

    def restrict(x: NDArray) -> NDArray:
        x = x.reshape(-1, n)
        return np.where(valid, x if dense else x[rows, index], 0.0)

    def on(geometry: Geometry) -> Geometry:
        if dense:
            return geometry
        if cache.get("for") is not geometry:
            cache["for"] = geometry
            cache["compact"] = RowSubsetGeometry(geometry.cost_matrix(), geometry.gamma, index)
        return cache["compact"]

    def value_and_grad(P: NDArray, q: NDArray, geometry: Geometry) -> tuple[float, NDArray]:
        if P.shape != mask.shape:
            raise ValueError(f"the masked loss was built for shape {mask.shape}, got {P.shape}")
        kept = restrict(P)
        mass = kept.sum(axis=-1, keepdims=True)
        normalised = kept / mass
        value, grad = base.value_and_grad(normalised, restrict(q), on(geometry))
        grad = np.where(valid, (grad - (grad * normalised).sum(axis=-1, keepdims=True)) / mass,
                        0.0)
        if not dense:
            full = np.zeros((len(index), n))
            full[np.broadcast_to(rows, index.shape)[valid], index[valid]] = grad[valid]
            grad = full
        return value, grad.reshape(*batch, n)

    return Loss(f"masked-{base.name}", value_and_grad, needs_positive_target=False)
