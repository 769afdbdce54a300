"""Completions measured against the truth: shipped meshes cut by a plane, completed, compared.

Each case cuts a whole sample mesh across its longest axis (the end 20-35 %
of its length removed, the cut capped), completes it against a database of
whole meshes that holds it, and measures the written mesh in the input's own
frame (``wbcgrade.shape.evaluate.restoration``). Small grids; the same
measure over more meshes and cuts: ``benchmarks/shape.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from wbcgrade.shape.complete import complete_shape
from wbcgrade.shape.database import load_shape
from wbcgrade.shape.evaluate import cut_mesh, restoration
from wbcgrade.shape.mesh import read_mesh, voxelize_together
from wbcgrade.shape.sheets import ADDED_COLOR, completion_sheet
from wbcgrade.shape.surface import completion_surface
from wbcgrade.shape.workflow import complete_mesh_file

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "shapes"
DATABASE = [SAMPLES / name for name in ("bull.ply", "cow.off", "elephant.off", "triceratops.off")]
FIT = {"resolution": 32, "n_iter": 40, "max_iter": 5}


def _cut(path: Path, fraction: float, from_top: bool) -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    whole = read_mesh(path)
    return whole, cut_mesh(whole, int(np.argmax(whole.extents)), fraction, from_top)


def test_cut_mesh_removes_the_end_and_closes_the_cut():
    whole, partial = _cut(SAMPLES / "cow.off", 0.3, from_top=False)
    axis = int(np.argmax(whole.extents))
    assert partial.is_watertight and partial.volume > 0
    assert partial.bounds[0, axis] == pytest.approx(
        whole.bounds[0, axis] + 0.3 * whole.extents[axis], abs=1e-9)
    assert partial.bounds[1, axis] == pytest.approx(whole.bounds[1, axis])
    assert 0.5 * whole.volume < partial.volume < 0.95 * whole.volume
    itself = restoration(whole, partial, whole, resolution=32)
    assert itself.restored == 1.0 and itself.iou_completed == 1.0
    assert itself.iou_partial < 0.95 and itself.cut_fraction > 0.05


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "fraction", "from_top"),
    [("elephant.off", 0.3, True), ("triceratops.off", 0.25, False), ("bull.ply", 0.35, True),
     ("cow.off", 0.2, False)],
)
def test_plane_cut_is_restored_in_the_input_frame(tmp_path, name, fraction, from_top):
    whole, partial = _cut(SAMPLES / name, fraction, from_top)
    # Moved and scaled: the completion must come back in the input's own coordinates.
    partial.apply_transform(trimesh.transformations.compose_matrix(
        scale=[2.5] * 3, translate=[3.0, -1.0, 0.5]))
    whole.apply_transform(trimesh.transformations.compose_matrix(
        scale=[2.5] * 3, translate=[3.0, -1.0, 0.5]))
    path = tmp_path / "partial.ply"
    partial.export(path)
    result = complete_mesh_file(path, DATABASE, output=tmp_path / "done.ply", **FIT)
    completed = trimesh.load(tmp_path / "done.ply", force="mesh")
    measured = restoration(whole, partial, completed)
    assert measured.restored >= 0.6, measured
    assert measured.iou_completed > measured.iou_partial, measured
    # The observed part is kept where it was; the added part goes past the cut.
    (observed, done), _ = voxelize_together([partial, completed], 64)
    assert np.count_nonzero((observed > 0.5) & (done > 0.5)) >= 0.99 * np.count_nonzero(
        observed > 0.5)
    axis = int(np.argmax(whole.extents))
    side = 1 if from_top else 0
    beyond = completed.bounds[side, axis] - partial.bounds[side, axis]
    assert abs(beyond) > 0.5 * abs(whole.bounds[side, axis] - partial.bounds[side, axis])
    assert np.sign(beyond) == (1 if from_top else -1)
    projection = result.projection
    assert projection.names[int(np.argmax(projection.weights))] == Path(name).stem
    # The missing fraction was estimated where the input sits on the database.
    truth = 1.0 - partial.volume / whole.volume
    assert projection.missing == pytest.approx(truth, abs=0.15)


def _is_added_colour(image: np.ndarray) -> np.ndarray:
    """Pixels of the added part's hue (blue), whatever their shading."""
    rgb = np.asarray(ADDED_COLOR)
    norm = image / np.maximum(image.max(axis=-1, keepdims=True), 1e-6)
    return (image.max(axis=-1) > 0.15) & (np.abs(norm - rgb / rgb.max()).max(axis=-1) < 0.12)


@pytest.mark.slow
def test_sheet_draws_the_input_and_the_added_part_in_the_input_frame(tmp_path):
    whole = read_mesh(SAMPLES / "cow.off")
    partial = cut_mesh(whole, 1, 0.3, from_top=False)  # the legs
    path = tmp_path / "legless.ply"
    partial.export(path)
    shape = load_shape(path, 20, keep_mesh=True)
    database = [load_shape(p, 20, keep_mesh=True) for p in DATABASE]
    completion = complete_shape(shape, database, n_iter=30, max_iter=3)
    surface = completion_surface(completion, n_iter=30)
    sheet = completion_sheet(completion, top=1, tile=120, surface=surface)
    columns = [sheet[:, 4 + c * 124: 4 + c * 124 + 120] for c in range(3)]
    added = [np.count_nonzero(_is_added_colour(column)) for column in columns]
    assert added[0] == 0 and added[2] == 0  # the input; the database shape
    assert added[1] > 200  # the legs, drawn below the input's body
    rows = np.nonzero(_is_added_colour(columns[1][:22 + 124]).any(axis=1))[0]
    body = np.nonzero((columns[0][:22 + 124].max(axis=-1) > 0.15).any(axis=1))[0]
    assert rows.max() > body.max()
