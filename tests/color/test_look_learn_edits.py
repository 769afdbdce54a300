"""Edited photos without their original (``look learn``, ``apply --originals``):
evidence of the look beside the before/after pairs (wbcgrade.color.look.learn)."""

import numpy as np
import pytest
from click.testing import CliRunner

from tests.color.test_look import LUMA, sample
from tests.color.test_look_learn import write
from wbcgrade.color.grade.look_files import learned_grade
from wbcgrade.color.look.learn import match_files, pair_files

NAMES = ("aitzgorri", "astronaut", "bridge", "chelsea", "coffee", "flower", "seeding",
         "sunset")
HELD = ("astronaut", "aitzgorri")


@pytest.fixture(scope="module")
def photos():
    return {name: sample(name, 200) for name in NAMES}


def bleach(rgb):
    """A strong look: most of the colour gone, more contrast."""
    luma = (rgb @ LUMA)[..., None]
    return np.clip(0.5 + 1.3 * (luma + 0.35 * (rgb - luma) - 0.5), 0.0, 1.0)


def shoot(root, photos, look, pair="bridge", alone=True, original_look=None):
    """ORIGINALS with one photo, EDITS with its edit and (``alone``) both halves of every
    other photo but the held-out ones, edited by ``look``."""
    before, after = root / "originals", root / "edits"
    before.mkdir()
    after.mkdir()
    write(before / f"{pair}.jpg", photos[pair])
    write(after / f"{pair}.png", (original_look or look)(photos[pair]))
    for name in NAMES:
        if alone and name not in HELD and name != pair:
            half = photos[name].shape[1] // 2
            write(after / f"{name}_left.png", look(photos[name][:, :half]))
            write(after / f"{name}_right.png", look(photos[name][:, half:]))
    return before, after


def error(grade, look, photo):
    """Mean |graded - truth| on a photo nothing showed, relative to doing nothing."""
    graded = grade.apply(photo.astype(np.float32))
    truth = look(photo)
    return float(np.mean(np.abs(graded - truth)) / np.mean(np.abs(photo - truth)))


def test_edits_without_an_original_are_matched_apart_and_still_named_by_pair_files(tmp_path):
    before, after = tmp_path / "b", tmp_path / "a"
    before.mkdir()
    after.mkdir()
    for name in ("IMG_1.jpg", "IMG_2.jpg"):
        (before / name).write_bytes(b"x")
    for name in ("IMG_1-edit.png", "IMG_3.png", "IMG_4.tif"):
        (after / name).write_bytes(b"x")
    found = match_files(before, after)
    assert [p.name for p in found.pairs] == ["IMG_1"]
    assert [p.name for p in found.edits_alone] == ["IMG_3.png", "IMG_4.tif"]
    assert [name for name, _ in found.problems] == ["IMG_2"]  # an original with no edit
    pairs, problems = pair_files(before, after)  # the pairs only: the others are problems
    assert [p.name for p in pairs] == ["IMG_1"]
    assert sorted(name for name, _ in problems) == ["IMG_2", "IMG_3", "IMG_4"]


