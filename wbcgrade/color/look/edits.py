"""A generator of photographers' edits: the kinds of look presets are made of.

The prior over looks (:mod:`wbcgrade.color.look.prior`) is learned from this
generator, never from any benchmark's or shipped film's look: a random edit is
a chain of the controls every raw editor has (exposure, a contrast curve,
lifted blacks and lowered whites (a fade), saturation, white balance,
split toning of shadows and highlights, a channel mix, per-channel film-like
gammas), each switched on at random with a random amount, at a random
overall size from a trace to a heavy look.

Beside it, :class:`CurvesEdit`, the family a look is extrapolated with from a pair or
two (:func:`fit_curves_edit`): a film-like response (a tone curve per channel after a
channel mix and a saturation) follows a film stock's look further from the colours a
pair shows than the raw editor's controls do.

Arrays in, arrays out: colours are (N, 3) encoded RGB in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbcgrade.color.colorspace import REC709_LUMA

__all__ = ["Edit", "random_edit", "fit_edit", "SPREADS", "CurvesEdit", "fit_curves_edit",
           "extrapolating_family", "choose_family", "FamilyChoice", "FAMILIES"]

_LUMA = np.array(REC709_LUMA)

#: How far each control goes in the generator at size 1 (:func:`random_edit`'s normal
#: spreads; saturation and gamma on a log scale): also how far :func:`fit_edit` lets the
#: pairs move a control for a given cost.
SPREADS = {"exposure": 0.4, "contrast": 0.5, "black": 0.06, "white": 0.06, "saturation": 0.45,
           "balance": 0.06, "shadow_tint": 0.08, "highlight_tint": 0.08, "mix": 0.08,
           "gamma": 0.12}


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class Edit:
    """One photographer's edit; all zero (saturation 1, mix the identity) changes nothing.

    Attributes
    ----------
    exposure : stops (applied as a gain on linear light, approximated by gamma 2.2).
    contrast : S-curve amount on luma (negative: flatter).
    black, white : fade: output black level lifted to ``black``, white lowered by ``white``.
    saturation : chroma scale about Rec.709 luma.
    balance : (3,) RGB gains - 1 (white balance: warm, cool, green, magenta).
    shadow_tint, highlight_tint : (3,) chroma added where the photo is dark / bright.
    mix : (3, 3) channel mix (rows sum to 1).
    gamma : (3,) per-channel power (film-like crossover), 1 = none.
    """

    exposure: float = 0.0
    contrast: float = 0.0
    black: float = 0.0
    white: float = 0.0
    saturation: float = 1.0
    balance: tuple = (0.0, 0.0, 0.0)
    shadow_tint: tuple = (0.0, 0.0, 0.0)
    highlight_tint: tuple = (0.0, 0.0, 0.0)
    mix: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    gamma: tuple = (1.0, 1.0, 1.0)

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """(..., 3) colours in [0, 1] -> (..., 3) float64 in [0, 1]."""
        rgb = np.asarray(rgb, dtype=np.float64)
        x = rgb.reshape(-1, 3)
        x = np.clip(x @ np.asarray(self.mix, dtype=np.float64).T, 0.0, 1.0)
        x = np.clip(x * (1.0 + np.asarray(self.balance)), 0.0, 1.0)
        if self.exposure:
            x = np.clip(x * 2.0 ** (self.exposure / 2.2), 0.0, 1.0)
        x = x ** np.asarray(self.gamma)
        luma = x @ _LUMA
        chroma = x - luma[:, None]
        curved = luma + self.contrast * (_smoothstep(luma) - luma)
        curved = np.clip(curved, 0.0, 1.0)
        toned = (chroma * self.saturation
                 + (1.0 - curved[:, None]) ** 2 * np.asarray(self.shadow_tint)
                 + curved[:, None] ** 2 * np.asarray(self.highlight_tint))
        out = curved[:, None] + toned
        out = self.black + (1.0 - self.black - self.white) * out
        return np.clip(out, 0.0, 1.0).reshape(rgb.shape)


def _chroma(rng: np.random.Generator, size: float) -> np.ndarray:
    """A random chroma vector (zero luma) of rms ``size``."""
    v = rng.normal(0.0, size, 3)
    return v - (v @ _LUMA)


def random_edit(rng: np.random.Generator, size: float | None = None) -> Edit:
    """A random edit (each control on with its own chance) at ``size`` (default
    log-uniform from 0.15, a trace, to 1.5, a heavy look)."""
    if size is None:
        size = float(np.exp(rng.uniform(np.log(0.15), np.log(1.5))))

    def on(chance: float) -> bool:
        return bool(rng.random() < chance)

    spread = SPREADS
    exposure = rng.normal(0.0, spread["exposure"]) * size if on(0.4) else 0.0
    contrast = rng.normal(0.1, spread["contrast"]) * size if on(0.6) else 0.0
    black = abs(rng.normal(0.0, spread["black"])) * size if on(0.35) else 0.0
    white = abs(rng.normal(0.0, spread["white"])) * size if on(0.25) else 0.0
    saturation = (float(np.exp(rng.normal(0.0, spread["saturation"]) * size)) if on(0.6)
                  else 1.0)
    balance = tuple(_chroma(rng, spread["balance"] * size)) if on(0.5) else (0.0, 0.0, 0.0)
    shadow = (tuple(_chroma(rng, spread["shadow_tint"] * size)) if on(0.35)
              else (0.0, 0.0, 0.0))
    highlight = (tuple(_chroma(rng, spread["highlight_tint"] * size)) if on(0.35)
                 else (0.0, 0.0, 0.0))
    mix = np.eye(3)
    if on(0.2):
        mix = mix + rng.normal(0.0, spread["mix"] * size, (3, 3)) * (1.0 - np.eye(3))
        mix = mix / mix.sum(axis=1, keepdims=True)
    gamma = (tuple(np.exp(rng.normal(0.0, spread["gamma"] * size, 3))) if on(0.25)
             else (1.0, 1.0, 1.0))
    return Edit(float(exposure), float(np.clip(contrast, -0.9, 1.5)), float(min(black, 0.3)),
                float(min(white, 0.3)), float(np.clip(saturation, 0.0, 3.0)), balance, shadow,
                highlight, tuple(map(tuple, mix)), gamma)


# --------------------------------------------------------------------------- fitting an edit

#: The controls as one vector (name, entries): saturation and gamma as logs, the mix as its
#: six off-diagonal entries (rows normalised to sum 1).
_LAYOUT = (("exposure", 1), ("contrast", 1), ("black", 1), ("white", 1), ("saturation", 1),
           ("balance", 3), ("shadow_tint", 3), ("highlight_tint", 3), ("mix", 6), ("gamma", 3))
_OFF_DIAGONAL = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
#: The pull of :func:`fit_edit` towards no edit: a control one :data:`SPREADS` away costs
#: as much as an rms colour error of ``0.02 * sqrt(EDIT_PULL)`` over all the pairs.
#: Measured on ``benchmarks/learn.py`` with one original (16 film looks, 384 px): 0.3, 1
#: and 3 recover alike on average; 3 keeps the worst photo highest.
EDIT_PULL = 3.0
#: Pairs (drawn by weight, seeded) the edit is fitted to, and the fit's tolerance: its 23
#: controls need few (500 pairs and 1e-4 extrapolate as 1000 and 1e-8 do, 3x faster).
EDIT_POINTS = 500
EDIT_TOLERANCE = 1e-4


def _edit_of(vector: np.ndarray) -> Edit:
    parts, start = {}, 0
    for name, size in _LAYOUT:
        parts[name] = vector[start:start + size]
        start += size
    mix = np.eye(3)
    for (row, column), value in zip(_OFF_DIAGONAL, parts["mix"]):
        mix[row, column] = value
    mix = mix / mix.sum(axis=1, keepdims=True)
    return Edit(float(parts["exposure"][0]), float(parts["contrast"][0]),
                float(abs(parts["black"][0])), float(abs(parts["white"][0])),
                float(np.exp(parts["saturation"][0])), tuple(map(float, parts["balance"])),
                tuple(map(float, parts["shadow_tint"])),
                tuple(map(float, parts["highlight_tint"])), tuple(map(tuple, mix)),
                tuple(map(float, np.exp(parts["gamma"]))))


def _as_pairs(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs as float64: sources (N, 3), targets (N, 3), weights (N,)."""
    return (np.asarray(sources, dtype=np.float64).reshape(-1, 3),
            np.asarray(targets, dtype=np.float64).reshape(-1, 3),
            np.asarray(weights, dtype=np.float64).ravel())


