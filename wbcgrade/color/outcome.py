"""What a grade did, in plain terms: :class:`GradeOutcome` (``grade.outcome``).

Every grade says where its colour map came from (:class:`GradeSource`), how
strongly it was applied, how large the look is and how much the photo's
colours actually moved; when they barely moved, it says so and why, and what
the user can do. The barycentric weights and the fit's loss come with it only
for a palette grade (:class:`PaletteFit`): in a look grade they mean nothing.

The command line, its JSON, batch lines, reports and ``explore`` read this
object instead of diagnostics keyed by strings. Its reason and advice name settings
as the library does (``map.strength``); :meth:`GradeOutcome.named` writes them as a
caller names them (the command line: as its flags).

Sizes are in 1/255 of the sRGB-encoded cube (whatever the working space), so
that "1.9" means the same on every photo:

- ``look_size``: the mean displacement |T(x) - x| of the grade's colour map,
  as applied, over every colour of the cube;
- ``mean_change``: the mean per-channel change |T(x) - x| of the photo's own
  colours (weighted by its histogram).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from wbcgrade.color.colorspace import convert, default_working_space, resolve_space
from wbcgrade.color.defaults import MIN_OWN_PHOTOS
from wbcgrade.color.histogram import grid_points
from wbcgrade.color.mapping.remap import apply_color_map
from wbcgrade.errors import Worded

__all__ = ["GradeSource", "FitStart", "fit_start_word", "SavedFrom", "TransportCheck", "PaletteFit",
           "GradeOutcome", "UNCHANGED_CHANGE",
           "UNCHANGED_STRENGTH", "FAINT_CHANGE", "FAINT_STRENGTH", "map_change", "unchanged_advice",
           "change_words", "VISIBILITY",
           "OWN_PHOTO_KEYS"]

#: Below this mean change of the photo's colours (in 1/255 of the sRGB cube) the
#: photo is "essentially unchanged".
UNCHANGED_CHANGE = 1.0
#: Below this strength (the look's own strength times ``map.strength``) a look is not applied.
UNCHANGED_STRENGTH = 0.05
#: Below this mean change (1/255 of the sRGB cube), or this strength, a grade is "faint":
#: it changed the photo, but hardly visibly; the terminal says so and what to do.
FAINT_CHANGE = 3.0
FAINT_STRENGTH = 0.25


class GradeSource(str, Enum):
    """Where a grade's colour map came from."""

    PRESET_LOOK = "preset-look"      #: a preset's own look, converted into the working space
    OWN_SCENE = "own-scene"          #: read off a style photo that shows the photo's scene
    SET_LOOK = "set-look"            #: the look the style photos share
    PALETTE = "palette"              #: a palette fit: barycentric weights of the style palettes
    SAVED = "saved"                  #: a saved grade (a JSON grade or a LUT)

    def describe(self, n_styles: int = 0) -> str:
        """The source in words."""
        return {
            GradeSource.PRESET_LOOK: "the preset's own look",
            GradeSource.OWN_SCENE: "the look of the style photo that shows this scene",
            GradeSource.SET_LOOK: (f"the look the {n_styles} style photos share"
                                   if n_styles != 1 else "the look of the one style photo"),
            GradeSource.PALETTE: f"a blend of the {n_styles} style palettes (palette fit)",
            GradeSource.SAVED: "a saved grade, applied as saved (no fit)",
        }[self]


class FitStart(str, Enum):
    """How a palette grade's weights were found (``FitSummary.start``, ``PaletteFit.start``;
    the JSON writes the value). Where any grade came from is its :class:`GradeSource`."""

    UNIFORM = "uniform"            #: a palette fit from uniform weights, kept
    VERTEX_REFIT = "vertex-refit"  #: refitted from the best single style, which beat it
    VERTEX = "vertex"              #: the best single style: no fit beat it
    GIVEN = "given"                #: the weights were given (``fit.weights``): no fit
    SHARED = "shared"              #: a shared grade whose fit the caller holds (a series')

    @property
    def fitted(self) -> bool:
        """Whether weights were fitted to the photo (not given)."""
        return self is not FitStart.GIVEN


