"""wbcgrade.brdf.workflow: the `brdf synth` / `brdf fit` work, called as a library."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wbcgrade.brdf import io, sampling
from wbcgrade.brdf.workflow import fit_measurement, fit_outputs, write_database
from wbcgrade.errors import InputError, OptionError

N = 24


@pytest.fixture
def files(tmp_path):
    calls = []
    written = write_database(tmp_path / "db", count=3, directions=N,
                             progress=lambda done, total, name: calls.append((done, total)))
    assert calls == [(1, 3), (2, 3), (3, 3)] and len(written) == 3
    (reference,) = write_database(tmp_path / "ref", ["bronze-ggx-0.25"], directions=N)
    return reference, tmp_path / "db"


@pytest.mark.slow
def test_fit_measurement_writes_and_reports(tmp_path, files):
    measured, database = files
    seen = []
    result = fit_measurement(
        measured, database, keeps=(0.5,), output=tmp_path / "fit.npz", directions=N,
        fit_directions=4, max_iter=3, n_iter=15, loss="quadratic",
        progress=lambda label, n, w, value: seen.append(label))
    assert [run.label for run in result.runs] == ["full", "keep 50%"]
    assert set(seen) == {"full", "keep 50%"}
    assert result.output.exists() and result.png == tmp_path / "fit.png" and result.png.exists()
    values = io.load_brdf(result.output, sampling.hemisphere_directions(N))
    assert np.allclose(values, result.runs[1].fit.values)  # the first keep's fit is written
    record = json.loads(json.dumps(result.as_dict(), allow_nan=False))
    assert record["fit_directions"] == 4 and len(record["database"]) == 3
    assert all(sum(f["weights"].values()) == pytest.approx(1.0) for f in record["fits"])


@pytest.mark.slow
def test_outputs_are_checked_before_any_work(tmp_path, files):
    measured, database = files
    out, png = fit_outputs(measured, database, keeps=(0.25,))
    assert out.name == f"{measured.stem}-keep25-fit.binary" and png == out.with_suffix(".png")
    with pytest.raises(OptionError, match="an input; choose another png") as info:
        fit_outputs(measured, database, output=measured.with_suffix(".npz"), png=measured)
    assert info.value.option == "png" and info.value.path == str(measured)
    with pytest.raises(OptionError, match="suffix"):
        fit_outputs(measured, database, output=tmp_path / "fit.txt")
    with pytest.raises(InputError, match="output folder does not exist"):
        fit_outputs(measured, database, output=tmp_path / "absent" / "fit.npz", no_png=True)
