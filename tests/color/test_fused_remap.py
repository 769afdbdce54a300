"""The fused remap of large photos (colour map and block means in one pass, no full-size
graded image) gives the numbers of the two steps, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

import wbcgrade.color.regrain as regrain_module
from wbcgrade.color.regrain import regrain, regrain_map
from wbcgrade.color.remap import apply_color_map, block_means_mapped, identity_map


def _image_and_map(rng, h=61, w=47, size=9):
    rgb = rng.random((h, w, 3)).astype(np.float32) * 1.2 - 0.1  # some values out of range
    table = np.clip(identity_map(size) ** 1.7 + 0.05 * rng.standard_normal((size,) * 3 + (3,)),
                    0.0, 1.0).astype(np.float32)
    return rgb, table


@pytest.mark.parametrize("step", [1, 2, 3, 5])
@pytest.mark.parametrize("strength", [1.0, 0.6])
def test_block_means_of_the_mapped_image(rng, step, strength):
    rgb, table = _image_and_map(rng)
    expected = regrain_module._downsample(apply_color_map(rgb, table, strength), step)
    assert np.array_equal(block_means_mapped(rgb, table, strength, step), expected)


@pytest.mark.parametrize("max_pixels", [10 ** 6, 700])  # solved at full size / subsampled
def test_regrain_map_is_regrain_of_the_mapped_image(rng, monkeypatch, max_pixels):
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", max_pixels)
    rgb, table = _image_and_map(rng)
    rgb = np.clip(rgb, 0.0, 1.0)
    assert (regrain_module._step(*rgb.shape[:2]) > 1) == (max_pixels < rgb.size)
    expected = regrain(rgb, apply_color_map(rgb, table, 0.8), 0.05, 0.01)
    assert np.array_equal(regrain_map(rgb, table, 0.8, 0.05, 0.01), expected)


@pytest.mark.parametrize("shape, coarse, step", [((23, 31), (6, 8), 4.0), ((9, 7), (3, 2), 3.0),
                                                 ((5, 6), (1, 2), 4.0)])
def test_regrain_applies_bilinearly_interpolated_coefficients(rng, shape, coarse, step):
    source = rng.random((*shape, 3)).astype(np.float32)
    A = (rng.random((*coarse, 3, 3)).astype(np.float32) - 0.5) * 0.5
    b = (rng.random((*coarse, 3)).astype(np.float32) - 0.5) * 0.2

    def weights(n_out, n_in):  # (n_out, n_in) bilinear weights, pixel centres, edges clamped
        pos = np.clip((np.arange(n_out) + 0.5) / step - 0.5, 0.0, n_in - 1.0)
        lo = np.minimum(pos.astype(int), max(n_in - 2, 0))
        frac = pos - lo
        m = np.zeros((n_out, n_in))
        m[np.arange(n_out), lo] += 1 - frac
        m[np.arange(n_out), np.minimum(lo + 1, n_in - 1)] += frac
        return m

    wy, wx = weights(shape[0], coarse[0]), weights(shape[1], coarse[1])
    A_full = np.einsum("yi,xj,ijac->yxac", wy, wx, A)
    b_full = np.einsum("yi,xj,ijc->yxc", wy, wx, b)
    expected = np.clip(source + np.einsum("yxac,yxa->yxc", A_full, source) + b_full, 0, 1)
    out = np.empty_like(source)
    regrain_module._apply_upsampled(source, A, b, step, out)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-6)