#: The JSON's ``fit_start`` of a grade no palette fit made: where its map came from.
_SOURCE_START = {GradeSource.PRESET_LOOK: "preset", GradeSource.OWN_SCENE: "scene",
                 GradeSource.SET_LOOK: "look", GradeSource.SAVED: "saved"}


def fit_start_word(source: GradeSource, fit_start: str | None) -> str:
    """What the JSON's ``fit_start`` says of a grade: how a palette fit found its weights
    (``fit_start``, a :class:`FitStart` value; None: a shared grade whose fit the caller
    holds), else where the map came from ("preset", "scene", "look", "saved").

    >>> fit_start_word(GradeSource.PALETTE, "vertex"), fit_start_word(GradeSource.SET_LOOK, None)
    ('vertex', 'look')
    """
    if source is not GradeSource.PALETTE:
        return _SOURCE_START[source]
    return FitStart.SHARED.value if fit_start is None else str(fit_start)


@dataclass(frozen=True)
class SavedFrom:
    """Where a saved grade was read from.

    Attributes
    ----------
    file : the file (a JSON grade or a LUT).
    kind : "json" (a grade :func:`~wbcgrade.color.grade.saved_grade.save_grade` wrote,
        regrain as saved), or the LUT's
        format ("cube", "clf", ...).
    """

    file: str
    kind: str

    @property
    def is_json(self) -> bool:
        return self.kind == "json"


@dataclass(frozen=True)
class TransportCheck:
    """How the transfer's Sinkhorn solve ended (a palette grade's transport plan).

    Attributes
    ----------
    converged : whether it reached its tolerance.
    error : its marginal error when it stopped.
    """

    converged: bool
    error: float


@dataclass(frozen=True)
class PaletteFit:
    """The barycentric weights of a palette grade (the paper's report).

    Attributes
    ----------
    names : the S style names, by decreasing weight.
    weights : the S weights, same order (they sum to 1).
    loss : the fit's loss at the weights.
    best_single : the style that alone has the lowest loss, and that loss.
    start : how the weights were found (:class:`FitStart`: UNIFORM, VERTEX_REFIT,
        VERTEX or GIVEN).
    evaluations : loss evaluations of the fit (0 for given weights).
    converged : whether the fit converged.
    """

    names: tuple[str, ...]
    weights: tuple[float, ...]
    loss: float
    best_single: tuple[str, float] | None = None
    start: FitStart = FitStart.UNIFORM
    evaluations: int = 0
    converged: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", FitStart(self.start))

    def as_dict(self) -> dict:
        return {"weights": [{"style": n, "weight": round(w, 6)}
                            for n, w in zip(self.names, self.weights)],
                "loss": self.loss,
                "best_single": None if self.best_single is None else
                {"style": self.best_single[0], "loss": self.best_single[1]},
                "start": self.start.value, "evaluations": self.evaluations,
                "converged": self.converged}


