"""Looks written as grades: a set's look (``wbcgrade look extract``) and a look learned
from before/after pairs (``wbcgrade look learn``, a grade given the originals).

The files around the looks' mathematics (:func:`wbcgrade.color.look.set_extraction.set_look_map`,
:func:`wbcgrade.color.look.learn.learn_look`): outputs are planned and checked before any
work (:func:`wbcgrade._publish.plan_outputs`), the styles or pairs are read in the working
space, and the look is written as a .cube or CLF whose header names its space, or as a
saved grade.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from dataclasses import replace as replaced
from pathlib import Path

import numpy as np

from wbcgrade._publish import plan_outputs, publish_bytes
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import Grade
from wbcgrade.color.grade.saved_grade import look_dict
from wbcgrade.color.look.learn import LearnResult, learn_look, match_files
from wbcgrade.color.look.set_extraction import load_naturals, set_look_map
from wbcgrade.color.mapping.lut import (
    check_lut_path,
    check_lut_size,
    lut_format_of,
    write_grade_lut,
)
from wbcgrade.color.outcome import (
    FAINT_STRENGTH,
    OWN_PHOTO_KEYS,
    UNCHANGED_STRENGTH,
    GradeOutcome,
    GradeSource,
    SavedFrom,
    map_change,
)
from wbcgrade.color.presets import StyleSource, load_styles
from wbcgrade.errors import InputError, OptionError

__all__ = ["ExtractedLook", "extract_look_file", "learned_grade", "learn_look_file"]

#: Grid of the style histograms the look is extracted from.
STYLE_BINS = 32


@dataclass
class ExtractedLook:
    """What :func:`extract_look_file` wrote.

    Attributes
    ----------
    lut : the LUT file.
    styles : the style names.
    strength : the scale the look was applied at.
    info : what the extraction found (JSON-friendly; ``amplitude_applied``:
        the mean colour shift in cube units, ...).
    outcome : what the LUT does, in plain terms (its ``mean_change`` is over the
        whole cube: there is no photo), or None.
    """

    lut: Path
    styles: list[str]
    strength: float
    info: dict = field(default_factory=dict)
    outcome: GradeOutcome | None = None

    def as_dict(self) -> dict:
        """JSON-friendly summary."""
        return {"lut": str(self.lut), "styles": list(self.styles), "strength": self.strength,
                **self.info,
                **({} if self.outcome is None else {"outcome": self.outcome.as_dict()})}


def extract_look_file(source: StyleSource, output: str | os.PathLike, *, lut_size: int = 33,
                      lut_format: str | None = None, strength: float | None = None,
                      natural: str | os.PathLike | None = None,
                      working_space: str | None = None, overwrite: bool = False,
                      warn: Callable[[str], None] | None = None,
                      on_style: Callable[[int, int, str], None] | None = None,
                      on_look: Callable[[int, int], None] | None = None) -> ExtractedLook:
    """Extract the look ``source``'s photos share and write it as a 3-D LUT.

    Parameters
    ----------
    source : a style folder or a preset (a preset's own look, when it carries
        one, is the look itself).
    output : the LUT file (.cube or .clf; ``lut_format`` names it, else its ending).
    lut_size : nodes per axis.
    strength : scale of the look; None: all of a preset's own look, an extracted
        one at its reliability (how far the two halves of the set agree).
    natural : a preset (.npz) of ungraded photos, the content model (None:
        the shipped one).
    working_space : where the look is extracted and the LUT applied (None:
        sRGB-encoded Rec.709).
    warn, on_style, on_look : messages (skipped files), styles read
        ``(done, total, name)``, styles explained ``(done, total)``.

    Raises
    ------
    InputError
        The LUT may not be written (checked before any work), unreadable styles.
    """
    lut_format = lut_format_of(output, lut_format, "output")
    check_lut_path(output, lut_format)
    output = plan_outputs([output], [], overwrite)[0]  # before any work
    encoding = ColorEncoding.of(None, working_space).within_working()
    styles = load_styles(source, STYLE_BINS, working_space, warn, on_style)
    naturals = load_naturals(natural, styles.working_space)
    # strength None: a preset's own look in full, an extracted one at its reliability
    asked = strength
    lattice, info = set_look_map(styles, naturals, strength, lut_size, on_look)
    strength = info.strength
    grade = Grade(tuple(styles.names), np.full(len(styles.names), 1.0 / len(styles.names)),
                  lattice, working=encoding.working)
    path = write_grade_lut(output, grade, encoding, lut_size, lut_format,
                           title="wbcgrade look", overwrite=overwrite,
                           comments=[f"look of {len(styles.names)} style photos"])
    size = map_change(lattice, 1.0, encoding.working)
    n_styles = len(styles.names)
    preset = info.from_preset
    why = None
    if not preset and strength < FAINT_STRENGTH:
        how = "no" if strength < UNCHANGED_STRENGTH else "little"
        why = (f"these {n_styles} style photos share {how} look that can be told apart "
               "from their content")
    extra = {k: info.count(k) for k in OWN_PHOTO_KEYS}
    look_strength, blend = float(strength), 1.0
    if info.probability is not None:
        # judged jointly, as apply says it: the share the photos show and the strength asked
        extra["probability"] = info.probability
        look_strength, blend = info.share, 1.0 if asked is None else float(asked)
    outcome = GradeOutcome.judge(GradeSource.PRESET_LOOK if preset else GradeSource.SET_LOOK,
                                 n_styles, look_strength, blend, size, size, why, extra=extra)
    return ExtractedLook(path, list(styles.names), float(strength), dict(info), outcome)


# --------------------------------------------------------------------------- learned looks

def _output_kind(output: Path) -> str:
    suffix = output.suffix.lower()
    if suffix == ".json":
        return "json"
    if suffix in (".cube", ".clf"):
        return suffix[1:]
    raise OptionError(f"{output}: {{output}} must be written as .cube, .clf or .json "
                      "(the ending names the format)", "output", path=output)


def learned_grade(before: str | os.PathLike, after: str | os.PathLike, *,
                  lut_size: int = 33, working_space: str | None = None,
                  warn: Callable[[str], None] | None = None,
                  progress: Callable[[int, int, str], None] | None = None):
    """The look of before/after pairs (and of edits without originals) as a grade.

    What ``look learn`` writes and a saved look reads back, and what a style folder with
    the originals of some of its photos applies: the learned look sampled as a
    ``lut_size``^3 lattice, in the look's working space, no regrain settings.

    Parameters
    ----------
    before, after : two photos, or two folders (:func:`match_files`): the originals,
        and the edited photos (those without an original count too).

    Returns (:class:`~wbcgrade.color.grade.grading.Grade`, :class:`LearnResult`).

    Raises
    ------
    InputError
        The paths do not pair, or no pair is usable (each pair's reason went to
        ``warn`` first).
    """
    check_lut_size(lut_size)
    matched = match_files(before, after)
    pairs, problems = matched.pairs, matched.problems
    warn = warn or (lambda message: None)
    for name, why in problems:
        warn(f"{name}: {why}")
    if not pairs:
        raise InputError(f"no before/after pairs: no photo in {after} has the name of one "
                         f"in {before}")
    result = learn_look(pairs, working_space, problems, warn, progress,
                        edits_alone=matched.edits_alone)
    if result.look is None:
        raise InputError(f"no usable before/after pair (all {len(pairs)} left out: see "
                         "the lines above)")
    encoding = ColorEncoding.of(result.working_space, result.working_space)
    described = result.describe()
    if result.far_trust:  # (few pairs, with edits without originals: how far it carries)
        described += (f", followed {100 * result.far_trust['by_edits']:.0f} % of the way "
                      "away from the pairs' colours")
    source = {"file": described, "kind": "learned"}
    if result.original_to_add:  # (the report's JSON: the original that would teach most)
        source["original_to_add"] = result.original_to_add_dict()
    grade = Grade(("learned look",), np.ones(1), result.look.lattice(lut_size),
                  working=encoding.working,  # no regrain: the look as the pairs show it
                  info={"saved_look": source},
                  saved=SavedFrom(described, "learned"))
    return grade, result


def learn_look_file(before: str | os.PathLike, after: str | os.PathLike,
                    output: str | os.PathLike, *, lut_size: int = 33,
                    working_space: str | None = None, overwrite: bool = False,
                    warn: Callable[[str], None] | None = None,
                    progress: Callable[[int, int, str], None] | None = None) -> LearnResult:
    """Learn the look of before/after pairs and write it as a LUT or a saved grade.

    Parameters
    ----------
    before, after : two photos or two folders (:func:`match_files`; edited photos
        without an original are evidence too: :func:`unpaired_correction`).
    output : ``.cube`` or ``.clf`` (a LUT whose header names its working
        space) or ``.json`` (a saved grade: ``{"saved_grade": ..., "learned":
        the report}``); checked before any work, never an input.
    lut_size : nodes per axis of the written map.
    working_space : None: :func:`learn_space`.
    warn, progress : as :func:`learn_look`; every pair that cannot be paired
        or used gets one ``warn`` line.

    Raises
    ------
    InputError
        The output may not be written, the paths do not pair, or no pair is
        usable (each pair's reason went to ``warn`` first).
    """
    output = Path(output)
    kind = _output_kind(output)
    check_lut_size(lut_size)
    matched = match_files(before, after)
    inputs = ([p.before for p in matched.pairs] + [p.after for p in matched.pairs]
              + matched.edits_alone)
    output = plan_outputs([output], inputs, overwrite)[0]  # before any work
    grade, result = learned_grade(before, after, lut_size=lut_size,
                                  working_space=working_space, warn=warn, progress=progress)
    grade = replaced(grade, info={}, saved=None)
    encoding = ColorEncoding.of(result.working_space, result.working_space)
    n = len(result.used)
    if kind == "json":
        result.output = output
        data = {"saved_grade": look_dict(grade), "learned": result.as_dict()}
        publish_bytes(output, (json.dumps(data, indent=1) + "\n").encode(), overwrite)
    else:
        comments = [f"look learned from {n} before/after pair{'s' if n != 1 else ''}"
                    + (f" and {len(result.edits_alone)} edited photo"
                       f"{'s' if len(result.edits_alone) != 1 else ''} without an original"
                       if result.edits_alone else "")]
        if result.held_out is not None:
            comments.append(f"mean CIEDE2000 on the pairs {result.delta_e:.2f}, "
                            f"held out {result.held_out:.2f}")
        result.output = write_grade_lut(output, grade, encoding, lut_size, kind,
                                        title="wbcgrade learned look", comments=comments,
                                        overwrite=overwrite)
    return result


# ------------------------------------------------------------------- edits without originals
