"""Colour transfer towards the closest barycenter of style palettes (paper §5.1).

Pipeline for one photo (docs/architecture.md, "Data flow"):

1. soft RGB histograms of the photo and the styles on a coarse *fit* grid;
2. barycentric coordinates: the weights whose barycenter best explains the
   photo's histogram (``wbcgrade.core.barycentric_coordinates``);
3. the barycenter with those weights on the finer *transfer* grid, Sinkhorn
   between the photo's histogram and it (optionally relaxed on the palette's
   side), and the barycentric projection ``T(x_i) = (K (b x))_i / (K b)_i``
   on every bin;
4. the colour map: a smooth 33^3 lattice LUT fitted to that projection,
   weighted by the photo's colours (:mod:`wbcgrade.color.smooth_map`), made
   monotone in lightness;
5. every pixel moved through the map by trilinear interpolation, then the
   input's grain and edges given back (:mod:`wbcgrade.color.regrain`).

Defaults and why (see :class:`GradeOptions`; measured on 2 shared cores,
``benchmarks/apply.py``): the photo's histogram, the Sinkhorn plan and the
colour map live on the paper's 128^3 grid. The weights are fitted on a 16^3
grid with a kernel whose sigma is fixed in colour units (0.1 of the cube,
1.5 bins there), in float32: the same energy on 32^3-128^3 grids has the same
minimiser (L-BFGS on the 128^3 energy from the fitted weights finds nothing
lower in five evaluations; at 64^3 the gap was 2e-6 relative), at a small
fraction of the cost. The target palette (barycenter)
and the plan use a kernel ten times narrower (sigma = 1/31 of the cube:
about 4 bins at 128^3), which keeps graded photos colourful (entropic blur
pulls colours towards grey; tested in ``tests/color``). The palette is
computed on 64^3 (2 bins wide: resolved) and interpolated to 128^3. The
plan is solved coarse-to-fine (32^3 with epsilon scaling, then 64^3, then
128^3, each warm-starting the next), so the 128^3 solve needs ~15-40
iterations instead of ~150.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wbcgrade.color.histogram import DEFAULT_FLOOR, DEFAULT_MAX_PIXELS, add_floor, image_histogram
from wbcgrade.color.presets import StyleSet
from wbcgrade.color.regrain import DEFAULT_REGRAIN_EPS, DEFAULT_REGRAIN_RADIUS, regrain_map
from wbcgrade.color.remap import apply_color_map, keep_lightness, monotone_lightness
from wbcgrade.color.smooth_map import (
    DEFAULT_MAP_SIZE,
    DEFAULT_SMOOTHNESS,
    DEFAULT_STIFFNESS,
    fit_smooth_map,
)
from wbcgrade.color.weights import parse_weights
from wbcgrade.errors import InputError, NumericalError

__all__ = ["GradeOptions", "Grade", "fit_weights", "color_transfer_map", "grade_color_map",
           "grade_image", "parse_weights"]

LOSSES = ("quadratic", "l1", "kl", "wasserstein")
#: How a grade's colour map is built (``GradeOptions.mode``).
MODES = ("look", "palette")


@dataclass
class GradeOptions:
    """Settings of a grade (all documented defaults).

    Attributes
    ----------
    bins : bins per axis of the transfer grid (the photo's histogram, the
        Sinkhorn plan and the raw barycentric projection).
    fit_bins : bins per axis of the grid the weights are fitted on (the fit
        kernel's sigma is fixed in colour units, so the same energy on a 128^3
        grid has the same minimiser: ``benchmarks/apply.py --verify``).
    palette_bins : the target palette (barycenter) is computed on at most this
        many bins per axis and interpolated onto the transfer grid (its kernel
        is >= 2 bins wide there, so it is resolved; 128^3 costs 8x more).
    loss : loss between the barycenter and the photo's histogram.
    width : fit kernel width, in bins of the fit grid (gamma = 2 (width/(fit_bins-1))^2).
    gamma : fit entropic regularisation; overrides ``width`` when given.
    transfer_width : kernel width, in bins of the transfer grid, of the
        transfer barycenter and the Sinkhorn plan (smaller = crisper colours,
        slower Sinkhorn). Default: sigma = 1/31 of the colour cube whatever
        the grid, i.e. ``max(1, (bins - 1) / 31)`` bins (1 bin at 32^3, ~2 at 64^3).
    n_iter : barycenter iterations L.
    max_iter : L-BFGS iterations at most.
    floor : fraction of mass spread uniformly over the bins of every histogram
        before fitting (real photo histograms are sparse; KL needs > 0).
    strength : t in [0, 1]: x -> (1 - t) x + t T(x).
    weights : fixed style weights (skip the fit).
    sinkhorn_tol, sinkhorn_max_iter : transfer Sinkhorn stopping rule
        (L1 error on the photo's marginal). 3e-3 gives the same smooth colour
        map as 1e-3 to 0.13/255 on average (0.37/255 at most) on the 16 MP
        sample, in half the time.
    max_pixels : photos larger than this are subsampled for histograms.
    fit_tol : the weight fit stops when an L-BFGS step lowers the (normalised)
        loss by less than this.
    relaxation : rho > 0 relaxes the palette side of the transfer plan by
        ``rho KL`` (unbalanced transport; colours of the palette the photo has
        no use for are left out instead of forced onto it); None: balanced.
    map_size : nodes per axis of the smooth colour map (the grade is this
        lattice LUT; ``--lut`` at the same size writes it exactly).
    smoothness, stiffness : curvature and first-difference penalties of the
        smooth map fit (:mod:`wbcgrade.color.smooth_map`); both 0: the raw
        barycentric projection on the transfer grid is the map (the paper's).
    regrain : keep the input's grain and edges (:mod:`wbcgrade.color.regrain`).
    regrain_radius : window radius as a fraction of the photo's long side.
    regrain_eps : below this variance (encoded units squared) input detail
        is kept as it is.
    preserve_luminance : keep each colour's Oklab lightness, change only its
        hue and chroma.
    monotone : make the map's output luma non-decreasing in each input
        channel (no lightness reversals between neighbouring colours).
    input_space, working_space : colour space names (OpenColorIO config;
        :mod:`wbcgrade.color.colorspace`); None: what the file says, and
        sRGB-encoded Rec.709.
    mode : "look": apply the look the style set shares, corrected towards the
        photo's own scene when a style is one (:mod:`wbcgrade.color.look`);
        "palette": move the photo's palette onto the closest barycenter of
        the style palettes (the paper's colour transfer).
    natural : preset file (.npz, ``wbcgrade preset build``) of ungraded
        photos, the content model of look extraction; None: the shipped one.
    """

    bins: int = 128
    fit_bins: int = 16
    palette_bins: int = 64
    loss: str = "quadratic"
    width: float = 1.5
    gamma: float | None = None
    transfer_width: float | None = None
    n_iter: int = 60
    max_iter: int = 30
    floor: float = DEFAULT_FLOOR
    strength: float = 1.0
    weights: Sequence[float] | None = None
    sinkhorn_tol: float = 3e-3
    sinkhorn_max_iter: int = 2000
    max_pixels: int = DEFAULT_MAX_PIXELS
    fit_tol: float = 1e-6
    relaxation: float | None = None
    map_size: int = DEFAULT_MAP_SIZE
    smoothness: float = DEFAULT_SMOOTHNESS
    stiffness: float = DEFAULT_STIFFNESS
    regrain: bool = True
    regrain_radius: float = DEFAULT_REGRAIN_RADIUS
    regrain_eps: float = DEFAULT_REGRAIN_EPS
    preserve_luminance: bool = False
    monotone: bool = True
    input_space: str | None = None
    working_space: str | None = None
    mode: str = "palette"
    natural: str | None = None

    def validate(self, n_styles: int | None = None) -> None:
        """Raise InputError on an option out of range."""
        if self.mode not in MODES:
            raise InputError(f"--mode must be one of {', '.join(MODES)}")
        if not 4 <= self.bins <= 256:
            raise InputError("--bins must be between 4 and 256")
        if not 4 <= self.fit_bins <= 256:
            raise InputError("--fit-bins must be between 4 and 256")
        if not 4 <= self.palette_bins <= 256:
            raise InputError("--palette-bins must be between 4 and 256")
        if self.loss not in LOSSES:
            raise InputError(f"--loss must be one of {', '.join(LOSSES)}")
        for name, value in (("--width", self.width), ("--transfer-width", self.transfer_width)):
            if value is not None and not (np.isfinite(value) and value > 0):
                raise InputError(f"{name} must be positive")
        if self.gamma is not None and not (np.isfinite(self.gamma) and self.gamma > 0):
            raise InputError("--gamma must be positive")
        if not 0.0 <= self.strength <= 1.0:
            raise InputError("--strength must be in [0, 1]")
        if not 0.0 <= self.floor < 1.0:
            raise InputError("floor must be in [0, 1)")
        if self.n_iter < 1 or self.max_iter < 1:
            raise InputError("iteration counts must be at least 1")
        if self.relaxation is not None and not (np.isfinite(self.relaxation)
                                                and self.relaxation > 0):
            raise InputError("--relax must be a positive number")
        if not 2 <= self.map_size <= 129:
            raise InputError("--map-size must be between 2 and 129")
        for name, value in (("--smoothness", self.smoothness), ("--stiffness", self.stiffness)):
            if not (np.isfinite(value) and value >= 0):
                raise InputError(f"{name} must be a non-negative number")
        for name, value in (("--regrain-radius", self.regrain_radius),
                            ("--regrain-eps", self.regrain_eps)):
            if not (np.isfinite(value) and value > 0):
                raise InputError(f"{name} must be positive")
        if not (np.isfinite(self.fit_tol) and self.fit_tol > 0):
            raise InputError("the fit tolerance must be positive")
        if self.weights is not None and n_styles is not None and len(self.weights) != n_styles:
            raise InputError(f"--weights gives {len(self.weights)} numbers for {n_styles} styles")


def transfer_width_bins(opts: GradeOptions) -> float:
    """The transfer kernel width in bins (see ``GradeOptions.transfer_width``)."""
    if opts.transfer_width is not None:
        return float(opts.transfer_width)
    return max(1.0, (opts.bins - 1) / 31.0)


@dataclass
class Grade:
    """A fitted grade: weights, the colour map and what it cost.

    Attributes
    ----------
    names : S style names.
    weights : (S,) barycentric weights.
    loss : fit loss at the weights (None when the weights were given).
    color_map : (m, m, m, 3) float32, new encoded colour of each node of the
        grade's lattice LUT (m = map_size; the transfer grid for a raw map;
        strength not applied).
    strength : the blend applied by :meth:`apply`.
    timings : seconds per stage.
    info : fit and Sinkhorn diagnostics (JSON-friendly).
    barycenter : (n, n, n) the target palette on the transfer grid.
    regrain : (radius, eps) of the regrain step applied to images, or None.
    """

    names: list[str]
    weights: np.ndarray
    loss: float | None
    color_map: np.ndarray
    strength: float = 1.0
    timings: dict[str, float] = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    barycenter: np.ndarray | None = None
    regrain: tuple[float, float] | None = None

    def apply(self, encoded: np.ndarray) -> np.ndarray:
        """Grade encoded colours in [0, 1] -> float32, same shape.

        An (H, W, 3) image also goes through the regrain step when the grade
        has one; other shapes (lists of colours) get the colour map only.
        """
        if self.regrain is not None and encoded.ndim == 3 and min(encoded.shape[:2]) > 1:
            return regrain_map(encoded, self.color_map, self.strength, *self.regrain)
        return apply_color_map(encoded, self.color_map, self.strength)

    def ranked(self) -> list[tuple[str, float]]:
        """(name, weight) sorted by decreasing weight."""
        order = np.argsort(-self.weights, kind="stable")
        return [(self.names[i], float(self.weights[i])) for i in order]


def _fit_geometry(opts: GradeOptions):
    from wbcgrade.core import GridGeometry

    shape = (opts.fit_bins,) * 3
    gamma = opts.gamma if opts.gamma is not None else 2.0 * (opts.width / (opts.fit_bins - 1)) ** 2
    # float32 products where they are exact enough (the core falls back to float64).
    return GridGeometry(shape, gamma, np.float32)


def fit_weights(photo_hist: np.ndarray, style_hists: np.ndarray, opts: GradeOptions,
                callback: Callable[[int, np.ndarray, float], None] | None = None):
    """Barycentric coordinates of a photo's histogram in the styles'.

    Parameters
    ----------
    photo_hist : (m, m, m) histogram on the fit grid (m = opts.fit_bins).
    style_hists : (S, m, m, m) histograms on the same grid.

    Returns
    -------
    wbcgrade.core.CoordinatesResult (weights (S,), loss, barycenter, ...).
    """
    from wbcgrade.core import barycentric_coordinates

    geometry = _fit_geometry(opts)
    target = add_floor(photo_hist, opts.floor)
    hists = np.stack([add_floor(h, opts.floor) for h in style_hists])
    return barycentric_coordinates(target, hists, geometry, loss=opts.loss, n_iter=opts.n_iter,
                                   max_iter=opts.max_iter, tol=opts.fit_tol, callback=callback)


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
    is removed on the finest grid, where an iteration costs 8 times more (on
    the 16 MP sample this takes the 128^3 solve from ~22 to ~6 iterations, and
    the map closer to a converged solve). Iterations are over-relaxed
    (``overrelaxation`` on the coarser grids, ``fine_overrelaxation`` on the
    finest): measured on four sample photos, 2-4 times fewer coarse iterations
    and a map 2-5 times closer to a converged solve (0.01-0.05/255 on average;
    the transfer 10-30 % faster: the relaxed update costs an exp and a log per
    bin).

    Returns
    -------
    color_map : (n, n, n, 3) float32 in [0, 1], the raw barycentric projection
    result : wbcgrade.core.SinkhornResult of the final solve
    """
    from wbcgrade.core import GridGeometry, barycentric_projection, multiscale_sinkhorn

    n = photo_hist.shape[0]
    sigma = width / (n - 1)  # kernel in colour units, the same on every grid
    geometry = GridGeometry((n,) * 3, 2.0 * sigma ** 2)
    result = multiscale_sinkhorn(
        photo_hist, target_hist, geometry, coarsest=coarsest, schedule=schedule, tol=tol,
        coarse_tol=coarse_tol, max_iter=max_iter, floor=floor, relaxation=relaxation,
        overrelaxation=overrelaxation, fine_overrelaxation=fine_overrelaxation)
    color_map = barycentric_projection(result, geometry)
    if not np.all(np.isfinite(color_map)):
        raise NumericalError("the colour map is not finite (try a larger --transfer-width)")
    return np.clip(color_map, 0.0, 1.0).astype(np.float32), result


def palette_barycenter(style_hists: StyleSet | Callable[[int], np.ndarray], weights: np.ndarray,
                       opts: GradeOptions) -> tuple[np.ndarray, dict]:
    """The target palette: the styles' barycenter with ``weights``, on the transfer grid.

    Computed (L = ``opts.n_iter`` iterations, transfer kernel) on
    ``min(bins, palette_bins)`` bins per axis and, when that is coarser than
    the transfer grid, interpolated onto it (densities, renormalised).

    Parameters
    ----------
    style_hists : the styles (only those with weight are re-binned), or a callable
        ``bins -> (S, bins, bins, bins)`` style histograms.
    weights : (S,) on the simplex.

    Returns
    -------
    ((bins, bins, bins) float64 summing to 1, info dict)
    """
    from wbcgrade.core import BarycenterSolver, GridGeometry
    from wbcgrade.core.geometry import refine_grid

    n = opts.bins
    m = min(n, opts.palette_bins)
    sigma = transfer_width_bins(opts) / (n - 1)
    geometry = GridGeometry((m,) * 3, 2.0 * sigma ** 2)
    keep = np.flatnonzero(np.asarray(weights) > 0)
    hists = (style_hists.at_bins(m, keep) if isinstance(style_hists, StyleSet)
             else style_hists(m)[keep])
    floored = np.stack([add_floor(h, opts.floor) for h in hists])
    solver = BarycenterSolver(floored, geometry, opts.n_iter)
    target = solver.barycenter(np.asarray(weights)[keep] / np.sum(np.asarray(weights)[keep]))
    if m != n:
        target = np.clip(refine_grid(target, (n,) * 3), 0.0, None)
        target /= target.sum()
    return target, {"bins": m, "gamma": float(geometry.gamma), "backend": solver.last_backend}


def grade_color_map(photo_hist: np.ndarray, target: np.ndarray,
                    opts: GradeOptions) -> tuple[np.ndarray, dict]:
    """The colour map of a grade: transport to the palette, then a smooth lattice fit.

    Sinkhorn between the photo's histogram and the target palette (relaxed on
    the palette's side when ``opts.relaxation`` is set), the barycentric
    projection of the plan on the transfer grid, then the smooth map fitted
    to it, weighted by the photo's colours (``opts.map_size`` nodes a side;
    the raw projection when ``opts.smoothness`` and ``opts.stiffness`` are 0),
    made monotone in lightness (``opts.monotone``), and the photo's lightness
    put back when ``opts.preserve_luminance``.

    Parameters
    ----------
    photo_hist, target : (n, n, n) histograms on the transfer grid (n = opts.bins).

    Returns
    -------
    color_map : (m, m, m, 3) float32 in [0, 1]
    info : Sinkhorn and map diagnostics (JSON-friendly)
    """
    from wbcgrade.core import GridGeometry

    width = transfer_width_bins(opts)
    raw, result = color_transfer_map(photo_hist, target, width, opts.sinkhorn_tol,
                                     opts.sinkhorn_max_iter, opts.floor,
                                     relaxation=opts.relaxation)
    info = {"sinkhorn": {"iterations": int(result.n_iter), "error": float(result.error),
                         "converged": bool(result.converged), "bins": opts.bins,
                         "gamma": float(GridGeometry.with_width((opts.bins,) * 3, width).gamma),
                         "width_bins": width, "relaxation": opts.relaxation}}
    color_map = raw
    if opts.smoothness > 0 or opts.stiffness > 0:
        color_map = fit_smooth_map(raw, photo_hist, opts.map_size, opts.smoothness,
                                   opts.stiffness)
        info["map"] = {"size": opts.map_size, "smoothness": opts.smoothness,
                       "stiffness": opts.stiffness}
    else:
        info["map"] = {"size": opts.bins, "smoothness": 0.0, "stiffness": 0.0}
    if opts.monotone and not opts.preserve_luminance:
        color_map = monotone_lightness(color_map)
    if opts.preserve_luminance:
        color_map = keep_lightness(color_map)
    info["map"].update(monotone=opts.monotone, preserve_luminance=opts.preserve_luminance)
    return color_map, info


def regrain_settings(opts: GradeOptions) -> tuple[float, float] | None:
    """(radius, eps) of the regrain step of a grade, or None when it is off."""
    return (opts.regrain_radius, opts.regrain_eps) if opts.regrain else None


def grade_image(encoded: np.ndarray, styles: StyleSet, opts: GradeOptions,
                alpha: np.ndarray | None = None,
                callback: Callable[[int, np.ndarray, float], None] | None = None,
                stage: Callable[[str], None] | None = None) -> Grade:
    """Fit a grade for an encoded (H, W, 3) photo against a style set (one pass, no checks).

    The building block of the per-photo pipeline: one weight fit from
    ``opts`` (or ``opts.weights``), the palette and the colour map. It does
    not check the fit against each single style, refit, or convert colour
    spaces; library users call :func:`wbcgrade.color.grading.grade_array`
    (arrays in and out, the command's guarantees) instead.

    ``callback`` receives the fit's progress (n_evaluations, weights, loss);
    ``stage`` the name of each stage as it starts. Returns a :class:`Grade`;
    call ``grade.apply(encoded)`` for the pixels.
    """

    opts.validate(len(styles.names))
    timings: dict[str, float] = {}
    info: dict = {}
    say = stage or (lambda name: None)

    def timed(name, fn, *args, **kwargs):
        say(name)
        start = time.perf_counter()
        out = fn(*args, **kwargs)
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - start
        return out

    photo_hist = timed("histograms", image_histogram, encoded, opts.bins, alpha, opts.max_pixels)
    loss = None
    if opts.weights is not None:
        weights = np.asarray(opts.weights, dtype=np.float64)
        weights = weights / weights.sum()
    else:
        photo_fit = timed("histograms", image_histogram, encoded, opts.fit_bins, alpha,
                          opts.max_pixels)
        style_fit = timed("histograms", styles.at_bins, opts.fit_bins)
        fit = timed("fit", fit_weights, photo_fit, style_fit, opts, callback)
        weights, loss = np.asarray(fit.weights), float(fit.loss)
        info["fit"] = {"evaluations": fit.n_evaluations, "iterations": fit.n_iterations,
                       "converged": fit.converged, "initial_loss": float(fit.initial_loss),
                       "bins": opts.fit_bins, "gamma": float(_fit_geometry(opts).gamma)}
    target, info["palette"] = timed("barycenter", palette_barycenter, styles, weights,
                                    opts)
    color_map, map_info = timed("transfer", grade_color_map, photo_hist, target, opts)
    info.update(map_info)
    return Grade(names=list(styles.names), weights=weights, loss=loss, color_map=color_map,
                 strength=opts.strength, timings=timings,
                 info=info, barycenter=target, regrain=regrain_settings(opts))
