"""Faults while grading one photo: full disks, killed writers, bombs, bad outputs (issue 12)."""

from __future__ import annotations

import os
import re
import resource
import signal
import struct
import subprocess
import sys
import textwrap
import time
import zlib
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.color.conftest import FAST_ARGS, write_array
from wbcgrade import _publish
from wbcgrade.color.io.images import (
    Image,
    check_output_path,
    read_image,
    set_max_image_pixels,
    write_image,
)
from wbcgrade.errors import InputError

FSIZE_LIMIT = 40 * 1024  # as `ulimit -f 40`


def noise(path: Path, size: int = 160, seed: int = 1) -> Path:
    """A photo of random noise: it compresses badly, so its graded copy is large."""
    pixels = np.random.default_rng(seed).random((size, size, 3)).astype(np.float32)
    return write_array(path, pixels, "uint8")


def _limit_file_size() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (FSIZE_LIMIT, FSIZE_LIMIT))


def wbcgrade(*args, cwd: Path, limit_size: bool = False, **kwargs) -> subprocess.CompletedProcess:
    """Run the CLI in its own process (optionally under a 40 KiB file size limit)."""
    return subprocess.run([sys.executable, "-c", "from wbcgrade.cli import main; main()",
                           *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=120,
                          preexec_fn=_limit_file_size if limit_size else None, **kwargs)


def hidden_files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _apply_args(photo: Path, out: Path) -> list[str]:
    return ["apply", str(photo), "--preset", "warm", "-o", str(out), *FAST_ARGS]


# -- 1, 2: a full disk ------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("ext", ["png", "jpg"])
def test_a_write_that_hits_the_file_size_limit_is_an_error_not_a_file(tmp_path, ext):
    """PNG reported the short write only via geterror() (published as success); libjpeg
    ended the process from inside the encoder (exit 1, a hidden temporary left)."""
    photo = noise(tmp_path / f"c.{ext}", 256 if ext == "jpg" else 160)
    out = tmp_path / f"c_graded.{ext}"
    run = wbcgrade(*_apply_args(photo, out), cwd=tmp_path, limit_size=True)
    assert run.returncode == 1, run.stdout + run.stderr
    lines = run.stderr.strip().splitlines()
    assert lines and lines[-1].startswith(f"Error: {out}: write failed"), run.stderr
    assert "disk full" in lines[-1]
    assert "Traceback" not in run.stderr and "Output file write error" not in run.stderr
    assert "wrote" not in run.stdout
    assert not out.exists()
    assert hidden_files(tmp_path) == []
    # Without the limit the same command succeeds (the failure was the limit's).
    run = wbcgrade(*_apply_args(photo, out), cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert out.stat().st_size > FSIZE_LIMIT
    assert read_image(out).pixels.shape == (photo_size := read_image(photo).pixels.shape)
    assert photo_size[0] in (160, 256)


def test_write_image_checks_what_it_wrote(tmp_path, monkeypatch):
    """A writer that returns success while its geterror() says the write failed."""
    pixels = np.full((8, 8, 3), 0.5, np.float32)
    like = Image(pixels=pixels, spec=oiio.ImageSpec(8, 8, 3, "uint8"), format_name="png")

    class Liar:
        def __init__(self, real):
            self.real = real

        def __getattr__(self, name):
            return getattr(self.real, name)

        def geterror(self):
            self.real.geterror()
            return "Write error at position 4096, could only write 10/8192 bytes"

    real_create = oiio.ImageOutput.create
    monkeypatch.setattr(oiio.ImageOutput, "create",
                        staticmethod(lambda name, *a: Liar(real_create(name, *a))))
    with pytest.raises(OSError, match="write failed"):
        write_image(tmp_path / "out.png", pixels, like)
    assert list(tmp_path.iterdir()) == []


# -- 3: SIGKILL during a write ----------------------------------------------------------------

KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    from wbcgrade._publish import atomic_path
    with atomic_path(sys.argv[1]) as tmp:
        open(tmp, "wb").write(b"half a photo")
        if sys.argv[2] == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        print("ready", flush=True)
        sys.stdin.readline()  # hold the temporary (locked) until told to go on
""")


def _age(path: Path, seconds: float = 3600) -> None:
    old = time.time() - seconds
    os.utime(path, (old, old))


@pytest.mark.slow
def test_a_rerun_removes_the_temporary_of_a_killed_run_only(tmp_path, photo, cli):
    out = tmp_path / "chelsea_graded.jpg"
    killed = subprocess.run([sys.executable, "-c", KILLED_WRITER, str(out), "kill"],
                            capture_output=True, timeout=60)
    assert killed.returncode == -signal.SIGKILL
    (stale,) = [p for p in tmp_path.iterdir() if p.name.startswith(".chelsea_graded.")]
    assert _publish.TEMP_MARK in stale.name
    _age(stale)
    old_style = tmp_path / ".chelsea_graded.ab12cd_3.jpg"  # the previous naming, unlocked
    old_style.write_bytes(b"x")
    _age(old_style)
    unrelated = tmp_path / ".chelsea_graded.jpg.notes"
    unrelated.write_bytes(b"mine")
    _age(unrelated)
    # A live run's temporary (locked), however old, is never removed.
    live_target = tmp_path / "other.jpg"
    live = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(live_target), "hold"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert live.stdout.readline().strip() == "ready"
        (live_tmp,) = [p for p in tmp_path.iterdir() if p.name.startswith(".other.")]
        _age(live_tmp)
        result = cli(*_apply_args(tmp_path / "chelsea.jpg", out))
        assert result.exit_code == 0, result.output
        assert not stale.exists() and not old_style.exists()
        assert unrelated.exists() and live_tmp.exists()
    finally:
        live.communicate("go\n", timeout=60)
    assert live.returncode == 0
    assert live_target.read_bytes() == b"half a photo" and not live_tmp.exists()


# -- 7: outputs checked before any work, photo and LUT published together -------------------

@pytest.fixture
def no_grading(monkeypatch):
    """Fail the test if a photo is graded."""
    import wbcgrade.photos.workflow as workflow

    def forbidden(*args, **kwargs):
        raise AssertionError("graded before checking the outputs")

    monkeypatch.setattr(workflow, "grade_photo", forbidden)


def test_unknown_output_format_is_refused_before_any_work(photo, tmp_path, no_grading, cli):
    result = cli(*_apply_args(photo, tmp_path / "x.xyz"))
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1].startswith(
        f"Error: {tmp_path / 'x.xyz'}: cannot write this file type")


@pytest.mark.slow
def test_a_failing_lut_publishes_no_photo(photo, tmp_path, monkeypatch, cli):
    import wbcgrade.color.mapping.lut as lut_module

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(lut_module, "write_cube", full_disk)
    out, lut = tmp_path / "graded.jpg", tmp_path / "grade.cube"
    result = cli(*_apply_args(photo, out), "--lut", str(lut))
    assert result.exit_code == 1
    assert "No space left on device" in result.output
    assert not out.exists() and not lut.exists()
    assert hidden_files(tmp_path) == []


# -- 8: decompression bombs ------------------------------------------------------------------

def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))


def bomb_png(path: Path, width: int = 60000, height: int = 60000) -> Path:
    """A small PNG whose header announces width x height RGB pixels (rows of zeros)."""
    rows = zlib.compress(b"\0" * (1 + 3 * width) * 4, 9)  # a few rows: enough for a header
    path.write_bytes(b"\x89PNG\r\n\x1a\n"
                     + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
                     + _png_chunk(b"IDAT", rows) + _png_chunk(b"IEND", b""))
    return path


def test_a_decompression_bomb_is_refused_from_its_header(tmp_path, cli):
    bomb = bomb_png(tmp_path / "bomb.png")
    start = time.perf_counter()
    # Refused by our pixel limit, or (OpenImageIO >= 3.2) already by OpenImageIO's own
    # check of the header against the file's size: either way before any pixel is decoded.
    refusal = r"3600000000 megapixels|3600\.0 megapixels|header claims a \d+ MB image"
    with pytest.raises(InputError, match=refusal):
        read_image(bomb)
    assert time.perf_counter() - start < 1.0
    result = cli("apply", str(bomb), "--preset", "warm", *FAST_ARGS)
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.output
    assert re.search(refusal, lines[0])
    if "megapixels" in lines[0]:
        assert "over the limit of 200 megapixels" in lines[0] and "--max-image-pixels" in lines[0]


@pytest.mark.slow
def test_the_pixel_limit_can_be_raised_or_lowered(tmp_path, photo, monkeypatch, cli):
    small = write_array(tmp_path / "small.png", np.full((20, 30, 3), 0.5, np.float32), "uint8")
    try:
        set_max_image_pixels(599)
        with pytest.raises(InputError, match="over the limit"):
            read_image(small)
        set_max_image_pixels(600)
        assert read_image(small).pixels.shape == (20, 30, 3)
        set_max_image_pixels(None)
        monkeypatch.setenv("WBCGRADE_MAX_IMAGE_PIXELS", "100")
        with pytest.raises(InputError, match="over the limit"):
            read_image(small)
        # The command-line option wins over the environment, for this run only.
        out = tmp_path / "out.jpg"
        result = cli("apply", str(photo), "--preset", "warm", "-o",
                     str(out), "--max-image-pixels", "100000", *FAST_ARGS)
        assert result.exit_code == 0, result.output
        result = cli("apply", str(photo), "--preset", "warm", "-o",
                     str(tmp_path / "out2.jpg"), *FAST_ARGS)
        assert result.exit_code == 1 and "over the limit of 0.0001 megapixels" in result.output
    finally:
        set_max_image_pixels(None)


@pytest.mark.parametrize("command", [["look", "learn", "{before}", "{after}", "-o", "{out}.cube"],
                                     ["look", "extract", "{after}", "-o", "{out}.cube"],
                                     ["preset", "build", "{after}", "-o", "{out}.npz"]])
def test_every_command_that_reads_photos_takes_the_pixel_limit(tmp_path, command, cli):
    before, after = tmp_path / "before", tmp_path / "after"
    for folder in (before, after):
        folder.mkdir()
        for name in ("a", "b"):
            write_array(folder / f"{name}.png", np.full((20, 30, 3), 0.5, np.float32), "uint8")
    args = [a.format(before=before, after=after, out=tmp_path / "out") for a in command]
    try:
        result = cli(*args, "--max-image-pixels", "100")
        assert result.exit_code == 1 and "Traceback" not in result.output
        # each photo left out says which flag lets it in, as the command line spells it
        refused = [line for line in result.output.splitlines() if "over the limit" in line]
        assert refused and all("--max-image-pixels 600 " in line for line in refused)
        assert not list(tmp_path.glob("out.*"))
    finally:
        set_max_image_pixels(None)


# -- 12: outputs that are not regular files --------------------------------------------------

def test_device_and_pipe_outputs_are_refused(tmp_path, photo, no_grading, cli):
    with pytest.raises(InputError, match="not a regular file"):
        check_output_path("/dev/null", overwrite=True)
    fifo = tmp_path / "graded.jpg"
    os.mkfifo(fifo)
    result = cli(*_apply_args(photo, fifo), "--overwrite")
    assert result.exit_code == 1
    assert "not a regular file" in result.output.strip().splitlines()[-1]
    assert fifo.is_fifo()
    with pytest.raises(InputError, match="not a regular file"), _publish.atomic_path(fifo):
        pass
    assert fifo.is_fifo() and hidden_files(tmp_path) == []


@pytest.mark.slow  # over 5 s of the fast tier: the whole suite runs it
def test_a_report_under_a_file_size_limit_fails_and_publishes_no_truncated_sheet(tmp_path):
    """``report`` under a file size limit exited 0 ("failed 0") with a PNG cut at the limit:
    each sheet is encoded in memory and checked, so the photo fails and no sheet is
    published that does not decode."""
    photos = tmp_path / "photos"
    photos.mkdir()
    noise(photos / "a.jpg", 160)
    run = wbcgrade("report", photos, "--preset", "warm", "-o", tmp_path / "rep", *FAST_ARGS,
                   cwd=tmp_path, limit_size=True)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "failed 1" in run.stdout + run.stderr and "Traceback" not in run.stderr
    for sheet in (tmp_path / "rep").rglob("*.png"):
        buf = oiio.ImageBuf(str(sheet))
        assert buf.read() and not buf.has_error, sheet
