"""Looks: a known look applied to synthetic scenes is found again (wbcgrade.color.look)."""

from pathlib import Path

import numpy as np
import pytest

from wbcgrade.color.histogram import image_histogram
from wbcgrade.color.look import (
    LookMap,
    extract_look,
    fit_look_map,
    fit_pair,
    look_reliability,
    photo_look,
    relaxed_correspondences,
    set_look_base,
)

LUMA = np.array([0.2126, 0.7152, 0.0722])
SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def warm_look(rgb):
    """An ASC CDL grade followed by saturation: warm, lifted blacks, less saturated."""
    out = np.clip(rgb * [1.08, 1.0, 0.86] + [0.03, 0.01, 0.0], 0.0, None) ** [0.95, 1.0, 1.08]
    luma = (out @ LUMA)[..., None]
    return np.clip(luma + 0.85 * (out - luma), 0.0, 1.0)


def scene(seed, size=48, regions=5):
    """A synthetic photo: vertical bands of colours around two of its own, grain, a gradient."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0.15, 0.85, (2, 3))  # the scene's character, shared by its framings
    colors = np.clip(centres[np.arange(regions) % 2] + rng.normal(0, 0.07, (regions, 3)), 0, 1)
    labels = np.broadcast_to(np.arange(size) * regions // size, (size, size))
    image = colors[labels] * np.linspace(0.85, 1.1, size)[:, None, None]
    return np.clip(image + rng.normal(0, 0.02, image.shape), 0.0, 1.0)


def halves(image):
    """Left and right 62 % framings of an image."""
    width = image.shape[1]
    k = int(round(0.62 * width))
    return image[:, :k], image[:, width - k:]


def error(look, truth, image):
    return float(np.mean(np.abs(look(image) - truth(image))))


def test_the_map_family_holds_a_cdl_grade_with_saturation():
    rng = np.random.default_rng(0)
    colors = rng.random((4000, 3))
    fitted = fit_look_map(colors, warm_look(colors), np.ones(len(colors)), ridge=1e-6,
                          smoothness=1e-6)
    assert np.mean(np.abs(fitted(colors) - warm_look(colors))) < 0.01
    assert LookMap.identity().amplitude() == 0.0
    assert fitted.lattice(5).shape == (5, 5, 5, 3)


def test_a_pair_of_framings_of_one_scene_gives_back_the_look():
    image = scene(1)
    left, right = halves(image)
    photo, style = image_histogram(right, 32), image_histogram(warm_look(left), 32)
    pair = fit_pair(photo, style)
    identity = error(LookMap.identity(), warm_look, right)
    assert error(pair.look, warm_look, right) < 0.35 * identity


@pytest.mark.slow
def test_extraction_finds_the_look_when_the_content_model_holds_the_scenes():
    contents = [scene(s) for s in range(10, 16)]
    others = [scene(s) for s in range(20, 24)]
    styles = {b: np.stack([image_histogram(warm_look(c), b) for c in contents]) for b in (16, 32)}
    naturals = {b: np.stack([image_histogram(c, b) for c in contents + others]) for b in (16, 32)}
    # the fitted content is right here (the naturals hold the very scenes): used as fitted
    result = extract_look(styles, naturals, shrink=False, content_shrink=0.0)
    test = scene(99)
    identity = error(LookMap.identity(), warm_look, test)
    assert error(result.look, warm_look, test) < 0.75 * identity
    # shrunk where the styles' own maps disagree: a smaller move, still towards the look
    shrunk = extract_look(styles, naturals, content_shrink=0.0)
    assert shrunk.look.amplitude() < result.look.amplitude()
    assert error(shrunk.look, warm_look, test) < 0.85 * identity
    # the contents pulled towards the average natural palette (the default): the look
    # also takes what the contents explained, still towards the look here
    pulled = extract_look(styles, naturals)
    assert np.allclose(pulled.weights.sum(axis=1), 1.0)
    assert pulled.weights.min() >= 0.6 / len(naturals[16]) - 1e-12
    assert error(pulled.look, warm_look, test) < 0.85 * identity
    # each style's content is found among the natural palettes: its own scene weighs most
    assert np.sum(np.argmax(result.weights, axis=1) == np.arange(6)) >= 4


def cool_look(rgb):
    """The opposite cast: blue, green-cyan mids, a little more colour."""
    out = np.clip(rgb * [0.86, 1.0, 1.1] + [0.0, 0.01, 0.03], 0.0, 1.0)
    luma = (out @ LUMA)[..., None]
    return np.clip(luma + 1.1 * (out - luma), 0.0, 1.0)


def test_reliability_is_the_agreement_of_the_halves_stepped_up_to_the_set():
    rng = np.random.default_rng(3)
    colors = rng.random((500, 3))
    warm = fit_look_map(colors, warm_look(colors), np.ones(500), ridge=1e-6, smoothness=1e-6)
    cool = fit_look_map(colors, cool_look(colors), np.ones(500), ridge=1e-6, smoothness=1e-6)
    assert look_reliability(warm, warm, colors) == pytest.approx(1.0)
    assert look_reliability(warm, cool, colors) == 0.0  # opposite casts: nothing agreed
    assert look_reliability(warm, LookMap.identity(), colors) == 0.0  # one half moves nothing
    # part of the displacement shared: cosine r, stepped up to 2 r / (1 + r)
    other = LookMap(warm.coefficients + 0.8 * cool.coefficients, warm.knots)
    a, b = warm(colors) - colors, other(colors) - colors
    r = np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b))
    assert 0.1 < r < 0.9
    assert look_reliability(warm, other, colors) == pytest.approx(2 * r / (1 + r))


#: Colours of everyday scenes (sky, foliage, skin, grey, white, shadow, wood, haze).
EVERYDAY = np.array([[0.45, 0.6, 0.85], [0.3, 0.45, 0.2], [0.8, 0.6, 0.5], [0.5, 0.5, 0.5],
                     [0.9, 0.9, 0.88], [0.15, 0.12, 0.1], [0.6, 0.45, 0.3], [0.7, 0.75, 0.8]])


def everyday_scene(seed, size=48):
    """A synthetic photo whose colours come from one shared prior, as natural photos' do:
    four bands of four of the :data:`EVERYDAY` colours, a gradient, grain."""
    rng = np.random.default_rng(seed)
    colors = np.clip(EVERYDAY[rng.choice(len(EVERYDAY), 4, replace=False)]
                     + rng.normal(0, 0.05, (4, 3)), 0, 1)
    cuts = np.sort(rng.choice(np.arange(4, size - 4), 3, replace=False))
    labels = np.broadcast_to(np.searchsorted(cuts, np.arange(size), side="right"), (size, size))
    image = colors[labels] * np.linspace(0.8, 1.1, size)[:, None, None]
    return np.clip(image + rng.normal(0, 0.02, image.shape), 0.0, 1.0)


@pytest.mark.slow
def test_a_look_every_style_shows_is_applied_and_one_the_styles_disagree_on_is_not(
        monkeypatch):
    """The transport extraction (the statistics one: tests/color/test_look_statistics.py,
    on photos with more colours than these four-band scenes)."""
    from wbcgrade.color.look import set_extraction as look

    monkeypatch.setattr(look, "SET_LOOK_METHOD", "transport")

    contents = [everyday_scene(s) for s in range(10, 14)]
    naturals = style_set([everyday_scene(s) for s in range(40, 50)])  # other scenes
    test = everyday_scene(99)
    photo_hist = image_histogram(test, 32)
    def graded(rgb):  # the warm grade twice: a look clearly larger than content's noise
        return warm_look(warm_look(rgb))

    identity = error(LookMap.identity(), graded, test)
    shared = style_set([graded(c) for c in contents])
    base, extracted, strength = set_look_base(shared, naturals, photo_hist=photo_hist)
    assert error(base, graded, test) < 0.6 * identity
    # ungraded photos: what content alone makes of a look is hardly applied
    ungraded = style_set(contents)
    plain = set_look_base(ungraded, naturals, photo_hist=photo_hist)[0]
    assert plain.amplitude() < 0.5 * base.amplitude()
    # styles 0 and 2 warm, 1 and 3 cool: the styles disagree, the look is hardly applied
    mixed = style_set([(warm_look if i % 2 == 0 else cool_look)(c)
                       for i, c in enumerate(contents)])
    split = set_look_base(mixed, naturals, photo_hist=photo_hist)[0]
    assert split.amplitude() < 0.35 * base.amplitude()
    # a fixed strength is taken as it is
    assert set_look_base(mixed, naturals, 0.5)[2] == 0.5


def sample(name, width=96):
    """A shipped sample photo, small: (H, W, 3) sRGB in [0, 1]."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(SAMPLES / f"{name}.jpg"))
    spec = buf.spec()
    height = max(1, round(spec.height * width / spec.width))
    small = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, width, 0, height, 0, 1, 0, 3))
    return np.asarray(small.get_pixels(oiio.FLOAT))[..., :3].astype(np.float64)


