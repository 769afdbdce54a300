"""Completing a partial shape from a database of whole ones (paper §5.3).

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
own coordinates (:func:`wbcgrade.shape.surface.completion_surface`).

Missing fraction. When not given, ``alpha`` is estimated where the input was
placed: the volume it lacks next to the database shape it was placed on
(then next to the weighted database, after a second placement), clipped to
``[0, 0.9]`` (:func:`estimate_missing_fraction`). Its error is about three
times the placement's relative scale error (a few per cent); pass it
explicitly when it is known. It matters for the default loss and for the
quadratic and L1 losses; for ``kl_reverse`` and ``kl`` the factor
``1 - alpha`` only adds a constant to the energy (the barycenter always has
mass 1).

How the weights are fitted (kernel width, loss):
:mod:`wbcgrade.shape.projection`; the surface written:
:mod:`wbcgrade.shape.surface`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.ndimage as ndi

from wbcgrade.core import GridGeometry, debiased_barycenter, refine_grid
from wbcgrade.shape.database import (
    VoxelShape,
    check_database_size,
    place_shape,
    voxelised_at,
)
from wbcgrade.shape.defaults import DEFAULT_LOSS, DEFAULT_MAX_ITER, DEFAULT_N_ITER
from wbcgrade.shape.projection import Projection, default_width, project
from wbcgrade.shape.register import Placement, place_partial
from wbcgrade.shape.volume import DEFAULT_EPS, density_from_volume

log = logging.getLogger(__name__)

MAX_MISSING = 0.9


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
    input's voxels only (:data:`~wbcgrade.shape.projection.KL_OBSERVED` for the default loss).
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
        own = voxelised_at(partial, grid)
        references = [voxelised_at(s, grid) for s in database]
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
    occupancies = [voxelised_at(database[i], resolution) for i in heavy]
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
    (:func:`~wbcgrade.shape.projection.default_width`): parts too thin for the fit's grid survive
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
