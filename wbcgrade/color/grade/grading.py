"""The grade path: fit the weights, build the colour map, a frozen :class:`Grade`.

One path for every caller (``apply``, ``batch``, ``video``, :func:`grade_array`):

1. the photo's histograms (:func:`photo_histograms`), on the fit grid and
   the transfer grid, of colours in the working space's unit cube;
2. the colour map, built by the *map builder* that ``options.map.builder``
   names (:data:`MAP_BUILDERS`):

   - "palette" (:func:`palette_map`): the weights
     (:func:`wbcgrade.color.palette.fit.fit_weights`: barycentric coordinates never
     worse than the best single style), then the fitted palette, Sinkhorn
     and the smooth map (:func:`wbcgrade.color.palette.transfer.transport_map`);
   - "look" (:func:`wbcgrade.color.grade.look_builder.look_map`): the look the style
     set shares (:mod:`wbcgrade.color.look`), moved towards the palette grade of the
     photo by how sure it is that a style shows the photo's own scene;

3. the map finished in the working space's own terms (monotone in its
   luma, or keeping each colour's Oklab lightness; :func:`finish_map`);
4. a frozen :class:`Grade`: ``grade.apply(encoded)`` grades pixels (colour
   map and regrain), ``grade.lut(size, encoding)`` is the grade as a LUT
   table in any encoding of its working space.

A series (a batch's ``consistent`` grade, a video shot) takes the same path with a
pooled histogram (:class:`wbcgrade.color.histogram.PaletteSum`).

Other ways of building the map plug in with :func:`register_map_builder`:
a builder (:mod:`wbcgrade.color.grade.builders`) takes a :class:`MapRequest` (the
photo's histograms, the styles in the working space, the options, the
encoding, progress callbacks, the grade path itself for a palette grade) and
returns a :class:`BuiltMap` (the map before finishing, the palette it aimed
at, diagnostics, timings, and the weights with how sure it is of them).

>>> import numpy as np
>>> from wbcgrade.color.grade.grading import grade_array
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
from dataclasses import dataclass, field, replace

import numpy as np

from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.builders import (
    BuiltMap,
    FitCallback,
    LookFound,
    MapRequest,
    PhotoHistograms,
    palette_map,
    quiet,
)
from wbcgrade.color.grade.look_builder import look_map
from wbcgrade.color.histogram import Deferred, image_histogram
from wbcgrade.color.look.set_extraction import FIT_BINS as LOOK_FIT_BINS
from wbcgrade.color.mapping.lut import check_lut_size, color_map_to_lut
from wbcgrade.color.mapping.regrain import regrain_map
from wbcgrade.color.mapping.remap import (
    apply_color_map,
    identity_map,
    keep_lightness,
    monochrome_toning,
    monotone_lightness,
    to_monochrome,
)
from wbcgrade.color.options import GradeOptions, as_options
from wbcgrade.color.outcome import (
    FAINT_STRENGTH,
    OWN_PHOTO_KEYS,
    UNCHANGED_STRENGTH,
    FitStart,
    GradeOutcome,
    GradeSource,
    PaletteFit,
    SavedFrom,
    TransportCheck,
    map_change,
)
from wbcgrade.color.palette.fit import FitSummary
from wbcgrade.color.presets import StyleSet, own_style, styles_in_space
from wbcgrade.errors import InputError, OptionError

__all__ = ["Grade", "PhotoHistograms", "MapRequest", "BuiltMap", "MAP_BUILDERS",
           "register_map_builder", "palette_map", "look_map", "photo_histograms", "style_grids",
           "finish_map",
           "grade_histograms", "grade_outcome", "outcome_on_photo", "strengthened",
           "grade_encoded", "grade_array"]






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
    outcome : what the grade did, in plain terms (source, strength, size, the
        photo's change; :class:`wbcgrade.color.outcome.GradeOutcome`), or None.
    saved : the file a saved grade was read from (:class:`~wbcgrade.color.outcome.SavedFrom`),
        None for a grade made here.
    own_style : the style the photo itself is (graded towards itself), or None.
    transport : how the transfer's Sinkhorn solve ended
        (:class:`~wbcgrade.color.outcome.TransportCheck`), None when there was none.
    regrain_follow : in [0, 1], how far the regrain lets the input's grain follow the map
        where it lowers contrast or saturation (:func:`wbcgrade.color.mapping.regrain.regrain_map`'s
        ``follow``): 1 for a preset's own look, a scene's look by the match's confidence
        (:func:`regrain_follow`); 0, the grain as it is, for the others.
    source : where the map came from (:class:`~wbcgrade.color.outcome.GradeSource`), set
        once: by the map builder on the grade path, SAVED for a saved grade (one with
        ``saved``), else PALETTE (weights and a map made by hand).
    look : what a look builder found (:class:`~wbcgrade.color.grade.builders.LookFound`),
        or None.
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
    outcome: GradeOutcome | None = field(default=None, compare=False)
    saved: SavedFrom | None = field(default=None, compare=False)
    own_style: str | None = field(default=None, compare=False)
    transport: TransportCheck | None = field(default=None, compare=False)
    regrain_follow: float = 0.0
    source: GradeSource | None = field(default=None, compare=False)
    look: LookFound | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.source is None:
            object.__setattr__(self, "source", GradeSource.SAVED if self.saved is not None
                               else GradeSource.PALETTE)

    def apply(self, encoded: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Grade working-space colours in [0, 1] -> float32, same shape.

        An (H, W, 3) image also goes through the regrain step when the grade
        has one; other shapes (lists of colours) get the colour map only.
        ``out``: a C-contiguous float32 array of that shape to write the result
        into, which may be ``encoded`` itself (graded in place); returned.
        """
        if self.regrain is not None and encoded.ndim == 3 and min(encoded.shape[:2]) > 1:
            graded = regrain_map(encoded, self.color_map, self.strength, *self.regrain, out=out,
                                 follow=self.regrain_follow)
            if self.strength == 1.0:  # a black-and-white map stays so: no colour regrained
                toning = monochrome_toning(self.color_map)
                if toning is not None:
                    to_monochrome(graded, toning, out=graded)
            return graded
        graded = apply_color_map(encoded, self.color_map, self.strength)
        if out is None:
            return graded
        out[...] = graded
        return out

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




