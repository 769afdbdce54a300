"""wbcgrade.shape.workflow: the `shape complete` / `shape project` work, called as a library."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
import trimesh

from tests.shape.helpers import ball, synthetic_meshes
from wbcgrade._publish import TEMP_MARK
from wbcgrade.errors import InputError
from wbcgrade.shape.workflow import complete_mesh_file, project_volume_file

FAST = {"resolution": 12, "n_iter": 20, "max_iter": 3}


@pytest.mark.slow
def test_complete_mesh_file_reports_progress_and_files(tmp_path):
    folder = tmp_path / "db"
    folder.mkdir()
    for name, mesh in synthetic_meshes().items():
        mesh.export(folder / f"{name}.off")
    partial = tmp_path / "partial.stl"
    trimesh.creation.box(extents=(1.0, 0.5, 0.3)).export(partial)
    meshes, evaluations = [], []
    result = complete_mesh_file(
        partial, [folder], output=tmp_path / "done.obj", missing=0.1,
        on_mesh=lambda done, total, path: meshes.append((done, total)),
        callback=lambda n, w, loss: evaluations.append(n), **FAST)
    assert meshes == [(0, 4), (1, 4), (2, 4), (3, 4), (4, 4)] and evaluations
    assert sorted(result.projection.names) == ["box", "sphere", "torus"]
    record = result.as_dict()
    assert record["mesh_file"] == str(tmp_path / "done.obj") and not record["missing_estimated"]
    assert record["missing"] == 0.1  # given explicitly: not estimated, even after placing
    assert all((tmp_path / name).exists() for name in ("done.obj", "done.npy", "done.png"))
    with pytest.raises(InputError, match="would overwrite an input"):
        complete_mesh_file(partial, [folder], output=tmp_path / "x.obj",
                           png_path=folder / "box.off", **FAST)
    # The database voxelised by two worker processes: the same fit, in the same order.
    meshes.clear()
    parallel = complete_mesh_file(partial, [folder], output=tmp_path / "two.obj", missing=0.1,
                                  on_mesh=lambda done, total, path: meshes.append((done, total)),
                                  jobs=2, **FAST)
    assert parallel.projection.names == result.projection.names
    np.testing.assert_array_equal(parallel.projection.weights, result.projection.weights)
    assert sorted(meshes) == [(0, 4), (1, 4), (2, 4), (3, 4), (4, 4)]


def test_project_volume_file_rescales_to_the_input(tmp_path):
    paths = []
    for i, centre in enumerate([(0.4, 0.5, 0.5), (0.6, 0.5, 0.5)]):
        paths.append(tmp_path / f"db{i}.npy")
        np.save(paths[-1], ball(10, 0.3, centre))
    source = tmp_path / "scan.npy"
    np.save(source, 3.0 * ball(10, 0.3, (0.5, 0.5, 0.5)))
    stale = tmp_path / f".fit{TEMP_MARK}a1b2c3d4.npy"  # what a killed run left
    stale.write_bytes(b"partial")
    os.utime(stale, (time.time() - 3600, time.time() - 3600))
    result = project_volume_file(source, paths, output=tmp_path / "fit.npy", loss="quadratic",
                                 **FAST)
    fitted = np.load(tmp_path / "fit.npy")
    assert fitted.sum() == pytest.approx(np.load(source).sum())
    assert result.as_dict()["shape"] == [10, 10, 10]
    assert result.projection.weights == pytest.approx([0.5, 0.5], abs=0.05)
    assert not stale.exists()
