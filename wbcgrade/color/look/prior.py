"""What a set's statistics say of its look, judged jointly against what content does.

A style set's median statistics differ from content's by the look plus noise:
the sampling error of a median of S photos and a collection's own character
(a share of what single photos vary by). Both are Gaussian here, with the
full covariance of the statistics (their correlations count: saturation down
in all six photos *and* teal shadows in all six is far less likely from
content than either alone). The look itself has a prior learned from a
generator of photographers' edits (:mod:`wbcgrade.color.look.edits`): a
"no look" spike and a mixture of Gaussians of several sizes.

:func:`posterior_look` gives the posterior mean of the differences (what the
grade applies) and the probability that the set has a look at all; the
strength reported is how much of what the set shows is applied.

``python -m wbcgrade.color.look.prior`` rebuilds the shipped prior
(``wbcgrade/color/data/look_prior.npz``) from the generator and the shipped
natural palettes.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbcgrade.color.histogram import grid_points, soft_histogram
from wbcgrade.color.io.cache import entry_path, read_entry, write_entry
from wbcgrade.color.look.edits import random_edit
from wbcgrade.color.look.statistics import (
    MEDIAN_SE,
    MIN_OWN_PHOTOS,
    LookDifferences,
    PaletteStatistics,
    content_centre,
    in_colour,
    look_differences,
    look_from_differences,
    own_photos_blend,
    palette_statistics,
    tinted_statistics,
)
from wbcgrade.color.presets import load_preset

__all__ = ["LookPosterior", "posterior_look", "content_noise", "load_prior", "build_prior",
           "NO_LOOK", "PRIOR_SCALES", "COLLECTION_SHARE", "jackknife_share", "posterior_spread"]

#: Prior probability that a style set has no look at all (the spike at zero).
NO_LOOK = 0.3
#: Sizes of the looks' Gaussians, as shares of the generator's covariance (equal weights):
#: traces to heavy looks.
PRIOR_SCALES = (1.0 / 64.0, 1.0 / 16.0, 1.0 / 4.0, 1.0, 4.0)
#: A collection's own character, as a share of what single natural photos vary by
#: (its variance: COLLECTION_SHARE ** 2 times theirs), added to every set's noise.
COLLECTION_SHARE = 0.2
#: Content of an unusual kind: (factor on the collection's share of the single photos'
#: spread, the same for the neutral tints alone, prior weight). A set of sunsets or of snow
#: scenes is unusual as a whole; a set of food or wine photos holds no greys, so its
#: "neutral" tints are its content's colours.
UNUSUAL_CONTENT = ((1.0, 0.0, 0.8), (1.0, 6.0, 0.2))
#: Whether the slab lets the sizes of a look's parts (:data:`PARTS`: tone, saturation, tint)
#: vary apart, each over :data:`PRIOR_SCALES` (True), or ties them to one size. Measured on
#: ``benchmarks/set_calibration.py`` (four photographers' looks, 3 / 6 / 12 style photos):
#: tied +0.02 / +0.03 / +0.18, apart +0.03 / +0.03 / +0.20; every three of the six warmest
#: photos (no look) moved others by at most 2.01 dE tied, 0.86 dE apart (a strong warm tint
#: no longer lets the tone's size grow with it).
SEPARATE_PARTS = True
#: How much the prior favours parts of one size (:data:`SEPARATE_PARTS`): a combination
#: weighs ``exp(-PART_TIE * sum of squared differences, in steps of PRIOR_SCALES, over
#: pairs of parts)`` (0: every combination alike; large: one size for all). A trade
#: measured at 0 / 0.3 / 1 / one size: every three of the six warmest photos moved others by
#: at most 0.86 / 1.40 / 1.77 / 2.01 dE (``benchmarks/set_calibration.py``); six palettes
#: of alike content in the generator's world moved 22 / 14 / 8 / 6 % of palettes over 1.5 dE
#: (``benchmarks/set_simulation.py``); the looks recovered alike. Real photos chose 0.
PART_TIE = 0.0
#: Pull of the covariances towards their diagonals (316 palettes estimate 42 x 42).
DIAGONAL_SHRINK = 0.2
#: Random sets drawn to measure the noise of a set's median statistics.
NOISE_DRAWS = 400
#: Bumped when the statistics or their noise change (cached noise of an older one unused).
NOISE_VERSION = 2


@dataclass(frozen=True)
class LookPosterior:
    """The look a set's statistics support.

    Attributes
    ----------
    differences : the posterior mean of the differences (what is applied).
    probability : posterior probability that the set has a look.
    share : how much of the raw differences is applied (projection, whitened), in [0, 1].
    evidence : whitened size of the raw differences (rms z against the noise).
    operator : (P, P) the posterior mean as a linear map of the raw differences, its
        mixture's weights held (what other raw differences of the same set would give).
    covariance : (P, P) the posterior covariance of the differences (the mixture's: how
        unsure the look is around its mean).
    """
    differences: LookDifferences
    probability: float
    share: float
    evidence: float
    operator: np.ndarray | None = None
    covariance: np.ndarray | None = None


def _shrunk_to_diagonal(cov: np.ndarray) -> np.ndarray:
    return (1.0 - DIAGONAL_SHRINK) * cov + DIAGONAL_SHRINK * np.diag(np.diag(cov))


_NOISE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def content_noise(naturals: PaletteStatistics, n_styles: int,
                  cache: Path | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Covariances of the differences content alone makes: (of a median of ``n_styles``
    natural photos, of a single photo), each (P, P), from random draws (seeded).

    Kept for the process and, with a ``cache`` folder, on disk (``looks/`` in it; an
    entry of the wrong shape or not finite is computed again)."""
    digest = hashlib.sha1(np.ascontiguousarray(naturals.quantiles).tobytes())
    digest.update(np.ascontiguousarray(naturals.band_neutral).tobytes())
    digest.update(repr((NOISE_DRAWS, DIAGONAL_SHRINK, NOISE_VERSION)).encode())
    key = (f"{digest.hexdigest()}|{n_styles}", n_styles)
    path = entry_path(cache, "looks", "noise-" + key[0].replace("|", "-"))
    if key not in _NOISE:
        data = read_entry(path)
        try:
            found = (np.asarray(data["sets"], np.float64), np.asarray(data["singles"], np.float64))
            size = len(look_differences(naturals.take(np.array([0])), naturals).vector())
            if any(m.shape != (size, size) or not np.isfinite(m).all() for m in found):
                found = None
        except Exception:  # noqa: BLE001 - a cache never fails a run: any damage is a miss
            found = None
        if found is not None:
            _NOISE[key] = found
    if key not in _NOISE:
        rng = np.random.default_rng(0)
        k = len(naturals.quantiles)
        size = min(n_styles, max(k - 1, 1))

        def spread(draws, least: int = 2) -> np.ndarray:
            vectors = np.stack([look_differences(naturals.take(idx), naturals,
                                                 min_styles=least).vector()
                                for idx in draws])
            return _shrunk_to_diagonal(np.cov(vectors, rowvar=False))

        sets = spread(rng.choice(k, size, replace=False) for _ in range(NOISE_DRAWS))
        base = key[0].split("|")[0]
        known = next((v[1] for (d, _), v in _NOISE.items() if d.split("|")[0] == base),
                     None)  # a single photo's spread does not depend on the set's size
        singles = known if known is not None else spread(
            (np.array([i]) for i in range(k)), least=1)
        if len(_NOISE) > 16:
            _NOISE.pop(next(iter(_NOISE)))
        _NOISE[key] = (sets, singles)
        write_entry(path, sets=sets, singles=singles)
    return _NOISE[key]


