"""``apply`` decodes the photo on another thread while its styles load (and their scene
images are read): the same grade, the same errors."""

from __future__ import annotations

import threading

import numpy as np

import wbcgrade.photos.workflow as workflow
from tests.color.conftest import SAMPLES, small_copy
from wbcgrade.color.io.images import read_image
from wbcgrade.errors import InputError


def test_a_read_ahead_gives_the_photo_or_raises_what_reading_raised(tmp_path):
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "coffee.jpg")
    ahead = workflow._ReadAhead(photo)
    assert np.array_equal(ahead.image().pixels, read_image(photo).pixels)
    broken = tmp_path / "broken.jpg"
    broken.write_bytes(photo.read_bytes()[:200])
    try:
        workflow._ReadAhead(broken).image()
    except InputError as exc:
        expected = str(exc)
    else:  # pragma: no cover - the truncated file must be refused
        raise AssertionError("a truncated JPEG was read")
    try:
        read_image(broken)
    except InputError as exc:
        assert str(exc) == expected


def test_apply_decodes_the_photo_while_the_styles_load(tmp_path, style_dir, monkeypatch, cli):
    """The photo is decoded on the read-ahead thread, started before the styles load, and
    the style photos are prepared for matching before the grade asks for them."""
    photo = small_copy(SAMPLES / "sunset.jpg", tmp_path / "sunset.jpg")
    events: list[tuple[str, str]] = []
    reading, loading = workflow.read_image, workflow.load_styles

    def read(path):
        events.append(("read", threading.current_thread().name))
        return reading(path)

    def load(*args, **kwargs):
        events.append(("styles", threading.current_thread().name))
        return loading(*args, **kwargs)

    kept = []
    monkeypatch.setattr(workflow, "read_image", read)
    monkeypatch.setattr(workflow, "load_styles", load)
    monkeypatch.setattr(workflow, "keep_style_scenes", lambda styles: kept.append(styles))
    result = cli("apply", str(photo), "--style", str(style_dir), "-o",
                 str(tmp_path / "out.jpg"))
    assert result.exit_code == 0, result.output
    assert ("read", "wbcgrade-read") in events and ("styles", "MainThread") in events
    assert len(kept) == 1 and kept[0].files  # the style photos, prepared ahead
