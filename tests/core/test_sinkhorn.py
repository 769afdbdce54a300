"""Sinkhorn: marginals, the two domains agree, memory layouts, batches, relaxation."""

from __future__ import annotations

import importlib
import logging

import numpy as np
import pytest

from tests.core.helpers import blobs
from wbcgrade.core import GridGeometry, sinkhorn

sinkhorn_module = importlib.import_module("wbcgrade.core.sinkhorn")


def _plan(result, geometry: GridGeometry) -> np.ndarray:
    """The dense plan ``diag(a) K diag(b)`` (small grids only)."""
    K = np.exp(-geometry.cost_matrix() / geometry.gamma)
    return np.exp(result.log_a).ravel()[:, None] * K * np.exp(result.log_b).ravel()[None, :]


@pytest.fixture
def problem(rng):
    geometry = GridGeometry((8, 8, 8), 2 * (1.2 / 7) ** 2)
    p, q = blobs(geometry.shape, 2, rng, width=0.15, floor=1e-4, components=2)
    return p, q, geometry


def test_the_plan_has_both_marginals(problem):
    p, q, geometry = problem
    result = sinkhorn(p, q, geometry, tol=1e-9, max_iter=5000)
    plan = _plan(result, geometry)
    assert result.converged
    assert np.abs(plan.sum(axis=1) - p.ravel()).sum() <= 1e-9 * 1.01
    assert np.abs(plan.sum(axis=0) - q.ravel()).sum() < 1e-7


def test_scaling_and_log_domains_give_the_same_plan(problem, monkeypatch):
    p, q, geometry = problem
    scaled = sinkhorn(p, q, geometry, tol=1e-10, max_iter=5000)

    def unsafe(*args, **kwargs):
        raise sinkhorn_module._Unsafe("forced")

    monkeypatch.setattr(sinkhorn_module, "_scaling", unsafe)
    logged = sinkhorn(p, q, geometry, tol=1e-10, max_iter=5000)
    assert scaled.n_iter == logged.n_iter
    np.testing.assert_allclose(logged.log_a, scaled.log_a, atol=1e-8)
    np.testing.assert_allclose(logged.log_b, scaled.log_b, atol=1e-8)


def test_any_memory_layout_stays_in_the_scaling_domain(problem, caplog):
    """Fortran-ordered and transposed inputs: same answer, no fallback to the log domain
    (the fused passes once wrote into a copy of a non-contiguous array and found 0)."""
    p, q, geometry = problem
    reference = sinkhorn(p, q, geometry, tol=1e-8, max_iter=5000)
    with caplog.at_level(logging.INFO, logger="wbcgrade.core.sinkhorn"):
        for layout in (np.asfortranarray, lambda x: np.ascontiguousarray(x.T).T):
            result = sinkhorn(layout(p), layout(q), geometry, tol=1e-8, max_iter=5000,
                              init_log_b=layout(np.zeros(geometry.shape)))
            assert result.n_iter == reference.n_iter
            np.testing.assert_allclose(result.log_a, reference.log_a, atol=1e-10)
    assert "log domain" not in caplog.text


def test_a_batch_solves_each_problem(problem, rng):
    p, q, geometry = problem
    p2, q2 = blobs(geometry.shape, 2, rng, width=0.2, floor=1e-4)
    batch = sinkhorn(np.stack([p, p2]), np.stack([q, q2]), geometry, tol=1e-9, max_iter=5000)
    for i, (pi, qi) in enumerate(((p, q), (p2, q2))):
        single = sinkhorn(pi, qi, geometry, tol=1e-9, max_iter=5000)
        np.testing.assert_allclose(batch.log_b[i] - batch.log_b[i].mean(),
                                   single.log_b - single.log_b.mean(), atol=1e-5)


