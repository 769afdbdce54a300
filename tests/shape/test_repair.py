"""Open and non-manifold meshes (scans, cut caps): winding numbers, repairs, completion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from tests.conftest import run_cli
from wbcgrade.errors import InputError
from wbcgrade.shape.complete import complete_shape
from wbcgrade.shape.database import intersection_over_union, load_shape
from wbcgrade.shape.mesh import edge_counts, normalize_mesh, read_mesh, voxelize
from wbcgrade.shape.winding import winding_numbers, winding_numbers_exact

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "shapes"
CUT = Path(__file__).resolve().parent / "data" / "elephant_cut.ply"
DATABASE = ("bull.ply", "cow.off", "elephant.off", "triceratops.off")


def holed(mesh: trimesh.Trimesh, centres, radius: float) -> trimesh.Trimesh:
    """``mesh`` less the faces whose centre lies within ``radius`` of any of ``centres``."""
    keep = np.ones(len(mesh.faces), dtype=bool)
    for centre in centres:
        keep &= np.linalg.norm(mesh.triangles_center - centre, axis=1) > radius
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=True)


@pytest.fixture(scope="module")
def cow_with_holes(tmp_path_factory) -> Path:
    cow = trimesh.load(SAMPLES / "cow.off", force="mesh")
    path = tmp_path_factory.mktemp("holes") / "cow_holes.off"
    holed(cow, [cow.vertices[100], cow.vertices[2000]], 0.06).export(path)
    return path


@pytest.fixture(scope="module")
def database():
    return [load_shape(SAMPLES / name, 20, keep_mesh=True) for name in DATABASE]


@pytest.mark.slow
def test_winding_numbers_tree_matches_exact_sum_and_closes_holes():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    open_sphere = holed(sphere, [(0.0, 0.0, 1.0)], 0.5)  # a cap of the sphere removed
    assert edge_counts(open_sphere)[0] > 0
    rng = np.random.default_rng(0)
    points = np.concatenate([rng.uniform(-1.5, 1.5, (400, 3)),
                             open_sphere.sample(200, seed=1) * rng.uniform(0.97, 1.03, (200, 1))])
    exact = winding_numbers_exact(open_sphere.triangles, points)
    tree = winding_numbers(open_sphere.triangles, points)
    assert np.abs(tree - exact).max() < 0.03
    closed = winding_numbers(sphere.triangles, np.array([[0, 0, 0], [0, 0, 2.0], [0.5, 0.2, 0]]))
    np.testing.assert_allclose(closed, [1, 0, 1], atol=0.03)
    # The hole is closed smoothly: the centre and the points just under the hole are inside.
    assert winding_numbers(open_sphere.triangles, np.array([[0, 0, 0], [0, 0, 0.8]])).min() > 0.5


@pytest.mark.slow
def test_open_mesh_is_voxelised_like_the_closed_one(cow_with_holes):
    with pytest.raises(InputError, match="not closed"):
        read_mesh(cow_with_holes)  # strict reading still refuses it
    closed = read_mesh(SAMPLES / "cow.off")
    opened = read_mesh(cow_with_holes, repair=True)
    assert "2 open holes" in opened.metadata["repairs"]
    _, transform = normalize_mesh(closed)
    closed.apply_transform(transform)
    opened.apply_transform(transform)
    reference = voxelize(closed, 32)
    repaired = voxelize(opened, 32)
    assert intersection_over_union(reference > 0.5, repaired > 0.5) > 0.97
    assert repaired.sum() == pytest.approx(reference.sum(), rel=0.03)


def test_cut_and_capped_mesh_is_voxelised(database):
    boundary, non_manifold = edge_counts(trimesh.load(CUT, force="mesh"))
    assert non_manifold == 2 and boundary > 0  # as trimesh's cap left it
    messages = []
    shape = load_shape(CUT, 20, warn=messages.append)
    assert len(messages) == 1
    assert str(CUT) in messages[0] and "2 non-manifold edges" in messages[0]
    assert "winding numbers" in messages[0]
    elephant = database[DATABASE.index("elephant.off")]
    # 84% of the elephant's volume is kept.
    assert shape.voxel_volume == pytest.approx(0.84 * elephant.voxel_volume, rel=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("source", ["holes", "cut"])
def test_completion_ranks_the_source_shape_first(source, cow_with_holes, database):
    path, expected = (cow_with_holes, "cow") if source == "holes" else (CUT, "elephant")
    partial = load_shape(path, 20, warn=lambda message: None, keep_mesh=True)
    completion = complete_shape(partial, database, n_iter=30, max_iter=5)
    projection = completion.projection
    assert projection.names[projection.order()[0]] == expected, dict(
        zip(projection.names, projection.weights.round(3)))


def test_sheet_of_triangles_is_refused(tmp_path):
    book = tmp_path / "book.off"  # three pages on one edge: no inside to speak of
    book.write_text("OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n0 -1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 1 4\n")
    with pytest.raises(InputError, match="not a surface that encloses a volume.*non-manifold"):
        load_shape(book, 12)


def _complete(args):
    return run_cli("shape", "complete", *args, "-n", "12", "--iterations",
                   "20", "--max-iter", "2", "--quiet")


@pytest.mark.slow
def test_cli_completes_a_mesh_with_holes_with_one_warning(tmp_path, cow_with_holes):
    result = _complete([str(cow_with_holes), "-d", str(SAMPLES / "cow.off"),
                        "-d", str(SAMPLES / "elephant.off"), "-o", str(tmp_path / "c.obj")])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(warnings) == 1, result.stderr
    assert warnings[0].startswith("Warning: ") and str(cow_with_holes) in warnings[0]
    assert "open holes" in warnings[0]
    assert (tmp_path / "c.obj").exists()


@pytest.mark.filterwarnings("error")  # numpy's overflow warnings printed 56 lines
def test_huge_coordinates_give_one_error_line_and_no_numpy_warnings(tmp_path):
    box = trimesh.creation.box()
    path = tmp_path / "huge.off"
    path.write_text(f"OFF\n{len(box.vertices)} {len(box.faces)} 0\n"
                    + "".join(f"{x:g}e300 {y:g}e300 {z:g}e300\n" for x, y, z in box.vertices)
                    + "".join(f"3 {a} {b} {c}\n" for a, b, c in box.faces))
    result = _complete([str(path), "-d", str(SAMPLES / "cow.off"), "-d",
                        str(SAMPLES / "elephant.off"), "-o", str(tmp_path / "h.obj")])
    assert result.exit_code == 1
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    assert "huge.off" in lines[0] and "too large" in lines[0]
