import sys

import numpy as np
import pytest

from tests.core.helpers import blobs, dense_barycenter, finite_difference
from wbcgrade.core import (
    BarycenterSolver,
    DenseGeometry,
    Geometry,
    GridGeometry,
    barycenter,
    barycenter_gradient,
    get_loss,
)

barycenter_module = sys.modules["wbcgrade.core.barycenter"]

GRIDS = [(20,), (9, 8), (6, 5, 4)]
LOSSES = ["quadratic", "l1", "kl", "kl_reverse", "wasserstein"]


@pytest.mark.parametrize("shape", GRIDS)
def test_forward_matches_dense_reference(shape, rng):
    geom = GridGeometry(shape, gamma=0.03)
    H = rng.random((3, *shape)) ** 2
    w = rng.dirichlet(np.ones(3))
    P = barycenter(H, w, geom, n_iter=25)
    ref = dense_barycenter(H, w, geom.cost_matrix(), geom.gamma, 25).reshape(shape)
    assert np.abs(P - ref).max() <= 1e-10 * ref.max()


def test_forward_on_dense_geometry_matches_reference(rng):
    pts = rng.random((30, 3))
    cost = ((pts[:, None] - pts[None]) ** 2).sum(-1)
    geom = DenseGeometry(cost, gamma=0.05)
    H = rng.random((4, 30))
    w = rng.dirichlet(np.ones(4))
    ref = dense_barycenter(H, w, cost, 0.05, 30)
    np.testing.assert_allclose(barycenter(H, w, geom, n_iter=30), ref, rtol=1e-10)


def test_converged_barycenter_matches_pot_log_domain(rng):
    ot = pytest.importorskip("ot")
    geom = GridGeometry(40, gamma=0.004)
    H = blobs((40,), 3, rng, width=0.08)
    w = np.array([0.2, 0.5, 0.3])
    P = barycenter(H, w, geom, n_iter=3000)
    M = geom.cost_matrix()
    ref = ot.bregman.barycenter(
        H.T, M, reg=geom.gamma, weights=w, method="sinkhorn_log", numItermax=5000, stopThr=1e-14
    )
    np.testing.assert_allclose(P / P.sum(), ref / ref.sum(), atol=1e-7 * ref.max())


@pytest.mark.slow
def test_barycenter_of_translated_gaussians_is_displacement_interpolation():
    n = 100
    x = np.linspace(0, 1, n)
    geom = GridGeometry.with_width(n, 1.5)
    sigma = 0.04
    H = np.stack([np.exp(-((x - c) ** 2) / (2 * sigma**2)) for c in (0.25, 0.75)])
    H[H < 1e-12] = 0.0  # binned data has no 1e-77 tails
    for t in (0.3, 0.5):
        P = barycenter(H, [1 - t, t], geom, n_iter=200)
        P = P / P.sum()
        mean = (P * x).sum()
        expected = (1 - t) * 0.25 + t * 0.75
        assert abs(mean - expected) < 0.01  # within 1% of the domain width
        # One bump in between, not a mixture of the two inputs.
        std = np.sqrt((P * (x - mean) ** 2).sum())
        assert std < 2 * sigma
        # A mixture would keep ~(1 - t) * 68% of its mass within sigma of the first bump.
        assert P[np.abs(x - 0.25) < sigma].sum() < 0.05
        assert P[np.abs(x - 0.75) < sigma].sum() < 0.05


def _fd_check(H, geom, q, loss, n_iter=15, rng=None):
    solver = BarycenterSolver(H, geom, n_iter)
    w = np.random.default_rng(7).dirichlet(np.ones(len(H)))
    value, grad, P = solver.value_and_grad(w, q, loss)
    fd = finite_difference(lambda ww: solver.value_and_grad(ww, q, loss)[0], w)
    assert np.all(np.isfinite(grad))
    assert np.abs(grad - fd).max() <= 1e-5 * np.abs(fd).max(), (grad, fd)
    return solver


@pytest.mark.parametrize("loss", LOSSES)
@pytest.mark.parametrize("shape", GRIDS)
def test_gradient_matches_finite_differences_on_grids(shape, loss, rng):
    geom = GridGeometry(shape, gamma=0.02)
    H = rng.random((3, *shape)) ** 3
    q = rng.random(shape) + 0.05
    q /= q.sum()
    _fd_check(H, geom, q, loss)


