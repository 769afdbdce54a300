"""A set's look from statistics that content hardly moves, measured against natural photos.

A look moves every photo it touches the same way; content moves each photo
its own way. So compare, statistic by statistic, the *median over the style
photos* with the *median over natural (ungraded) photos*:

- the lightness distribution (quantiles of luma, black and white levels
  included): a tone curve ``g`` mapping the natural quantiles onto the
  styles' ones (a median commutes with a monotone curve, so the styles'
  median quantile is the curve applied to their content's);
- per lightness band, the mean chroma (the tint of shadows, mid-tones and
  highlights: white balance, split toning) and the chroma spread around it
  (saturation; zero in a black-and-white set).

Every difference is shrunk by how much that statistic varies between sets of
as many natural photos (``1.25 sd / sqrt(S)`` for a median of ``S``, ``sd``
robust, over the natural palettes) plus a share of ``sd`` for content that
differs from the natural photos' kind: a difference content alone would make
is dropped, a larger one kept in part (positive-part James-Stein), so a
black level every style lifts is kept, a brightness two scenes could explain
is not. That share eases for a set of six or more styles whose statistics stand
far from the natural ones as a whole (a strong look: :data:`EVIDENCE_FLOOR`). Six or
more of the user's own ungraded photos lean the natural medians towards theirs as far
as their number says (:func:`content_centre`). The
statistics define a look ``T``: luma through ``g``, chroma scaled
by ``s(Y)`` and shifted by ``t(Y)``; a set whose every photo is monochrome
(or toned) gets ``s = 0``. ``T`` is fitted into the smooth
:class:`~wbcgrade.color.look.LookMap` family the grade applies.

Arrays in, arrays out: histograms are (K, n, n, n) on the colour grid of
:func:`~wbcgrade.color.histogram.grid_points`.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, fields

import numpy as np

from wbcgrade.color.colorspace import REC709_LUMA
from wbcgrade.color.defaults import MIN_OWN_PHOTOS
from wbcgrade.color.histogram import grid_points

__all__ = ["PaletteStatistics", "palette_statistics", "tinted_statistics", "StatisticsLook",
           "statistics_look", "own_photos_blend", "content_centre", "holds_colour",
           "QUANTILES", "BANDS", "MIN_OWN_PHOTOS"]

#: Rec.709 luma weights on encoded values (the look family's lightness; toning is a
#: function of it: :data:`wbcgrade.color.mapping.remap.TONE_LUMA`).
LUMA = np.array(REC709_LUMA)
#: Levels of the luma quantiles compared (black and white levels at the ends).
QUANTILES = np.array([0.005, 0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95,
                      0.98, 0.995])
#: Lightness bands (tent functions centred on ``linspace(0, 1, BANDS)``).
BANDS = 9
#: A band holding less of a photo's mass than this says nothing about it.
MIN_BAND_MASS = 0.01
#: Efficiency of a median against a mean (its standard error is this times sd / sqrt(n)).
MEDIAN_SE = 1.2533
#: Share of the natural photos' spread added to every statistic's uncertainty: content
#: of another kind than the natural photos' (another camera, another collection).
CONTENT_BIAS = 1.0
#: The same for the luma quantiles (a collection's typical exposure differs more).
TONE_BIAS = 1.0
#: Which tint the look takes: "neutral" (of each band's least colourful colours) or "mean".
TINT_FROM = "neutral"
#: Share of a band's mass (its least colourful colours) whose tint is the band's neutral tint.
NEUTRAL_SHARE = 0.2
#: Chroma spread (sRGB-encoded units) under which a photo counts as monochrome or toned.
MONOCHROME_SPREAD = 0.01


@dataclass(frozen=True)
class PaletteStatistics:
    """Per-palette statistics of K histograms.

    Attributes
    ----------
    quantiles : (K, Q) luma at :data:`QUANTILES`.
    band_mass : (K, B) share of the palette in each lightness band.
    band_mean : (K, B, 3) mean chroma (colour minus its luma) in each band (NaN where
        the band holds under :data:`MIN_BAND_MASS`).
    band_spread : (K, B) rms distance of the band's chroma from that mean (NaN likewise).
    spread : (K,) rms chroma spread about the band means over the whole palette.
    band_neutral : (K, B, 3) mean chroma of the least colourful :data:`NEUTRAL_SHARE` of
        each band (what is grey in a natural photo: its tint is the look's; NaN likewise).
    """

    quantiles: np.ndarray
    band_mass: np.ndarray
    band_mean: np.ndarray
    band_spread: np.ndarray
    spread: np.ndarray
    band_neutral: np.ndarray

    def take(self, index: np.ndarray) -> PaletteStatistics:
        """The statistics of the palettes at ``index`` (an index array or a mask)."""
        return PaletteStatistics(*(getattr(self, f.name)[index] for f in fields(self)))


def hats(t: np.ndarray, knots: int) -> np.ndarray:
    """(N,) values in [0, 1] -> (N, knots) piecewise-linear hat functions (a partition of 1)."""
    pos = np.clip(t, 0.0, 1.0) * (knots - 1)
    base = np.minimum(pos.astype(np.int64), knots - 2)
    frac = pos - base
    out = np.zeros((len(t), knots))
    rows = np.arange(len(t))
    out[rows, base] = 1.0 - frac
    out[rows, base + 1] = frac
    return out


def _bands(luma: np.ndarray) -> np.ndarray:
    """(N,) luma -> (N, B) tent memberships of the lightness bands."""
    return hats(luma, BANDS)


def palette_statistics(hists: np.ndarray, centre: np.ndarray | None = None,
                       source_bins: int | None = None) -> PaletteStatistics:
    """Statistics of (K, n, n, n) histograms (or one (n, n, n)) on the colour grid.

    ``centre``: (B, 3) chroma per band from which the least colourful colours are
    measured (default 0, the grey axis; a set's rough tint finds the colours that were
    grey before it: :func:`tinted_statistics`). ``source_bins``: the grid the
    histograms were first binned on, when they were re-binned from a finer one.
    """
    hists = np.asarray(hists, dtype=np.float64)
    if hists.ndim == 3:
        hists = hists[None]
    k, n = len(hists), hists.shape[1]
    flat = hists.reshape(k, -1)
    flat = flat / np.maximum(flat.sum(axis=1, keepdims=True), 1e-300)
    used = np.flatnonzero(flat.max(axis=0) > 0)  # bins some palette holds
    flat = np.ascontiguousarray(flat[:, used])
    points = grid_points(n)[used]
    luma = points @ LUMA
    chroma = points - luma[:, None]
    # luma quantiles: the cumulative mass in luma order, interpolated
    order = np.argsort(luma, kind="stable")
    sorted_luma = luma[order]
    cumulative = np.cumsum(flat[:, order], axis=1)
    quantiles = np.stack([np.interp(QUANTILES, c, sorted_luma) for c in cumulative])
    # chroma per lightness band (matrix products: K palettes x N bins)
    member = _bands(luma)                                           # (N, B)
    mass = flat @ member                                            # (K, B)
    safe = np.maximum(mass, 1e-300)
    weighted = (member[:, :, None] * chroma[:, None, :]).reshape(len(used), -1)
    mean = (flat @ weighted).reshape(k, BANDS, 3) / safe[..., None]
    second = (flat @ (member * np.sum(chroma ** 2, axis=1)[:, None])) / safe
    # soft binning spreads each channel by f (1 - f) / (n - 1)^2 (f: where a colour falls
    # between two nodes; 1/6 on average), independently, which chroma (summed over its three
    # components) takes 1 + 3 |luma weights|^2 times
    binning = (1.0 + 3.0 * float(LUMA @ LUMA)) / (6.0 * (n - 1) ** 2)
    if source_bins is not None and source_bins > n:  # binned on that grid first
        binning *= 1.0 + ((n - 1) / (source_bins - 1)) ** 2
    spread = np.sqrt(np.maximum(second - np.sum(mean ** 2, axis=-1) - binning, 0.0))
    whole = np.sqrt(np.maximum(np.sum(mass * spread ** 2, axis=1), 0.0))
    # the least colourful share of each band (bands by nearest centre here)
    nearest = np.rint(np.clip(luma, 0.0, 1.0) * (BANDS - 1)).astype(np.int64)
    centre = np.zeros((BANDS, 3)) if centre is None else np.nan_to_num(centre)
    neutral = np.full((k, BANDS, 3), np.nan)
    for b in range(BANDS):
        idx = np.flatnonzero(nearest == b)
        magnitude = np.sum((chroma[idx] - centre[b]) ** 2, axis=1)
        idx = idx[np.argsort(magnitude, kind="stable")]
        band = flat[:, idx]
        total = band.sum(axis=1, keepdims=True)
        cumulative = np.cumsum(band, axis=1)
        # each bin's share of the band's least colourful NEUTRAL_SHARE (partial at the edge)
        limit = NEUTRAL_SHARE * total
        take = np.clip(limit - (cumulative - band), 0.0, band)
        got = take.sum(axis=1)
        ok = total[:, 0] >= MIN_BAND_MASS
        neutral[ok, b] = (take[ok] @ chroma[idx]) / got[ok, None]
    empty = mass < MIN_BAND_MASS
    mean[empty] = np.nan
    spread = np.where(empty, np.nan, spread)
    return PaletteStatistics(quantiles, mass, mean, spread, whole, neutral)


def tinted_statistics(hists: np.ndarray, naturals: PaletteStatistics,
                      reference: PaletteStatistics | None = None,
                      source_bins: int | None = None,
                      own_count: int | None = None,
                      space_scale: float = 1.0) -> PaletteStatistics:
    """:func:`palette_statistics` of a style set, its neutral tints measured from the set's
    rough tint (the median band means' departure from the natural ones): a tint every
    style shows moves what was grey, and the least colourful colours of a strongly
    tinted photo are not what was grey."""
    first = palette_statistics(hists, source_bins=source_bins)
    centre = content_centre(naturals, in_colour(reference, space_scale), own_count)
    rough = _nanmedian(first.band_mean, axis=0) - _nanmedian(centre.band_mean, axis=0)
    sd = _robust_sd(naturals.band_mean)
    sigma = np.sqrt((MEDIAN_SE * sd) ** 2 / len(first.quantiles) + (CONTENT_BIAS * sd) ** 2)
    return palette_statistics(hists, _shrink(rough, sigma), source_bins)


def _nanmedian(values: np.ndarray, axis: int = 0, keepdims: bool = False) -> np.ndarray:
    """``np.nanmedian``, bit for bit (the mean of the two middle values, or the middle one),
    NaN for an all-NaN slice without a warning: one sort instead of numpy's masked median
    per call (a set's look takes hundreds of these on small arrays)."""
    ordered = np.sort(np.moveaxis(np.asarray(values), axis, -1), axis=-1)  # NaN last
    count = np.count_nonzero(~np.isnan(ordered), axis=-1)
    half = count // 2
    last = max(ordered.shape[-1] - 1, 0)
    low = np.take_along_axis(ordered, np.maximum(np.where(count % 2 == 1, half, half - 1),
                                                 0)[..., None], -1)[..., 0]
    high = np.take_along_axis(ordered, np.minimum(half, last)[..., None], -1)[..., 0]
    median = np.where(count > 0, (low + high) / 2, np.nan)
    if keepdims:
        median = np.expand_dims(median, axis)
    return median[()] if median.ndim == 0 else median


def _robust_sd(values: np.ndarray, axis: int = 0) -> np.ndarray:
    """1.4826 x the median absolute deviation (NaN ignored)."""
    centre = _nanmedian(values, axis=axis, keepdims=True)
    return 1.4826 * _nanmedian(np.abs(values - centre), axis=axis)


def _shrink(difference: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Positive-part James-Stein: ``d * max(0, 1 - sigma^2 / d^2)`` (0 where d is NaN)."""
    d = np.nan_to_num(difference)
    power = d * d
    factor = np.where(power > 0, np.maximum(0.0, 1.0 - sigma ** 2 / np.maximum(power, 1e-300)),
                      0.0)
    return d * factor


def _shrink_vectors(difference: np.ndarray, sigma: np.ndarray, dof: float = 3.0) -> np.ndarray:
    """(B, 3) chroma differences shrunk band by band as vectors: ``d * max(0, 1 - dof / q)``,
    ``q`` the squared norm of ``d / sigma`` (``dof``: its mean where there is no tint, one a
    channel, as a channel by channel shrink drops ``z^2 < 1``), so a tint keeps its hue
    (shrunk channel by channel, a blue shadow tint whose green part varies least between
    natural photos turned teal: crisp winter on a dusk sky). NaN counts as 0."""
    d = np.nan_to_num(difference)
    q = np.sum((d / np.maximum(np.broadcast_to(sigma, d.shape), 1e-12)) ** 2, axis=-1)
    factor = np.where(q > 0, np.maximum(0.0, 1.0 - dof / np.maximum(q, 1e-300)), 0.0)
    return d * factor[..., None]


def _read_at(values: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(S, B) per-band values of S palettes read at ``positions`` (B,) on the band axis
    (missing bands filled from their neighbours; a palette with none stays NaN)."""
    centres = np.linspace(0.0, 1.0, BANDS)
    return np.stack([np.interp(positions, centres, _fill(row, centres))
                     if np.isfinite(row).any() else np.full(BANDS, np.nan)
                     for row in values])


def _fill(values: np.ndarray, axis_values: np.ndarray) -> np.ndarray:
    """Interpolate NaN entries of a 1-D profile from its valid neighbours (edges held)."""
    values = np.asarray(values, dtype=np.float64)
    valid = np.isfinite(values)
    if not valid.any():
        return np.zeros_like(values)
    return np.interp(axis_values, axis_values[valid], values[valid])


#: The share of the natural spread added for a collection's own difference
#: (:data:`CONTENT_BIAS`, :data:`TONE_BIAS`) eases from 1 at an ``evidence``
#: (:func:`_look_evidence`: 1 where ungraded sets stop) of ``EVIDENCE_FLOOR`` to
#: :data:`MIN_CONTENT_BIAS` at ``EVIDENCE_FLOOR + EVIDENCE_SPAN``: statistics far beyond
#: what content makes of them are a look, not a collection (docs/benchmarks.md).
EVIDENCE_FLOOR = 1.0
EVIDENCE_SPAN = 1.0
#: Each statistic's z counts up to this (one odd photo's band does not make a look).
EVIDENCE_CLIP = 3.0
#: Sets of fewer styles keep the full share: a median of a few photos is often far from
#: the natural one without a look (ungraded 3-photo sets reached 3.9), and a set under
#: four styles has no halves to check its look by.
MIN_EASED_STYLES = 6
#: The least share of the natural spread a look's statistics are shrunk by.
MIN_CONTENT_BIAS = 0.25
#: Random sets of natural photos drawn to learn where ungraded sets' evidence stops, kind
#: by kind, and the margin kept above their 99th percentile (another collection's photos
#: stand further from the natural ones than the natural photos do).
NULL_DRAWS = 200
NULL_MARGIN = 1.5


def _z2(values: np.ndarray, centre: np.ndarray, sd: np.ndarray, n_styles: int) -> np.ndarray:
    """Squared z (clipped at :data:`EVIDENCE_CLIP`) of the median of ``values`` (S, ...)."""
    sigma = sd * np.sqrt(MEDIAN_SE ** 2 / n_styles + 1.0)
    z = (_nanmedian(values, axis=0) - centre) / np.maximum(sigma, 1e-12)
    return np.minimum(np.ravel(z[np.isfinite(z)]) ** 2, EVIDENCE_CLIP ** 2)


def _groups(stats: PaletteStatistics) -> list[np.ndarray]:
    """The statistics the evidence weighs, by kind: tone, saturation, tint."""
    return [stats.quantiles, np.log(np.maximum(stats.band_spread, 1e-4)), stats.band_neutral]


def _mean(values: np.ndarray) -> float:
    return float(np.mean(values)) if len(values) else 0.0


#: Per natural palettes and set size: each kind's mean squared z that sets of as many
#: natural photos exceed one time in a hundred.
_NULLS: dict[tuple, np.ndarray] = {}


def _look_evidence(styles: PaletteStatistics, naturals: PaletteStatistics,
                   centre_of: PaletteStatistics, n_styles: int, kinds: int = 3) -> float:
    """How far the styles' median statistics stand from the natural ones, 1 where ungraded
    sets stop: the larger of the mean squared z over all of them (luma quantiles, log chroma
    spreads, neutral tints per band; each z in units of what a median of as many natural
    photos varies by plus the natural spread itself, clipped at :data:`EVIDENCE_CLIP`) and,
    kind by kind, the kind's mean over :data:`NULL_MARGIN` times what random sets of as
    many natural photos reach (their 99th percentile, :data:`NULL_DRAWS` draws).
    ``kinds``: the first so many kinds only (1: tone alone)."""
    nat = _groups(naturals)[:kinds]
    sds = [_robust_sd(v) for v in nat]
    centres = [_nanmedian(v, axis=0) for v in _groups(centre_of)[:kinds]]
    found = [_z2(v, c, sd, n_styles) for v, c, sd in zip(_groups(styles), centres, sds)]
    centres = [_nanmedian(v, axis=0) for v in nat]  # random natural sets about their own
    overall = _mean(np.concatenate(found))
    digest = hashlib.sha1(np.ascontiguousarray(naturals.quantiles).tobytes()).hexdigest()
    key = (digest, naturals.quantiles.shape, n_styles, kinds)
    if key not in _NULLS:
        rng = np.random.default_rng(0)
        k = len(naturals.quantiles)
        draws = [[_mean(_z2(v[idx], c, sd, n_styles)) for v, c, sd in zip(nat, centres, sds)]
                 for idx in (rng.choice(k, min(n_styles, k), replace=False)
                             for _ in range(NULL_DRAWS))]
        _NULLS[key] = np.quantile(np.array(draws), 0.99, axis=0)
    null = NULL_MARGIN * np.maximum(_NULLS[key], 1e-6)
    return max(overall, float(np.max(np.array([_mean(f) for f in found]) / null)))


#: What one of the user's own ungraded photos says of their collection's content, against
#: what the natural photos' median says of it: a median of ``R`` own photos counts as
#: ``OWN_PHOTO_NOISE / R`` natural spreads squared of error (its sampling error, with the
#: heavy tails of a few photos' statistics), the natural photos' as one (:data:`CONTENT_BIAS`:
#: another collection), and the centre the styles are compared with weighs the two
#: inversely (:func:`own_photos_blend`; docs/benchmarks.md).
OWN_PHOTO_NOISE = 5.0


def own_photos_blend(count: int) -> float:
    """Share of the natural photos in the content centre when ``count`` of the user's own
    ungraded photos are given (1 with fewer than :data:`MIN_OWN_PHOTOS`, 0.45 with six, 0.38
    with eight, 0.09 with fifty)."""
    if count < MIN_OWN_PHOTOS:
        return 1.0
    noise = OWN_PHOTO_NOISE / count
    return noise / (noise + CONTENT_BIAS ** 2)


def holds_colour(spread: np.ndarray, space_scale: float = 1.0) -> np.ndarray:
    """(K,) whole-palette chroma spreads -> (K,) whether each palette holds colour (not
    black and white or toned: :data:`MONOCHROME_SPREAD`, scaled to the working space)."""
    return np.asarray(spread) >= MONOCHROME_SPREAD * space_scale


def in_colour(reference: PaletteStatistics | None,
               space_scale: float = 1.0) -> PaletteStatistics | None:
    """The palettes of ``reference`` that hold colour (a black-and-white or toned photo
    says nothing of how colourful ungraded content is), or None when none does."""
    if reference is None:
        return None
    keep = holds_colour(reference.spread, space_scale)
    if keep.all():
        return reference
    if not keep.any():
        return None
    return PaletteStatistics(*(getattr(reference, name)[keep] for name in (
        "quantiles", "band_mass", "band_mean", "band_spread", "spread", "band_neutral")))


def content_centre(naturals: PaletteStatistics, reference: PaletteStatistics | None,
                   own_count: int | None = None) -> PaletteStatistics:
    """What the styles' statistics are compared with: the natural photos' medians, leaned
    towards the user's own photos' (``reference``) by :func:`own_photos_blend` of their
    number (``own_count``: of the whole own set ``reference`` is a part of; one row;
    ``reference`` in colour: :func:`in_colour`)."""
    count = own_count or (0 if reference is None else len(reference.quantiles))
    if reference is None or count < MIN_OWN_PHOTOS:
        return naturals
    blend = own_photos_blend(count)

    def mixed(name: str) -> np.ndarray:  # (a band none of the own photos holds: natural)
        natural = _nanmedian(getattr(naturals, name), axis=0)
        own = _nanmedian(getattr(reference, name), axis=0)
        return np.where(np.isfinite(own), blend * natural + (1.0 - blend) * own, natural)[None]

    return PaletteStatistics(*(mixed(name) for name in (
        "quantiles", "band_mass", "band_mean", "band_spread", "spread", "band_neutral")))


@dataclass(frozen=True)
class StatisticsLook:
    """The look the statistics describe, as functions of lightness.

    Attributes
    ----------
    tone_in, tone_out : (Q + 2,) knots of the monotone tone curve on luma.
    saturation : (B,) chroma scale per input lightness band.
    tint : (B, 3) chroma added per input lightness band.
    monochrome : every style photo is monochrome or toned (saturation 0).
    info : JSON-friendly diagnostics (shrink factors, differences).
    """

    tone_in: np.ndarray
    tone_out: np.ndarray
    saturation: np.ndarray
    tint: np.ndarray
    monochrome: bool
    info: dict

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """(..., 3) colours in [0, 1] -> (..., 3) float64 in [0, 1]."""
        rgb = np.asarray(rgb, dtype=np.float64)
        flat = rgb.reshape(-1, 3)
        luma = flat @ LUMA
        chroma = flat - luma[:, None]
        centres = np.linspace(0.0, 1.0, BANDS)
        new_luma = np.interp(luma, self.tone_in, self.tone_out)
        scale = np.interp(luma, centres, self.saturation)
        shift = np.stack([np.interp(luma, centres, self.tint[:, c]) for c in range(3)], axis=1)
        out = new_luma[:, None] + scale[:, None] * chroma + shift
        return np.clip(out, 0.0, 1.0).reshape(rgb.shape)


def statistics_look(styles: PaletteStatistics, naturals: PaletteStatistics,
                    space_scale: float = 1.0, content_bias: float | None = None,
                    reference: PaletteStatistics | None = None,
                    own_count: int | None = None) -> StatisticsLook:
    """The look the styles' statistics show beyond what natural content varies by.

    Parameters
    ----------
    styles : statistics of the S style palettes.
    naturals : statistics of K natural palettes (K >= 2; more is better), same space.
    space_scale : the working space's colour differences against sRGB-encoded ones
        (scales :data:`MONOCHROME_SPREAD`).
    content_bias : share of the natural spread added to each statistic's uncertainty
        (default :data:`CONTENT_BIAS`; the tone curve's :data:`TONE_BIAS`).
    reference : statistics of the user's own ungraded photos: what content looks like
        in this collection. The centre the styles are compared with leans from the natural
        medians towards theirs as far as their number says (:func:`content_centre`;
        fewer than :data:`MIN_OWN_PHOTOS` are not used); each statistic's uncertainty
        counts the natural share's collection bias and the own share's sampling error.
    own_count : how many own photos the share is weighed by when ``reference`` is a part of
        them (a half's: its centre as far from the natural one as the whole's, twice as
        noisy, so that two halves' looks disagree by the own photos' sampling error too).
    """
    n_styles = len(styles.quantiles)
    unused = 0
    given = 0 if reference is None else len(reference.quantiles)
    reference = in_colour(reference, space_scale)
    if reference is None:
        unused = given
    if reference is not None and (own_count or len(reference.quantiles)) < MIN_OWN_PHOTOS:
        unused, reference = len(reference.quantiles), None
    bias = CONTENT_BIAS if content_bias is None else content_bias
    tone_bias = TONE_BIAS if content_bias is None else content_bias
    n_reference = 0 if reference is None else len(reference.quantiles)
    blend = own_photos_blend((own_count or n_reference) if n_reference else 0)
    monochrome = bool(np.all(styles.spread < MONOCHROME_SPREAD * space_scale))
    # the user's own photos: the centre leans on them as far as their number says (the
    # natural photos' share keeps its collection bias, the own photos' their sampling error)
    centre_of = content_centre(naturals, reference, own_count)
    evidence = None  # weighed only where it may ease the share (and so trust the look)
    if content_bias is None and n_styles >= MIN_EASED_STYLES:
        # a set without colour says nothing of its tone curve's size by lacking colour;
        # measured from the centre the look is
        evidence = _look_evidence(styles, naturals, centre_of, n_styles,
                                  kinds=1 if monochrome else 3)
        eased = 1.0 - (evidence - EVIDENCE_FLOOR) * (1.0 - MIN_CONTENT_BIAS) / EVIDENCE_SPAN
        bias = float(np.clip(eased, MIN_CONTENT_BIAS, bias))
        tone_bias = float(np.clip(eased, MIN_CONTENT_BIAS, tone_bias))
    bias, tone_bias = blend * bias, blend * tone_bias

    def sigma(natural_values: np.ndarray, count: np.ndarray | int,
              share: float | None = None) -> np.ndarray:
        sd = _robust_sd(natural_values)
        count = np.maximum(np.asarray(count, dtype=np.float64), 1.0)
        share = bias if share is None else share
        own = (1 - blend) ** 2 * (MEDIAN_SE * sd) ** 2 / n_reference if n_reference else 0.0
        return np.sqrt((MEDIAN_SE * sd) ** 2 / count + (share * sd) ** 2 + own)

    # tone curve: natural median quantiles -> the styles' median quantiles, shrunk
    nat_q = np.median(centre_of.quantiles, axis=0)
    sty_q = np.median(styles.quantiles, axis=0)
    tone_shift = _shrink(sty_q - nat_q, sigma(naturals.quantiles, n_styles, tone_bias))
    tone_out = np.maximum.accumulate(np.clip(nat_q + tone_shift, 0.0, 1.0))
    tone_in = np.concatenate([[0.0], nat_q, [1.0]])
    tone_out = np.concatenate([[np.clip(tone_shift[0], 0.0, 1.0)], tone_out,
                               [np.clip(1.0 + tone_shift[-1], 0.0, 1.0)]])
    tone_in, keep = np.unique(tone_in, return_index=True)
    tone_out = np.maximum.accumulate(tone_out[keep])

    centres = np.linspace(0.0, 1.0, BANDS)
    mapped = np.interp(centres, tone_in, tone_out)  # where each band's colours land
    valid_styles = np.sum(np.isfinite(styles.band_spread), axis=0)

    # the styles' band statistics read at the lightness the tone curve sends each band to
    def at_mapped(values: np.ndarray) -> np.ndarray:  # (S, B) -> (S, B)
        return _read_at(values, mapped)

    sty_spread = _nanmedian(at_mapped(styles.band_spread), axis=0)
    nat_spread = _nanmedian(centre_of.band_spread, axis=0)
    log_nat = np.log(np.maximum(naturals.band_spread, 1e-4))
    log_ratio = np.log(np.maximum(sty_spread, 1e-4)) - np.log(np.maximum(nat_spread, 1e-4))
    log_ratio = _shrink(log_ratio, sigma(log_nat, valid_styles))
    log_ratio = _fill(np.where(valid_styles >= 2, log_ratio, np.nan), centres)
    saturation = np.zeros(BANDS) if monochrome else np.exp(log_ratio)

    sty_mean = np.stack([_nanmedian(at_mapped(styles.band_mean[..., c]), axis=0)
                         for c in range(3)], axis=-1)               # (B, 3)
    nat_mean = _nanmedian(centre_of.band_mean, axis=0)            # (B, 3)
    nat_mean = np.stack([_fill(nat_mean[:, c], centres) for c in range(3)], axis=-1)
    if monochrome:  # the toning itself: what every style shows (a trace is black and white)
        tint = _shrink(sty_mean, np.full(sty_mean.shape, 0.004 * space_scale))
    elif TINT_FROM == "neutral":  # how the least colourful colours moved
        sty_neutral = np.stack([_nanmedian(at_mapped(styles.band_neutral[..., c]), axis=0)
                                for c in range(3)], axis=-1)
        nat_neutral = _nanmedian(centre_of.band_neutral, axis=0)
        tint = _shrink_vectors(sty_neutral - nat_neutral,
                               sigma(naturals.band_neutral, valid_styles[:, None]))
    else:
        tint = _shrink(sty_mean - saturation[:, None] * nat_mean,
                       sigma(naturals.band_mean, valid_styles[:, None]))
    has = valid_styles >= (1 if monochrome else 2)
    tint = np.stack([_fill(np.where(has & np.isfinite(tint[:, c]), tint[:, c], np.nan)
                           if has.any() else np.zeros(BANDS), centres)
                     for c in range(3)], axis=-1)
    tint -= (tint @ LUMA)[:, None]  # chroma only: the tone curve owns lightness
    info = {"method": "statistics", "monochrome": monochrome,
            "tone_shift": [round(float(v), 4) for v in tone_shift],
            "tone_raw": [round(float(v), 4) for v in sty_q - nat_q],
            "saturation": [round(float(v), 3) for v in saturation],
            "tint": [[round(float(v), 4) for v in row] for row in tint],
            "evidence": None if evidence is None else round(evidence, 3),
            "content_bias": round(bias, 3),
            "styles": n_styles, "naturals": len(naturals.quantiles), "own_photos": n_reference,
            "own_photos_share": round(1.0 - blend, 3), "own_photos_unused": unused}
    return StatisticsLook(tone_in, tone_out, saturation, tint, monochrome, info)


# --------------------------------------------------------------------------- the calibrated look

#: Luma quantiles, log chroma spreads per band and the neutral tint's R and B chroma per
#: band: the statistics a set's look is judged on jointly (:class:`LookDifferences`).
TINT_CHANNELS = (0, 2)


@dataclass(frozen=True)
class LookDifferences:
    """How a set's median statistics differ from content's (no shrinking).

    Attributes
    ----------
    centre_quantiles : (Q,) the content's median luma quantiles (the tone curve's input).
    tone : (Q,) the styles' median quantiles minus those.
    saturation : (B,) log of the styles' median chroma spread over content's, per band
        (read at the lightness the tone curve sends each band to).
    tint : (B, 3) the styles' median neutral tint minus content's, per band (chroma).
    """

    centre_quantiles: np.ndarray
    tone: np.ndarray
    saturation: np.ndarray
    tint: np.ndarray

    def vector(self) -> np.ndarray:
        """(Q + 3 B,) the differences as one vector (tint: R and B chroma; G follows)."""
        return np.concatenate([self.tone, self.saturation,
                               self.tint[:, TINT_CHANNELS].ravel()])

    def with_vector(self, vector: np.ndarray) -> LookDifferences:
        """The same centre with differences read from :meth:`vector`'s layout."""
        q, b = len(self.tone), len(self.saturation)
        tint = np.zeros((b, 3))
        tint[:, TINT_CHANNELS] = np.asarray(vector[q + b:]).reshape(b, len(TINT_CHANNELS))
        others = [c for c in range(3) if c not in TINT_CHANNELS][0]
        tint[:, others] = -(tint[:, TINT_CHANNELS] @ LUMA[list(TINT_CHANNELS)]) / LUMA[others]
        return LookDifferences(self.centre_quantiles, np.asarray(vector[:q]),
                               np.asarray(vector[q:q + b]), tint)


def _tone_curve(centre_q: np.ndarray, shift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Knots (in, out) of the monotone tone curve moving ``centre_q`` by ``shift``."""
    tone_out = np.maximum.accumulate(np.clip(centre_q + shift, 0.0, 1.0))
    tone_in = np.concatenate([[0.0], centre_q, [1.0]])
    tone_out = np.concatenate([[np.clip(shift[0], 0.0, 1.0)], tone_out,
                               [np.clip(1.0 + shift[-1], 0.0, 1.0)]])
    tone_in, keep = np.unique(tone_in, return_index=True)
    return tone_in, np.maximum.accumulate(tone_out[keep])


def look_differences(styles: PaletteStatistics, centre_of: PaletteStatistics,
                     monochrome: bool = False, min_styles: int = 2) -> LookDifferences:
    """The raw differences of the styles' median statistics from ``centre_of``'s
    medians (bands fewer than ``min_styles`` styles hold are filled from their
    neighbours)."""
    nat_q = _nanmedian(centre_of.quantiles, axis=0)
    tone = _nanmedian(styles.quantiles, axis=0) - nat_q
    tone_in, tone_out = _tone_curve(nat_q, tone)
    centres = np.linspace(0.0, 1.0, BANDS)
    mapped = np.interp(centres, tone_in, tone_out)
    valid = np.sum(np.isfinite(styles.band_spread), axis=0)

    def at_mapped(values: np.ndarray) -> np.ndarray:  # (S, B) -> (S, B)
        return _read_at(values, mapped)

    sty_spread = _nanmedian(at_mapped(styles.band_spread), axis=0)
    nat_spread = _nanmedian(centre_of.band_spread, axis=0)
    ratio = np.log(np.maximum(sty_spread, 1e-4)) - np.log(np.maximum(nat_spread, 1e-4))
    ratio = _fill(np.where(valid >= min_styles, ratio, np.nan), centres)
    if monochrome:
        tint = np.zeros((BANDS, 3))
    else:
        sty = np.stack([_nanmedian(at_mapped(styles.band_neutral[..., c]), axis=0)
                        for c in range(3)], axis=-1)
        tint = sty - _nanmedian(centre_of.band_neutral, axis=0)
        tint = np.stack([_fill(np.where((valid >= min_styles) & np.isfinite(tint[:, c]),
                                        tint[:, c],
                                        np.nan), centres) for c in range(3)], axis=-1)
        tint -= (tint @ LUMA)[:, None]
    return LookDifferences(nat_q, tone, ratio, tint)


def look_from_differences(differences: LookDifferences, monochrome: bool = False,
                          info: dict | None = None) -> StatisticsLook:
    """The :class:`StatisticsLook` the (shrunk) differences describe."""
    tone_in, tone_out = _tone_curve(differences.centre_quantiles, differences.tone)
    saturation = np.zeros(BANDS) if monochrome else np.exp(differences.saturation)
    return StatisticsLook(tone_in, tone_out, saturation, differences.tint, monochrome,
                          dict(info or {}))
