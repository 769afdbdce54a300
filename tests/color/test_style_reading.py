"""A style folder is read fast and once (issue 34, item 6: the first ``apply --style`` on a
folder is not a wait): integer files scaled by numpy exactly as OpenImageIO scales them,
each photo decoded once for its histogram and its scene image, photos read in threads in
the folder's order."""

from __future__ import annotations

import concurrent.futures
import pickle
import threading
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

import wbcgrade.color.io.images as imageio
import wbcgrade.color.look.scene as scene
import wbcgrade.color.presets as presets
from tests.color.conftest import SAMPLES, STYLE_PHOTOS, small_copy, write_array
from wbcgrade.color.histogram import Deferred, HistogramCache
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
        fresh = scene._as_stored(scene._read_style(path, styles.working_space))
        assert np.array_equal(image.colors, fresh.colors)
        assert np.array_equal(image.points, fresh.points)
        assert np.array_equal(image.descriptors, fresh.descriptors)
    # and from the disk cache in another process (the in-memory ones forgotten): the same
    # values, so a first run and a later one grade alike
    monkeypatch.setattr(scene, "_IN_MEMORY", {})
    read_fresh = len(reads)
    again = scene.style_scene_images(styles)
    assert len(reads) == read_fresh
    for first, later in zip(images, again):
        assert np.array_equal(first.colors, later.colors)
        assert np.array_equal(first.descriptors, later.descriptors)


@pytest.mark.slow  # over 5 s of the fast tier: the whole suite runs it
def test_apply_decodes_each_style_photo_once(tmp_path, monkeypatch, cli):
    """Through the command line, with style photos larger than the matching size (their
    scene images shrunk from the decode the histograms are read from)."""
    styles = tmp_path / "big"
    styles.mkdir()
    for name in STYLE_PHOTOS:
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", width=scene.MATCH_SIZE + 200)
    photo = small_copy(SAMPLES / "sunset.jpg", tmp_path / "sunset.jpg", width=160)
    reads: list[str] = []
    real = imageio.read_image

    def counting(path):
        reads.append(Path(path).name)
        return real(path)

    monkeypatch.setattr(imageio, "read_image", counting)
    monkeypatch.setattr(presets, "read_image", counting)
    monkeypatch.setattr(scene, "_IN_MEMORY", {})
    result = cli("apply", photo, "--style", styles, "-o", tmp_path / "out.jpg",
                 env={"WBCGRADE_CACHE_DIR": str(tmp_path / "cache")})
    assert result.exit_code == 0, result.output
    assert sorted(r for r in reads if r != "sunset.jpg") == sorted(f"{n}.jpg" for n in STYLE_PHOTOS)


def test_scene_images_are_prepared_only_where_photos_match_scenes(folder, tmp_path, monkeypatch):
    source = StyleSource(str(folder), None, None)
    photo = tmp_path / "photo.jpg"
    assert scene.matching_hook(source, GradeOptions(), [photo]) is not None
    assert scene.matching_hook(source, GradeOptions(mode="palette")) is None
    assert scene.matching_hook(source, GradeOptions(weights=(0.5, 0.5))) is None
    assert scene.matching_hook(StyleSource(None, "warm", None), GradeOptions()) is None
    # raw photos alone, graded in ACEScct, look the styles up in that space, not this one
    raws = [tmp_path / "a.CR2", tmp_path / "b.dng"]
    assert scene.matching_hook(source, GradeOptions(), raws) is None
    assert scene.matching_hook(source, GradeOptions(), [*raws, photo]) is not None
    assert scene.matching_hook(source, GradeOptions(working_space="acescct"), raws) is not None
    # more photos than are kept in memory: not prepared ahead (they would be dropped)
    monkeypatch.setattr(scene, "_IN_MEMORY_MAX", 3)
    assert scene.matching_hook(source, GradeOptions(), [photo]) is None


