"""Projecting a density onto a database: its barycentric coordinates (paper §5.4).

A density ``q`` is explained by the Wasserstein barycenter ``P(w)`` of the
database densities, fitted by the core's
:func:`~wbcgrade.core.barycentric_coordinates` (or, with ``euclidean``, by
a linear mixture) on the target ``(1 - alpha) * q / sum(q)``, ``alpha`` the
fraction of the input's mass that is missing (:func:`project`). A
completion (:mod:`wbcgrade.shape.complete`) fits its placed input this way.

Kernel width. The Gibbs kernel is a Gaussian of standard deviation
``width`` voxels (``GridGeometry.with_width``). The barycenter of L
iterations is blurred by about that much, so the width should be small next
to the shapes' thinnest parts, but wide enough for mass to travel between
shapes in L iterations. :func:`default_width` uses 1 voxel at 64^3 and keeps
the width a fixed fraction (1/63) of the box at other resolutions, never below
1 voxel: the same physical smoothing whatever the resolution. Measured at
64^3 (cow 0.9 + triceratops 0.1, L = 60): IoU of the iso-surface with the cow
0.884 at 1.5 voxels, 0.905 at 1.0, 0.913 at 0.75; all in the fast scaling
domain; narrower kernels widen the scalings' range (docs/architecture.md, numerics).

Loss. The default is ``kl_reverse``, ``KL(q | P)``; completions sum it over
the input's voxels only (:data:`KL_OBSERVED`), projections over every voxel;
the paper's ``KL(P | q)`` is ``kl``. The paper's direction
charges the barycenter for every bit of mass it puts where the input is
missing, which is exactly what a completion must do, and on shapes with a
slab cut away it prefers wrong weights to the true ones (see
:data:`KL_REVERSE`); ``kl_reverse`` still charges that mass a little (see
:data:`KL_OBSERVED`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade.core import (
    GridGeometry,
    Loss,
    barycentric_coordinates,
    get_loss,
    mixture_coordinates,
    resample_grid,
)
from wbcgrade.errors import InputError
from wbcgrade.shape.database import check_database_size
from wbcgrade.shape.defaults import DEFAULT_LOSS, DEFAULT_MAX_ITER, DEFAULT_N_ITER

COARSE_MIN_SIZE = 16


# --------------------------------------------------------------------------- loss


KL_REVERSE = get_loss("kl_reverse")
"""KL of the input from the barycenter, ``KL(q | P)`` (the paper's KL reversed).

The paper's ``KL(P | q)`` charges ``P log(P / q)`` where the input is missing
(``q`` at the floor), i.e. it penalises exactly the mass a completion must put
there: on a barycenter of database shapes with a slab cut away, the true
weights score worse than shapes that avoid the cut (measured: 2.14 against
1.51 at 20^3). ``KL(q | P)`` only asks the barycenter to cover the observed
part; a completion costs at most its (linear) mass.
"""

OBSERVED_LEVEL = 0.5
"""Voxels where the target is at least this fraction of its maximum count as observed."""

POINTWISE_LOSSES = ("kl_reverse", "kl", "quadratic", "l1")
"""Losses that are sums over voxels, which :func:`on_observed_voxels` can restrict."""


def on_observed_voxels(loss: str | Loss) -> Loss:
    """A voxel-wise loss summed over the observed voxels only, ``{q >= max(q) / 2}``.

    Outside them the barycenter is compared with ``q`` itself (each term is 0)
    and the gradient is 0. Raises InputError for a loss that is not a sum
    over voxels (``wasserstein``).
    """
    base = get_loss(loss)
    if base.name not in POINTWISE_LOSSES:
        raise InputError(f"the {base.name} loss compares whole shapes and cannot be restricted "
                         "to the observed voxels; compare all voxels instead")

    def value_and_grad(P: np.ndarray, q: np.ndarray, geometry) -> tuple[float, np.ndarray]:
        observed = q >= OBSERVED_LEVEL * float(q.max())
        value, grad = base.value_and_grad(np.where(observed, P, q), q, geometry)
        return value, np.where(observed, grad, 0.0)

    return Loss(f"{base.name}, observed voxels", value_and_grad, base.needs_positive_target)


KL_OBSERVED = on_observed_voxels("kl_reverse")
"""``KL(q | P)`` on the observed voxels only: the sum over ``{q >= max(q) / 2}``
of ``q log(q / P) - q + P`` (generalised KL, unnormalised); what a completion
fits by default.

For a shape with a fraction ``alpha`` missing, ``q`` holds ``1 - alpha`` of
the mass on the observed voxels and the barycenter must match it there; the
remaining ``alpha`` of its mass is free to go where the input is missing.
``KL(q | P)`` over all voxels also charges that mass (its ``+ P`` term,
about ``alpha``), so it prefers barycenters that crowd onto the observed
part over the whole shape (about ``(1 - alpha) log(1 - alpha) + alpha``,
0.02 at ``alpha = 0.2``, against 0.2): measured on a cow with the rear 20 %
of its length cut at 32^3, 0.16 of the weight went to a triceratops and
38 % of the cut part came back (0.98 on the cow and 80 % restored here).
Here the missing fraction matters (too small pulls towards the observed
part, too large towards fatter shapes).
"""


def resolve_loss(name: str | Loss, observed_only: bool = False) -> Loss:
    """The core's :class:`~wbcgrade.core.Loss` called ``name``, restricted to the
    observed voxels with ``observed_only`` (:func:`on_observed_voxels`)."""
    return on_observed_voxels(name) if observed_only else get_loss(name)


def default_width(resolution: int) -> float:
    """Kernel standard deviation in voxels: 1 at 64^3, a fixed 1/63 of the box, >= 1."""
    return max(1.0, (int(resolution) - 1) / 63.0)


# --------------------------------------------------------------------------- fitting


@dataclass(frozen=True)
class Projection:
    """Result of projecting a density onto a database.

    weights : (S,) on the simplex, in database order.
    names : database labels.
    barycenter : (X, Y, Z) fitted density (Wasserstein barycenter, or linear
        mixture for the Euclidean method), sums to about 1.
    target : (X, Y, Z) the density that was fitted, ``(1 - missing) q / sum(q)``.
    missing : the missing fraction used.
    method : "wasserstein" or "euclidean".
    loss_name, loss, initial_loss : the loss, its final value and its value at
        the start of the full-resolution fit (uniform weights, or the coarse
        level's weights).
    width : kernel width in voxels (Wasserstein only; 0 for Euclidean).
    n_evaluations : energy evaluations in all, ``n_coarse_evaluations`` of
        them on the half-size grid of the coarse-to-fine schedule.
    converged : whether the optimiser met its tolerance.
    time_s : wall time of the fit.
    history : loss per evaluation.
    """

    weights: np.ndarray
    names: list[str]
    barycenter: np.ndarray
    target: np.ndarray
    missing: float
    method: str
    loss_name: str
    loss: float
    initial_loss: float
    width: float
    n_evaluations: int
    converged: bool
    time_s: float
    history: list[float] = field(default_factory=list)
    n_coarse_evaluations: int = 0

    def order(self) -> np.ndarray:
        """Database indices by decreasing weight."""
        return np.argsort(-self.weights, kind="stable")


def make_target(density: np.ndarray, missing: float = 0.0) -> np.ndarray:
    """``(1 - missing) * density / sum(density)``, the fitted target."""
    if not 0.0 <= missing < 1.0:
        raise InputError(f"the missing fraction must be in [0, 1), got {missing}")
    density = np.asarray(density, dtype=np.float64)
    total = float(density.sum())
    if not np.isfinite(total) or total <= 0:
        raise InputError("the input is empty")
    return (1.0 - missing) * density / total


def project(
    density: np.ndarray,
    database: Sequence[np.ndarray],
    *,
    names: Sequence[str] | None = None,
    missing: float = 0.0,
    loss: str = DEFAULT_LOSS,
    euclidean: bool = False,
    width: float | None = None,
    n_iter: int = DEFAULT_N_ITER,
    max_iter: int = DEFAULT_MAX_ITER,
    callback: Callable[[int, np.ndarray, float], None] | None = None,
    coarse_to_fine: bool = True,
    init_weights: np.ndarray | None = None,
    observed_only: bool = False,
) -> Projection:
    """Fit ``density`` by a barycenter (or linear mixture) of ``database``.

    Parameters
    ----------
    density : (X, Y, Z) non-negative input density (any total mass); with the
        KL loss it must be positive everywhere (see :func:`density_from_volume`).
    database : S >= 2 arrays of the same shape, each normalised by the core.
    names : labels for the database entries (default "0", "1", ...).
    missing : fraction alpha of the input's mass that is missing.
    loss : one of :data:`LOSS_NAMES`; "kl_reverse" (default, ``KL(q | P)``),
        "kl" (the paper's ``KL(P | q)``), "quadratic", "l1", "wasserstein".
    euclidean : fit the linear mixture ``sum_s w_s p_s`` instead of the
        Wasserstein barycenter (the paper's Figure 10 comparison).
    width : kernel standard deviation in voxels (default :func:`default_width`).
    n_iter : barycenter iterations L.
    max_iter : optimiser iterations at most.
    callback : ``callback(n_evaluations, weights, loss)`` after each evaluation.
    coarse_to_fine : on grids of 32 voxels or more per axis, fit first on a
        grid of half the size (``max_iter`` iterations), then refine on the
        full grid from those weights (``max(3, max_iter // 3)`` iterations):
        one coarse evaluation costs an eighth of a fine one.
    init_weights : (S,) weights to start from (a previous fit): the coarse
        level is skipped and ``max(3, max_iter // 3)`` iterations refine them.
    observed_only : compare the observed voxels only (:func:`on_observed_voxels`;
        :data:`KL_OBSERVED` for ``kl_reverse``).

    Returns
    -------
    Projection
    """
    stack = np.stack([np.asarray(d, dtype=np.float64) for d in database])
    density = np.asarray(density, dtype=np.float64)
    if stack.shape[0] < 2:
        check_database_size([Path(str(i)) for i in range(stack.shape[0])])
    if stack.shape[1:] != density.shape or density.ndim != 3:
        raise InputError(
            f"the input volume has shape {density.shape} but the database {stack.shape[1:]}"
        )
    names = [str(i) for i in range(len(stack))] if names is None else [str(n) for n in names]
    target = make_target(density, missing)
    loss_object = resolve_loss(loss, observed_only)
    if loss_object.needs_positive_target and np.any(target <= 0):
        raise InputError(f"the {loss} loss needs an input density positive everywhere")
    start = time.perf_counter()
    if euclidean:
        # the losses see the grid's kernel (transport losses) or just its shape
        geometry = GridGeometry.with_width(target.shape, default_width(max(target.shape)))
        mixture = mixture_coordinates(target, stack, geometry, loss_object, max_iter, callback)
        weights, fitted, value = mixture.weights, mixture.barycenter, mixture.loss
        initial, history, converged = mixture.initial_loss, mixture.history, mixture.converged
        used_width, n_coarse = 0.0, 0
    else:
        used_width = default_width(max(density.shape)) if width is None else float(width)
        fine_iter, coarse_history = max_iter, []
        if init_weights is not None:
            init_weights = np.asarray(init_weights, dtype=np.float64)
            init_weights = (init_weights + 1e-3) / (1.0 + 1e-3 * len(init_weights))
            fine_iter = max(3, max_iter // 3)
        elif coarse_to_fine and min(density.shape) >= 2 * COARSE_MIN_SIZE:
            # Half size, corners aligned, each density's mass kept (positive stays positive).
            coarse_shape = tuple((n + 1) // 2 for n in density.shape)
            coarse_target = resample_grid(target, coarse_shape)
            coarse_stack = resample_grid(stack, coarse_shape)
            coarse_width = used_width * (max(coarse_target.shape) - 1) / (max(density.shape) - 1)
            coarse = barycentric_coordinates(
                coarse_target, coarse_stack,
                GridGeometry.with_width(coarse_target.shape, max(coarse_width, 1.0)),
                loss=loss_object, n_iter=n_iter, max_iter=max_iter, callback=callback,
            )
            # A small floor lets the fine level revive a weight the coarse one dropped.
            init_weights = (coarse.weights + 1e-3) / (1.0 + 1e-3 * len(coarse.weights))
            coarse_history = list(coarse.history)
            fine_iter = max(3, max_iter // 3)
        fine_callback = callback
        if callback is not None and coarse_history:
            offset = len(coarse_history)

            def fine_callback(k: int, w: np.ndarray, value: float) -> None:
                callback(offset + k, w, value)

        geometry = GridGeometry.with_width(density.shape, used_width)
        fit = barycentric_coordinates(
            target, stack, geometry, loss=loss_object, n_iter=n_iter, max_iter=fine_iter,
            init_weights=init_weights, callback=fine_callback,
        )
        weights, fitted, value = fit.weights, fit.barycenter, fit.loss
        initial, converged = fit.initial_loss, fit.converged
        history, n_coarse = coarse_history + list(fit.history), len(coarse_history)
    return Projection(
        weights=np.asarray(weights, dtype=np.float64),
        names=names,
        barycenter=fitted,
        target=target,
        missing=float(missing),
        method="euclidean" if euclidean else "wasserstein",
        loss_name=loss_object.name,
        loss=float(value),
        initial_loss=float(initial),
        width=used_width,
        n_evaluations=len(history),
        n_coarse_evaluations=n_coarse,
        converged=bool(converged),
        time_s=time.perf_counter() - start,
        history=history,
    )
