"""The look of a set: the global colour map a set of graded photos share, apart from their content.

A folder of style photos is usually one look ``T`` applied to various scenes.
Each style palette is modelled as ``s_m ~ T # P_N(w_m)``: a Wasserstein
barycenter of *natural* (ungraded) palettes ``n_1..n_K`` pushed through one
low-complexity map ``T``. Starting from ``T = identity``, :func:`extract_look`
alternates

1. coordinates: ``w_m`` minimising ``KL(P(T # n; w_m), s_m)`` (the core's
   barycentric coordinates against the pushed natural palettes);
2. correspondences: the content ``c_m = P_N(w_m)``, pushed through ``T``,
   transported to ``s_m`` with both marginals relaxed (unbalanced Sinkhorn:
   colours either side lacks are left out, not forced), the plan's
   barycentric projection read at ``T(x)`` for every content colour ``x``;
3. the map: ``T`` refitted to all styles' correspondences at once, weighted
   by the mass each moved (:func:`fit_look_map`).

Content differs from style to style and averages out in the pool; what the
styles share is the look.

What a grade uses of it: :func:`set_look` (by summary statistics by default,
or the transport iteration above; cached on disk), its reliability from two
halves of the set (:func:`set_look_halves`, :func:`look_reliability`), the
look at that strength (:func:`set_look_base`), as a LUT (:func:`set_look_map`),
and the natural palettes that model content (:func:`natural_palettes`,
:func:`load_naturals`) with their statistics.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wbcgrade.color.colorspace import default_working_space
from wbcgrade.color.histogram import (
    HistogramCache,
    add_floor,
    deferred_shape,
    grid_points,
    resample_histogram,
)
from wbcgrade.color.io.cache import cache_folder, entry_path, read_entry, write_entry
from wbcgrade.color.look import prior
from wbcgrade.color.look import statistics as stats
from wbcgrade.color.look.family import (
    DEFAULT_KNOTS,
    DEFAULT_SMOOTHNESS,
    DEFAULT_WIDTH,
    LookMap,
    fit_geometry,
    fit_look_map,
    look_coordinates,
    look_correspondences,
    push_histogram,
)
from wbcgrade.color.look.prior import posterior_statistics_look
from wbcgrade.color.look.statistics import (
    MONOCHROME_SPREAD,
    QUANTILES,
    PaletteStatistics,
    holds_colour,
    palette_statistics,
    statistics_look,
    tinted_statistics,
)
from wbcgrade.color.mapping.remap import monochrome_map, resample_lattice
from wbcgrade.color.presets import (
    SHIPPED_NATURALS,
    StyleSet,
    load_preset,
    load_style_folder,
    styles_in_space,
)
from wbcgrade.core import barycenter

__all__ = ["LookResult", "LookInfo", "extract_look", "set_look", "set_look_base", "set_look_halves",
           "look_reliability", "set_look_map", "natural_palettes", "load_naturals",
           "statistics_set_look"]

#: Relaxation and pull towards the identity of a SET's look (:func:`extract_look`).
#: A relaxation of 0.01 leaves out of the plan any move longer than about 0.1 of
#: the cube (moving that far costs more than dropping the mass), and looks move
#: colours by 0.1-0.3: the extracted looks pointed the right way (cosine with
#: the true displacement 0.54-0.87 on 10 of 12 looks) at only 13-39 % of their
#: size. Measured on ``benchmarks/look.py``'s cross-content sets, 6 tuned and 6
#: held-out looks, displacement error on the graded photos' colours relative to
#: doing nothing: 0.79 as before, 0.68 with relaxation 0.1, 0.48 with relaxation
#: 0.1, contents at the average (:data:`DEFAULT_CONTENT_SHRINK` 1) and ridge 1e-3
#: (tuned 0.48, held out 0.48), applied in full.
SET_RELAXATION = 0.1
SET_RIDGE = 1e-3
#: How far each style's content coordinates are pulled towards the average natural
#: palette (0: as fitted, 1: every style's content is the average). A style's fitted
#: content takes in part of the look (a desaturated set is explained by grey scenes);
#: shrinking it leaves what all styles share beyond typical content to the look.
#: Measured on ``benchmarks/look.py`` (cross-content, 18 photos at 384 px, strength
#: 0.7, relaxation 0.01): 0 / 0.3 / 0.6 / 0.8 / 1.0 recover +0.07 / +0.10 / +0.12 /
#: +0.12 / +0.12, worst photo -0.16 / -0.11 / -0.05 / -0.06 / -0.07; with the set's
#: relaxation (:data:`SET_RELAXATION`) the displacement error of 12 looks falls from
#: 0.61 (0.6) to 0.53 (1.0): every style's content is the average natural palette,
#: and the coordinates are not fitted.
DEFAULT_CONTENT_SHRINK = 1.0


@dataclass
class LookResult:
    """An extracted look and how it was found.

    Attributes
    ----------
    look : the map.
    weights : (M, K) natural-palette coordinates of each style's content.
    losses : (M,) KL loss of each style's fit at the last round.
    info : diagnostics (JSON-friendly).
    """
    look: LookMap
    weights: np.ndarray
    losses: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def share(self) -> float:
        """How much of what the styles show is applied (1 where the rule has no share)."""
        return float(self.info.get("share", 1.0))

    @property
    def own_photos(self) -> int | None:
        """How many of the user's own photos the look was measured against (None: unknown)."""
        count = self.info.get("own_photos")
        return None if count is None else int(count)


