"""Words a photographer reads: help that fits a screen and starts with what the command does
by default, and output lines in percent with how visible the change is (issue 47)."""

from __future__ import annotations

from wbcgrade.color.outcome import GradeOutcome, GradeSource, change_words


def test_apply_help_fits_a_screen_and_help_all_lists_every_option(cli):
    short = cli("apply", "--help")
    assert short.exit_code == 0
    lines = short.output.splitlines()
    assert len(lines) <= 60, len(lines)
    assert "PHOTO is the photo to grade" in short.output
    assert "--help-all" in short.output and "--style" in short.output
    assert "--relax" not in short.output  # a palette-fit option: behind --help-all
    full = cli("apply", "--help-all")
    assert full.exit_code == 0 and len(full.output.splitlines()) > 100
    for flag in ("--relax", "--bit-depth", "--working-space", "--natural", "--no-regrain"):
        assert flag in full.output, flag


def test_the_top_level_help_starts_with_the_look():
    from click.testing import CliRunner

    from wbcgrade.cli import main

    text = CliRunner().invoke(main, ["--help"]).output
    first = text.split("\n\n")[1]  # the paragraph after the usage line
    assert "look" in first and "barycenter" not in first and "palette" not in first


def test_look_extract_help_has_no_mode_heading(cli):
    text = cli("look", "extract", "--help").output
    assert "--mode" not in text and "(--mode look" not in text


def test_outcome_lines_are_in_percent_and_say_how_visible():
    clear = GradeOutcome.judge(GradeSource.PRESET_LOOK, 6, 1.0, 0.8, 12.0, 10.0)
    line = clear.headline()
    assert line == ("grade: the preset's own look, strength 0.80; this photo's colours move "
                    "3.9 % on average (clear)")
    assert "/255" not in line and "look size" not in line
    assert clear.headline("this clip").endswith("this clip's colours move 3.9 % on average "
                                                "(clear)")
    faint = GradeOutcome.judge(GradeSource.SET_LOOK, 3, 0.1, 1.0, 2.0, 1.5, "too few styles")
    text = "\n".join(faint.lines("this clip"))
    assert "this photo" not in text and "/255" not in text
    assert "the colours move by 0.6 % on average (barely visible)" in text
    unchanged = GradeOutcome.judge(GradeSource.PRESET_LOOK, 6, 1.0, 0.01, 5.0, 0.05)
    assert unchanged.lines("this clip")[1].startswith("the clip is essentially unchanged")
    assert [change_words(c).split("(")[1] for c in (0.5, 2, 5, 12, 40)] == [
        "not visible)", "barely visible)", "subtle)", "clear)", "strong)"]


def test_video_says_what_the_clip_holds_in_plain_words(capsys):
    """The clip's line: frame rate without trailing zeros, its length in seconds and its
    streams by kind (was "25.000 fps, 150 frames, yuv420p, 2 stream(s)")."""
    from pathlib import Path
    from types import SimpleNamespace

    from wbcgrade.cli.video import _print_result

    info = SimpleNamespace(path=Path("clip.mp4"), width=640, height=360, fps=25.0, frames=150,
                           duration=6.0, pix_fmt="yuv420p", streams=["video", "audio"])
    result = SimpleNamespace(info=info, encoding=None, shots=[], timings={"total": 1.0},
                             output="out.mp4", luts=[], encoder="libx264", pix_fmt="yuv420p")
    _print_result(result, False)
    first = capsys.readouterr().out.splitlines()[0]
    assert first == ("clip.mp4: 640x360, 25 fps, 150 frames (6.0 s), yuv420p pixels, "
                     "streams: 1 video, 1 audio")
