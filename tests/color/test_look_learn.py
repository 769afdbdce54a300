"""``look learn``: before/after pairs become a look (wbcgrade.color.look.learn, the command)."""

import json

import numpy as np
import pytest

from tests.color.test_look import LUMA, sample, warm_look
from wbcgrade.color.grade.look_files import learn_look_file
from wbcgrade.color.grade.saved_grade import load_look
from wbcgrade.color.histogram import grid_points
from wbcgrade.color.look.learn import learn_look, pair_files

STYLE = ("aitzgorri", "astronaut", "chelsea", "coffee", "flower")
WIDTH = 240


def write(path, rgb):
    import OpenImageIO as oiio

    data = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(data.shape[1], data.shape[0], data.shape[2],
                                       oiio.UINT8))
    out.write_image(np.ascontiguousarray(data))
    out.close()
    return path


def grey(rgb):
    """A black-and-white film: luma of the warm look, a little more contrast."""
    luma = np.clip((warm_look(rgb) @ LUMA - 0.5) * 1.15 + 0.5, 0.0, 1.0)
    return np.repeat(luma[..., None], 3, axis=-1)


@pytest.fixture(scope="module")
def photos():
    return {name: sample(name, WIDTH) for name in STYLE + ("sunset", "bridge")}


def make_pairs(root, photos, look=warm_look, edit=None, names=STYLE):
    """BEFORE and AFTER folders: the photos as JPEGs, their looked versions as PNGs
    (``edit(name, image) -> image`` changes an after)."""
    before, after = root / "before", root / "after"
    before.mkdir(parents=True)
    after.mkdir()
    for name in names:
        write(before / f"{name}.jpg", photos[name])
        looked = look(photos[name])
        write(after / f"{name}.png", edit(name, looked) if edit else looked)
    return before, after


def lattice_error(grade, look, size=9):
    """Mean distance between a learned grade and the true look over the colours of
    the sample photos (the colours a look is learned on)."""
    points = grid_points(size)
    table = np.asarray(grade.color_map)
    from wbcgrade.color.mapping.remap import resample_lattice

    mapped = resample_lattice(table, size).reshape(-1, 3)
    return float(np.mean(np.linalg.norm(mapped - look(points), axis=1)))


def photo_error(grade, look, photo):
    """Mean |graded - truth| on a photo no pair showed, relative to doing nothing."""
    graded = grade.apply(photo.astype(np.float32))
    truth = look(photo)
    return float(np.mean(np.abs(graded - truth)) / np.mean(np.abs(photo - truth)))


@pytest.mark.slow
def test_a_known_look_is_learned_from_pairs_and_reproduced_on_another_photo(tmp_path, photos):
    import OpenImageIO as oiio

    before, after = make_pairs(tmp_path, photos)
    (after / "coffee.png").unlink()  # one edit a 16-bit TIFF
    data = np.round(np.clip(warm_look(photos["coffee"]), 0, 1) * 65535).astype(np.uint16)
    out = oiio.ImageOutput.create(str(after / "coffee.tif"))
    out.open(str(after / "coffee.tif"), oiio.ImageSpec(data.shape[1], data.shape[0], 3,
                                                       oiio.UINT16))
    out.write_image(data)
    out.close()
    result = learn_look_file(before, after, tmp_path / "look.cube")
    assert len(result.used) == len(STYLE)
    assert all(p.registered == "same framing" for p in result.used)
    grade = load_look(tmp_path / "look.cube")  # as `apply --look` reads it
    for other in ("sunset", "bridge"):  # in no pair
        assert photo_error(grade, warm_look, photos[other]) < 0.2
    assert result.delta_e < 1.5 and result.held_out < 2.0
    assert not result.look.monochrome


