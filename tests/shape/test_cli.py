"""`wbcgrade shape` through click's CliRunner: small runs and one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from tests.conftest import run_cli
from tests.shape.helpers import ball, synthetic_meshes

FAST = ["--resolution", "12", "--iterations", "20", "--max-iter", "3", "--quiet"]


@pytest.fixture
def database(tmp_path):
    folder = tmp_path / "db"
    folder.mkdir()
    for name, mesh in synthetic_meshes().items():
        mesh.export(folder / f"{name}.off")
    return folder


@pytest.fixture
def partial(tmp_path):
    mesh = trimesh.creation.box(extents=(1.0, 0.5, 0.3))
    path = tmp_path / "partial.stl"
    mesh.export(path)
    return path


def _run(args):
    return run_cli("shape", *args)


@pytest.mark.slow
def test_complete_writes_mesh_volume_png_and_json(tmp_path, database, partial):
    out = tmp_path / "done.ply"
    result = _run(["complete", str(partial), "-d", str(database), "-o", str(out), "--json", *FAST])
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout)
    assert set(record["weights"]) == {"box", "sphere", "torus"}
    assert sum(record["weights"].values()) == pytest.approx(1.0)
    assert record["loss"] == "kl_reverse, observed voxels" and record["watertight"]
    mesh = trimesh.load(out, force="mesh")
    assert mesh.is_watertight
    assert np.load(tmp_path / "done.npy").shape == (12, 12, 12)
    assert (tmp_path / "done.png").stat().st_size > 0


@pytest.mark.slow
def test_complete_prints_a_weight_table_for_euclidean(tmp_path, database, partial):
    out = tmp_path / "mix.obj"
    result = _run(
        ["complete", str(partial), "-d", str(database), "-o", str(out), "--euclidean",
         "--missing", "0.1", *FAST]
    )
    assert result.exit_code == 0, result.output
    assert "shape" in result.stdout and "euclidean projection" in result.stdout
    assert "missing fraction 0.100" in result.stdout
    assert trimesh.load(out, force="mesh").is_watertight


def test_project_volume_with_quadratic_loss(tmp_path):
    rng = np.random.default_rng(0)
    names = []
    for i, centre in enumerate([(0.4, 0.5, 0.5), (0.6, 0.5, 0.5), (0.5, 0.4, 0.6)]):
        path = tmp_path / f"db{i}.npy"
        np.save(path, ball(14, 0.25, centre) * rng.uniform(1, 2))
        names.append(path)
    source = tmp_path / "scan.npy"
    np.save(source, ball(14, 0.25, (0.5, 0.5, 0.5)))
    out = tmp_path / "fit.npy"
    args = ["project", str(source), "-o", str(out), "--loss", "quadratic", "--json"]
    for path in names:
        args += ["-d", str(path)]
    result = _run([*args, *FAST])
    assert result.exit_code == 0, result.output
    record = json.loads(result.stdout)
    assert record["loss"] == "quadratic"
    fitted = np.load(out)
    assert fitted.shape == (12, 12, 12)
    assert (tmp_path / "fit.png").exists()


def _assert_one_line_error(result, fragment):
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    assert fragment in lines[0], lines[0]


def test_unreadable_mesh(tmp_path, database):
    bad = tmp_path / "bad.off"
    bad.write_text("OFF\nnot a mesh at all\n")
    _assert_one_line_error(_run(["complete", str(bad), "-d", str(database), *FAST]), "unreadable")


def test_empty_mesh(tmp_path, database):
    empty = tmp_path / "empty.off"
    empty.write_text("OFF\n0 0 0\n")
    _assert_one_line_error(_run(["complete", str(empty), "-d", str(database), *FAST]), "empty")


def test_non_manifold_mesh_in_database(tmp_path, database, partial):
    book = tmp_path / "db" / "book.off"
    book.write_text("OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n0 -1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 1 4\n")
    result = _run(["complete", str(partial), "-d", str(database), *FAST, "-o",
                   str(tmp_path / "x.obj")])
    _assert_one_line_error(result, "non-manifold")


def test_database_of_one_shape(tmp_path, database, partial):
    one = database / "sphere.off"
    result = _run(["complete", str(partial), "-d", str(one), *FAST])
    _assert_one_line_error(result, "at least 2")


def test_resolution_too_large_for_memory(tmp_path, database, partial):
    result = _run(["complete", str(partial), "-d", str(database), "--resolution", "4096"])
    _assert_one_line_error(result, "lower --resolution")


def test_output_never_overwrites_an_input(tmp_path, database, partial):
    target = database / "box.off"
    result = _run(["complete", str(partial), "-d", str(database), "-o", str(target), *FAST])
    _assert_one_line_error(result, "overwrite")


def test_without_the_shape_extra_a_one_line_hint(monkeypatch, tmp_path, cli):
    """trimesh and scikit-image are the ``shape`` extra: a base install says how to add
    them instead of failing with an ImportError traceback."""
    import sys

    monkeypatch.setitem(sys.modules, "trimesh", None)  # as if not installed
    result = cli("shape", "project", str(tmp_path / "v.npy"),
                 str(tmp_path))
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert result.output.strip() == ("Error: wbcgrade shape needs trimesh: "
                                     "pip install 'wbcgrade[shape]'")
