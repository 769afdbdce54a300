"""Bad inputs caught early and told plainly (issue 12: preset width, weights, messages, CSV)."""

from __future__ import annotations

import csv
import io
import shutil

import numpy as np
import pytest

from tests.color.conftest import FAST_ARGS, write_array
from tests.conftest import run_cli as run
from wbcgrade.color.presets import load_preset, load_style_folder, save_preset
from wbcgrade.color.weights import parse_weights
from wbcgrade.errors import InputError
from wbcgrade.photos.report import _csv_text, csv_cell


def _one_error_line(result) -> str:
    assert result.exit_code != 0, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    return lines[0]


@pytest.mark.parametrize("width", ["-1", "nan", "inf", "0"])
def test_preset_build_refuses_a_bad_width_before_writing(tmp_path, style_dir, width):
    out = tmp_path / "p.npz"
    line = _one_error_line(run("preset", "build", style_dir, "-o", out, "--bins", 8,
                               "--width", width, "--no-cache"))
    assert "--width" in line and ("positive" in line or "not a finite number" in line)
    assert not out.exists()


def test_save_preset_refuses_a_bad_width(tmp_path, style_dir):
    styles = load_style_folder(style_dir, 8)
    with pytest.raises(InputError, match="width must be a positive, finite number"):
        save_preset(tmp_path / "p.npz", styles, width=float("nan"))
    assert load_preset(save_preset(tmp_path / "p.npz", styles, width=2)).width == 2.0


def test_huge_finite_weights_are_equal_weights():
    assert parse_weights("1e308,1e308,1e308") == pytest.approx([1 / 3] * 3)
    assert parse_weights("1e308,0") == [1.0, 0.0]
    with pytest.raises(InputError, match="finite"):
        parse_weights("inf,1")


@pytest.mark.slow
def test_apply_with_huge_weights_grades(tmp_path, style_dir, photo):
    result = run("apply", photo, "--style", style_dir, "-o", tmp_path / "out.png", "--json",
                 "--weights", "1e308,1e308,1e308,1e308", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    weights = [w["weight"] for w in __import__("json").loads(result.stdout)["weights"]]
    assert weights == pytest.approx([0.25] * 4, abs=1e-6)


def test_a_preset_that_is_not_a_zip_names_no_numpy_option(tmp_path, photo):
    fake = tmp_path / "fake.npz"
    fake.write_bytes(b"this is not an archive at all" * 4)
    with pytest.raises(InputError, match="fake.npz") as info:
        load_preset(fake)
    assert "allow_pickle" not in str(info.value) and "not a zip" in str(info.value)
    line = _one_error_line(run("apply", photo, "--preset", fake, *FAST_ARGS))
    assert "allow_pickle" not in line and "fake.npz" in line


def test_a_pickled_preset_names_no_numpy_option(tmp_path):
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, header=np.array([{"evil": 1}], dtype=object))
    with pytest.raises(InputError, match="pickled") as info:
        load_preset(pickled)
    assert "allow_pickle" not in str(info.value)


def test_transparent_style_photo_warning_names_the_file(tmp_path, style_dir):
    folder = tmp_path / "styles"
    shutil.copytree(style_dir, folder)
    pixels = np.zeros((8, 8, 4), np.float32)
    pixels[..., :3] = 0.5  # fully transparent: alpha 0 everywhere
    write_array(folder / "glass.png", pixels, "uint8")
    warnings = []
    styles = load_style_folder(folder, 8, warn=warnings.append)
    assert "glass" not in styles.names
    assert len(warnings) == 1 and "glass.png" in warnings[0], warnings
    assert "transparent" in warnings[0]


@pytest.mark.parametrize("start", ["=", "+", "-", "@", "\t", "\r"])
def test_csv_cells_starting_a_formula_are_escaped(start):
    assert csv_cell(start + "HYPERLINK(\"http://x\")") == "'" + start + "HYPERLINK(\"http://x\")"


def test_weights_csv_cannot_inject_formulas():
    names = ["=cmd|' /C calc'!A0", "plain"]
    entries = [
        {"photo": "=HYPERLINK(\"http://evil\",\"x\").jpg", "status": "graded",
         "weights": [{"style": names[0], "weight": 0.25}, {"style": "plain", "weight": 0.75}],
         "loss": -0.5, "best_single_style": {"style": "@SUM(1+1)", "loss": 0.1},
         "nonzero_weights": 2},
        {"photo": "+1.jpg", "status": "failed"},
        {"photo": "-2.jpg", "status": "graded"},
        {"photo": "\tq.jpg", "status": "graded"},
    ]
    rows = list(csv.reader(io.StringIO(_csv_text(entries, names))))
    text_cells = [rows[0][2], rows[1][0], rows[1][-7], rows[2][0], rows[3][0], rows[4][0]]
    for cell in text_cells:
        assert cell.startswith("'"), cell
    assert rows[1][2:4] == ["0.25", "0.75"] and rows[1][4] == "-0.5"  # numbers stay numbers
    assert rows[1][0] == "'=HYPERLINK(\"http://evil\",\"x\").jpg"  # inner quotes kept intact
