"""The transport map: fitted palette -> (unbalanced) Sinkhorn -> smooth map (§5.1).

What the "palette" map builder (``map.builder = "palette"``,
:func:`wbcgrade.color.grade.builders.palette_map`) does once the weights are
fitted (:func:`transport_map`):

1. the palette: the styles' barycenter with the fitted weights, on the
   transfer grid (:func:`palette_barycenter`);
2. Sinkhorn between the photo's histogram and the palette (optionally
   relaxed on the palette's side), and the barycentric projection of the
   plan ``T(x_i) = (K (b x))_i / (K b)_i`` on every bin
   (:func:`color_transfer_map`);
3. a smooth 33^3 lattice LUT fitted to that projection, weighted by the
   photo's colours (:mod:`wbcgrade.color.palette.smooth_map`).

Everything lives in the working space's unit cube. Defaults and why
(docs/benchmarks.md, the figures behind the code's settings): the photo's
histogram, the plan and the map live on the paper's 128^3 grid; the
palette and the plan use a kernel of sigma = 1/31 of the cube (about 4 bins
at 128^3), ten times narrower than the fit's, which keeps graded photos
colourful (entropic blur pulls colours towards grey; tested in
``tests/color``). The palette is computed on 64^3 (2 bins wide: resolved)
and interpolated to 128^3. The plan is solved coarse-to-fine (32^3 with
epsilon scaling, then 64^3, then 128^3, each warm-starting the next), so the
128^3 solve starts close to its answer.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from wbcgrade.color.histogram import DEFAULT_FLOOR, add_floor
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.outcome import TransportCheck
from wbcgrade.color.palette.smooth_map import fit_smooth_map
from wbcgrade.color.presets import StyleSet
from wbcgrade.core import (
    BarycenterSolver,
    GridGeometry,
    barycentric_projection,
    multiscale_sinkhorn,
)
from wbcgrade.core.geometry import refine_grid
from wbcgrade.errors import NumericalError

__all__ = ["color_transfer_map", "palette_barycenter", "TransportMap", "transport_map"]

#: Weights below this share of the largest are left out of the palette's barycenter.
NEGLIGIBLE_WEIGHT = 1e-6


def color_transfer_map(photo_hist: np.ndarray, target_hist: np.ndarray, width: float,
                       tol: float = 1e-3, max_iter: int = 2000, floor: float = DEFAULT_FLOOR,
                       schedule: Sequence[float] = (4.0, 2.0), coarsest: int = 32,
                       relaxation: float | None = None, coarse_tol: float | None = None,
                       overrelaxation: float = 1.7, fine_overrelaxation: float = 1.5):
    """Colour map moving a photo's colours onto a target palette.

    Entropic transport (Sinkhorn) between the photo's histogram and the
    target on their (n, n, n) grid with a kernel ``width`` bins wide, then the
    barycentric projection of the plan ``T(x_i) = (K (b x))_i / (K b)_i``.

    The plan is solved coarse to fine (:func:`wbcgrade.core.multiscale_sinkhorn`):
    first on coarser grids (halving down to ``coarsest`` bins, same kernel in
    colour units) and, on the coarsest, with kernels ``schedule`` times wider
    (to a loose tolerance); each solve warm-starts the next. Every level's
    histograms are mixed with ``floor`` of the uniform one. The coarser grids
    are solved to ``coarse_tol`` (default ``tol / 3``): what error they leave
    is removed on the finest grid, where an iteration costs 8 times more. Iterations
    are over-relaxed (``overrelaxation`` on the coarser grids, ``fine_overrelaxation``
    on the finest): fewer iterations and a map closer to a converged solve
    (docs/benchmarks.md).

    Returns
    -------
    color_map : (n, n, n, 3) float32 in [0, 1], the raw barycentric projection
    result : wbcgrade.core.SinkhornResult of the final solve
    """
    n = photo_hist.shape[0]
    sigma = width / (n - 1)  # kernel in colour units, the same on every grid
    geometry = GridGeometry((n,) * 3, 2.0 * sigma ** 2)
    result = multiscale_sinkhorn(
        photo_hist, target_hist, geometry, coarsest=coarsest, schedule=schedule, tol=tol,
        coarse_tol=coarse_tol, max_iter=max_iter, floor=floor, relaxation=relaxation,
        overrelaxation=overrelaxation, fine_overrelaxation=fine_overrelaxation)
    color_map = barycentric_projection(result, geometry)
    if not np.all(np.isfinite(color_map)):
        raise NumericalError("the colour map is not finite (try a larger {transfer.width})",
                             fields=("transfer.width",))
    return np.clip(color_map, 0.0, 1.0).astype(np.float32), result


def palette_barycenter(style_hists: StyleSet | Callable[[int], np.ndarray], weights: np.ndarray,
                       options: GradeOptions) -> tuple[np.ndarray, dict]:
    """The target palette: the styles' barycenter with ``weights``, on the transfer grid.

    Computed (the fit's L = ``options.fit.n_iter`` iterations, the transfer
    kernel) on ``min(transfer.bins, transfer.palette_bins)`` bins per axis
    and, when that is coarser than the transfer grid, interpolated onto it
    (densities, renormalised). Styles whose weight is below
    :data:`NEGLIGIBLE_WEIGHT` of the largest are left out (the others' weights
    renormalised).

    Parameters
    ----------
    style_hists : the styles (only those with weight are re-binned), or a callable
        ``bins -> (S, bins, bins, bins)`` style histograms.
    weights : (S,) on the simplex.

    Returns
    -------
    ((bins, bins, bins) float64 summing to 1, info dict)
    """
    transfer = options.transfer
    n = transfer.bins
    m = min(n, transfer.palette_bins)
    sigma = transfer.width_bins / (n - 1)
    geometry = GridGeometry((m,) * 3, 2.0 * sigma ** 2)
    # styles whose weight is negligible (the softmax fit leaves ~1e-13) change the palette
    # by less than 1e-5 of a bin's mass: not computed (each costs 1/S of the barycenter)
    keep = np.flatnonzero(np.asarray(weights) > NEGLIGIBLE_WEIGHT * np.max(weights))
    hists = (style_hists.at_bins(m, keep) if isinstance(style_hists, StyleSet)
             else style_hists(m)[keep])
    floored = np.stack([add_floor(h, transfer.floor) for h in hists])
    solver = BarycenterSolver(floored, geometry, options.fit.n_iter)
    target = solver.barycenter(np.asarray(weights)[keep] / np.sum(np.asarray(weights)[keep]))
    if m != n:
        target = np.clip(refine_grid(target, (n,) * 3), 0.0, None)
        target /= target.sum()
    return target, {"bins": m, "gamma": float(geometry.gamma), "backend": solver.last_backend}



class TransportMap(NamedTuple):
    """What :func:`transport_map` returns: the map (m, m, m, 3) float32 in [0, 1], the
    palette (n, n, n), diagnostics (JSON-friendly), seconds per stage, and how the plan's
    Sinkhorn solve ended."""

    color_map: np.ndarray
    palette: np.ndarray
    info: dict
    timings: dict
    check: TransportCheck


def transport_map(photo: np.ndarray, styles: StyleSet, weights: np.ndarray,
                  options: GradeOptions,
                  stage: Callable[[str], None] | None = None) -> TransportMap:
    """The colour map moving a photo's colours onto the styles' palette at ``weights``.

    The palette, the plan and the smooth map (see the module docstring); the
    "palette" map builder (:func:`wbcgrade.color.grade.builders.palette_map`) after
    the weight fit.

    Parameters
    ----------
    photo : (n, n, n) the photo's histogram on the transfer grid.
    styles : the styles, in the working space.
    weights : (S,) on the simplex.

    Returns
    -------
    :class:`TransportMap`; the raw projection on the transfer grid is the map when
    ``map.smoothness`` and ``map.stiffness`` are 0.
    """
    say = stage or (lambda name: None)
    transfer, shape = options.transfer, options.map
    timings: dict[str, float] = {}
    say("barycenter")
    start = time.perf_counter()
    palette, palette_info = palette_barycenter(styles, weights, options)
    timings["barycenter"] = time.perf_counter() - start
    say("transfer")
    start = time.perf_counter()
    width = transfer.width_bins
    raw, result = color_transfer_map(photo, palette, width, transfer.tol,
                                     transfer.max_iter, transfer.floor,
                                     relaxation=transfer.relaxation)
    info = {"palette": palette_info,
            "sinkhorn": {"iterations": int(result.n_iter), "error": float(result.error),
                         "converged": bool(result.converged), "bins": transfer.bins,
                         "gamma": float(GridGeometry.with_width((transfer.bins,) * 3,
                                                                width).gamma),
                         "width_bins": width, "relaxation": transfer.relaxation}}
    if shape.smoothed:
        color_map = fit_smooth_map(raw, photo, shape.size, shape.smoothness,
                                   shape.stiffness)
        info["map"] = {"size": shape.size, "smoothness": shape.smoothness,
                       "stiffness": shape.stiffness}
    else:
        color_map = raw
        info["map"] = {"size": transfer.bins, "smoothness": 0.0, "stiffness": 0.0}
    timings["transfer"] = time.perf_counter() - start
    return TransportMap(color_map, palette, info, timings,
                        TransportCheck(bool(result.converged), float(result.error)))
