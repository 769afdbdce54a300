"""The shape database: mesh files voxelised in the unit frame, and moved there.

A :class:`VoxelShape` is one mesh normalised by its own centroid and extent
and voxelised (:mod:`wbcgrade.shape.mesh`); :func:`load_shape` reads one
(open scans included), :func:`expand_paths` the files of a database folder,
:func:`place_shape` moves a shape by a similarity of the unit frame and
:func:`voxelised_at` draws it on another grid. What is fitted to the
database is in :mod:`wbcgrade.shape.projection`, the completion in
:mod:`wbcgrade.shape.complete`.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.ndimage as ndi
import trimesh

from wbcgrade.core import refine_grid
from wbcgrade.errors import InputError
from wbcgrade.shape.defaults import DEFAULT_RESOLUTION
from wbcgrade.shape.mesh import MESH_SUFFIXES, normalization_transform, read_mesh, voxelize
from wbcgrade.shape.volume import volume_suffix

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VoxelShape:
    """A shape voxelised in the unit frame.

    name : label (file stem).
    occupancy : (n, n, n) fraction of each voxel inside the shape, in [0, 1].
    transform : (4, 4) similarity transform from the mesh's frame to the unit frame.
    mesh_volume : volume of the mesh in the unit frame (of its voxelisation for
        an open or non-manifold mesh).
    mesh : the mesh in its own frame, kept (``load_shape(keep_mesh=True)``)
        to voxelise the shape again in another frame; None otherwise.
    """

    name: str
    occupancy: np.ndarray
    transform: np.ndarray
    mesh_volume: float
    mesh: trimesh.Trimesh | None = None

    @property
    def voxel_volume(self) -> float:
        """Occupied volume of the voxelisation in the unit frame."""
        h = 1.0 / (self.occupancy.shape[0] - 1)
        return float(self.occupancy.sum()) * h**3


def expand_paths(items: Sequence[str | os.PathLike], kind: str = "mesh") -> list[Path]:
    """Files named by ``items``; folders expand to their mesh (or volume) files, sorted.

    Parameters
    ----------
    items : files or folders.
    kind : "mesh" or "volume": which suffixes a folder contributes.
    """
    paths: list[Path] = []
    for item in items:
        path = Path(item)
        if path.is_dir():
            found = sorted(
                p
                for p in path.iterdir()
                if p.is_file()
                and (
                    p.suffix.lower() in MESH_SUFFIXES if kind == "mesh" else bool(volume_suffix(p))
                )
            )
            if not found:
                raise InputError(f"{path}: the folder holds no {kind} files")
            paths.extend(found)
        elif path.exists():
            paths.append(path)
        else:
            raise InputError(f"{path}: no such file or folder")
    unique = list(dict.fromkeys(p.resolve() for p in paths))
    return [Path(p) for p in unique]


def check_database_size(paths: Sequence[Path]) -> None:
    """A projection needs at least two database shapes."""
    if len(paths) < 2:
        raise InputError(
            f"the database holds {len(paths)} shape{'s' if len(paths) != 1 else ''}; "
            "barycentric coordinates need at least 2"
        )


def load_shape(
    path: str | os.PathLike,
    resolution: int = DEFAULT_RESOLUTION,
    *,
    align: bool = False,
    supersample: int | None = None,
    reference: VoxelShape | None = None,
    warn: Callable[[str], None] | None = None,
    keep_mesh: bool = False,
) -> VoxelShape:
    """Read, normalise and voxelise one mesh file.

    Open and slightly non-manifold meshes (scans) are accepted: their inside
    is decided by generalised winding numbers, and ``warn`` (default: the
    log) is told in one line what was found and repaired.

    Parameters
    ----------
    path : mesh file.
    resolution : voxels per axis.
    align : rotate the principal axes onto x, y, z (see
        :func:`~wbcgrade.shape.mesh.normalization_transform`).
    supersample : samples per voxel and axis; default 2 up to 128^3, 1 above.
    reference : with ``align``, choose among the four proper sign flips of
        the principal axes the one whose voxelisation overlaps ``reference``
        most (IoU), which settles the axes' sign ambiguity consistently
        across a database.
    warn : called with a one-line message when the mesh needed repairs.
    keep_mesh : keep the mesh in the result (see :func:`place_shape`).
    """
    mesh = read_mesh(path, repair=True)
    repairs = mesh.metadata.get("repairs")
    if repairs:
        (warn or log.warning)(f"{path}: {repairs}")
    if supersample is None:
        supersample = voxel_supersample(resolution)
    transform = normalization_transform(mesh, align=align)
    candidates = [transform]
    if align and reference is not None:
        candidates = [_flip_about_centre(signs) @ transform for signs in _PROPER_FLIPS]
    best = None
    for candidate in candidates:
        normalised = mesh.copy()
        normalised.apply_transform(candidate)
        occupancy = voxelize(normalised, resolution, supersample=supersample)
        score = (
            intersection_over_union(occupancy > 0.5, reference.occupancy > 0.5)
            if reference is not None and len(candidates) > 1
            else 0.0
        )
        if best is None or score > best[0]:
            if repairs and "winding" in repairs:  # no volume of its own: the voxels'
                volume = float(occupancy.sum()) / (resolution - 1) ** 3
            else:
                volume = float(normalised.volume)
            best = (score, occupancy, candidate, volume)
    _, occupancy, transform, volume = best
    if occupancy.max() <= 0:
        if repairs and "winding" in repairs:
            raise InputError(f"{path}: the mesh encloses no volume ({repairs.split(';')[0]})")
        raise InputError(f"{path}: the mesh is too thin to cover any voxel at {resolution}^3")
    return VoxelShape(Path(path).stem, occupancy, transform, volume,
                      mesh if keep_mesh else None)


def voxel_supersample(resolution: int) -> int:
    """Samples per voxel and axis by default: 2 up to 128^3, 1 above."""
    return 2 if resolution <= 128 else 1


def place_shape(shape: VoxelShape, placement: np.ndarray) -> VoxelShape:
    """``shape`` moved by the unit-frame similarity ``placement`` (4, 4).

    The mesh, when kept, is voxelised again in the new frame; otherwise the
    occupancy is resampled (trilinear). The result's ``transform`` is
    ``placement @ shape.transform`` and its volume scales with ``placement``.
    """
    placement = np.asarray(placement, dtype=np.float64)
    n = shape.occupancy.shape[0]
    transform = placement @ shape.transform
    if shape.mesh is not None:
        moved = shape.mesh.copy()
        moved.apply_transform(transform)
        occupancy = voxelize(moved, n, supersample=voxel_supersample(n))
    else:
        inverse = np.linalg.inv(placement)
        occupancy = ndi.affine_transform(shape.occupancy, inverse[:3, :3],
                                         offset=inverse[:3, 3] * (n - 1),
                                         order=1, mode="constant", cval=0.0)
    volume = shape.mesh_volume * abs(float(np.linalg.det(placement[:3, :3])))
    return VoxelShape(shape.name, occupancy, transform, volume, shape.mesh)


_PROPER_FLIPS = ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1))


def _flip_about_centre(signs) -> np.ndarray:
    """(4, 4) reflection of the unit frame's axes through its centre (0.5, 0.5, 0.5)."""
    flip = np.eye(4)
    flip[:3, :3] = np.diag(np.asarray(signs, dtype=float))
    flip[:3, 3] = 0.5 - 0.5 * np.asarray(signs, dtype=float)
    return flip


def intersection_over_union(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two boolean volumes of the same shape."""
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 1.0


def voxelised_at(shape: VoxelShape, resolution: int) -> np.ndarray:
    """``shape`` on a ``resolution``^3 grid of its unit frame: its mesh voxelised
    there when kept, else its occupancy interpolated."""
    if shape.mesh is None:
        return refine_grid(shape.occupancy, (resolution,) * 3)
    moved = shape.mesh.copy()
    moved.apply_transform(shape.transform)
    return voxelize(moved, resolution, supersample=voxel_supersample(resolution))