def _log_gaussian(vector: np.ndarray, cov: np.ndarray) -> tuple[float, np.ndarray]:
    """log N(vector; 0, cov) and cov^-1 vector."""
    chol = np.linalg.cholesky(cov)
    solved = np.linalg.solve(chol, vector)
    logdet = 2.0 * np.sum(np.log(np.diag(chol)))
    inverse = np.linalg.solve(chol.T, solved)
    return float(-0.5 * (solved @ solved + logdet + len(vector) * np.log(2 * np.pi))), inverse


def _slabs(prior: np.ndarray, scales: tuple[float, ...],
           parts: list[np.ndarray] | None) -> list[tuple[np.ndarray, float]]:
    """The slab's covariances and the logs of their prior weights (which sum to 1):
    ``prior`` at each scale, or, with ``parts``, at every combination of one scale per
    part (``D prior D``, ``D`` the square roots of the parts' scales on the diagonal: each
    part's size its own, their correlations kept), weighted by how far apart the sizes
    are (:data:`PART_TIE`)."""
    from scipy.special import logsumexp

    if parts is None:
        return [(scale * prior, -np.log(len(scales))) for scale in scales]
    steps = np.log(np.asarray(scales, dtype=np.float64))  # in steps of the closest two
    gaps = np.diff(np.sort(steps))
    if gaps.size and gaps.min() > 0:
        steps = steps / gaps.min()
    slabs, weights = [], []
    for combination in itertools.product(range(len(scales)), repeat=len(parts)):
        root = np.zeros(len(prior))
        for index, part in zip(combination, parts):
            root[part] = np.sqrt(scales[index])
        slabs.append(root[:, None] * prior * root[None, :])
        at = steps[list(combination)]
        weights.append(-PART_TIE * float(np.sum((at[:, None] - at[None, :]) ** 2)) / 2.0)
    weights = np.array(weights)
    return list(zip(slabs, weights - logsumexp(weights)))


