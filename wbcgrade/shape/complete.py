"""Completing shapes and projecting volumes onto a database (paper §5.3-5.4).

Pipeline of a completion (:func:`complete_shape`): every mesh is normalised
into the unit frame by itself and voxelised (:mod:`wbcgrade.shape.mesh`).
The database shapes are complete, so their own frames agree; the input's
does not (a shape with a part missing has another centroid and extent), so
the input is *placed* on the database (:mod:`wbcgrade.shape.register`: the
similarity under which it overlaps one database shape best). There its
density ``q`` (uniform inside, ``eps`` times less outside) is explained by
the Wasserstein barycenter ``P(w)`` of the database densities, fitted by the
core's :func:`~wbcgrade.core.barycentric_coordinates` with

    target = (1 - alpha) * q / sum(q)

where ``alpha`` is the fraction of the shape's volume missing from the input
(the barycenter has mass 1, the observed part only ``1 - alpha`` of it). The
shape drawn from the weights is the debiased barycenter
(:func:`wbcgrade.core.debiased_barycenter`), whose parts beyond the input are
added to it; the written surface is the input mesh united with them, in the input's
own coordinates (:func:`completion_surface`).

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

Missing fraction. When not given, ``alpha`` is estimated where the input was
placed: the volume it lacks next to the database shape it was placed on
(then next to the weighted database, after a second placement), clipped to
``[0, 0.9]`` (:func:`estimate_missing_fraction`). Its error is about three
times the placement's relative scale error (a few per cent); pass it
explicitly when it is known. It matters for the default loss and for the
quadratic and L1 losses; for ``kl_reverse`` and ``kl`` the factor
``1 - alpha`` only adds a constant to the energy (the barycenter always has
mass 1).

Loss. The default is ``kl_reverse``, ``KL(q | P)``; completions sum it over
the input's voxels only (:data:`KL_OBSERVED`), projections over every voxel;
the paper's ``KL(P | q)`` is ``kl``. The paper's direction
charges the barycenter for every bit of mass it puts where the input is
missing, which is exactly what a completion must do, and on shapes with a
slab cut away it prefers wrong weights to the true ones (see
:data:`KL_REVERSE`); ``kl_reverse`` still charges that mass a little (see
:data:`KL_OBSERVED`).
"""

from __future__ import annotations

import logging
import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.ndimage as ndi
import trimesh

