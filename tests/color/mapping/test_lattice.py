"""The lattice readers of wbcgrade.color.mapping.remap agree: lattice to lattice (separable),
at scattered colours (float64, any channels) and the pixels' kernel (LUT export)."""

import numpy as np
import pytest

from wbcgrade.color.histogram import grid_points
from wbcgrade.color.mapping.remap import (
    apply_color_map,
    identity_map,
    interpolate_lattice,
    resample_lattice,
)


@pytest.mark.parametrize(("n", "size"), [(5, 9), (17, 33), (33, 17), (9, 9), (2, 7)])
def test_the_three_readers_agree_on_a_lattice(n, size):
    rng = np.random.default_rng(n * 100 + size)
    lattice = rng.random((n, n, n, 3))
    resampled = resample_lattice(lattice, size)
    assert resampled.shape == (size, size, size, 3) and resampled.dtype == np.float32
    scattered = interpolate_lattice(lattice, grid_points(size)).reshape(resampled.shape)
    assert np.abs(resampled - scattered).max() < 1e-6
    pixels = apply_color_map(identity_map(size), lattice.astype(np.float32))
    assert np.abs(resampled - pixels).max() < 1e-6


def test_the_identity_is_read_as_the_identity_and_any_channels_are_read():
    assert np.abs(resample_lattice(identity_map(5), 12) - identity_map(12)).max() < 1e-6
    values = np.random.default_rng(0).random((4, 4, 4, 2))
    colors = np.random.default_rng(1).random((50, 3))
    read = interpolate_lattice(values, colors)
    assert read.shape == (50, 2)
    assert np.allclose(interpolate_lattice(values, grid_points(4)), values.reshape(-1, 2))
