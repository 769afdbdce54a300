"""Faults during a batch: full disks, killed runs and parents, cluster paths, locks (issue 12)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.batch.test_batch import FAST, SAMPLES, small_copy
from tests.color.test_faults import KILLED_WRITER, hidden_files, noise, wbcgrade
from tests.conftest import run_cli
from wbcgrade._publish import TEMP_MARK, lock_folder


@pytest.fixture(scope="module")
def shoot(tmp_path_factory) -> tuple[Path, Path]:
    """(photos, styles): two small photos (one in a sub-folder) and three style photos."""
    root = tmp_path_factory.mktemp("shoot")
    photos, styles = root / "photos", root / "styles"
    for name in ("aitzgorri", "coffee", "flower"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", 48)
    small_copy(SAMPLES / "chelsea.jpg", photos / "chelsea.jpg")
    small_copy(SAMPLES / "bridge.jpg", photos / "sub" / "bridge.jpg")
    return photos, styles


def _batch(photos: Path, styles: Path, out: Path, *extra: str):
    return run_cli("batch", str(photos), "-o", str(out), "--style",
                   str(styles), "-r", *FAST, *extra)


def _age(path: Path, seconds: float = 3600) -> None:
    old = time.time() - seconds
    os.utime(path, (old, old))


@pytest.mark.slow
def test_a_full_disk_fails_one_photo_and_the_batch_goes_on(shoot, tmp_path):
    """libjpeg ended the whole batch on the first failed write: no summary, later photos
    never graded, a hidden temporary left."""
    photos, styles = tmp_path / "photos", shoot[1]
    small_copy(SAMPLES / "chelsea.jpg", photos / "a_small.jpg")
    noise(photos / "b_big.jpg", 256)  # its graded copy is over the 40 KiB limit
    small_copy(SAMPLES / "bridge.jpg", photos / "c_small.png")
    out = tmp_path / "out"
    run = wbcgrade("batch", photos, "-o", out, "--style", styles, *FAST, cwd=tmp_path,
                   limit_size=True)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "graded 2, skipped 0, failed 1" in run.stdout, run.stdout + run.stderr
    assert f"failed   b_big.jpg: {out / 'b_big.jpg'}: write failed" in run.stdout
    assert "Traceback" not in run.stderr
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "a_small.jpg", "c_small.png"]
    assert not any(TEMP_MARK in name for name in hidden_files(out))
    # A rerun without the limit finishes the failed photo only.
    run = wbcgrade("batch", photos, "-o", out, "--style", styles, *FAST, cwd=tmp_path)
    assert run.returncode == 0 and "graded 1, skipped 2, failed 0" in run.stdout, run.stdout


@pytest.mark.slow
def test_a_rerun_removes_the_temporaries_of_a_killed_run(shoot, tmp_path):
    photos, styles = shoot
    out = tmp_path / "out"
    assert _batch(photos, styles, out).exit_code == 0
    target = out / "sub" / "bridge.jpg"
    killed = subprocess.run([sys.executable, "-c", KILLED_WRITER, str(target), "kill"],
                            capture_output=True, timeout=60)
    assert killed.returncode == -signal.SIGKILL
    (stale,) = [p for p in target.parent.iterdir() if TEMP_MARK in p.name]
    _age(stale)
    old_style = out / ".chelsea.k2j4x9_a.jpg"  # the previous naming (a_big.XXXXXXXX.png)
    old_style.write_bytes(b"half")
    _age(old_style)
    result = _batch(photos, styles, out)
    assert result.exit_code == 0, result.output
    assert "graded 0, skipped 2, failed 0" in result.output
    assert not stale.exists() and not old_style.exists()


@pytest.mark.slow
def test_a_rerun_removes_the_record_temporaries_of_a_killed_run(shoot, tmp_path):
    """A batch killed while recording a photo's result left its temporary in
    ``.wbcgrade-results/`` for good; the next run removes it (and keeps the records)."""
    photos, styles = shoot
    out = tmp_path / "out"
    assert _batch(photos, styles, out).exit_code == 0
    records = out / ".wbcgrade-results"
    target = records / "sub" / "bridge.jpg.json"
    kept = sorted(p.relative_to(records) for p in records.rglob("*.json"))
    killed = subprocess.run([sys.executable, "-c", KILLED_WRITER, str(target), "kill"],
                            capture_output=True, timeout=60)
    assert killed.returncode == -signal.SIGKILL
    (stale,) = [p for p in target.parent.iterdir() if TEMP_MARK in p.name]
    _age(stale)
    result = _batch(photos, styles, out)
    assert result.exit_code == 0, result.output
    assert not stale.exists()
    assert sorted(p.relative_to(records) for p in records.rglob("*.json")) == kept


def _children(pid: int) -> dict[int, str]:
    """pid -> command line of the processes whose parent is ``pid``."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            # another process's name or arguments need not be UTF-8
            stat = (entry / "stat").read_bytes().decode(errors="replace")
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(
                errors="replace")
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            found[int(entry.name)] = cmdline
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def _cpu_seconds(pid: int) -> float:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
def test_workers_stop_when_the_batch_is_killed(shoot, tmp_path):
    """SIGKILL of the parent of `batch -j 2` left its workers grading for minutes."""
    photos, styles = tmp_path / "photos", shoot[1]
    for i in range(4):
        small_copy(SAMPLES / "chelsea.jpg", photos / f"p{i}.jpg", 96)
    slow = ["--mode", "palette", "--bins", "64", "--fit-bins", "16", "--max-iter", "50",
            "--iterations", "100",
            "--no-cache"]
    parent = subprocess.Popen(
        [sys.executable, "-c", "from wbcgrade.cli import main; main()", "batch", str(photos),
         "-o", str(tmp_path / "out"), "--style", str(styles), "-j", "2", *slow],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:  # two workers, each busy grading
            workers = [pid for pid, cmd in _children(parent.pid).items() if "spawn_main" in cmd]
            # busy: past their start-up (a worker's whole share of this batch is ~3.5 s CPU)
            if len(workers) == 2 and all(_cpu_seconds(pid) > 2.0 for pid in workers):
                break
            assert parent.poll() is None, "the batch ended before the test could kill it"
            time.sleep(0.2)
        else:
            pytest.fail("the workers did not start")
        parent.kill()
        parent.wait()
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(_alive(pid) for pid in workers):
            time.sleep(0.1)
        assert not [pid for pid in workers if _alive(pid)], "workers outlived their parent"
    finally:
        parent.kill()
        for pid in workers:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


@pytest.mark.slow
def test_relative_paths_work_with_a_scheduler(shoot, tmp_path):
    """Dask workers run in another folder: relative paths failed every photo."""
    distributed = pytest.importorskip("distributed")
    photos, styles = shoot
    work = tmp_path / "work"
    work.mkdir()
    os.symlink(photos, work / "photos")
    os.symlink(styles, work / "styles")
    assert Path.cwd().resolve() != work.resolve()
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  protocol="tcp://", host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        run = wbcgrade("batch", "photos", "-o", "out", "--style", "styles", "-r", *FAST,
                       "--consistent", "--report", "rep", "--scheduler", address, cwd=work)
        assert run.returncode == 0, run.stdout + run.stderr
        assert "graded 2, skipped 0, failed 0" in run.stdout
        run = wbcgrade("report", "photos", "-o", "rep2", "--style", "styles", "-r", *FAST,
                       "--scheduler", address, cwd=work)
        assert run.returncode == 0, run.stdout + run.stderr
    assert (work / "out" / "chelsea.jpg").is_file()
    assert (work / "out" / "sub" / "bridge.jpg").is_file()
    assert (work / "rep" / "sheets" / "chelsea.jpg.png").is_file()
    assert (work / "rep2" / "sheets" / "sub" / "bridge.jpg.png").is_file()
    import json

    entries = json.loads((work / "rep" / "report.json").read_text())["photos"]
    assert {e["source"] for e in entries} == {"photos/chelsea.jpg", "photos/sub/bridge.jpg"}


def test_outputs_are_checked_before_any_work(shoot, tmp_path, monkeypatch):
    import wbcgrade.batch.task as batch

    def forbidden(*args, **kwargs):
        raise AssertionError("graded before checking the outputs")

    monkeypatch.setattr(batch, "grade_file", forbidden)
    photos, styles = shoot
    result = _batch(photos, styles, tmp_path / "out", "--consistent", "--lut",
                    str(tmp_path / "nodir" / "series.cube"))
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1] == (
        f"Error: {tmp_path / 'nodir'}: output folder does not exist")


