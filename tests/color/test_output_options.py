"""Output control: --quality, --bit-depth, grey stays grey, the LUT format from its ending,
CMYK JPEGs come out as plain RGB without their CMYK profile."""

from __future__ import annotations

import shutil

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.color.conftest import FAST_ARGS, SAMPLES, small_copy, write_array
from tests.conftest import run_cli as run
from wbcgrade.color.io.images import WriteOptions, read_image
from wbcgrade.color.mapping.lut import write_cube
from wbcgrade.color.mapping.remap import identity_map
from wbcgrade.errors import OptionError


@pytest.fixture(scope="module")
def warm_look(tmp_path_factory):
    """A real grade (warm preset on a sample photo) saved as a .cube: fast to apply."""
    folder = tmp_path_factory.mktemp("look")
    photo = small_copy(SAMPLES / "chelsea.jpg", folder / "cat.png", width=128)
    result = run("apply", photo, "--preset", "warm", "-o", folder / "cat_graded.png",
                 "--lut", folder / "warm.cube", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    return folder / "warm.cube"


@pytest.mark.slow
def test_quality_sets_the_jpeg_size(tmp_path, warm_look):
    sizes = {}
    for quality in (50, 90, None):
        out = tmp_path / f"q{quality}.jpg"
        args = [] if quality is None else ["--quality", quality]
        result = run("apply", SAMPLES / "coffee.jpg", "--look", warm_look, "-o", out, *args)
        assert result.exit_code == 0, result.output
        sizes[quality] = out.stat().st_size
    assert sizes[50] < sizes[90] < sizes[None]
    # the shipped samples are ordinary camera-quality JPEGs: 90 gives about their size
    for name in ("chelsea", "coffee", "sunset"):
        out = tmp_path / f"{name}.jpg"
        result = run("apply", SAMPLES / f"{name}.jpg", "--look", warm_look, "--quality", 90,
                     "-o", out)
        assert result.exit_code == 0, result.output
        ratio = out.stat().st_size / (SAMPLES / f"{name}.jpg").stat().st_size
        assert 0.9 <= ratio <= 1.1, (name, ratio)
    result = run("apply", SAMPLES / "coffee.jpg", "--look", warm_look, "--quality", 0,
                 "-o", tmp_path / "zero.jpg")
    assert result.exit_code != 0 and not (tmp_path / "zero.jpg").exists()


@pytest.mark.slow
def test_bit_depth(tmp_path, warm_look):
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "coffee.jpg")
    for depth, name, expected in (("16", "a.png", oiio.UINT16), ("float", "a.tif", oiio.FLOAT),
                                  ("8", "b.tif", oiio.UINT8), ("16", "a.exr", oiio.HALF)):
        result = run("apply", photo, "--look", warm_look, "--bit-depth", depth,
                     "-o", tmp_path / name)
        assert result.exit_code == 0, result.output
        assert read_image(tmp_path / name).spec.format == expected, (depth, name)
    result = run("apply", photo, "--look", warm_look, "--bit-depth", "16",
                 "-o", tmp_path / "c.jpg")
    assert result.exit_code != 0 and "JPEG" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "c.jpg").exists()
    with pytest.raises(OptionError, match="quality must be between 1 and 100"):
        WriteOptions(quality=101)


@pytest.mark.slow
def test_grey_in_grey_out(tmp_path, warm_look, style_dir, rng):
    grey = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "rgb.png")
    pixels = read_image(grey).pixels.mean(axis=2, keepdims=True)
    for name, fmt in (("grey.jpg", "uint8"), ("grey.png", "uint16")):
        write_array(tmp_path / name, pixels, fmt)
        for args in (["--look", warm_look], ["--style", style_dir, *FAST_ARGS]):
            out = tmp_path / f"out_{args[0][2:]}_{name}"
            result = run("apply", tmp_path / name, *args, "-o", out)
            assert result.exit_code == 0, result.output
            back = read_image(out)
            assert back.pixels.shape[2] == 1 and back.spec.format == read_image(
                tmp_path / name).spec.format
            assert np.abs(back.pixels - read_image(tmp_path / name).pixels).mean() > 0.005
    grey_alpha = rng.random((12, 16, 2)).astype(np.float32)
    write_array(tmp_path / "ga.png", grey_alpha, "uint8")
    result = run("apply", tmp_path / "ga.png", "--look", warm_look, "-o", tmp_path / "ga2.png")
    assert result.exit_code == 0, result.output
    back = read_image(tmp_path / "ga2.png")
    assert back.pixels.shape[2] == 2 and back.alpha_channel == 1
    assert np.array_equal(np.round(back.pixels[:, :, 1] * 255),
                          np.round(grey_alpha[:, :, 1] * 255))


