"""`brdf fit` never reports NaN: huge values, non-finite fits, strict JSON (issue 12 item 9)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from tests.conftest import run_cli
from wbcgrade.brdf import analytic, io, sampled, sampling
from wbcgrade.brdf import fit as fit_module
from wbcgrade.errors import InputError, NumericalError

N = 24


def _strict_json(text: str):
    """Parse JSON as the standard has it: NaN and Infinity are errors."""
    def refuse(constant):
        raise ValueError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture
def files(tmp_path):
    directions = sampling.hemisphere_directions(N)
    database = tmp_path / "db"
    database.mkdir()
    for material in analytic.default_materials(3):
        io.write_sampled(database / f"{material.name}.npz",
                         analytic.sample_material(material, directions), directions)
    values = analytic.sample_material(analytic.material_by_name("bronze-ggx-0.25"), directions)
    measured = io.write_sampled(tmp_path / "bronze.npz", values, directions)
    huge = io.write_sampled(tmp_path / "huge.npz", values * 1e300, directions)
    return database, measured, huge


def _fit(measured, database, tmp_path, *extra):
    return run_cli(
        "brdf", "fit", str(measured), "--database", str(database), "--directions", str(N),
        "--fit-directions", "4", "--max-iter", "3", "--n-iter", "15", "--no-png",
        "-o", str(tmp_path / "fit.npz"), *extra)


def test_psnr_of_huge_values_is_that_of_the_scaled_ones():
    rng = np.random.default_rng(0)
    reference = rng.uniform(0, 1, (6, 6, 3))
    estimate = reference + rng.normal(0, 0.01, reference.shape)
    expected = sampled.psnr(reference, estimate)
    assert np.isfinite(expected)
    assert sampled.psnr(reference * 1e300, estimate * 1e300) == pytest.approx(expected)
    assert sampled.psnr(reference, reference) == float("inf")
    with pytest.raises(NumericalError, match="NaN or infinite"):
        sampled.psnr(reference, np.full_like(reference, np.nan))


def test_fit_of_values_times_1e300_gives_the_same_finite_psnr_and_valid_json(tmp_path, files):
    database, measured, huge = files
    plain = _strict_json(_fit(measured, database, tmp_path, "--json").stdout)
    result = _fit(huge, database, tmp_path, "--json")
    assert result.exit_code == 0, result.output
    scaled = _strict_json(result.stdout)
    psnr = scaled["fits"][0]["psnr_db"]
    assert psnr == pytest.approx(plain["fits"][0]["psnr_db"], abs=1e-6)
    assert scaled["fits"][0]["weights"] == pytest.approx(plain["fits"][0]["weights"], abs=1e-6)
    table = _fit(huge, database, tmp_path)
    assert table.exit_code == 0 and "nan" not in table.stdout.lower()


@pytest.mark.filterwarnings("error")  # and no numpy overflow warnings on the way
def test_values_too_large_to_add_up_are_refused():
    directions = sampling.hemisphere_directions(N)
    geometry = sampling.hemisphere_geometry(N)
    base = np.stack([analytic.sample_material(m, directions)
                     for m in analytic.default_materials(3)])
    with pytest.raises(InputError, match="too large"):
        fit_module.fit_brdf(base[0] / base[0].max() * 1.7e308, base, geometry, max_iter=2)


def test_non_finite_fit_is_one_error_line(tmp_path, files, monkeypatch):
    database, measured, _ = files
    real = fit_module.barycentric_coordinates

    def broken(*args, **kwargs):
        return dataclasses.replace(real(*args, **kwargs), loss=float("nan"))

    monkeypatch.setattr(fit_module, "barycentric_coordinates", broken)
    for extra in ((), ("--json",)):
        result = _fit(measured, database, tmp_path, *extra)
        assert result.exit_code == 1, result.output
        lines = [line for line in result.output.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
        assert "NaN or infinite" in lines[0]
    assert not (tmp_path / "fit.npz").exists()
