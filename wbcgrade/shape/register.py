"""Placing a partial shape on complete ones: a similarity registration on voxels.

A shape with a part missing, normalised by its own centroid and extent, is
larger and off-centre next to complete shapes normalised by theirs, and a
barycenter fitted in that frame (then mapped back through the partial's own
transform) squeezes the whole shape into the partial's extent. The partial is
instead *placed* on a complete shape ``R`` (occupancy on the unit-frame grid)
by the similarity ``U(x) = s Q (x - c) + c + t`` (scale ``s``, translation
``t``, rotation ``Q`` only when asked, ``c`` the partial's centroid) that
maximises

    J(U) = integral over U(partial) of F_R,

with ``F_R = +1/2`` inside ``R`` and a penalty outside growing with the
distance to ``R`` (both softened across the surface, :func:`soft_field`).
``J`` counts volume in the unit frame, so it grows with ``s`` while the
partial stays inside ``R`` and drops once it spills out: it peaks where the
observed part lies on the matching part of ``R``, whatever is missing.

Search: global over scale and translation on a grid of at most
:data:`SEARCH_SIZE` voxels per axis (for each of :data:`SEARCH_SCALES`, one
FFT cross-correlation gives ``J`` at every voxel shift), which ranks the
references; then local (Powell on ``log s``, ``t`` and the rotation vector)
from the best distinct peaks on the best references, with the surface band
narrowing (:data:`REFINE_BANDS`). Measured on plane cuts (20-35 % of an
axis) of 6 CGAL meshes at 48^3: median error 0.6 voxel, none above 2.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi
import scipy.optimize
from scipy.signal import fftconvolve
from scipy.spatial.transform import Rotation

SEARCH_SIZE = 32
"""Voxels per axis of the grid the global search runs on (coarser grids are kept)."""

SEARCH_SCALES = tuple(float(s) for s in np.geomspace(0.4, 1.25, 16))
"""Scales of the partial (relative to its own normalisation) tried by the global search."""

SEARCH_BAND = 2.0
"""Half-width (coarse voxels) of the soft surface band of the global search."""

SEARCH_PEAKS = 6
"""Distinct local maxima of the global search refined on each finalist reference."""

REFINE_BANDS = (1.5, 0.5)
"""Half-widths (voxels) of the soft surface band, one local refinement per band."""

OUTSIDE_DEPTH = 4.0
"""Depth (in bands) past which spilling out of the reference costs no more (:func:`soft_field`)."""

MAX_POINTS = 8000
"""Sample points of the partial in the local refinement, at most (coarser voxels above)."""


@dataclass(frozen=True)
class Placement:
    """Where a partial shape sits on a reference shape.

    transform : (4, 4) similarity of the unit frame, partial's own -> reference's.
    score : ``J``, volume in the unit frame (see the module's docstring).
    explained : ``J`` over the reference's score on itself: 1 when the partial
        fills the whole reference, about ``1 - missing`` when it lies exactly
        on a complete shape it is part of.
    reference : index of the reference among those searched.
    """

    transform: np.ndarray
    score: float
    explained: float
    reference: int = 0

    @property
    def scale(self) -> float:
        """The similarity's scale factor."""
        return float(np.cbrt(np.linalg.det(self.transform[:3, :3])))


def soft_field(occupancy: np.ndarray, band: float) -> np.ndarray:
    """What a unit of the partial's volume scores at each voxel of a reference.

    With ``d`` the signed distance (voxels, positive outside) to the surface
    of ``{occupancy > 1/2}``: ``min(-d / band, 1) / 2`` inside (a ramp up to
    1/2, flat deeper in: thin parts keep their full value, unlike a blur) and
    ``-min(d / band, OUTSIDE_DEPTH) / 2`` outside, a penalty growing with the
    depth of the spill: a partial is not enlarged, or slid towards where the
    reference is wider, at the price of a part sticking out (measured on
    plane cuts of 7 meshes at 48^3: mean placement error 0.95 voxel with a
    flat penalty of 1/2, 0.74 with this one).
    """
    inside = np.asarray(occupancy) > 0.5
    if not inside.any():
        return np.full(inside.shape, -0.5 * OUTSIDE_DEPTH)
    outside_distance = ndi.distance_transform_edt(~inside) - 0.5
    inside_distance = ndi.distance_transform_edt(inside) - 0.5
    return np.where(inside, 0.5 * np.minimum(inside_distance / band, 1.0),
                    -0.5 * np.minimum(outside_distance / band, OUTSIDE_DEPTH))


def similarity(params: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(4, 4) matrix of ``x -> s Q (x - c) + c + t``.

    ``params`` = ``(log s, t_x, t_y, t_z)`` or those and a rotation vector (7,).
    """
    params = np.asarray(params, dtype=np.float64)
    rotation = Rotation.from_rotvec(params[4:7]).as_matrix() if params.size > 4 else np.eye(3)
    linear = np.exp(params[0]) * rotation
    matrix = np.eye(4)
    matrix[:3, :3] = linear
    matrix[:3, 3] = centre + params[1:4] - linear @ centre
    return matrix


def shrink(volume: np.ndarray, size: int) -> np.ndarray:
    """Values of ``volume`` (n, n, n) on a grid of ``size`` points per axis, corners kept.

    Slightly smoothed first so a coarser grid does not alias; volumes already
    small enough are returned unchanged.
    """
    volume = np.asarray(volume, dtype=np.float64)
    n = volume.shape[0]
    if n <= size:
        return volume
    ratio = (n - 1) / (size - 1)
    smooth = ndi.gaussian_filter(volume, 0.4 * ratio)
    axis = np.linspace(0.0, n - 1.0, size)
    coordinates = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"))
    return ndi.map_coordinates(smooth, coordinates, order=1, mode="nearest")


def _centroid(occupancy: np.ndarray) -> np.ndarray:
    """Centroid (3,) of an occupancy in unit-frame coordinates."""
    n = occupancy.shape[0]
    x = np.linspace(0.0, 1.0, n)
    total = float(occupancy.sum())
    return np.array([
        np.dot(occupancy.sum(axis=tuple(a for a in range(3) if a != axis)), x) / total
        for axis in range(3)
    ])


def scaled(occupancy: np.ndarray, centre: np.ndarray, scale: float) -> np.ndarray:
    """``occupancy`` (n, n, n) scaled by ``scale`` about ``centre`` (unit frame), same grid."""
    n = occupancy.shape[0]
    c = np.asarray(centre, dtype=np.float64) * (n - 1)
    return ndi.affine_transform(occupancy, np.full(3, 1.0 / scale), offset=c - c / scale,
                                order=1, mode="constant", cval=0.0)


def self_score(occupancy: np.ndarray, band: float) -> float:
    """``J`` of a shape placed on itself (unit-frame volume): what a perfect fit scores."""
    n = occupancy.shape[0]
    return float(np.sum(np.asarray(occupancy) * soft_field(occupancy, band))) / (n - 1) ** 3


def _global_peaks(
    partial: np.ndarray, reference: np.ndarray, centre: np.ndarray, keep: int = SEARCH_PEAKS
) -> tuple[float, list[np.ndarray]]:
    """Global search on one reference, on the coarse grid.

    Returns the best peak's score over the reference's own, and the params
    ``(log s, t)`` of the ``keep`` best distinct local maxima of ``J`` over
    scales and voxel shifts (one FFT cross-correlation per scale).
    """
    small = shrink(partial, SEARCH_SIZE)
    coarse = shrink(reference, SEARCH_SIZE)
    m = small.shape[0]
    field = soft_field(coarse, SEARCH_BAND)
    own = float(np.sum(coarse * field))
    found = []
    for scale in SEARCH_SCALES:
        kernel = scaled(small, centre, scale)[::-1, ::-1, ::-1]
        correlation = fftconvolve(field, kernel, mode="full")  # index k: shift k - (m - 1)
        maxima = np.argwhere(correlation == ndi.maximum_filter(correlation, size=3))
        values = correlation[tuple(maxima.T)]
        for k in np.argsort(-values)[:keep]:
            shift = (maxima[k] - (m - 1)) / (m - 1)
            found.append((float(values[k]), np.array([np.log(scale), *shift])))
    found.sort(key=lambda peak: -peak[0])
    distinct: list[tuple[float, np.ndarray]] = []
    step = np.log(SEARCH_SCALES[1] / SEARCH_SCALES[0])
    for value, params in found:
        if all(abs(params[0] - p[0]) > 1.5 * step
               or np.abs(params[1:] - p[1:]).max() * (m - 1) > 1.5 for _, p in distinct):
            distinct.append((value, params))
        if len(distinct) == keep:
            break
    return (distinct[0][0] / own if own > 0 else 0.0), [params for _, params in distinct]


def _sample_points(partial: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Occupied voxel centres (P, 3), their occupancies (P,) and the voxel volume."""
    size = partial.shape[0]
    while size > 8 and np.count_nonzero(shrink(partial, size)) > MAX_POINTS:
        size = int(round(size * 0.8))
    grid = shrink(partial, size)
    index = np.nonzero(grid > 1e-3)
    x = np.linspace(0.0, 1.0, size)
    points = np.stack([x[i] for i in index], axis=1)
    return points, grid[index], (1.0 / (size - 1)) ** 3


def _refine(
    points: np.ndarray,
    weights: np.ndarray,
    voxel_volume: float,
    reference: np.ndarray,
    centre: np.ndarray,
    start: np.ndarray,
    bands: Sequence[float],
) -> tuple[np.ndarray, float]:
    """Local maximisation of ``J`` from ``start``, one Powell run per band; -> (params, J)."""
    n = reference.shape[0]
    params = np.asarray(start, dtype=np.float64)
    score = -np.inf
    for band in bands:
        field = soft_field(reference, band)

        def negative_score(p: np.ndarray, field: np.ndarray = field) -> float:
            matrix = similarity(p, centre)
            moved = points @ matrix[:3, :3].T + matrix[:3, 3]
            values = ndi.map_coordinates(field, (moved * (n - 1)).T, order=1,
                                         mode="constant", cval=-0.5 * OUTSIDE_DEPTH)
            return -float(np.exp(3.0 * p[0]) * np.dot(weights, values) * voxel_volume)

        result = scipy.optimize.minimize(negative_score, params, method="Powell",
                                         options={"xtol": 1e-3, "ftol": 1e-7})
        params, score = np.asarray(result.x), -float(result.fun)
    return params, score


def _start_params(start: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``(log s, t, rotation vector)`` of the similarity matrix ``start`` about ``centre``."""
    linear = np.asarray(start, dtype=np.float64)[:3, :3]
    scale = float(np.cbrt(np.linalg.det(linear)))
    translation = np.asarray(start)[:3, 3] + linear @ centre - centre
    rotation = Rotation.from_matrix(linear / scale).as_rotvec()
    return np.array([np.log(scale), *translation, *rotation])


def place_partial(
    partial: np.ndarray,
    references: Sequence[np.ndarray],
    rotate: bool = False,
    start: np.ndarray | None = None,
    finalists: int = 3,
) -> Placement:
    """Similarity placing ``partial`` where it overlaps one of ``references`` best.

    The global search ranks the references by how much of themselves the
    partial explains on the coarse grid; the :data:`SEARCH_PEAKS` best
    distinct placements on each of the ``finalists`` best references are
    refined, and the refined placement explaining the most of its reference
    wins.

    Parameters
    ----------
    partial : (n, n, n) occupancy in [0, 1] of the partial shape in its own
        unit frame.
    references : occupancies of complete shapes on grids of the same shape.
    rotate : also fit a rotation (small: the search starts unrotated).
    start : (4, 4) similarity to refine locally instead of searching globally
        (on the first reference).
    finalists : references refined with every band.

    Returns
    -------
    Placement; ``explained`` is ``J`` over the reference's own score
    (:func:`self_score`), comparable between references.
    """
    partial = np.asarray(partial, dtype=np.float64)
    centre = _centroid(partial)
    points, weights, voxel_volume = _sample_points(partial)
    size = 7 if rotate else 4

    def refine(index: int, params: np.ndarray, bands) -> tuple[float, np.ndarray]:
        params = np.concatenate([params, np.zeros(3)])[:size]
        params, score = _refine(points, weights, voxel_volume, references[index], centre,
                                params, bands)
        own = self_score(references[index], bands[-1])
        return (score / own if own > 0 else 0.0), params

    if start is not None:
        candidates = [(0, _start_params(start, centre))]
    else:
        searched = [(*_global_peaks(partial, reference, centre), index)
                    for index, reference in enumerate(references)]
        searched.sort(key=lambda found: -found[0])
        candidates = [(index, params) for _, peaks, index in searched[:finalists]
                      for params in peaks]
    best = None
    for index, params in candidates:
        explained, params = refine(index, params, REFINE_BANDS)
        if best is None or explained > best.explained:
            score = explained * self_score(references[index], REFINE_BANDS[-1])
            best = Placement(similarity(params, centre), score, explained, index)
    return best
