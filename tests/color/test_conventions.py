"""What a photographer expects of any tool: preset names in any case, a photo given for a
folder said so plainly, a missing output folder made (never over a file), JPEGs written at
the input's quality, a batch run again with its ``--report`` folder resumed (issue 47)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image as PILImage

from tests.color.conftest import FAST_ARGS, SAMPLES, small_copy
from tests.conftest import run_cli as run
from wbcgrade.color.io.images import DEFAULT_JPEG_QUALITY, jpeg_quality, read_image, write_image
from wbcgrade.color.presets import (
    StyleSource,
    load_style_folder,
    one_style_warning,
    resolve_preset,
)
from wbcgrade.errors import InputError


def test_preset_names_ignore_case():
    assert resolve_preset("Warm") == resolve_preset("WARM") == resolve_preset("warm")
    with pytest.raises(InputError, match="unknown preset 'Warmer'"):
        resolve_preset("Warmer")


def test_a_photo_given_as_the_style_folder_is_named_as_such(tmp_path):
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "coffee.jpg")
    # the library names its setting (style_dir), the command line its flag (--style)
    with pytest.raises(InputError, match=r"coffee\.jpg: is a file; style_dir takes a folder"):
        load_style_folder(photo, 16)
    result = run("apply", photo, "--style", photo, "-o", tmp_path / "out.jpg")
    assert result.exit_code == 1 and "is a file; --style takes a folder" in result.stderr
    assert not (tmp_path / "out.jpg").exists()


@pytest.fixture
def one_style(tmp_path) -> Path:
    folder = tmp_path / "styles"
    folder.mkdir()
    small_copy(SAMPLES / "coffee.jpg", folder / "coffee.jpg")
    return folder


def test_output_folders_are_made_but_never_over_a_file(tmp_path, photo, one_style):
    target = tmp_path / "new" / "deeper" / "out.jpg"
    lut = tmp_path / "luts" / "grade.cube"
    result = run("apply", photo, "--style", one_style, "-o", target, "--lut", lut, *FAST_ARGS)
    assert result.exit_code == 0, result.output
    assert read_image(target).pixels.shape == read_image(photo).pixels.shape
    assert lut.is_file()
    (tmp_path / "a_file").write_bytes(b"keep me")
    result = run("apply", photo, "--style", one_style, "-o", tmp_path / "a_file" / "out.jpg",
                 *FAST_ARGS)
    assert result.exit_code == 1
    assert result.stderr.strip() == f"Error: {tmp_path / 'a_file'}: is a file, not a folder; " \
                                    f"cannot write {tmp_path / 'a_file' / 'out.jpg'} under it"
    assert (tmp_path / "a_file").read_bytes() == b"keep me"


def test_a_one_photo_style_set_gets_a_one_line_warning(photo, one_style, tmp_path):
    result = run("apply", photo, "--style", one_style, "-o", tmp_path / "o.jpg", "--no-cache")
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if line.startswith("Warning:")]
    assert len(warnings) == 1 and "one style photo" in warnings[0], result.stderr
    assert "use --mode palette to move" in warnings[0]  # the flag on the command line
    source = StyleSource(style_dir=str(one_style))
    said = one_style_warning(source, load_style_folder(one_style, 16), "look")
    assert "use map.builder palette to move" in said  # the setting in the library
    result = run("apply", photo, "--style", one_style, "-o", tmp_path / "p.jpg", *FAST_ARGS)
    assert "one style photo" not in result.stderr  # a palette transfer from one photo is fine


@pytest.mark.parametrize("quality", [60, 85, 92])
def test_a_jpeg_keeps_the_input_quality_and_about_its_size(tmp_path, quality):
    source = tmp_path / "in.jpg"
    with PILImage.open(SAMPLES / "bridge.jpg") as image:
        image.save(source, quality=quality)
    assert jpeg_quality(source) == quality
    image = read_image(source)
    out = write_image(tmp_path / "out.jpg", image.pixels, image)
    assert jpeg_quality(out) == quality
    assert abs(out.stat().st_size / source.stat().st_size - 1) < 0.15
    # asked for: as asked; a PNG's pixels into a JPEG: the default quality
    png = tmp_path / "in.png"
    PILImage.open(source).save(png)
    from wbcgrade.color.io.images import WriteOptions

    assert jpeg_quality(write_image(tmp_path / "q.jpg", image.pixels, image,
                                    options=WriteOptions(quality=70))) == 70
    like = read_image(png)
    assert jpeg_quality(write_image(tmp_path / "p.jpg", like.pixels, like)) == \
        DEFAULT_JPEG_QUALITY
    assert jpeg_quality(png) is None and jpeg_quality(tmp_path / "nothing.jpg") is None


def test_a_batch_run_again_with_its_report_folder_resumes_it(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    for name in ("chelsea", "coffee"):
        small_copy(SAMPLES / f"{name}.jpg", photos / f"{name}.jpg", width=64)
    out, report = tmp_path / "out", tmp_path / "report"
    args = ("batch", photos, "-o", out, "--preset", "warm", "--report", report)
    first = run(*args)
    assert first.exit_code == 0, first.output
    before = json.loads((report / "report.json").read_text())
    small_copy(SAMPLES / "flower.jpg", photos / "flower.jpg", width=64)  # one more photo
    again = run(*args)
    assert again.exit_code == 0, again.output
    assert "graded 1, skipped 2" in again.stdout
    after = json.loads((report / "report.json").read_text())
    assert [p["photo"] for p in before["photos"]] == ["chelsea.jpg", "coffee.jpg"]
    assert sorted(p["photo"] for p in after["photos"]) == ["chelsea.jpg", "coffee.jpg",
                                                            "flower.jpg"]
    assert all(p.get("outcome") for p in after["photos"])
    # a folder holding files wbcgrade did not write is still refused
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "report.json").write_text(json.dumps({"mine": True}))
    refused = run("batch", photos, "-o", tmp_path / "out2", "--preset", "warm", "--report",
                  foreign)
    assert refused.exit_code == 1 and "report.json: file exists" in refused.stderr
    assert json.loads((foreign / "report.json").read_text()) == {"mine": True}
    assert np.isfinite(after["time_s"])


def test_a_look_grade_gets_a_look_report(tmp_path):
    """A preset's look: the report shows the look (a colour chart before and after), its
    source, strength and each photo's change; no empty weight table, no preset photos."""
    from wbcgrade.batch.records import read_record
    from wbcgrade.photos.report import look_chart, sheet_from_files

    photos = tmp_path / "photos"
    photos.mkdir()
    for name in ("chelsea", "coffee"):
        small_copy(SAMPLES / f"{name}.jpg", photos / f"{name}.jpg", width=64)
    out, report = tmp_path / "out", tmp_path / "report"
    result = run("batch", photos, "-o", out, "--preset", "kodak-2383", "--report", report)
    assert result.exit_code == 0, result.output
    for folder in (report, tmp_path / "again"):
        if folder != report:  # `report` on the finished batch: its results, read
            again = run("report", out, "-o", folder)
            assert again.exit_code == 0, again.output
            assert again.stdout.startswith("reported ") and "\ngraded " not in again.stdout
            # each line says how long the photo's grade took (not the report)
            lines = [line for line in again.stdout.splitlines() if ".jpg: " in line]
            assert len(lines) == 2 and all(re.search(r"  \(graded in \d+\.\d s\)$", line)
                                           for line in lines), lines
        page = (folder / "index.html").read_text()
        assert "look report" in page and "palette weight report" not in page
        assert "fit loss" not in page and "<th>change</th>" in page
        assert "the preset&#x27;s own look" in page and "% on average" in page
        entries = json.loads((folder / "report.json").read_text())["photos"]
        for entry in entries:
            after = np.asarray(entry["look_chart"]["after"])
            assert after.shape == look_chart().shape
            assert np.abs(after - look_chart()).mean() > 0.01  # the look moved the chart
            assert (folder / entry["sheet"]).is_file()
    record = read_record(out, "chelsea.jpg")
    record.output = str(out / "chelsea.jpg")
    content = sheet_from_files(record, {})
    assert content.styles == [] and content.chart is not None  # not the preset's photos
