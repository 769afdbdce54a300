"""The regrain that follows the map where it lowers contrast (``regrain_map(follow=True)``):
grain flattened with a flattening look, never amplified by a contrasty one, the map's
contrast kept on real structure; the look grades use it, the palette mode does not."""

from __future__ import annotations

import json

import numpy as np
import pytest

import wbcgrade.color.mapping.regrain as regrain_module
from wbcgrade.color.mapping.regrain import map_gain_prior, regrain_map
from wbcgrade.color.mapping.remap import apply_color_map, identity_map

EPS = 0.04  # the default regulariser: grain (sd 0.01) is far under it


def _linear_map(gain: float, size: int = 17) -> np.ndarray:
    """Every channel through ``0.5 + gain (x - 0.5)``."""
    return (0.5 + gain * (identity_map(size) - 0.5)).astype(np.float32)


def _grain(rng, shape=(96, 128), sd=0.01) -> np.ndarray:
    """Mid grey with independent grain in each channel."""
    return np.clip(0.5 + sd * rng.standard_normal((*shape, 3)), 0.0, 1.0).astype(np.float32)


def _detail_sd(image: np.ndarray) -> float:
    return float(np.std(image - image.mean(axis=(0, 1))))


def test_the_prior_is_the_maps_gain_cut_at_one():
    identity = map_gain_prior(identity_map(9))
    np.testing.assert_allclose(identity, 0.0, atol=1e-5)
    half = map_gain_prior(_linear_map(0.5, 9)).reshape(9, 9, 9, 3, 3)
    np.testing.assert_allclose(half, np.broadcast_to(-0.5 * np.eye(3), half.shape), atol=1e-5)
    steep = map_gain_prior(_linear_map(2.0, 9))  # raised contrast: detail kept as it is
    np.testing.assert_allclose(steep, 0.0, atol=1e-5)
    # at half strength the halving map is 0.75 x: the prior follows the blend
    blended = map_gain_prior(_linear_map(0.5, 9), strength=0.5).reshape(9, 9, 9, 3, 3)
    np.testing.assert_allclose(blended, np.broadcast_to(-0.25 * np.eye(3), blended.shape),
                               atol=1e-5)


def test_desaturation_flattens_colour_grain_and_keeps_grey_grain():
    """A map that halves chroma about the grey axis: the prior contracts the two chroma
    directions by half and keeps the grey one (singular directions, not channels)."""
    grid = identity_map(9).astype(np.float64)
    grey = grid.mean(axis=-1, keepdims=True)
    prior = map_gain_prior((grey + 0.5 * (grid - grey)).astype(np.float32)).reshape(9, 9, 9, 3, 3)
    jacobian = np.swapaxes(prior[4, 4, 4], 0, 1) + np.eye(3)  # [out, in]
    np.testing.assert_allclose(jacobian @ np.ones(3), np.ones(3), atol=1e-4)
    chroma = np.array([1.0, -1.0, 0.0])
    np.testing.assert_allclose(jacobian @ chroma, 0.5 * chroma, atol=1e-4)


@pytest.mark.parametrize("max_pixels", [10 ** 6, 3000])  # solved at full size / subsampled
def test_grain_follows_a_flattening_map_and_is_never_amplified(rng, monkeypatch, max_pixels):
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", max_pixels)
    image = _grain(rng)
    before = _detail_sd(image)
    flat = _linear_map(0.5)
    # the plain regrain keeps the grain at the input's amplitude, the look's halves it
    kept = _detail_sd(regrain_map(image, flat, 1.0, 0.05, EPS))
    followed = _detail_sd(regrain_map(image, flat, 1.0, 0.05, EPS, follow=True))
    assert kept == pytest.approx(before, rel=0.1)
    assert followed == pytest.approx(0.5 * before, rel=0.12)
    # half way: the grain between the two (a scene matched with confidence 0.5)
    halfway = _detail_sd(regrain_map(image, flat, 1.0, 0.05, EPS, follow=0.5))
    assert halfway == pytest.approx(0.75 * before, rel=0.12)
    # a map that doubles contrast does not double the grain, followed or not
    steep = _linear_map(2.0)
    for follow in (False, True):
        assert _detail_sd(regrain_map(image, steep, 1.0, 0.05, EPS, follow=follow)) \
            == pytest.approx(before, rel=0.1)