@pytest.mark.slow
def test_edits_without_originals_correct_the_look_where_the_pair_shows_little(
        tmp_path, photos, monkeypatch):
    """One pair (a sunset: warm colours only) says little of what a strong look does to
    blues and greys; ten edited photos without originals say more, and never less. (The
    pair's look extrapolated with the raw editor's controls: with film curves the pair
    alone already comes within 6 % of the truth here, and the correction is measured
    where there is more to correct.)"""
    import wbcgrade.color.look.learn as learn
    from wbcgrade.color.look.edits import FamilyChoice

    monkeypatch.setattr(learn, "choose_family", lambda *args: FamilyChoice("edit"))
    before, after = shoot(tmp_path, photos, bleach, pair="sunset")
    with_edits, result = learned_grade(before, after)
    assert len(result.used) == 1 and len(result.edits_alone) == 10
    assert result.describe() == ("the look learned from 1 before/after pair and 10 edited "
                                 "photos without an original")
    alone_dir = tmp_path / "alone"
    alone_dir.mkdir()
    only_pair = shoot(alone_dir, photos, bleach, pair="sunset", alone=False)
    pair_only, _ = learned_grade(*only_pair)
    ratios = [error(with_edits, bleach, photos[name]) / error(pair_only, bleach, photos[name])
              for name in HELD]
    # (0.855 and 0.999: with the pair's colours weighed by how rare they are, the
    # sunset's look alone is closer and leaves the edits less to correct)
    assert min(ratios) < 0.9 and max(ratios) < 1.05
    # where the pair shows its colours, the pair decides
    pair = photos["sunset"].astype(np.float32)
    assert np.mean(np.abs(with_edits.apply(pair) - pair_only.apply(pair))) < 0.01
    assert learn.PAIR_SUPPORT > 0


@pytest.mark.slow
def test_a_pair_and_edits_with_no_look_learn_a_look_that_changes_nothing(tmp_path, photos):
    def same(rgb):
        return rgb

    from colour import XYZ_to_Lab, delta_E, sRGB_to_XYZ

    def lab(rgb):
        return XYZ_to_Lab(sRGB_to_XYZ(np.clip(rgb, 0.0, 1.0)))

    grade, result = learned_grade(*shoot(tmp_path, photos, same))
    assert len(result.edits_alone) == 10
    for name in HELD:
        photo = photos[name].astype(np.float32)
        moved = np.mean(delta_E(lab(photo), lab(grade.apply(photo)), method="CIE 2000"))
        # (0.73 and 0.88 dE2000 here, 0.72 and 0.83 before the edits chose how far the
        # pair's look is followed: they raised it 0.02 -> 0.24 on a 1.5-nat preference,
        # what the JPEG's errors are worth; the pair alone, a JPEG original against a PNG edit,
        # 0.51 and 0.62: its colours weighed by how rare they are, the JPEG's errors on
        # edges count more (0.38 and 0.50 by pixel count). With the edits' look fitted
        # as a smooth map on the cube, 0.98 and 0.76: it lifted black to blue. Real
        # photos with no look move 0.02: benchmarks/one_original.py --no-look)
        assert moved < 0.9
    black = grade.apply(np.zeros((4, 4, 3), np.float32))
    assert np.max(np.abs(black)) < 0.005  # (0.023 of blue with the smooth map)


@pytest.mark.slow
def test_black_and_white_stays_so_only_when_every_edit_is(tmp_path, photos):
    def grey(rgb):
        return np.repeat((rgb @ LUMA)[..., None], 3, axis=-1)

    grade, result = learned_grade(*shoot(tmp_path, photos, grey))
    assert result.look.monochrome
    out = grade.apply(photos["astronaut"].astype(np.float32))
    assert np.max(np.ptp(out, axis=-1)) < 1e-5
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    _, result = learned_grade(*shoot(mixed, photos, bleach, original_look=grey))
    assert not result.look.monochrome  # edits in colour beside a black-and-white pair


