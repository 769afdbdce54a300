"""Measuring completions against the truth: plane cuts and restored volume.

- :func:`cut_mesh`: cut a closed mesh by a plane across one axis and cap
  the cut, as a partial scan to complete.
- :func:`restoration`: how much of the cut part a completion gives back, and
  its IoU with the whole mesh beside the partial input's, all voxelised on
  one grid in the meshes' own frame.

Used by the tests and ``benchmarks/shape.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from trimesh.intersections import slice_faces_plane

from wbcgrade.errors import InputError
from wbcgrade.shape.database import intersection_over_union
from wbcgrade.shape.mesh import voxelize_together


def cut_mesh(
    mesh: trimesh.Trimesh, axis: int, fraction: float, from_top: bool = True
) -> trimesh.Trimesh:
    """``mesh`` with the end ``fraction`` of its length along ``axis`` cut away, capped.

    Parameters
    ----------
    mesh : closed mesh.
    axis : 0, 1 or 2: the cutting plane is perpendicular to this axis.
    fraction : part of the bounding box's extent along ``axis`` removed, in (0, 1).
    from_top : remove the end of larger coordinates (else of smaller ones).

    Returns
    -------
    trimesh.Trimesh, closed: each loop of the cut is capped by a fan of
    triangles from one point of the plane (overlapping where a loop is not
    star-shaped, which leaves inside/outside and the volume exact).
    """
    if not 0.0 < fraction < 1.0:
        raise InputError(f"the cut fraction must be in (0, 1), got {fraction}")
    lo, hi = mesh.bounds[:, axis]
    normal = np.zeros(3)
    normal[axis] = -1.0 if from_top else 1.0
    origin = np.zeros(3)
    origin[axis] = hi - fraction * (hi - lo) if from_top else lo + fraction * (hi - lo)
    vertices, faces = slice_faces_plane(mesh.vertices, mesh.faces, plane_normal=normal,
                                        plane_origin=origin)[:2]
    part = trimesh.Trimesh(vertices, faces, process=True)
    part.merge_vertices()
    boundary = part.edges[trimesh.grouping.group_rows(part.edges_sorted, require_count=1)]
    height = part.vertices[:, axis] - origin[axis]
    tolerance = 1e-9 * max(1.0, float(np.abs(part.vertices).max()))
    on_plane = boundary[np.all(np.abs(height[boundary]) <= tolerance, axis=1)]
    if len(on_plane) == 0:
        raise InputError("the plane does not cut the mesh")
    apex = part.vertices[np.unique(on_plane)].mean(axis=0)
    cap = np.column_stack([on_plane[:, 1], on_plane[:, 0], np.full(len(on_plane),
                                                                    len(part.vertices))])
    return trimesh.Trimesh(np.vstack([part.vertices, apex]), np.vstack([part.faces, cap]),
                           process=False)


@dataclass(frozen=True)
class Restoration:
    """A completion measured against the whole mesh (voxels of one grid).

    restored : fraction of the cut part's voxels inside the completion.
    iou_partial : IoU of the partial input with the whole mesh.
    iou_completed : IoU of the completion with the whole mesh.
    cut_fraction : the cut part's share of the whole mesh's voxels.
    """

    restored: float
    iou_partial: float
    iou_completed: float
    cut_fraction: float


def restoration(
    whole: trimesh.Trimesh,
    partial: trimesh.Trimesh,
    completed: trimesh.Trimesh,
    resolution: int = 64,
) -> Restoration:
    """Measure ``completed`` against ``whole``; all three meshes in one frame.

    The meshes are voxelised on one grid of ``resolution`` voxels along the
    longest side of their joint bounding box (a voxel is in when more than
    half of it is).
    """
    occupancies, _ = voxelize_together([whole, partial, completed], resolution, supersample=2)
    full, observed, done = (o > 0.5 for o in occupancies)
    cut = full & ~observed
    n_cut = np.count_nonzero(cut)

    return Restoration(
        restored=float(np.count_nonzero(cut & done) / n_cut) if n_cut else 1.0,
        iou_partial=intersection_over_union(observed, full),
        iou_completed=intersection_over_union(done, full),
        cut_fraction=n_cut / max(1, np.count_nonzero(full)),
    )
