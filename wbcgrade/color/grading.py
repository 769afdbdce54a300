"""Per-photo and series grades with a guarantee: never worse than one style alone.

The colour pipeline (:mod:`wbcgrade.color.transfer`) fits barycentric
coordinates from uniform weights. The energy is not convex, so a fit can end
above the loss of a single style image (a vertex of the simplex). This module
evaluates every vertex with the same core loss on the same histograms; when
the fit is worse than the best vertex it refits from that vertex and keeps
whichever of the two is better (the vertex itself if the refit does not beat
it). It also builds the one grade of a series (``--consistent``): one fit on
the pooled palette of all photos and one colour map for all of them.
"""

from __future__ import annotations

import concurrent.futures
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from wbcgrade.color.colorspace import Spaces, plan_spaces, spaces_for, to_working
from wbcgrade.color.histogram import add_floor, image_histogram
from wbcgrade.color.imageio import Image, read_image
from wbcgrade.color.presets import StyleSet, styles_in_space
from wbcgrade.color.render import render
from wbcgrade.color.transfer import (
    Grade,
    GradeOptions,
    _fit_geometry,
    fit_weights,
    grade_color_map,
    grade_image,
    palette_barycenter,
    regrain_settings,
)
from wbcgrade.errors import InputError

__all__ = ["NONZERO_THRESHOLD", "FitSummary", "PhotoGrade", "fit_geometry", "vertex_losses",
           "fit_with_vertex_check", "photo_histograms", "PaletteSum", "pooled_histogram",
           "series_grade", "fit_grade", "grade_array", "grade_photo"]

#: Weights at or above this count as "non-zero" (softmax weights are never exactly 0).
NONZERO_THRESHOLD = 1e-3

FitCallback = Callable[[int, np.ndarray, float], None]


@dataclass
class FitSummary:
    """The weights of a grade and how they compare with single styles.

    Attributes
    ----------
    weights : (S,) weights on the simplex.
    loss : loss of the barycenter at ``weights`` (fit grid, same loss as the fit).
    vertex_losses : (S,) loss of each style alone (weight 1 on it).
    start : "uniform" (the pipeline's fit was kept), "vertex-refit" (refit from
        the best vertex won) or "vertex" (the best single style is the answer);
        "given" when the weights were fixed by the user.
    info : fit diagnostics (JSON-friendly).
    time_s : wall time of the fit and the vertex checks.
    """

    weights: np.ndarray
    loss: float
    vertex_losses: np.ndarray
    start: str = "uniform"
    info: dict = field(default_factory=dict)
    time_s: float = 0.0

    @property
    def best_vertex(self) -> int:
        return int(np.argmin(self.vertex_losses))

    @property
    def n_nonzero(self) -> int:
        return int(np.sum(self.weights >= NONZERO_THRESHOLD))


def fit_geometry(opts: GradeOptions):
    """The core grid geometry the weights are fitted on (as in the pipeline)."""
    return _fit_geometry(opts)


def _fit_problem(photo_fit: np.ndarray, style_fit: np.ndarray, opts: GradeOptions):
    target = add_floor(photo_fit, opts.floor)
    hists = np.stack([add_floor(h, opts.floor) for h in style_fit])
    return target, hists, fit_geometry(opts)


def _loss_at(target, hists, geometry, weights, opts) -> float:
    from wbcgrade.core import barycenter, get_loss

    keep = np.flatnonzero(weights > 0)
    P = barycenter(hists[keep], weights[keep] / weights[keep].sum(), geometry, opts.n_iter)
    value, _ = get_loss(opts.loss).value_and_grad(P, target, geometry)
    return float(value)


def vertex_losses(photo_fit: np.ndarray, style_fit: np.ndarray, opts: GradeOptions) -> np.ndarray:
    """Loss of every single style against the photo, with the fit's loss and grid.

    Parameters
    ----------
    photo_fit : (m, m, m) photo histogram on the fit grid (m = opts.fit_bins).
    style_fit : (S, m, m, m) style histograms on the same grid.

    Returns
    -------
    (S,) losses of ``P_L(e_s)`` (the barycenter with all weight on style s).
    """
    target, hists, geometry = _fit_problem(photo_fit, style_fit, opts)
    return np.array([_loss_at(target, hists, geometry, np.eye(len(hists))[s], opts)
                     for s in range(len(hists))])


