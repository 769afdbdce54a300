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


# `wbcgrade ARGS` as the console script runs it, in a fresh interpreter: the numeric
# modules it imported.
_RUN = """
import sys
from wbcgrade.cli import main
try:
    main(sys.argv[1:])
except SystemExit as exc:
    print("EXIT", exc.code)
heavy = sorted(m for m in sys.modules
               if m.split(".")[0] in ("numba", "numpy", "scipy", "OpenImageIO", "colour",
                                      "PyOpenColorIO", "cv2")
               or m.startswith("wbcgrade.core"))
print("HEAVY", *heavy)
"""


def _imports_of(*args: str) -> tuple[str, list[str]]:
    """(what ``wbcgrade ARGS`` printed, its last two lines: the exit and the heavy modules)."""
    run = subprocess.run([sys.executable, "-c", _RUN, *args], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    lines = run.stdout.splitlines()
    return run.stdout + run.stderr, lines[-2:]


@pytest.mark.parametrize("args", [("--help",), ("apply", "--help"), ("batch", "--help"),
                                  ("video", "--help"), ("report", "--help"),
                                  ("look", "learn", "--help"), ("look", "extract", "--help")])
def test_help_imports_no_numerics(args):
    output, (exit_line, heavy) = _imports_of(*args)
    assert exit_line == "EXIT 0" and "Usage:" in output, output
    assert heavy == "HEAVY", heavy


@pytest.mark.parametrize("args", [
    ("apply", "{tmp}/missing.jpg", "--preset", "warm"),
    ("apply", "samples/chelsea.jpg", "--bins", "0"),
    ("apply", "samples/chelsea.jpg", "--preset", "no-such-look", "-o", "{tmp}/x.jpg"),
    ("batch", "{tmp}/no-folder", "-o", "{tmp}/out", "--preset", "warm"),
    ("video", "{tmp}/missing.mp4", "--preset", "warm"),
    ("look", "learn", "{tmp}/before", "{tmp}/after", "-o", "{tmp}/look.json"),
    ("preset", "build", "{tmp}/no-folder", "-o", "{tmp}/p.npz"),
])
def test_mistake_is_answered_before_numerics_load(tmp_path, args):
    output, (exit_line, heavy) = _imports_of(*(a.format(tmp=tmp_path) for a in args))
    assert exit_line in ("EXIT 1", "EXIT 2") and "Error:" in output, output
    assert heavy == "HEAVY", heavy


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


def test_printed_total_is_the_wall_time_with_start_up(tmp_path):
    """`apply` prints its start-up as a stage and a total that counts from the process start
    (the wall time a user waits), not the library's stages alone."""
    import time

    photo = ROOT / "samples" / "chelsea.jpg"
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "wbcgrade", "apply", str(photo), "--preset",
                          "warm", "-o", str(tmp_path / "out.jpg")], capture_output=True,
                         text=True, timeout=300, cwd=ROOT)
    wall = time.perf_counter() - start
    assert run.returncode == 0, run.stderr
    line = next(t for t in run.stdout.splitlines() if t.startswith("time:"))
    stages = dict(part.rsplit(" ", 1) for part in line[len("time: "):].split(" (")[0]
                  .split(", "))
    total = float(line.rsplit("total ", 1)[1].rstrip("s)"))
    assert "start-up" in stages and "grade" in stages, line
    assert sum(float(v.rstrip("s")) for v in stages.values()) <= total + 0.1, line
    # all but the interpreter's exit: far more than the library's stages (the old total)
    assert wall * 0.75 <= total <= wall + 0.05, (line, wall)


def test_small_photos_grade_loads_no_compiler(tmp_path):
    """The README's first grade (a 0.14-megapixel photo, a shipped preset) runs numpy twins
    of the compiled kernels: numba (its compiler: seconds after an install, half a second
    from its cache) and scipy are never imported."""
    output, (exit_line, heavy) = _imports_of("apply", "samples/chelsea.jpg", "--preset", "warm",
                                             "-o", str(tmp_path / "out.jpg"))
    assert exit_line == "EXIT 0" and "wrote" in output, output
    modules = heavy.split()[1:]
    assert "numpy" in modules and "OpenImageIO" in modules, modules
    assert not [m for m in modules if m.split(".")[0] in ("numba", "scipy")], modules