@dataclass(frozen=True)
class GradeOutcome:
    """What a grade did.

    Attributes
    ----------
    source : where the colour map came from.
    n_styles : how many styles (style photos, or a preset's palettes) it drew on.
    look_strength : the strength the grade chose for its look: 1 for a preset's
        look and a palette grade, the set look's reliability (0: no look to
        apply), a style photo's scene match's confidence; None for a saved grade.
    blend : ``map.strength``, the blend x -> (1-t) x + t T(x).
    look_size : mean displacement of the map as applied (look strength and blend)
        over the whole colour cube, in 1/255 of the sRGB cube.
    mean_change : mean per-channel change of the photo's colours, 1/255 (sRGB cube).
    unchanged : the photo is essentially unchanged (strength under
        :data:`UNCHANGED_STRENGTH` or ``mean_change`` under :data:`UNCHANGED_CHANGE`).
    reason : why it is unchanged or faint, in words (None when it visibly changed).
    advice : what the user can do about it (None when it visibly changed).
    match : the style the grade leans on (the scene's style photo, or the
        palette grade a set look was moved towards), or None.
    confidence : how sure the grade is of ``match`` (0-1).
    palette : the weights and loss, for a palette grade only.
    file : the saved grade's file, for a saved grade.
    faint : changed, but hardly visibly (strength under :data:`FAINT_STRENGTH` or
        ``mean_change`` under :data:`FAINT_CHANGE`); ``reason`` says why.
    setting_names : how the caller names the library's settings (the command line: setting ->
        flag) in ``reason``, ``advice`` and :meth:`lines`; None: as the library does
        (:meth:`named`).
    """

    source: GradeSource
    n_styles: int
    look_strength: float | None
    blend: float
    look_size: float
    mean_change: float
    unchanged: bool = False
    reason: str | None = None
    advice: str | None = None
    match: str | None = None
    confidence: float = 0.0
    palette: PaletteFit | None = None
    file: str | None = None
    faint: bool = False
    extra: dict = field(default_factory=dict, compare=False)
    setting_names: Mapping[str, str] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.setting_names is not None:  # the reason and advice in the caller's names
            for key in ("reason", "advice"):
                text = getattr(self, key)
                if isinstance(text, Worded):
                    object.__setattr__(self, key, text.worded(self.setting_names))

    def named(self, names: Mapping[str, str] | None) -> GradeOutcome:
        """The same outcome with the settings its words name written as ``names`` says
        (setting -> the caller's name: the command line passes its flags)."""
        return self if names is None else replace(self, setting_names=names)

    @property
    def probability(self) -> float | None:
        """How sure it is that the style photos share a look (a set look judged jointly),
        else None."""
        value = self.extra.get("probability")
        return None if value is None else float(value)

    @property
    def own_photos(self) -> tuple[int, int]:
        """(the user's own photos a set look was measured against, those given for that but
        too few to use)."""
        used, unused = (int(self.extra.get(key) or 0) for key in OWN_PHOTO_KEYS)
        return used, unused

    @property
    def strength(self) -> float:
        """The fraction of the look applied: its own strength times ``map.strength``."""
        return (1.0 if self.look_strength is None else self.look_strength) * self.blend

    def headline(self, subject: str = "this photo") -> str:
        """One line: the source, the strength and how much ``subject``'s colours move
        (in percent of the tonal range, and how visible that is: :func:`change_words`)."""
        what, strength = self.source_words()
        strength_words = "" if strength is None else f", strength {strength:.2f}"
        return (f"grade: {what}{strength_words}; {subject}'s colours move "
                f"{change_words(self.mean_change)}")

    def source_words(self) -> tuple[str, float | None]:
        """(where the grade came from, in words; the strength to print with it, None where
        the words say it: a set look judged jointly says how much of it is applied, and its
        strength is worth printing only when it was asked for)."""
        what = self.source.describe(self.n_styles)
        if self.source is GradeSource.SAVED and self.file:
            learned = self.extra.get("learned") or self.file.startswith(LEARNED_PREFIX)
            what = (self.file if learned  # a look learned for this run from originals
                    else f"the saved grade {self.file} (applied as saved, no fit)")
        if self.source is GradeSource.OWN_SCENE and self.match:
            what = f"the look of the style photo of this scene ({self.match}, " \
                   f"matched {100 * self.confidence:.0f} % sure)"
        elif self.source is GradeSource.SET_LOOK and self.match and self.confidence > 0:
            what += (f", nudged {100 * self.confidence:.0f} % towards the colours of "
                     f"{self.match}, the closest style")
        if self.source is GradeSource.SET_LOOK and self.probability is not None:
            what += f" ({sureness_words(self.probability, self.strength)})"
        if self.probability is not None:  # the share applied is said; the strength asked for
            return what, (None if self.blend == 1.0 else self.blend)
        return what, self.strength

    def lines(self, subject: str = "this photo") -> list[str]:
        """The outcome in words, one line each (the headline, then why and what to do)."""
        lines = [self.headline(subject)]
        if self.unchanged:
            lines.append(f"the {subject.removeprefix('this ')} is essentially unchanged: "
                         f"{self.reason}")
        elif self.faint:
            lines.append(f"a faint grade: {self.reason}")
        if (self.unchanged or self.faint) and self.advice:
            lines.append(self.advice)
        if (self.source is GradeSource.SET_LOOK and self.probability is not None
                and self.probability < SURE_LOOK and not self.unchanged
                and not self.faint):
            lines.append(UNSURE_ADVICE.worded(self.setting_names or {}))
        own, unused = self.own_photos
        if own:
            lines.append(f"content: the look was measured against {own} of your own photos "
                         "beside the shipped palettes")
        elif unused and not (self.advice and (self.unchanged or self.faint)):
            lines.append(_unused_own_photos(unused) + ")")
        return lines

    def as_dict(self) -> dict:
        """JSON-friendly (a few hundred bytes; no arrays)."""
        out = {"source": self.source.value, "source_text": self.source.describe(self.n_styles),
               "n_styles": self.n_styles, "strength": round(self.strength, 4),
               "look_strength": None if self.look_strength is None
               else round(self.look_strength, 4),
               "blend": self.blend, "look_size_255": round(self.look_size, 3),
               "mean_change_255": round(self.mean_change, 3), "unchanged": self.unchanged,
               "faint": self.faint,
               "reason": _text(self.reason), "advice": _text(self.advice), "match": self.match,
               "confidence": round(self.confidence, 4)}
        if self.file is not None:
            out["file"] = self.file
        if self.probability is not None:  # a set look judged jointly: how sure it is a look
            out["look_probability"] = round(self.probability, 4)
        if self.palette is not None:
            out["palette"] = self.palette.as_dict()
        return out

    @classmethod
    def from_dict(cls, entry: dict) -> GradeOutcome:
        """The outcome :meth:`as_dict` wrote."""
        palette = entry.get("palette")
        if palette is not None:
            best = palette.get("best_single")
            palette = PaletteFit(tuple(w["style"] for w in palette["weights"]),
                                 tuple(float(w["weight"]) for w in palette["weights"]),
                                 float(palette["loss"]),
                                 None if best is None else (best["style"], float(best["loss"])),
                                 palette.get("start", "uniform"),
                                 int(palette.get("evaluations", 0)),
                                 bool(palette.get("converged", True)))
        strength = entry.get("look_strength")
        return cls(GradeSource(entry["source"]), int(entry.get("n_styles", 0)),
                   None if strength is None else float(strength), float(entry.get("blend", 1)),
                   float(entry.get("look_size_255", 0)), float(entry.get("mean_change_255", 0)),
                   bool(entry.get("unchanged", False)), entry.get("reason"),
                   entry.get("advice"), entry.get("match"), float(entry.get("confidence", 0)),
                   palette, entry.get("file"), bool(entry.get("faint", False)),
                   {"probability": float(entry["look_probability"])}
                   if "look_probability" in entry else {})

    @classmethod
    def judge(cls, source: GradeSource, n_styles: int, look_strength: float | None,
              blend: float, look_size: float, mean_change: float,
              why_weak: str | None = None, **more) -> GradeOutcome:
        """An outcome with ``unchanged``, ``reason`` and ``advice`` decided here.

        ``why_weak``: what made the look weak, in words, when the grade knows
        (e.g. the style photos share no look); the default reason otherwise.
        """
        strength = (1.0 if look_strength is None else look_strength) * blend
        unchanged = strength < UNCHANGED_STRENGTH or mean_change < UNCHANGED_CHANGE
        faint = not unchanged and (strength < FAINT_STRENGTH or mean_change < FAINT_CHANGE)
        reason = advice = None
        if faint:
            reason = f"the colours move by {change_words(mean_change)}"
            if strength < FAINT_STRENGTH and why_weak is not None:
                reason += f"; the look is applied at strength {strength:.2f}: {why_weak}"
            advice = unchanged_advice(source, blend, more.get("extra"))
        if unchanged:
            if blend < UNCHANGED_STRENGTH:
                reason = Worded(f"{{map.strength}} {blend:g} applies almost none of the grade",
                                STRENGTH)
            elif why_weak is not None and strength < UNCHANGED_STRENGTH:
                reason = why_weak
            elif look_size < UNCHANGED_CHANGE:
                reason = f"the grade itself moves colours by only {change_words(look_size)}"
            else:
                reason = (f"the grade moves these colours by only {change_words(mean_change)} "
                          "(it changes other colours more)")
            advice = unchanged_advice(source, blend, more.get("extra"))
        more["faint"] = faint
        if why_weak is not None:
            more["extra"] = {**more.get("extra", {}), "why_weak": why_weak}
        return cls(source, n_styles, look_strength, blend, look_size, mean_change, unchanged,
                   reason, advice, **more)

    def on_photo(self, mean_change: float) -> GradeOutcome:
        """The same grade judged on another photo (whose colours move by ``mean_change``)."""
        return GradeOutcome.judge(self.source, self.n_styles, self.look_strength, self.blend,
                                  self.look_size, mean_change, self.extra.get("why_weak"),
                                  match=self.match, confidence=self.confidence,
                                  palette=self.palette, file=self.file, extra=self.extra,
                                  setting_names=self.setting_names)