def posterior_look(raw: LookDifferences, noise: np.ndarray | list[tuple[np.ndarray, float]],
                   prior: np.ndarray, no_look: float = NO_LOOK,
                   scales: tuple[float, ...] = PRIOR_SCALES,
                   parts: list[np.ndarray] | None = None) -> LookPosterior:
    """The posterior mean of a set's look differences under a spike-and-slab prior.

    Parameters
    ----------
    raw : the set's differences (:func:`~wbcgrade.color.look.statistics.look_differences`).
    noise : (P, P) covariance content makes of them (sampling and collection), or a
        mixture [(covariance, weight), ...] (content of an unusual kind: a set of sunsets).
    prior : (P, P) second moment of the generator's looks' differences.
    no_look : prior probability of no look.
    scales : the slab's Gaussians, as shares of ``prior``.
    parts : (P,) boolean masks (:data:`PARTS`) whose sizes the slab lets vary apart, each
        over ``scales`` (the generator turns a look's controls on one by one: a strong
        tint says nothing of the tone's size). None: one size for all.
    """
    v = raw.vector()
    ridge = 1e-10 * np.eye(len(v))
    mixture = [(noise, 1.0)] if isinstance(noise, np.ndarray) else list(noise)
    total = sum(w for _, w in mixture)
    slabs = _slabs(prior, scales, parts)
    logs, means, spikes, operators, covariances = [], [], [], [], []
    for cov_noise, weight in mixture:
        share = weight / total
        log, _ = _log_gaussian(v, cov_noise + ridge)
        logs.append(np.log(no_look * share) + log)
        means.append(np.zeros_like(v))
        operators.append(np.zeros((len(v), len(v))))
        covariances.append(np.zeros((len(v), len(v))))
        spikes.append(True)
        for cov, log_chance in slabs:
            log, inverse = _log_gaussian(v, cov + cov_noise + ridge)
            logs.append(np.log((1.0 - no_look) * share) + log_chance + log)
            means.append(cov @ inverse)
            gain = np.linalg.solve(cov + cov_noise + ridge, cov).T
            operators.append(gain)
            covariances.append(cov - gain @ cov)
            spikes.append(False)
    logs = np.array(logs)
    weights = np.exp(logs - logs.max())
    weights /= weights.sum()
    means = np.array(means)
    mean = np.sum(weights[:, None] * means, axis=0)
    # the mixture's covariance: within its components and between their means
    centred = means - mean
    covariance = (np.tensordot(weights, np.array(covariances), axes=1)
                  + (weights[:, None] * centred).T @ centred)
    chol = np.linalg.cholesky(mixture[0][0] + ridge)
    white_raw, white_mean = np.linalg.solve(chol, v), np.linalg.solve(chol, mean)
    power = float(white_raw @ white_raw)
    share = float(np.clip(white_mean @ white_raw / power, 0.0, 1.0)) if power > 0 else 0.0
    operator = np.tensordot(weights, np.array(operators), axes=1)
    return LookPosterior(raw.with_vector(mean), float(1.0 - weights[np.array(spikes)].sum()),
                         share, float(np.sqrt(power / len(v))), operator,
                         0.5 * (covariance + covariance.T))