class _Cancelled(Exception):
    """Stops a speculative refit whose answer is no longer needed."""


class _HeldProgress:
    """The progress callback of a fit run ahead of time, in another thread.

    Its calls are held until the fit is known to be needed, then replayed in
    order (the caller sees the same calls as from a sequential run); once
    cancelled, the next call stops the fit.
    """

    def __init__(self) -> None:
        self.calls: list[tuple[int, np.ndarray, float]] = []
        self.cancelled = threading.Event()

    def __call__(self, n_evaluations: int, weights: np.ndarray, value: float) -> None:
        if self.cancelled.is_set():
            raise _Cancelled
        self.calls.append((n_evaluations, np.array(weights, copy=True), value))

    def replay(self, callback: FitCallback | None) -> None:
        if callback is not None:
            for call in self.calls:
                callback(*call)


def _speculate() -> bool:
    """Whether a second core is there for the refit from the best vertex."""
    from wbcgrade.core._cpu import n_workers

    return n_workers() >= 2


def fit_with_vertex_check(photo_fit: np.ndarray, style_fit: np.ndarray, opts: GradeOptions,
                          callback: FitCallback | None = None) -> FitSummary:
    """Barycentric coordinates that are never worse than the best single style.

    Runs the pipeline's fit (from uniform weights), evaluates every vertex;
    if the best vertex has a lower loss, refits from it (95 % on that style)
    and keeps the better of the refit and the vertex. With ``opts.weights``
    set, only evaluates the losses of those weights and of the vertices.

    With two cores or more the refit runs ahead of time, beside the fit from
    uniform weights (the fit runs on one core: its products are too small to
    share), and is kept only when the vertex beats that fit; otherwise it is
    stopped. The answer and the callback's calls are those of running the two
    one after the other (the refit's calls are held and replayed).

    Parameters
    ----------
    photo_fit : (m, m, m) photo histogram on the fit grid.
    style_fit : (S, m, m, m) style histograms on the fit grid.
    """
    from wbcgrade.core import barycentric_coordinates

    start = time.perf_counter()
    target, hists, geometry = _fit_problem(photo_fit, style_fit, opts)
    n_styles = len(hists)
    vertices = vertex_losses(photo_fit, style_fit, opts)
    best = int(np.argmin(vertices))
    if opts.weights is not None:
        weights = np.asarray(opts.weights, dtype=np.float64)
        weights = weights / weights.sum()
        loss = _loss_at(target, hists, geometry, weights, opts)
        return FitSummary(weights, loss, vertices, "given", {"start": "given"},
                          time.perf_counter() - start)

    def refit_from_best(progress: FitCallback | None):
        init = np.full(n_styles, 0.05 / (n_styles - 1))
        init[best] = 0.95
        return barycentric_coordinates(target, hists, geometry, loss=opts.loss,
                                       n_iter=opts.n_iter, init_weights=init,
                                       max_iter=opts.max_iter, tol=opts.fit_tol,
                                       callback=progress)

    ahead: concurrent.futures.Future | None = None
    held = _HeldProgress()
    if n_styles > 1 and _speculate():
        runner = concurrent.futures.ThreadPoolExecutor(1, "refit-ahead")
        ahead = runner.submit(refit_from_best, held)
        runner.shutdown(wait=False)
    try:
        fit = fit_weights(photo_fit, style_fit, opts, callback)
        info = {"evaluations": fit.n_evaluations, "iterations": fit.n_iterations,
                "converged": fit.converged, "initial_loss": float(fit.initial_loss),
                "bins": opts.fit_bins, "gamma": float(geometry.gamma)}
        weights, loss, how = np.asarray(fit.weights, dtype=np.float64), float(fit.loss), \
            "uniform"
        if vertices[best] < loss and n_styles > 1:
            if ahead is not None:
                refit = ahead.result()
                held.replay(callback)
            else:
                refit = refit_from_best(callback)
            info["uniform_start_loss"] = loss
            info["evaluations"] += refit.n_evaluations
            if refit.loss < vertices[best]:
                weights, loss, how = np.asarray(refit.weights, dtype=np.float64), \
                    float(refit.loss), "vertex-refit"
                info["converged"] = refit.converged
            else:
                weights, loss, how = np.eye(n_styles)[best], float(vertices[best]), "vertex"
    finally:
        held.cancelled.set()  # a refit not needed (or not waited for) stops at its next step
    info["start"] = how
    return FitSummary(weights, loss, vertices, how, info, time.perf_counter() - start)