def extract_look(styles: dict[int, np.ndarray], naturals: dict[int, np.ndarray],
                 rounds: int = 1, relaxation: float = SET_RELAXATION,
                 width: float = DEFAULT_WIDTH, smoothness: float = DEFAULT_SMOOTHNESS,
                 ridge: float = SET_RIDGE, knots: int = DEFAULT_KNOTS,
                 fit_bins: int = 16, map_bins: int = 32, initial: LookMap | None = None,
                 style_weights: np.ndarray | None = None, shrink: bool = True,
                 content_shrink: float = DEFAULT_CONTENT_SHRINK,
                 progress: Callable[[int, int], None] | None = None) -> LookResult:
    """The look shared by style palettes, with natural palettes as the content model.

    Parameters
    ----------
    styles : {bins: (M, bins, bins, bins)} style histograms at ``fit_bins`` and ``map_bins``.
    naturals : {bins: (K, bins, bins, bins)} natural (ungraded) histograms, same grids.
    rounds : alternations of coordinates and map.
    relaxation : KL relaxation of both marginals of each content-to-style plan.
    width : plan kernel in bins of the ``map_bins`` grid.
    initial : the map to start from (default the identity).
    style_weights : (M,) how much each style's correspondences count (default equal).
    shrink : shrink the pooled map where the styles' own maps disagree (:func:`_shrunk`).
    content_shrink : pull of each style's content coordinates towards uniform
        weights (:data:`DEFAULT_CONTENT_SHRINK`); at 1 they are not fitted
        (every style's content is the natural palettes' barycenter; ``losses`` NaN).
    progress : called as ``progress(done, total)`` after each style of each round.
    """
    look = initial or LookMap.identity(knots)
    n_styles = len(styles[fit_bins])
    natural_map = naturals[map_bins]
    style_weights = (np.ones(n_styles) if style_weights is None
                     else np.asarray(style_weights, dtype=np.float64))
    geometry = fit_geometry(map_bins)
    all_weights = np.zeros((n_styles, len(natural_map)))
    losses = np.zeros(n_styles)
    average = content_shrink >= 1.0  # every style's content: the average natural palette
    if average:
        all_weights[:] = 1.0 / len(natural_map)
        losses[:] = np.nan
        average_content = _average_content(natural_map, geometry)
    for round_ in range(rounds):
        if not average:
            pushed = np.stack([push_histogram(h, look, fit_bins) for h in naturals[fit_bins]])
        sources, targets, masses = [], [], []
        for m in range(n_styles):
            if average:
                content = average_content
            else:
                weights, losses[m] = look_coordinates(styles[fit_bins][m], pushed)
                weights = (1.0 - content_shrink) * weights + content_shrink / len(weights)
                all_weights[m] = weights
                keep = np.flatnonzero(weights > 1e-3)
                content = barycenter(np.stack([add_floor(h, 1e-6) for h in natural_map[keep]]),
                                     weights[keep] / weights[keep].sum(), geometry, 60)
            points, moved_to, mass, _ = look_correspondences(content, styles[map_bins][m], look,
                                                         width, relaxation)
            sources.append(points)
            targets.append(moved_to)
            masses.append(style_weights[m] * mass / max(mass.sum(), 1e-300))
            if progress is not None:
                progress(round_ * n_styles + m + 1, rounds * n_styles)
        look = fit_look_map(np.concatenate(sources), np.concatenate(targets),
                            np.concatenate(masses), None, smoothness, ridge, knots)
        if shrink and n_styles > 1:
            look = _shrunk(look, [fit_look_map(sources[m], targets[m], masses[m], None,
                                               smoothness, ridge, knots)
                                  for m in range(n_styles)])
    info = {"rounds": rounds, "relaxation": relaxation, "width_bins": width,
            "content_shrink": content_shrink,
            "smoothness": smoothness, "ridge": ridge, "knots": knots,
            "fit_bins": fit_bins, "map_bins": map_bins, "amplitude": look.amplitude()}
    return LookResult(look, all_weights, losses, info)


#: The natural palettes' barycenter by a digest of the palettes: a style set and its two
#: halves (and every set graded against the same palettes) share it, and with hundreds
#: of palettes it is most of an extraction's time.
_AVERAGE_CONTENTS: dict[str, np.ndarray] = {}


def _average_content(natural_map: np.ndarray, geometry) -> np.ndarray:
    """The uniform Wasserstein barycenter of the natural palettes (n, b, b, b), computed once."""
    digest = hashlib.sha1(np.ascontiguousarray(natural_map, dtype=np.float64).tobytes())
    digest.update(repr(natural_map.shape).encode())
    key = digest.hexdigest()
    if key not in _AVERAGE_CONTENTS:
        weights = np.full(len(natural_map), 1.0 / len(natural_map))
        _AVERAGE_CONTENTS[key] = barycenter(np.stack([add_floor(h, 1e-6) for h in natural_map]),
                                            weights, geometry, 60)
    return _AVERAGE_CONTENTS[key]