def _text(words: str | None) -> str | None:
    """Plain text (a :class:`~wbcgrade.errors.Worded` as the library names its settings)."""
    return None if words is None else str(words)


#: The set look's counts of the user's own photos (``LookFound``) that the advice
#: for a faint grade reads from ``GradeOutcome.extra``.
OWN_PHOTO_KEYS = ("own_photos", "own_photos_unused")


def _unused_own_photos(count: int) -> str:
    """The start of the words for own photos given but not used (the caller closes the
    parenthesis)."""
    return (f"your {count} own photo{'s were' if count != 1 else ' was'} not used "
            f"({MIN_OWN_PHOTOS} or more in colour are needed")


#: The settings the words of an outcome name (:class:`~wbcgrade.errors.Worded`).
STRENGTH = ("map.strength",)
ADVICE_SETTINGS = ("map.strength", "map.builder", "map.natural", "originals")


def unchanged_advice(source: GradeSource, blend: float,
                     look: dict | None = None) -> Worded | None:
    """What the user can do about a grade that leaves the photo unchanged (naming settings
    as the library does: :class:`~wbcgrade.errors.Worded`).

    ``look``: the set look's own photos (``own_photos``: the user's photos it was
    measured against; ``own_photos_unused``: photos given for that but too few)."""
    if blend < UNCHANGED_STRENGTH:
        return Worded("raise {map.strength} (1 applies the grade in full)", STRENGTH)
    if source is GradeSource.SET_LOOK:
        look = look or {}
        own, unused = int(look.get("own_photos") or 0), int(look.get("own_photos_unused") or 0)
        if own:
            content = f"the look is faint beside what your {own} own photos vary by; "
        elif unused:
            content = _unused_own_photos(unused) + " to tell a faint look from content); "
        else:
            content = (f"{{map.natural}} DIR with {MIN_OWN_PHOTOS} or more of your own ungraded "
                       "photos (what `batch` does with the photos it grades) helps tell a "
                       "faint look from what the photos show; ")
        return Worded("the original of one style photo settles it: {originals} DIR (a folder "
                      "with it, named as its edit) learns the look from that pair; " + content
                      + _PALETTE_OR_STRONGER, ADVICE_SETTINGS)
    if source is GradeSource.OWN_SCENE:
        return Worded(_PALETTE_OR_STRONGER, ADVICE_SETTINGS)
    if source is GradeSource.PRESET_LOOK:
        return Worded("{map.strength} above 1 strengthens the preset's look", STRENGTH)
    if source is GradeSource.PALETTE:
        return Worded("the style palettes are close to the photo's own: choose styles further "
                      "from it")
    return None