@pytest.mark.slow
def test_apply_with_originals_is_look_learn_then_apply_look(tmp_path, photos):
    import OpenImageIO as oiio

    from wbcgrade.cli import main

    originals, edits = shoot(tmp_path, photos, bleach)
    photo = write(tmp_path / "photo.png", photos["astronaut"])
    runner = CliRunner()
    learned = runner.invoke(main, ["apply", str(photo), "--style", str(edits), "--originals",
                                   str(originals), "-o", str(tmp_path / "learned.png")])
    assert learned.exit_code == 0, learned.output
    assert "the look learned from 1 before/after pair and 10 edited photos" in learned.output
    assert "of the way away from the pairs' colours" in learned.output  # (how far it carries)
    steps = runner.invoke(main, ["look", "learn", str(originals), str(edits), "-o",
                                 str(tmp_path / "look.cube")])
    assert steps.exit_code == 0, steps.output
    assert "10 edited photos without an original" in steps.output
    assert "away from the pairs' colours the look is followed" in steps.output
    # how sure the look is, region by region: the same words from either command
    sure = [line.strip() for line in steps.output.splitlines()
            if line.strip().startswith("how much of each kind of colour the pairs show")]
    assert len(sure) == 1 and "skies and water" in sure[0]
    assert f"learned look: {sure[0]}" in learned.output
    # which original would teach more (a bridge shows 0.41 of natural colours): the same
    asked = [line.strip() for line in steps.output.splitlines()
             if "would teach the look more" in line]
    assert len(asked) == 1 and f"learned look: {asked[0]}" in learned.output
    saved = runner.invoke(main, ["apply", str(photo), "--look", str(tmp_path / "look.cube"),
                                 "-o", str(tmp_path / "saved.png")])
    assert saved.exit_code == 0, saved.output
    a, b = (oiio.ImageBuf(str(tmp_path / f"{n}.png")).get_pixels(oiio.UINT8).astype(int)
            for n in ("learned", "saved"))
    assert np.max(np.abs(a - b)) <= 1
    # the grade is the look: the photo moves a good part of the way to the truth
    truth = np.round(bleach(photos["astronaut"]) * 255)
    before = np.round(photos["astronaut"] * 255)
    assert np.mean(np.abs(a - truth)) < 0.6 * np.mean(np.abs(before - truth))


def test_the_original_to_add_is_the_one_that_widens_what_the_pairs_show():
    """A pair of blues alone: of an edited photo of more blues, one of greens and one of
    every colour, the last is named, with the share the pooled colours cover; a pair
    that already shows every colour is asked nothing."""
    from wbcgrade.color.colorspace import default_working_space
    from wbcgrade.color.look import learn as learned

    working = default_working_space()
    rng = np.random.default_rng(5)
    blues = np.clip(rng.normal([0.2, 0.3, 0.7], 0.05, (3000, 3)), 0.0, 1.0)
    greens = np.clip(rng.normal([0.3, 0.6, 0.2], 0.05, (40, 40, 3)), 0.0, 1.0)
    everything = rng.uniform(0.0, 1.0, (40, 40, 3))
    more_blues = np.clip(rng.normal([0.2, 0.3, 0.7], 0.05, (40, 40, 3)), 0.0, 1.0)
    weights = np.full(len(blues), 1.0 / len(blues))
    edits = [("IMG_1", more_blues), ("IMG_2", greens), ("IMG_3", everything)]
    add = learned.teaching_original(blues, weights, edits, working)
    assert add is not None and add["name"] == "IMG_3"
    flat = everything.reshape(-1, 3)
    pooled = learned._support(np.concatenate([blues, flat]), np.concatenate(
        [weights, np.full(len(flat), 1.0 / len(flat))]))
    assert np.isclose(add["with_it"], learned._covered(pooled, working))
    assert add["with_it"] >= add["now"] + learned.ADVICE_GAIN
    broad = flat
    assert learned.teaching_original(broad, np.full(len(broad), 1.0 / len(broad)), edits,
                                     working) is None


