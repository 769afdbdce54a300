r"""Wasserstein barycentric coordinates: the weights whose barycenter best fits a target.

Minimises ``E(w) = Loss(P_L(w), q)`` over the simplex (Bonneel, Peyré, Cuturi
2016, §4) with ``w = softmax(alpha)`` and scipy's L-BFGS on ``alpha``, starting
from uniform weights. The energy is divided by its value at the start so
L-BFGS sees numbers of order one (raw quadratic losses are ~1e-10).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wbcgrade.core import _validation
from wbcgrade.core.barycenter import DEFAULT_CHECKPOINT_BYTES, BarycenterSolver
from wbcgrade.core.geometry import Geometry
from wbcgrade.core.losses import Loss, get_loss

__all__ = [
    "CoordinatesResult",
    "barycentric_coordinates",
    "mixture_coordinates",
    "softmax",
]


@dataclass(frozen=True)
class CoordinatesResult:
    """Fitted barycentric coordinates.

    Attributes
    ----------
    weights : ndarray, shape (S,)
        Weights on the simplex (the best evaluated point).
    barycenter : ndarray, shape (*batch, *geometry.shape)
        ``P_L(weights)``.
    loss : float
        ``Loss(P_L(weights), target)``.
    initial_loss : float
        The loss at the starting weights.
    n_evaluations : int
        Energy and gradient evaluations (each one forward and one reverse pass).
    n_iterations : int
        L-BFGS iterations.
    converged : bool
        Whether L-BFGS met its tolerance (rather than its iteration limit).
    message : str
        L-BFGS's reason for stopping.
    history : list of float
        Loss after each evaluation.
    time_s : float
        Wall time of the fit.
    backend : str
        Which computation the last evaluation used ("scaling-float64", "log", ...).
    """

    weights: NDArray
    barycenter: NDArray
    loss: float
    initial_loss: float
    n_evaluations: int
    n_iterations: int
    converged: bool
    message: str
    history: list[float] = field(default_factory=list)
    time_s: float = 0.0
    backend: str = ""


def softmax(alpha: NDArray) -> NDArray:
    """Weights on the simplex from unconstrained parameters, shape (S,)."""
    z = np.exp(alpha - alpha.max())
    return z / z.sum()


def barycentric_coordinates(
    target: ArrayLike,
    histograms: ArrayLike,
    geometry: Geometry,
    loss: str | Loss = "quadratic",
    n_iter: int = 60,
    init_weights: ArrayLike | None = None,
    max_iter: int = 30,
    tol: float = 1e-9,
    callback: Callable[[int, NDArray, float], None] | None = None,
    checkpoint_bytes: int = DEFAULT_CHECKPOINT_BYTES,
) -> CoordinatesResult:
    """Weights ``w`` on the simplex minimising ``Loss(P_L(w), target)``.

    Parameters
    ----------
    target : array_like, shape (*batch, *geometry.shape)
        Histogram to explain (not normalised: the loss sees it as given).
    histograms : array_like, shape (S, *batch, *geometry.shape)
        The database; each histogram is normalised to sum 1.
    geometry : Geometry
    loss : {"quadratic", "l1", "kl", "wasserstein"} or Loss, default "quadratic"
    n_iter : int, default 60
        Barycenter iterations L.
    init_weights : array_like, shape (S,), optional
        Starting weights (default uniform), e.g. from a coarser grid.
    max_iter : int, default 30
        L-BFGS iterations at most (the paper reports ~10 suffice).
    tol : float, default 1e-9
        Relative decrease of the (normalised) energy at which L-BFGS stops.
    callback : callable, optional
        ``callback(n_evaluations, weights, loss)`` after each evaluation.
    checkpoint_bytes : int
        Memory budget for the reverse pass.

    Returns
    -------
    CoordinatesResult

    References
    ----------
    Bonneel, Peyré, Cuturi (2016), Wasserstein barycentric coordinates:
    histogram regression using optimal transport. ACM TOG 35(4).

    Examples
    --------
    The weights of a barycenter are found again from the barycenter:

    >>> import numpy as np
    >>> from wbcgrade.core import GridGeometry, barycenter, barycentric_coordinates
    >>> x = np.linspace(0, 1, 40)
    >>> bumps = np.stack([np.exp(-(x - c) ** 2 / 0.003) for c in (0.2, 0.8)])
    >>> bumps /= bumps.sum(axis=1, keepdims=True)
    >>> geometry = GridGeometry.with_width(40, 1.0)
    >>> target = barycenter(bumps, [0.7, 0.3], geometry, n_iter=30)
    >>> fit = barycentric_coordinates(target, bumps, geometry, n_iter=30)
    >>> np.round(fit.weights, 2).tolist()
    [0.7, 0.3]
    """
    start = time.perf_counter()
    solver = BarycenterSolver(histograms, geometry, n_iter, checkpoint_bytes)
    loss = get_loss(loss)
    S = solver.n_histograms
    if init_weights is None:
        w0 = np.full(S, 1.0 / S)
    else:
        w0 = np.array(init_weights, dtype=np.float64)
        if w0.shape != (S,) or not np.all(np.isfinite(w0)) or np.any(w0 < 0) or w0.sum() <= 0:
            raise ValueError(f"init_weights must be {S} non-negative numbers, not all zero")
        w0 = w0 / w0.sum()
    if max_iter < 1:
        raise ValueError("max_iter must be at least 1")
    # Keep the start strictly inside the simplex: softmax never reaches zero.
    alpha0 = np.log(np.maximum(w0, 1e-12))

    history: list[float] = []
    best: dict = {}
    scale = {}

    def energy(alpha: NDArray) -> tuple[float, NDArray]:
        w = softmax(alpha)
        value, grad_w, P = solver.value_and_grad(w, target, loss)
        history.append(value)
        if "value" not in best or value < best["value"]:
            best.update(value=value, weights=w, barycenter=P)
        if callback is not None:
            callback(len(history), w, value)
        if "scale" not in scale:
            scale["scale"] = abs(value) if value != 0 else 1.0
        # Chain rule through softmax: d/dalpha = w * (grad_w - <w, grad_w>).
        grad_alpha = w * (grad_w - np.dot(w, grad_w))
        return value / scale["scale"], grad_alpha / scale["scale"]

    if S == 1:
        value, _, P = solver.value_and_grad(np.ones(1), target, loss)
        return CoordinatesResult(
            np.ones(1), P, value, value, 1, 0, True, "one histogram", [value],
            time.perf_counter() - start, solver.last_backend,
        )

    import scipy.optimize  # here, not at import: it costs ~0.3 s of every command's start

    result = scipy.optimize.minimize(
        energy,
        alpha0,
        jac=True,
        method="L-BFGS-B",
        options={"maxiter": int(max_iter), "ftol": float(tol), "gtol": 1e-9, "maxcor": 10},
    )
    return CoordinatesResult(
        weights=best["weights"],
        barycenter=best["barycenter"],
        loss=float(best["value"]),
        initial_loss=float(history[0]),
        n_evaluations=len(history),
        n_iterations=int(result.nit),
        converged=bool(result.success),
        message=str(result.message),
        history=history,
        time_s=time.perf_counter() - start,
        backend=solver.last_backend,
    )


def mixture_coordinates(
    target: ArrayLike,
    histograms: ArrayLike,
    geometry: Geometry,
    loss: str | Loss = "quadratic",
    max_iter: int = 30,
    callback: Callable[[int, NDArray, float], None] | None = None,
) -> CoordinatesResult:
    """The Euclidean baseline: weights minimising ``Loss(sum_s w_s p_s, target)``.

    The mixture is linear in the weights, so the energy is convex for the
    quadratic and KL losses; SLSQP handles the simplex directly (weights may
    reach exactly 0, as in the paper's Euclidean projections). Same inputs
    and result as :func:`barycentric_coordinates` (``barycenter`` holds the
    fitted mixture, ``backend`` is ``"mixture"``); ``geometry`` is what the
    loss sees (its kernel for transport losses).
    """
    start = time.perf_counter()
    loss = get_loss(loss)
    stack = _validation.histogram_stack(histograms, geometry)
    q = _validation.target(target, stack.shape[1:], loss, geometry)
    if max_iter < 1:
        raise ValueError("max_iter must be at least 1")
    n = stack.shape[0]
    flat = stack.reshape(n, -1)
    history: list[float] = []
    best: dict = {}
    scale: dict = {}

    def energy(weights: NDArray) -> tuple[float, NDArray]:
        weights = np.clip(weights, 0.0, None)
        weights = weights / weights.sum()
        mixture = np.tensordot(weights, stack, axes=1)
        value, grad_p = loss.value_and_grad(mixture, q, geometry)
        grad = flat @ np.asarray(grad_p).ravel()
        history.append(float(value))
        if "value" not in best or value < best["value"]:
            best.update(value=float(value), weights=weights, mixture=mixture)
        if callback is not None:
            callback(len(history), weights, float(value))
        scale.setdefault("scale", abs(value) if value != 0 else 1.0)
        return value / scale["scale"], grad / scale["scale"]

    import scipy.optimize  # here, not at import: it costs ~0.3 s of every command's start

    result = scipy.optimize.minimize(
        energy,
        np.full(n, 1.0 / n),
        jac=True,
        method="SLSQP",
        bounds=[(0.0, 1.0)] * n,
        constraints=[
            {"type": "eq", "fun": lambda w: w.sum() - 1.0, "jac": lambda w: np.ones_like(w)}
        ],
        options={"maxiter": int(max_iter) * 5, "ftol": 1e-10},
    )
    return CoordinatesResult(
        weights=best["weights"],
        barycenter=best["mixture"],
        loss=best["value"],
        initial_loss=history[0],
        n_evaluations=len(history),
        n_iterations=int(result.nit),
        converged=bool(result.success),
        message=str(result.message),
        history=history,
        time_s=time.perf_counter() - start,
        backend="mixture",
    )
