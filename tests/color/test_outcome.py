"""What a grade did (``grade.outcome``), said on the terminal, in --json, batch lines and
reports; weights only for palette grades; options that cannot apply are refused; a
preset's look is the same look in every working space (issue 30)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.color.conftest import FAST_ARGS, SAMPLES, small_copy, write_array
from tests.conftest import run_cli as run
from wbcgrade.cli.grading_options import PALETTE_ONLY
from wbcgrade.cli.option_table import flag_of
from wbcgrade.color.grade.builders import LookFound
from wbcgrade.color.grade.grading import Grade, grade_array, grade_outcome
from wbcgrade.color.io.images import read_image
from wbcgrade.color.mapping.remap import identity_map
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.outcome import GradeOutcome, GradeSource, map_change
from wbcgrade.color.palette.fit import FitSummary
from wbcgrade.color.presets import load_preset, look_in_space, resolve_preset


def _look_grade(color_map, set_strength, n=3, strength=1.0, **found):
    """A set look's grade, as the look builder makes it (``found``: :class:`LookFound`)."""
    return Grade(tuple(f"s{i}" for i in range(n)), np.full(n, 1.0 / n),
                 np.asarray(color_map, np.float32), "", strength,
                 source=GradeSource.SET_LOOK, look=LookFound(set_strength, **found))


def _fit(n=3, start="look"):
    return FitSummary(np.full(n, 1.0 / n), 0.0, np.zeros(n), start)


# ------------------------------------------------------------------------ the outcome


def test_a_set_look_at_strength_zero_says_the_photo_is_unchanged_and_why():
    grade = _look_grade(identity_map(9), 0.0)
    outcome = grade_outcome(grade, _fit(), None)
    assert outcome.source is GradeSource.SET_LOOK and outcome.palette is None
    assert outcome.unchanged and outcome.mean_change == pytest.approx(0.0, abs=1e-3)
    assert "3 style photos share no look" in outcome.reason
    assert "map.builder palette" in outcome.advice
    text = "\n".join(outcome.lines())
    assert "essentially unchanged" in text and "map.builder palette" in text


def test_an_outcome_names_settings_as_the_library_does_and_as_a_caller_asks():
    """The library's words name its settings (``map.strength``); named with the command
    line's table they are its flags, in every word an outcome says, and stay so when the
    outcome is judged on another photo."""
    grade = _look_grade(identity_map(9), 0.0, probability=0.5)
    outcome = grade_outcome(grade, _fit(), None)
    library = [outcome.reason, outcome.advice, *outcome.lines(), json.dumps(outcome.as_dict())]
    assert not any("--" in text for text in library)
    assert "map.strength above 1" in outcome.advice and "originals DIR" in outcome.advice
    named = outcome.named(flag_of)
    assert "--strength above 1" in named.advice and "--originals DIR" in named.advice
    assert "--mode palette" in named.as_dict()["advice"]
    assert "--strength above 1" in "\n".join(named.lines())
    again = named.on_photo(0.1)
    assert "--mode palette" in again.advice and isinstance(again.as_dict()["advice"], str)
    zero = grade_outcome(_look_grade(identity_map(9), 1.0), _fit(), None, blend=0.0)
    assert zero.reason.startswith("map.strength 0 applies almost none")
    assert zero.named(flag_of).reason.startswith("--strength 0 applies almost none")
    assert zero.named(flag_of).advice == "raise --strength (1 applies the grade in full)"


def test_the_advice_for_a_faint_set_look_names_what_the_user_has_not_tried():
    """No own photos: natural photos are the lever; own photos used: it is not offered
    again; too few given: says they were not used. One original first, every time."""
    def advice(**look):
        grade = _look_grade(identity_map(9), 0.0, **look)
        return grade_outcome(grade, _fit(), None).named(flag_of).advice

    plain, used, few = advice(), advice(own_photos=9), advice(own_photos_unused=4)
    assert "--natural DIR with 6 or more" in plain
    assert "--natural" not in used and "your 9 own photos" in used
    assert "your 4 own photos were not used (6 or more" in few
    assert all(text.startswith("the original of one style photo settles it: --originals DIR")
               and "--mode palette" in text for text in (plain, used, few))
    assert "was not used" in advice(own_photos_unused=1)