@pytest.mark.slow
def test_the_learned_look_names_the_original_that_would_teach_it_most(tmp_path, photos,
                                                                      monkeypatch):
    """One pair of a coffee cup (about half of what natural photos hold) beside edited
    photos without originals: the report names the edited photo whose original would
    widen what the pairs show most, judged from its edited colours, and it is the one
    whose real original does; the command says it in words (and --json as
    ``original_to_add``, as apply's report does with the grade's source)."""
    import json

    import wbcgrade.color.look.learn as learn
    from wbcgrade.cli import main
    from wbcgrade.color.colorspace import default_working_space

    skills = []  # (what learn_look hands the trust: the family's skill within the pair)
    supported = learn.supported_look

    def recording(look, sources, weights, working, skill=None):
        skills.append(skill)
        return supported(look, sources, weights, working, skill)

    monkeypatch.setattr(learn, "supported_look", recording)
    originals, edits = shoot(tmp_path, photos, bleach, pair="coffee")
    grade, result = learned_grade(originals, edits)
    # (bleach carried within the espresso: skill 0.99, so it is followed fully)
    assert skills and all(s is not None and s > 0.9 for s in skills)
    assert result.far_trust["by_pairs"] == 1.0
    monkeypatch.undo()
    advice = result.original_to_add
    assert advice is not None and advice["with_it"] >= advice["now"] + learn.ADVICE_GAIN
    working = default_working_space()
    coffee = photos["coffee"].reshape(-1, 3).astype(np.float64)
    truly = {}  # the share the pair pooled with each real original (a half photo) covers
    for path in edits.iterdir():
        if path.stem != "coffee":
            name, side = path.stem.rsplit("_", 1)
            half = photos[name].shape[1] // 2
            part = photos[name][:, :half] if side == "left" else photos[name][:, half:]
            part = part.reshape(-1, 3).astype(np.float64)
            pooled = learn._support(np.concatenate([coffee, part]), np.concatenate(
                [np.full(len(coffee), 1.0 / len(coffee)), np.full(len(part), 1.0 / len(part))]))
            truly[path.stem] = learn._covered(pooled, working)
    assert max(truly, key=truly.get) == advice["name"]
    assert abs(truly[advice["name"]] - advice["with_it"]) < 0.1
    runner = CliRunner()
    said = runner.invoke(main, ["look", "learn", str(originals), str(edits), "-o",
                                str(tmp_path / "look.cube")])
    assert said.exit_code == 0, said.output
    assert f"the original of {advice['name']} would teach the look more" in said.output
    assert json.loads(json.dumps(result.as_dict()))["original_to_add"]["name"] == advice["name"]
    # (apply --originals --json reports it with the grade's source)
    assert grade.info["saved_look"]["original_to_add"]["name"] == advice["name"]
    # a pair that shows as much as the others could add is not asked to grow
    (tmp_path / "broad").mkdir()
    _, broad = learned_grade(*shoot(tmp_path / "broad", photos, bleach, pair="sunset"))
    assert broad.original_to_add is None


def test_originals_need_style_photos_and_no_saved_look(tmp_path):
    from wbcgrade.cli import main

    photo = write(tmp_path / "p.png", np.full((8, 8, 3), 0.5))
    folder = tmp_path / "o"
    folder.mkdir()
    runner = CliRunner()
    for extra in ([], ["--preset", "warm"], ["--look", str(photo)],
                  ["--style", str(folder), "--mode", "palette"]):
        result = runner.invoke(main, ["apply", str(photo), "--originals", str(folder), *extra])
        assert result.exit_code == 2 and "--originals" in result.output, (extra, result.output)
        assert "Traceback" not in result.output


@pytest.mark.slow
def test_the_learned_look_says_which_colours_the_pairs_show(tmp_path, photos):
    """A pair of a coffee cup (browns, reds, whites) shows skin-like and red colours, not
    skies or foliage; the report says so per region of colour."""
    _, result = learned_grade(*shoot(tmp_path, photos, bleach, pair="coffee", alone=False))
    cover = result.coverage
    assert set(cover) >= {"skin", "skies and water", "foliage", "greys"}
    assert all(0.0 <= v <= 1.0 for v in cover.values())
    assert cover["skin"] > 0.5 > cover["skies and water"]
    assert cover["skin"] > cover["foliage"]
    assert result.as_dict()["pairs_cover"]["skin"] == pytest.approx(cover["skin"], abs=1e-3)


