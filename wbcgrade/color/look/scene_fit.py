"""Pair and scene fits: the look of one photo against the style photos that show its scene.

:func:`fit_pair` and :func:`photo_look` read it from palettes (which style's palette
is the photo's own, and how sure that is); :func:`fit_scene_look` and
:func:`find_scene_look` from matched pixels of style photos of the same scene
(:mod:`wbcgrade.color.look.scene`), with :func:`fit_pairs_look` the robust fit of
colour pairs and :func:`fit_correction` the smooth residual on top of the look.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from wbcgrade.color.histogram import grid_points
from wbcgrade.color.look.family import (
    DEFAULT_RELAXATION,
    DEFAULT_RIDGE,
    DEFAULT_SMOOTHNESS,
    DEFAULT_WIDTH,
    LookMap,
    fit_look_map,
    look_correspondences,
    push_histogram,
)
from wbcgrade.color.look.scene import (
    SceneMatch,
    colour_pairs,
    match_scene,
    mirrored,
    scene_image,
    style_scene_images,
    unmirror,
)
from wbcgrade.color.mapping.remap import interpolate_lattice
from wbcgrade.color.palette.smooth_map import interpolation_matrix
from wbcgrade.core import fast_cpu, n_workers, single_threaded_blas

__all__ = ["PairFit", "fit_pair", "PhotoLook", "photo_look", "SceneLook", "fit_scene_look",
           "find_scene_look", "fit_correction", "fit_pairs_look"]


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
        points, targets, mass, _ = look_correspondences(photo, style, look, width, relaxation)
        look = fit_look_map(points, targets, mass, prior, smoothness, ridge, prior.knots)
    _, targets, mass, moved = look_correspondences(photo, style, look, width, relaxation)
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
#: match is not the photo's scene, and at or above which it surely is (between what
#: framings of one scene and other scenes give: docs/benchmarks.md).
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
    photo : :class:`~wbcgrade.color.look.scene.SceneImage` of the photo.
    styles : a SceneImage (or None) per style.
    prior : the map the fit falls back on for colours no overlap shows
        (default identity).
    rounds : robust refits (pairs far from the fit, e.g. content that moved
        between the shots, weigh less each round).
    correct : add the smooth lattice correction (:func:`fit_correction`, 9^3)
        for what the map family cannot hold (film and bleach-bypass looks:
        docs/benchmarks.md).

    why : filled with the reason each style (by index) does not show the scene.

    Returns None when no style shows the scene.
    """
    prior = prior or LookMap.identity()
    present = [index for index, style in enumerate(styles) if style is not None]
    # a flipped framing (or a symmetric scene matched the wrong way)?
    flipped = mirrored(photo) if present else None
    width = photo.colors.shape[1]

    def matched(job: tuple[int, bool]) -> tuple[SceneMatch | None, list[str]]:
        index, flip = job
        reasons: list[str] = []
        return match_scene(flipped if flip else photo, styles[index], why=reasons), reasons

    # each match is one BLAS product and its row minima: single-threaded products side by
    # side on the cores (OpenBLAS's own threads busy-wait between products); the matches
    # are the same numbers in any order
    jobs = [(index, False) for index in present] + [(index, True) for index in present]
    with single_threaded_blas(), ThreadPoolExecutor(min(n_workers(), 4)) as pool:
        found = dict(zip(jobs, pool.map(matched, jobs)))
    matches = {}
    for index in present:
        match, reasons = found[index, False]
        if match is None:
            if why is not None and reasons:
                why[index] = reasons[0]
            continue
        matches[index] = match
    for index in present:
        match, _ = found[index, True]
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


def find_scene_look(photo_colors: np.ndarray, styles, prior: LookMap | None = None,
                    progress: Callable[[int, int], None] | None = None,
                    why: dict[str, str] | None = None) -> SceneLook | None:
    """The look read off the style photos that show the photo's own scene, if any do.

    Parameters
    ----------
    photo_colors : (H, W, 3) the photo's working-space colours in [0, 1].
    styles : StyleSet whose ``meta`` names its files or carries its images
        (:func:`~wbcgrade.color.look.scene.style_scene_images`); a preset has none.
    prior : what colours absent from every overlap get (default identity).
    """

    style_images = style_scene_images(styles, progress)
    if not any(image is not None for image in style_images):
        return None
    reasons: dict[int, str] = {}
    found = fit_scene_look(scene_image(photo_colors), style_images, prior, why=reasons)
    if why is not None:
        why.update({styles.names[i]: reason for i, reason in reasons.items()})
    return found
