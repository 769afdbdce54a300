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
