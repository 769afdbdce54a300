"""``wbcgrade look extract``: the look a set of style photos shares, written as a LUT.

The files around :func:`wbcgrade.color.look.set_extraction.set_look_map` (which does the
mathematics): the LUT is planned and checked before any work
(:func:`wbcgrade._publish.plan_outputs`), the styles are loaded in the
working space, the look is extracted against the natural palettes (the
content model) and written as a .cube or CLF whose header names its space.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade._publish import plan_outputs
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import Grade
from wbcgrade.color.look.set_extraction import load_naturals, set_look_map
from wbcgrade.color.mapping.lut import check_lut_path, lut_format_of, write_grade_lut
from wbcgrade.color.outcome import (
    FAINT_STRENGTH,
    OWN_PHOTO_KEYS,
    UNCHANGED_STRENGTH,
    GradeOutcome,
    GradeSource,
    map_change,
)
from wbcgrade.color.presets import StyleSource, load_styles

__all__ = ["ExtractedLook", "extract_look_file"]

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