#: Groups of style photos left out in turn to measure how much a set's look varies with
#: its photos (:func:`jackknife_share`).
JACKKNIFE_GROUPS = 10


def small_sample_margin(groups: int) -> float:
    """The factor on a jackknife variance from ``groups`` groups: ``(g + 1) / (g - 1)``, 2
    for three photos and 1.22 for ten groups. On simulated sets of the generator's edits
    (``benchmarks/set_simulation.py``) it halves how far three photos without a look move
    others and keeps the mean recovered within 0.005 at 3, 6 and 12 photos."""
    return (groups + 1.0) / (groups - 1.0)


def jackknife_share(model, refit: Callable[[np.ndarray], object], n_styles: int,
                    colors: np.ndarray, masses: np.ndarray,
                    groups: int = JACKKNIFE_GROUPS,
                    unsure: Callable[[], float] | None = None) -> float:
    """How much of a set's look to apply, given how much it changes with the photos shown.

    The look is found again with each group of style photos left out (``refit``: a mask of
    the styles kept -> a look, callable on (N, 3) colours); their spread on ``colors``
    (weighted by ``masses``) is the look's own variance ``V`` (a delete-a-group
    jackknife), and the share kept is ``max(0, 1 - V / P)``, ``P`` the look's mean square
    displacement there: the least-squares shrinkage of a look measured with that error. A
    look every photo shows keeps nearly all of itself; one that a photo or two make up is
    dropped. ``V`` from ``g`` groups is uncertain when ``g`` is small (three photos left out
    one by one): it is counted ``(g + 1) / (g - 1)`` times (:func:`small_sample_margin`).
    ``unsure``: the posterior's own variance of the look on ``colors`` (how far the looks
    the statistics allow lie from it, :func:`posterior_spread`); ``V`` is never taken under
    it (a few photos that agree because they show alike content do not make a look sure).
    Under three styles: 1 (nothing to leave out).
    """
    if n_styles < 3:
        return 1.0
    masses = np.asarray(masses, dtype=np.float64) / np.sum(masses)
    moved = model(colors) - colors
    power = float(masses @ np.sum(moved * moved, axis=1))
    if not power > 0:
        return 1.0
    count = min(groups, n_styles)
    member = np.arange(n_styles) % count
    refits = np.stack([refit(member != g)(colors) - colors for g in range(count)])
    spread = refits - refits.mean(axis=0)
    variance = (count - 1) / count * float(np.sum(masses * np.sum(spread * spread, axis=2)))
    # a variance from count - 1 degrees of freedom, taken at its small-sample margin
    variance *= small_sample_margin(count)
    if unsure is not None:
        variance = max(variance, float(unsure()))
    return float(np.clip(1.0 - variance / power, 0.0, 1.0))


#: Draws from the posterior that measure how unsure a look is on colours
#: (:func:`posterior_spread`).
POSTERIOR_DRAWS = 32


def posterior_spread(look_of: Callable[[np.ndarray], object], mean: np.ndarray,
                     covariance: np.ndarray, colors: np.ndarray, masses: np.ndarray,
                     draws: int = POSTERIOR_DRAWS) -> float:
    """The posterior's variance of a look on ``colors`` (N, 3) weighted by ``masses``: the
    mean square distance, over draws of the differences from N(``mean``, ``covariance``)
    (seeded), of ``look_of(draw)``'s colours from ``look_of(mean)``'s."""
    masses = np.asarray(masses, dtype=np.float64) / np.sum(masses)
    values, vectors = np.linalg.eigh(covariance)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))
    if not np.any(root):
        return 0.0
    centre = look_of(mean)(colors)
    rng = np.random.default_rng(0)
    total = 0.0
    for _ in range(draws):
        moved = look_of(mean + root @ rng.standard_normal(len(mean)))(colors) - centre
        total += float(masses @ np.sum(moved * moved, axis=1))
    return total / draws


# --------------------------------------------------------------------------- the shipped prior

def _prior_path() -> Path:
    return Path(__file__).parents[1] / "data" / "look_prior.npz"


@functools.cache
def load_prior() -> np.ndarray:
    """(P, P) the shipped prior's second moment of look differences."""
    with np.load(_prior_path()) as data:
        return np.asarray(data["second_moment"], dtype=np.float64)