@pytest.mark.parametrize("loss", LOSSES)
def test_gradient_matches_finite_differences_on_dense_geometry(loss, rng):
    pts = rng.normal(size=(25, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)  # points on a sphere
    cost = np.arccos(np.clip(pts @ pts.T, -1, 1)) ** 2  # squared geodesic distance
    geom = DenseGeometry(cost, gamma=0.3)
    H = rng.random((4, 25))
    q = rng.random(25) + 0.05
    _fd_check(H, geom, q / q.sum(), loss)


@pytest.mark.parametrize("loss", ["quadratic", "kl", "wasserstein"])
def test_log_domain_agrees_with_scaling_domain(loss, rng):
    geom = GridGeometry((7, 6, 5), gamma=0.02)
    H = rng.random((4, 7, 6, 5)) ** 4
    H[H < 0.2] = 0.0  # sparse, like real colour histograms
    q = rng.random((7, 6, 5)) + 0.1
    w = rng.dirichlet(np.ones(4))
    solver = BarycenterSolver(H, geom, 15)
    v1, g1, P1 = solver.value_and_grad(w, q, loss)
    assert solver.last_backend == "scaling-float64"
    backend = barycenter_module._LogBackend(solver.H, w, geom)
    v2, g2, P2 = solver._gradient(backend, w, q, get_loss(loss))
    assert abs(v1 - v2) <= 1e-10 * abs(v1)
    np.testing.assert_allclose(P2, P1, rtol=1e-10, atol=1e-14 * P1.max())
    assert np.abs(g2 - g1).max() <= 1e-9 * np.abs(g1).max()


class _DirectLogGrid(Geometry):
    """A grid whose log-domain product is scipy's log-sum-exp per entry (the exact reference);
    every capability is the base class's default."""

    def __init__(self, grid):
        self.grid, self.shape, self.gamma, self.dtype = grid, grid.shape, grid.gamma, grid.dtype

    log_apply_work = property(lambda self: self.grid.log_apply_work)
    points = property(lambda self: self.grid.points)

    def apply(self, values):
        return self.grid.apply(values)

    def cost_matrix(self):
        return self.grid.cost_matrix()

    def log_apply(self, log_values):
        from scipy.special import logsumexp

        out = np.asarray(log_values, dtype=np.float64)
        for axis, x in enumerate(self.grid.axes):
            log_kernel = -np.subtract.outer(x, x) ** 2 / self.gamma
            moved = np.moveaxis(out, out.ndim - self.ndim + axis, -1)  # (..., n_in)
            result = logsumexp(moved[..., None, :] + log_kernel, axis=-1)  # (..., n_out)
            out = np.moveaxis(result, -1, out.ndim - self.ndim + axis)
        return out


def _corner_histograms(n, rng):
    """Four sparse histograms in far-apart corners of an n^3 grid (photo-like: mostly zeros)."""
    H = np.zeros((4, n, n, n))
    corners = [(0, 0, 0), (n - 1, n - 1, n - 1), (0, n - 1, 1), (n - 1, 1, n // 2)]
    for s, corner in enumerate(corners):
        pts = np.clip(np.array(corner) + rng.integers(-1, 2, (8, 3)), 0, n - 1)
        H[s][tuple(pts.T)] += rng.random(8) + 0.1
    return H


@pytest.mark.slow
def test_fast_log_domain_gradient_is_the_exact_one(monkeypatch):
    """12^3, a 0.25-bin kernel: plain scalings underflow, the shifted log-domain products run
    (their per-block second pass included) and match the per-entry log-sum-exp and finite
    differences."""
    geometry_module = sys.modules["wbcgrade.core.geometry.logsum"]
    n, loss = 12, "kl"
    rng = np.random.default_rng(5)
    H = _corner_histograms(n, rng)
    q = rng.random((n, n, n)) + 0.5
    q /= q.sum()
    geom = GridGeometry.with_width((n, n, n), 0.25)
    w = np.array([0.1, 0.2, 0.3, 0.4])
    blocks = {"rows": 0}
    block_pass = geometry_module._block_pass

    def counting(*args):
        result = block_pass(*args)
        blocks["rows"] += result
        return result

    monkeypatch.setattr(geometry_module, "_block_pass", counting)
    solver = BarycenterSolver(H, geom, 10, checkpoint_bytes=3 * H[0].nbytes)  # checkpoints too
    value, grad, P = solver.value_and_grad(w, q, loss)
    assert solver.last_backend == "log" and blocks["rows"] > 0
    assert np.all(np.isfinite(grad)) and np.all(np.isfinite(P))

    reference = barycenter_module._LogBackend(solver.H, w, _DirectLogGrid(geom))
    v_ref, g_ref, P_ref = solver._gradient(reference, w, q, get_loss(loss))
    assert abs(value - v_ref) <= 1e-11 * abs(v_ref)
    np.testing.assert_allclose(P, P_ref, rtol=1e-10, atol=1e-13 * P_ref.max())
    assert np.abs(grad - g_ref).max() <= 1e-9 * np.abs(g_ref).max()

    energy = get_loss(loss)
    fd = finite_difference(
        lambda ww: energy.value_and_grad(solver.barycenter(ww), q, geom)[0], w)
    assert np.abs(grad - fd).max() <= 1e-5 * np.abs(fd).max(), (grad, fd)


def test_far_apart_sparse_histograms_switch_to_log_domain_without_nan():
    n = 64
    geom = GridGeometry.with_width(n, 0.7)
    x = np.arange(n)
    H = np.stack([np.exp(-((x - 6) ** 2) / 4.0), np.exp(-((x - 58) ** 2) / 4.0)])
    H[H < 1e-12] = 0.0
    solver = BarycenterSolver(H, geom, 40)
    P = solver.barycenter([0.5, 0.5])
    assert solver.last_backend == "log"
    assert np.all(np.isfinite(P)) and P.sum() > 0.99
    assert abs((P * x).sum() / P.sum() - 32) < 0.5
    q = np.full(n, 1.0 / n)
    value, grad, _ = solver.value_and_grad([0.3, 0.7], q)
    assert np.all(np.isfinite(grad))
    d = np.array([1.0, -1.0])
    w = np.array([0.3, 0.7])
    eps = 1e-6
    fd = (solver.value_and_grad(w + eps * d, q)[0] - solver.value_and_grad(w - eps * d, q)[0]) / (
        2 * eps
    )
    assert abs(grad @ d - fd) <= 1e-5 * np.abs(grad).max()


def test_checkpointing_gives_the_same_gradient_with_any_memory_budget(rng):
    geom = GridGeometry((8, 8), gamma=0.03)
    H = rng.random((3, 8, 8))
    q = rng.random((8, 8))
    w = np.array([0.5, 0.2, 0.3])
    full = barycenter_gradient(H, w, geom, q, n_iter=23, checkpoint_bytes=10**9)
    for budget in (1, 2 * H.nbytes, 3 * H.nbytes, 5 * H.nbytes, 7 * H.nbytes, 13 * H.nbytes):
        value, grad, P = barycenter_gradient(H, w, geom, q, n_iter=23, checkpoint_bytes=budget)
        assert value == full[0]
        np.testing.assert_array_equal(grad, full[1])


def test_float32_agrees_with_float64(rng):
    H = blobs((16, 16), 3, rng, width=0.15, floor=1e-3)
    w = np.array([0.3, 0.3, 0.4])
    q = H.mean(axis=0)
    geom64 = GridGeometry((16, 16), gamma=0.01)
    geom32 = GridGeometry((16, 16), gamma=0.01, dtype=np.float32)
    solver32 = BarycenterSolver(H, geom32, 30)
    P32 = solver32.barycenter(w)
    assert solver32.last_backend == "scaling-float32"
    P64 = barycenter(H, w, geom64, n_iter=30)
    assert np.abs(P32 - P64).max() <= 1e-4 * P64.max()
    v32, g32, _ = solver32.value_and_grad(w, q)
    v64, g64, _ = barycenter_gradient(H, w, geom64, q, n_iter=30)
    assert abs(v32 - v64) <= 1e-4 * abs(v64)
    assert np.abs(g32 - g64).max() <= 1e-4 * np.abs(g64).max()


def test_float32_falls_back_to_float64_when_out_of_range(rng):
    geom32 = GridGeometry.with_width((40, 40), 1.0, dtype=np.float32)
    H = blobs((40, 40), 2, rng, width=0.05)
    solver = BarycenterSolver(H, geom32, 20)
    P = solver.barycenter([0.5, 0.5])
    assert solver.last_backend != "scaling-float32"
    assert np.all(np.isfinite(P))


def test_batch_axes_are_independent_problems_sharing_weights(rng):
    geom = GridGeometry(12, gamma=0.02)
    H = rng.random((3, 4, 12))
    q = rng.random((4, 12))
    w = np.array([0.1, 0.6, 0.3])
    value, grad, P = barycenter_gradient(H, w, geom, q, loss="kl", n_iter=10)
    parts = [barycenter_gradient(H[:, i], w, geom, q[i], loss="kl", n_iter=10) for i in range(4)]
    np.testing.assert_allclose(P, np.stack([p[2] for p in parts]), rtol=1e-12)
    assert value == pytest.approx(sum(p[0] for p in parts), rel=1e-12)
    np.testing.assert_allclose(grad, sum(p[1] for p in parts), rtol=1e-10)


def test_zero_weights_are_allowed(rng):
    geom = GridGeometry((6, 6), gamma=0.05)
    H = rng.random((3, 6, 6))
    P = barycenter(H, [0.0, 1.0, 0.0], geom, n_iter=50)
    target = H[1] / H[1].sum()
    # All weight on one input: b stays 1, so P is that input seen through the kernel.
    expected = geom.apply(target / geom.apply(np.ones((6, 6))))
    np.testing.assert_allclose(P, expected, rtol=1e-12)
    value, grad, _ = barycenter_gradient(H, [0.0, 1.0, 0.0], geom, target, n_iter=20)
    assert np.all(np.isfinite(grad))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(histograms=np.ones((2, 5, 5))), "shape"),
        (dict(histograms=-np.ones((2, 6, 6))), "negative"),
        (dict(histograms=np.full((2, 6, 6), np.nan)), "NaN"),
        (dict(histograms=np.zeros((2, 6, 6))), "empty"),
        (dict(weights=[0.5, 0.6]), "simplex"),
        (dict(weights=[1.2, -0.2]), "simplex"),
        (dict(weights=[1.0]), "shape"),
        (dict(weights=[np.nan, 1.0]), "NaN"),
        (dict(target=np.ones((5, 6))), "target"),
        (dict(target=np.full((6, 6), np.inf)), "NaN"),
        (dict(loss="hinge"), "unknown loss"),
        (dict(loss="kl", target=np.zeros((6, 6))), "positive"),
        (dict(n_iter=0), "n_iter"),
    ],
)
def test_bad_input_raises_value_error(kwargs, message):
    args = dict(
        histograms=np.ones((2, 6, 6)),
        weights=[0.5, 0.5],
        geometry=GridGeometry((6, 6), gamma=0.05),
        target=np.ones((6, 6)),
        loss="quadratic",
        n_iter=5,
    )
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        barycenter_gradient(**args)


