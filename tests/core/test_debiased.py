"""The debiased Sinkhorn barycenter (Janati et al. 2020) against the ordinary one."""

from __future__ import annotations

import numpy as np
import pytest

from tests.core.helpers import blobs
from wbcgrade.core import GridGeometry, barycenter, debiased_barycenter
from wbcgrade.core import _barycenter_debiased as debiased_module

N = 64
X = np.linspace(0.0, 1.0, N)


def _gaussian(centre: float, sd: float) -> np.ndarray:
    p = np.exp(-((X - centre) ** 2) / (2 * sd**2)) + 1e-12
    return p / p.sum()


def _mean_and_variance(p: np.ndarray) -> tuple[float, float]:
    mean = float((X * p).sum() / p.sum())
    return mean, float(((X - mean) ** 2 * p).sum() / p.sum())


def test_identical_inputs_give_that_input_not_its_blur():
    p = _gaussian(0.5, 0.06)
    geometry = GridGeometry.with_width((N,), 2.0)
    histograms = np.stack([p, p, p])
    weights = np.array([0.2, 0.5, 0.3])
    sharp = debiased_barycenter(histograms, weights, geometry, n_iter=200)
    blurred = barycenter(histograms, weights, geometry, n_iter=200)
    assert np.abs(sharp - p).max() < 1e-8 * p.max()
    assert np.abs(blurred - p).max() > 0.05 * p.max()  # the ordinary one is widened by the kernel


def test_translates_meet_half_way_with_their_own_width():
    sd = 0.05
    histograms = np.stack([_gaussian(0.3, sd), _gaussian(0.7, sd)])
    geometry = GridGeometry.with_width((N,), 2.0)
    weights = np.array([0.5, 0.5])
    sharp = debiased_barycenter(histograms, weights, geometry, n_iter=200)
    blurred = barycenter(histograms, weights, geometry, n_iter=200)
    mean, variance = _mean_and_variance(sharp)
    assert mean == pytest.approx(0.5, abs=1e-3)
    assert variance == pytest.approx(sd**2, rel=1e-3)  # the W2 barycenter of translates
    assert _mean_and_variance(blurred)[1] > 1.2 * variance


def test_mass_is_one_and_a_zero_weight_changes_nothing(rng):
    shape = (12, 10)
    histograms = blobs(shape, 3, rng, floor=1e-6)
    geometry = GridGeometry.with_width(shape, 1.0)
    weights = np.array([0.6, 0.4, 0.0])
    result = debiased_barycenter(histograms, weights, geometry, n_iter=80)
    assert result.shape == shape
    assert result.sum() == pytest.approx(1.0, abs=1e-6)
    without = debiased_barycenter(histograms[:2], weights[:2], geometry, n_iter=80)
    np.testing.assert_allclose(result, without, rtol=1e-12, atol=0)


def test_log_domain_agrees_with_the_scalings(rng):
    shape = (16,)
    histograms = blobs(shape, 2, rng, floor=1e-6)
    geometry = GridGeometry.with_width(shape, 1.5)
    weights = np.array([0.3, 0.7])
    scaled = debiased_module._scaling(histograms, weights, geometry, 40)
    logged = debiased_module._log_domain(histograms, weights, geometry, 40)
    np.testing.assert_allclose(logged, scaled, rtol=1e-9)
