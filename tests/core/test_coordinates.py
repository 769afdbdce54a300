import numpy as np
import pytest

from tests.core.helpers import blobs
from wbcgrade.core import GridGeometry, barycenter, barycentric_coordinates, softmax

CASES = [((16, 16), 3), ((14, 14), 4), ((12, 12), 6), ((9, 9, 9), 3), ((8, 8, 8), 5)]


def _problem(shape, n_histograms, seed):
    rng = np.random.default_rng(seed)
    geom = GridGeometry.with_width(shape, 1.0)
    # Mixtures of two blobs of random widths: translates of a single blob would
    # only determine the weighted mean of their centres, not the weights.
    H = blobs(shape, n_histograms, rng, width=0.08, components=2)
    truth = rng.dirichlet(np.ones(n_histograms))
    return geom, H, truth


@pytest.mark.parametrize("loss", ["quadratic", "kl"])
@pytest.mark.parametrize("shape, n_histograms", CASES)
def test_known_weights_are_recovered(shape, n_histograms, loss):
    geom, H, truth = _problem(shape, n_histograms, seed=1)
    target = barycenter(H, truth, geom, n_iter=30)
    fit = barycentric_coordinates(target, H, geom, loss=loss, n_iter=30, max_iter=50)
    assert np.abs(fit.weights - truth).sum() < 0.02, (fit.weights, truth)
    assert fit.weights.sum() == pytest.approx(1.0) and np.all(fit.weights >= 0)
    assert fit.loss < fit.initial_loss
    assert fit.n_evaluations == len(fit.history) >= 2
    np.testing.assert_allclose(fit.barycenter, barycenter(H, fit.weights, geom, n_iter=30))


@pytest.mark.slow
@pytest.mark.parametrize("loss", ["l1", "wasserstein"])
@pytest.mark.parametrize("shape, n_histograms", [((12, 12), 3), ((8, 8, 8), 4)])
def test_fit_is_no_worse_than_the_true_weights(shape, n_histograms, loss):
    from wbcgrade.core import BarycenterSolver

    geom, H, truth = _problem(shape, n_histograms, seed=3)
    target = barycenter(H, truth, geom, n_iter=20)
    fit = barycentric_coordinates(target, H, geom, loss=loss, n_iter=20, max_iter=40)
    loss_at_truth = BarycenterSolver(H, geom, 20).value_and_grad(truth, target, loss)[0]
    # The L1 loss at the truth is exactly 0: allow round-off, a millionth of the start.
    assert fit.loss <= loss_at_truth + 1e-6 * abs(fit.initial_loss)
    assert fit.loss < fit.initial_loss


def test_init_weights_and_callback(rng):
    geom, H, truth = _problem((10, 10), 3, seed=1)
    target = barycenter(H, truth, geom, n_iter=20)
    seen = []
    fit = barycentric_coordinates(
        target, H, geom, n_iter=20, init_weights=truth, callback=lambda n, w, v: seen.append(n)
    )
    assert seen == list(range(1, fit.n_evaluations + 1))
    assert fit.history[0] == pytest.approx(0.0, abs=1e-20)  # started at the answer
    assert np.abs(fit.weights - truth).sum() < 1e-6


def test_single_histogram_needs_no_fit():
    geom, H, _ = _problem((8, 8), 1, seed=0)
    fit = barycentric_coordinates(H[0], H, geom, n_iter=10)
    assert fit.weights.tolist() == [1.0]


def test_softmax_is_on_the_simplex():
    w = softmax(np.array([1000.0, 0.0, -1000.0]))
    assert np.isfinite(w).all() and w.sum() == pytest.approx(1.0)


def test_bad_init_weights_raise_value_error():
    geom, H, _ = _problem((8, 8), 3, seed=0)
    with pytest.raises(ValueError, match="init_weights"):
        barycentric_coordinates(H[0], H, geom, init_weights=[1.0, -1.0, 1.0])


def test_mixture_coordinates_recover_known_mixture_weights(rng):
    from wbcgrade.core import mixture_coordinates

    geom = GridGeometry((10, 9), gamma=0.02)
    H = rng.random((4, 10, 9))
    H /= H.sum(axis=(1, 2), keepdims=True)
    truth = np.array([0.2, 0.0, 0.8, 0.0])
    target = np.tensordot(truth, H, axes=1)
    seen = []
    fit = mixture_coordinates(target, H, geom, "quadratic", max_iter=50,
                              callback=lambda n, w, v: seen.append(n))
    np.testing.assert_allclose(fit.weights, truth, atol=1e-4)
    np.testing.assert_allclose(fit.barycenter, target, atol=1e-6 * target.max())
    assert fit.backend == "mixture" and fit.loss < 1e-6 * fit.initial_loss
    assert seen == list(range(1, fit.n_evaluations + 1))
