"""Photos under hostile file names and disks (issue 21, cases 11, 12, 13).

- 11: file and folder names that are not UTF-8 (``caf\\xe9.png``: POSIX names
  are bytes) used to end in a ``TypeError`` traceback from OpenImageIO's
  binding, and ``batch`` stopped at that file (also with ``-j 2``);
- 12: ``batch -j 2`` workers held OpenImageIO objects in caches at exit
  (``nanobind: leaked ...`` lines with OpenImageIO builds on nanobind);
- 13: a full disk while the style histogram cache is written printed
  ``Exception ignored in ZipFile.__del__`` tracebacks, and left temporaries.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from tests.color.conftest import FAST_ARGS, SAMPLES, small_copy, write_array

NAME = os.fsdecode(b"caf\xe9")  # 'caf\udce9': the byte 0xE9 alone is not UTF-8


def _photos(folder: Path) -> Path:
    folder.mkdir()
    rng = np.random.default_rng(2)
    write_array(folder / "plain.png", rng.random((24, 32, 3)), "uint8")
    os.rename(write_array(folder / "x.png", rng.random((24, 32, 3)), "uint8"),
              folder / f"{NAME}.png")
    return folder


def wbcgrade(*args) -> subprocess.CompletedProcess:
    """The CLI in a process of its own, as from a shell (the names reach it as bytes)."""
    return subprocess.run([sys.executable, "-c", "from wbcgrade.cli import main; main()",
                           *map(str, args)], capture_output=True, timeout=300)


def _ok(run: subprocess.CompletedProcess) -> None:
    assert run.returncode == 0, run.stderr.decode("utf-8", "replace")
    assert b"Traceback" not in run.stderr


@pytest.mark.slow
def test_apply_reads_and_writes_names_that_are_not_utf8(tmp_path):
    photos = _photos(tmp_path / "in")
    folder = tmp_path / os.fsdecode(b"out\xff")
    folder.mkdir()
    out, lut = folder / f"{NAME}.jpg", folder / f"{NAME}.cube"
    _ok(wbcgrade("apply", photos / f"{NAME}.png", "--preset", "warm", "-o", out, "--lut", lut,
                 *FAST_ARGS))
    assert out.stat().st_size > 0 and lut.stat().st_size > 0
    assert b"caf\\xe9.png" in lut.read_bytes()  # the header names it readably
    assert sorted(os.listdir(folder)) == sorted([out.name, lut.name])  # no temporaries


@pytest.mark.slow
def test_batch_and_report_go_through_names_that_are_not_utf8(tmp_path):
    photos = _photos(tmp_path / "in")
    for jobs in ("1", "2"):
        out = tmp_path / os.fsdecode(b"graded\xe9" + jobs.encode())
        _ok(wbcgrade("batch", photos, "-o", out, "--preset", "warm", "-j", jobs, *FAST_ARGS))
        assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == \
            sorted([f"{NAME}.png", "plain.png"]), jobs
    report = tmp_path / os.fsdecode(b"report\xe9")
    _ok(wbcgrade("report", photos, "-o", report, "--preset", "warm", *FAST_ARGS))
    assert (report / "index.html").is_file() and len(list((report / "sheets").iterdir())) == 2


@pytest.mark.slow
def test_a_full_disk_under_the_histogram_cache_is_one_line(tmp_path):
    """Every cache file the run creates writes into /dev/full (ENOSPC from the kernel)."""
    styles = tmp_path / "styles"
    styles.mkdir()
    for name in ("coffee", "flower", "sunset"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", 48)
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "chelsea.jpg", 48)
    cache = tmp_path / "cache"
    script = textwrap.dedent(f"""
        import os, sys, tempfile
        real = tempfile.mkstemp

        def full_mkstemp(*args, **kwargs):
            fd, path = real(*args, **kwargs)
            if path.startswith({str(cache)!r}):  # the cache's files only, not the output
                os.unlink(path)  # the writer opens its temporary by name: /dev/full
                os.symlink("/dev/full", path)
            return fd, path

        tempfile.mkstemp = full_mkstemp
        from wbcgrade.cli import main
        main()
    """)
    run = subprocess.run([sys.executable, "-c", script, "apply", str(photo), "--style",
                          str(styles), "-o", str(tmp_path / "out.jpg"), "--cache-dir",
                          str(cache), *[a for a in FAST_ARGS if a != "--no-cache"]],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "Exception ignored" not in run.stderr and "Traceback" not in run.stderr, run.stderr
    lines = [ln for ln in run.stderr.splitlines() if "cache" in ln]
    assert len(lines) == 1 and "No space left on device" in lines[0], run.stderr
    assert [p for p in cache.rglob("*") if p.is_file()] == []  # no temporaries left behind
    assert (tmp_path / "out.jpg").is_file()


def test_workers_release_cached_library_objects_at_exit():
    from wbcgrade._executor import release_cached_objects
    from wbcgrade.color import colorspace

    colorspace.resolve_space("acescct")  # caches OpenImageIO's ColorConfig
    assert colorspace._config.cache_info().currsize >= 1
    release_cached_objects()
    assert colorspace._config.cache_info().currsize == 0
    assert colorspace.resolve_space("acescct")  # and it comes back when needed