def push_edit(hist: np.ndarray, edit) -> np.ndarray:
    """The (n, n, n) histogram of ``hist``'s colours moved through ``edit`` (soft binning)."""
    n = hist.shape[0]
    flat = hist.ravel()
    keep = np.flatnonzero(flat > 0)
    return soft_histogram(edit(grid_points(n)[keep]), n, flat[keep])


def build_prior(naturals: np.ndarray, edits: int = 400, sample: int = 64,
                seed: int = 0, progress=None) -> np.ndarray:
    """(P, P) second moment of the differences random edits
    (:func:`~wbcgrade.color.look.edits.random_edit`) make of ``sample`` natural palettes'
    median statistics (naturals: (K, n, n, n) histograms)."""
    rng = np.random.default_rng(seed)
    base = palette_statistics(naturals)
    vectors = []
    for i in range(edits):
        edit = random_edit(rng)
        picked = rng.choice(len(naturals), min(sample, len(naturals)), replace=False)
        pushed = np.stack([push_edit(naturals[j], edit) for j in picked])
        styles = tinted_statistics(pushed, base)
        monochrome = False
        vectors.append(look_differences(styles, base.take(picked), monochrome).vector())
        if progress is not None:
            progress(i + 1, edits)
    vectors = np.array(vectors)
    return vectors.T @ vectors / len(vectors)


def main() -> None:  # pragma: no cover - a build script
    from tqdm import tqdm

    naturals = load_preset(Path(__file__).parents[1] / "data" / "natural.npz").at_bins(32)
    bar = tqdm(total=400, desc="edits")
    moment = build_prior(naturals, progress=lambda done, total: bar.update(1))
    bar.close()
    np.savez_compressed(_prior_path(), second_moment=moment)
    print(f"wrote {_prior_path()}")


if __name__ == "__main__":  # pragma: no cover
    main()


