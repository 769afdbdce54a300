"""Looks: the global colour map a set of graded photos share, apart from their content.

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

The map family (:class:`LookMap`) is what a colourist's look is made of:
each output channel is the input channel plus a sum of smooth 1-D curves of
R, G, B and luma (``T_o(x) = x_o + sum_c f_oc(x_c) + g_o(Y)``). It holds
per-channel tone curves, any 3x3 matrix (saturation, white balance), an
ASC CDL grade followed by saturation exactly, and split toning by lightness
closely; it cannot repaint one hue into an unrelated one, so a look fitted
to a few style photos stays a look.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from wbcgrade.color.histogram import add_floor, grid_points, soft_histogram
from wbcgrade.color.look_statistics import LUMA
from wbcgrade.color.look_statistics import hats as _hats
from wbcgrade.color.remap import interpolate_lattice, resample_lattice

__all__ = ["LookMap", "fit_look_map", "push_histogram", "relaxed_correspondences",
           "LookResult", "extract_look", "look_coordinates", "PairFit", "fit_pair",
           "PhotoLook", "photo_look", "SceneLook", "fit_scene_look", "find_scene_look",
           "fit_correction", "fit_pairs_look",
           "set_look_base", "set_look_halves", "look_reliability"]


#: Knots of each 1-D curve, evenly spaced on [0, 1].
DEFAULT_KNOTS = 9

#: Settings chosen on ``benchmarks/look.py``: plan kernel (bins of a 32^3 grid),
#: KL relaxation of both marginals, curve smoothness and pull towards the prior
#: (of a pair's look: :func:`fit_pair`).
DEFAULT_WIDTH = 1.0
DEFAULT_RELAXATION = 0.01
DEFAULT_SMOOTHNESS = 0.03
DEFAULT_RIDGE = 0.01
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


@dataclass(frozen=True)
class LookMap:
    """A smooth global colour map: identity plus curves of R, G, B and luma per channel.

    ``T_o(x) = x_o + sum_j coefficients[o, j] * features_j(x)`` with the
    features the hat functions of each of R, G, B and luma (``knots`` each).

    Attributes
    ----------
    coefficients : (3, 4 * knots) float64; all zero is the identity.
    knots : knots per curve.
    """

    coefficients: np.ndarray
    knots: int = DEFAULT_KNOTS

    @classmethod
    def identity(cls, knots: int = DEFAULT_KNOTS) -> LookMap:
        return cls(np.zeros((3, 4 * knots)), knots)

    @staticmethod
    def features(rgb: np.ndarray, knots: int = DEFAULT_KNOTS) -> np.ndarray:
        """(N, 3) colours in [0, 1] -> (N, 4 * knots) feature matrix."""
        rgb = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
        luma = rgb @ LUMA
        return np.concatenate([_hats(rgb[:, 0], knots), _hats(rgb[:, 1], knots),
                               _hats(rgb[:, 2], knots), _hats(luma, knots)], axis=1)

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """Map colours: (..., 3) in [0, 1] -> (..., 3) float64 in [0, 1]."""
        rgb = np.asarray(rgb, dtype=np.float64)
        flat = rgb.reshape(-1, 3)
        out = flat + self.features(flat, self.knots) @ self.coefficients.T
        return np.clip(out, 0.0, 1.0).reshape(rgb.shape)

    def lattice(self, size: int = 33) -> np.ndarray:
        """The map sampled as a (size, size, size, 3) float32 lattice LUT (R slowest)."""
        return self(grid_points(size)).reshape(size, size, size, 3).astype(np.float32)

    def amplitude(self, size: int = 17) -> float:
        """Mean displacement |T(x) - x| over the colour cube (0 for the identity)."""
        points = grid_points(size)
        return float(np.mean(np.linalg.norm(self(points) - points, axis=1)))


def _second_difference(knots: int) -> np.ndarray:
    d = np.zeros((knots - 2, knots))
    for i in range(knots - 2):
        d[i, i:i + 3] = (1.0, -2.0, 1.0)
    return d


def fit_look_map(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                 prior: LookMap | None = None, smoothness: float = 3e-3,
                 ridge: float = 1e-3, knots: int = DEFAULT_KNOTS) -> LookMap:
    """The :class:`LookMap` that best moves ``sources`` onto ``targets`` (weighted least squares).

    Minimises ``sum_i w_i |T(x_i) - y_i|^2 + ridge |theta - theta_prior|^2
    + smoothness |D2 theta|^2`` (``D2``: second differences along each curve;
    the weights are normalised to sum 1, so both penalties are in colour
    units squared whatever the number of points).

    Parameters
    ----------
    sources, targets : (N, 3) colours in [0, 1].
    weights : (N,) non-negative.
    prior : the map the ridge pulls towards (default the identity).
    """
    sources = np.asarray(sources, dtype=np.float64).reshape(-1, 3)
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    weights = np.asarray(weights, dtype=np.float64).ravel()
    total = weights.sum()
    if not total > 0:
        return prior if prior is not None else LookMap.identity(knots)
    weights = weights / total
    if prior is None or prior.knots != knots:
        prior = LookMap.identity(knots)
    features = LookMap.features(sources, knots)
    n_features = features.shape[1]
    weighted = features * weights[:, None]
    gram = features.T @ weighted
    d2 = _second_difference(knots)
    block = d2.T @ d2
    penalty = np.zeros((n_features, n_features))
    for g in range(4):
        sl = slice(g * knots, (g + 1) * knots)
        penalty[sl, sl] = smoothness * block
    system = gram + penalty + ridge * np.eye(n_features)
    rhs = weighted.T @ (targets - sources) + ridge * prior.coefficients.T
    coefficients = np.linalg.solve(system, rhs).T
    return LookMap(coefficients, knots)


def push_histogram(hist: np.ndarray, look: LookMap, bins: int | None = None) -> np.ndarray:
    """The histogram of the colours of ``hist`` moved through ``look`` (soft binning).

    (n, n, n) -> (bins, bins, bins), default ``bins = n``; sums to 1.
    """
    n = hist.shape[0]
    flat = hist.ravel()
    keep = np.flatnonzero(flat > 0)
    points = grid_points(n)[keep]
    return soft_histogram(look(points), bins or n, flat[keep])


def relaxed_correspondences(source: np.ndarray, target: np.ndarray, width: float = 1.5,
                            relaxation: float = 0.01, n_iter: int = 300,
                            floor: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Where each colour of ``source`` goes under unbalanced transport to ``target``.

    Entropic transport on the (n, n, n) grid with both marginals relaxed by
    ``relaxation * KL`` (scalings raised to ``rho / (rho + gamma)``; Chizat et
    al. 2018), solved in the log domain.

    Parameters
    ----------
    source, target : (n, n, n) histograms.
    width : kernel standard deviation in bins.

    Returns
    -------
    projection : (n, n, n, 3) barycentric projection ``(K (b x)) / (K b)`` of every bin.
    kept : (n, n, n) share of each source bin's mass the plan moves (0..~1).
    """
    from wbcgrade.core import GridGeometry

    n = source.shape[0]
    geometry = GridGeometry.with_width((n,) * 3, width)
    tau = relaxation / (relaxation + geometry.gamma)
    log_p = np.log(add_floor(source / source.sum(), floor))
    log_q = np.log(add_floor(target / target.sum(), floor))
    f = np.zeros_like(log_p)
    g = np.zeros_like(log_q)
    for _ in range(n_iter):
        f_new = tau * (log_p - geometry.log_apply(g))
        g = tau * (log_q - geometry.log_apply(f_new))
        change = np.max(np.abs(f_new - f))
        f = f_new
        if change < 1e-6:
            break
    log_kb = geometry.log_apply(g)
    axis = np.linspace(0.0, 1.0, n)
    shifted = [axis.reshape(shape) + 1.0 for shape in ((n, 1, 1), (1, n, 1), (1, 1, n))]
    projection = np.stack(
        [np.exp(geometry.log_apply(g + np.log(np.broadcast_to(s, g.shape))) - log_kb) - 1.0
         for s in shifted], axis=-1)
    kept = np.exp(f + log_kb - log_p)
    return np.clip(projection, 0.0, 1.0), np.clip(kept, 0.0, 1.0)


