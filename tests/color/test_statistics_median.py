"""The look statistics' median: numpy's ``nanmedian`` bit for bit, without its masked
median per call (a set's look takes hundreds of them)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from wbcgrade.color.look.statistics import _nanmedian


def _numpy(values, axis, keepdims):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(values, axis=axis, keepdims=keepdims)


@pytest.mark.parametrize("seed", range(2))
def test_the_median_is_numpys_nanmedian_bit_for_bit(seed):
    """Odd and even counts, ties, NaN anywhere, all-NaN slices (NaN, no warning), float32,
    any axis, kept dimensions, a 1-D array's scalar."""
    rng = np.random.default_rng(seed)
    for _ in range(150):
        shape = tuple(int(n) for n in rng.integers(1, 30, size=int(rng.integers(1, 4))))
        values = rng.standard_normal(shape) * 10.0 ** rng.uniform(-4, 3)
        if rng.random() < 0.3:
            values = np.round(values, 1)  # ties
        if rng.random() < 0.2:
            values = values.astype(np.float32)
        values[rng.random(shape) < rng.uniform(0, 1)] = np.nan
        for axis in range(values.ndim):
            for keepdims in (False, True):
                ours, theirs = _nanmedian(values, axis, keepdims), _numpy(values, axis, keepdims)
                assert np.shape(ours) == np.shape(theirs)
                assert np.asarray(ours).dtype == np.asarray(theirs).dtype
                assert np.array_equal(ours, theirs, equal_nan=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(_nanmedian(np.full((3, 2), np.nan))).all()
    assert type(_nanmedian(np.array([1.0, np.nan, 4.0]))) is np.float64
