"""Triangle meshes: reading, normalising, voxelising and surface extraction.

Meshes are read with trimesh (OFF, OBJ, PLY, STL, ...). Every mesh is mapped
into the *unit frame* ``[0, 1]^3`` (the frame of the core's grid points,
``linspace(0, 1, n)`` per axis) by a similarity transform, voxelised there,
and the completed surface is mapped back with the inverse transform.

Normalisation (:func:`normalization_transform`)
    centre = the mesh's volume centroid, moved to ``(0.5, 0.5, 0.5)``;
    scale  = the largest coordinate distance from the centroid is mapped to
    ``0.5 - margin``. Centring on the centroid (not the bounding box) keeps a
    partial scan close to where its complete shape would sit when the missing
    part is small in volume; optional principal-axes alignment rotates the
    inertia axes onto x, y, z (largest extent first) for databases whose
    meshes are not aligned.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import trimesh

from wbcgrade.errors import InputError

MESH_SUFFIXES = (".off", ".obj", ".ply", ".stl")
"""File suffixes read and written as meshes."""


def read_mesh(path: str | os.PathLike) -> trimesh.Trimesh:
    """Read a closed triangle mesh.

    Parameters
    ----------
    path : file in a format trimesh reads (``.off``, ``.obj``, ``.ply``, ``.stl``).

    Returns
    -------
    trimesh.Trimesh with consistent outward winding.

    Raises
    ------
    InputError
        The file is missing or unreadable, the mesh is empty, has non-manifold
        edges (shared by more than two faces) or is not closed.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such mesh file")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(
            f"{path}: unsupported mesh format {path.suffix or '(none)'!r}; "
            f"use one of {', '.join(MESH_SUFFIXES)}"
        )
    try:
        loaded = trimesh.load(str(path), force="mesh", process=True)
    except Exception as exc:  # trimesh raises many kinds on corrupt files
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: unreadable mesh ({detail})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise InputError(f"{path}: the mesh is empty (no triangles)")
    check_closed_mesh(loaded, name=str(path))
    if loaded.volume < 0:
        loaded.invert()
    return loaded


def check_closed_mesh(mesh: trimesh.Trimesh, name: str = "mesh") -> None:
    """Raise :class:`InputError` unless ``mesh`` is a closed 2-manifold with volume.

    Open meshes whose holes are single triangles or quads are closed in place
    (``trimesh.repair.fill_holes``); larger holes are refused, since the
    inside of an open surface is undefined.
    """
    if len(mesh.faces) == 0:
        raise InputError(f"{name}: the mesh is empty (no triangles)")
    _, counts = np.unique(mesh.edges_sorted, axis=0, return_counts=True)
    n_non_manifold = int(np.count_nonzero(counts > 2))
    if n_non_manifold:
        raise InputError(
            f"{name}: non-manifold mesh ({n_non_manifold} edges shared by more than two faces)"
        )
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
    if not mesh.is_watertight:
        _, counts = np.unique(mesh.edges_sorted, axis=0, return_counts=True)
        n_boundary = int(np.count_nonzero(counts == 1))
        raise InputError(
            f"{name}: the mesh is not closed ({n_boundary} boundary edges); "
            "close its holes first (e.g. MeshLab 'Close Holes')"
        )
    if not mesh.is_winding_consistent:
        trimesh.repair.fix_winding(mesh)
    if abs(mesh.volume) <= 1e-12 * max(float(np.prod(mesh.extents)), 1e-300):
        raise InputError(f"{name}: the mesh encloses no volume")


def normalization_transform(
    mesh: trimesh.Trimesh, align: bool = False, margin: float = 0.05
) -> np.ndarray:
    """Similarity transform taking ``mesh`` into the unit frame ``[0, 1]^3``.

    Parameters
    ----------
    mesh : closed mesh.
    align : also rotate the principal inertia axes onto x, y, z (largest
        spread first; signs chosen so the third moment along each axis is
        positive, right-handed).
    margin : empty border left on each side, as a fraction of the unit cube.

    Returns
    -------
    (4, 4) homogeneous matrix ``T``; ``mesh.apply_transform(T)`` normalises.
    """
    if not 0.0 <= margin < 0.5:
        raise InputError(f"margin must be in [0, 0.5), got {margin}")
    centroid = np.asarray(mesh.center_mass if mesh.is_volume else mesh.centroid, float)
    rotation = np.eye(3)
    if align:
        rotation = _principal_axes(mesh.vertices - centroid, mesh)
    local = (mesh.vertices - centroid) @ rotation.T
    radius = float(np.abs(local).max())
    if not np.isfinite(radius) or radius <= 0.0:
        raise InputError("the mesh has no extent (all vertices coincide)")
    scale = (0.5 - margin) / radius
    transform = np.eye(4)
    transform[:3, :3] = scale * rotation
    transform[:3, 3] = 0.5 - scale * rotation @ centroid
    return transform