def test_lut_format_follows_the_ending(tmp_path, warm_look):
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "coffee.jpg")
    result = run("apply", photo, "--look", warm_look, "-o", tmp_path / "a.jpg",
                 "--lut", tmp_path / "a.clf")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "a.clf").read_text().lstrip().startswith("<?xml")
    result = run("apply", photo, "--look", warm_look, "-o", tmp_path / "b.jpg",
                 "--lut", tmp_path / "b.txt")
    assert result.exit_code == 2 and "b.txt: --lut file name must end in .cube or .clf" \
        in result.output
    assert not (tmp_path / "b.jpg").exists()
    result = run("apply", photo, "--look", warm_look, "-o", tmp_path / "c.jpg",
                 "--lut", tmp_path / "c.cube", "--lut-format", "clf")
    assert result.exit_code == 2 and "must end in .clf (--lut-format clf)" in result.output


def cmyk_jpeg(path, profile: bytes | None = None):
    """A CMYK JPEG (Pillow): cyan, magenta, yellow and half-black patches."""
    from PIL import Image as PILImage

    cmyk = np.zeros((16, 64, 4), np.uint8)
    cmyk[:, :16, 0] = 255
    cmyk[:, 16:32, 1] = 255
    cmyk[:, 32:48, 2] = 255
    cmyk[:, 48:, 3] = 128
    extra = {} if profile is None else {"icc_profile": profile}
    PILImage.fromarray(cmyk, "CMYK").save(path, quality=95, **extra)
    return path


def fake_cmyk_profile() -> bytes:
    """An ICC header saying CMYK, with no usable tables (LittleCMS cannot use it)."""
    header = bytearray(128)
    header[36:40] = b"acsp"
    header[16:20] = b"CMYK"
    header[12:16] = b"prtr"
    header[20:24] = b"Lab "
    header[0:4] = (128 + 4).to_bytes(4, "big")
    return bytes(header) + b"\0\0\0\0"


def test_cmyk_jpeg_comes_out_rgb_without_the_cmyk_profile(tmp_path):
    identity = write_cube(tmp_path / "identity.cube", identity_map(2))
    for name, profile in (("plain.jpg", None), ("tagged.jpg", fake_cmyk_profile())):
        photo = cmyk_jpeg(tmp_path / name, profile)
        image = read_image(photo)
        assert image.pixels.shape[2] == 3
        assert image.spec.getattribute("ICCProfile") is None
        assert image.spec.get_string_attribute("jpeg:ColorSpace", "") == ""
        out = tmp_path / f"out_{name}"
        result = run("apply", photo, "--look", identity, "-o", out)
        assert result.exit_code == 0, result.output
        written = oiio.ImageInput.open(str(out))
        spec = written.spec()
        pixels = written.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        written.close()
        assert spec.nchannels == 3 and spec.getattribute("ICCProfile") is None
        assert spec.get_string_attribute("jpeg:ColorSpace", "RGB") != "CMYK"
        cyan, magenta, yellow, grey = (pixels[8, x] for x in (8, 24, 40, 56))
        assert cyan[0] < 0.2 and min(cyan[1:]) > 0.8
        assert magenta[1] < 0.2 and min(magenta[[0, 2]]) > 0.8
        assert yellow[2] < 0.2 and min(yellow[:2]) > 0.8
        assert np.ptp(grey) < 0.05 and 0.3 < grey[0] < 0.7


def test_write_options_reach_batch(tmp_path, warm_look):
    folder = tmp_path / "in"
    folder.mkdir()
    shutil.copy(SAMPLES / "chelsea.jpg", folder / "chelsea.jpg")
    small_copy(SAMPLES / "coffee.jpg", folder / "coffee.png")
    result = run("batch", folder, "-o", tmp_path / "out", "--look", warm_look,
                 "--quality", 60, "--bit-depth", "16")
    assert result.exit_code == 0, result.output
    # where the format holds it: the PNG is 16-bit, the JPEG stays 8-bit (at quality 60)
    assert read_image(tmp_path / "out" / "coffee.png").spec.format == oiio.UINT16
    assert read_image(tmp_path / "out" / "chelsea.jpg").spec.format == oiio.UINT8
    assert (tmp_path / "out" / "chelsea.jpg").stat().st_size < \
        0.9 * (SAMPLES / "chelsea.jpg").stat().st_size
