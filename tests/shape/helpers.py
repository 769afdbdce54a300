"""Small synthetic meshes and volumes for the shape tests."""

from __future__ import annotations

import numpy as np
import trimesh

from wbcgrade.shape.database import VoxelShape
from wbcgrade.shape.mesh import normalize_mesh, voxelize


def synthetic_meshes() -> dict[str, trimesh.Trimesh]:
    """Closed meshes of clearly different shapes."""
    return {
        "box": trimesh.creation.box(extents=(1.0, 0.5, 0.5)),
        "sphere": trimesh.creation.icosphere(subdivisions=3),
        "torus": trimesh.creation.torus(major_radius=1.0, minor_radius=0.35),
    }


def voxel_shapes(resolution: int) -> list[VoxelShape]:
    """The synthetic meshes, normalised and voxelised."""
    shapes = []
    for name, mesh in synthetic_meshes().items():
        normalised, transform = normalize_mesh(mesh)
        occupancy = voxelize(normalised, resolution)
        shapes.append(VoxelShape(name, occupancy, transform, float(normalised.volume)))
    return shapes


def ball(n: int, radius: float = 0.3, centre=(0.5, 0.5, 0.5)) -> np.ndarray:
    """Occupancy (n, n, n) of a ball in the unit frame."""
    x = np.linspace(0, 1, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    d2 = (X - centre[0]) ** 2 + (Y - centre[1]) ** 2 + (Z - centre[2]) ** 2
    return (d2 <= radius**2).astype(float)
