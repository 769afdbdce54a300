"""A style folder is read fast and once (issue 34, item 6: the first ``apply --style`` on a
folder is not a wait): integer files scaled by numpy exactly as OpenImageIO scales them,
each photo decoded once for its histogram and its scene image, photos read in threads in
the folder's order."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

import wbcgrade.color.imageio as imageio
import wbcgrade.color.look.scene as scene
import wbcgrade.color.presets as presets
from tests.color.conftest import SAMPLES, STYLE_PHOTOS, small_copy, write_array
from wbcgrade.color.histogram import HistogramCache
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.presets import StyleSource, load_styles
from wbcgrade.errors import InputError


def _oiio_float(path) -> np.ndarray:
    """OpenImageIO's own float conversion (colours kept unassociated, as read_image asks)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    spec = inp.spec()
    pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    return np.asarray(pixels, np.float32).reshape(spec.height, spec.width, spec.nchannels)


@pytest.mark.parametrize("fmt, suffix, channels", [("uint8", "png", 3), ("uint8", "jpg", 3),
                                                   ("uint16", "png", 4), ("uint16", "tif", 3),
                                                   ("half", "exr", 3)])
def test_integer_files_read_to_the_same_float_values_as_openimageio_gives(tmp_path, fmt,
                                                                           suffix, channels):
    rng = np.random.default_rng(1)
    pixels = rng.random((23, 31, channels)).astype(np.float32)
    pixels[0, :4, 0] = [0.0, 1.0, 1 / 255, 254 / 255]  # the ends of the range
    path = write_array(tmp_path / f"p.{suffix}", pixels, fmt)
    image = imageio.read_image(path)
    assert image.pixels.dtype == np.float32
    assert np.array_equal(image.pixels, _oiio_float(path))  # bit for bit


def test_a_nan_in_a_float_file_is_still_refused(tmp_path):
    pixels = np.full((4, 4, 3), 0.5, np.float32)
    pixels[1, 1, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        imageio.read_image(write_array(tmp_path / "nan.exr", pixels, "float"))


@pytest.fixture
def folder(tmp_path):
    styles = tmp_path / "styles"
    styles.mkdir()
    for name in STYLE_PHOTOS:
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", width=160)
    (styles / "broken.jpg").write_bytes(b"\xff\xd8 not a jpeg")
    return styles


def test_a_folder_read_for_a_look_is_decoded_once_and_its_scene_images_are_the_same(
        folder, tmp_path, monkeypatch):
    options = GradeOptions()
    reads: list[str] = []
    real = imageio.read_image

    def counting(path):
        reads.append(str(path))
        return real(path)

    monkeypatch.setattr(presets, "read_image", counting)
    monkeypatch.setattr(imageio, "read_image", counting)
    monkeypatch.setattr(scene, "_IN_MEMORY", {})
    source = StyleSource(str(folder), None, HistogramCache(tmp_path / "cache"))
    styles = load_styles(source, 32, None, lambda _: None, None,
                         scene.matching_hook(source, options))
    assert len(styles.names) == len(STYLE_PHOTOS)
    read_for_histograms = len(reads)
    images = scene.style_scene_images(styles)
    assert len(reads) == read_for_histograms  # no photo decoded a second time
    for path, image in zip(styles.files, images):
        fresh = scene._read_style(path, styles.working_space)
        assert np.array_equal(image.colors, fresh.colors)
        assert np.array_equal(image.points, fresh.points)
        assert np.array_equal(image.descriptors, fresh.descriptors)
    # and from the disk cache in another process (the in-memory ones forgotten)
    monkeypatch.setattr(scene, "_IN_MEMORY", {})
    read_fresh = len(reads)
    again = scene.style_scene_images(styles)
    assert len(reads) == read_fresh
    assert all(np.allclose(a.colors, b.colors, atol=1e-3) for a, b in zip(images, again))


def test_a_palette_grade_prepares_no_scene_images(folder):
    source = StyleSource(str(folder), None, None)
    assert scene.matching_hook(source, GradeOptions(mode="palette")) is None
    assert scene.matching_hook(source, GradeOptions(weights=(0.5, 0.5))) is None
    assert scene.matching_hook(StyleSource(None, "warm", None), GradeOptions()) is None
    assert scene.matching_hook(source, GradeOptions()) is not None


def test_photos_read_in_threads_keep_the_folders_order_and_skip_a_broken_one(
        folder, monkeypatch):
    def load(threads):
        monkeypatch.setattr(presets, "READ_THREADS", threads)
        warnings, steps = [], []
        styles = presets.load_style_folder(folder, 16, warn=warnings.append,
                                           progress=lambda n, total, name: steps.append(n))
        return styles, warnings, steps

    one, warned_one, steps_one = load(1)
    many, warned_many, steps_many = load(4)
    assert many.names == one.names == sorted(STYLE_PHOTOS)
    assert np.array_equal(many.histograms, one.histograms)
    assert warned_many == warned_one and len(warned_one) == 1 and "broken.jpg" in warned_one[0]
    assert steps_many == steps_one == list(range(len(STYLE_PHOTOS) + 2))


def test_an_interrupted_folder_read_stops_reading(folder, monkeypatch):
    """Ctrl+C (in the main thread) while a folder is read: the photos not started are not
    read (the one in flight finishes)."""
    monkeypatch.setattr(presets, "READ_THREADS", 1)
    started: list[str] = []
    real = presets._photo_histogram

    def reading(path, *args):
        started.append(path.name)
        return real(path, *args)

    def progress(number, total, name):
        if number == 1:
            raise KeyboardInterrupt

    monkeypatch.setattr(presets, "_photo_histogram", reading)
    with pytest.raises(KeyboardInterrupt):
        presets.load_style_folder(folder, 16, progress=progress)
    assert 2 <= len(started) <= 3 < len(STYLE_PHOTOS) + 1
