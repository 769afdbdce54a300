"""Colour transfer towards the closest barycenter of style palettes (paper §5.1).

Pipeline for one photo (DESIGN.md §1 "Colour transfer"):

1. soft RGB histograms of the photo and the styles on a coarse *fit* grid;
2. barycentric coordinates: the weights whose barycenter best explains the
   photo's histogram (``wbcgrade.core.barycentric_coordinates``);
3. the barycenter with those weights on the finer *transfer* grid, Sinkhorn
   between the photo's histogram and it, and the barycentric projection
   ``T(x_i) = (K (b x))_i / (K b)_i`` on every bin: a colour map;
4. every pixel moved through the map by trilinear interpolation.

Defaults and why (see :class:`GradeOptions`; measured on 2 shared cores):
the weights are fitted on a 16^3 grid with a kernel 1.5 bins wide (sigma
~0.1 of the cube): ~0.4 s per gradient, ~10 s per fit, where a 128^3 fit takes
hours (DESIGN.md §4). The colour map is built on a 32^3 grid with a kernel 1
bin wide (sigma = 1/31 of the cube, gamma ~0.002, ten times smaller than the
fit's): barycenter ~1-2 s, Sinkhorn ~1-3 s with epsilon scaling. The
transfer kernel keeps that sigma on other grids: ``--bins 64`` (2 bins wide)
takes ~6 s of barycenter and ~6 s of Sinkhorn, ``--bins 128`` ~95 s and ~80 s
(1 GB) for three styles. Entropic blur pulls each colour towards the mean
of where its mass goes; the narrow transfer
kernel keeps graded photos far more colourful than a map built with the
fit's kernel (tested in ``tests/color``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wbcgrade.color.histogram import DEFAULT_FLOOR, DEFAULT_MAX_PIXELS, add_floor, image_histogram
from wbcgrade.color.presets import StyleSet
from wbcgrade.color.remap import apply_color_map
from wbcgrade.errors import InputError, NumericalError

__all__ = ["GradeOptions", "Grade", "fit_weights", "color_transfer_map", "grade_image",
           "parse_weights"]

LOSSES = ("quadratic", "l1", "kl", "wasserstein")


@dataclass
class GradeOptions:
    """Settings of a grade (all documented defaults).

    Attributes
    ----------
    bins : bins per axis of the transfer grid (the colour map's resolution).
    fit_bins : bins per axis of the grid the weights are fitted on.
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
        (L1 error on the photo's marginal).
    max_pixels : photos larger than this are subsampled for histograms.
    """

    bins: int = 32
    fit_bins: int = 16
    loss: str = "quadratic"
    width: float = 1.5
    gamma: float | None = None
    transfer_width: float | None = None
    n_iter: int = 60
    max_iter: int = 30
    floor: float = DEFAULT_FLOOR
    strength: float = 1.0
    weights: Sequence[float] | None = None
    sinkhorn_tol: float = 1e-3
    sinkhorn_max_iter: int = 2000
    max_pixels: int = DEFAULT_MAX_PIXELS

    def validate(self, n_styles: int | None = None) -> None:
        """Raise InputError on an option out of range."""
        if not 4 <= self.bins <= 256:
            raise InputError("--bins must be between 4 and 256")
        if not 4 <= self.fit_bins <= 256:
            raise InputError("--fit-bins must be between 4 and 256")
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
        if self.weights is not None and n_styles is not None and len(self.weights) != n_styles:
            raise InputError(f"--weights gives {len(self.weights)} numbers for {n_styles} styles")


def transfer_width_bins(opts: GradeOptions) -> float:
    """The transfer kernel width in bins (see ``GradeOptions.transfer_width``)."""
    if opts.transfer_width is not None:
        return float(opts.transfer_width)
    return max(1.0, (opts.bins - 1) / 31.0)


def parse_weights(text: str) -> list[float]:
    """'a,b,c' -> weights normalised to sum 1 (InputError when malformed)."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--weights {text!r}: expected comma-separated numbers") from None
    if not values or any(not np.isfinite(v) or v < 0 for v in values) or sum(values) <= 0:
        raise InputError(f"--weights {text!r}: need non-negative numbers, not all zero")
    return [v / sum(values) for v in values]


@dataclass
class Grade:
    """A fitted grade: weights, the colour map and what it cost.

    Attributes
    ----------
    names : S style names.
    weights : (S,) barycentric weights.
    loss : fit loss at the weights (None when the weights were given).
    color_map : (n, n, n, 3) float32, new encoded colour of each transfer bin
        (strength not applied).
    strength : the blend applied by :meth:`apply`.
    timings : seconds per stage.
    info : fit and Sinkhorn diagnostics (JSON-friendly).
    barycenter : (n, n, n) the target palette on the transfer grid.
    """

    names: list[str]
    weights: np.ndarray
    loss: float | None
    color_map: np.ndarray
    strength: float = 1.0
    timings: dict[str, float] = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    barycenter: np.ndarray | None = None

    def apply(self, encoded: np.ndarray) -> np.ndarray:
        """Grade (..., 3) encoded colours in [0, 1] -> float32 (..., 3)."""
        return apply_color_map(encoded, self.color_map, self.strength)

    def ranked(self) -> list[tuple[str, float]]:
        """(name, weight) sorted by decreasing weight."""
        order = np.argsort(-self.weights, kind="stable")
        return [(self.names[i], float(self.weights[i])) for i in order]


def _fit_geometry(opts: GradeOptions):
    from wbcgrade.core import GridGeometry

    shape = (opts.fit_bins,) * 3
    if opts.gamma is not None:
        return GridGeometry(shape, opts.gamma)
    return GridGeometry.with_width(shape, opts.width)


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
                                   max_iter=opts.max_iter, callback=callback)