@pytest.mark.slow
def test_the_photo_is_matched_with_its_own_scene_and_weighs_most():
    images = [sample(n) for n in ("aitzgorri", "astronaut", "chelsea", "coffee", "flower")]
    styles = np.stack([image_histogram(warm_look(halves(i)[0]), 32) for i in images])
    for index, image in enumerate(images):
        found = photo_look(image_histogram(halves(image)[1], 32), styles)
        assert found.match == index
        assert np.argmax(found.weights) == index
        assert found.confidence > 0.0


@pytest.mark.slow
def test_a_colour_the_photo_lacks_stays_out_of_the_grade():
    image = scene(41, regions=8)
    left, right = halves(image)
    styled = warm_look(left).copy()
    yellow = np.array([0.95, 0.85, 0.05])
    styled[: styled.shape[0] // 4] = yellow  # a quarter of the style is a yellow the photo lacks
    photo, style = image_histogram(right, 32), image_histogram(styled, 32)

    def share_sent_to_yellow(relaxation):
        projection, _ = relaxed_correspondences(photo, style, 1.0, relaxation)
        return photo[np.linalg.norm(projection - yellow, axis=-1) < 0.2].sum()

    relaxed, balanced = share_sent_to_yellow(0.01), share_sent_to_yellow(100.0)
    assert balanced > 0.1  # balanced transport forces the yellow onto the photo
    assert relaxed < 0.3 * balanced
    graded = fit_pair(photo, style).look(right).reshape(-1, 3)
    truth = warm_look(right).reshape(-1, 3)
    # no photo colour is pulled towards the yellow further than the look itself takes it
    pulled = np.linalg.norm(truth - yellow, axis=1) - np.linalg.norm(graded - yellow, axis=1)
    assert np.quantile(pulled, 0.99) < 0.05


@pytest.mark.slow
def test_look_mode_and_look_extract_through_the_commands(tmp_path, cli):
    """``apply --mode look`` takes the grade path's "look" map builder; ``look extract``
    writes the set's look as a LUT and, like every command, refuses an existing file."""
    import json

    from tests.color.conftest import small_copy
    from wbcgrade.color.mapping.lut import read_cube

    # a preset of palettes only (no look of its own): the look is extracted
    palettes = str(Path(__file__).resolve().parents[1] / "data" / "three_samples.npz")
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "c.jpg", 64)
    result = cli("apply", str(photo), "--preset", palettes, "-o",
                 str(tmp_path / "o.png"), "--json", "--no-cache")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["map"]["builder"] == "look" and report["fit_start"] == "look"
    assert report["outcome"]["source"] == "set-look" and "weights" not in report
    lut = tmp_path / "look.cube"
    args = ["look", "extract", "--preset", palettes, "-o", str(lut), "--lut-size", "9"]
    assert cli(*args).exit_code == 0
    assert read_cube(lut).size == 9
    result = cli(*args)
    assert result.exit_code == 1 and "file exists (use --overwrite" in result.output