def posterior_statistics_look(styles: PaletteStatistics, naturals: PaletteStatistics,
                              space_scale: float = 1.0,
                              reference: PaletteStatistics | None = None,
                              own_count: int | None = None,
                              noise_from: PaletteStatistics | None = None,
                              cache: Path | None = None, no_look: float = NO_LOOK,
                              jackknife_colors: tuple[np.ndarray, np.ndarray] | None = None):
    """The look a style set's statistics support (:func:`posterior_look`), as a
    :class:`~wbcgrade.color.look.statistics.StatisticsLook` whose ``info`` holds the
    probability of a look, the share applied and the evidence.

    Parameters
    ----------
    styles : statistics of the S style palettes (neutral tints measured from their rough
        tint: :func:`~wbcgrade.color.look.statistics.tinted_statistics`).
    naturals : statistics of the natural palettes (K >= 2), same working space.
    reference, own_count : the user's own ungraded photos, as for
        :func:`~wbcgrade.color.look.statistics.statistics_look`: the centre leans on them
        as far as their number says, and their sampling error counts as noise.
    noise_from : the palettes whose statistics' spread is content's noise (default
        ``naturals``; the same palettes before a known look, whose noise is cached).
    cache : the cache folder that keeps the noise on disk (None: kept in memory only).
    no_look : prior probability of no look (:data:`NO_LOOK`; higher where a look is
        already known and only a correction of it is sought).
    jackknife_colors : (colours (N, 3), masses (N,)) on which to measure how much the look
        changes with the photos shown (:func:`jackknife_share`, the posterior's mixture
        held); the look is applied at the share that survives it. None: in full.
    """
    n_styles = len(styles.quantiles)
    given = 0 if reference is None else len(reference.quantiles)
    reference = in_colour(reference, space_scale)
    unused = given if reference is None else 0
    if reference is not None and (own_count or len(reference.quantiles)) < MIN_OWN_PHOTOS:
        unused, reference = len(reference.quantiles), None
    n_reference = 0 if reference is None else len(reference.quantiles)
    blend = own_photos_blend((own_count or n_reference) if n_reference else 0)
    centre_of = content_centre(naturals, reference, own_count)
    raw = look_differences(styles, centre_of)
    sets, singles = content_noise(naturals if noise_from is None else noise_from, n_styles,
                                  cache)
    own = (1.0 - blend) ** 2 * MEDIAN_SE ** 2 / n_reference * singles if n_reference else 0.0
    tint = np.zeros(len(raw.vector()))
    tint[len(raw.tone) + len(raw.saturation):] = 1.0  # the neutral tints' rows and columns
    greyless = np.outer(tint, tint) * singles
    noise = [(sets + (blend * COLLECTION_SHARE * spread) ** 2 * singles + own
              + (blend * COLLECTION_SHARE * no_greys) ** 2 * greyless, weight)
             for spread, no_greys, weight in UNUSUAL_CONTENT]
    # the prior was learned in sRGB-encoded units (the noise is measured in this space):
    # luma quantiles and tints scale with the working space, the log spreads do not
    units = np.full(len(raw.vector()), float(space_scale))
    units[len(raw.tone):len(raw.tone) + len(raw.saturation)] = 1.0
    prior = load_prior() * np.outer(units, units)
    parts = _parts(raw)
    found = posterior_look(raw, noise, prior, no_look, parts=parts if SEPARATE_PARTS else None)
    mean = found.differences.vector()
    kept = np.ones(len(parts))
    if jackknife_colors is not None:
        colors, masses = jackknife_colors

        def part_look(vector: np.ndarray, part: np.ndarray):
            return look_from_differences(raw.with_vector(np.where(part, vector, 0.0)))

        def refit(keep: np.ndarray) -> np.ndarray:  # the posterior's mean of the styles kept
            return found.operator @ look_differences(styles.take(keep), centre_of).vector()

        def unsure(part: np.ndarray) -> float:  # the posterior's spread of the part's look
            inside = np.outer(part, part)
            return posterior_spread(lambda vector: part_look(vector, part), mean,
                                    np.where(inside, found.covariance, 0.0), colors, masses)

        kept = np.array([jackknife_share(
            part_look(mean, part), lambda keep, part=part: part_look(refit(keep), part),
            n_styles, colors, masses, unsure=lambda part=part: unsure(part))
            for part in parts])
    applied = np.sum([k * np.where(part, mean, 0.0) for k, part in zip(kept, parts)], axis=0)
    shown = raw.with_vector(applied)
    info = {"method": "statistics", "rule": "posterior", "monochrome": False,
            "probability": round(found.probability, 3), "share": round(found.share, 3),
            "evidence": round(found.evidence, 3),
            "tone_shift": [round(float(v), 4) for v in shown.tone],
            "tone_raw": [round(float(v), 4) for v in raw.tone],
            "saturation": [round(float(np.exp(v)), 3) for v in shown.saturation],
            "tint": [[round(float(v), 4) for v in row] for row in shown.tint],
            "styles": n_styles, "naturals": len(naturals.quantiles), "own_photos": n_reference,
            "own_photos_share": round(1.0 - blend, 3), "own_photos_unused": unused}
    info["jackknife"] = {name: round(float(k), 3) for name, k in zip(PARTS, kept)}
    if jackknife_colors is not None:  # the posterior's share, times what of it is kept
        info["share"] = round(found.share * _kept_share(mean, applied, noise[0][0]), 3)
    return look_from_differences(shown, False, info)


#: The parts of a look checked against themselves one by one (:func:`jackknife_share`):
#: a set can show its tone curve clearly and its tint not at all.
PARTS = ("tone", "saturation", "tint")


def _parts(raw: LookDifferences) -> list[np.ndarray]:
    """Masks of :data:`PARTS` in the differences' vector."""
    q, b, size = len(raw.tone), len(raw.saturation), len(raw.vector())
    index = np.arange(size)
    return [index < q, (index >= q) & (index < q + b), index >= q + b]


def _kept_share(mean: np.ndarray, applied: np.ndarray, noise: np.ndarray) -> float:
    """How much of the posterior ``mean`` the ``applied`` differences keep, measured as the
    posterior's share is (whitened by content's ``noise``): a projection in [0, 1]."""
    chol = np.linalg.cholesky(noise + 1e-10 * np.eye(len(mean)))
    white_mean, white_applied = np.linalg.solve(chol, mean), np.linalg.solve(chol, applied)
    power = float(white_mean @ white_mean)
    return float(np.clip(white_applied @ white_mean / power, 0.0, 1.0)) if power > 0 else 0.0
