"""What grading one photo produced: the graded pixels in memory and the run's report.

:class:`PhotoGrade` (:func:`wbcgrade.photos.workflow.grade_photo`) and
:class:`GradeReport` (:func:`wbcgrade.photos.workflow.grade_file`), kept
apart from the workflow so that what reads them (the palette weight report,
:mod:`wbcgrade.photos.report`) needs nothing of the workflow.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import Grade
from wbcgrade.color.io.images import Image
from wbcgrade.color.outcome import FitStart, fit_start_word
from wbcgrade.color.palette.fit import FitSummary

__all__ = ["PhotoGrade", "GradeReport"]


@dataclass
class PhotoGrade:
    """A graded photo in memory.

    Attributes
    ----------
    image : the decoded input.
    pixels : (H, W, C') float32 graded pixels (the image's value convention).
    alpha_channel : index of alpha in ``pixels`` or -1.
    grade : the grade applied (weights, colour map, palette).
    fit : weights and single-style comparison (None for a shared series grade
        whose summary the caller holds).
    encoding : the photo's input and working colour spaces.
    timings : seconds per stage.
    """

    image: Image
    pixels: np.ndarray
    alpha_channel: int
    grade: Grade
    fit: FitSummary | None
    encoding: ColorEncoding
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class GradeReport:
    """What :func:`grade_file` did, for printing, JSON and the report."""

    photo: Path
    output: Path | None
    lut: Path | None
    grade: Grade
    styles_source: str  # the style folder or preset, or a saved grade's file
    graded: PhotoGrade
    timings: dict[str, float] = field(default_factory=dict)
    fit: FitSummary | None = None
    report: Path | None = None

    @property
    def fit_start(self) -> str:
        """The JSON's ``fit_start`` (:func:`~wbcgrade.color.outcome.fit_start_word`): how a
        palette fit found the weights ("shared" for a series' grade whose fit the caller
        holds), else where the grade came from ("preset", "scene", "look", "saved")."""
        return fit_start_word(self.grade.source, None if self.fit is None else self.fit.start)

    @property
    def color(self) -> dict:
        """The colour spaces (JSON-friendly)."""
        return self.graded.encoding.as_dict()

    @property
    def outcome(self):
        """What the grade did to this photo (:class:`wbcgrade.color.outcome.GradeOutcome`),
        or None for a grade that has no outcome (built by hand)."""
        return self.grade.outcome

    def as_dict(self) -> dict:
        """JSON-friendly summary (a few KB: no colour map;
        :func:`~wbcgrade.color.grade.saved_grade.save_grade` writes the grade itself). The style
        weights and the fit's loss are there for a palette grade only (under ``"outcome"``
        and, as before, ``"weights"``/``"loss"``): a look grade has none that mean anything."""
        outcome = self.outcome
        palette = outcome is None or outcome.palette is not None
        info = {k: v for k, v in dict(self.grade.info).items() if palette or k != "fit"}
        out = {
            "photo": str(self.photo),
            "output": None if self.output is None else str(self.output),
            "lut": None if self.lut is None else str(self.lut),
            "styles": self.styles_source,
            "outcome": None if outcome is None else outcome.as_dict(),
            "fit_start": self.fit_start,
            "regrain": self.grade.regrain is not None,
            "timings_s": {k: round(v, 3) for k, v in self.timings.items()},
            **info,  # diagnostics of the fit, the look, the transport and the map
            "color": self.color,
            **({"report": str(self.report)} if self.report is not None else {}),
        }
        if palette:
            out.update({"weights": [{"style": name, "weight": round(w, 6)}
                                    for name, w in self.grade.ranked()],
                        "loss": self.grade.loss,
                        "fitted": FitStart(self.fit_start).fitted})
        return out