def test_shrinking_keeps_what_the_styles_agree_on_and_drops_what_they_do_not():
    from wbcgrade.color.look.set_extraction import _shrunk

    rng = np.random.default_rng(3)
    colors = rng.random((3000, 3))
    warm = fit_look_map(colors, warm_look(colors), np.ones(len(colors)), ridge=1e-6)
    agreeing = _shrunk(warm, [warm, warm, warm])
    assert np.mean(np.abs(agreeing(colors) - warm(colors))) < 0.003
    cool = LookMap(-warm.coefficients, warm.knots)  # the opposite move
    pooled = LookMap(0.2 * warm.coefficients, warm.knots)  # their pool leans one way a little
    torn = _shrunk(pooled, [warm, cool, warm, cool])
    assert torn.amplitude() < 0.25 * pooled.amplitude()  # (0.2^2 / (0.2^2 + 1/4) = 0.14)


def test_a_preset_made_with_a_known_look_grades_with_that_look(tmp_path, cli):
    """The shipped presets carry the look they were made with: the look grade applies it as
    it is (no estimate), `look extract` writes it, and a preset with a broken look is refused."""
    import OpenImageIO as oiio

    from tests.color.conftest import small_copy
    from wbcgrade.color.mapping.lut import read_cube
    from wbcgrade.color.mapping.remap import interpolate_lattice, resample_lattice
    from wbcgrade.color.presets import load_preset, resolve_preset, save_preset
    from wbcgrade.errors import InputError

    styles = load_preset(resolve_preset("warm"))
    look = styles.meta["look"]
    assert look.shape == (33, 33, 33, 3)
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "c.png", 96)
    out = tmp_path / "o.png"
    result = cli("apply", str(photo), "--preset", "warm", "--no-regrain",
                 "-o", str(out))
    assert result.exit_code == 0, result.output
    pixels = oiio.ImageBuf(str(photo)).get_pixels(oiio.FLOAT)[..., :3].reshape(-1, 3)
    graded = oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)[..., :3].reshape(-1, 3)
    expected = interpolate_lattice(look.astype(np.float64), pixels.astype(np.float64))
    assert np.abs(graded - expected).max() <= 1.5 / 255
    assert np.abs(graded - pixels).mean() > 5 / 255  # and the look is not a small one
    cube = tmp_path / "look.cube"
    assert cli("look", "extract", "--preset", "warm", "--strength", "1",
               "-o", str(cube)).exit_code == 0
    assert np.abs(read_cube(cube).table - resample_lattice(look, 33)).max() < 1e-4
    broken = look.copy()
    broken[0, 0, 0, 0] = np.nan
    with pytest.raises(InputError, match="finite"):
        save_preset(tmp_path / "bad.npz", styles, look=broken)


