import json
import subprocess
import sys
from pathlib import Path

import pytest

from wbcgrade import __version__
from wbcgrade.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_version_and_help(cli):
    result = cli("--version")
    assert result.exit_code == 0 and __version__ in result.output
    result = cli("--help")
    assert result.exit_code == 0
    for command in ("apply", "batch", "brdf", "preset", "report", "shape", "video"):
        assert command in result.output
    assert "demo" not in result.output  # an example script now: examples/demo.py


# `wbcgrade --help` as the console script runs it, in a fresh interpreter.
_HELP = """
import sys
from wbcgrade.cli import main
try:
    main(["--help"])
except SystemExit as exc:
    assert exc.code == 0, exc.code
heavy = sorted(m for m in sys.modules
               if m.split(".")[0] in ("numba", "numpy", "scipy")
               or m.startswith(("wbcgrade.core", "wbcgrade.color")))
print("HEAVY", *heavy)
"""


def test_help_imports_neither_numba_nor_the_core():
    run = subprocess.run([sys.executable, "-c", _HELP], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert "Usage:" in run.stdout
    assert run.stdout.splitlines()[-1] == "HEAVY", run.stdout.splitlines()[-1]


@pytest.mark.slow
def test_demo_example_recovers_weights():
    run = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "demo.py"), "--size", "8", "--styles", "3",
         "--iterations", "15", "--json"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    assert report["l1_error"] < 0.02
    assert len(report["fitted_weights"]) == 3


def test_bad_option_is_one_line_error_without_traceback(cli):
    result = cli("brdf", "synth", "--count", "0", "-o", "x")
    assert result.exit_code == 2 and isinstance(result.exception, SystemExit)
    assert "Error" in result.output and "--count" in result.output


def test_library_error_becomes_one_line_message(tmp_path, cli):
    result = cli("apply", str(tmp_path / "missing.jpg"), "--preset", "warm")
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:") and "missing.jpg" in lines[0]


def test_library_warnings_reach_the_user_as_one_line(cli):
    import warnings

    import click

    from wbcgrade.errors import ConvergenceWarning

    @click.command("warns")
    def warns():
        warnings.warn(ConvergenceWarning("sinkhorn stopped after 3 iterations\nmore"),
                      stacklevel=1)

    main.add_command(warns)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            result = cli("warns")
    finally:
        main.commands.pop("warns")
    assert result.exit_code == 0
    assert result.output.strip() == "Warning: sinkhorn stopped after 3 iterations"
