"""Property tests (Hypothesis) of the core's grid resampler: re-binned masses keep their
total, stay non-negative, and, coarsening, keep their mean position."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from wbcgrade.core import resample_grid

FEW = settings(max_examples=30, deadline=None)


@st.composite
def grids(draw, coarsen_only: bool = False):
    """(histogram (2, *old), new shape) on 1 to 3 axes of 1 to 12 points."""
    axes = draw(st.integers(1, 3))
    old = tuple(draw(st.integers(1, 12)) for _ in range(axes))
    new = tuple(draw(st.integers(1, n if coarsen_only else 12)) for n in old)
    values = draw(arrays(np.float64, (2, *old), elements=st.floats(0, 1e3)))
    return values, new


def _mean_position(values: np.ndarray) -> np.ndarray:
    axes = [np.linspace(0, 1, n) for n in values.shape]
    return np.array([(values * np.expand_dims(a, tuple(j for j in range(values.ndim) if j != i))
                      ).sum() for i, a in enumerate(axes)]) / values.sum()


@FEW
@given(grids())
def test_resampling_keeps_each_histogram_mass_and_its_sign(case):
    values, shape = case
    out = resample_grid(values, shape)
    assert out.shape == (2, *shape) and np.all(out >= 0)
    for before, after in zip(values, out):
        assert after.sum() == pytest.approx(before.sum(), rel=1e-9, abs=1e-9)


@FEW
@given(grids(), st.floats(1e-3, 1e3))
def test_resampling_to_a_given_mass_normalises(case, mass):
    values, shape = case
    values = values + 1e-3  # some mass everywhere
    out = resample_grid(values, shape, mass=mass)
    np.testing.assert_allclose(out.reshape(2, -1).sum(axis=1), mass, rtol=1e-9)


@FEW
@given(grids(coarsen_only=True))
def test_coarsening_keeps_the_mean_position(case):
    values, shape = case
    values = values + 1e-3
    out = resample_grid(values, shape)
    for before, after in zip(values, out):
        keep = [n > 1 for n in shape]  # an axis of one point has its mean at 0 by definition
        np.testing.assert_allclose(_mean_position(after)[keep], _mean_position(before)[keep],
                                   atol=1e-9)
