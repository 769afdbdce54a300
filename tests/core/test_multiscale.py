"""Multiscale Sinkhorn: the single-grid fixed point, fewer fine iterations, levels, errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from tests.core.helpers import blobs
from wbcgrade.core import DenseGeometry, GridGeometry, multiscale_sinkhorn, sinkhorn
from wbcgrade.core.multiscale import grid_levels
from wbcgrade.errors import ConvergenceWarning


def _plan(result, geometry: GridGeometry) -> np.ndarray:
    """The dense plan ``diag(a) K diag(b)`` (small grids only)."""
    K = np.exp(-geometry.cost_matrix() / geometry.gamma)
    return np.exp(result.log_a).ravel()[:, None] * K * np.exp(result.log_b).ravel()[None, :]


@pytest.fixture
def problem(rng):
    """A non-cubic 2-D grid and a kernel one bin wide: slow from a cold start."""
    shape = (32, 24)
    geometry = GridGeometry(shape, 2 * (1.0 / 31) ** 2)
    p, q = blobs(shape, 2, rng, width=0.1, floor=1e-5, components=3)
    return p, q, geometry


def test_grid_levels_halve_each_axis_down_to_coarsest():
    assert grid_levels((128, 128, 128), 32) == [(32, 32, 32), (64, 64, 64), (128, 128, 128)]
    assert grid_levels((32, 24), 8) == [(8, 12), (16, 12), (32, 24)]
    assert grid_levels((40, 30), 64) == [(40, 30)]
    assert grid_levels((9, 9), 1) == [(4, 4), (9, 9)]  # never below 4 bins


def test_the_multiscale_plan_is_the_single_grid_plan(problem):
    p, q, geometry = problem
    single = sinkhorn(p, q, geometry, tol=1e-9, max_iter=20000)
    multi = multiscale_sinkhorn(p, q, geometry, coarsest=8, tol=1e-9, max_iter=20000)
    assert single.converged and multi.converged and multi.error <= 1e-9
    plan = _plan(multi, geometry)
    assert np.abs(plan - _plan(single, geometry)).sum() < 1e-7
    np.testing.assert_allclose(plan.sum(axis=0), q.ravel(), atol=1e-9)


def test_coarse_levels_save_finest_iterations(problem):
    p, q, geometry = problem
    cold = sinkhorn(p, q, geometry, tol=1e-6, max_iter=20000, check_every=1,
                    overrelaxation=1.5)
    multi = multiscale_sinkhorn(p, q, geometry, coarsest=8, tol=1e-6, max_iter=20000)
    assert multi.converged and cold.converged
    assert multi.n_iter < cold.n_iter / 2, (multi.n_iter, cold.n_iter)
    # The levels: epsilon scaling on the coarsest grid, then the same kernel
    # (gamma in the units of the box) on every grid; the result is the last solve.
    g = geometry.gamma
    assert [(lv.shape, lv.gamma) for lv in multi.levels] == [
        ((8, 12), 16 * g), ((8, 12), 4 * g), ((8, 12), g), ((16, 12), g), ((32, 24), g)]
    assert multi.levels[-1].n_iter == multi.n_iter and multi.levels[-1].error == multi.error


def test_warm_starts_from_coarser_grids_reach_the_same_fixed_point(problem):
    """Without epsilon scaling, and from different coarsest grids: one plan."""
    p, q, geometry = problem
    plans = [_plan(multiscale_sinkhorn(p, q, geometry, coarsest=c, schedule=s, tol=1e-10,
                                       max_iter=20000), geometry)
             for c, s in ((8, ()), (16, ()), (32, (2.0,)))]
    assert np.abs(plans[0] - plans[1]).sum() < 1e-8
    assert np.abs(plans[0] - plans[2]).sum() < 1e-8


def test_log_domain_levels_give_the_scaling_plan(problem):
    p, q, geometry = problem
    scaling = multiscale_sinkhorn(p, q, geometry, coarsest=8, tol=1e-9, max_iter=20000)
    log = multiscale_sinkhorn(p, q, geometry, coarsest=8, tol=1e-9, max_iter=20000,
                              method="log")
    assert log.method == "log" and {lv.method for lv in log.levels} == {"log"}
    assert np.abs(_plan(log, geometry) - _plan(scaling, geometry)).sum() < 1e-7


def test_floor_and_relaxation_are_those_of_the_finest_problem(problem):
    p, q, geometry = problem
    floor, rho = 1e-3, 0.05
    multi = multiscale_sinkhorn(p, q, geometry, coarsest=8, tol=1e-9, max_iter=20000,
                                floor=floor, relaxation=rho)
    mixed_p, mixed_q = ((1 - floor) * h + floor / h.size for h in (p, q))
    single = sinkhorn(mixed_p, mixed_q, geometry, tol=1e-9, max_iter=20000, relaxation=rho)
    plan = _plan(multi, geometry)
    assert np.abs(plan - _plan(single, geometry)).sum() < 1e-7
    assert np.abs(plan.sum(axis=1) - mixed_p.ravel()).sum() <= 1.01e-9


def test_unconverged_finest_solve_warns_once(problem):
    p, q, geometry = problem
    with pytest.warns(ConvergenceWarning, match="multiscale_sinkhorn") as caught:
        result = multiscale_sinkhorn(p, q, geometry, coarsest=8, tol=1e-12, max_iter=5)
    assert not result.converged and len(caught) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        multiscale_sinkhorn(p, q, geometry, coarsest=8, tol=1e-12, max_iter=5, warn=False)


def test_needs_a_grid_and_one_problem(problem):
    p, q, geometry = problem
    dense = DenseGeometry(geometry.cost_matrix(), geometry.gamma)
    with pytest.raises(TypeError, match="GridGeometry"):
        multiscale_sinkhorn(p.ravel(), q.ravel(), dense)
    with pytest.raises(ValueError, match="no batch axes"):
        multiscale_sinkhorn(np.stack([p, p]), np.stack([q, q]), geometry)
    with pytest.raises(ValueError, match="schedule"):
        multiscale_sinkhorn(p, q, geometry, schedule=(0.5,))
    with pytest.raises(ValueError, match="floor"):
        multiscale_sinkhorn(p, q, geometry, floor=1.0)
