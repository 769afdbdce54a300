"""Soft histograms, the histogram cache, the colour-map remap and .cube export."""

from __future__ import annotations

import os

import numpy as np
import pytest

from wbcgrade.color.histogram import (
    HistogramCache,
    add_floor,
    grid_points,
    image_histogram,
    resample_histogram,
    soft_histogram,
)
from wbcgrade.color.mapping.lut import color_map_to_lut, read_cube, write_cube
from wbcgrade.color.mapping.remap import apply_color_map, blend_map, identity_map
from wbcgrade.errors import InputError


def _mean(hist):
    n = hist.shape[0]
    return (grid_points(n) * hist.reshape(-1, 1)).sum(axis=0)


def test_soft_histogram_is_normalised_and_keeps_the_mean(rng):
    colors = rng.random((5000, 3))
    hist = soft_histogram(colors, 9)
    assert hist.shape == (9, 9, 9) and hist.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(_mean(hist), colors.mean(axis=0), atol=1e-12)
    # A colour on a bin lands entirely in that bin.
    single = soft_histogram(np.array([[0.5, 0.25, 1.0]]), 5)
    assert single[2, 1, 4] == pytest.approx(1.0)


def test_image_histogram_subsamples_and_weights_by_alpha(rng):
    rgb = rng.random((300, 200, 3)).astype(np.float32)
    alpha = np.zeros((300, 200), np.float32)
    alpha[:, :100] = 1.0
    rgb[:, 100:] = 1.0  # fully transparent white half must not count
    hist = image_histogram(rgb, 8, alpha, max_pixels=5000)
    assert hist[-1, -1, -1] < 0.01
    with pytest.raises(InputError, match="fully transparent"):
        image_histogram(rgb, 8, np.zeros_like(alpha))


def test_resample_and_floor(rng):
    hist = soft_histogram(rng.random((2000, 3)), 16)
    coarse = resample_histogram(hist, 8)
    assert coarse.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(_mean(coarse), _mean(hist), atol=1e-12)
    floored = add_floor(coarse, 1e-3)
    assert floored.min() > 0 and floored.sum() == pytest.approx(1.0)


def test_cache_hits_and_invalidates_on_change(tmp_path, rng):
    photo = tmp_path / "p.bin"
    photo.write_bytes(b"x" * 10)
    cache = HistogramCache(tmp_path / "cache")
    hist = soft_histogram(rng.random((100, 3)), 6)
    assert cache.get(photo, 6) is None
    cache.put(photo, 6, hist)
    np.testing.assert_allclose(cache.get(photo, 6), hist, rtol=1e-6)
    assert cache.get(photo, 7) is None
    photo.write_bytes(b"y" * 11)
    os.utime(photo, ns=(1, 1))
    assert cache.get(photo, 6) is None
    assert HistogramCache(tmp_path / "cache", enabled=False).get(photo, 6) is None


def test_remap_identity_strength_and_clipping(rng):
    rgb = rng.random((40, 30, 3)).astype(np.float32)
    np.testing.assert_allclose(apply_color_map(rgb, identity_map(9)), rgb, atol=1e-6)
    inverted = 1.0 - identity_map(9)
    np.testing.assert_allclose(apply_color_map(rgb, inverted), 1.0 - rgb, atol=1e-6)
    half = apply_color_map(rgb, inverted, strength=0.25)
    np.testing.assert_allclose(half, 0.75 * rgb + 0.25 * (1 - rgb), atol=1e-6)
    np.testing.assert_allclose(apply_color_map(rgb, blend_map(inverted, 0.25)), half, atol=1e-6)
    assert apply_color_map(np.array([[2.0, -1.0, 0.5]]), identity_map(5)).tolist() == \
        [[1.0, 0.0, 0.5]]


def test_cube_file_reproduces_the_map(tmp_path, rng):
    # A smooth non-trivial map on a 17^3 grid, exported as a 33^3 LUT.
    x = identity_map(17)
    color_map = np.clip(np.stack([x[..., 0] ** 0.7, 0.2 + 0.6 * x[..., 1] * x[..., 2],
                                  x[..., 2] ** 1.4], axis=-1), 0, 1).astype(np.float32)
    table = color_map_to_lut(color_map, 33, strength=0.8)
    path = write_cube(tmp_path / "grade.cube", table, comments=["test"])
    text = path.read_text()
    assert "LUT_3D_SIZE 33" in text
    assert len([line for line in text.splitlines() if line[:1].isdigit()]) == 33 ** 3
    lut = read_cube(path)
    rgb = rng.random((64, 64, 3))
    error = np.abs(lut.apply(rgb) - apply_color_map(rgb, color_map, 0.8)).mean()
    assert error < 1 / 255 / 4
    with pytest.raises(InputError, match="exists"):
        write_cube(path, table)
    with pytest.raises(InputError, match=".cube"):
        write_cube(tmp_path / "grade.txt", table)


def test_resampling_matches_soft_binning_of_bin_centres_and_upsamples_smoothly(rng):
    from wbcgrade.color.histogram import grid_points

    hist = soft_histogram(rng.random((3000, 3)), 20)
    flat = hist.ravel()
    nonzero = np.flatnonzero(flat)
    reference = soft_histogram(grid_points(20)[nonzero], 7, flat[nonzero])
    np.testing.assert_allclose(resample_histogram(hist, 7), reference, atol=1e-15)
    fine = resample_histogram(hist, 39)
    assert fine.shape == (39, 39, 39) and fine.min() >= 0 and fine.sum() == pytest.approx(1.0)
    # No comb: every fine bin between two occupied coarse bins gets mass.
    assert np.count_nonzero(fine) > 4 * np.count_nonzero(hist)
    np.testing.assert_allclose(_mean(fine), _mean(hist), atol=2e-3)