def _shrunk(pooled: LookMap, each: list[LookMap], size: int = 17) -> LookMap:
    """``pooled`` with its displacement shrunk where the styles' own maps disagree.

    At every colour of a ``size``^3 lattice the pooled displacement ``d`` is
    scaled by ``|d|^2 / (|d|^2 + v / M)``, ``v`` the spread of the M styles'
    own displacements around their mean (a colour the styles move alike keeps
    the pooled move; one they move every which way, or only one style shows,
    moves little), and the family is fitted again to the result.
    """
    points = grid_points(size)
    moved = pooled(points) - points
    own = np.stack([look(points) - points for look in each])
    spread = np.mean(np.sum((own - own.mean(axis=0)) ** 2, axis=-1), axis=0)
    power = np.sum(moved ** 2, axis=-1)
    factor = power / np.maximum(power + spread / len(each), 1e-300)
    return fit_look_map(points, points + factor[:, None] * moved, np.ones(len(points)), None,
                        1e-4, 1e-6, pooled.knots)


# --------------------------------------------------------------------------- grading with looks

#: Strength of the set's own look when the set has a single style (no halves to
#: compare; :func:`set_look_base` takes the look's reliability otherwise). Chosen
#: when every set's look was applied at one strength (benchmarks/look.py,
#: cross-content, 36 photos at 768 px, relaxation 0.01: 0.7 / 0.85 / 1.0
#: recovered +0.10 / +0.12 / +0.13, worst photo -0.11 / -0.18 / -0.27).
SET_LOOK_STRENGTH = 0.7

#: Grids of the look fits: coordinates on 16^3, plans and maps on 32^3.
FIT_BINS = 16
MAP_BINS = 32


#: A preset whose provenance holds this key is of the user's own ungraded photos (used
#: beside the shipped palettes, as a folder of them is): a batch's own photos.
OWN_PHOTOS_PROVENANCE = "own_photos_of"


_OWN_NATURALS: dict[tuple, object] = {}


def _remember_own(key: tuple, naturals) -> None:
    """Keep a few content models with own photos (one a working space a batch grades in)."""
    if len(_OWN_NATURALS) >= 4:
        _OWN_NATURALS.pop(next(iter(_OWN_NATURALS)))
    _OWN_NATURALS[key] = naturals


def colour_photos(styles, working_space: str | None = None):
    """The photos of ``styles`` that hold colour (a black-and-white or toned photo says
    nothing of how colourful ungraded content is: a batch of them taken for content made
    a colour look saturate colour photos 2-9 times), or None when none does."""
    space = working_space or styles.meta.get("working_space") or default_working_space()
    spread = palette_statistics(styles.at_bins(MAP_BINS), source_bins=styles.bins).spread
    keep = np.flatnonzero(holds_colour(spread, space_scale(space)))
    if len(keep) == len(styles.names):
        return styles
    return styles.subset(keep) if len(keep) else None


def _beside_shipped(own, working_space: str):
    """The shipped palettes in ``working_space`` with ``own`` photos' palettes (those in
    colour: :func:`colour_photos`) beside them."""
    given = len(own.names)  # (black-and-white ones too: the advice counts them as unused)
    own = colour_photos(own, working_space)
    naturals = styles_in_space(natural_palettes(), working_space)
    if own is None:
        return _with_meta(naturals, own_given=given)
    return _with_meta(naturals, own=own, own_given=given)


def _with_meta(palettes, **meta):
    """``palettes`` (a StyleSet) with ``meta`` added (the own photos beside the natural ones)."""
    return type(palettes)(palettes.names, palettes.histograms, palettes.source, palettes.width,
                          palettes.description, {**palettes.meta, **meta})


def load_naturals(natural: str | None, working_space: str):
    """The content model a command names: ``natural`` a preset file (.npz) of natural
    palettes, a folder of the user's own ungraded photos (their statistics say what
    content looks like in their collection; the shipped palettes how much it varies:
    its ``own`` palettes; a preset marked :data:`OWN_PHOTOS_PROVENANCE` is read the same way),
    or None or :data:`~wbcgrade.color.presets.SHIPPED_NATURALS` (the shipped palettes); in
    ``working_space``."""
    from pathlib import Path

    if natural == SHIPPED_NATURALS:
        natural = None
    if natural is not None and Path(natural).is_dir():

        # once per process and state of the folder (a batch grades each photo against it)
        try:
            listing = tuple(sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns)
                                   for p in Path(natural).iterdir() if p.is_file()))
        except OSError:  # the folder changing under us: read it, keep nothing
            listing = None
        key = (str(Path(natural).resolve()), working_space, listing)
        if listing is not None and key in _OWN_NATURALS:
            return _OWN_NATURALS[key]
        naturals = _beside_shipped(load_style_folder(natural, MAP_BINS, cache=HistogramCache(),
                                                     working_space=working_space),
                                   working_space)
        if listing is not None:
            _remember_own(key, naturals)
        return naturals
    if natural:
        try:
            stat = Path(natural).stat()
            key = (str(Path(natural).resolve()), working_space, stat.st_size, stat.st_mtime_ns)
        except OSError:
            key = None
        if key is not None and key in _OWN_NATURALS:
            return _OWN_NATURALS[key]
        preset = load_preset(natural)
        if OWN_PHOTOS_PROVENANCE in (preset.meta.get("provenance") or {}):
            # (a batch kept only its photos in colour)
            own = _with_meta(styles_in_space(natural_palettes(), working_space),
                             own=styles_in_space(preset, working_space))
            if key is not None:
                _remember_own(key, own)
            return own
        return styles_in_space(preset, working_space)
    return styles_in_space(natural_palettes(), working_space)


