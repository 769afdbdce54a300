"""The photo's own scene among the style photos (wbcgrade.color.look.scene): found, and its look
read off the overlap; photos of other scenes are not matched."""

from pathlib import Path

import numpy as np
import pytest

from tests.color.test_look import halves, sample, warm_look
from wbcgrade.color.look import find_scene_look, fit_scene_look
from wbcgrade.color.look.scene import match_scene, scene_image

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
NAMES = ("aitzgorri", "coffee", "flower", "seeding", "sunset")


@pytest.fixture(scope="module")
def photos():
    return {name: sample(name, 480) for name in NAMES}


def error(mapped, truth):
    return float(np.mean(np.abs(mapped - truth)))


@pytest.mark.slow
def test_two_framings_of_a_scene_match_and_other_scenes_do_not(photos):
    prepared = {n: scene_image(warm_look(halves(p)[0]).astype(np.float32))
                for n, p in photos.items()}
    for name, image in photos.items():
        right = scene_image(halves(image)[1].astype(np.float32))
        own = match_scene(right, prepared[name])
        assert own is not None and own.inliers >= 24, name
        # the left framing lies left of the right one: the homography shifts it rightwards
        assert own.homography[0, 2] / own.homography[2, 2] < 0
        assert 0.2 < own.coverage < 0.8
        others = [match_scene(right, prepared[n]) for n in photos if n != name]
        assert all(m is None for m in others), name


@pytest.mark.slow
def test_the_look_read_off_the_overlap_is_the_look(photos):
    image = photos["aitzgorri"]
    left, right = halves(image)
    styles = [scene_image(warm_look(halves(photos[n])[0]).astype(np.float32)) for n in NAMES]
    found = fit_scene_look(scene_image(right.astype(np.float32)), styles)
    assert found is not None
    assert list(found.matches) == [NAMES.index("aitzgorri")]
    assert found.confidence == 1.0 and found.residual < 0.02
    truth = warm_look(right)
    # recovered on the whole right framing, its unseen part included
    assert error(found.look(right), truth) < 0.15 * error(right, truth)


@pytest.mark.slow
def test_dark_and_flipped_framings_find_their_scene_and_its_look(photos):
    """A framing shot two and a half stops darker (the keypoints are found on ranked
    lightness: a tone curve does not change them), or flipped left to right (matched on
    the mirrored photo when nothing matches as it is), still finds its scene; the look
    read off the flipped overlap is the look."""
    styles = [scene_image(warm_look(halves(photos[n])[0]).astype(np.float32)) for n in NAMES]
    for name in ("aitzgorri", "sunset"):
        right = halves(photos[name])[1]
        dark = scene_image((0.18 * right).astype(np.float32))
        assert match_scene(dark, styles[NAMES.index(name)]) is not None, name
        flipped = np.ascontiguousarray(right[:, ::-1])
        assert match_scene(scene_image(flipped.astype(np.float32)),
                           styles[NAMES.index(name)]) is None  # not as it is
        found = fit_scene_look(scene_image(flipped.astype(np.float32)), styles)
        assert found is not None and list(found.matches) == [NAMES.index(name)], name
        truth = warm_look(flipped)
        assert error(found.look(flipped), truth) < 0.25 * error(flipped, truth), name


def test_no_scene_without_a_match_and_none_from_palettes_alone(photos):
    from wbcgrade.color.histogram import image_histogram
    from wbcgrade.color.presets import StyleSet

    others = [warm_look(photos[n]) for n in ("seeding", "coffee")]
    with_images = StyleSet(["seeding", "coffee"],
                           np.stack([image_histogram(o, 16) for o in others]),
                           meta={"images": [o.astype(np.float32) for o in others]})
    why = {}
    assert find_scene_look(photos["sunset"].astype(np.float32), with_images, why=why) is None
    # each style's reason, in words (--json's look.no_scene)
    assert set(why) == {"seeding", "coffee"}
    assert all("needed" in reason or "framing" in reason for reason in why.values()), why
    palettes_only = StyleSet(["seeding", "coffee"], with_images.histograms)
    assert find_scene_look(photos["coffee"].astype(np.float32), palettes_only) is None