def photo_histograms(path: str | os.PathLike, bins: tuple[int, ...],
                     max_pixels: int, input_space: str | None = None,
                     working_space: str | None = None) -> dict[int, np.ndarray]:
    """Histograms of a photo file at several grid sizes -> {bins: (b, b, b)}.

    The colours are those of the working space (``None``: sRGB-encoded
    Rec.709); ``input_space`` None: what the file says.
    """
    image = read_image(path)
    spaces = plan_spaces(image, input_space, working_space)
    encoded, _ = to_working(image.rgb(), spaces, image.is_float)
    return {b: image_histogram(encoded, b, image.alpha(), max_pixels) for b in bins}


class PaletteSum:
    """Running sum of normalised histograms whose result does not depend on their order.

    Each histogram is rounded to fixed point (2^-40 of its mass) and summed in
    int64, so photos may arrive in any order (process pool, Dask) and the
    pooled palette, hence the series grade, is bit-for-bit the same.
    """

    _ONE = float(2 ** 40)

    def __init__(self) -> None:
        self.total: np.ndarray | None = None
        self.count = 0

    def add(self, hist: np.ndarray) -> None:
        """Add an (n, n, n) histogram (normalised here: every photo counts once)."""
        fixed = np.rint(np.asarray(hist, dtype=np.float64) / hist.sum() * self._ONE)
        fixed = fixed.astype(np.int64)
        self.total = fixed if self.total is None else self.total + fixed
        self.count += 1

    def result(self) -> np.ndarray:
        """The pooled (n, n, n) histogram, summing to 1."""
        if self.total is None:
            raise ValueError("no histograms to pool")
        return self.total / self.total.sum()


def pooled_histogram(histograms: list[np.ndarray]) -> np.ndarray:
    """The palette of a series: the sum of the photos' (normalised) histograms, normalised.

    Every photo counts once whatever its size. (n, n, n) list -> (n, n, n).
    """
    pool = PaletteSum()
    for hist in histograms:
        pool.add(hist)
    return pool.result()


def series_grade(pooled_fit: np.ndarray, pooled: np.ndarray, styles: StyleSet,
                 opts: GradeOptions, callback: FitCallback | None = None,
                 stage: Callable[[str], None] | None = None) -> tuple[Grade, FitSummary]:
    """One grade for a whole series: one fit on the pooled palette, one colour map.

    Parameters
    ----------
    pooled_fit : (m, m, m) pooled histogram on the fit grid (m = opts.fit_bins).
    pooled : (n, n, n) pooled histogram on the transfer grid (n = opts.bins).

    Costs one fit, one barycenter and one Sinkhorn, whatever the number of photos.
    """
    opts.validate(len(styles.names))
    say = stage or (lambda name: None)
    timings: dict[str, float] = {}
    say("fit")
    summary = fit_with_vertex_check(pooled_fit, styles.at_bins(opts.fit_bins), opts, callback)
    timings["fit"] = summary.time_s
    say("barycenter")
    start = time.perf_counter()
    target, palette_info = palette_barycenter(styles, summary.weights, opts)
    timings["barycenter"] = time.perf_counter() - start
    say("transfer")
    start = time.perf_counter()
    color_map, map_info = grade_color_map(pooled, target, opts)
    timings["transfer"] = time.perf_counter() - start
    info = {"fit": summary.info, "palette": palette_info, **map_info}
    grade = Grade(names=list(styles.names), weights=summary.weights, loss=summary.loss,
                  color_map=color_map, strength=opts.strength, timings=timings, info=info,
                  barycenter=target, regrain=regrain_settings(opts))
    return grade, summary


@dataclass
class PhotoGrade:
    """A graded photo in memory.

    Attributes
    ----------
    image : the decoded input.
    pixels : (H, W, C') float32 graded pixels (the image's value convention).
    alpha_channel : index of alpha in ``pixels`` or -1.
    grade : the grade applied (weights, colour map, barycenter).
    fit : weights and single-style comparison (None for a shared series grade
        whose summary the caller holds).
    timings : seconds per stage.
    spaces : the photo's input and working colour spaces.
    """

    image: Image
    pixels: np.ndarray
    alpha_channel: int
    grade: Grade
    fit: FitSummary | None
    timings: dict[str, float] = field(default_factory=dict)
    spaces: Spaces | None = None


