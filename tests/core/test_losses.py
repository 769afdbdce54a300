"""The entropic transport losses: debiasing, gradients, warm starts, fresh instances."""

from __future__ import annotations

import numpy as np
import pytest

from tests.core.helpers import blobs, finite_difference
from wbcgrade.core import BarycenterSolver, DenseGeometry, GridGeometry, get_loss
from wbcgrade.core.losses import (
    EntropicTransportLoss,
    _symmetric_log_scaling,
    sinkhorn_divergence_loss,
)


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def _sphere(rng, n=25, gamma=0.3):
    points = rng.normal(size=(n, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    return DenseGeometry(np.arccos(np.clip(points @ points.T, -1, 1)) ** 2, gamma=gamma)


@pytest.mark.parametrize("where", ["grid", "sphere"])
def test_sinkhorn_divergence_gradient_matches_finite_differences(where, rng):
    if where == "grid":
        geometry = GridGeometry((9, 8), gamma=0.02)
        H = blobs((9, 8), 3, rng, components=2, floor=1e-3)
        q = blobs((9, 8), 1, rng, components=2, floor=1e-3)[0]
    else:
        geometry = _sphere(rng)
        H = rng.random((4, 25))
        q = rng.random(25) + 0.05
        q /= q.sum()
    solver = BarycenterSolver(H, geometry, 20)
    loss = sinkhorn_divergence_loss(tol=1e-12, warm_start=False)
    w = rng.dirichlet(np.ones(len(H)))
    _, grad, _ = solver.value_and_grad(w, q, loss)
    fd = finite_difference(lambda ww: solver.value_and_grad(ww, q, loss)[0], w)
    assert np.abs(grad - fd).max() <= 1e-5 * np.abs(fd).max(), (grad, fd)


def test_sinkhorn_divergence_is_zero_only_at_the_target(rng):
    geometry = GridGeometry((12, 12), gamma=0.01)
    p, q = blobs((12, 12), 2, rng, components=2, floor=1e-4)
    loss = get_loss("sinkhorn_divergence")
    assert abs(loss.value_and_grad(q, q, geometry)[0]) < 1e-10
    assert loss.value_and_grad(p, q, geometry)[0] > 1e-3
    # The plain entropic loss is lower at a blurred q than at q itself (its bias).
    blurred = geometry.apply(q)
    blurred /= blurred.sum()
    wasserstein = get_loss("wasserstein")
    assert wasserstein.value_and_grad(blurred, q, geometry)[0] < \
        wasserstein.value_and_grad(q, q, geometry)[0]
    assert loss.value_and_grad(blurred, q, geometry)[0] > 0


def test_far_apart_atoms_use_the_log_domain_and_approach_exact_transport():
    """A kernel so narrow that the plan needs underflowed entries: the core's Sinkhorn
    falls back to the log domain; the divergence is then close to the exact cost."""
    geometry = GridGeometry((40,), gamma=2e-4)
    x = np.linspace(0, 1, 40)
    p = np.zeros(40)
    p[[2, 30]] = [0.3, 0.7]
    q = np.zeros(40)
    q[[5, 36]] = [0.6, 0.4]
    value, grad = get_loss("sinkhorn_divergence").value_and_grad(p, q, geometry)
    assert np.all(np.isfinite(grad[p > 0]))
    exact = 0.3 * (x[2] - x[5]) ** 2 + 0.3 * (x[30] - x[5]) ** 2 + 0.4 * (x[30] - x[36]) ** 2
    assert value == pytest.approx(exact, rel=0.05)


def test_symmetric_scaling_survives_underflow():
    """Scalings that underflow in the symmetric solve: the log-domain fallback is exact."""
    geometry = GridGeometry((30,), gamma=0.05)
    p = np.full(30, 1.0)
    p[:3] = 1e-306
    p /= p.sum()
    log_u = _symmetric_log_scaling(p, geometry, 1e-10, 10_000, None)
    assert np.all(np.isfinite(log_u))
    log_marginal = log_u + geometry.log_apply(log_u)
    np.testing.assert_allclose(log_marginal, np.log(p), atol=1e-6)


def test_each_lookup_is_a_fresh_loss_and_hyphens_are_accepted():
    first, second = get_loss("sinkhorn_divergence"), get_loss("sinkhorn-divergence")
    assert first.name == second.name == "sinkhorn_divergence"
    assert isinstance(first.value_and_grad, EntropicTransportLoss)
    assert first.value_and_grad is not second.value_and_grad
    assert get_loss(first) is first  # a Loss passes through, with its state
    assert get_loss("wasserstein").value_and_grad is not get_loss("wasserstein").value_and_grad


def test_warm_start_saves_iterations_and_changes_nothing(rng):
    geometry = GridGeometry((16, 16), gamma=0.005)
    H = blobs((16, 16), 3, rng, components=2, floor=1e-4)
    q = blobs((16, 16), 1, rng, components=2, floor=1e-4)[0]
    solver = BarycenterSolver(H, geometry, 20)
    warm = get_loss("sinkhorn_divergence")
    solver.value_and_grad([0.3, 0.3, 0.4], q, warm)
    before = warm.value_and_grad.inner_iterations
    v_warm, g_warm, _ = solver.value_and_grad([0.31, 0.3, 0.39], q, warm)
    cold = get_loss("sinkhorn_divergence")
    v_cold, g_cold, _ = solver.value_and_grad([0.31, 0.3, 0.39], q, cold)
    warm_iterations = warm.value_and_grad.inner_iterations - before
    assert warm_iterations < 0.8 * cold.value_and_grad.inner_iterations
    assert v_warm == pytest.approx(v_cold, rel=1e-8)
    np.testing.assert_allclose(g_warm, g_cold, rtol=1e-4, atol=1e-4 * np.abs(g_cold).max())