def natural_palettes(exclude: set[str] | frozenset[str] = frozenset()):
    """The shipped palettes of ungraded photos (a :class:`~wbcgrade.color.presets.StyleSet`).

    Built by ``python -m wbcgrade.color.natural`` from photos whose licences
    allow it (``wbcgrade/color/data/NATURAL.md`` names them); ``exclude``
    leaves photos out by name (a benchmark holds out the photos it grades).
    """
    styles = load_preset(_natural_path())
    keep = [i for i, name in enumerate(styles.names) if name not in exclude]
    if len(keep) == len(styles.names):
        return styles
    return StyleSet([styles.names[i] for i in keep], styles.histograms[keep], styles.source,
                    styles.width, styles.description, dict(styles.meta))


def _natural_path():
    from pathlib import Path

    return Path(__file__).parents[1] / "data" / "natural.npz"


_SET_LOOKS: dict[tuple, LookResult] = {}


def set_look(styles, naturals=None, progress: Callable[[int, int], None] | None = None,
             cache: bool = True) -> LookResult:
    """The look a style set shares (:func:`extract_look`), computed once per set.

    Kept in memory for the process and, with ``cache``, on disk beside the
    style histogram cache (``looks/`` in the styles' cache folder, see
    :func:`_look_cache_path`), keyed by the histograms themselves.

    Parameters
    ----------
    styles : StyleSet of the graded photos.
    naturals : StyleSet of ungraded photos (default :func:`natural_palettes`),
        in the same working space as ``styles``.
    """
    naturals = naturals if naturals is not None else natural_palettes()
    digest = hashlib.sha1()
    own = naturals.meta.get("own")
    digest.update(np.ascontiguousarray(styles.at_bins(FIT_BINS), dtype=np.float64).tobytes())
    for palettes in (naturals, *([own] if own is not None else [])):
        digest.update(_palettes_digest(palettes).encode())
    digest.update(repr(naturals.meta.get("own_count")).encode())
    # the settings too: a look cached under other settings (an experiment's) is not reused
    digest.update(repr((LOOK_VERSION, FIT_BINS, MAP_BINS, SET_RELAXATION, SET_RIDGE,
                        DEFAULT_CONTENT_SHRINK, DEFAULT_WIDTH, DEFAULT_SMOOTHNESS,
                        DEFAULT_KNOTS, SET_LOOK_METHOD, SET_LOOK_RULE, statistics_settings(),
                        _prior_settings())).encode())
    key = (digest.hexdigest(),)
    if key not in _SET_LOOKS:
        found = _read_cached_look(key[0], styles) if cache else None
        if found is None:
            if SET_LOOK_METHOD == "statistics":
                found = statistics_set_look(styles, naturals)
            else:
                found = extract_look(
                    {b: styles.at_bins(b) for b in (FIT_BINS, MAP_BINS)},
                    {b: naturals.at_bins(b) for b in (FIT_BINS, MAP_BINS)},
                    relaxation=SET_RELAXATION, width=DEFAULT_WIDTH,
                    smoothness=DEFAULT_SMOOTHNESS, ridge=SET_RIDGE, knots=DEFAULT_KNOTS,
                    content_shrink=DEFAULT_CONTENT_SHRINK, fit_bins=FIT_BINS,
                    map_bins=MAP_BINS, progress=progress)
            if cache:
                _write_cached_look(key[0], found, styles)
        _SET_LOOKS[key] = found
    found = _SET_LOOKS[key]
    given = naturals.meta.get("own_given")  # a folder of own photos, black-and-white ones too
    if given is not None and found.own_photos is not None:
        found = LookResult(found.look, found.weights, found.losses,
                           {**found.info, "own_photos_unused": given - found.own_photos})
    return found


#: Bumped when extraction changes, so cached looks of an older version are not used.
LOOK_VERSION = 20

#: How a set's look is found: "statistics" (:func:`statistics_set_look`: statistics
#: content hardly moves, against the natural palettes' spread) or "transport"
#: (:func:`extract_look`: relaxed plans from the natural barycenter, pooled).
SET_LOOK_METHOD = "statistics"
#: How the statistics are shrunk: "posterior" (jointly, against content's noise, with a
#: prior over looks learned from a generator of edits:
#: :func:`wbcgrade.color.look.prior.posterior_statistics_look`) or "shrink" (statistic by
#: statistic, then the halves' agreement: :func:`wbcgrade.color.look.statistics.statistics_look`).
SET_LOOK_RULE = "posterior"

