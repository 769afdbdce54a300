"""``wbcgrade.color``'s front door: a few names, loaded on first use; a saved grade
applied from Python as ``apply --look`` applies it."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

import wbcgrade.color as wc


def test_the_front_door_is_small_and_every_name_resolves():
    assert 0 < len(wc.__all__) <= 15
    for name in wc.__all__:
        assert getattr(wc, name) is not None
    assert set(wc.__all__) <= set(dir(wc))


def test_importing_the_front_door_imports_no_numerics():
    code = ("import sys, wbcgrade.color as wc; "
            "print(sorted(m for m in ('numpy', 'OpenImageIO', 'wbcgrade.color.grade.grading') "
            "if m in sys.modules))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert run.stdout.strip() == "[]"


def test_a_preset_by_name_and_a_saved_grade_grade_an_array(tmp_path):
    rgb = np.random.default_rng(0).random((24, 32, 3))
    options = wc.GradeOptions(bins=16, fit_bins=8, map_size=9, n_iter=20, max_iter=5)
    graded, grade = wc.grade_array(rgb, wc.load_preset("warm"), options)
    saved = wc.save_grade(tmp_path / "grade.json", grade)
    again, applied = wc.grade_array(rgb, wc.load_grade(saved), options)
    assert np.abs(again - graded).max() < 1e-3  # the map is saved as 16-bit codes
    assert applied.saved is not None and "saved grade" in applied.outcome.headline()
    lut = wc.write_lut(tmp_path / "grade.cube", grade, size=9)
    assert lut.read_text().count("\n") > 9 ** 3
