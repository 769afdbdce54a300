"""What grading one photo produced: the graded pixels in memory and the run's report.

:class:`PhotoGrade` (:func:`wbcgrade.color.workflow.grade_photo`) and
:class:`GradeReport` (:func:`wbcgrade.color.workflow.grade_file`), kept
apart from the workflow so that what reads them (the palette weight report,
:mod:`wbcgrade.color.report`) needs nothing of the workflow.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.fit import FitSummary
from wbcgrade.color.grading import Grade
from wbcgrade.color.imageio import Image

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
    styles_source: str
    graded: PhotoGrade
    timings: dict[str, float] = field(default_factory=dict)
    fit: FitSummary | None = None
    report: Path | None = None

    @property
    def fit_start(self) -> str:
        """How the weights were found: "uniform", "vertex-refit", "vertex", "given" or
        "saved" (a saved grade, ``--look``: nothing fitted)."""
        return self.fit.start if self.fit is not None else "shared"

    @property
    def color(self) -> dict:
        """The colour spaces (JSON-friendly)."""
        return self.graded.encoding.as_dict()

    def as_dict(self, saved_grade: bool = False) -> dict:
        """JSON-friendly summary; ``saved_grade``: with the grade itself under
        ``"saved_grade"`` (what ``apply --look`` reads back, no fit)."""
        saved = {}
        if saved_grade:
            from wbcgrade.color.saved_look import look_dict

            saved = {"saved_grade": look_dict(self.grade)}
        return {
            "photo": str(self.photo),
            "output": None if self.output is None else str(self.output),
            "lut": None if self.lut is None else str(self.lut),
            "styles": self.styles_source,
            "weights": [{"style": name, "weight": round(w, 6)} for name, w in self.grade.ranked()],
            "loss": self.grade.loss,
            "fitted": self.fit_start not in ("given", "saved"),
            "fit_start": self.fit_start,
            "regrain": self.grade.regrain is not None,
            "timings_s": {k: round(v, 3) for k, v in self.timings.items()},
            **dict(self.grade.info),
            "color": self.color,
            **({"report": str(self.report)} if self.report is not None else {}),
            **saved,
        }