def color_transfer_map(photo_hist: np.ndarray, target_hist: np.ndarray, width: float,
                       tol: float = 1e-3, max_iter: int = 2000, floor: float = DEFAULT_FLOOR,
                       schedule: Sequence[float] = (4.0, 2.0)):
    """Colour map moving a photo's colours onto a target palette.

    Entropic transport (Sinkhorn) between the photo's histogram and the
    target on their (n, n, n) grid with a kernel ``width`` bins wide, then the
    barycentric projection of the plan ``T(x_i) = (K (b x))_i / (K b)_i``.

    A narrow kernel converges slowly from a cold start, so the plan is first
    solved with kernels ``schedule`` times wider (to a loose tolerance) and
    each solve warm-starts the next (epsilon scaling: the dual potential
    ``gamma log b`` carries over).

    Returns
    -------
    color_map : (n, n, n, 3) float32 in [0, 1]
    result : wbcgrade.core.SinkhornResult of the final solve
    """
    from wbcgrade.core import GridGeometry, barycentric_projection, sinkhorn

    n = photo_hist.shape[0]
    p, q = add_floor(photo_hist, floor), add_floor(target_hist, floor)
    log_b, gamma_prev = None, None
    for factor in [f for f in schedule if f > 1.0] + [1.0]:
        geometry = GridGeometry.with_width((n,) * 3, width * factor)
        init = None if log_b is None else log_b * (gamma_prev / geometry.gamma)
        last = factor == 1.0
        result = sinkhorn(p, q, geometry, tol=tol if last else max(tol, 1e-2),
                          max_iter=max_iter, init_log_b=init)
        log_b, gamma_prev = result.log_b, geometry.gamma
    color_map = barycentric_projection(result, geometry)
    if not np.all(np.isfinite(color_map)):
        raise NumericalError("the colour map is not finite (try a larger --transfer-width)")
    return np.clip(color_map, 0.0, 1.0).astype(np.float32), result


def grade_image(encoded: np.ndarray, styles: StyleSet, opts: GradeOptions,
                alpha: np.ndarray | None = None,
                callback: Callable[[int, np.ndarray, float], None] | None = None,
                stage: Callable[[str], None] | None = None) -> Grade:
    """Fit a grade for an encoded (H, W, 3) photo against a style set.

    ``callback`` receives the fit's progress (n_evaluations, weights, loss);
    ``stage`` the name of each stage as it starts. Returns a :class:`Grade`;
    call ``grade.apply(encoded)`` for the pixels.
    """
    from wbcgrade.core import barycenter

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
    from wbcgrade.core import GridGeometry

    style_hists = timed("histograms", styles.at_bins, opts.bins)
    width = transfer_width_bins(opts)
    geometry = GridGeometry.with_width((opts.bins,) * 3, width)
    floored = np.stack([add_floor(h, opts.floor) for h in style_hists])
    target = timed("barycenter", barycenter, floored, weights, geometry, opts.n_iter)
    color_map, result = timed("transfer", color_transfer_map, photo_hist, target,
                              width, opts.sinkhorn_tol, opts.sinkhorn_max_iter,
                              opts.floor)
    info["sinkhorn"] = {"iterations": int(result.n_iter), "error": float(result.error),
                        "converged": bool(result.converged), "bins": opts.bins,
                        "gamma": float(geometry.gamma), "width_bins": width}
    return Grade(names=list(styles.names), weights=weights, loss=loss, color_map=color_map,
                 strength=opts.strength, timings=timings,
                 info=info, barycenter=target)
