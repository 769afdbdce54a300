"""The look mode and the saves: the page's look is the grade `apply` gives and says so,
the presets it switches to are theirs, a saved photo is `apply`'s at full size in the
save folder under a new name, and a bad request changes nothing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.explore.test_server import api, error_of, request
from wbcgrade.color.io.images import read_image
from wbcgrade.color.mapping.lut import read_cube
from wbcgrade.color.mapping.remap import apply_color_map, identity_map

LUT_BYTES = 33 ** 3 * 3 * 4


def _state(server, query=""):
    status, _, body = request(server, "GET", f"/{server.token}/api/state{query}")
    assert status == 200, body
    return json.loads(body)


def test_the_look_is_apply_s_grade_and_says_what_it_is(server):
    session = server.studio.session
    grade = session.look_grade()
    status, headers, body = api(server, "look", {"strength": 0.5})
    assert status == 200 and len(body) == LUT_BYTES
    lut = np.frombuffer(body, dtype="<f4").reshape(33, 33, 33, 3)
    assert np.array_equal(lut, grade.color_map)  # the page blends it at the strength itself
    meta = json.loads(headers["X-Explore-Meta"])
    assert meta["command"].endswith("--preset " + session.preset + " --mode look --no-regrain "
                                    "--strength 0.5")
    stated = meta["grade"]
    assert stated["source"] == grade.outcome.source.value
    assert stated["blend"] == 0.5
    assert stated["strength"] == pytest.approx(0.5 * grade.outcome.strength, abs=1e-4)
    assert stated["words"].startswith(grade.outcome.source.describe(3))
    # the state holds the same, at strength 1, and the picker's entries
    state = _state(server)
    assert state["look"]["grade"]["source"] == stated["source"]
    assert state["look"]["grade"]["strength"] == pytest.approx(grade.outcome.strength, abs=1e-4)
    labels = [choice["label"] for choice in state["sources"]]
    assert labels[0].startswith("preset ") and "preset warm" in labels


def test_a_shipped_preset_s_look_is_its_own(server):
    state = _state(server)
    index = [c["label"] for c in state["sources"]].index("preset warm")
    status, headers, body = api(server, "look", {"source": index})
    assert status == 200
    assert json.loads(headers["X-Explore-Meta"])["grade"]["source"] == "preset-look"
    lut = np.frombuffer(body, dtype="<f4").reshape(33, 33, 33, 3)
    warm = server.studio.source(index).session.look_grade()
    assert np.array_equal(lut, warm.color_map)
    assert np.abs(lut - identity_map(33)).mean() > 0.005  # a look, not the identity
    # its thumbnails and palette state are its own
    assert request(server, "GET", f"/{server.token}/style/5.png?source={index}")[0] == 200
    assert request(server, "GET", f"/{server.token}/style/5.png")[0] == 404  # three styles


@pytest.mark.parametrize("body, message", [
    ({"strength": 2.5}, "strength must be between 0 and 2"),
    ({"strength": "1"}, "strength must be a number"),
    ({"strength": 1, "weights": [1, 0, 0]}, "unknown setting 'weights'"),
    ({"source": 99}, "source must be a number from 0 to"),
    ({"source": "0"}, "source must be a number from 0 to"),
    ({"mode": "film"}, "mode must be one of look, palette"),
])
def test_bad_look_requests_get_a_json_error(server, body, message, save_dir):
    before = sorted(save_dir.iterdir())
    for route in ("look", "save"):
        status, _, payload = api(server, route, {"mode": "look", **body}
                                 if route == "save" else body)
        assert status == 400 and message in error_of(payload), (route, payload)
    assert sorted(save_dir.iterdir()) == before
    assert api(server, "look", {})[0] == 200


@pytest.mark.slow
def test_a_save_is_apply_s_photo_under_a_new_name_in_the_save_folder(server, photo, save_dir):
    stem = photo.stem
    taken = save_dir / f"{stem}_explore_1.png"
    taken.write_bytes(b"someone else's")  # never replaced
    beside = sorted(photo.parent.iterdir())
    status, _, body = api(server, "save", {"mode": "look", "strength": 0.75})
    assert status == 200, body
    saved = json.loads(body)
    assert saved["file"] == f"{stem}_explore_2.png" and saved["folder"] == str(save_dir)
    assert saved["command"].endswith("--strength 0.75")
    assert taken.read_bytes() == b"someone else's"
    assert sorted(photo.parent.iterdir()) == beside  # nothing beside the photo
    graded = read_image(save_dir / saved["file"]).pixels[:, :, :3]
    original = read_image(photo).pixels[:, :, :3]
    grade = server.studio.session.look_grade()
    expected = apply_color_map(original, grade.color_map, 0.75)
    assert graded.shape == original.shape
    assert np.abs(graded - expected).max() <= 1 / 255 + 1e-6
    # the next save takes the next name; the export holds the same grade
    status, _, body = api(server, "save", {"mode": "look", "strength": 0.75})
    assert json.loads(body)["file"] == f"{stem}_explore_3.png"
    status, headers, body = api(server, "export", {"mode": "look", "strength": 0.75,
                                                    "format": "cube", "size": 33})
    assert status == 200
    lut_file = save_dir.parent / "look.cube"
    lut_file.write_bytes(body)
    through = apply_color_map(original, read_cube(lut_file).table.astype(np.float32))
    assert np.abs(graded - through).max() <= 1 / 255 + 1e-6


@pytest.mark.slow
def test_a_palette_save_is_the_exact_mix_shown(server, photo, save_dir):
    weights = [0.2, 0.5, 0.3]
    status, _, body = api(server, "save", {"mode": "palette", "weights": weights,
                                           "strength": 1})
    assert status == 200, body
    saved = json.loads(body)
    assert "--mode palette --weights 0.2,0.5,0.3 --no-regrain" in saved["command"]
    studio = server.studio
    exact = studio.worker.reference(studio.fitted.__class__(tuple(weights))).exact
    graded = read_image(save_dir / saved["file"]).pixels[:, :, :3]
    expected = apply_color_map(read_image(photo).pixels[:, :, :3], exact)
    assert np.abs(graded - expected).max() <= 1 / 255 + 1e-6


@pytest.mark.slow
def test_a_blend_of_two_looks_is_their_mix_and_its_save_carries_its_grade(server, save_dir,
                                                                          photo):
    state = _state(server)
    warm = [c["label"] for c in state["sources"]].index("preset warm")
    body = {"strength": 0.5, "blend": {"source": warm, "amount": 0.25}}
    status, headers, payload = api(server, "look", body)
    assert status == 200, payload
    lut = np.frombuffer(payload, dtype="<f4").reshape(33, 33, 33, 3)
    first = server.studio.session.look_grade().color_map
    second = server.studio.source(warm).session.look_grade().color_map
    assert np.abs(lut - (0.75 * first + 0.25 * second)).max() < 1e-6
    meta = json.loads(headers["X-Explore-Meta"])
    assert meta["grade"]["source"] == "blend" and meta["command"] is None
    assert "75 % preset" in meta["grade"]["words"] and "25 % preset warm" in meta["grade"]["words"]
    status, _, payload = api(server, "save", {"mode": "look", **body})
    assert status == 200, payload
    saved = json.loads(payload)
    grade_file = save_dir / saved["grade_file"]
    assert grade_file.name == saved["file"].rsplit(".", 1)[0] + ".grade.json"
    assert saved["command"].endswith(f"--look {grade_file} --no-regrain")
    from wbcgrade.color.grade.saved_grade import load_look

    look = load_look(grade_file)
    assert look.strength == 0.5 and np.abs(look.color_map - lut).max() < 1e-4
    graded = read_image(save_dir / saved["file"]).pixels[:, :, :3]
    expected = apply_color_map(read_image(photo).pixels[:, :, :3], lut, 0.5)
    assert np.abs(graded - expected).max() <= 1 / 255 + 1e-6


@pytest.mark.parametrize("blend, message", [
    ({"source": 1}, "blend must be null or"),
    ({"source": 1, "amount": 1.5}, "amount must be between 0 and 1"),
    ({"source": -1, "amount": 0.5}, "picker entry's number"),
    ({"source": 999, "amount": 0.5}, "source must be a number from 0 to"),
    ("warm", "blend must be null or"),
])
def test_bad_blends_are_refused(server, blend, message):
    status, _, payload = api(server, "look", {"blend": blend})
    assert status == 400 and message in error_of(payload)
