"""The completed surface: the input mesh united with the part a completion adds."""

from __future__ import annotations

import logging
import warnings

import numpy as np
import trimesh

from wbcgrade.shape.complete import (
    SHELL_VOXELS,
    Completion,
    extension_occupancy,
    fitted_occupancy_at,
)
from wbcgrade.shape.database import voxelised_at
from wbcgrade.shape.defaults import DEFAULT_N_ITER
from wbcgrade.shape.mesh import surface_from_volume

log = logging.getLogger(__name__)


SURFACE_MIN_RESOLUTION = 97
"""Voxels per axis, at least, of the grid the completed surface is drawn on."""


def surface_resolution(resolution: int) -> int:
    """Grid for the surface: twice as fine as the fit's, and at least
    :data:`SURFACE_MIN_RESOLUTION` (or four times the fit's, if less)."""
    n = int(resolution)
    return max(2 * (n - 1) + 1, min(SURFACE_MIN_RESOLUTION, 4 * (n - 1) + 1))


def completion_surface(
    completion: Completion,
    smooth_iterations: int = 10,
    resolution: int | None = None,
    n_iter: int = DEFAULT_N_ITER,
) -> trimesh.Trimesh:
    """Closed surface of the completed shape, in the input mesh's own frame.

    The part of the fitted shape that extends the input
    (:func:`extension_occupancy`) is drawn on a grid finer than the fit's
    (``resolution``, default :func:`surface_resolution`; the fitted shape
    drawn there by :func:`fitted_occupancy_at`, ``n_iter`` iterations), its
    iso-surface mapped back through the placed input's transform and united
    with the input mesh itself (a mesh boolean, manifold3d): the observed
    surface is kept exactly, the added part extends it wherever the database
    says, beyond the input's bounding box if need be. When the input is not
    a closed volume (a scan with holes), its mesh was not kept or the
    boolean is unavailable, the union is taken on the fine grid instead
    (the observed part then moves by up to a fine voxel).

    Returns
    -------
    trimesh.Trimesh (watertight); added components smaller than 1% of the
    largest one's volume (specks) are dropped.
    """
    n = completion.shape.shape[0]
    fine = surface_resolution(n) if resolution is None else int(resolution)
    partial = completion.partial
    observed = voxelised_at(partial, fine)
    fitted = fitted_occupancy_at(completion, fine, n_iter)
    extension = extension_occupancy(fitted, observed, SHELL_VOXELS * (fine - 1) / (n - 1))
    source = partial.mesh
    if source is not None and _is_volume(source):
        if not np.any(extension > 0.5):
            return source.copy()
        added = _surface(extension, partial.transform, smooth_iterations)
        united = _union(source, added)
        if united is not None:
            return united
    return _surface(np.maximum(observed, extension), partial.transform, smooth_iterations)


def _is_volume(mesh: trimesh.Trimesh) -> bool:
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        return bool(mesh.is_volume)


def _surface(volume: np.ndarray, transform: np.ndarray, smooth_iterations: int) -> trimesh.Trimesh:
    """Iso-surface at 1/2 of a unit-frame occupancy, in the input's frame, specks dropped."""
    surface = surface_from_volume(volume, 0.5, transform=transform,
                                  smooth_iterations=smooth_iterations)
    parts = surface.split(only_watertight=True)
    if len(parts) > 1:
        volumes = np.array([abs(p.volume) for p in parts])
        keep = [p for p, v in zip(parts, volumes, strict=True) if v >= 0.01 * volumes.max()]
        surface = trimesh.util.concatenate(keep)
    return surface


def _union(first: trimesh.Trimesh, second: trimesh.Trimesh) -> trimesh.Trimesh | None:
    """Boolean union of two closed meshes (manifold3d), or None when it cannot be had."""
    try:
        united = trimesh.boolean.union([first, second], engine="manifold")
    except Exception as exc:  # no manifold3d, or a mesh it refuses
        log.info("mesh union unavailable (%s); uniting on the voxel grid", exc)
        return None
    if not (united.is_watertight and united.volume >= 0.999 * first.volume):
        log.info("mesh union gave no closed superset of the input; uniting on the voxel grid")
        return None
    return united