@pytest.mark.slow
def test_a_device_or_pipe_in_the_output_folder_is_not_replaced(shoot, tmp_path):
    photos, styles = shoot
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / "chelsea.jpg")
    result = _batch(photos, styles, out)
    assert result.exit_code == 1
    assert "graded 1, skipped 0, failed 1" in result.output
    assert "failed   chelsea.jpg:" in result.output and "not a regular file" in result.output
    assert (out / "chelsea.jpg").is_fifo()


@pytest.mark.slow
def test_a_second_batch_into_the_same_folder_is_refused(shoot, tmp_path):
    photos, styles = shoot
    out = tmp_path / "out"
    out.mkdir()
    with lock_folder(out, "batch"):  # as if another run were writing there
        result = _batch(photos, styles, out)
        assert result.exit_code == 1
        line = result.output.strip().splitlines()[-1]
        assert line.startswith(f"Error: {out}: another wbcgrade batch (pid {os.getpid()}) is "
                               "writing into this folder")
        assert not [p for p in out.iterdir() if not p.name.startswith(".")]
    result = _batch(photos, styles, out)  # once it is done
    assert result.exit_code == 0, result.output
    assert "graded 2" in result.output


@pytest.mark.parametrize("extra", [
    (),
    pytest.param(("-j", "2", "--consistent"), marks=pytest.mark.slow),  # worker processes
], ids=["serial", "workers-consistent"])
def test_a_gif_or_null_file_fails_alone_and_the_batch_goes_on(shoot, tmp_path, extra):
    """One GIF (alpha as OpenImageIO's channel 4 of 4) and a zero-byte ``.null`` among the
    photos: the GIF is graded, the ``.null`` fails alone, every JPEG is graded."""
    from PIL import Image as PILImage

    photos = tmp_path / "photos"
    for name in ("chelsea", "coffee", "flower"):
        small_copy(SAMPLES / f"{name}.jpg", photos / f"{name}.jpg", 32)
    PILImage.open(photos / "coffee.jpg").convert("RGB").save(photos / "anim.gif")
    (photos / "x.null").write_bytes(b"")
    out = tmp_path / "out"
    result = _batch(photos, shoot[1], out, *extra)
    assert "Traceback" not in result.output and result.exception is None \
        or isinstance(result.exception, SystemExit), result.output
    assert sorted(p.name for p in out.glob("[!.]*.*")) == [
        "anim.gif", "chelsea.jpg", "coffee.jpg", "flower.jpg"], result.output
    assert "x.null" in result.output and "failed 1" in result.output