def test_a_set_look_says_how_sure_it_is_and_what_settles_it():
    """A set look judged jointly: the line says how sure the look is and how much of it is
    applied, the strength is the one asked for, and an unsure look names the originals."""
    def lines(probability, share, blend=1.0):
        nodes = identity_map(9)
        moved = nodes.copy()
        moved[..., 2] = np.minimum(nodes[..., 2] + 0.2, 1.0)  # a clear look: not faint
        grade = _look_grade(moved, share, probability=probability)
        return grade_outcome(grade, _fit(), None, blend=blend).named(flag_of).lines()

    sure = lines(0.999, 0.9)
    assert "the photos show it clearly; 90 % of it applied" in sure[0]
    # the share applied is said; the strength only when it was asked for
    assert "strength" not in sure[0] and not any("--originals" in line for line in sure)
    unsure = lines(0.6, 0.3, blend=2.0)
    assert "unsure it is a look; 60 % of it applied" in unsure[0]  # 30 % at strength 2
    assert "strength 2.00" in unsure[0]
    assert any(line.startswith("the style photos may share this look") and "--originals DIR"
               in line for line in unsure)


def test_the_terminal_says_whether_the_users_own_photos_were_used():
    def lines(set_strength, **look):
        nodes = identity_map(9)
        moved = nodes.copy()
        moved[..., 2] = np.minimum(nodes[..., 2] + 0.2, 1.0)  # a clear look: not faint
        grade = _look_grade(moved if set_strength else nodes, set_strength, **look)
        return "\n".join(grade_outcome(grade, _fit(), None).lines())

    assert "measured against 9 of your own photos" in lines(1.0, own_photos=9)
    assert "your 4 own photos were not used (6 or more" in lines(1.0, own_photos_unused=4)
    assert "own photos" not in lines(1.0)
    # an unchanged grade says it once, in its advice
    assert lines(0.0, own_photos_unused=4).count("were not used") == 1


def test_mean_change_is_the_photos_own_change_in_255ths():
    """A map that adds 0.1 to red moves a photo's colours by 0.1 / 3 per channel where red
    has room, and the outcome says the same size."""
    nodes = identity_map(9)
    moved = nodes.copy()
    moved[..., 0] = np.minimum(nodes[..., 0] + 0.1, 1.0)
    hist = np.zeros((8, 8, 8))
    hist[2, 3, 4] = 1.0  # one colour, red 2/7: room to move
    change = map_change(moved, 1.0, "", hist)
    assert change == pytest.approx(255 * 0.1 / 3, rel=1e-3)
    assert map_change(moved, 0.5, "", hist) == pytest.approx(255 * 0.05 / 3, rel=1e-3)
    outcome = grade_outcome(_look_grade(moved, 1.0), _fit(), hist)
    assert not outcome.unchanged and not outcome.faint
    assert outcome.mean_change == pytest.approx(change)


def test_outcome_round_trips_through_json():
    outcome = grade_outcome(_look_grade(identity_map(5), 0.0), _fit(), None)
    back = GradeOutcome.from_dict(json.loads(json.dumps(outcome.as_dict())))
    assert back == outcome


@pytest.mark.slow
def test_palette_grade_carries_its_weights_and_a_look_grade_none(photo, style_dir):
    rgb = read_image(photo).rgb()
    styles = load_preset(resolve_preset("warm"))
    _, palette = grade_array(rgb, styles, GradeOptions(mode="palette", bins=16, fit_bins=8,
                                                       max_iter=5, n_iter=20))
    fit = palette.outcome.palette
    assert palette.outcome.source is GradeSource.PALETTE and fit is not None
    assert sum(fit.weights) == pytest.approx(1.0) and list(fit.weights) == sorted(
        fit.weights, reverse=True)
    _, look = grade_array(rgb, styles)
    assert look.outcome.source is GradeSource.PRESET_LOOK and look.outcome.palette is None


def test_outcome_mean_change_matches_the_pixels(photo):
    rgb = read_image(photo).rgb()
    graded, grade = grade_array(rgb, load_preset(resolve_preset("kodak-2383")),
                                GradeOptions(regrain=False))
    actual = 255 * float(np.mean(np.abs(graded - rgb)))
    assert grade.outcome.mean_change == pytest.approx(actual, rel=0.15)


# ------------------------------------------------------------------------ the terminal


