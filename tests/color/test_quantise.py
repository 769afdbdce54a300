"""8-bit outputs: the pixels are converted as OpenImageIO converts them (value for value)."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from wbcgrade.color._quantise import _rule, _to_uint8, probe_values, to_uint8
from wbcgrade.color.imageio import read_image, write_image


def _oiio_uint8(values: np.ndarray) -> np.ndarray:
    n = values.size
    buf = oiio.ImageBuf(oiio.ImageSpec(n, 1, 1, "float"))
    buf.set_pixels(oiio.ROI(0, n, 0, 1, 0, 1, 0, 1), values.reshape(1, n, 1))
    return buf.get_pixels(oiio.UINT8).ravel()


def test_to_uint8_is_openimageios_conversion(rng):
    values = np.concatenate([probe_values(), rng.uniform(-0.2, 1.2, 200_000).astype(np.float32)])
    assert np.array_equal(to_uint8(values), _oiio_uint8(values))


def test_both_rounding_rules_are_known_and_the_installed_one_is_used():
    ties = probe_values()[8:256 * 17:17]  # each code's half-way point
    up, even = np.empty(ties.shape, np.uint8), np.empty(ties.shape, np.uint8)
    _to_uint8(ties, up, False)
    _to_uint8(ties, even, True)
    exact = ties * np.float32(255) == np.floor(ties * np.float32(255)) + 0.5
    assert exact.sum() > 100  # the probe has exact halves, where the rules differ
    assert np.any(up[exact] != even[exact])
    assert _rule() in (False, True)  # one of them is OpenImageIO's here
    assert np.array_equal(to_uint8(ties), _oiio_uint8(ties))


@pytest.mark.parametrize("suffix", [".png", ".tif"])
def test_an_8_bit_file_holds_what_openimageio_would_have_written(tmp_path, rng, suffix):
    pixels = rng.uniform(-0.1, 1.1, (37, 53, 3)).astype(np.float32)
    source = tmp_path / f"in{suffix}"
    spec = oiio.ImageSpec(53, 37, 3, "uint8")
    out = oiio.ImageOutput.create(str(source))
    assert out.open(str(source), spec)
    assert out.write_image(np.clip(pixels, 0, 1))  # OpenImageIO converts the floats
    out.close()
    like = read_image(source)
    written = write_image(tmp_path / f"out{suffix}", pixels, like)
    expected = oiio.ImageBuf(str(source)).get_pixels(oiio.UINT8)
    assert np.array_equal(oiio.ImageBuf(str(written)).get_pixels(oiio.UINT8), expected)