def photo_histograms(encoded: np.ndarray, options: GradeOptions,
                     alpha: np.ndarray | None = None) -> PhotoHistograms:
    """The histograms of working-space colours (H, W, 3) in [0, 1]; pixels with alpha 0
    do not count; photos above ``transfer.max_pixels`` are subsampled. The transfer grid's
    is binned when first read (a look grade does not read it)."""
    limit = options.transfer.max_pixels
    bins = options.transfer.bins
    return PhotoHistograms(image_histogram(encoded, options.fit.bins, alpha, limit),
                           Deferred((bins,) * 3, image_histogram, encoded, bins, alpha, limit),
                           (encoded, alpha, limit))












def style_grids(options: GradeOptions) -> tuple[int, ...]:
    """The grids the grade path re-bins a style set onto (:meth:`StyleSet.at_bins`) besides
    the transfer grid: the fit's, and for a look the look's (the set's look is keyed by
    it), which a folder's histogram cache keeps
    (:func:`wbcgrade.color.presets.load_styles`)."""
    look = (LOOK_FIT_BINS,) if options.map.builder == "look" else ()
    return tuple(sorted({options.fit.bins, *look}))


#: Map builders by name (``map.builder``): MapRequest -> BuiltMap.
MAP_BUILDERS: dict[str, Callable[[MapRequest], BuiltMap]] = {"palette": palette_map,
                                                              "look": look_map}


def register_map_builder(name: str, builder: Callable[[MapRequest], BuiltMap]) -> None:
    """Make ``builder`` the map builder that ``MapOptions(builder=name)`` selects."""
    if not isinstance(name, str) or not name:
        raise ValueError("a map builder needs a name")
    MAP_BUILDERS[name] = builder


def finish_map(color_map: np.ndarray, options: GradeOptions,
               encoding: ColorEncoding) -> np.ndarray:
    """The finishing steps of every map, in the working space's own terms.

    ``map.preserve_luminance``: each colour keeps its Oklab lightness
    (:func:`wbcgrade.color.mapping.remap.keep_lightness`, through the encoding);
    otherwise ``map.monotone``: the map's luma, with the working encoding's
    luma weights, made non-decreasing in each channel
    (:func:`wbcgrade.color.mapping.remap.monotone_lightness`).
    """
    if options.map.preserve_luminance:
        return keep_lightness(color_map, encoding)
    if options.map.monotone:
        return monotone_lightness(color_map, encoding.luma_weights)
    return color_map


# ------------------------------------------------------------------------------ the path


