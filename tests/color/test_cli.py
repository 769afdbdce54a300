"""`wbcgrade apply` and `wbcgrade preset` end to end through click's runner."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.color.conftest import FAST_ARGS, SAMPLES, small_copy, write_array
from tests.conftest import run_cli as run
from wbcgrade.color.io.images import read_image
from wbcgrade.color.mapping.lut import read_cube


@pytest.fixture
def styles(tmp_path, style_dir):
    folder = tmp_path / "styles"
    shutil.copytree(style_dir, folder)
    (folder / "notes.txt").write_text("not a photo")
    return folder


@pytest.mark.slow
def test_apply_with_style_folder_json_and_lut(tmp_path, styles):
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "cat.png")
    result = run("apply", photo, "--style", styles, "--lut", tmp_path / "grade.cube",
                 "--lut-size", 33, "--json", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    assert "skipping notes.txt: not an image" in result.stderr
    report = json.loads(result.stdout)
    weights = [w["weight"] for w in report["weights"]]
    assert [w["style"] for w in report["weights"]][0] in {"aitzgorri", "coffee", "flower",
                                                           "seeding"}
    assert weights == sorted(weights, reverse=True) and sum(weights) == pytest.approx(1, abs=1e-5)
    assert {"fit", "barycenter", "transfer", "remap", "write", "lut"} <= set(report["timings_s"])
    graded_path = tmp_path / "cat_graded.png"
    assert report["output"] == str(graded_path)
    graded = read_image(graded_path).pixels
    original = read_image(photo).pixels
    assert graded.shape == original.shape and np.abs(graded - original).mean() > 0.02
    assert report["map"]["size"] == 33 and report["regrain"] is True
    # The LUT is the grade's colour map: without the regrain step (which looks at
    # each pixel's neighbours, so no LUT can hold it) it reproduces the photo
    # within 1/255 on average; the regrain step only adjusts detail around it.
    lut = read_cube(tmp_path / "grade.cube")
    assert lut.size == 33
    result = run("apply", photo, "--style", styles, "-o", tmp_path / "plain.png",
                 "--no-regrain", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    plain = read_image(tmp_path / "plain.png").pixels
    by_lut = lut.apply(original.astype(np.float64))
    assert np.abs(by_lut - plain).mean() < 1 / 255
    assert 0 < np.abs(by_lut - graded).mean() < 0.05


@pytest.mark.slow
def test_apply_table_weights_and_strength(tmp_path, styles, photo):
    out = tmp_path / "out.jpg"
    result = run("apply", photo, "--style", styles, "-o", out, "--weights", "1,1,0,0",
                 "--strength", "0.5", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].split() == ["style", "weight"]
    assert lines[2].split()[1] == "0.500" and lines[4].split()[1] == "0.000"
    # Fixed weights skip the fit, but their loss is still evaluated and shown (it once
    # said "from nan at uniform weights, 0 evaluations").
    assert re.search(r"^loss: \d\S* at the weights given with --weights$", result.stdout, re.M)
    assert "nan" not in result.stdout and "time:" in result.stdout
    assert read_image(out).pixels.shape == read_image(photo).pixels.shape


@pytest.mark.slow
def test_apply_json_says_whether_the_weights_were_fitted(tmp_path, styles, photo):
    """"fitted" was always true, also for --weights."""
    given = run("apply", photo, "--style", styles, "-o", tmp_path / "a.jpg", "--weights",
                "1,1,0,0", "--json", *FAST_ARGS)
    fitted = run("apply", photo, "--style", styles, "-o", tmp_path / "b.jpg", "--json",
                 *FAST_ARGS)
    assert given.exit_code == 0 and fitted.exit_code == 0, given.output + fitted.output
    given, fitted = json.loads(given.stdout), json.loads(fitted.stdout)
    assert given["fitted"] is False and given["fit_start"] == "given"
    assert fitted["fitted"] is True
    assert fitted["fit_start"] in ("uniform", "vertex-refit", "vertex")
    assert fitted["fit"]["start"] == fitted["fit_start"]


@pytest.mark.slow
def test_preset_build_list_and_apply(tmp_path, styles, photo):
    preset_file = tmp_path / "mine.npz"
    result = run("preset", "build", styles, "-o", preset_file, "--bins", 16, "--no-cache")
    assert result.exit_code == 0, result.output
    assert "4 styles" in result.stdout and "skipping notes.txt" in result.stderr
    result = run("apply", photo, "--preset", preset_file, "-o", tmp_path / "a.jpg", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    listing = run("preset", "list")
    assert listing.exit_code == 0 and "warm" in listing.stdout and "kodak-2383" in listing.stdout
    result = run("apply", photo, "--preset", "kodak-2383", "-o", tmp_path / "b.jpg", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    assert {"grace_hopper", "china", "wine"} <= set(result.stdout.split())


@pytest.mark.slow
def test_apply_keeps_16bit_rgba_and_orientation(tmp_path, styles, rng):
    pixels = rng.random((12, 20, 4)).astype(np.float32)
    photo = write_array(tmp_path / "in.tif", pixels, "uint16", {"Orientation": 8})
    out = tmp_path / "out.tif"
    result = run("apply", photo, "--style", styles, "-o", out, *FAST_ARGS)
    assert result.exit_code == 0, result.output
    back = oiio.ImageInput.open(str(out))
    spec = back.spec()
    data = back.read_image(0, 0, 0, 4, "uint16")
    back.close()
    assert spec.format == oiio.TypeDesc("uint16") and (spec.width, spec.height) == (12, 20)
    assert spec.get_int_attribute("Orientation", 0) == 1
    expected_alpha = np.rot90(np.round(pixels[:, :, 3] * 65535), k=1)
    np.testing.assert_array_equal(data[:, :, 3], expected_alpha)


@pytest.mark.slow
def test_apply_exr_keeps_values_above_one(tmp_path, styles, rng):
    linear = (rng.random((10, 12, 3)) * 0.5).astype(np.float32)
    linear[0, 0] = [4.0, 2.0, 1.0]
    photo = write_array(tmp_path / "hdr.exr", linear, "half")
    result = run("apply", photo, "--style", styles, *FAST_ARGS)
    assert result.exit_code == 0, result.output
    graded = read_image(tmp_path / "hdr_graded.exr")
    assert graded.spec.format == oiio.TypeDesc("half")
    assert graded.pixels[0, 0].max() == pytest.approx(4.0, rel=0.01)


def _bad_photo(tmp_path, case):
    if case == "truncated":
        data = (SAMPLES / "coffee.jpg").read_bytes()
        (tmp_path / "p.jpg").write_bytes(data[: len(data) // 2])
        return tmp_path / "p.jpg"
    if case == "not-image":
        (tmp_path / "p.jpg").write_text("hello")
        return tmp_path / "p.jpg"
    if case == "missing":
        return tmp_path / "p.jpg"
    if case == "nan":
        pixels = np.full((4, 4, 3), 0.5, np.float32)
        pixels[2, 2, 1] = np.nan
        return write_array(tmp_path / "p.exr", pixels, "float")
    return small_copy(SAMPLES / "chelsea.jpg", tmp_path / "p.jpg")


@pytest.mark.parametrize("case, extra, message", [
    ("truncated", [], "corrupt or truncated"),
    ("not-image", [], "not a readable image"),
    ("missing", [], "no such file"),
    ("nan", [], "NaN or infinite"),
    ("ok", ["--style", "{empty}"], "no readable photos"),
    ("ok", ["--preset", "{broken}"], "not a valid wbcgrade preset"),
    ("ok", ["--preset", "{foreign}"], "not a valid wbcgrade preset"),
    ("ok", ["--preset", "nosuchpreset"], "unknown preset"),
    ("ok", ["-o", "{photo}"], "refusing to overwrite the input"),
    ("ok", ["-o", "{photo}", "--overwrite"], "refusing to overwrite the input"),
    ("ok", ["-o", "{existing}"], "file exists"),
    ("ok", ["-o", "{under_a_file}"], "existing.jpg: is a file, not a folder"),
    ("ok", ["--lut", "{existing_cube}"], "file exists"),
    ("ok", ["--strength", "5"], "--strength must be in [0, 4]"),
    ("ok", ["--weights", "1,x"], "comma-separated numbers"),
    ("ok", ["--weights", "1,1"], "2 numbers for 4 styles"),
    ("ok", ["--regrain-eps", "1e8"], "--regrain-eps must be between"),  # 1e39: all black
    ("ok", ["--width", "1e300"], "not a finite number"),
    ("ok", ["--lut-size", "0"], "--lut-size must be between 2 and 129"),  # even with no --lut
])
def test_bad_input_gives_one_line_and_no_file(tmp_path, styles, case, extra, message):
    photo = _bad_photo(tmp_path, case)
    (tmp_path / "empty").mkdir()
    (tmp_path / "broken.npz").write_bytes(b"PK\x03\x04 not really a zip")
    np.savez(tmp_path / "foreign.npz", weights=np.ones(3))
    (tmp_path / "existing.jpg").write_bytes(b"keep me")
    (tmp_path / "existing.cube").write_text("keep me")
    names = {"empty": tmp_path / "empty", "broken": tmp_path / "broken.npz",
             "foreign": tmp_path / "foreign.npz", "photo": photo,
             "existing": tmp_path / "existing.jpg",
             "under_a_file": tmp_path / "existing.jpg" / "out.jpg",
             "existing_cube": tmp_path / "existing.cube"}
    extra = [str(a).format(**names) for a in extra]
    if not any(a in ("--style", "--preset") for a in extra):
        extra = ["--style", str(styles), *extra]
    before = sorted(p.name for p in tmp_path.iterdir())
    result = run("apply", photo, *extra, *FAST_ARGS)
    # a bad option value is a usage error (2, as click's own); a bad file 1
    usage = {"--strength", "--weights", "--regrain-eps", "--width", "--lut-size"}
    assert result.exit_code == (2 if usage & set(extra) else 1), \
        result.output
    assert "Traceback" not in result.output
    errors = [line for line in result.stderr.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and message in errors[0], result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert (tmp_path / "existing.jpg").read_bytes() == b"keep me"


@pytest.mark.slow
def test_options_are_validated_once_per_run(tmp_path, styles, monkeypatch):
    """The options of a run are made and checked once (the CLI made them, then the
    pipeline validated them again three times), each error naming its flag."""
    from wbcgrade.color import options

    counts = {}
    for group in (options.FitOptions, options.TransferOptions, options.MapOptions,
                  options.RegrainOptions, options.SpaceOptions):
        check = group.__post_init__

        def counting(self, check=check, name=group.__name__):
            counts[name] = counts.get(name, 0) + 1
            check(self)

        monkeypatch.setattr(group, "__post_init__", counting)
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "cat.jpg")
    result = run("apply", photo, "--style", styles, "--lut", tmp_path / "g.cube",
                 "--report", tmp_path / "report", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    assert counts == {"FitOptions": 1, "TransferOptions": 1, "MapOptions": 1,
                      "RegrainOptions": 1, "SpaceOptions": 1}
    result = run("apply", photo, "--style", styles, "--map-size", 1, *FAST_ARGS)
    assert result.exit_code == 2
    assert result.stderr.strip() == "Error: --map-size must be between 2 and 129"


def test_unusable_paths_exit_1_and_reports_show_bidi_controls(tmp_path, styles, photo):
    """Missing or unusable paths exit 1 as docs/architecture.md says (click answered 2),
    with a message that says what the path is; an option given is checked though the
    grade does not use it (``--natural /missing`` with a preset); a photo named with
    U+202E cannot reorder the report's page."""
    import os

    os.mkfifo(tmp_path / "pipe.jpg")
    out = tmp_path / "o.jpg"
    cases = [(("apply", tmp_path, "--preset", "warm", "-o", out), "is a folder"),
             (("apply", tmp_path / "pipe.jpg", "--preset", "warm", "-o", out), "FIFO"),
             (("apply", photo, "--look", tmp_path, "-o", out), "is a folder"),
             (("apply", photo, "--style", photo, "-o", out), "is a file; --style takes a folder"),
             (("apply", photo, "--preset", "warm", "--natural", tmp_path / "missing",
               "-o", out), "no such natural"),
             (("batch", tmp_path / "missing", "-o", tmp_path / "b", "--preset", "warm"),
              "no such file"),
             (("report", tmp_path / "missing", "--preset", "warm"), "no such file")]
    for args, words in cases:
        result = run(*args)
        assert result.exit_code == 1 and words in result.output, (args, result.output)
        assert not out.exists()
    photos = tmp_path / "photos"
    photos.mkdir()
    shutil.copy(photo, photos / "cat\u202egpj.exe.jpg")
    result = run("report", photos, "--preset", "warm", "-o", tmp_path / "rep", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    page = (tmp_path / "rep" / "index.html").read_text("utf-8")
    assert "\u202e" not in page and "cat\\u202egpj.exe.jpg" in page