def fit_grade(encoded: np.ndarray, styles: StyleSet, opts: GradeOptions,
              alpha: np.ndarray | None = None, callback: FitCallback | None = None,
              stage: Callable[[str], None] | None = None) -> tuple[Grade, FitSummary]:
    """The grade of encoded pixels: vertex-checked weights, palette and colour map.

    The one per-photo pipeline (``apply``, ``batch`` without ``--consistent``,
    :func:`grade_array`): fit never worse than the best single style, then the
    palette and the smooth colour map of :func:`wbcgrade.color.transfer.grade_image`
    with those weights.

    Parameters
    ----------
    encoded : (H, W, 3) float32 encoded colours in [0, 1].
    alpha : (H, W) optional; pixels with alpha 0 do not count.

    Returns
    -------
    (grade, fit summary); ``grade.timings`` holds the stages.
    """
    say = stage or (lambda name: None)
    opts.validate(len(styles.names))
    if opts.mode == "look" and opts.weights is None:
        return _look_grade(encoded, styles, opts, alpha, say)
    say("fit")
    photo_fit = image_histogram(encoded, opts.fit_bins, alpha, opts.max_pixels)
    summary = fit_with_vertex_check(photo_fit, styles.at_bins(opts.fit_bins), opts, callback)
    fixed = replace(opts, weights=[float(w) for w in summary.weights])
    grade = grade_image(encoded, styles, fixed, alpha, None, stage)
    grade.loss = summary.loss
    grade.info["fit"] = summary.info
    grade.timings = {"fit": summary.time_s,
                     **{k: v for k, v in grade.timings.items() if k != "fit"}}
    return grade, summary


def _look_grade(encoded: np.ndarray, styles: StyleSet, opts: GradeOptions,
                alpha: np.ndarray | None, say: Callable[[str], None]) -> tuple[Grade, FitSummary]:
    """The grade of ``mode="look"``: the set's look, corrected towards the photo's scene.

    The colour map is the set's look (:func:`wbcgrade.color.look.look_color_map`)
    moved towards the palette grade of the photo (KL fit, relaxed transport)
    by how sure it is that a style shows the photo's own scene.
    """
    from wbcgrade.color.look import (
        MAP_BINS,
        SCENE_LOSS,
        SCENE_RELAXATION,
        look_color_map,
        natural_palettes,
    )
    from wbcgrade.color.presets import load_preset
    from wbcgrade.color.remap import keep_lightness, monotone_lightness

    timings: dict[str, float] = {}
    start = time.perf_counter()
    say("histograms")
    photo_hist = image_histogram(encoded, MAP_BINS, alpha, opts.max_pixels)
    timings["histograms"] = time.perf_counter() - start
    say("look")
    start = time.perf_counter()
    naturals = load_preset(opts.natural) if opts.natural else natural_palettes()
    naturals = styles_in_space(naturals, styles.working_space)
    base, photo, info = look_color_map(photo_hist, styles, naturals)
    timings["look"] = time.perf_counter() - start
    n_styles = len(styles.names)
    confidence = photo.confidence
    weights = np.full(n_styles, 1.0 / n_styles)
    color_map = base.lattice(opts.map_size)
    fit_info: dict = {"start": "look", "match": info["look"]["match"],
                      "confidence": confidence}
    if confidence > 0:
        scene_opts = replace(opts, mode="palette", loss=SCENE_LOSS,
                             relaxation=opts.relaxation or SCENE_RELAXATION)
        scene, summary = fit_grade(encoded, styles, scene_opts, alpha, None,
                                   lambda name: say(f"scene {name}"))
        for name, seconds in scene.timings.items():
            timings[f"scene {name}"] = seconds
        base_map = base.lattice(scene.color_map.shape[0])
        color_map = (base_map + confidence * (scene.color_map - base_map)).astype(np.float32)
        weights = confidence * np.asarray(summary.weights) + (1.0 - confidence) * weights
        fit_info["scene_fit"] = {**summary.info, "weights": [float(w) for w in summary.weights],
                                 "loss": summary.loss}
        info.update({k: v for k, v in scene.info.items() if k != "fit"})
    if opts.monotone and not opts.preserve_luminance:
        color_map = monotone_lightness(color_map)
    if opts.preserve_luminance:
        color_map = keep_lightness(color_map)
    info["map"] = {"size": int(color_map.shape[0]), "monotone": opts.monotone,
                   "preserve_luminance": opts.preserve_luminance}
    info["fit"] = fit_info
    grade = Grade(names=list(styles.names), weights=weights, loss=None,
                  color_map=color_map, strength=opts.strength, timings=timings, info=info,
                  barycenter=None, regrain=regrain_settings(opts))
    summary = FitSummary(weights, float(photo.residuals[photo.match]), photo.residuals,
                         "look", fit_info, sum(timings.values()))
    return grade, summary