def grade_histograms(photo: PhotoHistograms, styles: StyleSet, options: GradeOptions,
                     encoding: ColorEncoding, callback: FitCallback | None = None,
                     stage: Callable[[str], None] | None = None) -> tuple[Grade, FitSummary]:
    """The one grade path: the map builder (the fit inside), the finishing, a Grade.

    ``styles`` must be in ``encoding.working`` (:func:`styles_in_space`).
    ``callback`` receives a fit's progress ``(n_evaluations, weights, loss)``,
    ``stage`` each stage's name as it starts. Returns the grade and how its
    weights were found.
    """
    options.check_styles(len(styles.names))
    name = options.map.builder
    if name not in MAP_BUILDERS:
        raise OptionError(f"{{map.builder}} must be one of {', '.join(MAP_BUILDERS)}",
                          "map.builder")
    def palette_grade(other: GradeOptions, stage: Callable[[str], None]):
        return grade_histograms(photo, styles, other, encoding, None, stage)

    built = MAP_BUILDERS[name](MapRequest(photo, styles, options, encoding, callback,
                                          stage or quiet, palette_grade))
    start = time.perf_counter()
    finish = options
    if built.source is GradeSource.PRESET_LOOK and options.map.monotone:
        # a preset's look is applied as it was made (monotone in its own space already):
        # the lattice of its conversion into another space also covers colours outside
        # the preset's gamut, where a monotone pass would drag the look inside it
        finish = replace(options, map=replace(options.map, monotone=False))
    color_map = finish_map(built.color_map, finish, encoding)
    timings = {**built.timings, "finish": time.perf_counter() - start}
    info = {"fit": built.fit.info, **built.info}
    info["map"] = {**info.get("map", {}), "builder": name, "monotone": options.map.monotone,
                   "preserve_luminance": options.map.preserve_luminance}
    found = own_style(photo.fit, styles.at_bins(photo.fit.shape[0]), styles.names,
                      built.fit.weights)
    if found is not None:  # the photo is one of the styles (the CLI warns)
        info["own_style"] = found
    color_map, strength = strengthened(color_map, options.map.strength)
    grade = Grade(names=tuple(styles.names),
                  weights=np.asarray(built.fit.weights, dtype=np.float64),
                  color_map=np.asarray(color_map, dtype=np.float32), working=encoding.working,
                  strength=strength, regrain=options.regrain.settings,
                  loss=built.fit.loss, barycenter=built.palette, info=info, timings=timings,
                  own_style=found, transport=built.transport,
                  regrain_follow=regrain_follow(built.source, built.look),
                  source=built.source, look=built.look)
    outcome = grade_outcome(grade, built.fit, photo.fit, options.map.strength)
    return replace(grade, outcome=outcome), built.fit


def regrain_follow(source: GradeSource, look: LookFound | None = None) -> float:
    """How far a look grade's regrain lets the grain follow its map
    (:attr:`Grade.regrain_follow`): fully for a preset's own look, for the look read off
    the style photo of the photo's scene as far as the match is sure (the map is that much
    the scene's; the rest is the set's look); not at all for a set's look read from
    statistics, whose slopes are a guess (docs/benchmarks.md, regrain of a set's look)."""
    if source is GradeSource.PRESET_LOOK:
        return 1.0
    if source is GradeSource.OWN_SCENE and look is not None:
        return float(np.clip(look.confidence, 0.0, 1.0))
    return 0.0


def strengthened(color_map: np.ndarray, strength: float) -> tuple[np.ndarray, float]:
    """A map and the blend that apply it at ``strength``: up to 1 the map as it is and
    that blend; above 1 the map's displacement scaled by ``strength`` (clipped to the
    unit cube) and blend 1. (m, m, m, 3) -> same shape, float32."""
    if strength <= 1.0:
        return color_map, float(strength)
    nodes = identity_map(color_map.shape[0])
    return np.clip(nodes + strength * (color_map - nodes), 0.0, 1.0).astype(np.float32), 1.0


def outcome_on_photo(grade: Grade, photo_hist: np.ndarray) -> GradeOutcome:
    """The outcome of an existing grade (a series' shared grade, a saved one) on a photo
    whose (n, n, n) working-space histogram is ``photo_hist``."""
    change = map_change(grade.color_map, grade.strength, grade.working, photo_hist)
    if grade.outcome is not None:
        return grade.outcome.on_photo(change)
    return grade_outcome(grade, None, photo_hist)


