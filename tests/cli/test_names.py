"""One name per idea on the command line: --overwrite everywhere, --force a hidden alias."""

from __future__ import annotations

import click

from wbcgrade.cli import main


def test_overwrite_is_the_name_and_force_is_hidden(cli):
    for command in (["apply"], ["batch"], ["preset", "build"]):
        text = cli(*command, "--help").output
        assert "--overwrite" in text and "--force" not in text, command


def test_batch_force_still_works_with_a_deprecation_warning(tmp_path, cli):
    photos = tmp_path / "in"
    photos.mkdir()
    args = ["batch", str(photos), "-o", str(tmp_path / "out"), "--lut", "x.cube"]
    old = cli(*args, "--force")
    new = cli(*args, "--overwrite")
    # Both reach the same check (--lut without --consistent, a usage error); only --force
    # warns.
    assert old.exit_code == new.exit_code == 2
    assert old.output.splitlines()[-1] == new.output.splitlines()[-1]
    assert "--lut needs --consistent" in new.output
    assert "--force is deprecated; use --overwrite" in old.output
    assert "deprecated" not in new.output


def _loss_choices(*command: str) -> list[str]:
    group = main
    for name in command:
        group = group.commands[name] if hasattr(group, "commands") else group
    ctx = click.Context(group)
    option = next(p for p in group.get_params(ctx) if "--loss" in getattr(p, "opts", ()))
    return list(option.type.choices)


def test_every_loss_the_cli_offers_is_the_core_registrys():
    """The loss lists were written by hand in several places and drifted: each
    command's --loss choices are its domain's list, and every name is a loss of the
    core's registry."""
    from wbcgrade.brdf.defaults import BRDF_LOSSES
    from wbcgrade.color.options import LOSSES as COLOR_LOSSES
    from wbcgrade.core import get_loss
    from wbcgrade.shape.defaults import LOSS_NAMES

    offered = {("apply",): COLOR_LOSSES, ("batch",): COLOR_LOSSES, ("report",): COLOR_LOSSES,
               ("shape", "complete"): LOSS_NAMES, ("shape", "project"): LOSS_NAMES,
               ("brdf", "fit"): BRDF_LOSSES}
    for command, names in offered.items():
        assert _loss_choices(*command) == list(names), command
        for name in names:
            assert get_loss(name).name == name.replace("-", "_"), name
