"""Grid resampling of masses: mass and mean kept, the adjoint of interpolation, N-D shapes."""

from __future__ import annotations

import numpy as np
import pytest

from wbcgrade.core import refine_grid, resample_grid
from wbcgrade.core.geometry import binning_matrix


def _mean(hist: np.ndarray) -> np.ndarray:
    """Mean position on the grid ``linspace(0, 1, n)`` per axis, ``(ndim,)``."""
    axes = np.meshgrid(*[np.linspace(0, 1, n) for n in hist.shape], indexing="ij")
    return np.array([(hist * ax).sum() for ax in axes]) / hist.sum()


def _reference_cube(hist: np.ndarray, bins: int) -> np.ndarray:
    """The colour histograms' former resampler (3-D cubes, normalised), kept as the reference."""
    n = hist.shape[0]
    if bins > n:
        fine = np.clip(refine_grid(hist, (bins,) * 3), 0.0, None)
        return fine / fine.sum()
    pos = np.linspace(0.0, 1.0, n) * (bins - 1)
    base = np.minimum(pos.astype(np.int64), bins - 2)
    frac = pos - base
    weights = np.zeros((bins, n))
    weights[base, np.arange(n)] += 1.0 - frac
    weights[base + 1, np.arange(n)] += frac
    out = np.asarray(hist, dtype=np.float64)
    for axis in range(3):
        out = np.moveaxis(np.tensordot(weights, out, axes=(1, axis)), 0, axis)
    out = np.clip(out, 0.0, None)
    return out / out.sum()


@pytest.mark.parametrize("old, new", [
    ((17, 12, 9), (6, 5, 4)),        # coarser on every axis
    ((5, 7, 4), (11, 9, 13)),        # finer on every axis
    ((9, 14, 5), (4, 20, 5)),        # mixed, one axis unchanged
    ((6, 5, 4, 7), (3, 9, 2, 7)),    # 4-D
    ((30,), (7,)),                   # 1-D
])
def test_mass_is_kept_on_any_shape(rng, old, new):
    hist = rng.random(old) ** 3
    out = resample_grid(hist, new)
    assert out.shape == new and out.min() >= 0
    assert out.sum() == pytest.approx(hist.sum(), rel=1e-13)
    assert resample_grid(hist, new, mass=2.5).sum() == pytest.approx(2.5, rel=1e-13)


def test_coarsening_keeps_the_mean_position_and_is_the_adjoint_of_interpolation(rng):
    hist = rng.random((21, 16, 11)) ** 4
    coarse = resample_grid(hist, (8, 5, 4))
    np.testing.assert_allclose(_mean(coarse), _mean(hist), atol=1e-13)
    # <W h, g> = <h, R g> for any function g on the coarse grid (R: linear interpolation).
    g = rng.standard_normal((8, 5, 4))
    assert np.sum(coarse * g) == pytest.approx(np.sum(hist * refine_grid(g, hist.shape)),
                                               rel=1e-12)
    # Each old point's mass is split between its two nearest new points.
    W = binning_matrix(21, 8)
    np.testing.assert_allclose(W.sum(axis=0), 1.0, rtol=1e-15)
    assert np.all(np.count_nonzero(W, axis=0) <= 2)


def test_refining_then_coarsening_a_constant(rng):
    """A constant density refines to the constant exactly; binned back, the interior
    bins are constant again and the mass is kept (boundary points own half cells)."""
    coarse = np.full((5, 7), 3.0)
    fine = resample_grid(coarse, (9, 13))
    np.testing.assert_allclose(fine, coarse.sum() / fine.size, rtol=1e-15)
    back = resample_grid(fine, (5, 7))
    assert back.sum() == pytest.approx(coarse.sum(), rel=1e-14)
    np.testing.assert_allclose(back[1:-1, 1:-1], back[2, 3], rtol=1e-14)
    # the exact boundary share: the binning matrices' row sums (1.5 vs 2 on nested grids)
    cell = np.outer(binning_matrix(9, 5).sum(axis=1), binning_matrix(13, 7).sum(axis=1))
    np.testing.assert_allclose(back, cell / cell.sum() * coarse.sum(), rtol=1e-14)


def test_leading_axes_are_independent_histograms(rng):
    stack = rng.random((2, 3, 10, 8)) * np.array([1.0, 4.0, 9.0])[None, :, None, None]
    out = resample_grid(stack, (5, 12))
    assert out.shape == (2, 3, 5, 12)
    np.testing.assert_allclose(out.sum(axis=(2, 3)), stack.sum(axis=(2, 3)), rtol=1e-13)
    np.testing.assert_array_equal(out[1, 2], resample_grid(stack[1, 2], (5, 12)))


@pytest.mark.parametrize("old, bins", [(20, 7), (32, 16), (16, 32), (7, 39), (12, 12)])
def test_matches_the_colour_resampler_bit_for_bit(rng, old, bins):
    hist = rng.random((old,) * 3) ** 6
    hist /= hist.sum()
    out = resample_grid(hist, (bins,) * 3, mass=1.0)
    reference = hist / hist.sum() if bins == old else _reference_cube(hist, bins)
    assert np.array_equal(out, reference)
    # and so does what is computed from it (sums depend on the memory order)
    assert out.sum() == reference.sum()


def test_shape_unchanged_and_errors(rng):
    hist = rng.random((4, 6))
    same = resample_grid(hist, (4, 6))
    assert np.array_equal(same, hist) and same is not hist
    assert np.zeros((4, 6)).sum() == resample_grid(np.zeros((4, 6)), (2, 3)).sum() == 0
    assert resample_grid(hist, (1, 6)).shape == (1, 6)
    with pytest.raises(ValueError, match="non-negative"):
        resample_grid(-hist, (2, 3))
    with pytest.raises(ValueError, match="cannot resample"):
        resample_grid(hist, (2, 3, 4))
    with pytest.raises(ValueError, match="empty"):
        resample_grid(np.zeros((4, 6)), (2, 3), mass=1.0)
