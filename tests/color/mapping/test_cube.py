"""The ``.cube`` writer (wbcgrade.color.mapping.lut.cube_text) writes colour-science's "Resolve
Cube" text byte for byte, without importing colour-science on a ``--lut`` run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wbcgrade.color.mapping.lut import _shaper_header_for_readers, cube_text, write_cube

REPO = Path(__file__).resolve().parents[3]


def colour_science_text(path: Path, table, title, comments, shaper) -> str:
    """What write_cube wrote through colour-science (the former writer, kept as the oracle)."""
    from wbcgrade.color._colour import colour

    grid = colour.LUT3D(table=np.asarray(table, dtype=np.float64), name=title,
                        domain=np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]),
                        size=table.shape[0], comments=list(comments))
    lut, decimals = grid, 6
    if shaper is not None:
        curve, (low, high) = shaper
        grid.name, grid.comments = "grade", []
        lut, decimals = colour.LUTSequence(
            colour.LUT3x1D(table=np.repeat(np.asarray(curve, np.float64)[:, None], 3, axis=1),
                           name=title, domain=np.array([[low] * 3, [high] * 3]),
                           comments=list(comments)), grid), 7
    colour.write_LUT(lut, str(path), decimals=decimals, method="Resolve Cube")
    lines = path.read_text("utf-8").splitlines()
    if shaper is not None:
        start = next(n for n, line in enumerate(lines) if line and line[0] in "0123456789-+.")
        lines = _shaper_header_for_readers(lines[:start]) + lines[start:]
    return "\n".join(lines) + "\n"


CASES = [
    (2, "wbcgrade", [], None),
    (5, "a title with \"quotes\" and \u00e9t\u00e9", ["input space: x", "# hash"], None),
    (33, "wbcgrade", ["one", "two"], None),
    (9, "acescct", ["input space: ACEScg"], (np.linspace(0.0, 1.0, 257) ** 0.5, (0.0, 1.0))),
    (5, "log", [], (np.linspace(-0.1, 1.2, 64), (-0.0072, 222.875))),
]


@pytest.mark.parametrize(("size", "title", "comments", "shaper"), CASES)
def test_the_text_is_colour_sciences(tmp_path, size, title, comments, shaper):
    rng = np.random.default_rng(size)
    table = rng.normal(0.5, 0.4, (size, size, size, 3)).astype(np.float32)
    table[0, 0, 0] = [-0.0, 1e-9, -1e-9]  # signed zeros as fixed-point numbers
    expected = colour_science_text(tmp_path / "c.cube", table, title, comments, shaper)
    assert cube_text(table, title, comments, shaper) == expected
    written = write_cube(tmp_path / "w.cube", table, title, comments, shaper=shaper)
    assert written.read_text("utf-8") == expected


@pytest.mark.slow  # over 4 s of the fast tier: the whole suite runs it
def test_a_lut_run_does_not_import_colour_science(tmp_path):
    script = ("import sys\nfrom wbcgrade.cli import main\n"
              "try:\n    main()\nexcept SystemExit as exit:\n"
              "    print('colour' in sys.modules, exit.code)")
    run = subprocess.run([sys.executable, "-c", script, "apply", str(REPO / "samples" /
                          "chelsea.jpg"), "--preset", "warm", "-o", str(tmp_path / "o.jpg"),
                          "--lut", str(tmp_path / "o.cube")], cwd=REPO, capture_output=True,
                         text=True, timeout=300)
    assert run.stdout.split()[-2:] == ["False", "0"], run.stdout + run.stderr
    assert (tmp_path / "o.cube").read_text().startswith('TITLE "')
