"""One output rule for every command, checked once before any work (issue 21, cases 1-3).

Outputs are resolved through links, never land on an input or leave their
output folder through a link, and a run never replaces a file it did not
write unless --overwrite. Each case is run as a user runs the command.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import pytest

from tests.batch.test_batch import FAST, SAMPLES, small_copy
from tests.conftest import run_cli


def _digest(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _run(*args) -> object:
    return run_cli(*map(str, args))


@pytest.fixture(scope="module")
def styles(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("styles")
    for name in ("aitzgorri", "coffee", "flower"):
        small_copy(SAMPLES / f"{name}.jpg", folder / f"{name}.jpg", 40)
    return folder


@pytest.mark.slow
def test_batch_never_writes_through_a_link_back_into_the_input_tree(tmp_path, styles):
    """Case 1: out/sub -> ../in made in/sub/x.jpg's output in/x.jpg itself: the input
    was replaced by the graded coffee photo, exit 0."""
    src, out = tmp_path / "in", tmp_path / "out"
    small_copy(SAMPLES / "chelsea.jpg", src / "x.jpg", 48)
    small_copy(SAMPLES / "coffee.jpg", src / "sub" / "x.jpg", 48)
    out.mkdir()
    os.symlink("../in", out / "sub")
    before = _digest(src)
    result = _run("batch", src, "-o", out, "-r", "--style", styles, *FAST)
    assert result.exit_code == 1, result.output
    assert _digest(src) == before  # no input changed
    assert "leads out of the output folder" in result.output
    assert "graded 1, skipped 0, failed 1" in result.output
    assert (out / "x.jpg").is_file() and "Traceback" not in result.output


@pytest.mark.slow
@pytest.mark.parametrize("foreign", ["other-size", "older-than-the-photo"])
def test_batch_never_replaces_a_file_it_did_not_write(tmp_path, styles, foreign):
    """Case 2: a file in the output folder that is older than its photo or of another
    size was replaced without --overwrite (exit 0, no word)."""
    src, out = tmp_path / "in", tmp_path / "out"
    small_copy(SAMPLES / "chelsea.jpg", src / "x.jpg", 48)
    small_copy(SAMPLES / "bridge.jpg", src / "y.jpg", 48)
    if foreign == "other-size":
        small_copy(SAMPLES / "coffee.jpg", out / "x.jpg", 20)
    else:
        small_copy(SAMPLES / "coffee.jpg", out / "x.jpg", 48)
        old = (src / "x.jpg").stat().st_mtime - 3600
        os.utime(out / "x.jpg", (old, old))
    kept = (out / "x.jpg").read_bytes()
    result = _run("batch", src, "-o", out, "--style", styles, *FAST)
    assert result.exit_code == 1, result.output
    assert (out / "x.jpg").read_bytes() == kept
    assert "x.jpg: file exists (use --overwrite to replace it)" in result.output
    assert "graded 1, skipped 0, failed 1" in result.output and (out / "y.jpg").is_file()
    if foreign == "other-size":  # (one case is enough to show --overwrite replaces it)
        result = _run("batch", src, "-o", out, "--style", styles, *FAST, "--overwrite")
        assert result.exit_code == 0, result.output
        assert (out / "x.jpg").read_bytes() != kept


def _report_folder(folder: Path, name: str = "index.html") -> dict[str, str]:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_text("keep me")
    return _digest(folder)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["index.html", "weights.csv", "report.json",
                                  "sheets/x.jpg.png"])
def test_report_never_replaces_a_report_it_did_not_write(tmp_path, styles, name):
    """Case 3 (``report``): an existing report's files were replaced without --overwrite."""
    src = tmp_path / "in"
    small_copy(SAMPLES / "chelsea.jpg", src / "x.jpg", 48)
    report = tmp_path / "report"
    (report / Path(name).parent).mkdir(parents=True, exist_ok=True)
    before = _report_folder(report, name)
    result = _run("report", src, "-o", report, "--style", styles, *FAST)
    assert result.exit_code == 1 and "file exists (use --overwrite" in result.output
    assert _digest(report) == before  # nothing written: checked before any work
    if name == "index.html":  # (one case is enough to show --overwrite replaces them)
        result = _run("report", src, "-o", report, "--style", styles, *FAST, "--overwrite")
        assert result.exit_code == 0, result.output
        document = json.loads((report / "report.json").read_text())
        assert document["photos"][0]["photo"] == "x.jpg"


@pytest.mark.slow
def test_apply_report_never_replaces_a_report_it_did_not_write(tmp_path, styles):
    """Case 3 (``apply --report``): checked with the photo's outputs, before any work."""
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "x.jpg", 48)
    report = tmp_path / "report"
    before = _report_folder(report, "weights.csv")
    out = tmp_path / "graded.jpg"
    result = _run("apply", photo, "-o", out, "--report", report, "--style", styles, *FAST)
    assert result.exit_code == 1 and "weights.csv: file exists" in result.output
    assert _digest(report) == before and not out.exists()
    result = _run("apply", photo, "-o", out, "--report", report, "--style", styles, *FAST,
                  "--overwrite")
    assert result.exit_code == 0, result.output
    assert (report / "weights.csv").read_text() != "keep me" and out.is_file()


def test_video_report_never_replaces_a_report_it_did_not_write(tmp_path):
    """Case 3 (``video --report``): report.json and the shot sheets of another run."""
    clip = tmp_path / "clip.mp4"
    shutil.copy(SAMPLES / "clip.mp4", clip)
    report = tmp_path / "report"
    _report_folder(report, "shot-01.png")
    before = _report_folder(report, "report.json")
    out = tmp_path / "graded.mp4"
    result = _run("video", clip, "-o", out, "--report", report, "--preset", "warm",
                  "--mode", "palette", "--weights", "1,1,1", "--bins", "16", "--fit-bins", "8",
                  "--iterations", "10", "--sample-every", "2")
    assert result.exit_code == 1 and "file exists (use --overwrite" in result.output
    assert _digest(report) == before and not out.exists()