def test_an_edit_fitted_to_a_few_colours_moves_the_others_as_the_edit_does():
    """The colours of one photo (warm, dark) say how an edit moves them; the fitted edit
    moves colours the photo does not hold (skies, greens) much as the edit does."""
    from wbcgrade.color.histogram import grid_points
    from wbcgrade.color.look.edits import Edit, fit_edit

    edit = Edit(contrast=0.4, saturation=0.6, balance=(0.04, 0.0, -0.05),
                shadow_tint=(-0.03, 0.0, 0.04))
    rng = np.random.default_rng(0)
    seen = np.clip(rng.normal((0.45, 0.3, 0.2), 0.12, (3000, 3)), 0.0, 1.0)
    fitted = fit_edit(seen, edit(seen), np.ones(len(seen)))
    assert np.mean(np.abs(fitted(seen) - edit(seen))) < 0.01
    others = grid_points(9)
    unseen = others[np.linalg.norm(others - (0.45, 0.3, 0.2), axis=1) > 0.4]
    moved = np.mean(np.abs(edit(unseen) - unseen))
    assert np.mean(np.abs(fitted(unseen) - edit(unseen))) < 0.5 * moved
    # no edit in the colours: none fitted
    assert np.allclose(fit_edit(seen, seen, np.ones(len(seen)))(others), others, atol=2e-3)


def test_one_pair_reaches_the_colours_it_does_not_show_through_the_edit_it_explains(
        tmp_path, photos):
    """One pair (a sunset's warm colours) learns a look that moves other photos' colours
    (a blue bridge, a green field) towards the look, better than a fit without the edit."""
    import wbcgrade.color.look.learn as learn

    before, after = shoot(tmp_path, photos, bleach, pair="sunset", alone=False)
    grade, result = learned_grade(before, after)
    assert len(result.used) == 1
    errors = [error(grade, bleach, photos[name]) for name in HELD]
    old = learn.EDIT_PRIOR_PAIRS
    learn.EDIT_PRIOR_PAIRS = 0
    try:
        again = tmp_path / "again"
        again.mkdir()
        plain, _ = learned_grade(*shoot(again, photos, bleach, pair="sunset", alone=False))
    finally:
        learn.EDIT_PRIOR_PAIRS = old
    assert np.mean(errors) < 0.8 * np.mean([error(plain, bleach, photos[n]) for n in HELD])


def _film_curves():
    """A film-like look: cross-talk, less colour, a different S-curve per channel."""
    from wbcgrade.color.look.edits import CurvesEdit

    knots = np.linspace(0.0, 1.0, 9)
    curves = np.stack([knots + 0.08 * np.sin(np.pi * knots) ** 2 * np.sign(0.5 - knots),
                       knots + 0.03 * np.sin(np.pi * knots),
                       0.04 + 0.9 * knots])
    mix = np.array([[0.9, 0.1, 0.0], [0.05, 0.9, 0.05], [0.0, 0.1, 0.9]])
    return CurvesEdit(mix, 0.75, curves)


def test_film_curves_fitted_to_one_photo_move_the_colours_it_does_not_show():
    """A warm photo with shadows to highlights teaches each channel's curve over its whole
    range: the fitted curves move blues and greens (absent from the photo) much as the
    look does, and nearer than the raw editor's controls fitted to the same colours."""
    from wbcgrade.color.histogram import grid_points
    from wbcgrade.color.look.edits import fit_curves_edit, fit_edit

    look = _film_curves()
    rng = np.random.default_rng(1)
    luma = rng.uniform(0.02, 0.98, 3000)
    seen = np.clip(luma[:, None] * np.array([1.15, 0.95, 0.75])
                   + rng.normal(0.0, 0.04, (3000, 3)), 0.0, 1.0)
    fitted = fit_curves_edit(seen, look(seen), np.ones(len(seen)))
    assert np.mean(np.abs(fitted(seen) - look(seen))) < 0.01
    nodes = grid_points(9)
    unseen = nodes[(nodes[:, 2] > nodes[:, 0] + 0.2) | (nodes[:, 1] > nodes[:, 0] + 0.3)]
    moved = np.mean(np.abs(look(unseen) - unseen))
    error = np.mean(np.abs(fitted(unseen) - look(unseen)))
    assert error < 0.5 * moved
    assert error < np.mean(np.abs(fit_edit(seen, look(seen), np.ones(len(seen)))(unseen)
                                  - look(unseen)))
    # no look in the colours: none fitted
    assert np.allclose(fit_curves_edit(seen, seen, np.ones(len(seen)))(nodes), nodes,
                       atol=2e-3)