@pytest.mark.slow
def test_style_folder_grade_says_what_it_did_without_a_weight_table(tmp_path, photo,
                                                                     style_dir):
    result = run("apply", photo, "--style", style_dir, "-o", tmp_path / "o.jpg", "--no-cache")
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert not any(line.startswith("style ") and "weight" in line for line in lines)
    assert lines[0].startswith("grade: the look the 4 style photos share") or \
        lines[0].startswith("grade: the look of the style photo")
    as_json = run("apply", photo, "--style", style_dir, "-o", tmp_path / "o.jpg",
                  "--overwrite", "--no-cache", "--json")
    document = json.loads(as_json.stdout)
    outcome = document["outcome"]
    assert "weights" not in document and "loss" not in document and "fitted" not in document
    assert outcome["source"] in ("set-look", "own-scene") and "palette" not in outcome
    if outcome["mean_change_255"] < 3.0:  # faint or unchanged: said, with what to do
        assert ("a faint grade" in result.output
                or "essentially unchanged" in result.output)
        assert "--mode palette" in result.output


def test_strength_zero_exits_zero_and_says_unchanged(tmp_path, photo):
    result = run("apply", photo, "--preset", "warm", "--strength", "0", "-o",
                 tmp_path / "o.jpg")
    assert result.exit_code == 0, result.output
    assert "the photo is essentially unchanged: --strength 0" in result.output


def test_strength_above_one_strengthens_a_grade(tmp_path, photo):
    rgb = read_image(photo).rgb()
    styles = load_preset(resolve_preset("warm"))
    once, _ = grade_array(rgb, styles, GradeOptions(regrain=False))
    twice, grade = grade_array(rgb, styles, GradeOptions(regrain=False, strength=2.0))
    assert np.mean(np.abs(twice - rgb)) > 1.6 * np.mean(np.abs(once - rgb))
    assert grade.outcome.blend == 2.0