@pytest.mark.slow
def test_a_large_relaxation_is_balanced_transport_and_a_small_one_is_not(problem):
    p, q, geometry = problem
    balanced = _plan(sinkhorn(p, q, geometry, tol=1e-10, max_iter=5000), geometry)
    loose = _plan(sinkhorn(p, q, geometry, tol=1e-10, max_iter=5000, relaxation=1e6,
                           warn=False), geometry)  # slow to reach 1e-10: close enough
    tight = _plan(sinkhorn(p, q, geometry, tol=1e-10, max_iter=5000, relaxation=1e-3),
                  geometry)
    assert np.abs(loose - balanced).sum() < 1e-4
    # The relaxed side no longer matches q; the first marginal still does.
    assert np.abs(tight.sum(axis=0) - q.ravel()).sum() > 1e-2
    assert np.abs(tight.sum(axis=1) - p.ravel()).sum() < 1e-9


def test_overrelaxation_reaches_the_same_plan_in_fewer_iterations(rng):
    geometry = GridGeometry((12, 12, 12), 2 * (0.8 / 11) ** 2)  # narrow: slow plain iterations
    p, q = blobs(geometry.shape, 2, rng, width=0.12, floor=1e-5, components=3)
    plain = sinkhorn(p, q, geometry, tol=1e-6, max_iter=20000, check_every=1)
    fast = sinkhorn(p, q, geometry, tol=1e-6, max_iter=20000, check_every=1,
                    overrelaxation=1.7)
    assert plain.converged and fast.converged
    assert fast.n_iter < 0.6 * plain.n_iter
    np.testing.assert_allclose(_plan(fast, geometry), _plan(plain, geometry), atol=1e-6)


def test_a_diverging_overrelaxation_falls_back_to_plain_iterations(problem, monkeypatch, caplog):
    p, q, geometry = problem
    plain = sinkhorn(p, q, geometry, tol=1e-8, max_iter=5000)

    def broken(errors, error, omega):  # as if the relaxed iterations went astray
        if omega != 1.0:
            raise sinkhorn_module._Diverged("forced")

    monkeypatch.setattr(sinkhorn_module, "_watch", broken)
    with caplog.at_level(logging.INFO, logger="wbcgrade.core.sinkhorn"):
        result = sinkhorn(p, q, geometry, tol=1e-8, max_iter=5000, overrelaxation=1.9)
    assert "diverged" in caplog.text and result.n_iter == plain.n_iter
    np.testing.assert_allclose(result.log_a, plain.log_a)
    with pytest.raises(ValueError, match="overrelaxation"):
        sinkhorn(p, q, geometry, overrelaxation=2.0)


def test_overrelaxation_in_the_log_domain_matches_the_scaling_domain(problem, monkeypatch):
    p, q, geometry = problem
    scaled = sinkhorn(p, q, geometry, tol=1e-10, max_iter=5000, overrelaxation=1.5)

    def unsafe(*args, **kwargs):
        raise sinkhorn_module._Unsafe("forced")

    monkeypatch.setattr(sinkhorn_module, "_scaling", unsafe)
    logged = sinkhorn(p, q, geometry, tol=1e-10, max_iter=5000, overrelaxation=1.5)
    assert logged.n_iter == scaled.n_iter
    np.testing.assert_allclose(logged.log_b, scaled.log_b, atol=1e-7)


@pytest.mark.parametrize("shape", [(8, 8, 8), (6, 9, 7)])
def test_the_grid_projection_is_the_plan_average(rng, shape):
    """The separable projection on a grid (9 axis products) is the plan's average of the
    bins' coordinates, as from the full products of the general path."""
    from wbcgrade.core import barycentric_projection

    geometry = GridGeometry(shape, 2 * (1.2 / 7) ** 2)
    p, q = blobs(geometry.shape, 2, rng, width=0.15, floor=1e-4, components=2)
    result = sinkhorn(p, q, geometry, tol=1e-8)
    fast = barycentric_projection(result, geometry)
    general = barycentric_projection(result, geometry, values=geometry.points)
    plan = _plan(result, geometry)
    exact = (plan @ geometry.points) / plan.sum(axis=1, keepdims=True)
    assert fast.shape == general.shape == (*shape, 3)
    np.testing.assert_allclose(fast, general, rtol=0, atol=1e-13)
    np.testing.assert_allclose(fast.reshape(-1, 3), exact, rtol=0, atol=1e-12)