_NATURAL_STATISTICS: dict[str, object] = {}


def _prior_settings() -> tuple:
    """The settings of :mod:`wbcgrade.color.look.prior` a set's look depends on."""
    return (prior.NO_LOOK, prior.PRIOR_SCALES, prior.COLLECTION_SHARE, prior.UNUSUAL_CONTENT,
            prior.DIAGONAL_SHRINK, prior.NOISE_DRAWS, prior.JACKKNIFE_GROUPS, prior.PARTS,
            prior.SEPARATE_PARTS, prior.PART_TIE, JACKKNIFE_BINS,
            prior.POSTERIOR_DRAWS,
            float(np.sum(prior.load_prior())))


def statistics_settings() -> tuple:
    """The settings of :mod:`wbcgrade.color.look.statistics` a set's look depends on."""
    return (stats.CONTENT_BIAS, stats.TONE_BIAS, stats.NEUTRAL_SHARE, stats.MONOCHROME_SPREAD,
            stats.BANDS, tuple(stats.QUANTILES), stats.TINT_FROM, stats.MIN_BAND_MASS,
            stats.EVIDENCE_FLOOR, stats.EVIDENCE_SPAN, stats.EVIDENCE_CLIP,
            stats.MIN_EASED_STYLES, stats.MIN_CONTENT_BIAS, stats.NULL_DRAWS, stats.NULL_MARGIN,
            stats.OWN_PHOTO_NOISE, stats.MIN_OWN_PHOTOS)


_DIGESTS: dict[int, tuple[object, str]] = {}
_STAT_FIELDS = ("quantiles", "band_mass", "band_mean", "band_spread", "spread", "band_neutral")


def _palettes_digest(palettes) -> str:
    """A digest of a StyleSet's histograms (as stored: no re-binning), once per array."""
    meta = getattr(palettes, "meta", {}) or {}
    file_digest = getattr(palettes, "file_digest", None)
    if file_digest:  # (styles of) a preset file, in a working space: no array hashed or made
        names = hashlib.sha1("\0".join(palettes.names).encode()).hexdigest()
        return (f"{file_digest}|{meta.get('working_space', '')}|"
                f"{meta.get('converted_from', '')}|{deferred_shape(palettes, 'histograms')}|"
                f"{names}")
    hists = palettes.histograms
    known = _DIGESTS.get(id(hists))
    if known is None or known[0] is not hists:
        digest = hashlib.sha1(repr((hists.shape, str(hists.dtype))).encode())
        digest.update(np.ascontiguousarray(hists).tobytes())
        known = _DIGESTS[id(hists)] = (hists, digest.hexdigest())
    return known[1]


def natural_statistics(naturals, cache_from=None):
    """:func:`~wbcgrade.color.look.statistics.palette_statistics` of the natural palettes,
    once per process and set of palettes, and kept on disk in the looks' cache folder
    (``cache_from``: the StyleSet whose cache settings apply; a damaged entry is rebuilt)."""
    key = _palettes_digest(naturals) + repr(statistics_settings())
    if key in _NATURAL_STATISTICS:
        return _NATURAL_STATISTICS[key]
    name = "natural-" + hashlib.sha1(key.encode()).hexdigest()
    path = _look_cache_path(name, cache_from)

    found = None
    data = read_entry(path)
    if data is not None:
        try:
            found = PaletteStatistics(**{f: np.asarray(data[f], np.float64)
                                         for f in _STAT_FIELDS})
            if found.quantiles.shape != (len(naturals.names), len(QUANTILES)):
                found = None
        except Exception:  # noqa: BLE001 - a cache never fails a run: any damage is a miss
            found = None
    if found is None:
        found = palette_statistics(naturals.at_bins(MAP_BINS))
        write_entry(path, **{f: getattr(found, f) for f in _STAT_FIELDS})
    _NATURAL_STATISTICS[key] = found
    return found