@pytest.mark.slow
def test_resized_cropped_and_turned_afters_learn_the_same_look(tmp_path, photos):
    def edit(name, looked):
        h, w = looked.shape[:2]
        if name == "aitzgorri":  # resized to 60 %
            import cv2
            return cv2.resize(looked.astype(np.float32), (round(w * 0.6), round(h * 0.6)),
                              interpolation=cv2.INTER_AREA)
        if name == "chelsea":  # cropped
            return looked[h // 8: h - h // 10, w // 6: w - w // 12]
        if name == "coffee":  # turned a quarter
            return np.rot90(looked, 1)
        if name == "flower":  # cropped keeping its shape, turned half
            return np.rot90(looked[h // 10: h - h // 10, w // 10: w - w // 10], 2)
        return looked

    plain = learn_look_file(*make_pairs(tmp_path / "plain", photos), tmp_path / "a.cube")
    edited = learn_look_file(*make_pairs(tmp_path / "edited", photos, edit=edit),
                             tmp_path / "b.cube")
    how = {p.name: p.registered for p in edited.used}
    assert len(how) == len(STYLE)
    assert how["aitzgorri"] == "resized"
    assert how["chelsea"].startswith("keypoints")
    assert how["coffee"].endswith("turned 270 degrees")
    # its shape is the original's, turned or not, but no turn lays it on the original
    assert how["flower"].startswith("keypoints")
    a, b = load_look(tmp_path / "a.cube"), load_look(tmp_path / "b.cube")
    for other in ("sunset", "bridge"):
        assert abs(photo_error(a, warm_look, photos[other])
                   - photo_error(b, warm_look, photos[other])) < 0.05
    assert edited.held_out < plain.held_out + 0.5


@pytest.mark.slow
def test_black_and_white_afters_give_a_black_and_white_look(tmp_path, photos):
    before, after = make_pairs(tmp_path, photos, look=grey)
    result = learn_look_file(before, after, tmp_path / "bw.json", lut_size=17)
    assert result.look.monochrome
    grade = load_look(tmp_path / "bw.json")
    table = np.asarray(grade.color_map).reshape(-1, 3)
    assert np.ptp(table, axis=1).max() < 1e-4  # every colour, greys included, to a grey
    graded = grade.apply(photos["sunset"].astype(np.float32))
    assert np.ptp(graded, axis=-1).max() < 1e-4
    truth = grey(photos["sunset"])
    assert np.mean(np.abs(graded - truth)) < 0.2 * np.mean(np.abs(photos["sunset"] - truth))
    data = json.loads((tmp_path / "bw.json").read_text())
    assert data["learned"]["monochrome"] is True


def sepia(rgb):
    """A toned black-and-white film: the grey film's luma plus a warm brown tint that is
    strongest in the mid-tones."""
    luma = grey(rgb)[..., 0]
    tint = np.array([0.07, 0.005, -0.08]) * (4.0 * luma * (1.0 - luma))[..., None]
    return np.clip(luma[..., None] + tint, 0.0, 1.0)


def selenium(rgb):
    """A split toning: cool purple shadows, neutral highlights."""
    luma = grey(rgb)[..., 0]
    tint = np.array([0.01, -0.03, 0.04]) * np.clip(1.0 - 1.6 * luma, 0.0, 1.0)[..., None]
    return np.clip(luma[..., None] + tint, 0.0, 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("toner", [sepia, selenium])
def test_toned_afters_give_a_toned_look(tmp_path, photos, toner):
    """Sepia or selenium afters (every colour its luma plus a tint of that luma) learn a
    look whose every output is so: a colourful photo comes out toned, its chroma no more
    than the afters hold, in the toning's hue at each lightness."""
    from wbcgrade.color.mapping.remap import TONE_LUMA

    before, after = make_pairs(tmp_path, photos, look=toner)
    (after / "coffee.png").unlink()
    write(after / "coffee.jpg", toner(photos["coffee"]))
    result = learn_look_file(before, after, tmp_path / "toned.cube")
    assert len(result.used) == len(STYLE)
    assert result.look.toned and not result.look.monochrome
    assert all(p.toned for p in result.used)
    assert result.as_dict()["toned"] is True
    afters = np.concatenate([toner(photos[n]).reshape(-1, 3) for n in STYLE])
    afters_chroma = float(np.ptp(afters, axis=1).max())
    grade = load_look(tmp_path / "toned.cube")
    photo = photos["sunset"]  # colourful, in no pair
    assert np.ptp(photo, axis=-1).max() > 4 * afters_chroma
    graded = grade.apply(photo.astype(np.float32)).reshape(-1, 3).astype(np.float64)
    assert np.ptp(graded, axis=1).max() <= afters_chroma + 0.01
    truth = toner(photo).reshape(-1, 3)
    assert np.mean(np.abs(graded - truth)) < 0.25 * np.mean(np.abs(photo.reshape(-1, 3) - truth))
    # at each lightness the tint the afters hold, in hue and in strength
    after_luma, luma = afters @ TONE_LUMA, graded @ TONE_LUMA
    compared = 0
    for lo in np.arange(0.1, 0.8, 0.1):
        band, held = (luma >= lo) & (luma < lo + 0.1), (after_luma >= lo) & (after_luma < lo + 0.1)
        if band.sum() < 50 or held.sum() < 50:
            continue
        tint = (graded[band] - luma[band, None]).mean(axis=0)
        true_tint = (afters[held] - after_luma[held, None]).mean(axis=0)
        if np.linalg.norm(true_tint) < 0.01:
            continue
        compared += 1
        cosine = tint @ true_tint / (np.linalg.norm(tint) * np.linalg.norm(true_tint))
        assert cosine > 0.95, (lo, tint, true_tint)
        assert 0.7 < np.linalg.norm(tint) / np.linalg.norm(true_tint) < 1.4, (lo, tint, true_tint)
    assert compared >= 2


def test_colour_afters_are_not_taken_for_toned(photos):
    """A look that keeps some colour (bleach bypass-like: most saturation gone) is a colour
    look; a photo's own colours are not a toning."""
    from wbcgrade.color.look.learn import _tint_spread

    for name in ("sunset", "coffee", "bridge"):
        photo = photos[name]
        luma = (photo @ LUMA)[..., None]
        assert _tint_spread(photo) > 0.05
        assert _tint_spread(luma + 0.3 * (photo - luma)) > 0.03
        assert _tint_spread(sepia(photo)) < 0.02


def test_an_original_with_no_colour_says_nothing_of_toning(tmp_path, photos):
    """A toned after of a grey original (a night sky, an overcast scene) is no sign that
    the look takes colour away: the pair is neither toned nor colour."""
    from wbcgrade.color.colorspace import default_working_space
    from wbcgrade.color.look.learn import PairFiles, read_pair

    photo = photos["sunset"]
    dull = np.repeat((photo @ LUMA)[..., None], 3, axis=-1)
    pair = PairFiles("dull", write(tmp_path / "dull.png", dull),
                     write(tmp_path / "dull-edit.png", sepia(dull)))
    assert read_pair(pair, default_working_space()).toned is None
    pair = PairFiles("bright", write(tmp_path / "bright.png", photo),
                     write(tmp_path / "bright-edit.png", sepia(photo)))
    assert read_pair(pair, default_working_space()).toned is True


@pytest.mark.slow
def test_bad_pairs_are_reported_one_line_each_and_the_others_used(tmp_path, photos):
    before, after = make_pairs(tmp_path, photos)
    write(before / "lonely.jpg", photos["sunset"])  # no edited version
    write(after / "stray.png", warm_look(photos["bridge"]))  # no original: evidence too
    write(before / "other.jpg", photos["sunset"])  # an edit of another scene
    write(after / "other.png", warm_look(photos["bridge"]))
    write(before / "broken.jpg", photos["bridge"])
    (after / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
    lines = []
    result = learn_look_file(before, after, tmp_path / "look.cube", warn=lines.append)
    assert sorted(p.name for p in result.used) == sorted(STYLE)
    said = {line.split(":")[0]: line for line in lines}
    assert "no edited version" in said["lonely"]
    assert "stray" not in said and result.edits_alone == ["stray"]
    assert "another scene" in said["other"]
    assert "unreadable" in said["broken"] and "broken.jpg" in said["broken"]
    assert len(lines) == 3 and all("\n" not in line for line in lines)
    # the look is that of the good pairs
    assert photo_error(load_look(tmp_path / "look.cube"), warm_look, photos["sunset"]) < 0.2


@pytest.mark.slow
def test_a_pair_with_another_look_or_a_local_edit_is_named_and_weighs_little(tmp_path, photos):
    def cool(rgb):
        return np.clip(rgb * [0.8, 0.95, 1.2] + [0.0, 0.02, 0.05], 0.0, 1.0)

    def edit(name, looked):
        if name == "coffee":
            return cool(photos[name])  # another look
        if name == "flower":  # a masked area made much darker (a fifth of the photo)
            out = looked.copy()
            h, w = out.shape[:2]
            out[: h // 2, : w * 2 // 5] *= 0.4
            return out
        return looked

    before, after = make_pairs(tmp_path, photos, edit=edit, names=STYLE + ("sunset",))
    lines = []
    result = learn_look_file(before, after, tmp_path / "look.cube", warn=lines.append)
    warned = {p.name: p.warning for p in result.used if p.warning}
    assert set(warned) == {"coffee", "flower"}, lines
    assert "disagrees" in warned["coffee"]
    assert "local edits" in warned["flower"]
    assert photo_error(load_look(tmp_path / "look.cube"), warm_look, photos["bridge"]) < 0.35


@pytest.mark.slow
def test_the_command_prints_the_report_and_writes_a_look_apply_uses(tmp_path, photos, cli):
    before, after = make_pairs(tmp_path, photos)
    result = cli("look", "learn", str(before), str(after), "-o",
                 str(tmp_path / "look.json"), "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    for key in ("output", "working_space", "pairs_used", "delta_e", "held_out_delta_e",
                "held_out_folds", "monochrome", "pairs", "unpaired", "warnings", "seconds"):
        assert key in report
    assert report["pairs_used"] == len(STYLE) and report["held_out_folds"] == 4
    pair = report["pairs"][0]
    for key in ("name", "before", "after", "registered", "delta_e", "held_out", "warning"):
        assert key in pair
    assert 0 < report["delta_e"] <= report["held_out_delta_e"] < 3
    # plain words
    words = cli("look", "learn", str(before), str(after), "-o",
                str(tmp_path / "look.cube"))
    assert words.exit_code == 0 and "held out" in words.stdout and "wrote" in words.stdout
    # apply --look uses it as it is
    photo = write(tmp_path / "sunset.png", photos["sunset"])
    out = tmp_path / "graded.png"
    applied = cli("apply", str(photo), "--look", str(tmp_path / "look.json"),
                  "-o", str(out))
    assert applied.exit_code == 0, applied.output
    assert out.is_file()


@pytest.mark.parametrize("args, says", [
    (["-o", "{tmp}/look.png"], "must be written as .cube, .clf or .json"),
    (["-o", "{tmp}/look.cube", "--lut-size", "1"], "--lut-size"),
])
def test_command_errors_are_one_line(tmp_path, photos, args, says, cli):
    before, after = make_pairs(tmp_path, photos, names=STYLE[:1])
    result = cli(*["look", "learn", str(before), str(after)]
                                + [a.format(tmp=tmp_path) for a in args])
    assert result.exit_code != 0
    assert says in result.output
    assert "Traceback" not in result.output


def test_no_usable_pair_fails_in_one_line_after_naming_each(tmp_path, photos, cli):
    before, after = tmp_path / "before", tmp_path / "after"
    before.mkdir()
    after.mkdir()
    write(before / "a.jpg", photos["sunset"])
    write(after / "a.png", warm_look(photos["bridge"]))  # another scene
    write(before / "b.jpg", photos["coffee"])
    result = cli("look", "learn", str(before), str(after), "-o",
                 str(tmp_path / "look.cube"))
    assert result.exit_code == 1
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert any(line.startswith("Warning: a:") and "another scene" in line for line in lines)
    assert any(line.startswith("Warning: b:") and "no edited version" in line
               for line in lines)
    assert lines[-1].startswith("Error:") and "no usable" in lines[-1]
    assert not (tmp_path / "look.cube").exists()
    # a file and a folder do not pair
    mixed = cli("look", "learn", str(before / "a.jpg"), str(after), "-o",
                str(tmp_path / "look.cube"))
    assert mixed.exit_code != 0 and "two photos or two folders" in mixed.output


def test_stems_pair_across_formats_case_and_export_endings(tmp_path):
    before, after = tmp_path / "b", tmp_path / "a"
    before.mkdir()
    after.mkdir()
    for name in ("IMG_1.CR2", "img_2.jpg", "IMG_3.jpg", "IMG_3.tif"):
        (before / name).write_bytes(b"")
    for name in ("IMG_1.jpg", "IMG_2-Edit.tif", "IMG_3_copy.png"):
        (after / name).write_bytes(b"")
    pairs, problems = pair_files(before, after)
    assert [(p.before.name, p.after.name) for p in pairs] == [
        ("IMG_1.CR2", "IMG_1.jpg"), ("img_2.jpg", "IMG_2-Edit.tif"),
        ("IMG_3.tif", "IMG_3_copy.png")]
    assert len(problems) == 1 and "IMG_3.tif is used" in problems[0][1]


def test_a_single_pair_learns_without_a_held_out_check(tmp_path, photos):
    before = write(tmp_path / "one.jpg", photos["sunset"])
    after = write(tmp_path / "one-edited.png", warm_look(photos["sunset"]))
    pairs, _ = pair_files(before, after)
    result = learn_look(pairs)
    assert len(result.used) == 1 and result.folds == 0 and result.held_out is None
    assert result.used[0].delta_e < 1.5


def test_one_pair_draws_as_many_colour_pairs_as_a_shoot_of_many(tmp_path, photos, monkeypatch):
    """A single pair is sampled as densely as several together (``PAIRS_IN_ALL`` shared
    among them, never under ``PAIRS_PER_PHOTO`` each): one photo's colours are all the
    look is learned from."""
    import wbcgrade.color.look.learn as learn

    monkeypatch.setattr(learn, "PAIRS_PER_PHOTO", 400)
    monkeypatch.setattr(learn, "PAIRS_IN_ALL", 6000)
    drawn = []
    real = learn.pair_colours

    def spy(*args, **kwargs):
        found = real(*args, **kwargs)
        drawn.append(len(found[0]))
        return found

    monkeypatch.setattr(learn, "pair_colours", spy)
    before, after = make_pairs(tmp_path / "one", photos, names=("sunset",))
    learn_look(pair_files(before, after)[0])
    assert drawn == [6000]  # the sunset's overlap holds more than that
    drawn.clear()
    before, after = make_pairs(tmp_path / "five", photos)
    learn_look(pair_files(before, after)[0])
    assert drawn == [1200] * 5
    monkeypatch.setattr(learn, "PAIRS_IN_ALL", 1000)
    drawn.clear()
    learn_look(pair_files(before, after)[0])
    assert drawn == [400] * 5


@pytest.mark.slow
def test_raw_originals_are_read_and_the_look_learned_in_their_working_space(tmp_path, photos, cli):
    from tests.color.io.test_raw import write_dng
    from wbcgrade.color.colorspace import ColorEncoding
    from wbcgrade.color.io.images import read_image

    before, after = tmp_path / "before", tmp_path / "after"
    before.mkdir()
    after.mkdir()
    for name in ("sunset", "coffee", "flower"):
        linear = photos[name][:160, :224] ** 2.2
        mosaic = np.empty(linear.shape[:2])
        mosaic[0::2, 0::2] = linear[0::2, 0::2, 0]  # RGGB
        mosaic[0::2, 1::2] = linear[0::2, 1::2, 1]
        mosaic[1::2, 0::2] = linear[1::2, 0::2, 1]
        mosaic[1::2, 1::2] = linear[1::2, 1::2, 2]
        raw = read_image(write_dng(before / f"{name.upper()}.DNG",
                                   np.round(mosaic * 65535)))
        shown = ColorEncoding.for_image(raw).to_display(raw.rgb())  # as the camera showed it
        write(after / f"{name}.jpg", warm_look(shown))
    result = learn_look_file(before, after, tmp_path / "look.cube")
    assert len(result.used) == 3 and "ACEScct" in result.working_space
    assert all(p.registered == "same framing" for p in result.used)
    assert result.delta_e < 4.0  # the camera's rendering clips what ACEScct keeps
    graded = tmp_path / "graded.tif"
    applied = cli("apply", str(before / "SUNSET.DNG"), "--look",
                  str(tmp_path / "look.cube"), "-o", str(graded))
    assert applied.exit_code == 0, applied.output


@pytest.mark.slow
def test_a_learned_black_and_white_lut_stays_black_and_white_through_apply(tmp_path, photos, cli):
    """`apply --look` regrains a LUT by default; regrain keeps the input's colour edges,
    and the grade makes a black-and-white map's output black and white again."""
    import OpenImageIO as oiio

    before, after = make_pairs(tmp_path, photos, look=grey)
    learn_look_file(before, after, tmp_path / "bw.cube", lut_size=17)
    photo = write(tmp_path / "sunset.png", photos["sunset"])
    for flags in ((), ("--no-regrain",)):
        out = tmp_path / f"graded{len(flags)}.png"
        result = cli("apply", str(photo), "--look", str(tmp_path / "bw.cube"),
                     "-o", str(out), *flags)
        assert result.exit_code == 0, result.output
        pixels = oiio.ImageBuf(str(out)).get_pixels(oiio.UINT8).astype(int)
        assert (pixels.max(-1) - pixels.min(-1)).max() == 0, flags


def test_a_crop_of_the_original_shape_is_not_laid_on_it_turned():
    """A resized crop that keeps the photo's shape goes to keypoints: turned by half, the
    bridge's repeated structure passed the cheap check (its patches peaked at no shift:
    the window's own envelope), and the pair taught the look a mirror image of the scene."""
    import cv2

    from wbcgrade.color.look.learn import PairImages, pair_colours, register_pair

    before = sample("bridge", 480).astype(np.float32)
    looked = warm_look(before).astype(np.float32)
    h, w = looked.shape[:2]
    crop = looked[h // 10: h - h // 20, w // 10: w - w // 20]
    after = cv2.resize(crop, (round(crop.shape[1] * 0.6), round(crop.shape[0] * 0.6)),
                       interpolation=cv2.INTER_AREA)
    images = PairImages("bridge", before, after, False)
    found = register_pair(images)
    assert found is not None and found.how.startswith("keypoints"), found
    sources, targets, _ = pair_colours(images, found)
    assert np.median(np.abs(warm_look(sources) - targets)) < 0.02


def _one_hue(seed=0, size=64):
    """A photo of one hue (a purple sea): lightness and a little chroma vary, nothing else."""
    rng = np.random.default_rng(seed)
    light = np.linspace(0.35, 1.0, size)[None, :, None] * rng.uniform(0.8, 1.0, (size, 1, 1))
    hue = np.array([0.62, 0.22, 0.46]) + rng.normal(0.0, 0.03, (size, size, 3))
    return np.clip(light * hue, 0.0, 1.0)


def _saturated(rgb):
    """A look that leaves greys alone: chroma about luma times 1.35."""
    luma = (rgb @ LUMA)[..., None]
    return np.clip(luma + 1.35 * (rgb - luma), 0.0, 1.0)


def test_a_look_from_pairs_of_few_colours_is_trusted_only_near_them():
    from wbcgrade.color.colorspace import default_working_space
    from wbcgrade.color.look import learn as learned

    everywhere = grid_points(9)
    working = default_working_space()

    def pushed(x):
        return np.clip(np.asarray(x, dtype=np.float64) * 0.9 + 0.05, 0.0, 1.0)

    broad = learned.supported_look(pushed, everywhere, np.ones(len(everywhere)), working)
    assert broad.trust == 1.0
    np.testing.assert_allclose(broad(everywhere), pushed(everywhere))
    sea = _one_hue().reshape(-1, 3)
    narrow = learned.supported_look(pushed, sea, np.ones(len(sea)), working)
    assert narrow.trust == 0.0
    greys = np.linspace(0.5, 1.0, 11)[:, None].repeat(3, axis=1)  # (dark greys are near it)
    np.testing.assert_allclose(narrow(greys), greys, atol=1e-4)  # far from the sea: no change
    np.testing.assert_allclose(narrow(sea[:50]), pushed(sea[:50]), atol=0.02)  # on it: the look


def test_a_look_from_pairs_of_some_colours_reaches_further_just_beside_them(monkeypatch):
    """Beside a pair's colours (a node or so away) the look is followed further once the
    pairs cover enough of natural colours (NEAR_COVERAGE); far from them it still fades
    to no change."""
    from wbcgrade.color.colorspace import default_working_space
    from wbcgrade.color.look import learn as learned

    working = default_working_space()
    monkeypatch.setattr(learned, "TRUSTED_COVERAGE", (0.98, 0.99))  # (never trusted far)

    def pushed(x):
        return np.clip(np.asarray(x, dtype=np.float64) * 0.9 + 0.05, 0.0, 1.0)

    rng = np.random.default_rng(2)
    shown = rng.uniform(0.0, 1.0, (4000, 3))
    shown = shown[shown[:, 0] < 0.45]  # colours with little red: half the cube
    weights = np.ones(len(shown))
    beside = np.array([[0.54, 0.4, 0.5], [0.54, 0.2, 0.8]])  # just beyond their reds
    far = np.array([[0.95, 0.5, 0.5]])

    def followed(look):  # how far of the way to the look each colour beside goes
        return (np.linalg.norm(look(beside) - beside, axis=1)
                / np.linalg.norm(pushed(beside) - beside, axis=1))

    supported = learned.supported_look(pushed, shown, weights, working)
    assert supported.trust == 0.0
    monkeypatch.setattr(learned, "NEAR_GAIN", 1.0)
    before = learned.supported_look(pushed, shown, weights, working)
    # (0.77 and 0.69 of the way, against 0.51 and 0.43 by the pair's own support)
    assert np.all(followed(supported) > 0.65) and np.all(followed(before) < 0.55)
    assert np.all(followed(supported) > followed(before) + 0.2)
    np.testing.assert_allclose(supported(far), far, atol=1e-3)  # far: no change


@pytest.mark.slow
def test_one_pair_of_one_hue_keeps_greys_where_the_look_leaves_them(tmp_path, monkeypatch):
    from wbcgrade.color.look import learn as learned

    original = _one_hue()
    before = write(tmp_path / "sea.jpg", original)
    after = write(tmp_path / "sea-edited.png", _saturated(original))
    greys = np.linspace(0.5, 1.0, 21)[:, None].repeat(3, axis=1)  # (dark greys are near it)

    def learned_greys():
        pairs, _ = pair_files(before, after)
        result = learn_look(pairs)
        sea = original.reshape(-1, 3)
        return (np.abs(result.look(greys) - greys).max(),
                np.abs(result.look(sea) - _saturated(sea)).mean(),
                np.abs(sea - _saturated(sea)).mean())

    moved, error, size = learned_greys()
    assert error < 0.35 * size  # the pair's own colours get the look
    assert moved < 2.0 / 255.0  # greys, which the look leaves alone, stay put
    monkeypatch.setattr(learned, "TRUSTED_COVERAGE", (-1.0, 0.0))  # trusted everywhere
    trusted_moved, _, _ = learned_greys()
    assert trusted_moved > 2.0 * moved


def test_a_pairs_rare_colours_weigh_as_much_as_its_common_ones():
    """A portrait's few mid greys must count in the fit as its skin does: weights divided by
    how common each colour is give two regions of 9 000 and 1 000 pixels about the same
    weight (9 : 1 before)."""
    from wbcgrade.color.look import learn as learned

    rng = np.random.default_rng(3)
    common = np.array([0.8, 0.55, 0.45]) + rng.normal(0.0, 0.01, (9000, 3))
    rare = np.array([0.45, 0.45, 0.45]) + rng.normal(0.0, 0.01, (1000, 3))
    sources = np.clip(np.concatenate([common, rare]), 0.0, 1.0)
    weights = np.ones(len(sources))
    _, _, flat = learned._flattened((sources, sources, weights))
    share = flat[9000:].sum() / flat.sum()
    assert 0.4 < share < 0.6
    assert np.isclose(weights[9000:].sum() / weights.sum(), 0.1)
