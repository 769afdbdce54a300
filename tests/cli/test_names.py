"""One name per idea on the command line: --overwrite everywhere, --force a hidden alias."""

from __future__ import annotations

from click.testing import CliRunner

from wbcgrade.cli import main


def test_overwrite_is_the_name_and_force_is_hidden():
    for command in (["apply"], ["batch"], ["preset", "build"]):
        text = CliRunner().invoke(main, [*command, "--help"]).output
        assert "--overwrite" in text and "--force" not in text, command


def test_batch_force_still_works_with_a_deprecation_warning(tmp_path):
    photos = tmp_path / "in"
    photos.mkdir()
    args = ["batch", str(photos), "-o", str(tmp_path / "out"), "--lut", "x.cube"]
    old = CliRunner().invoke(main, [*args, "--force"])
    new = CliRunner().invoke(main, [*args, "--overwrite"])
    # Both reach the same check (--lut without --consistent); only --force warns.
    assert old.exit_code == new.exit_code == 1
    assert old.output.splitlines()[-1] == new.output.splitlines()[-1]
    assert "--lut needs --consistent" in new.output
    assert "--force is deprecated; use --overwrite" in old.output
    assert "deprecated" not in new.output