from wbcgrade.core import (
    GridGeometry,
    Loss,
    barycentric_coordinates,
    debiased_barycenter,
    get_loss,
    mixture_coordinates,
    refine_grid,
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
from wbcgrade.shape.register import Placement, place_partial
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

OBSERVED_LEVEL = 0.5
"""Voxels where the target is at least this fraction of its maximum count as observed."""

POINTWISE_LOSSES = ("kl_reverse", "kl", "quadratic", "l1")
"""Losses that are sums over voxels, which :func:`on_observed_voxels` can restrict."""


def on_observed_voxels(loss: str | Loss) -> Loss:
    """A voxel-wise loss summed over the observed voxels only, ``{q >= max(q) / 2}``.

    Outside them the barycenter is compared with ``q`` itself (each term is 0)
    and the gradient is 0. Raises InputError for a loss that is not a sum
    over voxels (``wasserstein``).
    """
    base = get_loss(loss)
    if base.name not in POINTWISE_LOSSES:
        raise InputError(f"the {base.name} loss compares whole shapes and cannot be restricted "
                         "to the observed voxels; compare all voxels instead")

    def value_and_grad(P: np.ndarray, q: np.ndarray, geometry) -> tuple[float, np.ndarray]:
        observed = q >= OBSERVED_LEVEL * float(q.max())
        value, grad = base.value_and_grad(np.where(observed, P, q), q, geometry)
        return value, np.where(observed, grad, 0.0)

    return Loss(f"{base.name}, observed voxels", value_and_grad, base.needs_positive_target)


KL_OBSERVED = on_observed_voxels("kl_reverse")
"""``KL(q | P)`` on the observed voxels only: the sum over ``{q >= max(q) / 2}``
of ``q log(q / P) - q + P`` (generalised KL, unnormalised); what a completion
fits by default.

For a shape with a fraction ``alpha`` missing, ``q`` holds ``1 - alpha`` of
the mass on the observed voxels and the barycenter must match it there; the
remaining ``alpha`` of its mass is free to go where the input is missing.
``KL(q | P)`` over all voxels also charges that mass (its ``+ P`` term,
about ``alpha``), so it prefers barycenters that crowd onto the observed
part over the whole shape (about ``(1 - alpha) log(1 - alpha) + alpha``,
0.02 at ``alpha = 0.2``, against 0.2): measured on a cow with the rear 20 %
of its length cut at 32^3, 0.16 of the weight went to a triceratops and
38 % of the cut part came back (0.98 on the cow and 80 % restored here).
Here the missing fraction matters (too small pulls towards the observed
part, too large towards fatter shapes).
"""


def resolve_loss(name: str | Loss, observed_only: bool = False) -> Loss:
    """The core's :class:`~wbcgrade.core.Loss` called ``name``, restricted to the
    observed voxels with ``observed_only`` (:func:`on_observed_voxels`)."""
    return on_observed_voxels(name) if observed_only else get_loss(name)


# --------------------------------------------------------------------------- inputs


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


def estimate_missing_fraction(
    partial: np.ndarray,
    database: Sequence[np.ndarray],
    weights: Sequence[float] | None = None,
) -> float:
    """Rough fraction of the input's volume that is missing, in ``[0, 0.9]``.

    ``1 - volume(partial) / sum_s weights_s volume(database_s)`` (default
    weights: the mean), volumes measured in one frame (sums of
    occupancies), clipped. Meaningful when the partial has been placed on
    the database shapes (:func:`complete_shape` does).
    """
    volumes = np.array([float(np.sum(d)) for d in database])
    weights = np.full(len(volumes), 1.0 / len(volumes)) if weights is None else np.asarray(weights)
    reference = float(np.dot(weights, volumes))
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
    *,
    names: Sequence[str] | None = None,
    missing: float = 0.0,
    loss: str = DEFAULT_LOSS,
    euclidean: bool = False,
    width: float | None = None,
    n_iter: int = DEFAULT_N_ITER,
    max_iter: int = DEFAULT_MAX_ITER,
    callback: Callable[[int, np.ndarray, float], None] | None = None,
    coarse_to_fine: bool = True,
    init_weights: np.ndarray | None = None,
    observed_only: bool = False,
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
    init_weights : (S,) weights to start from (a previous fit): the coarse
        level is skipped and ``max(3, max_iter // 3)`` iterations refine them.
    observed_only : compare the observed voxels only (:func:`on_observed_voxels`;
        :data:`KL_OBSERVED` for ``kl_reverse``).

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
    loss_object = resolve_loss(loss, observed_only)
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
        fine_iter, coarse_history = max_iter, []
        if init_weights is not None:
            init_weights = np.asarray(init_weights, dtype=np.float64)
            init_weights = (init_weights + 1e-3) / (1.0 + 1e-3 * len(init_weights))
            fine_iter = max(3, max_iter // 3)
        elif coarse_to_fine and min(density.shape) >= 2 * COARSE_MIN_SIZE:
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
    partial : the input voxelised where it was placed on the database;
        ``partial.transform`` takes the input mesh's frame to the unit frame.
    database : the voxelised database shapes.
    level : iso-level of the fitted shape on ``fitted``.
    placement : the (last) placement of the input's own normalisation on the
        database (:class:`~wbcgrade.shape.register.Placement`).
    shape : (n, n, n) the completed shape, values in [0, 1], surface at 1/2:
        the placed input united with the fitted shape.
    added : (n, n, n) bool, voxels of the completed shape outside the input.
    n_placements : 1, or 2 when placing the input on the fitted shape moved
        it by more than half a voxel and the weights were fitted again there.
    fitted : (n, n, n) the density the fitted shape is drawn from: the
        debiased barycenter of the fitted weights
        (:func:`~wbcgrade.core.debiased_barycenter`; the linear
        mixture for the Euclidean method).
    extension : (n, n, n) the fitted shape's occupancy where it extends the
        input (:func:`extension_occupancy`); ``shape`` is its maximum with
        the input's.
    """

    projection: Projection
    partial: VoxelShape
    database: list[VoxelShape]
    level: float
    placement: Placement
    shape: np.ndarray
    added: np.ndarray
    n_placements: int
    fitted: np.ndarray
    extension: np.ndarray


def fitted_occupancy(barycenter: np.ndarray, level: float) -> np.ndarray:
    """A fitted density as an occupancy, clip(barycenter / (2 level), 0, 1): 1/2 at ``level``."""
    return np.clip(np.asarray(barycenter, dtype=np.float64) / (2.0 * level), 0.0, 1.0)


PLACEMENT_MIN_RESOLUTION = 64
"""Voxels per axis of the grid the input is placed on (when the meshes were
kept), at most twice the fit's if that is coarser: thin parts lost at coarse
grids mislead the placement, and its precision sets the missing fraction's."""

SHELL_VOXELS = 1.5
"""Fitted shape within this many voxels of the input and not connected to
anything further out is dropped (see :func:`extension_occupancy`)."""


def extension_occupancy(
    fitted: np.ndarray, observed: np.ndarray, shell: float = SHELL_VOXELS
) -> np.ndarray:
    """The part of a fitted shape that extends an observed one, as an occupancy.

    Where the input was observed it is trusted: a thin shell of the fitted
    shape around it (the barycenter a little wider than the input, a
    placement a voxel off) would only move its surface. Kept: the fitted
    shape's parts reaching more than ``shell`` voxels beyond the input, with
    the fitted shape within ``shell + 1`` voxels of them (so they join the
    input without a groove).

    Parameters
    ----------
    fitted, observed : (n, n, n) occupancies in [0, 1].
    shell : voxels; 0 keeps the whole fitted shape.

    Returns
    -------
    (n, n, n) ``fitted`` where kept, 0 elsewhere.
    """
    fitted = np.asarray(fitted, dtype=np.float64)
    if shell <= 0:
        return fitted
    near = ndi.distance_transform_edt(np.asarray(observed) <= 0.5) <= shell
    far = (fitted > 0.5) & ~near
    if not far.any():
        return np.zeros_like(fitted)
    keep = ndi.distance_transform_edt(~far) <= shell + 1.0
    return np.where(keep, fitted, 0.0)


def placement_shift(first: np.ndarray, second: np.ndarray, occupancy: np.ndarray) -> float:
    """Largest distance (voxels) two placements put a corner of the shape's bounding box apart."""
    n = occupancy.shape[0]
    index = np.argwhere(occupancy > 0.5)
    if index.size == 0:
        return 0.0
    lo, hi = index.min(axis=0) / (n - 1), index.max(axis=0) / (n - 1)
    corners = np.array([[c[0], c[1], c[2], 1.0] for c in np.array(np.meshgrid(
        *zip(lo, hi, strict=True), indexing="ij")).reshape(3, -1).T])
    return float(np.abs(corners @ (np.asarray(first) - np.asarray(second))[:3].T).max() * (n - 1))


def complete_shape(
    partial: VoxelShape,
    database: Sequence[VoxelShape],
    *,
    missing: float | None = None,
    loss: str = DEFAULT_LOSS,
    euclidean: bool = False,
    width: float | None = None,
    eps: float = DEFAULT_EPS,
    n_iter: int = DEFAULT_N_ITER,
    max_iter: int = DEFAULT_MAX_ITER,
    callback: Callable[[int, np.ndarray, float], None] | None = None,
    coarse_to_fine: bool = True,
    rotate: bool = False,
    refine: bool = True,
    place: bool = True,
    observed_only: bool = True,
) -> Completion:
    """Complete a voxelised partial shape from a voxelised database.

    1. Place the input on the database: the similarity (scale, translation,
       rotation with ``rotate``) under which it overlaps one database shape
       best (:func:`~wbcgrade.shape.register.place_partial`), so input and
       database share one frame whatever part is missing.
    2. Fit the weights in that frame; ``missing`` None estimates the missing
       fraction there, against the shape the input was placed on.
    3. With ``refine``, place the input on the fitted shape; when that moves
       it by more than half a voxel, fit again from the weights found (the
       missing fraction, when estimated, against the weighted database).
    4. The fitted shape is ``{fitted > level}``, with ``fitted`` the
       debiased barycenter of the weights (sharp where the fitted one is
       blurred by the kernel: thin parts survive) and the level enclosing the
       weighted mean of the database shapes' volumes (``sum_s w_s |shape_s|``).
       The completed shape is the placed input united with the fitted shape's
       parts that extend it (:func:`extension_occupancy`).

    Placing runs on a grid of :data:`PLACEMENT_MIN_RESOLUTION` voxels (at most
    twice the fit's) when the meshes were kept (``load_shape(keep_mesh=True)``).
    ``place=False`` skips steps 1 and 3: for an input already voxelised in
    the database's frame. ``observed_only`` (default) fits the loss on the
    input's voxels only (:data:`KL_OBSERVED` for the default loss).
    """
    if len(database) < 2:
        check_database_size([Path(s.name) for s in database])
    occupancies = [s.occupancy for s in database]
    volumes = np.array([float(o.sum()) for o in occupancies])
    densities = [density_from_volume(o, eps) for o in occupancies]
    estimated = missing is None
    n = partial.occupancy.shape[0]
    grid = max(n, min(PLACEMENT_MIN_RESOLUTION, 2 * n))
    if grid == n or partial.mesh is None or any(s.mesh is None for s in database):
        grid, own, references = n, partial.occupancy, occupancies
    else:
        own = _voxelised_at(partial, grid)
        references = [_voxelised_at(s, grid) for s in database]
    if place:
        placement = place_partial(own, references, rotate=rotate)
        placed = place_shape(partial, placement.transform)
    else:
        placement, placed, refine = Placement(np.eye(4), 0.0, 0.0), partial, False
    if not placed.occupancy.max() > 0:  # placed off the grid or too small to see: keep its own
        log.warning("the input could not be placed on the database; using its own frame")
        placement = Placement(np.eye(4), 0.0, 0.0, placement.reference)
        placed = partial
    if estimated:
        missing = estimate_missing_fraction(placed.occupancy, [occupancies[placement.reference]])

    def fit(shape: VoxelShape, missing: float, init_weights=None, offset: int = 0) -> Projection:
        step = callback
        if callback is not None and offset:
            def step(k: int, w: np.ndarray, value: float) -> None:
                callback(offset + k, w, value)

        return project(
            density_from_volume(shape.occupancy, eps), densities,
            names=[s.name for s in database], missing=missing, loss=loss,
            euclidean=euclidean, width=width, n_iter=n_iter, max_iter=max_iter,
            callback=step, coarse_to_fine=coarse_to_fine, init_weights=init_weights,
            observed_only=observed_only,
        )

    def sharpen(projection: Projection) -> tuple[np.ndarray, float]:
        if projection.method == "euclidean":
            density = projection.barycenter
        else:
            geometry = GridGeometry.with_width(partial.occupancy.shape, projection.width)
            density = debiased_barycenter(np.stack(densities), projection.weights, geometry,
                                          n_iter)
        return density, iso_level(density, float(np.dot(projection.weights, volumes)))

    projection = fit(placed, missing)
    density, level = sharpen(projection)
    n_placements = 1
    if refine:
        fitted = (fitted_occupancy(density, level) if grid == n
                  else _drawn_at(database, projection, grid, n_iter, eps))
        again = place_partial(own, [fitted], rotate=rotate, start=placement.transform)
        moved = place_shape(partial, again.transform)
        if (placement_shift(placement.transform, again.transform, partial.occupancy) > 0.5
                and moved.occupancy.max() > 0 and 0.8 < again.scale / placement.scale < 1.25):
            placement = Placement(again.transform, again.score, again.explained,
                                  placement.reference)
            placed = moved
            if estimated:
                missing = estimate_missing_fraction(placed.occupancy, occupancies,
                                                    projection.weights)
            first = projection
            projection = fit(placed, missing, first.weights, first.n_evaluations)
            projection = replace(
                projection, history=first.history + projection.history,
                n_evaluations=first.n_evaluations + projection.n_evaluations,
                n_coarse_evaluations=first.n_coarse_evaluations,
                initial_loss=first.initial_loss,
                time_s=first.time_s + projection.time_s,
            )
            density, level = sharpen(projection)
            n_placements = 2
    extension = extension_occupancy(fitted_occupancy(density, level), placed.occupancy)
    shape = np.maximum(placed.occupancy, extension)
    added = (extension > 0.5) & (placed.occupancy <= 0.5)
    return Completion(projection, placed, list(database), level, placement, shape, added,
                      n_placements, density, extension)


def intersection_over_union(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two boolean volumes of the same shape."""
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 1.0


# --------------------------------------------------------------------------- outputs


SURFACE_MIN_RESOLUTION = 97
"""Voxels per axis, at least, of the grid the completed surface is drawn on."""


def surface_resolution(resolution: int) -> int:
    """Grid for the surface: twice as fine as the fit's, and at least
    :data:`SURFACE_MIN_RESOLUTION` (or four times the fit's, if less)."""
    n = int(resolution)
    return max(2 * (n - 1) + 1, min(SURFACE_MIN_RESOLUTION, 4 * (n - 1) + 1))


def _voxelised_at(shape: VoxelShape, resolution: int) -> np.ndarray:
    """``shape`` on a ``resolution``^3 grid of its unit frame: its mesh voxelised
    there when kept, else its occupancy interpolated."""
    if shape.mesh is None:
        return refine_grid(shape.occupancy, (resolution,) * 3)
    moved = shape.mesh.copy()
    moved.apply_transform(shape.transform)
    return voxelize(moved, resolution, supersample=voxel_supersample(resolution))


def _drawn_at(
    database: Sequence[VoxelShape], projection: Projection, resolution: int, n_iter: int,
    eps: float,
) -> np.ndarray | None:
    """The fitted shape drawn from the database meshes on a ``resolution``^3 grid (see
    :func:`fitted_occupancy_at`); None when a shape that weighs has no mesh."""
    heavy = np.nonzero(projection.weights > 1e-3)[0]
    if any(database[i].mesh is None for i in heavy):
        return None
    weights = projection.weights[heavy] / projection.weights[heavy].sum()
    occupancies = [_voxelised_at(database[i], resolution) for i in heavy]
    densities = np.stack([density_from_volume(o, eps) for o in occupancies])
    if projection.method == "euclidean":
        density = np.tensordot(weights, densities, axes=1)
    else:
        geometry = GridGeometry.with_width((resolution,) * 3, default_width(resolution))
        density = debiased_barycenter(densities, weights, geometry, n_iter)
    level = iso_level(density, float(np.dot(weights, [o.sum() for o in occupancies])))
    return fitted_occupancy(density, level)


def fitted_occupancy_at(
    completion: Completion, resolution: int, n_iter: int = DEFAULT_N_ITER,
    eps: float = DEFAULT_EPS,
) -> np.ndarray:
    """The fitted shape as an occupancy on a ``resolution``^3 grid of the unit frame.

    When every database shape of weight above 1e-3 kept its mesh
    (``load_shape(keep_mesh=True)``), they are voxelised on that grid and
    their debiased barycenter (or mixture) is drawn there with the fit's
    weights and the kernel a fit on that grid would use
    (:func:`default_width`): parts too thin for the fit's grid survive
    (a cow's legs, fitted at 32^3 and drawn at 97^3: with the fit's kernel,
    3.1 voxels there, only the hooves come back; with 1.5 voxels, the legs).
    Otherwise the fit's own fitted shape is interpolated.
    """
    n = completion.shape.shape[0]
    if resolution != n:
        drawn = _drawn_at(completion.database, completion.projection, resolution, n_iter, eps)
        if drawn is not None:
            return drawn
    coarse = fitted_occupancy(completion.fitted, completion.level)
    return coarse if resolution == n else refine_grid(coarse, (resolution,) * 3)


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
    observed = _voxelised_at(partial, fine)
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
    from wbcgrade.shape.mesh import surface_from_volume

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


INPUT_COLOR = (0.95, 0.7, 0.35)
"""Colour of the input (and of the input's part of a completion) in pictures."""

ADDED_COLOR = (0.35, 0.6, 1.0)
"""Colour of the part a completion adds, in pictures."""

SHEET_RESOLUTION = 96
"""Voxels along the longest side of the output-frame views of :func:`completion_sheet`."""


def completion_sheet(
    completion: Completion,
    top: int = 3,
    tile: int = 160,
    surface: trimesh.Trimesh | None = None,
) -> np.ndarray:
    """Contact sheet: input, completion (added part in blue), the ``top`` heaviest database shapes.

    With the written ``surface`` and the input's mesh (``load_shape(...,
    keep_mesh=True)``), the input and the completion are drawn in the input's
    own frame (both voxelised on one grid over their joint bounding box;
    voxels more than one voxel away from the input count as added);
    otherwise in the unit frame. Database shapes are drawn in the unit frame.

    Returns
    -------
    (H, W, 3) float32 RGB image in [0, 1].
    """
    from wbcgrade.shape.mesh import voxelize_together
    from wbcgrade.shape.render import Panel, contact_sheet

    projection = completion.projection
    title = "Euclidean" if projection.method == "euclidean" else "completion"
    source = completion.partial.mesh
    if surface is not None and source is not None:
        (observed, completed), _ = voxelize_together([source, surface], SHEET_RESOLUTION)
        near_input = ndi.binary_dilation(observed > 0.5, iterations=1)
        added = ~near_input
    else:
        observed, completed = completion.partial.occupancy, completion.shape
        added = completion.added
    panels = [
        Panel(observed, f"input {completion.partial.name}", 0.5, INPUT_COLOR),
        Panel(completed, f"{title} (blue: new)", 0.5, INPUT_COLOR, highlight=added,
              highlight_color=ADDED_COLOR),
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
