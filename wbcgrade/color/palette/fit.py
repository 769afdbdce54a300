"""The weight fit of a grade, never worse than one style alone.

Barycentric coordinates (``wbcgrade.core.barycentric_coordinates``) are
fitted from uniform weights. The energy is not convex, so a fit can end
above the loss of a single style (a vertex of the simplex): every vertex is
evaluated with the same core loss on the same histograms, and when the fit
is worse than the best vertex it is refitted from that vertex, keeping the
better of the refit and the vertex itself. With two cores or more and a fit
grid of :data:`SPECULATE_BINS` or more the refit runs ahead in its own thread
beside the fit from uniform weights (docs/architecture.md, threads).

>>> import numpy as np
>>> from wbcgrade.color.palette.fit import fit_weights
>>> from wbcgrade.color.histogram import soft_histogram
>>> from wbcgrade.color.options import FitOptions
>>> rng = np.random.default_rng(0)
>>> styles = np.stack([soft_histogram(rng.random((500, 3)) * 0.5 + shift, 8)
...                    for shift in (0.0, 0.5)])
>>> photo = soft_histogram(rng.random((500, 3)) * 0.5 + 0.5, 8)
>>> summary = fit_weights(photo, styles, FitOptions(bins=8, max_iter=5, n_iter=10))
>>> int(np.argmax(summary.weights)), summary.loss <= summary.vertex_losses.min()
(1, True)
"""

from __future__ import annotations

import concurrent.futures
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wbcgrade.color.histogram import add_floor
from wbcgrade.color.options import FitOptions
from wbcgrade.color.outcome import FitStart
from wbcgrade.core import GridGeometry, barycenter, barycentric_coordinates, get_loss, n_workers

__all__ = ["NONZERO_THRESHOLD", "FitSummary", "fit_geometry", "fit_problem", "loss_at",
           "vertex_losses", "fit_weights", "given_weights"]

#: Weights at or above this count as "non-zero" (softmax weights are never exactly 0).
NONZERO_THRESHOLD = 1e-3

FitCallback = Callable[[int, np.ndarray, float], None]


@dataclass(frozen=True)
class FitSummary:
    """The weights of a grade and how they compare with single styles.

    Attributes
    ----------
    weights : (S,) weights on the simplex.
    loss : loss of the barycenter at ``weights`` (fit grid, the fit's loss).
    vertex_losses : (S,) loss of each style alone (weight 1 on it).
    start : how a palette fit found the weights, a :class:`~wbcgrade.color.outcome.FitStart`
        value: "uniform" (the fit from uniform weights was kept), "vertex-refit"
        (the refit from the best vertex won), "vertex" (the best single style
        is the answer) or "given" (weights fixed by the user); None when no palette
        fit made them (a look: the grade's ``source`` says where it came from).
    info : fit diagnostics (JSON-friendly; :attr:`converged` and :attr:`evaluations`
        read it).
    time_s : wall time of the fit and the vertex checks.
    """

    weights: np.ndarray
    loss: float
    vertex_losses: np.ndarray
    start: str | None = "uniform"
    info: dict = field(default_factory=dict)
    time_s: float = 0.0

    @property
    def fit_start(self) -> FitStart | None:
        """``start`` as a :class:`~wbcgrade.color.outcome.FitStart` (None: no palette fit)."""
        return None if self.start is None else FitStart(self.start)

    @property
    def converged(self) -> bool:
        """Whether the weight fit converged (True when nothing was fitted)."""
        return bool(self.info.get("converged", True)) if self.info else True

    @property
    def evaluations(self) -> int:
        """Loss evaluations of the fit (0 when nothing was fitted)."""
        return int(self.info.get("evaluations", 0)) if self.info else 0

    @property
    def best_vertex(self) -> int:
        return int(np.argmin(self.vertex_losses))

    @property
    def n_nonzero(self) -> int:
        return int(np.sum(self.weights >= NONZERO_THRESHOLD))


def fit_geometry(options: FitOptions):
    """The core grid geometry the weights are fitted on (float32 products where they are
    exact enough; the core falls back to float64)."""
    return GridGeometry((options.bins,) * 3, options.kernel_gamma, np.float32)


def fit_problem(photo_fit: np.ndarray, style_fit: np.ndarray, options: FitOptions):
    """What the fit compares: (target (m, m, m), styles (S, m, m, m), both floored
    (``options.floor``), the grid geometry of :func:`fit_geometry`)."""
    target = add_floor(photo_fit, options.floor)
    hists = np.stack([add_floor(h, options.floor) for h in style_fit])
    return target, hists, fit_geometry(options)


def loss_at(target, hists, geometry, weights, options: FitOptions) -> float:
    """The fit's loss of the barycenter of ``hists`` at ``weights`` (S,) against ``target``
    (the three from :func:`fit_problem`)."""
    keep = np.flatnonzero(weights > 0)
    P = barycenter(hists[keep], weights[keep] / weights[keep].sum(), geometry, options.n_iter)
    value, _ = get_loss(options.loss).value_and_grad(P, target, geometry)
    return float(value)


def vertex_losses(photo_fit: np.ndarray, style_fit: np.ndarray,
                  options: FitOptions) -> np.ndarray:
    """Loss of every single style against the photo, with the fit's loss and grid.

    Parameters
    ----------
    photo_fit : (m, m, m) photo histogram on the fit grid (m = options.bins).
    style_fit : (S, m, m, m) style histograms on the same grid.

    Returns
    -------
    (S,) losses of ``P_L(e_s)`` (the barycenter with all weight on style s).
    """
    target, hists, geometry = fit_problem(photo_fit, style_fit, options)
    return np.array([loss_at(target, hists, geometry, np.eye(len(hists))[s], options)
                     for s in range(len(hists))])


