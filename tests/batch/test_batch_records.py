"""A batch records its results; `report` on its output reads them (grades nothing); one
line per photo; a photo that is one of the styles is warned about (issue 22)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from tqdm import tqdm

import wbcgrade.color.grade.builders as builders
import wbcgrade.color.grade.grading as grading
from tests.batch.test_batch import FAST, SAMPLES, small_copy


@pytest.fixture
def fits(monkeypatch) -> list[str]:
    """Every weight fit and every pass of the grade path, by name, as they happen."""
    calls: list[str] = []
    fit, grade = builders.fit_weights, grading.grade_histograms

    def counted_fit(*args, **kwargs):
        calls.append("fit")
        return fit(*args, **kwargs)

    def counted_grade(*args, **kwargs):
        calls.append("grade")
        return grade(*args, **kwargs)

    monkeypatch.setattr(builders, "fit_weights", counted_fit)  # the "palette" builder's
    monkeypatch.setattr(grading, "grade_histograms", counted_grade)
    return calls


@pytest.fixture
def folders(tmp_path) -> tuple[Path, Path]:
    """(photos, styles): chelsea and coffee; the styles coffee (a larger copy: the same
    photo), flower and sunset."""
    photos, styles = tmp_path / "photos", tmp_path / "styles"
    for name in ("chelsea", "coffee"):
        small_copy(SAMPLES / f"{name}.jpg", photos / f"{name}.jpg", 64)
    for name in ("coffee", "flower", "sunset"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", 96)
    return photos, styles


@pytest.mark.slow
def test_report_on_a_batch_output_reads_its_results_and_grades_nothing(tmp_path, folders, fits,
                                                                       cli):
    photos, styles = folders
    out = tmp_path / "out"
    result = cli("batch", str(photos), "-o", str(out), "--style",
                 str(styles), *FAST)
    assert result.exit_code == 0, result.output
    assert fits.count("grade") == 2 and "fit" in fits
    # one line per photo (not a terminal here): name, weights, loss, time
    lines = [line for line in result.stdout.splitlines() if line.startswith("graded   ")]
    assert len(lines) == 2 and all(" loss " in line and line.endswith(" s") for line in lines)
    assert any(line.startswith("graded   coffee.jpg: coffee 1.000") for line in lines)
    # coffee is one of the styles: one warning line, only for it
    warnings = [line for line in result.stderr.splitlines() if "its own palette" in line]
    assert len(warnings) == 1 and warnings[0].startswith("Warning: coffee.jpg is graded")
    records = {p.name: json.loads(p.read_text()) for p in (out / ".wbcgrade-results").iterdir()}
    assert set(records) == {"chelsea.jpg.json", "coffee.jpg.json"}
    assert records["coffee.jpg.json"]["own_style"]["style"] == "coffee"
    assert "own_style" not in records["chelsea.jpg.json"]

    fits.clear()
    report_dir = tmp_path / "report"
    result = cli("report", str(out), "-o", str(report_dir))
    assert result.exit_code == 0, result.output
    assert fits == []  # nothing graded
    assert "reported 2, skipped 0, failed 0" in result.stdout
    assert "coffee.jpg is graded towards its own palette" in result.stderr
    document = json.loads((report_dir / "report.json").read_text())
    assert document["style_names"] == ["coffee", "flower", "sunset"]
    for entry in document["photos"]:
        record = records[f"{entry['photo']}.json"]
        assert entry["weights"] == record["weights"] and entry["loss"] == record["loss"]
        assert entry["output"] == str(out / entry["photo"])
        assert (report_dir / entry["sheet"]).is_file()
    assert (report_dir / "weights.csv").read_text().count("\n") == 3
    # the batch's grades are reported whatever the options; other styles are refused
    result = cli("report", str(out), "-o", str(tmp_path / "r2"),
                 "--preset", "warm")
    assert result.exit_code == 1 and fits == []
    assert result.output.strip().splitlines()[-1].startswith(f"Error: {out} holds the graded")
    result = cli("report", str(out), "-o", str(tmp_path / "r3"),
                 "--style", str(styles), "--strength", "0.5")
    assert result.exit_code == 0 and fits == []
    assert "strength: ignored" in result.stderr


@pytest.mark.slow
def test_report_of_a_copy_the_batch_did_not_record_says_so(tmp_path, folders, fits, cli):
    photos, styles = folders
    out = tmp_path / "out"
    args = ["batch", str(photos), "-o", str(out), "--style", str(styles), *FAST]
    assert cli(*args).exit_code == 0
    small_copy(SAMPLES / "flower.jpg", out / "stranger.jpg", 32)
    fits.clear()
    result = cli("report", str(out), "-o", str(tmp_path / "report"))
    assert result.exit_code == 1 and fits == []
    assert "failed   stranger.jpg: no result recorded by the batch" in result.stdout


def test_stage_bar_says_what_it_does_and_drops_the_previous_photos_loss():
    from wbcgrade.cli._progress import bar_callbacks

    with tqdm(file=io.StringIO(), disable=False) as bar:
        callbacks = bar_callbacks(bar, photos=True)
        callbacks["photo"]("a.jpg")
        callbacks["stage"]("fit")
        callbacks["fit"](1, np.ones(3) / 3, 0.125)
        assert bar.desc.removesuffix(": ") == "a.jpg: fitting the weights"
        assert "0.125" in bar.postfix
        callbacks["stage"]("barycenter")
        assert bar.desc.removesuffix(": ") == "a.jpg: barycenter palette"
        callbacks["photo"]("b.jpg")
        assert bar.desc.removesuffix(": ") == "b.jpg: starting" and not bar.postfix
        callbacks["fit"](1, np.ones(3) / 3, 0.5)
        callbacks["stage"]("read")  # apply: no photo names, the read stage starts afresh
        assert bar.desc.removesuffix(": ") == "b.jpg: reading the photo" and not bar.postfix
        callbacks["stage"]("scene transfer")
        assert bar.desc.removesuffix(": ") == "b.jpg: scene: colour transport"


@pytest.mark.slow  # over 4 s of the fast tier: the whole suite runs it
def test_settings_are_recorded_before_the_first_photo_and_a_deep_record_heals(
        tmp_path, folders, monkeypatch, cli):
    """A batch stopped during its first photo has recorded its settings already (a rerun
    that grades nothing and `report OUT` read them); a settings record nested 200,000
    deep is replaced, not a traceback on every rerun."""
    import wbcgrade.batch.task as task
    from wbcgrade.batch.settings import SETTINGS_FILE

    photos, styles = folders
    out = tmp_path / "out"
    run_task = task.run_task

    def stopped(*args, **kwargs):
        assert (out / SETTINGS_FILE).is_file()  # recorded before any photo is graded
        raise KeyboardInterrupt

    monkeypatch.setattr(task, "run_task", stopped)
    monkeypatch.setattr("wbcgrade.batch.run.run_task", stopped)
    result = cli("batch", str(photos), "-o", str(out), "--preset", "warm", *FAST)
    assert result.exit_code == 130, result.output
    assert (out / SETTINGS_FILE).is_file()
    monkeypatch.setattr("wbcgrade.batch.run.run_task", run_task)
    (out / SETTINGS_FILE).write_text("[" * 200_000 + "]" * 200_000)
    result = cli("batch", str(photos), "-o", str(out), "--preset", "warm", *FAST)
    assert result.exit_code == 0 and "Traceback" not in result.output, result.output
    assert json.loads((out / SETTINGS_FILE).read_text())["styles"]
    result = cli("report", str(out), "-o", str(tmp_path / "rep"))
    assert result.exit_code == 0, result.output


@pytest.mark.slow  # over 5 s of the fast tier: the whole suite runs it
def test_a_stopped_report_is_finished_by_a_rerun_without_overwrite(tmp_path, folders,
                                                                   monkeypatch, cli):
    """A report stopped after its sheets (before index.html) is finished by the next run
    without --overwrite; a finished report is still never replaced without it."""
    import wbcgrade.batch.workflow as workflow  # the report command's own workflow

    photos, styles = folders
    out = tmp_path / "rep"
    write_report = workflow.write_report

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(workflow, "write_report", stopped)
    args = ("report", str(photos), "-o", str(out), "--preset", "warm", *FAST)
    assert cli(*args).exit_code == 130
    assert list((out / "sheets").glob("*.png")) and not (out / "index.html").exists()
    monkeypatch.setattr(workflow, "write_report", write_report)
    result = cli(*args)
    assert result.exit_code == 0, result.output
    assert (out / "index.html").is_file()
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []
    result = cli(*args)
    assert result.exit_code == 1 and "exists" in result.output, result.output


def test_a_batch_report_reads_jpegs_small_and_makes_each_picture_once(tmp_path, monkeypatch):
    """`report` on a batch's results decodes the photo, its graded copy and the style
    photos small (never a full-size read) and makes each picture at the size its sheet
    shows it: the sheet pastes it as it is, resized once (a quick report, issue 47)."""
    from PIL import Image

    import wbcgrade.photos.report as report
    import wbcgrade.photos.sheet as sheet
    from wbcgrade.color.presets import StyleSet
    from wbcgrade.photos.report import sheet_from_files, style_pictures
    from wbcgrade.photos.results import FileResult

    rng = np.random.default_rng(0)
    for name in ("photo", "graded", "style"):  # wide: the sheet's half width decides its size
        Image.fromarray(rng.integers(0, 256, (400, 1600, 3), dtype=np.uint8)).save(
            tmp_path / f"{name}.jpg", quality=90)

    def full_size_read(*args, **kwargs):
        raise AssertionError("a JPEG read at full size")

    monkeypatch.setattr(report, "read_image", full_size_read)  # (what the report reads with)
    pictures = style_pictures(StyleSet(["style"], np.ones((1, 4, 4, 4)) / 64, str(tmp_path)))
    assert pictures["style"].shape == (32, 128, 3)  # the photo itself, fitting 96 x 128
    result = FileResult("photo.jpg", str(tmp_path / "photo.jpg"), str(tmp_path / "graded.jpg"),
                        "graded", names=["style"], weights=[1.0], loss=0.1, vertex_losses=[0.1])
    content = sheet_from_files(result, pictures)
    height, width = sheet.fit_size(400, 1600, *sheet.picture_box())
    assert content.before.shape == content.after.shape == (height, width, 3)
    pixels = sheet.compose_sheet(content)
    top = left = sheet._PAD
    shown = pixels[top + 48:top + 48 + height, left:left + width]
    np.testing.assert_array_equal(shown, content.before)
