"""``wbcgrade video`` under hostile input (issue 21, cases 4, 5, 7-10, 14, 15).

Every test calls the command as a user would (``CliRunner`` or a process of
its own where signals or a hang are the point) on tiny clips made here with
the bundled ffmpeg, and checks that nothing is lost silently: alpha, frames,
bit depth and field order are kept or the loss is said; playlists do not
hang; a killed run leaves no work folder; every output goes out together or
not at all; ffmpeg's failures carry ffmpeg's own reason and come before the fit.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.color.conftest import THREE_STYLES
from tests.conftest import run_cli
from wbcgrade.color.mapping.lut import read_cube
from wbcgrade.video.ffmpeg import decode_frames, ffmpeg_exe, probe

CLI = [sys.executable, "-c", "from wbcgrade.cli import main; main()"]
FAST = ["--preset", str(THREE_STYLES), "--mode", "palette", "--bins", "16", "--no-cache",
        "--weights", "0.5,0.3,0.2"]


def _ffmpeg(*args: str, **kwargs) -> None:
    subprocess.run([ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-y", *args],
                   check=True, timeout=60, **kwargs)


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> dict[str, Path]:
    """Ten frames of 64x48 at 25 fps each: ProRes 4444 with an alpha ramp, PNG-in-MOV RGBA,
    12-bit HEVC, interlaced (top field first) H.264, an odd-sized 4:2:0 FFV1 clip, an FFV1
    clip with a subtitle stream; and two seconds of noise in an MP4 with its index first,
    cut in half."""
    folder = tmp_path_factory.mktemp("hostile")
    src = "testsrc2=size=64x48:rate=25:duration=0.4"
    out = {name: folder / name for name in ("alpha.mov", "rgba.mov", "hevc12.mp4",
                                            "interlaced.mp4", "odd.mkv", "subtitles.mkv",
                                            "truncated.mp4")}
    _ffmpeg("-f", "lavfi", "-i", src + ",format=yuva444p10le,geq=lum='p(X,Y)':cb='p(X,Y)':"
            "cr='p(X,Y)':a='X*16'", "-c:v", "prores_ks", "-profile:v", "4",
            str(out["alpha.mov"]))
    _ffmpeg("-f", "lavfi", "-i", src + ",format=rgba,geq=r='r(X,Y)':g='g(X,Y)':b='b(X,Y)':"
            "a='X*4'", "-c:v", "png", str(out["rgba.mov"]))
    _ffmpeg("-f", "lavfi", "-i", src, "-c:v", "libx265", "-pix_fmt", "yuv420p12le",
            "-x265-params", "log-level=error", str(out["hevc12.mp4"]))
    _ffmpeg("-f", "lavfi", "-i", src, "-vf", "setfield=tff", "-flags", "+ildct+ilme",
            "-c:v", "libx264", "-pix_fmt", "yuv420p", "-field_order", "tt",
            str(out["interlaced.mp4"]))
    odd = np.random.default_rng(0).integers(0, 256, 10 * (63 * 47 + 2 * 32 * 24), np.uint8)
    _ffmpeg("-f", "rawvideo", "-pix_fmt", "yuv420p", "-s", "63x47", "-r", "25", "-i", "pipe:0",
            "-c:v", "ffv1", str(out["odd.mkv"]), input=odd.tobytes())
    srt = folder / "s.srt"
    srt.write_text("1\n00:00:00,000 --> 00:00:00,300\nhello\n")
    _ffmpeg("-f", "lavfi", "-i", src, "-i", str(srt), "-c:v", "ffv1", "-c:s", "srt",
            str(out["subtitles.mkv"]))
    full = folder / "full.mp4"
    _ffmpeg("-f", "lavfi", "-i", "testsrc2=size=64x48:rate=25:duration=2,noise=alls=40:allf=t",
            "-c:v", "libx264", "-pix_fmt", "yuv420p", "-movflags", "+faststart", str(full))
    data = full.read_bytes()
    out["truncated.mp4"].write_bytes(data[:len(data) // 2])
    out["cut.mp4"] = folder / "cut.mp4"  # a cut by stream copy: an edit list trims packets
    _ffmpeg("-ss", "0.5", "-i", str(full), "-c", "copy", str(out["cut.mp4"]))
    return out


def run(*args):
    return run_cli("video", *map(str, args))


def refused(result, *words) -> str:
    assert result.exit_code == 1, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert lines and lines[-1].startswith("Error:"), result.output
    assert "Traceback" not in result.output
    for word in words:
        assert word in lines[-1], lines[-1]
    return lines[-1]


def plane(path: Path, vf: str, pix_fmt: str, dtype) -> np.ndarray:
    """Every frame through the filter ``vf`` as raw ``pix_fmt`` values, (n, h, w[, c])."""
    info = probe(path)
    raw = subprocess.run([ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-i", str(path),
                          "-vf", vf, "-f", "rawvideo", "-pix_fmt", pix_fmt, "pipe:1"],
                         check=True, capture_output=True, timeout=60).stdout
    return np.frombuffer(raw, dtype=dtype).reshape(info.frames, info.height, info.width, -1)


def outputs(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# --- 4: alpha ----------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("name, codec, suffix", [("alpha.mov", "prores", ".mov"),
                                                 ("rgba.mov", "ffv1", ".mkv")])
def test_alpha_is_carried_through_untouched_and_the_colour_graded(clips, tmp_path, name, codec,
                                                                   suffix):
    out = tmp_path / f"graded{suffix}"
    result = run(clips[name], "-o", out, "--codec", codec, *FAST)
    assert result.exit_code == 0, result.output
    assert probe(out).alpha and probe(out).frames == 10
    before = plane(clips[name], "format=rgba64le", "rgba64le", "<u2").astype(np.int64)
    after = plane(out, "format=rgba64le", "rgba64le", "<u2").astype(np.int64)
    assert before[..., 3].std() > 1000  # a real ramp of alpha
    assert np.abs(after[..., 3] - before[..., 3]).max() <= 64  # 10-bit ProRes: 1 step of 2^6
    assert np.abs(after[..., :3] - before[..., :3]).mean() > 5 * 257  # the colours graded


@pytest.mark.slow
def test_transparent_pixels_do_not_count_in_the_grade(tmp_path):
    """A clip whose left half is transparent magenta grades as its opaque right half alone."""
    half = tmp_path / "half.mov"
    _ffmpeg("-f", "lavfi", "-i", "testsrc2=size=64x48:rate=25:duration=0.2,format=rgba,"
            "geq=r='if(lt(X,32),255,r(X,Y))':g='if(lt(X,32),0,g(X,Y))':"
            "b='if(lt(X,32),255,b(X,Y))':a='if(lt(X,32),0,255)'", "-c:v", "png", str(half))
    opaque = tmp_path / "opaque.mkv"
    _ffmpeg("-i", str(half), "-vf", "crop=32:48:32:0,format=bgr0", "-c:v", "ffv1", str(opaque))
    tables = []
    for clip in (half, opaque):
        lut = tmp_path / f"{clip.stem}.cube"
        result = run(clip, "-o", tmp_path / f"{clip.stem}_graded.mkv", "--codec", "ffv1",
                     "--lut", lut, *FAST)
        assert result.exit_code == 0, result.output
        tables.append(read_cube(lut).table)
    assert np.abs(tables[0] - tables[1]).max() < 1e-5


def test_alpha_a_codec_cannot_store_is_refused_in_one_line(clips, tmp_path):
    line = refused(run(clips["alpha.mov"], "-o", tmp_path / "graded.mp4", *FAST),
                   "alpha", "--codec x264", "prores")
    assert "ffv1" in line
    assert outputs(tmp_path) == []


# --- 5: truncated ------------------------------------------------------------------------------

def test_a_truncated_clip_is_refused_not_graded_short(clips, tmp_path):
    refused(run(clips["truncated.mp4"], "-o", tmp_path / "graded.mp4", *FAST),
            "truncated", "2.00 s")
    assert outputs(tmp_path) == []


@pytest.mark.slow
def test_a_clip_cut_by_stream_copy_is_graded_to_its_visible_length(clips, tmp_path):
    """Not a truncation: the probe counts 50 packets, 37 frames are shown; all 37 come out."""
    out = tmp_path / "graded.mp4"
    result = run(clips["cut.mp4"], "-o", out, *FAST)
    assert result.exit_code == 0, result.output
    def shown(path):
        return sum(1 for _ in decode_frames(path, probe(path)))

    assert probe(out).frames == shown(out) == shown(clips["cut.mp4"])
    assert 30 < shown(out) < 50


# --- 7: every output together or none ----------------------------------------------------------

@pytest.mark.slow
def test_a_lut_that_cannot_be_written_publishes_no_clip(clips, tmp_path, monkeypatch):
    """A full disk under --lut (case 15 too: the message names the LUT, not a bare
    [Errno 28]); a rerun then works (nothing left that 'exists')."""
    import wbcgrade.video.workflow as workflow

    real = workflow.write_cube

    def full_beside_the_clip(path, *args, **kwargs):
        if Path(path).parent == tmp_path:
            with open(path, "wb") as handle:
                handle.write(b"LUT_3D_SIZE")
                raise OSError(28, "No space left on device")
        return real(path, *args, **kwargs)

    monkeypatch.setattr(workflow, "write_cube", full_beside_the_clip)
    out, lut = tmp_path / "graded.mkv", tmp_path / "grade.cube"
    args = [clips["rgba.mov"], "-o", out, "--codec", "ffv1", "--lut", lut, *FAST]
    refused(run(*args), f"{lut}: No space left on device (disk full)")
    assert outputs(tmp_path) == []
    monkeypatch.setattr(workflow, "write_cube", real)
    assert run(*args).exit_code == 0
    assert outputs(tmp_path) == ["grade.cube", "graded.mkv"]


@pytest.mark.slow
def test_a_report_that_cannot_be_written_publishes_no_clip(clips, tmp_path, monkeypatch):
    import wbcgrade.video.report as report

    def read_only(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(report, "write_sheet", read_only)
    out, lut = tmp_path / "graded.mkv", tmp_path / "grade.cube"
    refused(run(clips["rgba.mov"], "-o", out, "--codec", "ffv1", "--lut", lut, "--report",
                tmp_path / "report", *FAST), "Permission denied")
    assert outputs(tmp_path) == []


# --- 8: bit depth and interlacing --------------------------------------------------------------

@pytest.mark.slow
def test_twelve_bits_are_kept_where_the_codec_can_and_said_where_not(clips, tmp_path):
    kept = tmp_path / "x265.mp4"
    result = run(clips["hevc12.mp4"], "-o", kept, "--codec", "x265", *FAST)
    assert result.exit_code == 0 and "Warning" not in result.output, result.output
    assert probe(kept).pix_fmt == "yuv420p12le"
    result = run(clips["hevc12.mp4"], "-o", tmp_path / "x264.mp4", *FAST)
    assert result.exit_code == 0, result.output
    warning = [ln for ln in result.output.splitlines() if ln.startswith("Warning:")]
    assert len(warning) == 1 and "12-bit footage written 10-bit" in warning[0]
    assert "--codec x265" in warning[0]


@pytest.mark.slow
@pytest.mark.parametrize("codec, suffix", [("x264", ".mp4"), ("ffv1", ".mkv")])
def test_interlaced_footage_keeps_its_field_order(clips, tmp_path, codec, suffix):
    assert probe(clips["interlaced.mp4"]).field_order == "tt"
    out = tmp_path / f"graded{suffix}"
    result = run(clips["interlaced.mp4"], "-o", out, "--codec", codec, *FAST)
    assert result.exit_code == 0 and "Warning" not in result.output, result.output
    assert probe(out).field_order in ("tt", "tb")  # top field first (Matroska: "coded")


# --- 9: playlists ------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("name, text", [
    ("list.ffconcat", "ffconcat version 1.0\nfile 'fifo.mp4'\n"),
    ("list.m3u8", "#EXTM3U\n#EXT-X-TARGETDURATION:1\n#EXTINF:1,\nfifo.ts\n#EXT-X-ENDLIST\n")])
def test_a_playlist_pointing_at_a_fifo_is_refused_at_once(tmp_path, name, text):
    for fifo in ("fifo.mp4", "fifo.ts"):
        os.mkfifo(tmp_path / fifo)
    (tmp_path / name).write_text(text)
    start = time.monotonic()
    run_ = subprocess.run([*CLI, "video", name, "-o", "o.mp4",
                           *FAST], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert time.monotonic() - start < 30
    assert run_.returncode == 1 and "Traceback" not in run_.stderr, run_.stderr
    assert run_.stderr.strip().splitlines()[-1].startswith(f"Error: {name}: a playlist")
    assert not (tmp_path / "o.mp4").exists()


# --- 10: kills ---------------------------------------------------------------------------------

def _start(clip: Path, out: Path, temp: Path) -> subprocess.Popen:
    env = {**os.environ, "TMPDIR": str(temp)}
    return subprocess.Popen([*CLI, "video", str(clip), "-o",
                             str(out), "--codec", "ffv1", *FAST], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _work_folders(temp: Path) -> list[Path]:
    return [p for p in temp.iterdir() if p.name.startswith("wbcgrade-video-")]


def _wait_for_work_folder(proc: subprocess.Popen, temp: Path) -> None:
    deadline = time.monotonic() + 60
    while not _work_folders(temp):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.005)


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_clean_up_like_ctrl_c(clips, tmp_path, signum):
    temp, out = tmp_path / "tmp", tmp_path / "out"
    temp.mkdir()
    out.mkdir()
    proc = _start(clips["rgba.mov"], out / "graded.mkv", temp)
    _wait_for_work_folder(proc, temp)
    proc.send_signal(signum)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signum, stderr
    assert "Traceback" not in stderr and stderr.strip().splitlines()[-1].startswith("Terminated")
    assert _work_folders(temp) == [] and outputs(out) == []


@pytest.mark.slow
def test_the_work_folder_of_a_killed_run_is_removed_by_the_next(clips, tmp_path):
    temp, out = tmp_path / "tmp", tmp_path / "out"
    temp.mkdir()
    out.mkdir()
    proc = _start(clips["rgba.mov"], out / "killed.mkv", temp)
    _wait_for_work_folder(proc, temp)
    proc.kill()
    proc.wait()
    (left,) = _work_folders(temp)
    hour_ago = time.time() - 3600
    for path in (left, *left.iterdir()):
        os.utime(path, (hour_ago, hour_ago))
    proc = _start(clips["rgba.mov"], out / "graded.mkv", temp)
    assert proc.wait(timeout=120) == 0, proc.communicate()
    assert _work_folders(temp) == []


# --- 14: ffmpeg's own reasons, before the fit ---------------------------------------------------

@pytest.fixture
def no_fit(monkeypatch):
    import wbcgrade.video.workflow as workflow

    def forbidden(*args, **kwargs):
        raise AssertionError("the fit ran before the encoding was checked")

    monkeypatch.setattr(workflow, "shot_grade", forbidden)


def test_a_stream_the_container_cannot_hold_is_ffmpegs_reason_before_the_fit(clips, tmp_path,
                                                                              no_fit):
    line = refused(run(clips["subtitles.mkv"], "-o", tmp_path / "graded.mp4", *FAST),
                   "subrip", "not currently supported in container")
    assert "Terminating thread" not in line and "return code -22" not in line
    assert outputs(tmp_path) == []


def test_an_odd_size_the_codec_cannot_store_is_ffmpegs_reason_before_the_fit(clips, tmp_path,
                                                                           no_fit):
    refused(run(clips["odd.mkv"], "-o", tmp_path / "graded.mp4", *FAST),
            "width not divisible by 2 (63x47)")
    assert outputs(tmp_path) == []


# --- 15: a full TMPDIR ---------------------------------------------------------------------------

@pytest.mark.slow
def test_a_full_temporary_folder_is_named(clips, tmp_path, monkeypatch):
    import wbcgrade.video.workflow as workflow

    def full(path, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(workflow, "write_cube", full)
    line = refused(run(clips["rgba.mov"], "-o", tmp_path / "graded.mkv", "--codec", "ffv1",
                       *FAST), "wbcgrade-video-", "No space left on device", "TMPDIR")
    assert "[Errno" not in line
    assert outputs(tmp_path) == []
