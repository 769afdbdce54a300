"""Photo reading and writing: formats, bit depth, metadata, orientation, bad files."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.color.conftest import SAMPLES, write_array
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.io.images import orient, read_image, write_image
from wbcgrade.errors import InputError


def _icc_profile() -> np.ndarray:
    """A minimal well-formed ICC header (128 bytes, 'acsp' signature, no tags)."""
    data = bytearray(132)
    data[0:4] = (132).to_bytes(4, "big")
    data[8:12] = bytes([4, 0x40, 0, 0])
    data[12:16] = b"mntr"
    data[16:20] = b"RGB "
    data[20:24] = b"XYZ "
    data[36:40] = b"acsp"
    return np.frombuffer(bytes(data), dtype=np.uint8)


def _listed(path):
    return sorted(p.name for p in path.parent.iterdir())


# Display pixels of the stored image [[0, 1, 2], [3, 4, 5]] per EXIF/TIFF Orientation.
_EXIF_DISPLAY = {
    1: [[0, 1, 2], [3, 4, 5]],
    2: [[2, 1, 0], [5, 4, 3]],  # mirror horizontal
    3: [[5, 4, 3], [2, 1, 0]],  # rotate 180
    4: [[3, 4, 5], [0, 1, 2]],  # mirror vertical
    5: [[0, 3], [1, 4], [2, 5]],  # transpose: row 0 = left side, column 0 = top
    6: [[3, 0], [4, 1], [5, 2]],  # rotate 90 clockwise
    7: [[5, 2], [4, 1], [3, 0]],  # transverse: row 0 = right side, column 0 = bottom
    8: [[2, 5], [1, 4], [0, 3]],  # rotate 90 counter-clockwise
}


@pytest.mark.parametrize("orientation", range(1, 9))
def test_orientation_follows_exif_specification(orientation):
    stored = np.arange(6, dtype=np.float32).reshape(2, 3, 1)
    np.testing.assert_array_equal(orient(stored, orientation)[..., 0],
                                  _EXIF_DISPLAY[orientation])


# OpenImageIO before 3.2 swaps 5 and 7 in reorient() (OIIO issue #4661, fixed by PR #5350).
@pytest.mark.parametrize("orientation", [1, 2, 3, 4, 6, 8])
def test_orientation_matches_openimageio(orientation, rng):
    stored = rng.random((3, 5, 3)).astype(np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(5, 3, 3, "float"))
    buf.set_pixels(oiio.ROI(0, 5, 0, 3, 0, 1, 0, 3), stored)
    buf.specmod().attribute("Orientation", orientation)
    expected = oiio.ImageBufAlgo.reorient(buf).get_pixels(oiio.FLOAT)
    np.testing.assert_array_equal(orient(stored, orientation), expected)


def test_jpeg_round_trip_keeps_exif_icc_and_orientation(tmp_path, rng):
    pixels = np.zeros((20, 30, 3), np.float32)
    pixels[:, :10, 0] = 1.0  # red band on the left of the stored image
    icc = _icc_profile()
    src = write_array(tmp_path / "in.jpg", pixels, "uint8", {
        "Orientation": 6, "Make": "TestCam", "Exif:DateTimeOriginal": "2020:01:02 03:04:05",
        "ICCProfile": (oiio.TypeDesc(f"uint8[{len(icc)}]"), icc)})
    image = read_image(src)
    assert image.pixels.shape == (30, 20, 3)  # rotated for display
    assert image.pixels[:10, :, 0].mean() > 0.9  # the left band is now at the top
    out = write_image(tmp_path / "out.jpg", image.pixels, image)
    back = read_image(out)
    assert back.pixels.shape == (30, 20, 3)
    assert np.abs(back.pixels - image.pixels).mean() < 2 / 255
    spec = back.spec
    assert spec.get_int_attribute("Orientation", 0) == 1
    assert spec.get_string_attribute("Make") == "TestCam"
    assert spec.get_string_attribute("Exif:DateTimeOriginal") == "2020:01:02 03:04:05"
    assert np.array_equal(np.asarray(spec.getattribute("ICCProfile"), np.uint8), icc)
    assert spec.format == oiio.TypeDesc("uint8")


@pytest.mark.parametrize("ext", ["png", "tif"])
def test_16bit_round_trip_is_exact(tmp_path, rng, ext):
    codes = rng.integers(0, 65536, size=(8, 9, 3))
    src = write_array(tmp_path / f"in.{ext}", codes / 65535.0, "uint16")
    image = read_image(src)
    assert image.spec.format == oiio.TypeDesc("uint16")
    out = write_image(tmp_path / f"out.{ext}", image.pixels, image)
    back = oiio.ImageInput.open(str(out))
    assert back.spec().format == oiio.TypeDesc("uint16")
    np.testing.assert_array_equal(back.read_image(0, 0, 0, 3, "uint16"), codes)
    back.close()


def test_exr_float_round_trip_and_values_above_one(tmp_path, rng):
    linear = (rng.random((6, 7, 3)) * 4.0).astype(np.float32)  # HDR values up to 4
    src = write_array(tmp_path / "in.exr", linear, "half")
    image = read_image(src)
    assert image.is_float
    encoding = ColorEncoding.for_image(image)  # Linear Rec.709 graded in sRGB
    encoded, state = encoding.encode(image.rgb(), image.is_float)
    assert encoded.min() >= 0 and encoded.max() <= 1 and state.scale is not None
    # (OpenColorIO's float32 curves: a round trip within 1e-4, far below half precision)
    np.testing.assert_allclose(encoding.decode(encoded, state), image.rgb(), rtol=1e-4,
                               atol=1e-6)
    out = write_image(tmp_path / "out.exr", image.pixels, image)
    back = read_image(out)
    assert back.spec.format == oiio.TypeDesc("half")
    np.testing.assert_array_equal(back.pixels, image.pixels)


def test_rgba_alpha_and_grey(tmp_path, rng):
    rgba = rng.random((5, 6, 4)).astype(np.float32)
    image = read_image(write_array(tmp_path / "rgba.png", rgba, "uint8"))
    assert image.alpha_channel == 3
    assert image.rgb().shape == (5, 6, 3)
    grey = read_image(write_array(tmp_path / "grey.png", rgba[:, :, :1], "uint16"))
    assert grey.alpha() is None
    rgb = grey.rgb()
    assert rgb.shape == (5, 6, 3) and np.all(rgb[..., 0] == rgb[..., 2])


def test_truncated_jpeg_is_rejected(tmp_path):
    data = (SAMPLES / "coffee.jpg").read_bytes()
    path = tmp_path / "cut.jpg"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="corrupt or truncated"):
        read_image(path)


def test_not_an_image_and_missing_file(tmp_path):
    text = tmp_path / "notes.jpg"
    text.write_text("hello")
    with pytest.raises(InputError, match="not a readable image"):
        read_image(text)
    with pytest.raises(InputError, match="no such file"):
        read_image(tmp_path / "missing.png")


def test_nan_pixels_are_rejected(tmp_path):
    pixels = np.ones((4, 4, 3), np.float32)
    pixels[1, 2, 0] = np.nan
    with pytest.raises(InputError, match="NaN or infinite"):
        read_image(write_array(tmp_path / "nan.exr", pixels, "float"))
    pixels[1, 2, 0] = np.inf
    with pytest.raises(InputError, match="NaN or infinite"):
        read_image(write_array(tmp_path / "inf.exr", pixels, "float"))


def test_write_refuses_input_and_existing_files(tmp_path):
    src = write_array(tmp_path / "a.png", np.zeros((4, 4, 3)), "uint8")
    image = read_image(src)
    with pytest.raises(InputError, match="input"):
        write_image(src, image.pixels, image, overwrite=True)
    other = write_array(tmp_path / "b.png", np.zeros((4, 4, 3)), "uint8")
    with pytest.raises(InputError, match="exists"):
        write_image(other, image.pixels, image)
    write_image(other, image.pixels + 0.5, image, overwrite=True)
    assert read_image(other).pixels.mean() == pytest.approx(128 / 255, abs=1e-6)
    assert _listed(src) == ["a.png", "b.png"]  # no temporary file left


def test_failed_write_leaves_nothing(tmp_path):
    image = read_image(write_array(tmp_path / "a.png", np.zeros((4, 4, 3)), "uint8"))
    with pytest.raises(InputError, match="missing: output folder does not exist"):
        write_image(tmp_path / "missing" / "out.png", image.pixels, image)
    with pytest.raises((InputError, OSError), match=r"pixels must be \(H, W, C\)"):
        write_image(tmp_path / "out.png", image.pixels[:, :, :1].squeeze(), image)
    assert _listed(tmp_path / "a.png") == ["a.png"]


def test_interrupted_write_removes_the_temporary_file(tmp_path, monkeypatch):
    image = read_image(write_array(tmp_path / "a.png", np.zeros((4, 4, 3)), "uint8"))

    def fail(*args):
        raise OSError("disk full")

    monkeypatch.setattr("wbcgrade._publish.os.replace", fail)
    monkeypatch.setattr("wbcgrade._publish.os.link", fail)
    with pytest.raises(OSError, match="disk full"):
        write_image(tmp_path / "out.png", image.pixels, image)
    assert _listed(tmp_path / "a.png") == ["a.png"]


def test_unwritable_output_folder(tmp_path, monkeypatch):
    image = read_image(write_array(tmp_path / "a.png", np.zeros((4, 4, 3)), "uint8"))
    monkeypatch.setattr("wbcgrade.color.io.images.os.access", lambda *args: False)
    with pytest.raises(InputError, match="not writable"):
        write_image(tmp_path / "out.png", image.pixels, image)


@pytest.mark.parametrize("ext", ["png", "tif", "exr"])
def test_colour_under_partial_alpha_survives_read_and_write(tmp_path, ext):
    """Colour is handled unassociated: not darkened by alpha, not lost where alpha is 0."""
    import OpenImageIO as oiio

    from wbcgrade.color.io.images import read_image, write_image

    alpha = np.array([[1.0, 128 / 255], [0.0, 10 / 255]], np.float32)
    colour = np.zeros((2, 2, 4), np.float32)
    colour[..., 0], colour[..., 1], colour[..., 3] = 200 / 255, 100 / 255, alpha
    stored = colour.copy()
    spec = oiio.ImageSpec(2, 2, 4, oiio.HALF if ext == "exr" else oiio.UINT8)
    spec.alpha_channel = 3
    if ext == "exr":  # EXR stores colour multiplied by alpha
        stored[..., :3] *= alpha[..., None]
    else:
        spec.attribute("oiio:UnassociatedAlpha", 1)
    src = str(tmp_path / f"in.{ext}")
    out = oiio.ImageOutput.create(src)
    assert out.open(src, spec) and out.write_image(stored) and out.close()

    image = read_image(src)
    visible = alpha > 0
    np.testing.assert_allclose(image.pixels[..., 0][visible], 200 / 255, atol=1 / 255)
    np.testing.assert_allclose(image.pixels[..., 3], alpha, atol=1 / 255)
    write_image(tmp_path / f"out.{ext}", image.pixels, image)
    again = read_image(tmp_path / f"out.{ext}")
    np.testing.assert_allclose(again.pixels[..., :2][visible], image.pixels[..., :2][visible],
                               atol=0.5 / 255)


def test_output_that_appears_during_a_grade_is_not_replaced(tmp_path):
    """The existence check happens early; publishing must not clobber a newer file."""
    from wbcgrade._publish import atomic_path

    target = tmp_path / "out.txt"
    with pytest.raises(InputError, match="file exists"):
        with atomic_path(target, overwrite=False) as tmp:
            with open(tmp, "w") as handle:
                handle.write("ours")
            target.write_text("theirs")  # another process wrote it meanwhile
    assert target.read_text() == "theirs"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]  # no temporary left
    with atomic_path(target, overwrite=True) as tmp:
        with open(tmp, "w") as handle:
            handle.write("ours")
    assert target.read_text() == "ours"


def test_gif_alpha_and_synthetic_null_files(tmp_path, rng):
    """A GIF's alpha is channel 4 of 4 to OpenImageIO: read as the last channel; a file
    only OpenImageIO's ``null`` reader opens (zero bytes named .null) is not an image."""
    from PIL import Image as PILImage

    pixels = (rng.random((6, 7, 3)) * 255).astype(np.uint8)
    PILImage.fromarray(pixels).save(tmp_path / "a.gif")
    image = read_image(tmp_path / "a.gif")
    assert image.pixels.shape == (6, 7, 4) and image.alpha_channel == 3
    assert image.alpha().shape == (6, 7) and image.rgb().shape == (6, 7, 3)
    (tmp_path / "x.null").write_bytes(b"")
    (tmp_path / "big.null?RES=9000x9000").write_bytes(b"")
    for name in ("x.null", "big.null?RES=9000x9000"):
        with pytest.raises(InputError, match="not a readable image"):
            read_image(tmp_path / name)


