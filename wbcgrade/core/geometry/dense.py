"""Bins with an explicit cost matrix (:class:`DenseGeometry`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wbcgrade.core.geometry.base import Geometry, _apply_in_parallel, _check_gamma, _gibbs
from wbcgrade.core.geometry.logsum import logsumexp_product

__all__ = ["DenseGeometry"]


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
        logsumexp_product(self._log_kernel, flat, out)
        return out.reshape(log_values.shape)