def _drawn(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray, points: int,
           rng: np.random.Generator | None = None
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At most ``points`` pairs, drawn by weight without replacement (``rng``, default
    seeded 0) when there are more: (sources, targets, shares summing to 1)."""
    share = weights / weights.sum()
    if len(sources) > points:
        rng = np.random.default_rng(0) if rng is None else rng
        drawn = rng.choice(len(sources), points, replace=False, p=share)
        return sources[drawn], targets[drawn], np.full(points, 1.0 / points)
    return sources, targets, share


def fit_edit(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray,
             pull: float = EDIT_PULL, points: int = EDIT_POINTS, max_nfev: int = 200) -> Edit:
    """The :class:`Edit` that best moves ``sources`` (N, 3) onto ``targets`` (N, 3)
    (weighted least squares, ``weights`` (N,)), each control pulled towards none by the
    generator's spread of it (:data:`SPREADS`, ``pull``): a photographer's edit explains
    the colours a pair shows and extrapolates to those it does not as edits do."""
    from scipy.optimize import least_squares

    sources, targets, weights = _as_pairs(sources, targets, weights)
    if len(sources) == 0 or not weights.sum() > 0:
        return Edit()
    sources, targets, share = _drawn(sources, targets, weights, points)
    root = np.sqrt(share)[:, None]
    spreads = np.concatenate([[SPREADS[name]] * size for name, size in _LAYOUT])
    cost = 0.02 * np.sqrt(pull) / spreads

    def residuals(vector: np.ndarray) -> np.ndarray:
        moved = _edit_of(vector)(sources)
        return np.concatenate([((moved - targets) * root).ravel(), cost * vector])

    found = least_squares(residuals, np.zeros(len(spreads)), x_scale=spreads, max_nfev=max_nfev,
                          ftol=EDIT_TOLERANCE, xtol=EDIT_TOLERANCE, gtol=EDIT_TOLERANCE)
    return _edit_of(found.x)


# --------------------------------------------------------------------------- a film-like edit

#: Knots of each channel's tone curve in :class:`CurvesEdit` (evenly spread over [0, 1]).
CURVE_KNOTS = 9
#: What :func:`fit_curves_edit` charges, as an rms colour error over all the pairs, for a
#: unit of: a curve's departure from the identity at a knot, the curve's second difference
#: between knots (its bend), an off-diagonal entry of the channel mix (cross-talk: the
#: one-pair fit's wildest guess where its colours are few, so held hardest), the log of
#: the saturation. Chosen on the eight tuned looks of ``benchmarks/learn.py`` with one
#: original (docs/benchmarks.md); a mix held as loosely as the curves (0.02) let a sea's
#: blues swing skin tones.
CURVE_PULL = 0.02
CURVE_BEND = 0.5
CURVE_MIX_PULL = 0.4
CURVE_SATURATION_PULL = 0.02


@dataclass(frozen=True, eq=False)
class CurvesEdit:
    """A film-like edit: a channel mix (cross-talk between the dyes), a saturation about
    Rec.709 luma, then a tone curve per channel, piecewise linear through ``curves``
    (3, K) at K knots evenly spread over [0, 1]. The identity mix and saturation 1 with
    straight curves change nothing."""

    mix: np.ndarray
    saturation: float
    curves: np.ndarray

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """(..., 3) colours in [0, 1] -> (..., 3) float64 in [0, 1]."""
        rgb = np.asarray(rgb, dtype=np.float64)
        s = self.saturation
        matrix = (s * np.eye(3) + (1.0 - s) * _LUMA[None, :]) @ np.asarray(self.mix)
        x = np.clip(rgb.reshape(-1, 3) @ matrix.T, 0.0, 1.0)
        knots = np.linspace(0.0, 1.0, self.curves.shape[1])
        out = np.stack([np.interp(x[:, c], knots, self.curves[c]) for c in range(3)], axis=1)
        return np.clip(out, 0.0, 1.0).reshape(rgb.shape)


def _curves_edit_of(vector: np.ndarray, knots: int) -> CurvesEdit:
    """The edit of a vector: (3 * knots) curve departures, six mix entries, log saturation."""
    grid = np.linspace(0.0, 1.0, knots)
    curves = vector[:3 * knots].reshape(3, knots) + grid
    mix = np.eye(3)
    for (row, column), value in zip(_OFF_DIAGONAL, vector[3 * knots:3 * knots + 6]):
        mix[row, column] = value
    mix = mix / mix.sum(axis=1, keepdims=True)
    return CurvesEdit(mix, float(np.exp(vector[3 * knots + 6])), curves)


def fit_curves_edit(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                    points: int = EDIT_POINTS, knots: int = CURVE_KNOTS,
                    max_nfev: int = 300) -> CurvesEdit:
    """The :class:`CurvesEdit` that best moves ``sources`` (N, 3) onto ``targets`` (N, 3)
    (weighted least squares on ``points`` colours drawn by ``weights`` (N,), seeded), each
    part held towards no edit at its cost (:data:`CURVE_PULL`, :data:`CURVE_BEND`,
    :data:`CURVE_MIX_PULL`, :data:`CURVE_SATURATION_PULL`): a curve follows the pairs over
    the range of values they show and stays straight beyond it."""
    from scipy.optimize import least_squares

    sources, targets, weights = _as_pairs(sources, targets, weights)
    size = 3 * knots + 7
    if len(sources) == 0 or not weights.sum() > 0:
        return _curves_edit_of(np.zeros(size), knots)
    sources, targets, share = _drawn(sources, targets, weights, points)
    root = np.sqrt(share)[:, None]
    pull = np.concatenate([np.full(3 * knots, CURVE_PULL), np.full(6, CURVE_MIX_PULL),
                           [CURVE_SATURATION_PULL]])

    def residuals(vector: np.ndarray) -> np.ndarray:
        moved = _curves_edit_of(vector, knots)(sources)
        bend = np.diff(vector[:3 * knots].reshape(3, knots), 2, axis=1).ravel()
        return np.concatenate([((moved - targets) * root).ravel(), CURVE_BEND * bend,
                               pull * vector])

    found = least_squares(residuals, np.zeros(size), max_nfev=max_nfev)
    return _curves_edit_of(found.x, knots)


# --------------------------------------------------------------------------- which family

#: The families a pair's look is extrapolated with: name -> fit(sources, targets, weights).
FAMILIES = {"edit": fit_edit, "curves": fit_curves_edit}
#: Blocks of colour held out in turn by :func:`choose_family`, and the evaluations
#: its quick fits of the raw editor's controls may take (the full fit's 200 take seconds).
FAMILY_BLOCKS = 4
FAMILY_QUICK_NFEV = 40
#: A curve per channel is learned only over the values the pairs show: under this share
#: of their colours in any third of the tonal range (shadows, midtones, highlights), the
#: curves are not a candidate (a near-black photo leaves them unlearned above its blacks).
FAMILY_TONES = 0.05


def _colour_blocks(points: np.ndarray, blocks: int, rng: np.random.Generator) -> np.ndarray:
    """(N,) block of each colour: k-means of ``points`` (N, 3) into ``blocks`` (seeded; a
    block left empty keeps its centre, quietly: a flat photo's colours repeat)."""
    import warnings

    from scipy.cluster.vq import kmeans2

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        _, label = kmeans2(points, blocks, iter=10, minit="points", seed=rng, missing="warn")
    return label


@dataclass(frozen=True)
class FamilyChoice:
    """The family a pair's look is extrapolated with (:data:`FAMILIES`), and how well it
    carried the pairs' edit to their own held-out colours: ``skill`` is 1 minus its
    squared error there over no change's (1: exact, 0: no better than no change, below 0:
    worse; 0 when there was too little to judge)."""
    name: str
    skill: float = 0.0


def choose_family(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                  points: int = EDIT_POINTS, blocks: int = FAMILY_BLOCKS) -> FamilyChoice:
    """The family (in :data:`FAMILIES`) that best carries the pairs' edit to colours they
    do not show, judged within the pairs: their colours fall in ``blocks`` blocks of
    colour and in as many bands of luma, each held out in turn while both families are
    fitted to the others (quick fits), and the family whose fits come nearer the held-out
    targets (squared error) wins; pairs whose colours leave a third of the tonal range
    nearly empty (:data:`FAMILY_TONES`) keep the raw editor's controls. A film-like curve
    follows a stock from a photo with a range of values; from a near-black photo or a
    sea of blues the raw editor's controls guess more safely.

    Parameters
    ----------
    sources, targets : (N, 3) the pairs' colours before and after.
    weights : (N,) how much each counts.

    Returns
    -------
    :class:`FamilyChoice`: the family chosen and its own skill on the held-out colours
    (the raw editor's controls' when the tonal range keeps them; then the curves are
    not fitted).
    """
    sources, targets, weights = _as_pairs(sources, targets, weights)
    if len(sources) < 4 * blocks or not weights.sum() > 0:
        return FamilyChoice("edit")
    thirds = np.bincount(np.clip((sources @ _LUMA * 3).astype(int), 0, 2), weights, 3)
    tones = bool(thirds.min() >= FAMILY_TONES * weights.sum())
    rng = np.random.default_rng(0)
    sources, targets, _ = _drawn(sources, targets, weights, points, rng)
    label = _colour_blocks(sources, blocks, rng)
    luma = sources @ _LUMA
    tone = np.searchsorted(np.quantile(luma, np.linspace(0, 1, blocks + 1)[1:-1]), luma)
    errors = {"edit": 0.0, "curves": 0.0}
    unchanged = 0.0
    for held in [label == b for b in range(blocks)] + [tone == b for b in range(blocks)]:
        kept = ~held
        if not held.any() or kept.sum() < 2 * blocks:
            continue
        ones = np.ones(int(kept.sum()))
        fits = {"edit": fit_edit(sources[kept], targets[kept], ones,
                                 max_nfev=FAMILY_QUICK_NFEV)}
        if tones:
            fits["curves"] = fit_curves_edit(sources[kept], targets[kept], ones,
                                             max_nfev=FAMILY_QUICK_NFEV)
        for name, fitted in fits.items():
            errors[name] += float(np.sum((fitted(sources[held]) - targets[held]) ** 2))
        unchanged += float(np.sum((sources[held] - targets[held]) ** 2))
    name = "curves" if tones and errors["curves"] < errors["edit"] else "edit"
    skill = 1.0 - errors[name] / unchanged if unchanged > 0 else 0.0
    return FamilyChoice(name, float(skill) if np.isfinite(skill) else 0.0)


def extrapolating_family(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                         points: int = EDIT_POINTS, blocks: int = FAMILY_BLOCKS) -> str:
    """The name of the family :func:`choose_family` chooses."""
    return choose_family(sources, targets, weights, points, blocks).name
