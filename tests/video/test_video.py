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

Colour spaces (``--input-space``/``--working-space``): the default pair must
run the code of before colour management; another working space bakes the
LUT in the clip's encoding, which ffmpeg applies exactly as above; a PQ copy
of the lossless clip (10-bit RGB, BT.2020/ST 2084 tags, sRGB white at
100 cd/m²) is graded in its Rec.2100-PQ space, like the sRGB clip once
converted back; an HLG clip, for which the built-in config has no space, is
a one-line error.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.color.conftest import THREE_STYLES
from tests.conftest import run_cli
from wbcgrade.color.colorspace import convert
from wbcgrade.color.mapping.lut import read_cube
from wbcgrade.color.mapping.remap import apply_color_map
from wbcgrade.video.ffmpeg import decode_frames, ffmpeg_exe, probe
from wbcgrade.video.shots import frame_tables, lut_schedule

FAST = ["--preset", str(THREE_STYLES), "--no-cache"]
# skip the fit where the test is about frames (fixed weights: a palette grade)
WEIGHTS = ["--mode", "palette", "--bins", "32", "--weights", "0.5,0.3,0.2"]


def _ffmpeg(*args: str) -> None:
    subprocess.run([ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-y", *args],
                   check=True, timeout=60)


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> dict[str, Path]:
    """32 frames of 64x48 at 25 fps with a 440 Hz audio track: x264 + AAC (BT.709 tags),
    lossless RGB (FFV1 + PCM), and an RGB clip with a hard cut at frame 16; the lossless
    clip converted to PQ (10-bit RGB FFV1, tagged smpte2084/bt2020; no audio), and 12
    frames of 10-bit Y'CbCr tagged HLG."""
    folder = tmp_path_factory.mktemp("clips")
    src = "testsrc2=size=64x48:rate=25:duration=1.28"
    sine = "sine=frequency=440:sample_rate=48000:duration=1.28"
    out = {"x264": folder / "plain.mp4", "rgb": folder / "rgb.mkv", "cut": folder / "cut.mkv",
           "pq": folder / "pq.mkv", "hlg": folder / "hlg.mkv"}
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
    pq = convert(frames(out["rgb"]), "sRGB Encoded Rec.709 (sRGB)", "Rec.2100-PQ - Display")
    subprocess.run([ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo",
                    "-pix_fmt", "rgb48le", "-s", "64x48", "-r", "25", "-i", "pipe:0", "-vf",
                    "format=gbrp10le,setparams=range=pc:colorspace=gbr:color_primaries=bt2020:"
                    "color_trc=smpte2084", "-c:v", "ffv1", str(out["pq"])],
                   input=np.round(np.clip(pq, 0, 1) * 65535).astype("<u2").tobytes(),
                   check=True, timeout=60)
    short = "testsrc2=size=64x48:rate=25:duration=0.48"
    _ffmpeg("-f", "lavfi", "-i", short, "-vf", "format=yuv420p10le,setparams=range=tv:"
            "colorspace=bt2020nc:color_primaries=bt2020:color_trc=arib-std-b67", "-c:v", "ffv1",
            str(out["hlg"]))
    return out


def run(*args) -> object:
    result = run_cli("video", *map(str, args))
    return result


def frames(path: Path) -> np.ndarray:
    """All frames as (n, h, w, 3) float32 in [0, 1] (the clip's own matrix and range)."""
    return np.stack(list(decode_frames(path, probe(path)))).astype(np.float32) / 255


def frames16(path: Path) -> np.ndarray:
    """All frames of an RGB clip as (n, h, w, 3) float32 in [0, 1], 16 bits per channel."""
    info = probe(path)
    raw = subprocess.run([ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-i", str(path),
                          "-f", "rawvideo", "-pix_fmt", "rgb48le", "pipe:1"],
                         check=True, capture_output=True, timeout=60).stdout
    video = np.frombuffer(raw, dtype="<u2").reshape(-1, info.height, info.width, 3)
    return video.astype(np.float32) / 65535


def mean_steps(video: np.ndarray) -> np.ndarray:
    """Largest change of a channel's frame mean between consecutive frames, per frame pair."""
    return np.abs(np.diff(video.mean(axis=(1, 2)), axis=0)).max(axis=1)


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.slow
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
    # it did grade (the three unrelated styles share a faint look: measured 3.0/255)
    assert np.abs(after - before).mean() > 2 / 255
    document = json.loads((report / "report.json").read_text())
    assert len(document["shots"]) == 1 and document["shots"][0]["sampled_frames"] == [0, 25]
    assert (report / document["shots"][0]["sheet"]).stat().st_size > 1000
    shot = document["shots"][0]  # a look grade: what it did, no placeholder weights
    assert shot["outcome"]["source"] == "set-look" and shot["outcome"]["n_styles"] == 3
    assert "weights" not in shot and "loss" not in shot


@pytest.mark.slow
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


@pytest.mark.slow
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


# --- colour spaces ---------------------------------------------------------------------------

def _json(result) -> dict:
    assert result.exit_code == 0, result.output
    return json.loads(result.output[result.output.index("{"):])


@pytest.mark.slow
def test_a_clip_takes_the_photos_grade_path(clips, tmp_path):
    """A shot's grade is the one grade path of photos on its frames' pooled palette, and its
    LUT the map sampled at the LUT's nodes (sRGB footage graded in sRGB)."""
    from wbcgrade.color.colorspace import ColorEncoding
    from wbcgrade.color.grade.grading import PhotoHistograms, grade_histograms, photo_histograms
    from wbcgrade.color.histogram import PaletteSum
    from wbcgrade.color.mapping.lut import color_map_to_lut
    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.presets import load_preset, resolve_preset
    from wbcgrade.video.workflow import VideoSettings, grade_video

    styles = load_preset(resolve_preset(str(THREE_STYLES)))
    opts = GradeOptions(bins=32, weights=[0.5, 0.3, 0.2], regrain=False)
    result = grade_video(clips["rgb"], tmp_path / "graded.mkv", styles, opts,
                         settings=VideoSettings(codec="ffv1"))
    encoding = result.encoding
    assert encoding.input == encoding.working == "sRGB Encoded Rec.709 (sRGB)"
    shot = result.shots[0]
    pool_fit, pool = PaletteSum(), PaletteSum()
    for n in shot.samples:
        hists = photo_histograms(result.samples.frames[n].astype(np.float32) / 255, opts)
        pool_fit.add(hists.fit)
        pool.add(hists.transfer)
    before, _ = grade_histograms(PhotoHistograms(pool_fit.result(), pool.result()), styles,
                                 opts, ColorEncoding.of())
    assert np.array_equal(shot.grade.color_map, before.color_map)
    assert np.array_equal(shot.table, color_map_to_lut(before.color_map, 33).astype(np.float32))


@pytest.mark.slow
def test_explicit_srgb_spaces_equal_the_default(clips, tmp_path):
    outputs = {}
    for name, spaces in (("default", []),
                         ("srgb", ["--input-space", "sRGB", "--working-space", "srgb_tx"])):
        out, lut = tmp_path / f"{name}.mkv", tmp_path / f"{name}.cube"
        document = _json(run(clips["rgb"], "-o", out, "--codec", "ffv1", *FAST, *WEIGHTS,
                             "--lut", lut, "--json", *spaces))
        assert document["color"]["input_space"] == document["color"]["working_space"]
        outputs[name] = frames(out), read_cube(lut).table
    assert np.array_equal(outputs["default"][0], outputs["srgb"][0])
    assert np.array_equal(outputs["default"][1], outputs["srgb"][1])


@pytest.fixture(scope="module")
def acescct(clips, tmp_path_factory) -> dict:
    """The lossless clip graded in ACEScct: output, LUT and JSON."""
    folder = tmp_path_factory.mktemp("acescct")
    out, lut = folder / "graded.mkv", folder / "grade.cube"
    document = _json(run(clips["rgb"], "-o", out, "--codec", "ffv1", *FAST, *WEIGHTS,
                         "--working-space", "acescct", "--lut", lut, "--json"))
    return {"output": out, "lut": lut, "json": document}


@pytest.mark.slow
def test_acescct_working_space_bakes_the_lut_in_the_clips_encoding(clips, acescct, tmp_path):
    out, lut, color = acescct["output"], acescct["lut"], acescct["json"]["color"]
    assert (color["input_space"], color["working_space"]) == ("sRGB Encoded Rec.709 (sRGB)",
                                                              "ACEScct")
    assert color["styles_space"] == "ACEScct"
    assert color["ocio_config"] and color["ocio_version"]
    header = [ln for ln in lut.read_text().splitlines() if ln.startswith("#")]
    assert any("input space: sRGB Encoded Rec.709" in ln for ln in header)
    assert any("working space: ACEScct" in ln for ln in header)
    assert any("OpenColorIO config" in ln for ln in header)
    before, after = frames(clips["rgb"]), frames(out)
    table = read_cube(lut).table
    expected = apply_color_map(before, table)
    error = np.abs(after - expected) * 255
    assert error.max() <= 2 and error.mean() < 0.6, (error.max(), error.mean())
    default = tmp_path / "default.mkv"
    assert run(clips["rgb"], "-o", default, "--codec", "ffv1", *FAST, *WEIGHTS).exit_code == 0
    assert np.abs(after - frames(default)).mean() > 2 / 255  # another grade
    assert np.abs(after - before).mean() > 5 / 255  # that did grade


def test_a_grades_lut_in_the_clips_encoding_goes_through_the_working_space_and_back():
    from wbcgrade.color.grade.grading import Grade
    from wbcgrade.color.mapping.remap import identity_map
    from wbcgrade.color.options import SpaceOptions
    from wbcgrade.video.ffmpeg import VideoInfo
    from wbcgrade.video.spaces import clip_encoding

    info = VideoInfo(Path("pq.mkv"), 64, 48, 25.0, "gbrp10le", "pc", "gbr", "bt2020",
                     "smpte2084", 12, 0.48)
    encoding = clip_encoding(info, SpaceOptions(working="acescct"))
    assert (encoding.input, encoding.source) == ("Rec.2100-PQ - Display",
                                                 "tags smpte2084/bt2020")

    def grade(color_map):
        return Grade(("a",), np.ones(1), color_map, working=encoding.working)

    identity = identity_map(9)
    assert np.array_equal(grade(identity).lut(17, encoding), identity_map(17))  # exactly
    # a grade in ACEScct: a little less contrast, warmer
    warm = 0.5 + (identity_map(9) - 0.5) * np.float32(0.9) + np.float32([0.02, 0.0, -0.02])
    table = grade(warm).lut(33, encoding)
    x = np.random.default_rng(1).random((5000, 3)).astype(np.float32) * 0.8  # to 4000 cd/m²
    working, state = encoding.encode(x)
    exact = np.clip(encoding.decode(apply_color_map(working, warm), state), 0, 1)
    error = np.abs(apply_color_map(x, table) - exact)  # the 33³ LUT's interpolation
    assert error.max() < 8e-3 and error.mean() < 3e-4, (error.max(), error.mean())  # 5e-3, 1.4e-4
    middle = np.all((x > 0.2) & (x < 0.75), axis=1)  # no channel near PQ's steep toe
    assert error[middle].max() < 1.5e-3  # measured 0.7e-3
    assert np.abs(exact - x).mean() > 0.02


def test_unknown_spaces_are_one_line_errors(clips, tmp_path):
    out = tmp_path / "o.mkv"
    _refused(run(clips["rgb"], "-o", out, "--codec", "ffv1", *FAST, "--working-space",
                 "Rec.9999"), "--working-space", "Rec.9999", "ACEScct")
    _refused(run(clips["rgb"], "-o", out, "--codec", "ffv1", *FAST, "--input-space", "nope"),
             "--input-space", "nope")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_pq_clip_is_graded_in_its_rec2100_pq_space(clips, acescct, tmp_path):
    out, lut = tmp_path / "graded.mkv", tmp_path / "grade.cube"
    document = _json(run(clips["pq"], "-o", out, "--codec", "ffv1", *FAST, *WEIGHTS,
                         "--working-space", "acescct", "--lut", lut, "--json"))
    color = document["color"]
    assert color["input_space"] == "Rec.2100-PQ - Display"
    assert color["input_space_from"] == "tags smpte2084/bt2020"
    assert color["working_space"] == "ACEScct"
    src, dst = probe(clips["pq"]), probe(out)
    assert dst.pix_fmt == "gbrp10le" and dst.frames == 32 and dst.tags() == src.tags()
    assert any("input space: Rec.2100-PQ - Display" in ln for ln in lut.read_text().splitlines())
    before, after = frames16(clips["pq"]), frames16(out)
    error = np.abs(after - apply_color_map(before, read_cube(lut).table)) * 255
    assert error.max() <= 2 and error.mean() < 0.6, (error.max(), error.mean())  # 1.5, 0.08
    assert np.abs(after - before).mean() > 2 / 255
    # the same pictures in two encodings grade alike: the PQ grade, back in sRGB, is the
    # sRGB clip's grade (10-bit PQ, 8-bit samples of it: measured 3.1/255 at most, 0.9 mean)
    back = np.clip(convert(after, color["input_space"], "sRGB Encoded Rec.709 (sRGB)"), 0, 1)
    srgb = frames(acescct["output"])
    gap = np.abs(back - srgb) * 255
    assert gap.max() < 5 and gap.mean() < 1.5, (gap.max(), gap.mean())
    assert np.abs(srgb - frames(clips["rgb"])).mean() * 255 > 20  # against a large grade


def test_an_hlg_clip_without_a_config_space_asks_for_input_space(clips, tmp_path):
    result = run(clips["hlg"], "-o", tmp_path / "o.mkv", "--codec", "ffv1", *FAST, *WEIGHTS)
    _refused(result, "HLG", "arib-std-b67", "--input-space")
    assert list(tmp_path.iterdir()) == []