def test_only_regular_files_are_read(tmp_path):
    """A FIFO (which would block the read for ever) or a device is refused unopened
    (run in a child process: a read that blocks fails the test instead of hanging it)."""
    import os
    import subprocess
    import sys

    os.mkfifo(tmp_path / "pipe.jpg")
    code = ("from wbcgrade.color.io.images import read_image\n"
            "for name in ('pipe.jpg', '/dev/zero'):\n"
            "    try:\n        read_image(name)\n"
            "    except ValueError as exc:\n        print(exc)\n")
    try:
        done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, text=True,
                              capture_output=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("reading a FIFO blocked")
    assert "pipe.jpg: is a FIFO" in done.stdout and "is a character device" in done.stdout, \
        done.stdout + done.stderr


@pytest.mark.parametrize("name, stored, extra", [
    ("rgb.png", "uint8", {}), ("deep.png", "uint16", {}), ("strips.tif", "uint16", {}),
    ("interlaced.png", "uint8", {"png:interlace": 1}),
    ("progressive.jpg", "uint8", {"jpeg:progressive": 1, "Compression": "jpeg:100"}),
    ("tiles.tif", "uint8", {"tile_width": 16, "tile_height": 16})])
def test_integer_scanlines_are_scaled_in_bands_of_rows(tmp_path, monkeypatch, name, stored,
                                                       extra):
    """8/16-bit scanline files are read a band of rows at a time and scaled into the float32
    pixels (no full-size array of integers): OpenImageIO's stored values scaled, bit for
    bit, the last band short; a tiled file is read whole as before."""
    import wbcgrade.color.io.images as images

    monkeypatch.setattr(images, "_SCALED_ROWS", 7)
    rng = np.random.default_rng(3)
    top = np.iinfo(stored).max
    codes = rng.integers(0, top + 1, (45, 33, 3)).astype(stored)
    path = tmp_path / name
    spec = oiio.ImageSpec(33, 45, 3, stored)
    for key, value in extra.items():
        spec.attribute(key, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(codes) and out.close()
    stored_back = oiio.ImageInput.open(str(path)).read_image(0, 0, 0, 3, stored)
    image = read_image(path)
    assert image.pixels.dtype == np.float32
    assert np.array_equal(image.pixels,
                          np.multiply(stored_back, np.float32(1 / top), dtype=np.float32))
    assert np.array_equal(image.pixels, oiio.ImageInput.open(str(path)).read_image(
        0, 0, 0, 3, "float"))  # (OpenImageIO's own conversion gives these values)
    truncated = tmp_path / f"cut_{name}"
    truncated.write_bytes(path.read_bytes()[:len(path.read_bytes()) // 2])
    with pytest.raises(InputError, match="corrupt or truncated"):
        read_image(truncated)
