"""Completing shapes and projecting volumes onto a database (paper §5.3-5.4).

Pipeline: meshes are normalised into the unit frame and voxelised
(:mod:`wbcgrade.shape.mesh`), turned into densities (uniform inside, ``eps``
times less outside, summing to 1), and the input's density ``q`` is
explained by the Wasserstein barycenter ``P(w)`` of the database densities,
fitted by the core's :func:`~wbcgrade.core.barycentric_coordinates` with

    target = (1 - alpha) * q / sum(q)

where ``alpha`` is the fraction of the shape's volume missing from the input
(the barycenter has mass 1, the observed part only ``1 - alpha`` of it).

Kernel width. The Gibbs kernel is a Gaussian of standard deviation
``width`` voxels (``GridGeometry.with_width``). The barycenter of L
iterations is blurred by about that much, so the width should be small next
to the shapes' thinnest parts, but wide enough for mass to travel between
shapes in L iterations. :func:`default_width` uses 1 voxel at 64^3 and keeps
the width a fixed fraction (1/63) of the box at other resolutions, never below
1 voxel: the same physical smoothing whatever the resolution. Measured at
64^3 (cow 0.9 + triceratops 0.1, L = 60): IoU of the iso-surface with the cow
0.884 at 1.5 voxels, 0.905 at 1.0, 0.913 at 0.75; all in the fast scaling
domain; narrower kernels widen the scalings' range (docs/architecture.md, numerics).

Missing fraction. When not given, ``alpha`` is estimated as the volume the
input lacks relative to the database's mean volume in the unit frame,
clipped to ``[0, 0.9]`` (:func:`estimate_missing_fraction`); like the paper's
"rough estimate" it is only as good as the database is similar in size to
the input, so pass it explicitly when it is known. Note that the barycenter
always has mass 1, so for both KL losses the factor ``1 - alpha`` only adds a
constant to the energy and leaves the fitted weights unchanged; it matters
for the quadratic and L1 losses, where it sets the density level at which the
observed part is matched.

Loss. The default is ``kl_reverse``, ``KL(q | P)``, rather than the paper's
``KL(P | q)`` (available as ``kl``): the paper's direction charges the
barycenter for every bit of mass it puts where the input is missing, which
is exactly what a completion must do, and on shapes with a slab cut away it
prefers wrong weights to the true ones (see :data:`KL_REVERSE`).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade.core import (
    GridGeometry,
    Loss,
    barycentric_coordinates,
    get_loss,
    mixture_coordinates,
    resample_grid,
)
from wbcgrade.core.barycenter import DEFAULT_CHECKPOINT_BYTES, gradient_memory
from wbcgrade.errors import InputError
from wbcgrade.shape.defaults import (  # noqa: F401 - re-exported
    DEFAULT_LOSS,
    DEFAULT_MAX_ITER,
    DEFAULT_N_ITER,
    DEFAULT_RESOLUTION,
    LOSS_NAMES,
)
from wbcgrade.shape.mesh import MESH_SUFFIXES, normalization_transform, read_mesh, voxelize
from wbcgrade.shape.volume import DEFAULT_EPS, density_from_volume, volume_suffix

log = logging.getLogger(__name__)

COARSE_MIN_SIZE = 16
MAX_MISSING = 0.9


# --------------------------------------------------------------------------- loss


KL_REVERSE = get_loss("kl_reverse")
"""KL of the input from the barycenter, ``KL(q | P)`` (the paper's KL reversed).

The paper's ``KL(P | q)`` charges ``P log(P / q)`` where the input is missing
(``q`` at the floor), i.e. it penalises exactly the mass a completion must put
there: on a barycenter of database shapes with a slab cut away, the true
weights score worse than shapes that avoid the cut (measured: 2.14 against
1.51 at 20^3). ``KL(q | P)`` only asks the barycenter to cover the observed
part; a completion costs at most its (linear) mass.
"""

def resolve_loss(name: str | Loss) -> Loss:
    """The :class:`~wbcgrade.core.Loss` called ``name`` (``kl_reverse`` or a core loss)."""
    return get_loss(name)


# --------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class VoxelShape:
    """A shape voxelised in the unit frame.

    name : label (file stem).
    occupancy : (n, n, n) fraction of each voxel inside the shape, in [0, 1].
    transform : (4, 4) similarity transform from the mesh's frame to the unit frame.
    mesh_volume : volume of the mesh in the unit frame (of its voxelisation for
        an open or non-manifold mesh).
    """

    name: str
    occupancy: np.ndarray
    transform: np.ndarray
    mesh_volume: float

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
    align: bool = False,
    supersample: int | None = None,
    reference: VoxelShape | None = None,
    warn: Callable[[str], None] | None = None,
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
    """
    mesh = read_mesh(path, repair=True)
    repairs = mesh.metadata.get("repairs")
    if repairs:
        (warn or log.warning)(f"{path}: {repairs}")
    if supersample is None:
        supersample = 2 if resolution <= 128 else 1
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
    return VoxelShape(Path(path).stem, occupancy, transform, volume)


_PROPER_FLIPS = ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1))


