"""`brdf fit` checks its outputs before any work (issue 12, item 7)."""

from __future__ import annotations

import os

import pytest

from tests.conftest import run_cli


@pytest.fixture
def brdfs(tmp_path):
    for folder, materials in (("db", ["white-lambert", "brushed-steel-ward"]),
                              ("ref", ["brushed-gold-ward"])):
        args = ["brdf", "synth", "-o", str(tmp_path / folder), "--directions", "32"]
        for material in materials:
            args += ["--material", material]
        assert run_cli(*args).exit_code == 0
    return tmp_path / "ref" / "brushed-gold-ward.npz", tmp_path / "db"


@pytest.fixture
def no_fit(monkeypatch):
    import wbcgrade.brdf.fit as fit_module  # the workflow (wbcgrade.brdf.workflow) calls it

    def forbidden(*args, **kwargs):
        raise AssertionError("fitted before checking the outputs")

    monkeypatch.setattr(fit_module, "fit_brdf", forbidden)


def _fit(measured, database, *extra):
    return run_cli("brdf", "fit", str(measured), "--database", str(database),
                   "--directions", "32", *extra)


def test_missing_output_folder_is_refused_before_the_fit(brdfs, tmp_path, no_fit):
    result = _fit(*brdfs, "-o", str(tmp_path / "nodir" / "fit.binary"))
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1] == (
        f"Error: {tmp_path / 'nodir'}: output folder does not exist")
    result = _fit(*brdfs, "-o", str(tmp_path / "fit.binary"), "--png",
                  str(tmp_path / "nodir2" / "fit.png"))
    assert result.exit_code == 1
    assert "nodir2: output folder does not exist" in result.output


def test_a_pipe_is_not_an_output(brdfs, tmp_path, no_fit):
    fifo = tmp_path / "fit.png"
    os.mkfifo(fifo)
    result = _fit(*brdfs, "-o", str(tmp_path / "fit.binary"))
    assert result.exit_code == 1
    assert "not a regular file" in result.output.strip().splitlines()[-1]
    assert fifo.is_fifo()


def test_a_bad_output_is_an_option_error_naming_its_flag(brdfs, tmp_path, no_fit):
    measured, database = brdfs
    for extra, last in (
            (["-o", str(tmp_path / "fit.txt")],
             f"Error: {tmp_path / 'fit.txt'}: --output needs a .binary or .npz suffix"),
            (["-o", str(tmp_path / "fit.npz"), "--png", str(measured)],
             f"Error: {measured}: an input; choose another --png")):
        result = _fit(measured, database, *extra)
        assert result.exit_code == 2, result.output
        assert result.output.strip().splitlines()[-1] == last