def grade_outcome(grade: Grade, fit: FitSummary | None, photo_hist: np.ndarray | None,
                  blend: float | None = None) -> GradeOutcome:
    """What ``grade`` does to a photo whose histogram (any (n, n, n) grid of working-space
    colours) is ``photo_hist`` (None: judged on the whole colour cube).

    The source is the grade's own (:attr:`Grade.source`); a look's strength and match
    are what its builder found (:attr:`Grade.look`); a palette grade's weights and loss
    are ``fit``'s (None: the grade's own weights, given). ``blend``: the ``map.strength``
    asked for (default the grade's own blend; above 1 the map was scaled).
    """
    blend = float(grade.strength if blend is None else blend)
    n_styles = len(grade.names)
    look_size = map_change(grade.color_map, grade.strength, grade.working)
    mean_change = (look_size if photo_hist is None else
                   map_change(grade.color_map, grade.strength, grade.working, photo_hist))
    source = grade.source
    if source is GradeSource.SAVED:
        return GradeOutcome.judge(GradeSource.SAVED, n_styles, None, blend, look_size,
                                  mean_change,
                                  file=None if grade.saved is None else grade.saved.file,
                                  extra={"learned": grade.saved is not None
                                         and grade.saved.kind == "learned"})
    if source is GradeSource.PRESET_LOOK:
        return GradeOutcome.judge(GradeSource.PRESET_LOOK, n_styles, 1.0,
                                  blend, look_size, mean_change)
    if source in (GradeSource.OWN_SCENE, GradeSource.SET_LOOK):
        look = grade.look or LookFound()
        set_strength, confidence = look.set_strength, look.confidence
        strength = confidence + (1.0 - confidence) * set_strength
        why = None
        # the statistics look was shrunk by what content varies by: its size says how much
        shared = min(set_strength, look_size / 3.0) if look.shrunk else set_strength
        if shared < FAINT_STRENGTH and confidence <= 0:
            how = "no" if shared < UNCHANGED_STRENGTH else "little"
            why = (f"these {n_styles} style photos share {how} look that can be told apart "
                   "from their content" if n_styles > 1 else
                   f"the style photo shows {how} look that can be told apart from its content")
        return GradeOutcome.judge(source, n_styles, strength, blend,
                                  look_size, mean_change, why, match=look.match,
                                  confidence=confidence,
                                  extra={"set_strength": set_strength,
                                         **({"probability": look.probability}
                                            if look.probability is not None else {}),
                                         **dict(zip(OWN_PHOTO_KEYS, (look.own_photos,
                                                                     look.own_photos_unused)))})
    if fit is None:  # a grade's own weights, given
        fit = FitSummary(np.asarray(grade.weights), float(grade.loss or 0.0), np.zeros(0),
                         FitStart.GIVEN.value)
    start = fit.fit_start
    order = np.argsort(-np.asarray(fit.weights), kind="stable")
    best = fit.best_vertex if len(fit.vertex_losses) else None
    palette = PaletteFit(tuple(grade.names[i] for i in order),
                         tuple(float(fit.weights[i]) for i in order), float(fit.loss),
                         None if best is None or start == FitStart.GIVEN
                         else (grade.names[best], float(fit.vertex_losses[best])),
                         start, fit.evaluations, fit.converged)
    return GradeOutcome.judge(GradeSource.PALETTE, n_styles, 1.0, blend,
                              look_size, mean_change, palette=palette)


def grade_encoded(encoded: np.ndarray, styles: StyleSet, options: GradeOptions,
                  encoding: ColorEncoding, alpha: np.ndarray | None = None,
                  callback: FitCallback | None = None,
                  stage: Callable[[str], None] | None = None) -> tuple[Grade, FitSummary]:
    """:func:`grade_histograms` of working-space pixels (H, W, 3); the styles are converted
    into the working space when they are in another."""
    styles = styles_in_space(styles, encoding.working)
    return grade_histograms(photo_histograms(encoded, options, alpha), styles, options,
                            encoding, callback, stage)


def grade_array(rgb: np.ndarray, styles: StyleSet | Grade, options: GradeOptions | None = None,
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
        :func:`~wbcgrade.color.presets.load_style_folder`), or a :class:`Grade`
        (a saved one, :func:`wbcgrade.color.grade.saved_grade.load_look`) applied as it
        is in its own working space, nothing fitted.
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
    saved = isinstance(styles, Grade)
    working = (styles.working or None) if saved else options.spaces.working
    encoding = ColorEncoding.of(options.spaces.input, working)
    encoded, state = encoding.encode(np.asarray(rgb, dtype=np.float32))
    if alpha is not None:
        alpha = np.asarray(alpha, dtype=np.float32)
        if alpha.shape != encoded.shape[:2]:
            raise InputError(f"alpha must have shape {encoded.shape[:2]}, got {alpha.shape}")
    if saved:  # what the given grade does to this photo
        hist = image_histogram(encoded, 16, alpha, options.transfer.max_pixels)
        grade = replace(styles, outcome=outcome_on_photo(styles, hist))
    else:
        grade, _ = grade_encoded(encoded, styles, options, encoding, alpha)
    return encoding.decode(grade.apply(encoded), state), grade
