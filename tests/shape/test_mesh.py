"""Mesh reading, normalisation, voxelisation and surfaces."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from tests.shape.helpers import ball, synthetic_meshes
from wbcgrade.errors import InputError
from wbcgrade.shape.mesh import (
    normalize_mesh,
    read_mesh,
    surface_from_volume,
    voxelize,
    write_mesh,
)

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "shapes"


def test_voxel_volume_matches_mesh_volume_for_sample_meshes():
    for name in ("cow.off", "bull.ply"):
        mesh, _ = normalize_mesh(read_mesh(SAMPLES / name))
        n = 32
        occupancy = voxelize(mesh, n)
        voxel_volume = occupancy.sum() / (n - 1) ** 3
        assert voxel_volume == pytest.approx(mesh.volume, rel=0.05), name


@pytest.mark.parametrize("name", ["box", "sphere", "torus"])
def test_voxel_volume_matches_mesh_volume_for_closed_shapes(name):
    mesh, _ = normalize_mesh(synthetic_meshes()[name])
    n = 32  # a box's flat faces alias most; at 24^3 it is off by 5.3%
    occupancy = voxelize(mesh, n)
    assert occupancy.min() >= 0 and occupancy.max() <= 1
    assert occupancy.sum() / (n - 1) ** 3 == pytest.approx(mesh.volume, rel=0.05)


def test_voxelisation_is_inside_out_consistent():
    """A torus's hole is empty, its tube full."""
    mesh, _ = normalize_mesh(synthetic_meshes()["torus"])
    occupancy = voxelize(mesh, 21, supersample=1)
    assert occupancy[10, 10, 10] == 0  # centre of the hole
    tube = np.argmax(occupancy[:, 10, 10])
    assert occupancy[tube + 1, 10, 10] == 1


def test_normalisation_fits_the_unit_cube_and_inverts():
    mesh = synthetic_meshes()["box"]
    mesh.apply_transform(trimesh.transformations.random_rotation_matrix(seed=1))
    mesh.apply_scale(37.0)
    for align in (False, True):
        normalised, transform = normalize_mesh(mesh, align=align, margin=0.05)
        assert normalised.bounds.min() >= 0.05 - 1e-9 and normalised.bounds.max() <= 0.95 + 1e-9
        assert np.allclose(normalised.center_mass, 0.5)
        back = normalised.copy()
        back.apply_transform(np.linalg.inv(transform))
        assert np.allclose(back.vertices, mesh.vertices)
    # Principal axes put the box's long side along x.
    aligned, _ = normalize_mesh(mesh, align=True)
    extents = aligned.extents
    assert extents[0] == pytest.approx(0.9) and extents[1] < 0.5 and extents[2] < 0.5


def test_surface_is_watertight_and_maps_back(tmp_path):
    occupancy = ball(20, radius=0.3)
    occupancy[:, :8, :] = 0  # a flat cut leaves a closed surface all the same
    transform = np.diag([2.0, 2.0, 2.0, 1.0])
    surface = surface_from_volume(occupancy, 0.5, transform=transform)
    assert surface.is_watertight and surface.volume > 0
    # In the original frame (half the size of the unit frame).
    assert surface.bounds.max() <= 0.5
    for suffix in (".obj", ".ply", ".stl", ".off"):
        path = tmp_path / f"out{suffix}"
        write_mesh(surface, path)
        assert read_mesh(path).is_watertight
    assert not list(tmp_path.glob(".*tmp"))


def test_sample_partial_is_closed():
    assert read_mesh(SAMPLES / "cow_partial.ply").is_watertight


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


BAD_MESHES = {
    "garbage.off": ("OFF\nthis is not a mesh\n", "unreadable"),
    "empty.off": ("OFF\n0 0 0\n", "empty"),
    "nonmanifold.off": (
        # Three triangles on one edge (0-1), plus their closing faces: a "book" of pages.
        "OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n0 -1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 1 4\n",
        "non-manifold",
    ),
    "open.off": ("OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 1\n3 0 1 2\n3 0 2 3\n", "not closed"),
    "mesh.xyz": ("1 2 3\n", "unsupported"),
}


@pytest.mark.parametrize("name", sorted(BAD_MESHES))
def test_bad_meshes_are_refused(tmp_path, name):
    text, message = BAD_MESHES[name]
    with pytest.raises(InputError, match=message):
        read_mesh(_write(tmp_path / name, text))


def test_missing_file_is_refused(tmp_path):
    with pytest.raises(InputError, match="no such"):
        read_mesh(tmp_path / "absent.obj")