_PALETTE_OR_STRONGER = ("{map.builder} palette moves the photo's colours towards those of the "
                        "style photos; {map.strength} above 1 forces what look there is")

#: How a look learned for the run from originals names itself (its ``SavedFrom.file``).
LEARNED_PREFIX = "the look learned from "

#: Posterior probability of a look (the set look's ``probability``) from which the terminal
#: calls the style photos' look sure; under it, the set look's line says how unsure and
#: names the evidence that settles it (:data:`UNSURE_ADVICE`).
SURE_LOOK = 0.95
UNSURE_ADVICE = Worded("the style photos may share this look or only similar subjects: the "
                       "original of one of them settles it ({originals} DIR: a folder with the "
                       "unedited photo, named as its edit)", ("originals",))


def sureness_words(probability: float, share: float) -> str:
    """How sure a set's look is and how much of what the photos show is applied, in words.

    >>> sureness_words(0.99, 0.8), sureness_words(0.6, 0.2)
    ('the photos show it clearly; 80 % of it applied', 'unsure it is a look; 20 % of it applied')
    """
    how = ("the photos show it clearly" if probability >= SURE_LOOK else
           "fairly sure it is a look" if probability >= 0.75 else "unsure it is a look")
    return f"{how}; {100 * share:.0f} % of it applied"