def test_big_photos_are_not_decoded_together(folder, monkeypatch):
    """At most READ_MEGAPIXELS in flight; a photo bigger than that alone."""
    monkeypatch.setattr(presets, "READ_THREADS", 4)
    monkeypatch.setattr(presets, "_megapixels", lambda path: 30.0)
    monkeypatch.setattr(presets, "cpu_count", lambda: 4)  # (the executor's, as presets has it)
    in_flight, most = [0], [0]
    lock = threading.Lock()
    real = presets._photo_histogram

    def reading(path, *args):
        with lock:
            in_flight[0] += 1
            most[0] = max(most[0], in_flight[0])
        try:
            time.sleep(0.05)
            return real(path, *args)
        finally:
            with lock:
                in_flight[0] -= 1

    monkeypatch.setattr(presets, "_photo_histogram", reading)
    monkeypatch.setattr(presets, "READ_MEGAPIXELS", 48.0)
    presets.load_style_folder(folder, 16, warn=lambda _: None)
    assert most[0] == 1  # two 30 MP photos would be 60
    monkeypatch.setattr(presets, "READ_MEGAPIXELS", 120.0)
    most[0] = 0
    presets.load_style_folder(folder, 16, warn=lambda _: None)
    assert most[0] > 1


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
    read (the one in flight finishes). The reader holds the second photo until the pool has
    been told to cancel, and the interrupt waits until it holds it: on a busy machine the
    reader otherwise ran on through the folder before the main thread raised."""
    monkeypatch.setattr(presets, "READ_THREADS", 1)
    started: list[str] = []
    cancelled = threading.Event()
    real = presets._photo_histogram

    def reading(path, *args):
        started.append(path.name)
        if len(started) > 1:
            cancelled.wait(60)
        return real(path, *args)

    def progress(number, total, name):
        if number == 1:
            deadline = time.monotonic() + 60
            while len(started) < 2 and time.monotonic() < deadline:
                time.sleep(0.001)
            raise KeyboardInterrupt

    class Pool(concurrent.futures.ThreadPoolExecutor):
        def shutdown(self, wait=True, *, cancel_futures=False):
            super().shutdown(wait=False, cancel_futures=cancel_futures)
            cancelled.set()
            super().shutdown(wait=wait)

    monkeypatch.setattr(presets, "_photo_histogram", reading)
    monkeypatch.setattr(concurrent.futures, "ThreadPoolExecutor", Pool)
    monkeypatch.setattr(presets, "ThreadPoolExecutor", Pool, raising=False)  # if imported on top
    with pytest.raises(KeyboardInterrupt):
        presets.load_style_folder(folder, 16, progress=progress)
    assert cancelled.is_set()
    assert 2 <= len(started) <= 3 < len(STYLE_PHOTOS) + 1


def test_a_thumbnail_of_a_big_picture_is_the_filtered_resize_of_it():
    """Block-averaged first (a big photo's filtered resize took seconds), the thumbnail
    still matches OpenImageIO's filtered resize of the whole picture: a smooth gradient
    within 1/255, a fine stripe pattern averaged to its mean grey, not aliased."""
    from wbcgrade.photos.sheet import PRESHRINK, thumbnail

    height, width = 1203, 1807  # not multiples of the blocks
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    smooth = np.stack([x / width, y / height, 0.5 + 0.4 * np.sin(x / 150)], axis=-1)
    direct = np.asarray(oiio.ImageBufAlgo.resize(
        oiio.ImageBuf(smooth), roi=oiio.ROI(0, 120, 0, 80, 0, 1, 0, 3)).get_pixels(oiio.FLOAT))
    small = thumbnail(smooth, 80, 120)
    assert small.shape == direct.shape == (80, 120, 3)
    assert height // (PRESHRINK * 80) >= 2  # the block path was taken
    assert np.abs(small - direct).max() < 1 / 255
    stripes = np.repeat(((x % 2) * np.float32(1.0))[..., None], 3, axis=-1)
    tiny = thumbnail(stripes, 80, 120)
    assert np.abs(tiny[:, 1:-1] - 0.5).max() < 0.01  # (the edge columns: a partial block)


def test_header_pixels_reads_the_size_and_says_nothing_of_what_it_cannot_read(tmp_path):
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "c.jpg", width=90)
    image = imageio.read_image(photo)
    assert imageio.header_pixels(photo) == image.pixels.shape[0] * image.pixels.shape[1]
    (tmp_path / "broken.jpg").write_bytes(b"\xff\xd8 not a jpeg")
    for path in (tmp_path / "gone.jpg", tmp_path, tmp_path / "broken.jpg"):
        assert imageio.header_pixels(path) == 0  # read_image says what is wrong


def _dense_at(styles, bins: int) -> np.ndarray:
    """What ``at_bins`` gives from the dense histograms (re-binned here, not cached)."""
    return np.stack([presets.resample_histogram(h, bins) for h in styles.histograms])


def _small_style_folder(tmp_path, count: int):
    """A folder of ``count`` small style photos and a histogram cache beside it."""
    styles_dir = tmp_path / "styles"
    styles_dir.mkdir()
    for name in STYLE_PHOTOS[:count]:
        small_copy(SAMPLES / f"{name}.jpg", styles_dir / f"{name}.jpg", width=120)
    return styles_dir, HistogramCache(tmp_path / "cache")


def test_a_cached_folder_gives_its_coarse_grids_from_the_cache_and_stays_sparse(tmp_path):
    styles_dir, cache = _small_style_folder(tmp_path, 3)
    first = presets.load_style_folder(styles_dir, 32, cache=cache, resampled=(8,))
    expected, dense = first.at_bins(8).copy(), first.histograms.copy()
    assert np.array_equal(expected, _dense_at(first, 8))  # bit for bit what at_bins makes

    def refused(*_args, **_kwargs):
        raise AssertionError("re-binned again: the cache was not used")

    real = presets.resample_histogram
    presets.resample_histogram = refused
    try:
        again = presets.load_style_folder(styles_dir, 32, cache=cache, resampled=(8,))
        assert np.array_equal(again.at_bins(8), expected)
        assert again.bins == 32
        # nothing read the dense stack yet: it is still the cache's sparse entries
        assert isinstance(again.__dict__["_deferred_histograms"], Deferred)
    finally:
        presets.resample_histogram = real
    sent = pickle.dumps(again)  # (a batch's workers): made dense once, and kept
    assert isinstance(again.__dict__["_deferred_histograms"], np.ndarray)
    assert np.array_equal(again.histograms, dense)  # made dense as the first run had it
    assert np.array_equal(pickle.loads(sent).histograms, dense)


def test_an_edited_style_photo_is_re_binned_not_read_from_the_cache(tmp_path):
    styles_dir, cache = _small_style_folder(tmp_path, 2)
    before = presets.load_style_folder(styles_dir, 32, cache=cache, resampled=(8,)).at_bins(8)
    edited = styles_dir / f"{STYLE_PHOTOS[0]}.jpg"
    small_copy(SAMPLES / "sunset.jpg", edited, width=120)  # another photo under its name
    after = presets.load_style_folder(styles_dir, 32, cache=cache, resampled=(8,))
    assert not np.array_equal(after.at_bins(8)[0], before[0])
    assert np.array_equal(after.at_bins(8), _dense_at(after, 8))
    assert np.array_equal(after.at_bins(8)[1], before[1])


def test_a_preset_stack_is_made_as_each_histogram_was_and_the_photo_transfer_waits(rng):
    from wbcgrade.color.grade.grading import photo_histograms
    from wbcgrade.color.histogram import (
        from_sparse,
        image_histogram,
        stack_from_sparse,
        to_sparse,
    )

    hists = [np.abs(rng.normal(size=(16, 16, 16))) ** 4 for _ in range(3)]
    parts = [to_sparse(h, 1e-3) for h in hists]
    stacked = stack_from_sparse([parts[0], hists[1], parts[2]], 16)
    assert np.array_equal(stacked[0], from_sparse(*parts[0], 16))
    assert np.array_equal(stacked[1], hists[1])
    assert np.array_equal(stacked[2], from_sparse(*parts[2], 16))
    pixels = rng.random((40, 50, 3)).astype(np.float32)
    options = GradeOptions()
    photo = photo_histograms(pixels, options)
    assert isinstance(photo.__dict__["_deferred_transfer"], Deferred)  # not binned yet
    assert photo.at(options.transfer.bins).shape == (options.transfer.bins,) * 3
    assert np.array_equal(photo.transfer, image_histogram(pixels, options.transfer.bins, None,
                                                          options.transfer.max_pixels))
