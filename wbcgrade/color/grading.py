"""The grade path: fit the weights, build the colour map, a frozen :class:`Grade`.

One path for every caller (``apply``, ``batch``, ``video``, :func:`grade_array`):

1. the photo's histograms (:func:`photo_histograms`), on the fit grid and
   the transfer grid, of colours in the working space's unit cube;
2. the weights (:func:`wbcgrade.color.fit.fit_weights`): barycentric
   coordinates never worse than the best single style;
3. the colour map, built by the *map builder* that ``options.map.builder``
   names (:data:`MAP_BUILDERS`; "transport": the fitted palette, Sinkhorn,
   the smooth map, :func:`wbcgrade.color.transfer.transport_map`), then
   finished in the working space's own terms (monotone in its luma, or
   keeping each colour's Oklab lightness; :func:`finish_map`);
4. a frozen :class:`Grade`: ``grade.apply(encoded)`` grades pixels (colour
   map and regrain), ``grade.lut(size, encoding)`` is the grade as a LUT
   table in any encoding of its working space.

A series (``batch --consistent``, a video shot) takes the same path with a
pooled histogram (:class:`wbcgrade.color.histogram.PaletteSum`).

Other ways of building the map plug in with :func:`register_map_builder`:
a builder takes a :class:`MapRequest` (the photo's transfer histogram, the
styles in the working space, the fit, the options, the encoding, a stage
callback) and returns ``(color_map, palette, info, timings)``.

>>> import numpy as np
>>> from wbcgrade.color.grading import grade_array
>>> from wbcgrade.color.options import GradeOptions
>>> from wbcgrade.color.presets import load_preset, resolve_preset
>>> styles = load_preset(resolve_preset("warm"))
>>> rgb = np.random.default_rng(0).random((24, 32, 3))
>>> graded, grade = grade_array(rgb, styles, GradeOptions(bins=16, fit_bins=8, map_size=9,
...                                                       n_iter=20, max_iter=5))
>>> graded.shape, grade.color_map.shape, round(float(grade.weights.sum()), 6)
((24, 32, 3), (9, 9, 9, 3), 1.0)
>>> grade.lut(5).shape                            # the grade as a 5^3 LUT
(5, 5, 5, 3)
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.fit import FitSummary, fit_weights
from wbcgrade.color.histogram import image_histogram
from wbcgrade.color.lut import check_lut_size, color_map_to_lut
from wbcgrade.color.options import GradeOptions, as_options
from wbcgrade.color.presets import StyleSet, styles_in_space
from wbcgrade.color.regrain import regrain_map
from wbcgrade.color.remap import apply_color_map, identity_map, keep_lightness, monotone_lightness
from wbcgrade.color.transfer import transport_map
from wbcgrade.errors import InputError, OptionError

__all__ = ["Grade", "PhotoHistograms", "MapRequest", "BuiltMap", "MAP_BUILDERS",
           "register_map_builder", "photo_histograms", "build_grade", "finish_map",
           "grade_histograms", "grade_encoded", "grade_array"]

FitCallback = Callable[[int, np.ndarray, float], None]


def _quiet(name: str) -> None:
    """A stage callback that says nothing."""


@dataclass(frozen=True)
class Grade:
    """A fitted grade: weights and the colour map that is the grade.

    Attributes
    ----------
    names : S style names.
    weights : (S,) barycentric weights.
    color_map : (m, m, m, 3) float32, new working-space colour of each node of
        the grade's lattice LUT (strength not applied).
    working : the working space the map lives in (config name).
    strength : the blend applied by :meth:`apply` and :meth:`lut`.
    regrain : (radius, eps) of the regrain step applied to images, or None.
    loss : fit loss at the weights.
    barycenter : (n, n, n) the target palette on the transfer grid, or None.
    info : fit, palette, Sinkhorn and map diagnostics (JSON-friendly).
    timings : seconds per stage.
    """

    names: tuple[str, ...]
    weights: np.ndarray
    color_map: np.ndarray
    working: str = ""
    strength: float = 1.0
    regrain: tuple[float, float] | None = None
    loss: float | None = None
    barycenter: np.ndarray | None = None
    info: Mapping = field(default_factory=dict)
    timings: Mapping = field(default_factory=dict)

    def apply(self, encoded: np.ndarray) -> np.ndarray:
        """Grade working-space colours in [0, 1] -> float32, same shape.

        An (H, W, 3) image also goes through the regrain step when the grade
        has one; other shapes (lists of colours) get the colour map only.
        """
        if self.regrain is not None and encoded.ndim == 3 and min(encoded.shape[:2]) > 1:
            return regrain_map(encoded, self.color_map, self.strength, *self.regrain)
        return apply_color_map(encoded, self.color_map, self.strength)

    def lut(self, size: int = 33, encoding: ColorEncoding | None = None) -> np.ndarray:
        """The grade as a (size, size, size, 3) LUT table indexed [r, g, b], in [0, 1].

        ``encoding`` None (or one whose pixels are working-space colours): the
        map itself sampled at the lattice (trilinear, ``strength`` blended).
        Otherwise the lattice holds ``encoding``'s input code values: point x
        -> working space -> the map -> back to the input space, the table
        holding ``x + (back(graded) - back(working))`` (an identity grade
        gives exactly the identity), clipped to [0, 1].
        """
        if encoding is not None and self.working and encoding.working != self.working:
            raise InputError(f"the grade lives in {self.working}, not {encoding.working}")
        if encoding is None or encoding.input == encoding.working:
            return color_map_to_lut(self.color_map, size, self.strength)
        nodes = identity_map(check_lut_size(size))
        working, state = encoding.encode(nodes)
        graded = apply_color_map(working, self.color_map, self.strength)
        moved = encoding.decode(graded, state) - encoding.decode(working, state)
        return np.clip(nodes + moved, 0.0, 1.0)

    def ranked(self) -> list[tuple[str, float]]:
        """(name, weight) sorted by decreasing weight."""
        order = np.argsort(-self.weights, kind="stable")
        return [(self.names[i], float(self.weights[i])) for i in order]


# ------------------------------------------------------------------------------ builders


@dataclass(frozen=True)
class MapRequest:
    """What a map builder gets.

    Attributes
    ----------
    photo : (n, n, n) the photo's (or series') histogram on the transfer grid.
    styles : the style set, in the working space.
    fit : the fitted weights and how sure the fit is (loss, vertex losses).
    options : every setting of the grade.
    encoding : the colour encoding (working space) of the grade.
    stage : ``stage(name)`` as each stage starts (progress).
    """

    photo: np.ndarray
    styles: StyleSet
    fit: FitSummary
    options: GradeOptions
    encoding: ColorEncoding
    stage: Callable[[str], None] = _quiet


class BuiltMap(NamedTuple):
    """What a map builder returns: the map (before finishing), the palette it aimed
    at (or None), diagnostics and seconds per stage."""

    color_map: np.ndarray
    palette: np.ndarray | None
    info: dict
    timings: dict


#: Map builders by name (``map.builder``): MapRequest -> BuiltMap (or the same 4-tuple).
MAP_BUILDERS: dict[str, Callable[[MapRequest], tuple]] = {"transport": transport_map}


def register_map_builder(name: str, builder: Callable[[MapRequest], tuple]) -> None:
    """Make ``builder`` the map builder that ``MapOptions(builder=name)`` selects."""
    if not isinstance(name, str) or not name:
        raise ValueError("a map builder needs a name")
    MAP_BUILDERS[name] = builder


def finish_map(color_map: np.ndarray, options: GradeOptions,
               encoding: ColorEncoding) -> np.ndarray:
    """The finishing steps of every map, in the working space's own terms.

    ``map.preserve_luminance``: each colour keeps its Oklab lightness
    (:func:`wbcgrade.color.remap.keep_lightness`, through the encoding);
    otherwise ``map.monotone``: the map's luma, with the working encoding's
    luma weights, made non-decreasing in each channel
    (:func:`wbcgrade.color.remap.monotone_lightness`).
    """
    if options.map.preserve_luminance:
        return keep_lightness(color_map, encoding)
    if options.map.monotone:
        return monotone_lightness(color_map, encoding.luma_weights)
    return color_map


def build_grade(photo: np.ndarray, styles: StyleSet, fit: FitSummary, options: GradeOptions,
                encoding: ColorEncoding,
                stage: Callable[[str], None] | None = None) -> Grade:
    """The colour map of fitted weights, finished, as a :class:`Grade`.

    Parameters
    ----------
    photo : (n, n, n) histogram on the transfer grid (n = options.transfer.bins).
    styles : the styles, in ``encoding.working``.
    fit : the weights (:func:`wbcgrade.color.fit.fit_weights`).
    """
    name = options.map.builder
    if name not in MAP_BUILDERS:
        raise OptionError(f"map.builder must be one of {', '.join(MAP_BUILDERS)}",
                          "map.builder")
    request = MapRequest(photo, styles, fit, options, encoding, stage or _quiet)
    color_map, palette, info, timings = MAP_BUILDERS[name](request)
    start = time.perf_counter()
    color_map = finish_map(color_map, options, encoding)
    timings = dict(timings)
    timings["finish"] = time.perf_counter() - start
    info = {"fit": fit.info, **info}
    info.setdefault("map", {})
    info["map"] = {**info["map"], "builder": name, "monotone": options.map.monotone,
                   "preserve_luminance": options.map.preserve_luminance}
    return Grade(names=tuple(styles.names), weights=np.asarray(fit.weights, dtype=np.float64),
                 color_map=np.asarray(color_map, dtype=np.float32), working=encoding.working,
                 strength=options.map.strength, regrain=options.regrain.settings,
                 loss=fit.loss, barycenter=palette, info=info,
                 timings={"fit": fit.time_s, **timings})


# ------------------------------------------------------------------------------ the path


@dataclass(frozen=True)
class PhotoHistograms:
    """A photo's (or a series') histograms: ``fit`` on the fit grid, ``transfer`` on the
    transfer grid, both of working-space colours."""

    fit: np.ndarray
    transfer: np.ndarray


def photo_histograms(encoded: np.ndarray, options: GradeOptions,
                     alpha: np.ndarray | None = None) -> PhotoHistograms:
    """The histograms of working-space colours (H, W, 3) in [0, 1]; pixels with alpha 0
    do not count; photos above ``transfer.max_pixels`` are subsampled."""
    limit = options.transfer.max_pixels
    return PhotoHistograms(image_histogram(encoded, options.fit.bins, alpha, limit),
                           image_histogram(encoded, options.transfer.bins, alpha, limit))


def grade_histograms(photo: PhotoHistograms, styles: StyleSet, options: GradeOptions,
                     encoding: ColorEncoding, callback: FitCallback | None = None,
                     stage: Callable[[str], None] | None = None) -> tuple[Grade, FitSummary]:
    """The one grade path: fit the weights (vertex check inside), build the grade.

    ``styles`` must be in ``encoding.working`` (:func:`styles_in_space`).
    ``callback`` receives the fit's progress ``(n_evaluations, weights, loss)``,
    ``stage`` each stage's name as it starts. Returns the grade and the fit.
    """
    options.check_styles(len(styles.names))
    say = stage or _quiet
    say("fit")
    fit = fit_weights(photo.fit, styles.at_bins(options.fit.bins), options.fit, callback)
    return build_grade(photo.transfer, styles, fit, options, encoding, say), fit


def grade_encoded(encoded: np.ndarray, styles: StyleSet, options: GradeOptions,
                  encoding: ColorEncoding, alpha: np.ndarray | None = None,
                  callback: FitCallback | None = None,
                  stage: Callable[[str], None] | None = None) -> tuple[Grade, FitSummary]:
    """:func:`grade_histograms` of working-space pixels (H, W, 3); the styles are converted
    into the working space when they are in another."""
    styles = styles_in_space(styles, encoding.working)
    return grade_histograms(photo_histograms(encoded, options, alpha), styles, options,
                            encoding, callback, stage)


def grade_array(rgb: np.ndarray, styles: StyleSet, options: GradeOptions | None = None,
                alpha: np.ndarray | None = None, **flat) -> tuple[np.ndarray, Grade]:
    """Grade an image held in memory: arrays in, arrays out (no files).

    Parameters
    ----------
    rgb : (H, W, 3) display-encoded (e.g. sRGB) colours in [0, 1], any float
        or integer dtype (integers are scaled by their maximum value), in
        ``options.spaces.input`` (default sRGB); graded in
        ``options.spaces.working`` (default sRGB-encoded Rec.709) and returned
        in the input space.
    styles : the style palettes (:func:`wbcgrade.color.presets.load_preset`,
        :func:`~wbcgrade.color.presets.load_style_folder`).
    options : grade settings (default :class:`GradeOptions`); ``flat``
        keywords (the former flat names, e.g. ``relaxation=0.05``) change it.
    alpha : (H, W) optional coverage; transparent pixels do not count.

    Returns
    -------
    graded : (H, W, 3) float32 (colour map and regrain applied; in the input
        space, values outside the working cube carried through unclipped)
    grade : the weights, colour map and diagnostics (``grade.apply`` grades
        more working-space pixels the same way; ``grade.lut(size)`` is the LUT).
    """
    options = as_options(options, **flat)
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or min(rgb.shape[:2]) < 1:
        raise InputError(f"rgb must be an (H, W, 3) image, got shape {rgb.shape}")
    if np.issubdtype(rgb.dtype, np.integer):
        rgb = rgb / np.float32(np.iinfo(rgb.dtype).max)
    if not np.all(np.isfinite(rgb)):
        raise InputError("rgb contains NaN or inf")
    encoding = ColorEncoding.of(options.spaces.input, options.spaces.working)
    encoded, state = encoding.encode(np.asarray(rgb, dtype=np.float32))
    if alpha is not None:
        alpha = np.asarray(alpha, dtype=np.float32)
        if alpha.shape != encoded.shape[:2]:
            raise InputError(f"alpha must have shape {encoded.shape[:2]}, got {alpha.shape}")
    grade, _ = grade_encoded(encoded, styles, options, encoding, alpha)
    return encoding.decode(grade.apply(encoded), state), grade
