"""Losses between a barycenter ``P`` and a target ``q``, with their gradients in ``P``.

Each loss is a small object with ``value_and_grad(P, q, geometry)`` returning
the loss summed over any leading batch axes and its gradient ``dLoss/dP``
(same shape as ``P``). New losses plug in with :func:`register_loss`.

- ``quadratic``: ``0.5 |P - q|^2``, gradient ``P - q``.
- ``l1`` (total variation): ``|P - q|_1``, gradient ``sign(P - q)``.
- ``kl`` (generalised Kullback-Leibler): ``sum P log(P / q) - P + q``,
  gradient ``log(P / q)``; needs ``q > 0``.
- ``kl_reverse``: ``KL(q | P) = sum q log(q / P) - q + P``, gradient
  ``1 - q / P``; asks P to cover q without charging mass where q is absent
  (the better choice for completing partial shapes).
- ``wasserstein`` (entropic): ``W_gamma(P / |P|, q / |q|)``, the Sinkhorn
  dual value between the normalised histograms; gradient
  ``(f - <f, P/|P|>) / |P|`` with ``f = gamma log a`` the dual potential, the
  exact gradient of that value (it reduces to ``gamma log a`` centred when
  ``|P| = 1``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wbcgrade.core.geometry import Geometry

__all__ = ["Loss", "get_loss", "register_loss", "LOSSES"]


@dataclass(frozen=True)
class Loss:
    """A loss ``L(P, q)`` summed over leading batch axes, with ``dL/dP``.

    Attributes
    ----------
    name : str
    value_and_grad : callable
        ``(P, q, geometry) -> (float, ndarray like P)``.
    needs_positive_target : bool
        True when the target must be positive everywhere (KL).
    """

    name: str
    value_and_grad: Callable[[NDArray, NDArray, Geometry], tuple[float, NDArray]]
    needs_positive_target: bool = False


def _quadratic(P: NDArray, q: NDArray, geometry: Geometry) -> tuple[float, NDArray]:
    diff = P - q
    return 0.5 * float(np.vdot(diff, diff)), diff


def _l1(P: NDArray, q: NDArray, geometry: Geometry) -> tuple[float, NDArray]:
    diff = P - q
    return float(np.abs(diff).sum()), np.sign(diff)


def _kl(P: NDArray, q: NDArray, geometry: Geometry) -> tuple[float, NDArray]:
    with np.errstate(divide="ignore", invalid="ignore"):
        log_ratio = np.log(P) - np.log(q)
        terms = np.where(P > 0, P * log_ratio, 0.0) - P + q
    # Where P underflowed to 0 the gradient log(P/q) is -inf, but it only ever
    # enters the reverse pass multiplied by P, so any finite value is exact.
    grad = np.where(P > 0, log_ratio, 0.0)
    return float(terms.sum()), grad


def _kl_reverse(P: NDArray, q: NDArray, geometry: Geometry) -> tuple[float, NDArray]:
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        terms = np.where(q > 0, q * (np.log(q) - np.log(P)), 0.0) - q + P
        # Enters the reverse pass multiplied by P: (1 - q / P) P = P - q stays finite.
        grad = np.where(P > 0, 1.0 - q / P, 0.0)
    return float(terms.sum()), grad


def _wasserstein(P: NDArray, q: NDArray, geometry: Geometry) -> tuple[float, NDArray]:
    from wbcgrade.core.sinkhorn import sinkhorn

    axes = tuple(range(P.ndim - geometry.ndim, P.ndim))
    mass = P.sum(axis=axes, keepdims=True)
    if np.any(mass <= 0):
        raise ValueError("the barycenter has no mass: cannot compute a Wasserstein loss")
    p_hat = P / mass
    result = sinkhorn(p_hat, q, geometry, tol=1e-11, max_iter=100_000)
    f = geometry.gamma * result.log_a
    g = geometry.gamma * result.log_b
    q_hat = q / q.sum(axis=axes, keepdims=True)
    with np.errstate(invalid="ignore"):
        value = float(
            np.where(p_hat > 0, f * p_hat, 0.0).sum() + np.where(q_hat > 0, g * q_hat, 0.0).sum()
        )
    f = np.where(p_hat > 0, f, 0.0) if not np.all(np.isfinite(f)) else f
    centred = f - (f * p_hat).sum(axis=axes, keepdims=True)
    return value, centred / mass


LOSSES: dict[str, Loss] = {}


def register_loss(loss: Loss) -> Loss:
    """Make ``loss`` available by name to the barycenter gradient and the fit."""
    LOSSES[loss.name] = loss
    return loss


register_loss(Loss("quadratic", _quadratic))
register_loss(Loss("l1", _l1))
register_loss(Loss("kl", _kl, needs_positive_target=True))
register_loss(Loss("kl_reverse", _kl_reverse))
register_loss(Loss("wasserstein", _wasserstein))


def get_loss(loss: str | Loss) -> Loss:
    """Look a loss up by name (or pass a :class:`Loss` through)."""
    if isinstance(loss, Loss):
        return loss
    try:
        return LOSSES[str(loss).lower()]
    except KeyError:
        raise ValueError(
            f"unknown loss {loss!r}; choose one of {', '.join(sorted(LOSSES))}"
        ) from None