def style_set(images, cache_dir=None):
    """A StyleSet of the images' 32^3 histograms, cached in ``cache_dir`` (None: not)."""
    from wbcgrade.color.presets import StyleSet

    return StyleSet([f"s{i}" for i in range(len(images))],
                    np.stack([image_histogram(i, 32) for i in images]),
                    meta={"cache_dir": None if cache_dir is None else str(cache_dir)})

def test_a_set_look_cached_under_other_settings_is_not_reused(tmp_path, monkeypatch):
    """The disk cache is keyed by the extraction's settings as well as the histograms."""
    from wbcgrade.color.look import set_extraction as look

    styles = style_set([warm_look(everyday_scene(s)) for s in range(10, 12)], tmp_path)
    naturals = style_set([everyday_scene(s) for s in range(40, 44)], tmp_path)
    def looks():  # the cached set looks (the natural palettes' statistics are kept there too)
        return [p for p in (tmp_path / "looks").glob("*.npz")
                if "coefficients" in np.load(p).files]

    first = look.set_look(styles, naturals)
    assert len(looks()) == 1
    monkeypatch.setattr(look, "_SET_LOOKS", {})  # a new process: only the disk cache is left
    assert look.set_look(styles, naturals).info == first.info  # read back from disk
    monkeypatch.setattr(look, "_SET_LOOKS", {})
    from wbcgrade.color.look import statistics as look_statistics

    monkeypatch.setattr(look_statistics, "CONTENT_BIAS", 0.0)
    look.set_look(styles, naturals)
    assert len(looks()) == 2  # a second look: not the first one read back under others


def test_a_set_look_and_the_natural_statistics_are_read_back_from_disk(tmp_path, monkeypatch):
    """A new process reads the set's look and the natural palettes' statistics from the
    disk cache instead of computing them again (both hold NaN by design: a look's unknown
    losses, an empty lightness band's statistics; they were rebuilt on every run)."""
    from wbcgrade.color.look import set_extraction as look
    from wbcgrade.color.look import statistics as look_statistics

    styles = style_set([warm_look(everyday_scene(s)) for s in range(10, 12)], tmp_path)
    naturals = style_set([everyday_scene(s) for s in range(40, 44)], tmp_path)
    monkeypatch.setattr(look, "_SET_LOOKS", {})  # a process that computes and writes them
    monkeypatch.setattr(look, "_NATURAL_STATISTICS", {})
    first = look.set_look(styles, naturals)
    monkeypatch.setattr(look, "_SET_LOOKS", {})  # a new process: only the disk cache is left
    monkeypatch.setattr(look, "_NATURAL_STATISTICS", {})

    def computed(*args, **kwargs):
        raise AssertionError("computed again instead of read from the cache")

    monkeypatch.setattr(look, "statistics_set_look", computed)
    monkeypatch.setattr(look_statistics, "palette_statistics", computed)
    again = look.set_look(styles, naturals)
    assert np.array_equal(again.look.coefficients, first.look.coefficients)
    assert look.natural_statistics(naturals, styles) is not None


@pytest.mark.slow
def test_a_set_and_its_halves_share_one_barycenter_of_the_natural_palettes(monkeypatch):
    """The naturals' barycenter (the default content) is computed once, not per extraction."""
    from wbcgrade.color.look import set_extraction as look

    sizes = []
    real = look.barycenter

    def counted(histograms, *args, **kwargs):
        sizes.append(len(histograms))
        return real(histograms, *args, **kwargs)

    monkeypatch.setattr(look, "barycenter", counted)
    monkeypatch.setattr(look, "SET_LOOK_METHOD", "transport")  # the one that takes it
    monkeypatch.setattr(look, "_SET_LOOKS", {})
    monkeypatch.setattr(look, "_AVERAGE_CONTENTS", {}, raising=False)
    styles = style_set([warm_look(everyday_scene(s)) for s in range(10, 14)])
    naturals = style_set([everyday_scene(s) for s in range(40, 45)])
    whole = look.set_look(styles, naturals, cache=False)
    assert look.set_look_halves(styles, naturals) is not None
    assert sizes.count(len(naturals.names)) == 1  # three extractions, one barycenter
    monkeypatch.setattr(look, "_SET_LOOKS", {})
    assert look.set_look(styles, naturals, cache=False).info == whole.info
    assert sizes.count(len(naturals.names)) == 1
