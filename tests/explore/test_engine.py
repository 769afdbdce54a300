"""The engine: the preview follows the exact map, the command line reproduces the settings."""

from __future__ import annotations

import shlex

import numpy as np
import pytest

from tests.color.conftest import SAMPLES, small_copy
from tests.explore.conftest import PRESET
from wbcgrade.color.mapping.remap import apply_color_map
from wbcgrade.explore.engine import ExactGrader, load_session
from wbcgrade.explore.settings import settings_from_json


@pytest.mark.slow
def test_preview_near_a_known_exact_map_follows_the_exact_grade(server):
    """Corrected by the exact map at w0, the preview at w1 is closer to the exact map at w1
    than both the uncorrected preview and the exact map at w0 (the nearest one known)."""
    session = server.studio.session
    grader = ExactGrader(session.grader_state())
    w0 = settings_from_json({"weights": [0.5, 0.2, 0.3]}, 3)
    w1 = settings_from_json({"weights": [0.4, 0.25, 0.35]}, 3)
    reference = grader.reference(w0)
    exact1 = grader.color_map(w1)
    picture = session.preview / np.float32(255)

    def error(lut):  # mean difference on the preview picture, in 1/255
        return float(np.abs(apply_color_map(picture, lut) - apply_color_map(picture, exact1))
                     .mean() * 255)

    fast = session.fast_map(w1)
    corrected = error(session.preview_lut(fast, reference["offset"]))
    assert corrected < 1.0  # measured 0.70 at this L1 distance (0.2)
    assert corrected < error(session.preview_lut(fast, None))
    assert corrected < error(reference["exact"])
    # the page's instant step: the exact map at w0 plus the fast map's slopes times the move
    slopes = grader.slopes(w0)
    assert slopes.shape == (3, 33, 33, 33, 3)
    move = np.subtract(w1.weights, w0.weights)
    extrapolated = np.clip(reference["exact"] + np.tensordot(move, slopes, 1), 0, 1)
    assert error(extrapolated) < min(1.5, error(reference["exact"]))
    # at w0 itself the preview is the exact map (the fast map is the same, solved afresh)
    at_w0 = session.preview_lut(session.fast_map(w0), reference["offset"])
    assert np.abs(at_w0 - reference["exact"]).max() < 1e-6


def test_command_line_quotes_paths_and_names_every_setting(tmp_path):
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "my coffee's.png", width=64)
    session = load_session(str(photo), preset=PRESET)
    settings = settings_from_json({"weights": [0.5, 0.25, 0.25], "strength": 0.75,
                                   "relaxation": 0.5, "keep_lightness": True}, 3)
    args = shlex.split(session.command_line(settings))
    assert args == ["wbcgrade", "apply", str(photo), "--preset", PRESET, "--mode", "palette",
                    "--weights", "0.5,0.25,0.25", "--no-regrain", "--strength", "0.75",
                    "--relax", "0.5", "--preserve-luminance"]
    plain = settings_from_json({"weights": [1, 0, 0]}, 3)
    assert shlex.split(session.command_line(plain))[-3:] == ["--weights", "1,0,0",
                                                             "--no-regrain"]


@pytest.mark.slow  # over 4 s of the fast tier: the whole suite runs it
def test_a_session_on_a_style_folder_decodes_each_style_photo_for_its_look_once(
        tmp_path, monkeypatch):
    """The explorer opens on apply's look grade: its scene matching reads the style photos
    prepared from the decode their histograms came from (as ``apply`` does), not again."""
    import wbcgrade.color.io.images as imageio
    import wbcgrade.color.look.scene as scene
    import wbcgrade.color.presets as presets

    styles = tmp_path / "styles"
    styles.mkdir()
    for name in ("aitzgorri", "coffee", "flower", "seeding"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", width=120)
    photo = small_copy(SAMPLES / "sunset.jpg", tmp_path / "sunset.jpg", width=96)
    reads: list[str] = []
    real = imageio.read_image

    def counting(path):
        reads.append(str(path))
        return real(path)

    monkeypatch.setenv("WBCGRADE_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(imageio, "read_image", counting)
    monkeypatch.setattr(presets, "read_image", counting)
    monkeypatch.setattr(scene, "_IN_MEMORY", {})
    session = load_session(str(photo), style_dir=str(styles))
    before = [r for r in reads if "styles" in r]
    session.look_grade()
    assert [r for r in reads if "styles" in r] == before  # no style decoded for the scene