def _principal_axes(centred: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """Rotation (3, 3) whose rows are the principal axes, largest spread first."""
    inertia = np.asarray(mesh.moment_inertia, float)
    # Principal inertia components: the axis of *smallest* inertia is the one of
    # largest spread, so sort eigenvalues ascending.
    eigenvalues, eigenvectors = np.linalg.eigh(inertia)
    axes = eigenvectors[:, np.argsort(eigenvalues)].T
    projected = centred @ axes.T
    skew = np.mean(projected**3, axis=0)
    signs = np.where(skew < 0, -1.0, 1.0)
    axes = axes * signs[:, None]
    if np.linalg.det(axes) < 0:
        axes[2] = -axes[2]
    return axes


def normalize_mesh(
    mesh: trimesh.Trimesh, align: bool = False, margin: float = 0.05
) -> tuple[trimesh.Trimesh, np.ndarray]:
    """Copy of ``mesh`` in the unit frame, and the (4, 4) transform used."""
    transform = normalization_transform(mesh, align=align, margin=margin)
    normalised = mesh.copy()
    normalised.apply_transform(transform)
    return normalised, transform


def voxel_centers(resolution: int) -> np.ndarray:
    """Voxel centre coordinates along one axis, ``linspace(0, 1, n)``, shape (n,)."""
    return np.linspace(0.0, 1.0, resolution)


def voxelize(mesh: trimesh.Trimesh, resolution: int, supersample: int = 2) -> np.ndarray:
    """Fraction of each voxel inside a closed mesh given in the unit frame.

    Voxel ``(i, j, k)`` is the cube of side ``h = 1 / (n - 1)`` centred at
    ``(i, j, k) * h`` (the core's grid points). Each voxel is sampled at
    ``supersample^3`` points; a point is inside when rays along at least two
    of the three axes cross the surface an odd number of times below it
    (scan-line parity, majority vote over the axes, which makes the result
    robust to rays grazing edges).

    Parameters
    ----------
    mesh : closed mesh in the unit frame (see :func:`normalize_mesh`).
    resolution : n, voxels per axis (>= 2).
    supersample : samples per voxel and axis (1 = voxel centres only).

    Returns
    -------
    occupancy : (n, n, n) float64 array in [0, 1], C order (x, y, z).
    """
    if resolution < 2:
        raise InputError(f"resolution must be at least 2, got {resolution}")
    if supersample < 1:
        raise InputError(f"supersample must be at least 1, got {supersample}")
    n, s = int(resolution), int(supersample)
    h = 1.0 / (n - 1)
    m = n * s
    # Sample coordinates along one axis: s points per voxel, centred in the voxel.
    samples = (np.arange(m) + 0.5) * (h / s) - 0.5 * h
    triangles = np.asarray(mesh.triangles, dtype=np.float64)
    votes = np.zeros((m, m, m), dtype=np.uint8)
    for axis in range(3):
        votes += _parity_along_axis(triangles, samples, axis)
    inside = votes >= 2
    del votes
    return inside.reshape(n, s, n, s, n, s).mean(axis=(1, 3, 5))


def _parity_along_axis(triangles: np.ndarray, samples: np.ndarray, axis: int) -> np.ndarray:
    """Inside mask (m, m, m) by crossing parity of rays parallel to ``axis``."""
    m = samples.size
    step = samples[1] - samples[0] if m > 1 else 1.0
    others = [a for a in range(3) if a != axis]
    # A tiny irrational offset keeps rays off vertices and edges lying exactly on the grid.
    jitter = step * np.array([1.0e-6 * np.sqrt(2.0), 1.0e-6 * np.sqrt(3.0)])
    u = triangles[:, :, others[0]] - jitter[0]  # (F, 3)
    v = triangles[:, :, others[1]] - jitter[1]
    w = triangles[:, :, axis]
    # Signed doubled area of the projected triangles; skip degenerate ones.
    area = (u[:, 1] - u[:, 0]) * (v[:, 2] - v[:, 0]) - (u[:, 2] - u[:, 0]) * (v[:, 1] - v[:, 0])
    keep = np.abs(area) > 1e-300
    u, v, w, area = u[keep], v[keep], w[keep], area[keep]
    first = samples[0]
    lo_u = np.clip(np.ceil((u.min(1) - first) / step), 0, m).astype(np.int64)
    hi_u = np.clip(np.floor((u.max(1) - first) / step), -1, m - 1).astype(np.int64)
    lo_v = np.clip(np.ceil((v.min(1) - first) / step), 0, m).astype(np.int64)
    hi_v = np.clip(np.floor((v.max(1) - first) / step), -1, m - 1).astype(np.int64)
    count_u = np.maximum(hi_u - lo_u + 1, 0)
    count_v = np.maximum(hi_v - lo_v + 1, 0)
    counts = count_u * count_v
    toggles = np.zeros((m, m, m + 1), dtype=np.uint8)
    # Enumerate candidate (triangle, ray) pairs in chunks to bound memory.
    chunk = 4_000_000
    offsets = np.concatenate([[0], np.cumsum(counts)])
    start_tri = 0
    n_tri = counts.size
    while start_tri < n_tri:
        stop_tri = int(np.searchsorted(offsets, offsets[start_tri] + chunk, side="right")) - 1
        stop_tri = min(max(stop_tri, start_tri + 1), n_tri)
        idx = np.arange(start_tri, stop_tri)
        c = counts[idx]
        tri = np.repeat(idx, c)
        if tri.size:
            local = np.arange(tri.size) - np.repeat(offsets[idx] - offsets[start_tri], c)
            iu = lo_u[tri] + local // count_v[tri]
            iv = lo_v[tri] + local % count_v[tri]
            pu = samples[iu]
            pv = samples[iv]
            tu, tv, tw, ta = u[tri], v[tri], w[tri], area[tri]
            # Barycentric coordinates of the ray's foot point in the projected triangle.
            b0 = ((tu[:, 1] - pu) * (tv[:, 2] - pv) - (tu[:, 2] - pu) * (tv[:, 1] - pv)) / ta
            b1 = ((tu[:, 2] - pu) * (tv[:, 0] - pv) - (tu[:, 0] - pu) * (tv[:, 2] - pv)) / ta
            b2 = 1.0 - b0 - b1
            hit = (b0 >= 0) & (b1 >= 0) & (b2 >= 0)
            depth = b0[hit] * tw[hit, 0] + b1[hit] * tw[hit, 1] + b2[hit] * tw[hit, 2]
            first_above = np.searchsorted(samples, depth, side="right")
            np.add.at(toggles, (iu[hit], iv[hit], first_above), 1)
        start_tri = stop_tri
    # uint8 wrap-around keeps parity.
    parity = (np.cumsum(toggles[:, :, :m], axis=2, dtype=np.uint8) & 1).astype(np.uint8)
    # Back to (x, y, z) order: the ray axis was put last.
    order = [*others, axis]
    return np.moveaxis(parity, [0, 1, 2], order)


def surface_from_volume(
    volume: np.ndarray,
    level: float,
    transform: np.ndarray | None = None,
    smooth_iterations: int = 10,
) -> trimesh.Trimesh:
    """Closed iso-surface ``{volume = level}`` by marching cubes.

    Parameters
    ----------
    volume : (n, n, n) array on the unit-frame grid (voxel centres
        ``linspace(0, 1, n)``).
    level : iso-value; the surface encloses the voxels above it.
    transform : (4, 4) normalisation transform of the input mesh; the
        surface is mapped back through its inverse (None: stay in the unit frame).
    smooth_iterations : Taubin smoothing passes (0: none), which remove the
        voxel staircase while keeping the volume and the closed topology.

    Returns
    -------
    trimesh.Trimesh, watertight (the volume is padded with values below
    ``level`` so that the surface closes at the grid border).
    """
    from skimage.measure import marching_cubes

    volume = np.asarray(volume, dtype=np.float64)
    if volume.ndim != 3:
        raise InputError(f"expected a 3-D volume, got shape {volume.shape}")
    if not np.any(volume > level):
        raise InputError("the iso-surface is empty: no voxel lies above the level")
    spacing = 1.0 / (max(volume.shape) - 1)
    padded = np.pad(volume, 1, mode="constant", constant_values=min(level, volume.min()) - 1.0)
    # Degenerate (zero-area) triangles leave edges shared by 4 or 6 faces: drop them.
    verts, faces, _, _ = marching_cubes(
        padded, level=level, spacing=(spacing,) * 3, allow_degenerate=False
    )
    verts -= spacing  # undo the padding offset
    surface = trimesh.Trimesh(vertices=verts, faces=faces, process=True)
    # skimage's faces point inwards for volumes that are larger inside.
    if surface.volume < 0:
        surface.invert()
    if smooth_iterations > 0:
        trimesh.smoothing.filter_taubin(surface, iterations=smooth_iterations)
    if transform is not None:
        surface.apply_transform(np.linalg.inv(transform))
    return surface


def write_mesh(mesh: trimesh.Trimesh, path: str | os.PathLike) -> None:
    """Write ``mesh`` atomically in the format given by the suffix of ``path``."""
    path = Path(path)
    file_type = path.suffix.lower().lstrip(".")
    if "." + file_type not in MESH_SUFFIXES:
        raise InputError(
            f"{path}: unsupported mesh format {path.suffix or '(none)'!r}; "
            f"use one of {', '.join(MESH_SUFFIXES)}"
        )
    data = trimesh.exchange.export.export_mesh(mesh, file_obj=None, file_type=file_type)
    atomic_write_bytes(path, data.encode() if isinstance(data, str) else data)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, then rename it over ``path``."""
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"{directory}: output folder does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