def test_the_family_that_extrapolates_is_chosen_within_the_pairs_and_never_from_blacks(
        photos):
    """A sunset (shadows to highlights) under a strong look chooses the film curves, and
    they carry the look to a bridge and a field it does not show better than the raw
    editor's controls; a near-black photo (nothing above its blacks to learn a curve
    from) keeps the controls, whatever it shows."""
    from wbcgrade.color.look.edits import extrapolating_family, fit_curves_edit, fit_edit

    sunset = photos["sunset"].reshape(-1, 3).astype(np.float64)
    ones = np.ones(len(sunset))
    assert extrapolating_family(sunset, bleach(sunset), ones) == "curves"
    others = np.concatenate([photos[n].reshape(-1, 3) for n in HELD]).astype(np.float64)
    errors = [np.mean(np.abs(fit(sunset, bleach(sunset), ones)(others) - bleach(others)))
              for fit in (fit_curves_edit, fit_edit)]
    assert errors[0] < errors[1]
    look = _film_curves()
    rng = np.random.default_rng(2)
    dark = np.clip(rng.uniform(0.0, 0.12, (3000, 1)) + rng.normal(0.0, 0.02, (3000, 3)),
                   0.0, 1.0)
    assert extrapolating_family(dark, look(dark), np.ones(len(dark))) == "edit"


def _jumbled(rgb):
    """A look no global family holds: a coarse lattice of random shifts."""
    from scipy.ndimage import map_coordinates

    shifts = np.random.default_rng(0).uniform(-0.15, 0.15, (5, 5, 5, 3))
    flat = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
    moved = np.stack([map_coordinates(shifts[..., c], flat.T * 4, order=1) for c in range(3)],
                     axis=1)
    return np.clip(flat + moved, 0.0, 1.0).reshape(np.shape(rgb))


def test_a_look_its_family_carries_within_the_pair_is_trusted_away_from_its_colours(
        photos, monkeypatch):
    """How well the chosen family carries a pair's edit to the pair's own held-out colours
    (its skill) raises how far the look is followed away from them: a film-like look it
    carries is followed fully, a jumble of colours it cannot carry stays near the pair,
    and a pair of one hue (whose held-out blues lie beside the others) is not raised."""
    import wbcgrade.color.look.learn as learn
    from tests.color.test_look_learn import _one_hue
    from wbcgrade.color.colorspace import default_working_space
    from wbcgrade.color.look.edits import choose_family

    working = default_working_space()
    flower = photos["flower"].reshape(-1, 3).astype(np.float64)
    ones = np.ones(len(flower))
    carried = choose_family(flower, bleach(flower), ones)
    jumbled = choose_family(flower, _jumbled(flower), ones)
    # (0.95 and 0.37 here)
    assert carried.skill > 0.9 and jumbled.skill < 0.5
    monkeypatch.setattr(learn, "TRUSTED_COVERAGE", (0.98, 0.99))  # (trusted only near)
    monkeypatch.setattr(learn, "NEAR_COVERAGE", (-1.0, 0.0))  # (may be raised to 1)
    plain = learn.supported_look(bleach, flower, ones, working)
    assert plain.trust == 0.0 and plain.reach == 1.0
    assert learn.supported_look(bleach, flower, ones, working, carried.skill).trust == 1.0
    assert learn.supported_look(_jumbled, flower, ones, working, jumbled.skill).trust == 0.0
    monkeypatch.undo()
    sea = _one_hue().reshape(-1, 3)
    assert choose_family(sea, bleach(sea), np.ones(len(sea))).skill > learn.SKILLED_TRUST[1]
    assert learn.supported_look(bleach, sea, np.ones(len(sea)), working, 1.0).trust == 0.0


