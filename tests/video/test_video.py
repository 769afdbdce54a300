"""``wbcgrade video`` end to end on tiny clips made with the bundled ffmpeg (issue 15).

Exactness is checked on a lossless RGB clip (FFV1, ``bgr0``) graded into
FFV1: nothing is lost between the pixels the LUT sees and the ones stored, so
every output frame must equal the LUT (read back from ``--lut``) applied to
the input frame by the library's own trilinear interpolation, to within
ffmpeg's tetrahedral interpolation and 8-bit rounding (measured: 0.4/255 on
average, 1.0-1.6/255 at most). The default x264 path (yuv420p, CRF 18) halves
chroma resolution and is lossy, which at 64x48 on a test pattern's sharp
colour edges moves single pixels by tens of levels, so there only each
frame's mean colour is compared.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from wbcgrade.cli import main
from wbcgrade.color.lut import read_cube
from wbcgrade.color.remap import apply_color_map
from wbcgrade.video.ffmpeg import decode_frames, ffmpeg_exe, probe
from wbcgrade.video.shots import frame_tables, lut_schedule

FAST = ["--preset", "warm", "--bins", "32", "--no-cache"]
WEIGHTS = ["--weights", "0.5,0.3,0.2"]  # skip the fit where the test is about frames


def _ffmpeg(*args: str) -> None:
    subprocess.run([ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-y", *args],
                   check=True, timeout=60)


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> dict[str, Path]:
    """32 frames of 64x48 at 25 fps with a 440 Hz audio track: x264 + AAC (BT.709 tags),
    lossless RGB (FFV1 + PCM), and an RGB clip with a hard cut at frame 16."""
    folder = tmp_path_factory.mktemp("clips")
    src = "testsrc2=size=64x48:rate=25:duration=1.28"
    sine = "sine=frequency=440:sample_rate=48000:duration=1.28"
    out = {"x264": folder / "plain.mp4", "rgb": folder / "rgb.mkv", "cut": folder / "cut.mkv"}
    _ffmpeg("-f", "lavfi", "-i", src, "-f", "lavfi", "-i", sine,
            "-vf", "setparams=range=tv:colorspace=bt709:color_primaries=bt709:color_trc=bt709",
            "-c:v", "libx264", "-pix_fmt", "yuv420p", "-c:a", "aac", str(out["x264"]))
    _ffmpeg("-f", "lavfi", "-i", src, "-f", "lavfi", "-i", sine, "-vf", "format=bgr0",
            "-c:v", "ffv1", "-c:a", "pcm_s16le", str(out["rgb"]))
    half = "testsrc2=size=64x48:rate=25:duration=0.64"
    _ffmpeg("-f", "lavfi", "-i", half, "-f", "lavfi", "-i",
            half + ",hue=h=120,eq=brightness=-0.15", "-f", "lavfi", "-i", sine,
            "-filter_complex", "[0:v][1:v]concat=n=2:v=1:a=0,format=bgr0[v]",
            "-map", "[v]", "-map", "2:a", "-c:v", "ffv1", "-c:a", "pcm_s16le", str(out["cut"]))
    return out


def run(*args) -> object:
    result = CliRunner().invoke(main, ["video", *map(str, args)])
    return result


def frames(path: Path) -> np.ndarray:
    """All frames as (n, h, w, 3) float32 in [0, 1] (the clip's own matrix and range)."""
    return np.stack(list(decode_frames(path, probe(path)))).astype(np.float32) / 255


def mean_steps(video: np.ndarray) -> np.ndarray:
    """Largest change of a channel's frame mean between consecutive frames, per frame pair."""
    return np.abs(np.diff(video.mean(axis=(1, 2)), axis=0)).max(axis=1)


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_default_x264_keeps_frames_rate_audio_tags_and_writes_lut_and_report(clips, tmp_path):
    out, lut, report = tmp_path / "graded.mp4", tmp_path / "grade.cube", tmp_path / "report"
    result = run(clips["x264"], "-o", out, *FAST, "--lut", lut, "--report", report)
    assert result.exit_code == 0, result.output
    src, dst = probe(clips["x264"]), probe(out)
    assert (dst.frames, dst.fps, dst.width, dst.height) == (32, src.fps, 64, 48)
    assert dst.streams == ["video", "audio"] and dst.codec == "h264"
    assert dst.pix_fmt == "yuv420p" and dst.tags() == src.tags()
    assert dst.colorspace == dst.primaries == dst.transfer == "bt709"
    # lossy 4:2:0: compare each frame's mean colour with the LUT applied to the input
    before, after = frames(clips["x264"]), frames(out)
    expected = apply_color_map(before, read_cube(lut).table)
    gap = np.abs(after.mean(axis=(1, 2)) - expected.mean(axis=(1, 2))).max()
    assert gap < 3 / 255  # measured 2.1/255: the LUT is not linear, chroma is averaged after it
    assert np.abs(after - expected).mean() < 5 / 255  # measured 2.9/255
    assert np.abs(after - before).mean() > 5 / 255  # it did grade
    document = json.loads((report / "report.json").read_text())
    assert len(document["shots"]) == 1 and document["shots"][0]["sampled_frames"] == [0, 25]
    assert (report / document["shots"][0]["sheet"]).stat().st_size > 1000
    assert {w["style"] for w in document["shots"][0]["weights"]} == {"coffee", "flower", "sunset"}


def test_every_frame_is_the_lut_applied_to_the_input_and_nothing_flickers(clips, tmp_path):
    out, lut = tmp_path / "graded.mkv", tmp_path / "grade.cube"
    result = run(clips["rgb"], "-o", out, "--codec", "ffv1", *FAST, *WEIGHTS, "--lut", lut)
    assert result.exit_code == 0, result.output
    dst = probe(out)
    assert (dst.frames, dst.fps, dst.pix_fmt) == (32, 25.0, "bgr0")
    assert dst.streams == ["video", "audio"]
    before, after = frames(clips["rgb"]), frames(out)
    expected = apply_color_map(before, read_cube(lut).table)
    error = np.abs(after - expected) * 255
    assert error.max() <= 2 and error.mean() < 0.6, (error.max(), error.mean())
    assert mean_steps(after).max() <= mean_steps(before).max() + 1 / 255


def test_per_shot_two_grades_blended_at_the_cut_and_no_jump_elsewhere(clips, tmp_path):
    out, lut = tmp_path / "graded.mkv", tmp_path / "grade.cube"
    result = run(clips["cut"], "-o", out, "--codec", "ffv1", *FAST, *WEIGHTS, "--per-shot",
                 "--sample-every", "0.4", "--lut", lut, "--json")
    assert result.exit_code == 0, result.output
    document = json.loads(result.output[result.output.index("{"):])
    assert document["cuts"] == [16]
    assert [(s["first_frame"], s["last_frame"]) for s in document["shots"]] == [(0, 15), (16, 31)]
    tables = [read_cube(tmp_path / f"grade_shot0{k}.cube").table for k in (1, 2)]
    assert np.abs(tables[0] - tables[1]).max() > 0.05  # two different grades
    per_frame = frame_tables(lut_schedule([(0, 15), (16, 31)], tables, 8), 32)
    before, after = frames(clips["cut"]), frames(out)
    expected = np.stack([apply_color_map(f, t) for f, t in zip(before, per_frame)])
    assert np.abs(after - expected).max() * 255 <= 2
    steps_in, steps_out = mean_steps(before), mean_steps(after)
    away = [n for n in range(len(steps_in)) if not 11 <= n <= 20]  # pairs n, n+1 off the cut
    assert np.all(steps_out[away] <= steps_in[away] + 1 / 255)


def test_lut_schedule_spreads_the_change_evenly():
    a, b = np.zeros((2, 2, 2, 3)), np.ones((2, 2, 2, 3))
    segments = lut_schedule([(0, 9), (10, 29)], [a, b], 8)
    values = [t.mean() for t in frame_tables(segments, 30)]
    assert values[:6] == [0.0] * 6 and values[14:] == [1.0] * 16
    assert np.allclose(values[6:14], (np.arange(8) + 0.5) / 8) and values[9] < 0.5 < values[10]
    assert np.diff(values).max() <= 1 / 8 + 1e-12  # no frame takes more than 1/8 of the change
    short = lut_schedule([(0, 2), (3, 29)], [a, b], 8)  # window at most half a shot
    assert [t.mean() for t in frame_tables(short, 30)][0] == 0.0


def _refused(result, *words) -> None:
    assert result.exit_code != 0
    assert isinstance(result.exception, SystemExit), result.exception
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:"), result.output
    assert "Traceback" not in result.output
    for word in words:
        assert word in lines[0]


def test_bad_inputs_are_one_line_errors_and_leave_the_input_alone(clips, tmp_path):
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(clips["x264"].read_bytes())
    original = digest(clip)
    _refused(run(tmp_path / "missing.mp4", "-o", tmp_path / "o.mp4", *FAST), "no such file")
    text = tmp_path / "notes.mp4"
    text.write_text("not a video\n")
    _refused(run(text, "-o", tmp_path / "o.mp4", *FAST), "not a video")
    _refused(run(clip, "-o", clip, *FAST, "--overwrite"), "input")
    existing = tmp_path / "existing.mp4"
    existing.write_bytes(b"keep me")
    _refused(run(clip, "-o", existing, *FAST), "exists")
    assert existing.read_bytes() == b"keep me"
    _refused(run(clip, "-o", tmp_path / "o.webm", *FAST), "extension")
    _refused(run(clip, "-o", tmp_path / "o.mp4", "--codec", "prores", *FAST), ".mov")
    assert digest(clip) == original
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.mp4", "existing.mp4",
                                                          "notes.mp4"]


def test_ctrl_c_while_encoding_kills_ffmpeg_and_leaves_nothing(clips, tmp_path, monkeypatch):
    import wbcgrade.video.workflow as workflow

    def interrupted(args, progress=None, cwd=None):
        def stop(done):
            raise KeyboardInterrupt

        return real(args, stop, cwd)

    real = workflow.run_pass
    monkeypatch.setattr(workflow, "run_pass", interrupted)
    result = run(clips["rgb"], "-o", tmp_path / "graded.mkv", "--codec", "ffv1", *FAST,
                 *WEIGHTS)
    assert result.exit_code == 130
    assert list(tmp_path.iterdir()) == []