def _flip_about_centre(signs) -> np.ndarray:
    """(4, 4) reflection of the unit frame's axes through its centre (0.5, 0.5, 0.5)."""
    flip = np.eye(4)
    flip[:3, :3] = np.diag(np.asarray(signs, dtype=float))
    flip[:3, 3] = 0.5 - 0.5 * np.asarray(signs, dtype=float)
    return flip


# --------------------------------------------------------------------------- resources


def estimate_memory(
    shape: Sequence[int],
    n_shapes: int,
    n_iter: int = DEFAULT_N_ITER,
    checkpoint_bytes: int = DEFAULT_CHECKPOINT_BYTES,
) -> int:
    """Bytes a fit needs, roughly: the core's gradient (working arrays and stored
    scalings, :func:`wbcgrade.core.barycenter.gradient_memory`) plus the inputs,
    the voxelisation and the outputs (about S + 8 volumes).
    """
    n_voxels = int(np.prod([int(n) for n in shape], dtype=np.float64))
    core = gradient_memory(n_voxels, int(n_shapes), int(n_iter), int(checkpoint_bytes))
    return int(core + 8 * n_voxels * (int(n_shapes) + 8))


def available_memory() -> int | None:
    """Bytes of memory available to this process (Linux ``MemAvailable``), or None."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(
    shape: Sequence[int],
    n_shapes: int,
    n_iter: int = DEFAULT_N_ITER,
    available: int | None = None,
) -> int:
    """Refuse a fit that would not fit in memory; return the estimate in bytes.

    Raises :class:`InputError` when the estimate exceeds 80% of the available
    memory (``available`` bytes, default: what the system reports).
    """
    needed = estimate_memory(shape, n_shapes, n_iter)
    if available is None:
        available = available_memory()
    if available is not None and needed > 0.8 * available:
        dims = "x".join(str(int(n)) for n in shape)
        raise InputError(
            f"a {dims} grid with {n_shapes} shapes needs about {needed / 2**30:.1f} GiB, "
            f"more than the {available / 2**30:.1f} GiB available; lower --resolution"
        )
    return needed


def default_width(resolution: int) -> float:
    """Kernel standard deviation in voxels: 1 at 64^3, a fixed 1/63 of the box, >= 1."""
    return max(1.0, (int(resolution) - 1) / 63.0)


def estimate_missing_fraction(partial: np.ndarray, database: Sequence[np.ndarray]) -> float:
    """Rough fraction of the input's volume that is missing, in ``[0, 0.9]``.

    ``1 - volume(partial) / mean(volume(database))`` with volumes measured in
    the unit frame (sum of occupancies), clipped.
    """
    reference = float(np.mean([np.sum(d) for d in database]))
    if reference <= 0:
        return 0.0
    return float(np.clip(1.0 - float(np.sum(partial)) / reference, 0.0, MAX_MISSING))


def iso_level(volume: np.ndarray, n_inside: float) -> float:
    """Level whose super-level set ``{volume > level}`` holds about ``n_inside`` voxels."""
    values = np.sort(np.asarray(volume, dtype=np.float64).ravel())[::-1]
    k = int(np.clip(round(n_inside), 1, values.size - 1))
    return float(0.5 * (values[k - 1] + values[k]))


# --------------------------------------------------------------------------- fitting


@dataclass(frozen=True)
class Projection:
    """Result of projecting a density onto a database.

    weights : (S,) on the simplex, in database order.
    names : database labels.
    barycenter : (X, Y, Z) fitted density (Wasserstein barycenter, or linear
        mixture for the Euclidean method), sums to about 1.
    target : (X, Y, Z) the density that was fitted, ``(1 - missing) q / sum(q)``.
    missing : the missing fraction used.
    method : "wasserstein" or "euclidean".
    loss_name, loss, initial_loss : the loss, its final value and its value at
        the start of the full-resolution fit (uniform weights, or the coarse
        level's weights).
    width : kernel width in voxels (Wasserstein only; 0 for Euclidean).
    n_evaluations : energy evaluations in all, ``n_coarse_evaluations`` of
        them on the half-size grid of the coarse-to-fine schedule.
    converged : whether the optimiser met its tolerance.
    time_s : wall time of the fit.
    history : loss per evaluation.
    """

    weights: np.ndarray
    names: list[str]
    barycenter: np.ndarray
    target: np.ndarray
    missing: float
    method: str
    loss_name: str
    loss: float
    initial_loss: float
    width: float
    n_evaluations: int
    converged: bool
    time_s: float
    history: list[float] = field(default_factory=list)
    n_coarse_evaluations: int = 0

    def order(self) -> np.ndarray:
        """Database indices by decreasing weight."""
        return np.argsort(-self.weights, kind="stable")


def make_target(density: np.ndarray, missing: float = 0.0) -> np.ndarray:
    """``(1 - missing) * density / sum(density)``, the fitted target."""
    if not 0.0 <= missing < 1.0:
        raise InputError(f"the missing fraction must be in [0, 1), got {missing}")
    density = np.asarray(density, dtype=np.float64)
    total = float(density.sum())
    if not np.isfinite(total) or total <= 0:
        raise InputError("the input is empty")
    return (1.0 - missing) * density / total


def project(
    density: np.ndarray,
    database: Sequence[np.ndarray],
    names: Sequence[str] | None = None,
    missing: float = 0.0,
    loss: str = DEFAULT_LOSS,
    euclidean: bool = False,
    width: float | None = None,
    n_iter: int = DEFAULT_N_ITER,
    max_iter: int = DEFAULT_MAX_ITER,
    callback: Callable[[int, np.ndarray, float], None] | None = None,
    coarse_to_fine: bool = True,
) -> Projection:
    """Fit ``density`` by a barycenter (or linear mixture) of ``database``.

    Parameters
    ----------
    density : (X, Y, Z) non-negative input density (any total mass); with the
        KL loss it must be positive everywhere (see :func:`density_from_volume`).
    database : S >= 2 arrays of the same shape, each normalised by the core.
    names : labels for the database entries (default "0", "1", ...).
    missing : fraction alpha of the input's mass that is missing.
    loss : one of :data:`LOSS_NAMES`; "kl_reverse" (default, ``KL(q | P)``),
        "kl" (the paper's ``KL(P | q)``), "quadratic", "l1", "wasserstein".
    euclidean : fit the linear mixture ``sum_s w_s p_s`` instead of the
        Wasserstein barycenter (the paper's Figure 10 comparison).
    width : kernel standard deviation in voxels (default :func:`default_width`).
    n_iter : barycenter iterations L.
    max_iter : optimiser iterations at most.
    callback : ``callback(n_evaluations, weights, loss)`` after each evaluation.
    coarse_to_fine : on grids of 32 voxels or more per axis, fit first on a
        grid of half the size (``max_iter`` iterations), then refine on the
        full grid from those weights (``max(3, max_iter // 3)`` iterations):
        one coarse evaluation costs an eighth of a fine one.

    Returns
    -------
    Projection
    """
    stack = np.stack([np.asarray(d, dtype=np.float64) for d in database])
    density = np.asarray(density, dtype=np.float64)
    if stack.shape[0] < 2:
        check_database_size([Path(str(i)) for i in range(stack.shape[0])])
    if stack.shape[1:] != density.shape or density.ndim != 3:
        raise InputError(
            f"the input volume has shape {density.shape} but the database {stack.shape[1:]}"
        )
    names = [str(i) for i in range(len(stack))] if names is None else [str(n) for n in names]
    target = make_target(density, missing)
    loss_object = resolve_loss(loss)
    if loss_object.needs_positive_target and np.any(target <= 0):
        raise InputError(f"the {loss} loss needs an input density positive everywhere")
    start = time.perf_counter()
    if euclidean:
        # the losses see the grid's kernel (transport losses) or just its shape
        geometry = GridGeometry.with_width(target.shape, default_width(max(target.shape)))
        mixture = mixture_coordinates(target, stack, geometry, loss_object, max_iter, callback)
        weights, fitted, value = mixture.weights, mixture.barycenter, mixture.loss
        initial, history, converged = mixture.initial_loss, mixture.history, mixture.converged
        used_width, n_coarse = 0.0, 0
    else:
        used_width = default_width(max(density.shape)) if width is None else float(width)
        init_weights, fine_iter, coarse_history = None, max_iter, []
        if coarse_to_fine and min(density.shape) >= 2 * COARSE_MIN_SIZE:
            # Half size, corners aligned, each density's mass kept (positive stays positive).
            coarse_shape = tuple((n + 1) // 2 for n in density.shape)
            coarse_target = resample_grid(target, coarse_shape)
            coarse_stack = resample_grid(stack, coarse_shape)
            coarse_width = used_width * (max(coarse_target.shape) - 1) / (max(density.shape) - 1)
            coarse = barycentric_coordinates(
                coarse_target, coarse_stack,
                GridGeometry.with_width(coarse_target.shape, max(coarse_width, 1.0)),
                loss=loss_object, n_iter=n_iter, max_iter=max_iter, callback=callback,
            )
            # A small floor lets the fine level revive a weight the coarse one dropped.
            init_weights = (coarse.weights + 1e-3) / (1.0 + 1e-3 * len(coarse.weights))
            coarse_history = list(coarse.history)
            fine_iter = max(3, max_iter // 3)
        fine_callback = callback
        if callback is not None and coarse_history:
            offset = len(coarse_history)

            def fine_callback(k: int, w: np.ndarray, value: float) -> None:
                callback(offset + k, w, value)

        geometry = GridGeometry.with_width(density.shape, used_width)
        fit = barycentric_coordinates(
            target, stack, geometry, loss=loss_object, n_iter=n_iter, max_iter=fine_iter,
            init_weights=init_weights, callback=fine_callback,
        )
        weights, fitted, value = fit.weights, fit.barycenter, fit.loss
        initial, converged = fit.initial_loss, fit.converged
        history, n_coarse = coarse_history + list(fit.history), len(coarse_history)
    return Projection(
        weights=np.asarray(weights, dtype=np.float64),
        names=names,
        barycenter=fitted,
        target=target,
        missing=float(missing),
        method="euclidean" if euclidean else "wasserstein",
        loss_name=loss_object.name,
        loss=float(value),
        initial_loss=float(initial),
        width=used_width,
        n_evaluations=len(history),
        n_coarse_evaluations=n_coarse,
        converged=bool(converged),
        time_s=time.perf_counter() - start,
        history=history,
    )


# --------------------------------------------------------------------------- completion


@dataclass(frozen=True)
class Completion:
    """A completed shape.

    projection : the fit (weights, barycenter volume, ...).
    partial : the voxelised input.
    database : the voxelised database shapes.
    level : iso-level of the completed surface on ``projection.barycenter``.
    """

    projection: Projection
    partial: VoxelShape
    database: list[VoxelShape]
    level: float


def complete_shape(
    partial: VoxelShape,
    database: Sequence[VoxelShape],
    missing: float | None = None,
    loss: str = DEFAULT_LOSS,
    euclidean: bool = False,
    width: float | None = None,
    eps: float = DEFAULT_EPS,
    n_iter: int = DEFAULT_N_ITER,
    max_iter: int = DEFAULT_MAX_ITER,
    callback: Callable[[int, np.ndarray, float], None] | None = None,
    coarse_to_fine: bool = True,
) -> Completion:
    """Complete a voxelised partial shape from a voxelised database.

    ``missing`` None estimates it (:func:`estimate_missing_fraction`). The
    iso-level of the result encloses the weighted mean of the database
    shapes' volumes (``sum_s w_s |shape_s|``), so the surface has the size the
    weights call for whatever the blur of the barycenter.
    """
    if len(database) < 2:
        check_database_size([Path(s.name) for s in database])
    occupancies = [s.occupancy for s in database]
    if missing is None:
        missing = estimate_missing_fraction(partial.occupancy, occupancies)
    projection = project(
        density_from_volume(partial.occupancy, eps),
        [density_from_volume(o, eps) for o in occupancies],
        names=[s.name for s in database],
        missing=missing,
        loss=loss,
        euclidean=euclidean,
        width=width,
        n_iter=n_iter,
        max_iter=max_iter,
        callback=callback,
        coarse_to_fine=coarse_to_fine,
    )
    n_inside = float(np.dot(projection.weights, [o.sum() for o in occupancies]))
    level = iso_level(projection.barycenter, n_inside)
    return Completion(projection, partial, list(database), level)


def intersection_over_union(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two boolean volumes of the same shape."""
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 1.0


# --------------------------------------------------------------------------- outputs


def completion_surface(completion: Completion, smooth_iterations: int = 10):
    """Closed iso-surface of the completion, in the input mesh's own frame.

    Returns
    -------
    trimesh.Trimesh (watertight); components smaller than 1% of the largest
    one's volume (specks of the blurred barycenter) are dropped.
    """
    from wbcgrade.shape.mesh import surface_from_volume

    surface = surface_from_volume(
        completion.projection.barycenter,
        completion.level,
        transform=completion.partial.transform,
        smooth_iterations=smooth_iterations,
    )
    parts = surface.split(only_watertight=True)
    if len(parts) > 1:
        volumes = np.array([abs(p.volume) for p in parts])
        keep = [p for p, v in zip(parts, volumes, strict=True) if v >= 0.01 * volumes.max()]
        import trimesh

        surface = trimesh.util.concatenate(keep)
    return surface


def completion_sheet(completion: Completion, top: int = 3, tile: int = 160) -> np.ndarray:
    """Contact sheet: input, completion (new parts in red), the ``top`` heaviest database shapes.

    Returns
    -------
    (H, W, 3) float32 RGB image in [0, 1].
    """
    from wbcgrade.shape.render import Panel, contact_sheet

    projection = completion.projection
    title = "Euclidean" if projection.method == "euclidean" else "completion"
    panels = [
        Panel(completion.partial.occupancy, f"input {completion.partial.name}", 0.5,
              (0.95, 0.7, 0.35)),
        Panel(projection.barycenter, title, completion.level, (0.45, 0.65, 0.95),
              highlight=completion.partial.occupancy < 0.5),
    ]
    for index in projection.order()[: max(0, top)]:
        shape = completion.database[index]
        panels.append(Panel(shape.occupancy, f"{shape.name} {projection.weights[index]:.2f}", 0.5))
    return contact_sheet(panels, tile=tile)


def projection_sheet(
    volume: np.ndarray,
    projection: Projection,
    database: Sequence[np.ndarray],
    top: int = 3,
    tile: int = 160,
) -> np.ndarray:
    """Maximum-intensity projections of the input, the fit and the heaviest database volumes."""
    from wbcgrade.shape.render import Panel, contact_sheet

    title = "Euclidean" if projection.method == "euclidean" else "projection"
    panels = [Panel(volume, "input"), Panel(projection.barycenter, title)]
    for index in projection.order()[: max(0, top)]:
        panels.append(
            Panel(database[index], f"{projection.names[index]} {projection.weights[index]:.2f}")
        )
    return contact_sheet(panels, tile=tile)