def statistics_set_look(styles, naturals, knots: int = DEFAULT_KNOTS) -> LookResult:
    """The look a style set shares, from statistics content hardly moves
    (:func:`wbcgrade.color.look.statistics.statistics_look`), fitted into the
    :class:`LookMap` family on the colours natural photos hold (and, less, all others).

    Parameters
    ----------
    styles, naturals : StyleSets in one working space.
    """
    natural_stats = natural_statistics(naturals, styles)
    own = naturals.meta.get("own")
    own_count = naturals.meta.get("own_count")  # a half's: the whole own set's number
    reference = palette_statistics(own.at_bins(MAP_BINS)) if own is not None else None
    # re-binned from a finer grid, the styles' colours were binned twice (a trace of chroma
    # in a black-and-white set's histograms): both are taken off the chroma spread
    style_hists = styles.at_bins(MAP_BINS)
    scale = space_scale(styles.working_space)
    style_stats = tinted_statistics(style_hists, natural_stats, reference,
                                    source_bins=styles.bins, own_count=own_count,
                                    space_scale=scale)
    if SET_LOOK_RULE == "posterior" and not np.all(style_stats.spread
                                                   < MONOCHROME_SPREAD * scale):

        average = resample_histogram(naturals.at_bins(MAP_BINS).mean(axis=0), JACKKNIFE_BINS)
        model = posterior_statistics_look(style_stats, natural_stats, scale, reference,
                                          own_count, cache=cache_folder(styles),
                                          jackknife_colors=_histogram_colors(average))
    else:
        model = statistics_look(style_stats, natural_stats, scale, reference=reference,
                                own_count=own_count)
    size = 17
    points = grid_points(size)
    density = resample_histogram(naturals.at_bins(MAP_BINS).mean(axis=0), size).ravel()
    weights = density / density.sum() + 0.25 / len(points)
    look = fit_look_map(points, model(points), weights, None, 1e-4, 1e-6, knots)
    n_styles, n_naturals = len(styles.names), len(naturals.names)
    info = {**model.info, "amplitude": look.amplitude()}
    return LookResult(look, np.full((n_styles, n_naturals), 1.0 / max(n_naturals, 1)),
                      np.full(n_styles, np.nan), info)


#: The grid of the average natural palette on whose colours a set's look is checked
#: against itself (:func:`wbcgrade.color.look.prior.jackknife_share`).
JACKKNIFE_BINS = 16


def set_look_halves(styles, naturals=None) -> tuple[LookMap, LookMap] | None:
    """The looks of the two halves of a style set (styles 0, 2, 4, ... and 1, 3, 5, ...),
    each extracted as :func:`set_look` does (and cached the same way); None under 2 styles.
    With the user's own photos (the ``own`` palettes beside ``naturals``), each half is
    measured against its half of them too (weighed as the whole), so the halves disagree by the own
    photos' sampling error as well as by the styles'."""
    n = len(styles.names)
    if n < 2:
        return None
    own = None if naturals is None else naturals.meta.get("own")
    halves = []
    for h in (0, 1):
        against = naturals
        if own is not None and len(own.names) >= 2:
            against = _own_half(naturals, own, h)
        halves.append(set_look(styles.subset(range(h, n, 2)), against).look)
    return halves[0], halves[1]


_OWN_HALVES: dict[tuple, object] = {}


def _own_half(naturals, own, half: int):
    """``naturals`` with half ``half`` (0, 1) of its own photos, weighed as the whole set
    (the whole own set's count); made once per own set (its digest names the half's)."""
    digest = _palettes_digest(own)
    key = (id(naturals), digest, half)
    if key not in _OWN_HALVES or _OWN_HALVES[key][0] is not naturals:
        if len(_OWN_HALVES) >= 8:
            _OWN_HALVES.pop(next(iter(_OWN_HALVES)))
        picked = list(range(half, len(own.names), 2))
        part = StyleSet([own.names[i] for i in picked], own.histograms[picked], own.source,
                        own.width, own.description,
                        {"working_space": own.meta.get("working_space"),
                         "file_digest": f"{digest}|half {half}"})
        _OWN_HALVES[key] = (naturals, _with_meta(naturals, own_count=len(own.names), own=part))
    return _OWN_HALVES[key][1]


def look_reliability(first: LookMap, second: LookMap, colors: np.ndarray,
                     weights: np.ndarray | None = None) -> float:
    """How far two independent estimates of a look agree on ``colors``, in [0, 1].

    ``r`` is the cosine between the two maps' displacements ``T(x) - x`` over
    the colours (weighted by ``weights``), stepped up from a half to the whole
    set (Spearman-Brown, ``2 r / (1 + r)``); 0 when they do not agree (r <= 0).
    The share of the whole set's look that is the look rather than its styles'
    content: a look every style shows is applied in full, one the halves
    disagree on is not applied.

    Parameters
    ----------
    first, second : the looks of the two halves (:func:`set_look_halves`).
    colors : (N, 3) colours in [0, 1] (the photo's).
    weights : (N,) non-negative, default equal.
    """
    colors = np.asarray(colors, dtype=np.float64).reshape(-1, 3)
    w = np.ones(len(colors)) if weights is None else np.asarray(weights, np.float64).ravel()
    a, b = first(colors) - colors, second(colors) - colors
    norms = np.sqrt(np.sum(w * np.sum(a * a, axis=1)) * np.sum(w * np.sum(b * b, axis=1)))
    if not norms > 0:
        return 0.0
    r = float(np.sum(w * np.sum(a * b, axis=1)) / norms)
    return 2.0 * r / (1.0 + r) if r > 0 else 0.0


def _look_cache_path(key: str, styles=None):
    """Where a set's look (or the natural palettes' statistics) keyed by ``key`` is kept:
    ``looks/`` in the styles' cache folder (:func:`wbcgrade.color.io.cache.cache_folder`);
    None when caching is off."""
    return entry_path(cache_folder(styles), "looks", key)