def given_weights(photo_fit: np.ndarray, style_fit: np.ndarray, options: FitOptions,
                  weights: np.ndarray) -> FitSummary:
    """The summary of fixed weights: their loss and every vertex's (no fit)."""
    start = time.perf_counter()
    target, hists, geometry = fit_problem(photo_fit, style_fit, options)
    vertices = vertex_losses(photo_fit, style_fit, options)
    weights = np.asarray(weights, dtype=np.float64)
    weights = weights / weights.sum()
    loss = loss_at(target, hists, geometry, weights, options)
    return FitSummary(weights, loss, vertices, "given", {"start": "given"},
                      time.perf_counter() - start)


class _Cancelled(Exception):
    """Stops a speculative refit whose answer is no longer needed."""


class _HeldProgress:
    """The progress callback of a fit run ahead of time, in another thread.

    Its calls are held until the fit is known to be needed, then replayed in
    order (the caller sees the same calls as from a sequential run); once
    cancelled, the next call stops the fit.
    """

    def __init__(self) -> None:
        self.calls: list[tuple[int, np.ndarray, float]] = []
        self.cancelled = threading.Event()

    def __call__(self, n_evaluations: int, weights: np.ndarray, value: float) -> None:
        if self.cancelled.is_set():
            raise _Cancelled
        self.calls.append((n_evaluations, np.array(weights, copy=True), value))

    def replay(self, callback: FitCallback | None) -> None:
        if callback is not None:
            for call in self.calls:
                callback(*call)


#: Smallest fit grid (bins per axis) on which the refit runs ahead in a thread: below it an
#: evaluation is mostly Python and two fits share one interpreter lock (docs/benchmarks.md).
SPECULATE_BINS = 32


def _speculate(bins: int = SPECULATE_BINS) -> bool:
    """Whether the refit from the best vertex runs ahead: a second core is there and the
    fit grid (``bins`` per axis) is large enough for its products to leave the lock."""
    return bins >= SPECULATE_BINS and n_workers() >= 2


def fit_weights(photo_fit: np.ndarray, style_fit: np.ndarray, options: FitOptions,
                callback: FitCallback | None = None) -> FitSummary:
    """Barycentric coordinates of a photo's histogram, never worse than the best single style.

    Fits from uniform weights, evaluates every vertex; if the best vertex has
    a lower loss, refits from it (95 % on that style) and keeps the better of
    the refit and the vertex. With ``options.weights`` set, only evaluates
    the losses of those weights and of the vertices (:func:`given_weights`).

    With two cores or more and a fit grid of :data:`SPECULATE_BINS` bins or more
    the refit runs ahead of time, beside the fit from uniform weights (the fit
    runs on one core: its products are too small to share), and is kept only
    when the vertex beats that fit; otherwise it is
    stopped. The answer and the callback's calls are those of running the two
    one after the other (the refit's calls are held and replayed).

    Parameters
    ----------
    photo_fit : (m, m, m) photo histogram on the fit grid (m = options.bins).
    style_fit : (S, m, m, m) style histograms on the fit grid.
    callback : ``callback(n_evaluations, weights, loss)`` after each evaluation.
    """
    if options.weights is not None:
        return given_weights(photo_fit, style_fit, options, np.asarray(options.weights))
    start = time.perf_counter()
    target, hists, geometry = fit_problem(photo_fit, style_fit, options)
    n_styles = len(hists)
    vertices = vertex_losses(photo_fit, style_fit, options)
    best = int(np.argmin(vertices))

    def fit_from(init: np.ndarray | None, progress: FitCallback | None):
        return barycentric_coordinates(target, hists, geometry, loss=options.loss,
                                       n_iter=options.n_iter, init_weights=init,
                                       max_iter=options.max_iter, tol=options.tol,
                                       callback=progress)

    def refit_from_best(progress: FitCallback | None):
        init = np.full(n_styles, 0.05 / (n_styles - 1))
        init[best] = 0.95
        return fit_from(init, progress)

    ahead: concurrent.futures.Future | None = None
    held = _HeldProgress()
    if n_styles > 1 and _speculate(options.bins):
        runner = concurrent.futures.ThreadPoolExecutor(1, "refit-ahead")
        ahead = runner.submit(refit_from_best, held)
        runner.shutdown(wait=False)
    try:
        fit = fit_from(None, callback)
        info = {"evaluations": fit.n_evaluations, "iterations": fit.n_iterations,
                "converged": fit.converged, "initial_loss": float(fit.initial_loss),
                "bins": options.bins, "gamma": float(geometry.gamma)}
        weights, loss, how = np.asarray(fit.weights, dtype=np.float64), float(fit.loss), \
            "uniform"
        if vertices[best] < loss and n_styles > 1:
            if ahead is not None:
                refit = ahead.result()
                held.replay(callback)
            else:
                refit = refit_from_best(callback)
            info["uniform_start_loss"] = loss
            info["evaluations"] += refit.n_evaluations
            if refit.loss < vertices[best]:
                weights, loss, how = np.asarray(refit.weights, dtype=np.float64), \
                    float(refit.loss), "vertex-refit"
                info["converged"] = refit.converged
            else:
                weights, loss, how = np.eye(n_styles)[best], float(vertices[best]), "vertex"
    finally:
        held.cancelled.set()  # a refit not needed (or not waited for) stops at its next step
    info["start"] = how
    return FitSummary(weights, loss, vertices, how, info, time.perf_counter() - start)