def _fit_geometry(bins: int):
    from wbcgrade.core import GridGeometry

    return GridGeometry((bins,) * 3, 2.0 * (1.5 / (bins - 1)) ** 2)


def look_coordinates(target: np.ndarray, palettes: np.ndarray, floor: float = 1e-4,
                     max_iter: int = 15) -> tuple[np.ndarray, float]:
    """KL barycentric coordinates of ``target`` (m, m, m) over ``palettes`` (K, m, m, m).

    Returns (weights (K,), loss).
    """
    from wbcgrade.core import barycentric_coordinates

    bins = target.shape[0]
    result = barycentric_coordinates(
        add_floor(target, floor), np.stack([add_floor(h, floor) for h in palettes]),
        _fit_geometry(bins), loss="kl", n_iter=30, max_iter=max_iter, tol=1e-5)
    return np.asarray(result.weights, dtype=np.float64), float(result.loss)


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
    from wbcgrade.core import barycenter

    look = initial or LookMap.identity(knots)
    n_styles = len(styles[fit_bins])
    natural_map = naturals[map_bins]
    style_weights = (np.ones(n_styles) if style_weights is None
                     else np.asarray(style_weights, dtype=np.float64))
    geometry = _fit_geometry(map_bins)
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
            points, moved_to, mass, _ = _correspondences(content, styles[map_bins][m], look,
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
    import hashlib

    from wbcgrade.core import barycenter

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


def _correspondences(photo: np.ndarray, style: np.ndarray, look: LookMap, width: float,
                     relaxation: float):
    """Colours of ``photo`` (n^3 grid), where ``look`` then the relaxed plan to ``style`` send
    them, and the mass each moved: (points (N, 3), targets (N, 3), mass (N,), moved (N, 3))."""
    n = photo.shape[0]
    flat = photo.ravel()
    used = np.flatnonzero(flat > 1e-7)
    points = grid_points(n)[used]
    moved = look(points)
    projection, kept = relaxed_correspondences(push_histogram(photo, look), style, width,
                                               relaxation)
    mass = flat[used] * interpolate_lattice(kept[..., None], moved)[:, 0]
    return points, interpolate_lattice(projection, moved), mass, moved


@dataclass(frozen=True)
class PairFit:
    """The look that moves one photo's palette onto one style's.

    Attributes
    ----------
    look : the fitted map.
    residual : mean squared distance (colour units) still left between the
        photo's colours after the map and where the relaxed plan sends them:
        small when the style is the photo's own scene in some look.
    kept : share of the photo's mass the relaxed plan moved.
    overlap : shared mass of the mapped photo's histogram and the style's
        (each blurred by half a bin; 1 = the same palette): high when the
        style shows the photo's own scene.
    """

    look: LookMap
    residual: float
    kept: float
    overlap: float = 0.0


def fit_pair(photo: np.ndarray, style: np.ndarray, prior: LookMap | None = None,
             rounds: int = 2, width: float = DEFAULT_WIDTH,
             relaxation: float = DEFAULT_RELAXATION, smoothness: float = DEFAULT_SMOOTHNESS,
             ridge: float = DEFAULT_RIDGE) -> PairFit:
    """Fit the look taking a photo's palette to a style palette (same (n, n, n) grid).

    Starts at ``prior`` (default identity) and alternates ``rounds`` times a
    relaxed plan from the mapped palette to the style and a refit of the map
    (pulled towards ``prior`` by ``ridge``).
    """
    prior = prior or LookMap.identity()
    look = prior
    for _ in range(rounds):
        points, targets, mass, _ = _correspondences(photo, style, look, width, relaxation)
        look = fit_look_map(points, targets, mass, prior, smoothness, ridge, prior.knots)
    _, targets, mass, moved = _correspondences(photo, style, look, width, relaxation)
    total = max(float(mass.sum()), 1e-300)
    residual = float(np.sum(mass * np.sum((targets - moved) ** 2, axis=1)) / total)
    return PairFit(look, residual, float(mass.sum() / photo.sum()),
                   _overlap(push_histogram(photo, look), style))


def _overlap(first: np.ndarray, second: np.ndarray, blur: float = 0.5) -> float:
    """Shared mass of two histograms, each blurred by ``blur`` bins and normalised."""
    from scipy.ndimage import gaussian_filter

    a = gaussian_filter(first / first.sum(), blur, mode="constant")
    b = gaussian_filter(second / second.sum(), blur, mode="constant")
    return float(np.minimum(a / a.sum(), b / b.sum()).sum())


@dataclass(frozen=True)
class PhotoLook:
    """The look for one photo: the set's look, corrected towards its own scene when found.

    Attributes
    ----------
    look : the map to apply.
    match : index of the style whose scene fits the photo best.
    confidence : in [0, 1], how far the correction towards that style was taken.
    residuals : (S,) :attr:`PairFit.residual` of every style.
    overlap : :attr:`PairFit.overlap` of the match.
    """

    look: LookMap
    match: int
    confidence: float
    residuals: np.ndarray
    overlap: float = 0.0

    @property
    def weights(self) -> np.ndarray:
        """(S,) weight of each style in the grade: ``confidence`` on the match, rest shared."""
        n = len(self.residuals)
        weights = np.full(n, (1.0 - self.confidence) / n)
        weights[self.match] += self.confidence
        return weights


#: Match ratio (best residual over the median of the others) at or above which
#: no style counts as the photo's own scene, and at or below which one surely does.
UNSURE_RATIO = 0.75
SURE_RATIO = 0.35
#: Overlap of the mapped photo's palette with the match's at or below which the
#: match is not the photo's scene, and at or above which it surely is
#: (``benchmarks/look.py``: framings of one scene 0.4-0.8, other scenes 0.0-0.57).
UNSURE_OVERLAP = 0.55
SURE_OVERLAP = 0.65


def photo_look(photo: np.ndarray, styles: np.ndarray, set_look: LookMap | None = None,
               **fit_options) -> PhotoLook:
    """The look to apply to a photo graded towards a style set.

    Every style gets a :func:`fit_pair` from the photo starting at the set's
    look; the style left with the smallest residual is the photo's scene
    candidate. How sure that is: the product of two ramps, one on its
    residual against the others' (ratio to their median: ``SURE_RATIO`` or
    less is sure, ``UNSURE_RATIO`` or more is not) and one on how much of
    the mapped palette it shares (``UNSURE_OVERLAP`` .. ``SURE_OVERLAP``). A
    wrong match repaints the photo, so both must agree. The map moves from
    the set's look towards that pair's look by the confidence (coefficients
    blended: the family is linear).

    Parameters
    ----------
    photo : (n, n, n) the photo's histogram.
    styles : (S, n, n, n) the style histograms on the same grid.
    set_look : the set's look (:func:`extract_look`; default identity).
    """
    set_look = set_look or LookMap.identity()
    fits = [fit_pair(photo, style, set_look, **fit_options) for style in styles]
    residuals = np.array([fit.residual for fit in fits])
    match = int(np.argmin(residuals))
    if len(fits) > 1:
        ratio = residuals[match] / max(float(np.median(np.delete(residuals, match))), 1e-300)
        sure_of_ratio = np.clip((UNSURE_RATIO - ratio) / (UNSURE_RATIO - SURE_RATIO), 0.0, 1.0)
    else:
        sure_of_ratio = 1.0
    overlap = fits[match].overlap
    sure_of_overlap = np.clip((overlap - UNSURE_OVERLAP) / (SURE_OVERLAP - UNSURE_OVERLAP),
                              0.0, 1.0)
    confidence = float(sure_of_ratio * sure_of_overlap)
    chosen = fits[match].look
    coefficients = set_look.coefficients + confidence * (chosen.coefficients
                                                         - set_look.coefficients)
    return PhotoLook(LookMap(coefficients, set_look.knots), match, confidence, residuals,
                     overlap)


# --------------------------------------------------------------------------- the photo's own scene


@dataclass(frozen=True)
class SceneLook:
    """The look read off style photos that show the photo's own scene.

    Attributes
    ----------
    look : the map family fitted to the colour pairs of the overlaps.
    matches : {style index: agreeing keypoints} of the styles that show the scene.
    confidence : in [0, 1], how far the grade follows this look rather than the set's.
    residual : median distance (colour units) left between the pairs after ``look``.
    pairs : colour pairs the fit used.
    correction : (m, m, m, 3) smooth displacement lattice added after ``look``
        (what the family cannot hold; zero where no pair says otherwise), or None.
    """

    look: LookMap
    matches: dict
    confidence: float
    residual: float
    pairs: int
    correction: np.ndarray | None = None

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """Map colours: (..., 3) in [0, 1] -> (..., 3) float64 in [0, 1]."""
        mapped = self.look(rgb)
        if self.correction is None:
            return mapped
        flat = mapped.reshape(-1, 3)
        moved = flat + interpolate_lattice(self.correction, flat)
        return np.clip(moved, 0.0, 1.0).reshape(mapped.shape)

    def lattice(self, size: int = 33) -> np.ndarray:
        """The map sampled as a (size, size, size, 3) float32 lattice LUT (R slowest)."""
        return self(grid_points(size)).reshape(size, size, size, 3).astype(np.float32)


def fit_correction(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                   nodes: int = 9, smoothness: float = 1e-3, ridge: float = 1e-6) -> np.ndarray:
    """The smooth displacement lattice that best moves ``sources`` onto ``targets``.

    Minimises ``sum_i w_i |x_i + D(x_i) - y_i|^2 + smoothness |L D|^2 + ridge |D|^2``
    over the (nodes, nodes, nodes, 3) lattice ``D`` read trilinearly (``L``:
    second differences along each axis; weights normalised to sum 1). Solved
    as one sparse system (scipy.sparse).
    """
    import scipy.sparse as sparse
    from scipy.sparse.linalg import splu

    from wbcgrade.color.smooth_map import interpolation_matrix

    weights = np.asarray(weights, dtype=np.float64) / max(float(np.sum(weights)), 1e-300)
    interpolate = interpolation_matrix(np.asarray(sources, dtype=np.float64), nodes)
    second = sparse.diags([np.ones(nodes - 1), -2.0 * np.ones(nodes), np.ones(nodes - 1)],
                          [-1, 0, 1], shape=(nodes, nodes)).tolil()
    second[0, :] = 0.0
    second[nodes - 1, :] = 0.0
    second = second.tocsr()
    eye = sparse.identity(nodes, format="csr")
    curvature = (sparse.kron(sparse.kron(second, eye), eye)
                 + sparse.kron(sparse.kron(eye, second), eye)
                 + sparse.kron(sparse.kron(eye, eye), second))
    weighted = interpolate.T @ sparse.diags(weights)
    system = (weighted @ interpolate + smoothness * (curvature.T @ curvature)
              + ridge * sparse.identity(nodes ** 3)).tocsc()
    solve = splu(system)
    moves = np.asarray(targets, dtype=np.float64) - sources
    correction = np.stack([solve.solve(weighted @ moves[:, c]) for c in range(3)], axis=-1)
    return correction.reshape(nodes, nodes, nodes, 3)


#: Median pair residual (colour units) at or below which the matched scene fits
#: surely, and at or above which the overlap is not one look of one scene
#: (moved content, another place that happens to share keypoints).
SURE_RESIDUAL = 0.04
UNSURE_RESIDUAL = 0.10
#: Pull of the scene fit towards its prior and smoothness of its curves (pairs
#: are plentiful: the prior only fills colours the overlap lacks).
SCENE_RIDGE = 1e-3
SCENE_SMOOTHNESS = 3e-3


def fit_scene_look(photo, styles: Sequence, prior: LookMap | None = None,
                   rounds: int = 3, correct: bool = True,
                   why: dict[int, str] | None = None) -> SceneLook | None:
    """Fit the look on pixel pairs of the style photos that show the photo's scene.

    Parameters
    ----------
    photo : :class:`~wbcgrade.color.scene.SceneImage` of the photo.
    styles : a SceneImage (or None) per style.
    prior : the map the fit falls back on for colours no overlap shows
        (default identity).
    rounds : robust refits (pairs far from the fit, e.g. content that moved
        between the shots, weigh less each round).
    correct : add the smooth lattice correction (:func:`fit_correction`, 9^3)
        for what the map family cannot hold (measured on ``benchmarks/look.py``'s
        shot matching: +0.05 to +0.2 recovered on film and bleach-bypass looks).

    why : filled with the reason each style (by index) does not show the scene.

    Returns None when no style shows the scene.
    """
    from wbcgrade.color.scene import colour_pairs, match_scene, mirrored, unmirror

    prior = prior or LookMap.identity()
    matches = {}
    for index, style in enumerate(styles):
        if style is None:
            continue
        reasons: list[str] = []
        match = match_scene(photo, style, why=reasons)
        if match is None:
            if why is not None and reasons:
                why[index] = reasons[0]
            continue
        matches[index] = match
    if any(style is not None for style in styles):  # a flipped framing (or a symmetric
        flipped, width = mirrored(photo), photo.colors.shape[1]  # scene matched wrong way)?
        for index, style in enumerate(styles):
            match = match_scene(flipped, style) if style is not None else None
            if match is not None and match.inliers > getattr(matches.get(index), "inliers", 0):
                matches[index] = unmirror(match, width)
                if why is not None:
                    why.pop(index, None)
    parts = []
    for index, match in matches.items():
        sources, targets, weights = colour_pairs(photo, styles[index], match)
        parts.append((sources, targets, weights * match.sureness / max(len(weights), 1)))
    if not matches or not any(p[2].sum() > 0 for p in parts):
        return None
    sources, targets, weights = (np.concatenate(column) for column in zip(*parts))
    fitted, _ = fit_pairs_look(sources, targets, weights, prior, rounds, correct)
    sure_of_pairs = float(np.clip((UNSURE_RESIDUAL - fitted.residual)
                                  / (UNSURE_RESIDUAL - SURE_RESIDUAL), 0.0, 1.0))
    sureness = max(match.sureness for match in matches.values())
    return replace(fitted, matches={i: m.inliers for i, m in matches.items()},
                   confidence=sureness * sure_of_pairs)


def fit_pairs_look(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                   prior: LookMap | None = None, rounds: int = 3, correct: bool = True,
                   robust: np.ndarray | None = None) -> tuple[SceneLook, np.ndarray]:
    """The look of colour pairs (before, after): the map family, robustly, and its correction.

    What :func:`fit_scene_look` fits to the pairs of a matched scene (and
    ``wbcgrade look learn`` to a photographer's before/after pairs): the
    :class:`LookMap` refitted ``rounds`` times with Cauchy weights (pairs far
    from the fit, such as content that moved or a local edit, weigh less each
    round), then the smooth lattice correction (:func:`fit_correction`, 9^3)
    of what the family cannot hold.

    Parameters
    ----------
    sources, targets : (N, 3) colours in [0, 1].
    weights : (N,) non-negative.
    prior : the map the ridge pulls towards (default identity).
    robust : (N,) weights to start from instead of ``weights`` (a previous
        fit's robust weights: the rounds go on from there).

    Returns
    -------
    look : :class:`SceneLook` (no matches, confidence 1).
    robust : (N,) the final robust weights.
    """
    from wbcgrade.core import fast_cpu

    prior = prior or LookMap.identity()
    look, robust = prior, (weights if robust is None else robust)
    with fast_cpu():  # small products: OpenBLAS's threads cost 10-80x on a busy machine
        for _ in range(rounds):
            look = fit_look_map(sources, targets, robust, prior, SCENE_SMOOTHNESS, SCENE_RIDGE,
                                prior.knots)
            distance = np.linalg.norm(look(sources) - targets, axis=1)
            scale = max(float(np.median(distance)), 1e-3)
            robust = weights / (1.0 + (distance / (2.0 * scale)) ** 2)  # Cauchy
        mapped = look(sources)
        residual = float(np.median(np.linalg.norm(mapped - targets, axis=1)))
        correction = fit_correction(mapped, targets, robust) if correct else None
    return SceneLook(look, {}, 1.0, residual, int(len(sources)), correction), robust


# --------------------------------------------------------------------------- grading with looks

#: Strength of the set's own look when the set has a single style (no halves to
#: compare; :func:`set_look_base` takes the look's reliability otherwise). Chosen
#: when every set's look was applied at one strength (benchmarks/look.py,
#: cross-content, 36 photos at 768 px, relaxation 0.01: 0.7 / 0.85 / 1.0
#: recovered +0.10 / +0.12 / +0.13, worst photo -0.11 / -0.18 / -0.27).
SET_LOOK_STRENGTH = 0.7

#: The per-photo correction towards the photo's own scene (when a style shows
#: it): the palette grade with this loss and relaxation (benchmarks/look.py,
#: shot matching: KL with rho = 0.01 recovers +0.33 against -0.05 for the
#: quadratic, balanced fit).
SCENE_LOSS = "kl"
SCENE_RELAXATION = 0.01

#: Grids of the look fits: coordinates on 16^3, plans and maps on 32^3.
FIT_BINS = 16
MAP_BINS = 32


def load_naturals(natural: str | None, working_space: str):
    """The content model a command names: ``natural`` a preset file (.npz) of natural
    palettes, a folder of the user's own ungraded photos (their statistics say what
    content looks like in their collection; the shipped palettes how much it varies:
    ``meta["own"]``), or None (the shipped palettes); in ``working_space``."""
    from pathlib import Path

    from wbcgrade.color.presets import load_preset, load_style_folder, styles_in_space

    if natural is not None and Path(natural).is_dir():
        from wbcgrade.color.histogram import HistogramCache

        own = load_style_folder(natural, MAP_BINS, cache=HistogramCache(),
                                working_space=working_space)
        naturals = styles_in_space(natural_palettes(), working_space)
        return type(naturals)(naturals.names, naturals.histograms, naturals.source,
                              naturals.width, naturals.description,
                              {**naturals.meta, "own": own})
    naturals = load_preset(natural) if natural else natural_palettes()
    return styles_in_space(naturals, working_space)


def natural_palettes(exclude: set[str] | frozenset[str] = frozenset()):
    """The shipped palettes of ungraded photos (a :class:`~wbcgrade.color.presets.StyleSet`).

    Built by ``python -m wbcgrade.color.natural`` from photos whose licences
    allow it (``wbcgrade/color/data/NATURAL.md`` names them); ``exclude``
    leaves photos out by name (a benchmark holds out the photos it grades).
    """
    from wbcgrade.color.presets import StyleSet, load_preset

    styles = load_preset(_natural_path())
    keep = [i for i, name in enumerate(styles.names) if name not in exclude]
    if len(keep) == len(styles.names):
        return styles
    return StyleSet([styles.names[i] for i in keep], styles.histograms[keep], styles.source,
                    styles.width, styles.description, dict(styles.meta))


def _natural_path():
    from pathlib import Path

    return Path(__file__).with_name("data") / "natural.npz"


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
    import hashlib

    naturals = naturals if naturals is not None else natural_palettes()
    digest = hashlib.sha1()
    own = naturals.meta.get("own")
    digest.update(np.ascontiguousarray(styles.at_bins(FIT_BINS), dtype=np.float64).tobytes())
    for palettes in (naturals, *([own] if own is not None else [])):
        digest.update(_palettes_digest(palettes).encode())
    # the settings too: a look cached under other settings (an experiment's) is not reused
    digest.update(repr((LOOK_VERSION, FIT_BINS, MAP_BINS, SET_RELAXATION, SET_RIDGE,
                        DEFAULT_CONTENT_SHRINK, DEFAULT_WIDTH, DEFAULT_SMOOTHNESS,
                        DEFAULT_KNOTS, SET_LOOK_METHOD, statistics_settings())).encode())
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
    return _SET_LOOKS[key]


#: Bumped when extraction changes, so cached looks of an older version are not used.
LOOK_VERSION = 8

#: How a set's look is found: "statistics" (:func:`statistics_set_look`: statistics
#: content hardly moves, against the natural palettes' spread) or "transport"
#: (:func:`extract_look`: relaxed plans from the natural barycenter, pooled).
SET_LOOK_METHOD = "statistics"

_NATURAL_STATISTICS: dict[str, object] = {}


def statistics_settings() -> tuple:
    """The settings of :mod:`wbcgrade.color.look_statistics` a set's look depends on."""
    from wbcgrade.color import look_statistics as stats

    return (stats.CONTENT_BIAS, stats.TONE_BIAS, stats.NEUTRAL_SHARE, stats.MONOCHROME_SPREAD,
            stats.BANDS, tuple(stats.QUANTILES), stats.TINT_FROM, stats.MIN_BAND_MASS)


_DIGESTS: dict[int, tuple[object, str]] = {}
_STAT_FIELDS = ("quantiles", "band_mass", "band_mean", "band_spread", "spread", "band_neutral")


def _palettes_digest(palettes) -> str:
    """A digest of a StyleSet's histograms (as stored: no re-binning), once per array."""
    import hashlib

    hists = palettes.histograms
    meta = getattr(palettes, "meta", {}) or {}
    if "file_digest" in meta:  # a preset file, in a working space: no need to hash arrays
        return (f"{meta['file_digest']}|{meta.get('working_space', '')}|"
                f"{meta.get('converted_from', '')}|{hists.shape}")
    known = _DIGESTS.get(id(hists))
    if known is None or known[0] is not hists:
        digest = hashlib.sha1(repr((hists.shape, str(hists.dtype))).encode())
        digest.update(np.ascontiguousarray(hists).tobytes())
        known = _DIGESTS[id(hists)] = (hists, digest.hexdigest())
    return known[1]


def _natural_statistics(naturals, cache_from=None):
    """:func:`~wbcgrade.color.look_statistics.palette_statistics` of the natural palettes,
    once per process and set of palettes, and kept on disk in the looks' cache folder
    (``cache_from``: the StyleSet whose cache settings apply; a damaged entry is rebuilt)."""
    from wbcgrade.color.look_statistics import QUANTILES, PaletteStatistics, palette_statistics

    key = _palettes_digest(naturals) + repr(statistics_settings())
    if key in _NATURAL_STATISTICS:
        return _NATURAL_STATISTICS[key]
    import hashlib

    name = "natural-" + hashlib.sha1(key.encode()).hexdigest()
    path = _look_cache_path(name, cache_from)
    from wbcgrade.color.cache import read_entry, write_entry

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
    (:func:`wbcgrade.color.look_statistics.statistics_look`), fitted into the
    :class:`LookMap` family on the colours natural photos hold (and, less, all others).

    Parameters
    ----------
    styles, naturals : StyleSets in one working space.
    """
    from wbcgrade.color.histogram import resample_histogram
    from wbcgrade.color.look_statistics import (
        palette_statistics,
        statistics_look,
        tinted_statistics,
    )

    natural_stats = _natural_statistics(naturals, styles)
    own = naturals.meta.get("own")
    reference = palette_statistics(own.at_bins(MAP_BINS)) if own is not None else None
    # re-binned from a finer grid, the styles' colours were binned twice (a trace of chroma
    # in a black-and-white set's histograms): both are taken off the chroma spread
    style_hists = styles.at_bins(MAP_BINS)
    model = statistics_look(tinted_statistics(style_hists, natural_stats, reference,
                                              source_bins=styles.bins),
                            natural_stats, _space_scale(styles.working_space),
                            reference=reference)
    size = 17
    points = grid_points(size)
    density = resample_histogram(naturals.at_bins(MAP_BINS).mean(axis=0), size).ravel()
    weights = density / density.sum() + 0.25 / len(points)
    look = fit_look_map(points, model(points), weights, None, 1e-4, 1e-6, knots)
    n_styles, n_naturals = len(styles.names), len(naturals.names)
    info = {**model.info, "amplitude": look.amplitude()}
    return LookResult(look, np.full((n_styles, n_naturals), 1.0 / max(n_naturals, 1)),
                      np.full(n_styles, np.nan), info)


def _styles_subset(styles, indices):
    """The styles at ``indices`` as a StyleSet of their own (histograms, space, cache)."""
    from wbcgrade.color.presets import StyleSet

    indices = list(indices)
    meta = {k: v for k, v in styles.meta.items() if k in ("working_space", "cache_dir")}
    return StyleSet([styles.names[i] for i in indices], styles.histograms[indices],
                    styles.source, styles.width, styles.description, meta)


def set_look_halves(styles, naturals=None) -> tuple[LookMap, LookMap] | None:
    """The looks of the two halves of a style set (styles 0, 2, 4, ... and 1, 3, 5, ...),
    each extracted as :func:`set_look` does (and cached the same way); None under 2 styles."""
    n = len(styles.names)
    if n < 2:
        return None
    first, second = (set_look(_styles_subset(styles, range(h, n, 2)), naturals).look
                     for h in (0, 1))
    return first, second


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
    ``looks/`` in the styles' cache folder (:func:`wbcgrade.color.cache.cache_folder`);
    None when the command said ``--no-cache``."""
    from wbcgrade.color.cache import cache_folder, entry_path

    return entry_path(cache_folder(styles), "looks", key)


def _read_cached_look(key: str, styles=None) -> LookResult | None:
    import json

    from wbcgrade.color.cache import read_entry

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

    from wbcgrade.color.cache import write_entry

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
#: sRGB-encoded units; other working spaces scale it (:func:`_space_scale`).
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
    if strength is None and statistics and (extracted.info.get("monochrome")
                                            or len(styles.names) < MIN_HALF_STYLES * 2):
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
                null = NULL_LOOK_SIZE * _space_scale(styles.working_space)
                strength *= max(0.0, 1.0 - null ** 2 / max(size2, 1e-300))
    look = LookMap(strength * extracted.look.coefficients, extracted.look.knots)
    return look, extracted, float(strength)


@functools.cache
def _space_scale(working_space: str) -> float:
    """How large colour differences are in ``working_space``'s unit cube against the
    sRGB-encoded one (where :data:`NULL_LOOK_SIZE` was measured): the rms spread of
    the shipped natural palettes' colours there over their spread in sRGB (1 in the
    default space; about 0.5 in ACEScct, which packs sRGB into 0.07-0.55)."""
    from wbcgrade.color.presets import styles_in_space

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


def find_scene_look(photo_colors: np.ndarray, styles, prior: LookMap | None = None,
                    progress: Callable[[int, int], None] | None = None,
                    why: dict[str, str] | None = None) -> SceneLook | None:
    """The look read off the style photos that show the photo's own scene, if any do.

    Parameters
    ----------
    photo_colors : (H, W, 3) the photo's working-space colours in [0, 1].
    styles : StyleSet whose ``meta`` names its files or carries its images
        (:func:`~wbcgrade.color.scene.style_scene_images`); a preset has none.
    prior : what colours absent from every overlap get (default identity).
    """
    from wbcgrade.color.scene import scene_image, style_scene_images

    style_images = style_scene_images(styles, progress)
    if not any(image is not None for image in style_images):
        return None
    reasons: dict[int, str] = {}
    found = fit_scene_look(scene_image(photo_colors), style_images, prior, why=reasons)
    if why is not None:
        why.update({styles.names[i]: reason for i, reason in reasons.items()})
    return found


def look_color_map(photo_hist: np.ndarray, styles, naturals=None,
                   set_strength: float | None = None) -> tuple[LookMap, PhotoLook, dict]:
    """The set's look and how sure it is that a style shows the photo's own scene.

    Parameters
    ----------
    photo_hist : (n, n, n) the photo's histogram (any grid; re-binned to 32^3).
    styles : StyleSet.
    naturals : StyleSet of ungraded palettes (default the shipped ones).

    Returns
    -------
    base : the set's look at ``set_strength`` (what a photo of another scene gets;
        None: its reliability on the photo's colours, :func:`set_look_base`).
    photo : the :class:`PhotoLook` (match, confidence, residuals).
    info : JSON-friendly diagnostics.
    """
    from wbcgrade.color.histogram import resample_histogram

    base, extracted, set_strength = set_look_base(styles, naturals, set_strength, photo_hist)
    photo = photo_look(resample_histogram(photo_hist, MAP_BINS), styles.at_bins(MAP_BINS), base)
    info = {"look": {"set_amplitude": extracted.look.amplitude(),
                     "set_strength": set_strength,
                     "match": styles.names[photo.match],
                     "confidence": photo.confidence,
                     "overlap": photo.overlap,
                     "residuals": [float(r) for r in photo.residuals],
                     **extracted.info}}
    return base, photo, info


def set_look_map(styles, naturals=None, strength: float | None = None,
                 map_size: int = 33,
                 progress: Callable[[int, int], None] | None = None) -> tuple[np.ndarray, dict]:
    """The look a style set shares, as a lattice LUT (what ``wbcgrade look extract`` writes).

    ``strength`` scales the map's displacement; None: a preset's own look in
    full, an extracted one at its reliability on the average natural palette
    (:func:`set_look_base`; the grade takes it on the photo's own colours).

    Returns ((map_size,) * 3 + (3,) float32 lattice, JSON-friendly info).
    """
    if styles.meta.get("look") is not None:  # a preset made with a known look
        strength = 1.0 if strength is None else strength
        identity = grid_points(map_size).reshape((map_size,) * 3 + (3,))
        known = resample_lattice(styles.meta["look"], map_size)
        moved = strength * (known - identity)
        return ((identity + moved).astype(np.float32),
                {"source": "preset", "strength": strength,
                 "amplitude_applied": float(np.mean(np.linalg.norm(moved, axis=-1)))})
    look, extracted, strength = set_look_base(styles, naturals, strength, progress=progress)
    names = (naturals if naturals is not None else natural_palettes()).names
    if extracted.info.get("content_shrink", 0.0) >= 1.0:  # not fitted: the average of all
        content = {style: "the natural palettes' barycenter" for style in styles.names}
    else:
        content = {style: {names[k]: round(float(w), 3) for k, w in enumerate(row)
                           if w >= 0.05}
                   for style, row in zip(styles.names, extracted.weights)}
    info = {**extracted.info, "strength": strength, "amplitude_applied": look.amplitude(),
            "content": content}
    lattice = look.lattice(map_size)
    if extracted.info.get("monochrome"):
        from wbcgrade.color.remap import monochrome_map

        lattice = monochrome_map(lattice)
    return lattice, info