def _read_cached_look(key: str, styles=None) -> LookResult | None:
    import json

    data = read_entry(_look_cache_path(key, styles))  # damaged: removed, extracted again
    try:
        look = LookMap(np.array(data["coefficients"], dtype=np.float64), int(data["knots"]))
        if look.coefficients.shape != (3, 4 * look.knots) \
                or not np.isfinite(look.coefficients).all():
            return None
        return LookResult(look, np.array(data["weights"]), np.array(data["losses"]),
                          json.loads(str(data["info"])))
    except Exception:  # noqa: BLE001 - a cache never fails a run: any damage is a miss
        return None


def _write_cached_look(key: str, result: LookResult, styles=None) -> None:
    """Best effort: a cache that cannot be written is skipped."""
    import json

    write_entry(_look_cache_path(key, styles), coefficients=result.look.coefficients,
                knots=result.look.knots, weights=result.weights, losses=result.losses,
                info=json.dumps(result.info))


#: Styles each half of a set needs for the statistics look to be checked by its halves'
#: agreement (fewer: the shrunk statistics alone decide). Measured with
#: ``benchmarks/look.py`` (statistics look on 384 px photos, the film looks' twelve
#: styles and the other looks' six; on the photo's own colours): film looks +0.213 (worst
#: -0.05) unchecked, +0.199 (+0.00) checked; the other twelve looks +0.198 (-0.40) and
#: +0.180 (-0.22): a little of the mean for no photo clearly worse than doing nothing.
MIN_HALF_STYLES = 2

#: A statistics look whose evidence (its ``evidence``, 1 where ungraded sets stop;
#: :func:`wbcgrade.color.look.statistics._look_evidence`; weighed for sets of
#: :data:`~wbcgrade.color.look.statistics.MIN_EASED_STYLES` styles or more against the
#: shipped palettes, not against the user's own photos) reaches this is applied in full,
#: without its halves' check: at this evidence it is already shrunk by the least share
#: (:data:`wbcgrade.color.look.statistics.MIN_CONTENT_BIAS`), and six styles a half
#: estimate it noisily enough to halve a real look. Measured (``benchmarks/look.py``,
#: cross-content, 384 px): film looks +0.25 -> +0.26 (bleach bypass 2 +0.44 -> +0.60),
#: older looks +0.22 -> +0.25 (CDL warm +0.37 -> +0.49, cross process +0.12 -> +0.32),
#: worst photo unchanged; ungraded sets of 6 / 8 / 12 of the benchmark's photos (40 each):
#: the largest applied look 17.6 -> 21.2 / 4.6 / 4.2 (per 255, rms; one six-photo set of
#: warm scenes reached 2.4), the 90th percentile unchanged.
TRUSTED_EVIDENCE = 2.0

#: Size (rms displacement on a photo's colours) of the look :func:`extract_look` finds
#: in sets of UNGRADED photos: what content alone makes of a look, the part of any
#: extracted look that both halves of a set can share without its being a look.
#: Measured on ``benchmarks/look.py``'s 12 cross-content partitions with the looks
#: left off: 0.035-0.073 (the looks themselves: 0.10-0.43); this is the largest, so
#: that no ungraded set's look is applied. On the full cross-content run (768 px, 36
#: photos of the tuned looks / 36 of the held-out ones) 0.05 / 0.06 / 0.07 recover
#: +0.23 / +0.20 / +0.17 and +0.26 / +0.24 / +0.22, worst photo -0.49 / -0.25 /
#: -0.04 and -0.28 / -0.20 / -0.12 (a look the photo's colours barely show,
#: e.g. ARRI's on a purple gradient, dE 2.4 from the truth before grading). In
#: sRGB-encoded units; other working spaces scale it (:func:`space_scale`).
NULL_LOOK_SIZE = 0.07


def set_look_base(styles, naturals=None, strength: float | None = None,
                  photo_hist: np.ndarray | None = None,
                  progress: Callable[[int, int], None] | None = None
                  ) -> tuple[LookMap, LookResult, float]:
    """The set's look at ``strength`` (what a photo of another scene gets), and the extraction.

    ``strength`` None: the look's split-half reliability (:func:`look_reliability`
    of :func:`set_look_halves`) on the photo's colours (``photo_hist``, any
    (n, n, n) grid) or, without a photo, on the average natural palette's,
    times ``max(0, 1 - b^2 / a^2)`` (``a``: the look's rms displacement on those
    colours, ``b``: :data:`NULL_LOOK_SIZE` in the working space's units, what
    content alone makes of a look); a single style: :data:`SET_LOOK_STRENGTH`. Measured on
    ``benchmarks/look.py`` (cross-content, 384 px; see the README): a large
    look every style shows (a sepia, a day for night, a bleach bypass) is
    applied nearly in full, one whose halves disagree (teal-orange across
    scenes) not at all, a faint one (a mild colour correction) little.

    ``progress``: the whole set's extraction (:func:`set_look`).

    Returns (the look at that strength, the extraction, the strength).
    """
    extracted = set_look(styles, naturals, progress)
    statistics = extracted.info.get("method") == "statistics"
    if extracted.info.get("rule") == "posterior":
        # the look is already the posterior's: as strong as the styles support it
        scale = 1.0 if strength is None else float(strength)
        look = LookMap(scale * extracted.look.coefficients, extracted.look.knots)
        return look, extracted, scale * extracted.share
    if strength is None and statistics and (extracted.info.get("monochrome")
                                            or len(styles.names) < MIN_HALF_STYLES * 2
                                            or (extracted.info.get("evidence") or 0.0)
                                            >= TRUSTED_EVIDENCE):
        strength = 1.0  # every style black and white / too few styles to halve
    if strength is None:
        halves = set_look_halves(styles, naturals)
        if halves is None:
            strength = SET_LOOK_STRENGTH
        else:
            if photo_hist is None:
                naturals = naturals if naturals is not None else natural_palettes()
                photo_hist = naturals.at_bins(MAP_BINS).mean(axis=0)
            colors, weights = _histogram_colors(photo_hist)
            strength = look_reliability(*halves, colors, weights)
            if not statistics:  # (the statistics were shrunk by what content varies by)
                moved = extracted.look(colors) - colors
                size2 = float(np.sum(weights * np.sum(moved * moved, axis=1))
                              / np.sum(weights))
                null = NULL_LOOK_SIZE * space_scale(styles.working_space)
                strength *= max(0.0, 1.0 - null ** 2 / max(size2, 1e-300))
    look = LookMap(strength * extracted.look.coefficients, extracted.look.knots)
    return look, extracted, float(strength)