def test_structure_takes_the_maps_contrast_either_way(rng):
    """Edges (variance far above eps) follow the map with or without the prior."""
    y, x = np.mgrid[0:96, 0:128]
    image = np.repeat((0.2 + 0.6 * (((x // 16) + (y // 16)) % 2))[..., None], 3, axis=2)
    image = image.astype(np.float32)
    flat = _linear_map(0.5)
    mapped = apply_color_map(image, flat)
    for follow in (False, True):
        out = regrain_map(image, flat, 1.0, 0.01, EPS, follow=follow)
        assert np.mean(np.abs(out - mapped)) < 0.02


def test_opencv_and_numpy_solves_agree_with_a_prior(rng):
    guide = rng.random((37, 53, 3)).astype(np.float32)
    change = (0.3 * guide[..., ::-1] ** 2 - 0.1).astype(np.float32)
    prior = (rng.random((37, 53, 9)).astype(np.float32) - 0.5)
    fast = regrain_module._window_models_numpy(guide, change, 3, 0.01, prior,
                                               regrain_module._uniform_filter_cv2)
    plain = regrain_module._window_models_numpy(guide, change, 3, 0.01, prior)
    np.testing.assert_allclose(plain, fast, rtol=0, atol=5e-5)
    # and the prior moves the solution (eps A0 added to the cross-covariance)
    assert np.abs(fast - regrain_module._window_models_numpy(guide, change, 3, 0.01)).max() > 1e-3


def test_look_grades_follow_the_palette_mode_does_not_and_saved_grades_keep_it(tmp_path):
    from wbcgrade.color.grade.grading import Grade
    from wbcgrade.color.grade.saved_grade import look_dict, look_from_dict

    grade = Grade(("warm",), np.ones(1), _linear_map(0.5, 5), working="w",
                  regrain=(0.01, EPS), regrain_follow=0.75)
    entry = json.loads(json.dumps(look_dict(grade)))
    assert look_from_dict(entry).regrain_follow == 0.75
    del entry["regrain_follow"]  # a grade saved before it: grain kept as it was
    assert look_from_dict(entry).regrain_follow == 0.0
    from wbcgrade.errors import InputError
    for wrong in ("yes", True, 1.5, -0.1, None):
        entry["regrain_follow"] = wrong
        with pytest.raises(InputError, match="regrain_follow"):
            look_from_dict(entry)


@pytest.mark.slow
def test_known_looks_follow_set_looks_and_the_palette_mode_do_not():
    from pathlib import Path

    from wbcgrade.color.grade.grading import grade_array
    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.presets import load_preset

    preset = Path(__file__).resolve().parents[2] / "wbcgrade" / "color" / "presets_data"
    styles = load_preset(str(preset / "faded.npz"))
    photo = _grain(np.random.default_rng(0), (48, 64))
    _, look = grade_array(photo, styles, GradeOptions())
    _, palette = grade_array(photo, styles, GradeOptions(mode="palette"))
    assert look.regrain_follow == 1.0 and palette.regrain_follow == 0.0
    # a set's look read from statistics (no photo of this scene among the styles): its
    # slopes are a guess, the grain is kept as it is
    from tests.color.test_look import sample
    from wbcgrade.color.histogram import image_histogram
    from wbcgrade.color.presets import StyleSet

    images = [sample(name, 64) for name in ("coffee", "flower", "seeding", "sunset")]
    folder = StyleSet([f"s{i}" for i in range(4)],
                      np.stack([image_histogram(im.astype(np.float32), 16) for im in images]),
                      meta={"images": [im.astype(np.float32) for im in images]})
    _, set_look = grade_array(sample("aitzgorri", 64).astype(np.float32), folder,
                              GradeOptions())
    assert set_look.regrain_follow == 0.0
    # the photo's own scene among the styles: the look read off it is followed
    from tests.color.test_look import halves, warm_look

    scene = sample("aitzgorri", 480)
    left, right = halves(scene)
    matched = StyleSet(["left"], image_histogram(warm_look(left).astype(np.float32), 16)[None],
                       meta={"images": [warm_look(left).astype(np.float32)]})
    _, from_scene = grade_array(right.astype(np.float32), matched, GradeOptions())
    confidence = from_scene.info["look"]["confidence"]
    assert 0 < confidence <= 1 and from_scene.regrain_follow == pytest.approx(confidence)


@pytest.mark.parametrize("max_pixels", [10 ** 6, 3000])
def test_following_writes_in_place_and_into_out_as_a_new_array(rng, monkeypatch, max_pixels):
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", max_pixels)
    image = _grain(rng, (40, 56), sd=0.05)
    flat = _linear_map(0.6)
    expected = regrain_map(image, flat, 0.9, 0.05, EPS, follow=True)
    out = np.empty_like(image)
    assert regrain_map(image, flat, 0.9, 0.05, EPS, out=out, follow=True) is out
    np.testing.assert_array_equal(out, expected)
    in_place = image.copy()
    assert regrain_map(in_place, flat, 0.9, 0.05, EPS, out=in_place, follow=True) is in_place
    np.testing.assert_array_equal(in_place, expected)


def test_a_map_with_nan_is_refused_plainly():
    broken = _linear_map(0.5, 5)
    broken[2, 2, 2, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        map_gain_prior(broken)
    with pytest.raises(ValueError, match="follow"):
        regrain_map(_grain(np.random.default_rng(1), (8, 8)), _linear_map(0.5, 5), follow=2.0)