@pytest.mark.slow
def test_edited_photos_say_how_far_a_pairs_look_carries(photos, monkeypatch):
    """A pair of a flower trusted only near its colours; edited photos of the other
    scenes that all show the look say to follow it further, edited photos that show no
    look beyond the pair's colours say to keep it near them."""
    import wbcgrade.color.look.learn as learn
    from wbcgrade.color.colorspace import default_working_space

    working = default_working_space()
    monkeypatch.setattr(learn, "TRUSTED_COVERAGE", (0.98, 0.99))  # (trusted only near)
    monkeypatch.setattr(learn, "NEAR_COVERAGE", (-1.0, 0.0))  # (may be raised to 1)
    monkeypatch.setattr(learn, "NEAR_GAIN", 1.0)
    flower = photos["flower"].reshape(-1, 3).astype(np.float64)
    near = learn.supported_look(bleach, flower, np.ones(len(flower)), working)
    assert near.trust == 0.0 and near.reach == 1.0
    others = [photos[name] for name in NAMES if name != "flower"]
    pair = bleach(photos["flower"])
    shown = learn.evidence_trust(near, [bleach(p) for p in others] + [pair], working)
    kept = learn.evidence_trust(near, others + [pair], working)
    # (0.5 and 0.0 here)
    assert shown.trust > 0.35 and kept.trust < 0.1
    np.testing.assert_array_equal(shown.support, near.support)
    # a look trusted as far as it may be is left as it is
    full = learn.SupportedLook(bleach, near.support, 1.0, 1.0)
    assert learn.evidence_trust(full, others, working) is full


def test_small_bright_things_count_in_what_a_pair_shows(tmp_path, monkeypatch):
    """A starfield is all edges: black sky and small stars of every hue. The colours a pair
    shows (its coverage, and the support its look is trusted by) count every pixel of the
    original, so the stars' colours are shown; the fit's edge weighting (misaligned edges
    mix colours) does not hide them."""
    from wbcgrade.color.look import learn
    from wbcgrade.color.look.learn import colour_coverage, learn_look, pair_colours

    given = []  # (the colours and weights the look's support is built from)
    supported = learn.supported_look

    def recording(look, sources, weights, working, skill=None):
        given.append((sources, weights))
        return supported(look, sources, weights, working, skill)

    monkeypatch.setattr(learn, "supported_look", recording)
    rng = np.random.default_rng(3)
    sky = np.full((112, 112, 3), 0.03)
    for y, x in rng.integers(2, 108, (80, 2)):
        hue = rng.uniform(0.0, 2.0 * np.pi)
        star = 0.55 + 0.4 * np.cos(hue - np.array([0.0, 2.1, 4.2]))
        sky[y:y + 3, x:x + 3] = star * rng.uniform(0.5, 1.0)
    before, after = tmp_path / "b", tmp_path / "a"
    before.mkdir()
    after.mkdir()
    write(before / "stars.png", sky)
    write(after / "stars.png", bleach(sky))
    pairs, _ = learn.pair_files(before, after)
    result = learn_look(pairs)
    working = result.working_space
    images = learn.read_pair(pairs[0], working)
    sources, _, weights = pair_colours(images, learn.register_pair(images), learn.PAIRS_IN_ALL)
    every = colour_coverage(sources, np.ones(len(sources)), working)
    edged = colour_coverage(sources, weights, working)
    assert result.coverage == pytest.approx(every, abs=1e-6)
    # (the edge-weighted colours would show markedly less of the stars' hues)
    assert sum(every.values()) > sum(edged.values()) + 0.1, (every, edged)
    # the look's support (and each fold's) is of the same colours, every pixel alike
    assert given and all(np.ptp(w) == 0 and len(s) == len(sources) for s, w in given)
    assert np.allclose(given[0][0], sources)