def test_log_domain_job_over_budget_stops_with_clear_error(monkeypatch):
    from wbcgrade.errors import NumericalError

    n = 64
    geom = GridGeometry.with_width(n, 0.7)
    x = np.arange(n)
    H = np.stack([np.exp(-((x - 6) ** 2) / 4.0), np.exp(-((x - 58) ** 2) / 4.0)])
    H[H < 1e-12] = 0.0
    with pytest.raises(NumericalError, match="WBCGRADE_LOG_DOMAIN_BUDGET_S"):
        barycenter(H, [0.5, 0.5], geom, n_iter=40, log_domain_budget_s=1e-6)
    monkeypatch.setenv("WBCGRADE_LOG_DOMAIN_BUDGET_S", "1e-6")
    with pytest.raises(NumericalError, match="budget"):
        barycenter(H, [0.5, 0.5], geom, n_iter=40)
    # the argument wins over the environment, and raising the budget runs it
    P = barycenter(H, [0.5, 0.5], geom, n_iter=40, log_domain_budget_s=float("inf"))
    assert np.all(np.isfinite(P))
    monkeypatch.setenv("WBCGRADE_LOG_DOMAIN_BUDGET_S", "soon")
    with pytest.raises(ValueError, match="not a number"):
        barycenter(H, [0.5, 0.5], geom, n_iter=40)


