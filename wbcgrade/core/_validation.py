"""Checks shared by the core's solvers: histograms, weights, targets, iteration counts.

Each raises ``ValueError`` with a message that says what is wrong; the
returned arrays are float64 copies (histograms normalised to sum 1).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wbcgrade.core.geometry import Geometry

__all__ = ["histograms", "histogram_stack", "weights", "target", "n_iter"]


class _TargetRule(Protocol):
    """What :func:`target` reads of a loss (a :class:`wbcgrade.core.losses.Loss`)."""

    name: str
    needs_positive_target: bool


def histograms(x: ArrayLike, geometry: Geometry, name: str) -> NDArray:
    """``x`` (..., *geometry.shape) as float64, each histogram normalised to sum 1."""
    x = np.array(x, dtype=np.float64)
    if x.ndim < geometry.ndim or tuple(x.shape[x.ndim - geometry.ndim :]) != geometry.shape:
        raise ValueError(
            f"{name} must end with the geometry's shape {geometry.shape}, got {x.shape}"
        )
    _check_entries(x, name)
    axes = tuple(range(x.ndim - geometry.ndim, x.ndim))
    mass = x.sum(axis=axes, keepdims=True)
    if np.any(mass <= 0):
        raise ValueError(f"{name}: a histogram is empty (all zeros): it cannot be normalised")
    x /= mass
    return x


def histogram_stack(stack: ArrayLike, geometry: Geometry) -> NDArray:
    """Input histograms ``(S, *batch, *shape)``, S >= 1, each normalised to sum 1."""
    H = np.asarray(stack)
    if H.ndim < 1 + geometry.ndim or tuple(H.shape[H.ndim - geometry.ndim :]) != geometry.shape:
        raise ValueError(
            f"histograms must have shape (S, ..., *{geometry.shape}), got {H.shape}"
        )
    if H.shape[0] < 1:
        raise ValueError("at least one histogram is needed")
    return histograms(H, geometry, "histograms")


def _check_entries(x: NDArray, name: str) -> None:
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}: NaN or inf entries")
    if np.any(x < 0):
        raise ValueError(f"{name}: negative entries")


def weights(w: ArrayLike, n_histograms: int) -> NDArray:
    """Weights as float64 ``(S,)``, checked to lie on the simplex."""
    w = np.array(w, dtype=np.float64)
    if w.shape != (n_histograms,):
        raise ValueError(f"weights must have shape ({n_histograms},), got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("weights contain NaN or inf")
    if np.any(w < -1e-12) or abs(w.sum() - 1.0) > 1e-6:
        raise ValueError(
            f"weights must lie on the simplex (non-negative, summing to 1); got sum {w.sum():.6g}"
        )
    # Not renormalised: the energy is differentiable in every direction, and
    # finite differences of it stay within the tolerance above.
    return np.clip(w, 0.0, None)


def target(q: ArrayLike, shape: tuple[int, ...], loss: _TargetRule,
           geometry: Geometry) -> NDArray:
    """A loss's target, shape ``shape`` (*batch, *geometry.shape): finite, >= 0, not empty."""
    q = np.array(q, dtype=np.float64)
    if q.shape != shape:
        raise ValueError(f"target must have shape {shape}, got {q.shape}")
    _check_entries(q, "target")
    if loss.needs_positive_target and np.any(q <= 0):
        raise ValueError(
            f"the {loss.name} loss needs a target that is positive everywhere "
            "(add a small floor to it)"
        )
    axes = tuple(range(q.ndim - geometry.ndim, q.ndim))
    if np.any(q.sum(axis=axes) <= 0):
        raise ValueError("the target is empty (all zeros)")
    return q


def n_iter(value: int) -> int:
    """A positive integer number of iterations."""
    if int(value) != value or value < 1:
        raise ValueError(f"n_iter must be a positive integer, got {value!r}")
    return int(value)