#: How visible a mean change of colours is (upper bounds in 1/255 of the sRGB cube, words):
#: under :data:`UNCHANGED_CHANGE` not visible, under :data:`FAINT_CHANGE` barely visible.
VISIBILITY = ((UNCHANGED_CHANGE, "not visible"), (FAINT_CHANGE, "barely visible"),
              (8.0, "subtle"), (20.0, "clear"), (float("inf"), "strong"))


def change_words(mean_change: float) -> str:
    """A mean change of colours (1/255 of the sRGB cube) in words: the percent of the tonal
    range and how visible it is.

    >>> change_words(0.5), change_words(2.0), change_words(30.0)
    ('0.2 % on average (not visible)', '0.8 % on average (barely visible)', \
'11.8 % on average (strong)')
    """
    label = next(words for bound, words in VISIBILITY if mean_change < bound)
    return f"{100 * mean_change / 255:.1f} % on average ({label})"


def map_change(color_map: np.ndarray, strength: float, working: str,
               hist: np.ndarray | None = None) -> float:
    """Mean change of colours by a colour map, in 1/255 of the sRGB-encoded cube.

    Parameters
    ----------
    color_map : (m, m, m, 3) the map (working-space colours at the lattice's nodes).
    strength : the blend applied.
    working : the map's working space ("" or None: sRGB-encoded already).
    hist : (n, n, n) colour histogram of the photo in the working space: the mean
        per-channel change of its colours; None: the mean length |T(x) - x| of
        the displacement over the cube's colours (a 17^3 lattice).
    """
    if hist is None:
        colors, mass = grid_points(17), None
    else:
        flat = np.asarray(hist, dtype=np.float64).ravel()
        used = np.flatnonzero(flat > 0)
        if used.size == 0:
            return 0.0
        colors, mass = grid_points(hist.shape[0])[used], flat[used]
    colors = np.asarray(colors, dtype=np.float32)
    moved = np.asarray(apply_color_map(colors, np.asarray(color_map, dtype=np.float32),
                                       float(strength)), dtype=np.float64)
    before = np.asarray(colors, dtype=np.float64)
    if working:
        srgb = default_working_space()
        space = working if working == srgb else resolve_space(working)
        if space != srgb:
            before = np.clip(convert(before, space, srgb), 0.0, 1.0)
            moved = np.clip(convert(moved, space, srgb), 0.0, 1.0)
    if mass is None:
        return float(255.0 * np.mean(np.linalg.norm(moved - before, axis=1)))
    per_colour = np.mean(np.abs(moved - before), axis=1)
    return float(255.0 * np.sum(mass * per_colour) / np.sum(mass))
