"""The third hostile round (issue 31), batches: records that heal, SIGTERM that stops.

- 3: SIGTERM to ``batch -j 2`` (its parent only) took 23 s to end, its workers publishing
  queued photos meanwhile with no result recorded; a rerun then skipped those photos as
  complete and ``report`` failed on them for ever;
- 6: a record holding ``[1, 2]`` made ``report`` end in a traceback.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.batch.test_batch import FAST, SAMPLES, small_copy
from tests.conftest import run_cli as run
from wbcgrade.batch.records import RESULTS_FOLDER

CLI = [sys.executable, "-c", "from wbcgrade.cli import main; main()"]



@pytest.fixture(scope="module")
def shoot(tmp_path_factory) -> tuple[Path, Path]:
    """(photos, styles): three small photos and three style photos."""
    root = tmp_path_factory.mktemp("shoot")
    photos, styles = root / "photos", root / "styles"
    for name in ("aitzgorri", "coffee", "flower"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", 32)
    for name in ("chelsea", "bridge", "sunset"):
        small_copy(SAMPLES / f"{name}.jpg", photos / f"{name}.jpg", 40)
    return photos, styles


def _published(out: Path) -> list[str]:
    return sorted(p.name for p in out.iterdir() if not p.name.startswith("."))


def _recorded(out: Path) -> list[str]:
    folder = out / RESULTS_FOLDER
    return sorted(p.name[:-5] for p in folder.iterdir() if not p.name.startswith(".")) \
        if folder.is_dir() else []


@pytest.mark.slow
def test_a_published_photo_with_no_record_is_graded_again(shoot, tmp_path):
    photos, styles = shoot
    out = tmp_path / "out"
    first = run("batch", photos, "-o", out, "--style", styles, *FAST)
    assert first.exit_code == 0, first.output
    (out / RESULTS_FOLDER / "bridge.jpg.json").unlink()  # a run stopped between the two
    (out / RESULTS_FOLDER / "chelsea.jpg.json").write_text("[1, 2]")  # and a damaged one
    report = run("report", out, "-o", tmp_path / "rep1")
    assert report.exit_code != 0 and "Traceback" not in report.output, report.output
    assert not isinstance(report.exception, Exception) or isinstance(report.exception,
                                                                      SystemExit)
    assert "failed   bridge.jpg: no result recorded" in report.output
    again = run("batch", photos, "-o", out, "--style", styles, *FAST)
    assert again.exit_code == 0, again.output
    assert "graded 2, skipped 1, failed 0" in again.output, again.output
    assert _recorded(out) == _published(out) == ["bridge.jpg", "chelsea.jpg", "sunset.jpg"]
    report = run("report", out, "-o", tmp_path / "rep2")
    assert report.exit_code == 0, report.output
    entries = json.loads((tmp_path / "rep2" / "report.json").read_text())["photos"]
    assert len(entries) == 3


@pytest.mark.slow
def test_sigterm_to_a_parallel_batch_stops_its_workers_and_the_rerun_heals(shoot, tmp_path):
    photos, styles = tmp_path / "photos", shoot[1]
    for i in range(10):
        small_copy(SAMPLES / "chelsea.jpg", photos / f"p{i:02d}.jpg", 48 + 8 * i)
    out = tmp_path / "out"
    slow = ["--mode", "palette", "--bins", "16", "--fit-bins", "8", "--max-iter", "10",
            "--iterations", "30", "--no-cache"]
    batch = subprocess.Popen([*CLI, "batch", str(photos), "-o", str(out), "--style",
                              str(styles), "-j", "2", *slow],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not _recorded(out):  # the workers are up and grading
            assert batch.poll() is None, batch.communicate()
            assert time.monotonic() < deadline, "no photo was graded in 300 s"
            time.sleep(0.05)
        batch.send_signal(signal.SIGTERM)  # the parent only, as `kill PID` does
        signalled = time.monotonic()
        _, stderr = batch.communicate(timeout=120)
        took = time.monotonic() - signalled
    finally:
        batch.kill()
    assert batch.returncode == 128 + signal.SIGTERM, stderr
    assert "Traceback" not in stderr, stderr
    assert took < 10, f"the batch took {took:.1f} s to end after SIGTERM"  # 23 s before
    published, recorded = _published(out), _recorded(out)
    assert len(published) < 10, "the batch went on after SIGTERM until it had finished"
    assert not [p for p in out.iterdir() if p.name.startswith(".p")]  # no temporaries
    # whatever was published without a record is graded again, and the records heal
    again = subprocess.run([*CLI, "batch", str(photos), "-o", str(out), "--style",
                            str(styles), *slow], capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert f"skipped {len(set(recorded) & set(published))}," in again.stdout, again.stdout
    assert _recorded(out) == _published(out) == [f"p{i:02d}.jpg" for i in range(10)]
    report = run("report", out, "-o", tmp_path / "rep")
    assert report.exit_code == 0, report.output
