"""8-bit outputs: the pixels are converted as OpenImageIO converts them (value for value)."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from wbcgrade.color.io._quantise import HALVES_TO_EVEN, to_uint8
from wbcgrade.color.io.images import read_image, write_image


def _oiio_uint8(values: np.ndarray) -> np.ndarray:
    n = values.size
    buf = oiio.ImageBuf(oiio.ImageSpec(n, 1, 1, "float"))
    buf.set_pixels(oiio.ROI(0, n, 0, 1, 0, 1, 0, 1), values.reshape(1, n, 1))
    return buf.get_pixels(oiio.UINT8).ravel()


def _probe_values() -> np.ndarray:
    """Every code's half-way point and its float32 neighbours, the ends, NaN, infinities."""
    codes = np.arange(256, dtype=np.float32)
    ties = ((codes + np.float32(0.5)) / np.float32(255)).astype(np.float32)
    near = (ties.view(np.int32)[:, None] + np.arange(-8, 9, dtype=np.int32)).view(np.float32)
    ends = np.array([0.0, 1.0, -0.0, -0.5, 1.5, np.nan, np.inf, -np.inf], np.float32)
    return np.concatenate([near.ravel(), ends])


def test_to_uint8_is_openimageios_conversion(rng):
    values = np.concatenate([_probe_values(), rng.uniform(-0.2, 1.2, 200_000).astype(np.float32)])
    assert np.array_equal(to_uint8(values), _oiio_uint8(values))


def test_exact_halves_follow_the_rule_asked_for():
    values = _probe_values()
    with np.errstate(invalid="ignore"):
        exact = np.isfinite(values) & (values * np.float32(255)
                                       == np.floor(values * np.float32(255)) + 0.5)
    assert exact.sum() > 100  # the probe holds exact halves, where the two rules differ
    up, even = to_uint8(values, half_even=False), to_uint8(values, half_even=True)
    scaled = (values * np.float32(255)).astype(np.float64)
    np.testing.assert_array_equal(up[exact], np.clip(np.floor(scaled[exact] + 0.5), 0, 255))
    np.testing.assert_array_equal(even[exact], np.clip(np.rint(scaled[exact]), 0, 255))
    np.testing.assert_array_equal(up[~exact], even[~exact])
    assert HALVES_TO_EVEN == ((oiio.VERSION_MAJOR, oiio.VERSION_MINOR) >= (3, 2))


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


@pytest.mark.parametrize("half_even", [True, False])
def test_to_uint8_is_the_float64_rule_on_every_chunk_and_thread(rng, half_even):
    """The float32 conversion (in cache-sized chunks, on several threads) gives the code
    values of the rule computed in float64 (``floor(x + 0.5)`` or ``rint`` of the float32
    product), ties, NaN and infinities included, across chunk and band edges."""
    from wbcgrade.color.io import _quantise

    probe = _probe_values()
    values = rng.uniform(-0.2, 1.2, 3 * _quantise._CHUNK + 123).astype(np.float32)
    values[::997] = np.resize(probe, values[::997].shape)
    scaled = (values * np.float32(255)).astype(np.float64)
    with np.errstate(invalid="ignore"):
        rule = np.rint(scaled) if half_even else np.floor(scaled + 0.5)
        expected = np.where(rule > 0, np.minimum(rule, 255), 0).astype(np.uint8)
    out = np.empty(values.shape, np.uint8)
    _quantise.in_bands(_quantise._to_uint8_fast, values.shape[0], values, out, half_even,
                       min_band=_quantise._CHUNK // 2)  # several bands, unaligned chunks
    assert np.array_equal(out, expected)
    assert np.array_equal(to_uint8(values.reshape(-1, 3) if values.size % 3 == 0 else values,
                                   half_even).ravel(), expected)