def grade_array(rgb: np.ndarray, styles: StyleSet, opts: GradeOptions | None = None,
                alpha: np.ndarray | None = None) -> tuple[np.ndarray, Grade]:
    """Grade an image held in memory: arrays in, arrays out (no files).

    Parameters
    ----------
    rgb : (H, W, 3) encoded (e.g. sRGB) colours in [0, 1], any float or
        integer dtype (integers are scaled by their maximum value); in
        ``opts.input_space`` when given (default sRGB), graded in
        ``opts.working_space`` (default sRGB-encoded Rec.709) and returned
        in the input space.
    styles : the style palettes (:func:`wbcgrade.color.presets.load_preset`,
        :func:`~wbcgrade.color.presets.load_style_folder`).
    opts : grade settings (default :class:`GradeOptions`).
    alpha : (H, W) optional coverage; transparent pixels do not count.

    Returns
    -------
    graded : (H, W, 3) float32 in [0, 1] (colour map and regrain applied;
        colour-managed: in the input space, out-of-gamut values not clipped)
    grade : the weights, colour map and diagnostics (``grade.apply`` grades
        more pixels the same way; ``grade.color_map`` is the LUT).
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or min(rgb.shape[:2]) < 1:
        raise InputError(f"rgb must be an (H, W, 3) image, got shape {rgb.shape}")
    if np.issubdtype(rgb.dtype, np.integer):
        rgb = rgb / np.float32(np.iinfo(rgb.dtype).max)
    if not np.all(np.isfinite(rgb)):
        raise InputError("rgb contains NaN or inf")
    opts = opts or GradeOptions()
    spaces = spaces_for(opts.input_space, opts.working_space, is_float=False)
    encoded, state = to_working(np.asarray(rgb, dtype=np.float32), spaces, False)
    if alpha is not None:
        alpha = np.asarray(alpha, dtype=np.float32)
        if alpha.shape != encoded.shape[:2]:
            raise InputError(f"alpha must have shape {encoded.shape[:2]}, got {alpha.shape}")
    styles = styles_in_space(styles, spaces.working)
    grade, _ = fit_grade(encoded, styles, opts, alpha)
    graded = grade.apply(encoded)
    return (graded if spaces.legacy else state.decode(graded)), grade


def grade_photo(path: str | os.PathLike, styles: StyleSet, opts: GradeOptions,
                shared: Grade | None = None, callback: FitCallback | None = None,
                stage: Callable[[str], None] | None = None) -> PhotoGrade:
    """Read and grade one photo (nothing is written).

    With ``shared`` (a series grade), its colour map is applied as is;
    otherwise the photo gets its own vertex-checked fit and colour map
    (:func:`fit_grade`).
    """
    say = stage or (lambda name: None)
    timings: dict[str, float] = {}
    say("read")
    start = time.perf_counter()
    image = read_image(Path(path))
    spaces = plan_spaces(image, opts.input_space, opts.working_space)
    encoded, scale = to_working(image.rgb(), spaces, image.is_float)
    timings["read"] = time.perf_counter() - start
    summary = None
    if shared is not None:
        grade = shared
    else:
        styles = styles_in_space(styles, spaces.working)
        grade, summary = fit_grade(encoded, styles, opts, image.alpha(), callback, stage)
        timings.update(grade.timings)
    say("remap")
    start = time.perf_counter()
    pixels, alpha_channel = render(image, grade, (encoded, scale))
    timings["remap"] = time.perf_counter() - start
    return PhotoGrade(image, pixels, alpha_channel, grade, summary, timings, spaces)