@pytest.mark.slow
def test_palette_mode_prints_the_weights_and_the_loss(tmp_path, photo, style_dir):
    result = run("apply", photo, "--style", style_dir, "-o", tmp_path / "o.jpg", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    assert "weight" in result.output and "loss:" in result.output
    assert "palette fit" in result.output


def test_json_is_small_and_save_grade_is_what_look_reads(tmp_path, photo):
    saved = tmp_path / "grade.json"
    result = run("apply", photo, "--preset", "kodak-2383", "-o", tmp_path / "a.png",
                 "--json", "--save-grade", saved)
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    assert len(result.stdout.encode()) < 10_000 and "saved_grade" not in document
    assert "data" not in json.dumps(document.get("map", {}))  # diagnostics, not the map
    again = run("apply", photo, "--look", saved, "-o", tmp_path / "b.png")
    assert again.exit_code == 0, again.output
    assert f"grade: the saved grade {saved}" in again.output
    first, second = (read_image(tmp_path / n).rgb() for n in ("a.png", "b.png"))
    assert np.abs(first - second).max() <= 1.5 / 255


def test_a_lut_applied_with_look_is_not_listed_as_a_style(tmp_path, photo):
    lut = tmp_path / "warm.cube"
    assert run("apply", photo, "--preset", "warm", "-o", tmp_path / "a.png",
               "--lut", lut).exit_code == 0
    result = run("apply", photo, "--look", lut, "-o", tmp_path / "b.png")
    assert result.exit_code == 0, result.output
    assert "warm  1.000" not in result.output and "grade: the saved grade" in result.output


# ------------------------------------------------------------------------ options


@pytest.mark.parametrize("flag", sorted(PALETTE_ONLY.values()))
def test_palette_options_are_refused_in_look_mode(tmp_path, photo, flag):
    value = {"--weights": "1,0,0,0,0,0", "--loss": "kl"}.get(flag, "3")
    out = tmp_path / "o.jpg"
    result = run("apply", photo, "--preset", "warm", flag, value, "-o", out)
    assert result.exit_code != 0 and not out.exists()
    assert f"Error: {flag} " in result.output and "--mode palette" in result.output
    assert len(result.output.strip().splitlines()) == 1  # one line, no traceback


@pytest.mark.slow
def test_preset_weights_with_palette_mode_work(tmp_path, photo):
    result = run("apply", photo, "--preset", "warm", "--mode", "palette", "--weights",
                 "1,0,0,0,0,0", "--bins", "16", "-o", tmp_path / "o.jpg")
    assert result.exit_code == 0, result.output
    assert "at the weights given with --weights" in result.output


def test_fit_options_are_refused_with_a_saved_look(tmp_path, photo):
    lut = tmp_path / "g.cube"
    assert run("apply", photo, "--preset", "warm", "-o", tmp_path / "a.png",
               "--lut", lut).exit_code == 0
    result = run("apply", photo, "--look", lut, "--relax", "0.1", "-o", tmp_path / "b.png")
    assert result.exit_code != 0 and "--look applies a saved grade" in result.output


def test_lut_onto_the_look_file_is_refused(tmp_path, photo):
    lut = tmp_path / "g.cube"
    assert run("apply", photo, "--preset", "warm", "-o", tmp_path / "a.png",
               "--lut", lut).exit_code == 0
    before = lut.read_bytes()
    result = run("apply", photo, "--look", lut, "--lut", lut, "--overwrite",
                 "-o", tmp_path / "b.png")
    assert result.exit_code != 0 and "input" in result.output
    assert lut.read_bytes() == before


def test_natural_is_refused_in_palette_mode(tmp_path, photo):
    result = run("apply", photo, "--preset", "warm", "--mode", "palette", "--natural",
                 "x.npz", "-o", tmp_path / "o.jpg")
    assert result.exit_code != 0 and "--natural" in result.output


# ------------------------------------------------------------------------ working spaces


def test_preset_look_converted_keeps_the_look():
    """The converted lattice, read back through the conversion, is the preset's own look
    on the colours of its own cube."""
    from wbcgrade.color.colorspace import convert, default_working_space, resolve_space
    from wbcgrade.color.mapping.remap import apply_color_map

    styles = load_preset(resolve_preset("kodak-2383"))
    srgb, cct = default_working_space(), resolve_space("acescct")
    there = look_in_space(styles.meta["look"], srgb, cct, 65)
    colors = np.random.default_rng(1).uniform(0.02, 0.98, (2000, 3)).astype(np.float32)
    own = apply_color_map(colors, styles.meta["look"])
    back = convert(apply_color_map(convert(colors, srgb, cct), there), cct, srgb)
    # uniform colours of the whole sRGB cube (saturated ones included), shown in sRGB
    assert 255 * np.mean(np.abs(np.clip(back, 0, 1) - own)) < 2.0
    assert 255 * np.mean(np.abs(own - colors)) > 10.0  # the look itself is large


def test_preset_look_is_the_same_in_acescct(photo):
    rgb = read_image(photo).rgb()
    styles = load_preset(resolve_preset("kodak-2383"))
    here, _ = grade_array(rgb, styles, GradeOptions(regrain=False))
    there, grade = grade_array(rgb, styles, GradeOptions(regrain=False,
                                                         working_space="acescct"))
    assert grade.outcome.source is GradeSource.PRESET_LOOK
    assert 255 * np.mean(np.abs(here - there)) < 2.0
    assert 255 * np.mean(np.abs(here - rgb)) > 4.0  # the look itself is visible


def test_preset_on_an_acescct_exr_is_the_jpeg_look(tmp_path, photo):
    """An EXR (linear Rec.709) graded in ACEScct gets the look the JPEG gets in sRGB."""
    from wbcgrade.color.colorspace import ColorEncoding

    rgb = read_image(photo).rgb()
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    exr = write_array(tmp_path / "p.exr", linear.astype(np.float32), "float")
    jpeg_like = tmp_path / "p.png"
    write_array(jpeg_like, rgb, "uint16")
    for src, out, extra in ((exr, "g.exr", ["--working-space", "acescct"]),
                            (jpeg_like, "g.png", [])):
        result = run("apply", src, "--preset", "kodak-2383", "--no-regrain", "-o",
                     tmp_path / out, *extra)
        assert result.exit_code == 0, result.output
    graded_exr = read_image(tmp_path / "g.exr")
    shown = ColorEncoding.for_image(graded_exr).to_display(graded_exr.rgb())
    graded_png = read_image(tmp_path / "g.png").rgb()
    inside = np.all((rgb > 0.02) & (rgb < 0.98), axis=2)
    assert 255 * np.mean(np.abs(shown - graded_png)[inside]) < 2.0


def test_preset_on_a_raw_photo_is_the_jpeg_look(tmp_path):
    """A raw photo (graded in ACEScct) gets the preset's own look: the same as its sRGB
    rendering graded in sRGB, not a look re-extracted from the preset's palettes."""
    pytest.importorskip("tifffile")
    from tests.color.io.test_raw import WHITE, write_dng
    from wbcgrade.color.colorspace import ColorEncoding

    rng = np.random.default_rng(3)
    patches = rng.uniform(0.05, 0.6, (6, 8, 3)).repeat(8, 0).repeat(8, 1)
    mosaic = np.empty(patches.shape[:2])
    mosaic[0::2, 0::2] = patches[0::2, 0::2, 0]
    mosaic[0::2, 1::2] = patches[0::2, 1::2, 1]
    mosaic[1::2, 0::2] = patches[1::2, 0::2, 1]
    mosaic[1::2, 1::2] = patches[1::2, 1::2, 2]
    raw = write_dng(tmp_path / "p.dng", np.round(mosaic * WHITE))
    result = run("apply", raw, "--preset", "kodak-2383", "--no-regrain", "-o",
                 tmp_path / "g.exr")
    assert result.exit_code == 0, result.output
    source, graded = read_image(raw), read_image(tmp_path / "g.exr")
    before = ColorEncoding.for_image(source).to_display(source.rgb())
    after = ColorEncoding.for_image(graded).to_display(graded.rgb())
    inside = np.all((before > 0.02) & (before < 0.98), axis=2)
    assert inside.mean() > 0.5
    expected, _ = grade_array(np.clip(before, 0, 1), load_preset(resolve_preset("kodak-2383")),
                              GradeOptions(regrain=False))
    assert 255 * np.mean(np.abs(after - expected)[inside]) < 2.0


def test_batch_lines_and_report_of_a_look_grade_have_no_weights(tmp_path, photo):
    folder = tmp_path / "in"
    folder.mkdir()
    small_copy(SAMPLES / "coffee.jpg", folder / "coffee.jpg")
    small_copy(photo, folder / "chelsea.jpg")
    result = run("batch", folder, "-o", tmp_path / "out", "--preset", "warm",
                 "--report", tmp_path / "rep")
    assert result.exit_code == 0, result.output
    assert "the preset's own look, strength 1.00, colours move " in result.output
    rows = (tmp_path / "rep" / "weights.csv").read_text().splitlines()
    header = rows[0].split(",")
    for row in rows[1:]:
        cells = dict(zip(header, row.split(",")))
        assert cells["china"] == "" and cells["loss"] == ""
        assert cells["source"] == "preset-look" and float(cells["mean_change_255"]) > 1
    html = (tmp_path / "rep" / "index.html").read_text()
    assert "the preset&#x27;s own look" in html or "the preset's own look" in html
    assert "0.167" not in html  # no uniform 1/6 weights
    report = json.loads((tmp_path / "rep" / "report.json").read_text())
    photos = report.get("photos", report)
    assert "weights" not in json.dumps(photos)


@pytest.mark.slow
def test_look_extract_says_when_the_lut_does_nothing(tmp_path, style_dir):
    result = run("look", "extract", style_dir, "-o", tmp_path / "l.cube", "--strength", "0",
                 "--no-cache")
    assert result.exit_code == 0, result.output
    assert "strength 0.00" in result.output
    assert "it leaves colours essentially unchanged" in result.output
    found = run("look", "extract", style_dir, "-o", tmp_path / "m.cube", "--no-cache", "--json")
    outcome = json.loads(found.stdout)["outcome"]
    assert outcome["source"] == "set-look"
    if outcome["strength"] < 0.25:  # an ungraded set: said in words, not only a number
        text = run("look", "extract", style_dir, "-o", tmp_path / "n.cube", "--no-cache")
        assert "share no look" in text.output or "share little look" in text.output


def test_look_extract_of_a_preset_is_its_own_look(tmp_path):
    result = run("look", "extract", "--preset", "kodak-2383", "-o", tmp_path / "k.cube")
    assert result.exit_code == 0, result.output
    assert "the preset's own look, strength 1.00" in result.output
    assert "unchanged" not in result.output and "faint" not in result.output