def test_solve_reaches_the_fixed_point_and_a_warm_start_from_a_coarse_grid_saves_iterations():
    from wbcgrade.core import refine_grid

    fine, coarse = (24, 24), (12, 12)
    gamma = 2 * 0.06**2
    H_fine = blobs(fine, 3, np.random.default_rng(3), floor=1e-3, components=2)
    H_coarse = blobs(coarse, 3, np.random.default_rng(3), floor=1e-3, components=2)
    w = np.array([0.5, 0.3, 0.2])
    solver = BarycenterSolver(H_fine, GridGeometry(fine, gamma), 60)
    cold = solver.solve(w, tol=1e-12, max_iter=5000)
    assert cold.converged and cold.change < 1e-12
    # The fixed point of the iteration: one more iteration changes nothing.
    again = solver.solve(w, tol=1e-300, max_iter=1, init_log_scalings=cold.log_scalings,
                         warn=False)
    assert np.abs(again.barycenter - cold.barycenter).sum() < 1e-9
    # A long cold run of the plain iteration ends at the same barycenter.
    long_run = barycenter(H_fine, w, GridGeometry(fine, gamma), 3000)
    assert np.abs(long_run - cold.barycenter).sum() < 1e-8

    coarse_result = BarycenterSolver(H_coarse, GridGeometry(coarse, gamma), 60).solve(
        w, tol=1e-8, max_iter=5000)
    warm = solver.solve(w, tol=1e-8, max_iter=5000,
                        init_log_scalings=refine_grid(coarse_result.log_scalings, fine))
    plain = solver.solve(w, tol=1e-8, max_iter=5000)
    assert warm.converged and plain.converged
    assert np.abs(warm.barycenter - cold.barycenter).sum() < 1e-5
    assert warm.n_iter < plain.n_iter


