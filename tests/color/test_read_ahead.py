"""``apply`` decodes the photo (and finds its keypoints) on another thread while the grade's
modules import and its styles load (and their scene images are read): the same grade,
the same errors."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import wbcgrade.photos.read_ahead as read_ahead
import wbcgrade.photos.workflow as workflow
from tests.color.conftest import SAMPLES, small_copy
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.io.images import read_image
from wbcgrade.errors import InputError


@pytest.fixture(autouse=True)
def _no_scenes_left_by_other_tests():
    """These tests count what is prepared ahead: start from none. (An in-process command
    of another test that fails after its read-ahead started the photo's keypoints leaves
    them in the registry, which a process that exits never minds.)"""
    from wbcgrade.color.look import scene

    with scene._AHEAD_LOCK:
        scene._AHEAD.clear()
        scene._MIRRORS.clear()
    yield


def test_a_read_ahead_gives_the_photo_or_raises_what_reading_raised(tmp_path, monkeypatch):
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "coffee.jpg")
    ahead = read_ahead.ReadAhead(photo)
    image, encoding, encoded = ahead.result()
    assert np.array_equal(image.pixels, read_image(photo).pixels)
    expected = ColorEncoding.for_image(image).encode(image.rgb(), image.is_float)[0]
    assert np.array_equal(encoded[0], expected) and not ahead.scene_started
    monkeypatch.chdir(tmp_path)  # the same file named otherwise, in the same spaces
    assert ahead.serves("coffee.jpg", None, None) and ahead.serves(photo, None, None)
    assert not ahead.serves(photo, None, "acescct") and not ahead.serves("x.jpg", None, None)
    broken = tmp_path / "broken.jpg"
    broken.write_bytes(photo.read_bytes()[:200])
    with pytest.raises(InputError) as raised:
        read_ahead.ReadAhead(broken).result()
    with pytest.raises(InputError) as direct:
        read_image(broken)
    assert str(raised.value) == str(direct.value)


def test_apply_decodes_the_photo_while_the_styles_load(tmp_path, style_dir, monkeypatch, cli):
    """The photo is decoded on the read-ahead thread (started once the options are
    checked) and its keypoints found from there; the styles load on the main thread and
    their photos are prepared for matching before the grade asks; nothing of the photo's
    keypoints is kept after the grade."""
    photo = small_copy(SAMPLES / "sunset.jpg", tmp_path / "sunset.jpg")
    events: list[tuple[str, str]] = []
    reading, loading = read_ahead.read_image, workflow.load_styles

    def read(path):
        events.append(("read", threading.current_thread().name))
        return reading(path)

    def load(*args, **kwargs):
        events.append(("styles", threading.current_thread().name))
        return loading(*args, **kwargs)

    kept, prepared, forgotten = [], [], []
    monkeypatch.setattr(read_ahead, "read_image", read)  # (the grade's own read too)
    monkeypatch.setattr(workflow, "load_styles", load)
    monkeypatch.setattr(workflow, "keep_style_scenes", lambda styles: kept.append(styles))
    preparing, forgetting = read_ahead.prepare_photo_scene, workflow.forget_photo_scene
    monkeypatch.setattr(read_ahead, "prepare_photo_scene",
                        lambda colors, entry: (prepared.append(colors), preparing(colors, entry)))
    monkeypatch.setattr(workflow, "forget_photo_scene",
                        lambda colors: (forgotten.append(colors), forgetting(colors)))
    result = cli("apply", str(photo), "--style", str(style_dir), "-o",
                 str(tmp_path / "out.jpg"))
    assert result.exit_code == 0, result.output
    assert ("read", "wbcgrade-read") in events and ("styles", "MainThread") in events
    assert len([e for e in events if e[0] == "read"]) == 1  # read once, ahead
    assert len(kept) == 1 and kept[0].files  # the style photos, prepared ahead
    assert len(prepared) == 1 and len(forgotten) == 1 and prepared[0] is forgotten[0]
    result = cli("apply", str(photo), "--preset", "warm", "-o", str(tmp_path / "p.jpg"))
    assert result.exit_code == 0, result.output
    assert len(prepared) == 1  # a preset's look matches no scene: nothing prepared
    assert events.count(("read", "wbcgrade-read")) == 2  # (but read ahead all the same)


def test_a_photo_prepared_ahead_gives_the_scene_and_mirror_it_would_have(rng):
    """``prepare_photo_scene`` (started by ``grade_photo`` beside the photo's histograms):
    the grade's ``scene_image`` and ``mirrored`` of that very array get the keypoints
    they would have computed; another array (even an equal one) is computed as before;
    nothing is kept once forgotten, and a failure is raised where the grade asks."""
    from wbcgrade.color.look import scene

    colors = np.clip(rng.random((120, 160, 3)).cumsum(axis=1) / 80 % 1.0, 0, 1) \
        .astype(np.float32)
    expected = scene._scene_image(colors)
    expected_mirror = scene._mirrored(expected)
    scene.prepare_photo_scene(colors)
    photo = scene.scene_image(colors)
    mirror = scene.mirrored(photo)
    for got, want in ((photo, expected), (mirror, expected_mirror)):
        assert np.array_equal(got.colors, want.colors)
        assert np.array_equal(got.points, want.points)
        assert np.array_equal(got.descriptors, want.descriptors)
    assert not scene._AHEAD and not scene._MIRRORS  # each taken once
    scene.prepare_photo_scene(colors)
    assert scene.scene_image(colors.copy()) is not None and scene._AHEAD  # not this array
    scene.forget_photo_scene(colors)
    assert not scene._AHEAD and not scene._MIRRORS
    bad = np.zeros(5, np.float32)  # not an image: scene_image raises
    scene.prepare_photo_scene(bad)
    try:
        scene.scene_image(bad)
    except Exception as exc:  # noqa: BLE001 - whatever computing it raises
        kind = type(exc)
    else:  # pragma: no cover
        raise AssertionError("a 1-D array was prepared")
    try:
        scene._scene_image(bad)
    except Exception as exc:  # noqa: BLE001
        assert type(exc) is kind
    assert not scene._AHEAD


@pytest.mark.slow
def test_a_command_refused_while_its_photo_is_read_ahead_exits_with_its_error(tmp_path):
    """A large photo is still being decoded when the plan refuses the command (its output
    exists): one line, exit 1, no abort (a daemon thread inside OpenImageIO when the
    interpreter ends aborted the process: exit 134)."""
    import os
    import subprocess
    import sys

    import cv2

    rng = np.random.default_rng(0)
    photo = tmp_path / "large.jpg"
    noise = rng.integers(0, 256, (3000, 4000, 3), dtype=np.uint8)
    cv2.imwrite(str(photo), cv2.GaussianBlur(noise, (0, 0), 3))
    (tmp_path / "out.jpg").write_bytes(b"taken")
    env = {**os.environ, "WBCGRADE_CACHE_DIR": str(tmp_path / "cache")}
    for _ in range(3):
        done = subprocess.run([sys.executable, "-m", "wbcgrade", "apply", str(photo),
                               "--style", str(SAMPLES), "-o", str(tmp_path / "out.jpg")],
                              capture_output=True, text=True, env=env)
        assert done.returncode == 1, done.stderr[-2000:]
        assert done.stderr.strip().splitlines() == [
            f"Error: {tmp_path / 'out.jpg'}: file exists (use --overwrite to replace it)"]
    assert (tmp_path / "out.jpg").read_bytes() == b"taken"


def test_a_photos_keypoints_are_kept_in_the_cache_and_found_again(rng, tmp_path,
                                                                  monkeypatch):
    """The photo's keypoints and its mirror's, prepared ahead, are kept in the cache
    (``scenes/``, keyed by the file, the spaces and the matching settings): graded again,
    the photo gets exactly what preparing them gives, without preparing them; a damaged
    entry, or one of another size, is prepared again."""
    from wbcgrade.color.io import cache
    from wbcgrade.color.look import scene

    monkeypatch.setattr(cache, "_COMMAND", {"folder": str(tmp_path / "cache")})
    photo = small_copy(SAMPLES / "bridge.jpg", tmp_path / "bridge.jpg", width=900)
    colors = read_image(photo).pixels[..., :3].copy()
    entry = scene.photo_scene_entry(photo, None, "sRGB")
    assert entry is not None and entry != scene.photo_scene_entry(photo, "sRGB", "sRGB")
    expected = scene._scene_image(colors)
    expected_mirror = scene._mirrored(expected)

    def prepared() -> tuple:
        scene.prepare_photo_scene(colors, entry)
        found = scene.scene_image(colors)
        return found, scene.mirrored(found)

    computed = []
    real = scene._scene_image
    monkeypatch.setattr(scene, "_scene_image",
                        lambda *args, **kwargs: computed.append(1) or real(*args, **kwargs))
    for damage in (None, b"not an archive"):
        if damage is not None:
            entry.write_bytes(damage)
        computed.clear()
        first = prepared()
        assert computed and entry.is_file()  # prepared, then kept
        computed.clear()
        again = prepared()
        assert not computed  # read back
        for got in (first, again):
            for image, want in zip(got, (expected, expected_mirror)):
                assert np.array_equal(image.colors, want.colors)
                assert np.array_equal(image.points, want.points)
                assert np.array_equal(image.descriptors, want.descriptors)
    computed.clear()
    smaller = colors[:200, :300].copy()  # another photo at that key: prepared again
    scene.prepare_photo_scene(smaller, entry)
    assert scene.scene_image(smaller).colors.shape[:2] == (200, 300) and computed
    scene.forget_photo_scene(smaller)


def test_style_photos_prepared_ahead_are_waited_for_and_found(tmp_path, style_dir,
                                                             monkeypatch):
    """``keep_style_scenes`` reads the style photos' scene images on another thread; the
    grade's ``style_scene_images`` waits for it and gets the same images, prepared once."""
    from wbcgrade.color.io import cache
    from wbcgrade.color.look import scene
    from wbcgrade.color.presets import load_style_folder

    monkeypatch.setattr(cache, "_COMMAND", {"folder": str(tmp_path / "cache")})
    monkeypatch.setattr(scene, "_IN_MEMORY", {})
    styles = load_style_folder(style_dir, 8)
    prepared = []
    real = scene._scene_image
    monkeypatch.setattr(scene, "_scene_image",
                        lambda *args, **kwargs: prepared.append(1) or real(*args, **kwargs))
    assert scene.keep_style_scenes(styles) and scene._STYLES_AHEAD
    images = scene.style_scene_images(styles)
    assert not scene._STYLES_AHEAD and len(prepared) == len(styles.names)  # once each
    again = scene.style_scene_images(styles)
    assert len(prepared) == len(styles.names)
    for a, b in zip(images, again):
        assert a is b  # kept in this process
    assert not scene.keep_style_scenes(type(styles)(styles.names, styles.histograms))


def test_a_read_ahead_the_grade_does_not_use_keeps_nothing(tmp_path):
    """A read-ahead of other spaces than the grade's is discarded: the photo is read again
    and what the read-ahead prepared for matching is not kept."""
    from wbcgrade.color.look import scene

    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "coffee.jpg")
    ahead = read_ahead.ReadAhead(photo, None, "acescct", match_scenes=True)
    ahead.proceed()
    ahead.result()
    assert ahead.scene_started and scene._AHEAD
    ahead.discard()
    assert not scene._AHEAD
    unused = read_ahead.ReadAhead(photo, None, None, match_scenes=True)
    unused.discard()  # (before the keypoints were started: never started)
    assert not unused.scene_started and not scene._AHEAD