@pytest.mark.slow
def test_apply_in_look_mode_finds_the_scene_in_a_style_folder(tmp_path, photos, monkeypatch, cli):
    """``apply --mode look --style DIR``: the folder's graded framing of the photo's scene
    gives the look; the grade lands close to the truth and the report names the scene."""
    import json

    import OpenImageIO as oiio


    monkeypatch.setenv("WBCGRADE_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    styles = tmp_path / "styles"
    styles.mkdir()

    def write(path, rgb):
        buf = oiio.ImageBuf(oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, oiio.UINT8))
        buf.set_pixels(oiio.ROI(), np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8))
        assert buf.write(str(path)), buf.geterror()

    for name in ("seeding", "coffee", "sunset"):
        write(styles / f"{name}.png", warm_look(halves(photos[name])[0]))
    right = halves(photos["coffee"])[1]
    write(tmp_path / "photo.png", right)
    out = tmp_path / "out.png"
    result = cli("apply", str(tmp_path / "photo.png"), "--style",
                 str(styles), "--mode", "look", "-o", str(out), "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["fit_start"] == "scene"
    assert report["outcome"]["source"] == "own-scene"
    assert report["outcome"]["match"] == "coffee" and "weights" not in report
    graded = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[..., :3]
    truth = np.round(warm_look(right) * 255) / 255
    assert error(graded, truth) < 0.25 * error(right, truth)
    # a second run reads the style images (and the photo's own keypoints) back from the
    # cache folder and agrees
    cached = list((tmp_path / "cache" / "scenes").glob("*.npz"))
    assert len(cached) == 4  # the three style photos' and the photo's
    again = tmp_path / "again.png"
    result = cli("apply", str(tmp_path / "photo.png"), "--style",
                 str(styles), "--mode", "look", "-o", str(again))
    assert result.exit_code == 0, result.output
    assert np.abs(oiio.ImageBuf(str(again)).get_pixels(oiio.FLOAT)[..., :3]
                  - graded).max() <= 1.5 / 255  # the cache keeps colours in half floats
    # --no-cache reads the photos and writes no cache
    result = cli("apply", str(tmp_path / "photo.png"), "--style",
                 str(styles), "--mode", "look", "-o",
                 str(tmp_path / "uncached.png"), "--no-cache",
                 "--cache-dir", str(tmp_path / "other"))
    assert result.exit_code == 0, result.output
    assert not (tmp_path / "other").exists()



def test_the_lattice_correction_holds_what_the_curves_cannot():
    """A cross-channel move (green follows red times blue) is beyond curves of R, G, B and
    luma; the smooth lattice fitted after them takes most of the rest."""
    from wbcgrade.color.look import SceneLook, fit_correction, fit_look_map

    rng = np.random.default_rng(5)
    colors = rng.random((20000, 3))

    def look(rgb):
        out = rgb.copy()
        out[:, 1] += 0.25 * (rgb[:, 0] * rgb[:, 2] - 0.25)
        return np.clip(out, 0.0, 1.0)

    targets, ones = look(colors), np.ones(len(colors))
    curves = fit_look_map(colors, targets, ones, ridge=1e-6, smoothness=1e-6)
    mapped = curves(colors)
    correction = fit_correction(mapped, targets, ones)
    test = rng.random((2000, 3))
    both = SceneLook(curves, {}, 1.0, 0.0, len(colors), correction)
    alone = float(np.mean(np.abs(curves(test) - look(test))))
    assert float(np.mean(np.abs(both(test) - look(test)))) < 0.5 * alone
    assert correction.shape == (9, 9, 9, 3)


def _8bit(image: np.ndarray) -> np.ndarray:
    return (np.rint(np.clip(image, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)


@pytest.mark.slow
def test_an_8bit_dark_framing_with_a_lifted_black_finds_its_scene(photos):
    """A framing over four stops under, through a look that lifts the black and flattens
    the tones, saved in 8 bits: a dozen grey levels, whose steps make keypoints that match
    nothing unless the lightness is smoothed and equalised locally (stretched alone,
    aitzgorri's framings agreed on no keypoints). Its scene is found from an
    under-exposed other framing; other scenes still are not."""
    def dark_look(rgb):  # lifted black, flat
        return 0.25 + 0.3 * rgb

    styles = {n: scene_image(_8bit(dark_look(_8bit(0.04 * halves(p)[0]))))
              for n, p in photos.items()}
    for name in NAMES:
        right = scene_image(_8bit(0.18 * halves(photos[name])[1]))
        own = match_scene(right, styles[name])
        assert own is not None and own.inliers >= 20, name
        assert all(match_scene(right, styles[n]) is None for n in NAMES if n != name), name


def test_nearest_two_is_opencvs_brute_force_match_ties_included():
    """The matcher's two nearest descriptors and distances are OpenCV's ``knnMatch``'s,
    bit for bit: SIFT-like whole numbers (with exact ties, lower index first), and other
    values through OpenCV; rows whose squared distances pass 2^21 (float32 roots of
    neighbouring whole numbers may be equal there) mixed with nearer ones."""
    import cv2

    from wbcgrade.color.look.scene import nearest_two

    rng = np.random.default_rng(3)
    query = rng.integers(0, 200, (90, 128)).astype(np.float32)
    train = np.concatenate([query[:20], rng.integers(0, 3, (70, 128)), query[:20]]
                           ).astype(np.float32)
    far = np.concatenate([np.full((5, 128), 255.0), query[:5]]).astype(np.float32)
    for q in (query, query + 0.25, rng.integers(0, 3, (40, 128)).astype(np.float32), far):
        pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(q, train, k=2)
        distance, nearest = nearest_two(q, train)
        assert np.array_equal(nearest, [[p[0].trainIdx, p[1].trainIdx] for p in pairs])
        assert np.array_equal(distance, np.float32([[p[0].distance, p[1].distance]
                                                    for p in pairs]))