@functools.cache
def space_scale(working_space: str) -> float:
    """How large colour differences are in ``working_space``'s unit cube against the
    sRGB-encoded one (where :data:`NULL_LOOK_SIZE` was measured): the rms spread of
    the shipped natural palettes' colours there over their spread in sRGB (1 in the
    default space; about 0.5 in ACEScct, which packs sRGB into 0.07-0.55)."""
    def spread(hist: np.ndarray) -> float:
        colors, weights = _histogram_colors(hist)
        mean = weights @ colors / weights.sum()
        return float(np.sqrt(weights @ np.sum((colors - mean) ** 2, axis=1) / weights.sum()))

    naturals = natural_palettes()
    srgb = spread(naturals.at_bins(MAP_BINS).mean(axis=0))
    there = styles_in_space(naturals, working_space).at_bins(MAP_BINS).mean(axis=0)
    return spread(there) / srgb


def _histogram_colors(hist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The occupied bins of an (n, n, n) histogram: (colours (N, 3), masses (N,))."""
    flat = np.asarray(hist, dtype=np.float64).ravel()
    used = np.flatnonzero(flat > 0)
    return grid_points(hist.shape[0])[used], flat[used]


class LookInfo(dict):
    """What :func:`set_look_map` found (JSON-friendly), with typed readings of it."""

    @property
    def strength(self) -> float:
        """The strength the look was written at."""
        return float(self["strength"])

    @property
    def from_preset(self) -> bool:
        """A preset's own look (not one extracted from photos)."""
        return self.get("source") == "preset"

    @property
    def probability(self) -> float | None:
        """How sure it is that the set has a look, where the styles were judged jointly."""
        if self.get("rule") != "posterior" or self.get("probability") is None:
            return None
        return float(self["probability"])

    @property
    def share(self) -> float:
        """How much of what the styles show is applied."""
        return float(self.get("share", self.strength))

    def count(self, key: str) -> int:
        """A count it holds (own photos used, unused...), 0 when absent."""
        return int(self.get(key) or 0)


def set_look_map(styles, naturals=None, strength: float | None = None,
                 map_size: int = 33,
                 progress: Callable[[int, int], None] | None = None
                 ) -> tuple[np.ndarray, LookInfo]:
    """The look a style set shares, as a lattice LUT (what ``wbcgrade look extract`` writes).

    ``strength`` scales the map's displacement; None: a preset's own look in
    full, an extracted one at its reliability on the average natural palette
    (:func:`set_look_base`; the grade takes it on the photo's own colours).

    Returns ((map_size,) * 3 + (3,) float32 lattice, :class:`LookInfo`).
    """
    if styles.look is not None:  # a preset made with a known look
        strength = 1.0 if strength is None else strength
        identity = grid_points(map_size).reshape((map_size,) * 3 + (3,))
        known = resample_lattice(styles.look, map_size)
        moved = strength * (known - identity)
        return ((identity + moved).astype(np.float32),
                LookInfo({"source": "preset", "strength": strength,
                 "amplitude_applied": float(np.mean(np.linalg.norm(moved, axis=-1)))}))
    look, extracted, strength = set_look_base(styles, naturals, strength, progress=progress)
    names = (naturals if naturals is not None else natural_palettes()).names
    if extracted.info.get("content_shrink", 0.0) >= 1.0:  # not fitted: the average of all
        content = {style: "the natural palettes' barycenter" for style in styles.names}
    else:
        content = {style: {names[k]: round(float(w), 3) for k, w in enumerate(row)
                           if w >= 0.05}
                   for style, row in zip(styles.names, extracted.weights)}
    info = LookInfo({**extracted.info, "strength": strength,
                     "amplitude_applied": look.amplitude(), "content": content})
    lattice = look.lattice(map_size)
    if extracted.info.get("monochrome"):

        lattice = monochrome_map(lattice)
    return lattice, info
