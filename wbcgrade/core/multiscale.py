r"""Multiscale Sinkhorn on grids: epsilon scaling and coarse-to-fine warm starts.

A narrow kernel converges slowly from a cold start (the iterations move
mass about one kernel width each). :func:`multiscale_sinkhorn` solves the
same problem first on coarser grids, each axis halved down to ``coarsest``
bins, with the *same* kernel in the units of the box (``gamma`` is the same
on every level, since every grid spans ``[0, 1]`` per axis), and on the
coarsest grid first with wider kernels (``gamma f^2`` for each factor ``f``
of ``schedule``: epsilon scaling). Each solve warm-starts the next with its
dual potential ``gamma log b``, interpolated onto the finer grid
(:func:`~wbcgrade.core.refine_grid`). Marginals are re-binned onto the
coarser grids with :func:`~wbcgrade.core.resample_grid` (mass kept).

The fixed point is the one :func:`~wbcgrade.core.sinkhorn` finds on the
finest grid; only the number of (costly) finest-grid iterations changes.

References
----------
Schmitzer (2019), Stabilized sparse scaling algorithms for entropy regularized
transport problems; Feydy (2020), Geometric data analysis, beyond convolutions.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wbcgrade.core import _validation
from wbcgrade.core.geometry import Geometry, refine_grid, resample_grid
from wbcgrade.core.sinkhorn import SinkhornLevel, SinkhornResult, sinkhorn
from wbcgrade.errors import ConvergenceWarning

__all__ = ["multiscale_sinkhorn", "grid_levels"]


def grid_levels(shape: tuple[int, ...], coarsest: int = 32) -> list[tuple[int, ...]]:
    """The grids of a multiscale solve, coarsest first, ``shape`` last.

    Each level halves (``n // 2``) every axis whose half keeps at least
    ``max(coarsest, 4)`` bins; the others stay as they are.
    """
    least = max(int(coarsest), 4)
    levels = [tuple(int(n) for n in shape)]
    while True:
        half = tuple(n // 2 if n // 2 >= least else n for n in levels[-1])
        if half == levels[-1]:
            break
        levels.append(half)
    return levels[::-1]


def _mix_uniform(hist: NDArray, floor: float) -> NDArray:
    """``(1 - floor) h / sum(h) + floor / N``."""
    hist = hist / hist.sum()
    if floor <= 0:
        return hist
    return (1.0 - floor) * hist + floor / hist.size


def multiscale_sinkhorn(
    p: ArrayLike,
    q: ArrayLike,
    geometry: Geometry,
    *,
    coarsest: int = 32,
    schedule: Sequence[float] = (4.0, 2.0),
    tol: float = 1e-6,
    coarse_tol: float | None = None,
    schedule_tol: float = 1e-2,
    max_iter: int = 1000,
    floor: float = 0.0,
    relaxation: float | None = None,
    overrelaxation: float = 1.7,
    fine_overrelaxation: float = 1.5,
    check_every: int = 1,
    method: str = "auto",
    warn: bool = True,
) -> SinkhornResult:
    """Entropic optimal transport on a grid, solved coarse to fine with epsilon scaling.

    The same problem as :func:`~wbcgrade.core.sinkhorn` on ``geometry`` (the
    module docstring says how the levels are built). Every solve is a
    :func:`~wbcgrade.core.sinkhorn` call and takes its options.

    Parameters
    ----------
    p, q : array_like, shape geometry.shape
        Non-negative marginals (one problem, no batch axes); each is
        normalised to sum 1.
    geometry : GridGeometry
        The finest grid and the kernel (its ``gamma``, in the units of the box).
    coarsest : int, default 32
        No axis is halved below ``max(coarsest, 4)`` bins; ``coarsest`` at
        least the largest axis gives a single-grid solve (with the schedule).
    schedule : sequence of float, default (4.0, 2.0)
        Kernel width factors ``f > 1``, solved in this order on the coarsest
        grid before its own kernel, with ``gamma f^2``; ``()`` for none.
    tol : float, default 1e-6
        L1 error on the first marginal at which the finest solve stops.
    coarse_tol : float, optional
        Tolerance of the coarser grids' solves, default ``tol / 3``: what error
        they leave is removed on the finest grid, where an iteration costs most.
    schedule_tol : float, default 1e-2
        The wider kernels' solves stop at ``max(level tolerance, schedule_tol)``.
    max_iter : int, default 1000
        Iterations at most, per solve.
    floor : float, default 0.0
        Every level's marginals, after re-binning, are mixed with the uniform
        histogram: ``(1 - floor) p / sum(p) + floor / N`` (keeps every scaling
        finite where a marginal has no mass; 0: unchanged).
    relaxation : float, optional
        Unbalanced transport on the second marginal, as in ``sinkhorn``.
    overrelaxation, fine_overrelaxation : float, default 1.7 and 1.5
        ``sinkhorn``'s ``overrelaxation`` on the coarser grids and on the
        finest one (plain iterations come back by themselves if relaxed ones
        stall).
    check_every : int, default 1
        Iterations between convergence checks (levels are short: checking
        every iteration stops each as soon as it reaches its tolerance).
    method : {"auto", "scaling", "log"}, default "auto"
        As in ``sinkhorn``, on every level.
    warn : bool, default True
        Issue a :class:`~wbcgrade.errors.ConvergenceWarning` when the finest
        solve ends above ``tol`` (coarser solves only warm-start it).

    Returns
    -------
    SinkhornResult
        The finest solve (``n_iter``, ``errors`` and ``method`` are its own),
        with ``levels``: every solve's grid, gamma, iterations and error,
        coarsest first.

    Raises
    ------
    TypeError
        ``geometry`` is not a :class:`~wbcgrade.core.GridGeometry` (coarser
        levels are built from its shape; use ``sinkhorn`` on other geometries).
    """
    if not geometry.is_grid:
        raise TypeError(
            "multiscale_sinkhorn needs a GridGeometry (its coarser grids are built from the "
            f"grid's shape), got {type(geometry).__name__}; use sinkhorn() on other geometries")
    p_fine = _validation.histograms(p, geometry, "p")
    q_fine = _validation.histograms(q, geometry, "q")
    for name, x in (("p", p_fine), ("q", q_fine)):
        if x.shape != geometry.shape:
            raise ValueError(f"{name} must have the geometry's shape {geometry.shape} (one "
                             f"problem, no batch axes), got {x.shape}")
    factors = [float(f) for f in schedule]
    if not all(np.isfinite(f) and f > 1.0 for f in factors):
        raise ValueError(f"schedule factors must be finite and > 1, got {tuple(schedule)}")
    if not (np.isfinite(floor) and 0.0 <= floor < 1.0):
        raise ValueError(f"floor must be in [0, 1), got {floor!r}")
    if int(coarsest) < 1:
        raise ValueError(f"coarsest must be a positive number of bins, got {coarsest!r}")
    # The inputs, as given: validation normalised copies (bit-for-bit the same
    # marginals as re-binning and mixing the caller's arrays).
    p_in, q_in = np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
    levels = grid_levels(geometry.shape, coarsest)
    fine_start_tol = tol / 3.0 if coarse_tol is None else float(coarse_tol)
    log_b, gamma_prev, shape_prev = None, None, None
    trace: list[SinkhornLevel] = []
    result = None
    for shape in levels:
        finest = shape == geometry.shape
        p_level = _mix_uniform(p_in if finest else resample_grid(p_in, shape, mass=1.0), floor)
        q_level = _mix_uniform(q_in if finest else resample_grid(q_in, shape, mass=1.0), floor)
        level_tol = tol if finest else fine_start_tol
        for factor in (factors if shape == levels[0] else []) + [1.0]:
            if factor == 1.0 and finest:
                level_geometry = geometry
            else:
                level_geometry = geometry.with_grid(shape, geometry.gamma * factor ** 2)
            init = None
            if log_b is not None:
                init = log_b * (gamma_prev / level_geometry.gamma)  # gamma log b carries over
                if shape_prev != shape:
                    init = refine_grid(init, shape)
            result = sinkhorn(
                p_level, q_level, level_geometry,
                tol=level_tol if factor == 1.0 else max(level_tol, schedule_tol),
                max_iter=max_iter, init_log_b=init, check_every=check_every,
                relaxation=relaxation,
                overrelaxation=fine_overrelaxation if finest else overrelaxation,
                method=method, warn=False)
            trace.append(SinkhornLevel(shape, level_geometry.gamma, result.n_iter, result.error,
                                       result.method))
            log_b, gamma_prev, shape_prev = result.log_b, level_geometry.gamma, shape
    if warn and not result.converged:
        warnings.warn(ConvergenceWarning(
            f"multiscale_sinkhorn: the finest solve stopped after {result.n_iter} iterations "
            f"with marginal error {result.error:.3g} > tol {tol:g}"), stacklevel=2)
    return SinkhornResult(result.log_a, result.log_b, result.n_iter, result.error,
                          result.converged, result.errors, result.method, tuple(trace))