def test_solve_rejects_bad_warm_starts():
    geom = GridGeometry((6, 6), 0.05)
    solver = BarycenterSolver(blobs((6, 6), 2, np.random.default_rng(0)), geom, 10)
    with pytest.raises(ValueError, match=r"init_log_scalings must have shape \(2, 6, 6\)"):
        solver.solve([0.5, 0.5], init_log_scalings=np.zeros((2, 5, 6)))
    with pytest.raises(ValueError, match="init_log_scalings contain NaN"):
        solver.solve([0.5, 0.5], init_log_scalings=np.full((2, 6, 6), np.nan))


def test_all_weight_on_one_histogram_is_computed_in_one_step(rng):
    """P_L(e_s) = P_1(e_s): the scalings of the weighted histogram stay 1 (the
    shortcut the solver takes); checked against the dense L-step iteration."""
    geometry = GridGeometry((6, 6, 6), 2 * (1.5 / 5) ** 2)
    hists = blobs(geometry.shape, 3, rng, floor=1e-3, components=2)
    for s in range(3):
        weights = np.eye(3)[s]
        dense = dense_barycenter(hists, weights, geometry.cost_matrix(), geometry.gamma, 25)
        np.testing.assert_allclose(barycenter(hists, weights, geometry, 25).ravel(), dense,
                                   rtol=1e-10, atol=1e-14)
    steps = []
    step = barycenter_module._ScalingBackend.step

    def counted(self, *args, **kwargs):
        steps.append(1)
        return step(self, *args, **kwargs)

    barycenter_module._ScalingBackend.step = counted
    try:
        barycenter(hists, np.eye(3)[1], geometry, 25)
        one = len(steps)
        barycenter(hists, [0.5, 0.5, 0.0], geometry, 25)
    finally:
        barycenter_module._ScalingBackend.step = step
    assert one == 1 and len(steps) == 26


class _OutsideGeometry(Geometry):
    """A geometry written outside the package: only the public contract."""

    def __init__(self, inner):
        self.inner, self.shape = inner, inner.shape
        self.gamma, self.dtype = inner.gamma, inner.dtype

    log_apply_work = property(lambda self: self.inner.log_apply_work)
    points = property(lambda self: self.inner.points)

    def apply(self, values):
        return self.inner.apply(values)

    def log_apply(self, log_values):
        return self.inner.log_apply(log_values)

    def cost_matrix(self):
        return self.inner.cost_matrix()


@pytest.mark.slow
@pytest.mark.parametrize("gamma", [0.05, 0.0004])  # scaling domain, then log domain
def test_a_geometry_with_only_the_public_contract_runs_barycenters_and_gradients(gamma, rng):
    grid = GridGeometry((7, 6), gamma=gamma)
    dense = DenseGeometry(grid.cost_matrix(), gamma)
    outside = _OutsideGeometry(dense)
    H = rng.random((3, 42))
    H[0, :30] = H[1, 12:] = 0.0  # far apart: the narrow kernel needs the log domain
    w, q = np.array([0.2, 0.3, 0.5]), rng.random(42) + 0.1
    expected = barycenter_gradient(H, w, dense, q, n_iter=15)
    solver = BarycenterSolver(H, outside, 15)
    got = solver.value_and_grad(w, q)
    assert solver.last_backend == ("log" if gamma < 0.01 else "scaling-float64")
    assert got[0] == pytest.approx(expected[0], rel=1e-10)
    np.testing.assert_allclose(got[1], expected[1], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(got[2], expected[2], rtol=1e-8, atol=1e-14)
