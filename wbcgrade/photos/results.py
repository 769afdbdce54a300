"""What a batch did: one FileResult per photo, and the BatchResult of a run."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wbcgrade.color.outcome import GradeOutcome
from wbcgrade.color.palette.fit import NONZERO_THRESHOLD, FitSummary

if TYPE_CHECKING:  # (a report of a batch's results loads no grade)
    from wbcgrade.color.grade.grading import Grade

__all__ = ["FileResult", "BatchResult"]


@dataclass
class FileResult:
    """What happened to one photo (JSON-friendly via :meth:`as_dict`)."""

    relative: str
    source: str
    output: str | None
    status: str  # "graded", "skipped" or "failed"
    error: str = ""
    names: list[str] = field(default_factory=list)
    weights: list[float] = field(default_factory=list)
    loss: float | None = None
    vertex_losses: list[float] = field(default_factory=list)
    start: str = ""
    sheet: str | None = None
    timings: dict[str, float] = field(default_factory=dict)
    color: dict = field(default_factory=dict)  # colour spaces and config (ColorEncoding)
    own_style: dict | None = None  # the photo is one of the styles (presets.own_style)
    palette: dict | None = None  # display colours and shares the grade aimed at (sheets)
    outcome: dict | None = None  # what the grade did (GradeOutcome.as_dict())
    chart: dict | None = None  # a look grade: a colour chart through it (report.chart_record)

    @property
    def grade_outcome(self):
        """The :class:`~wbcgrade.color.outcome.GradeOutcome` of the grade, or None (a record
        from before outcomes, a photo not graded)."""
        if not self.outcome:
            return None
        return GradeOutcome.from_dict(self.outcome)

    @property
    def has_weights(self) -> bool:
        """Whether the weights mean something: a palette grade's (a look grade has none)."""
        return bool(self.weights) and (not self.outcome
                                       or self.outcome.get("palette") is not None)

    @property
    def n_nonzero(self) -> int:
        return int(sum(w >= NONZERO_THRESHOLD for w in self.weights))

    def as_dict(self) -> dict:
        """Report entry: ranked weights, fitted and best single-style loss, time."""
        order = sorted(range(len(self.weights)), key=lambda i: -self.weights[i])
        entry: dict = {"photo": self.relative, "source": self.source, "output": self.output,
                       "status": self.status}
        if self.error:
            entry["error"] = self.error
        if self.outcome:
            entry["outcome"] = self.outcome
            if not self.has_weights and self.names:
                entry["style_names"] = list(self.names)
        if self.has_weights:
            best = int(np.argmin(self.vertex_losses)) if self.vertex_losses else None
            entry.update({
                "weights": [{"style": self.names[i], "weight": round(self.weights[i], 6)}
                            for i in order],
                "loss": self.loss,
                "best_single_style": None if best is None else {
                    "style": self.names[best], "loss": self.vertex_losses[best]},
                "single_style_losses": dict(zip(self.names, self.vertex_losses)),
                "fit_start": self.start,
                "nonzero_weights": self.n_nonzero,
                "nonzero_threshold": NONZERO_THRESHOLD,
            })
        if self.own_style:
            entry["own_style"] = self.own_style
        if self.palette:
            entry["target_palette"] = self.palette
        if self.chart:
            entry["look_chart"] = self.chart
        if self.color:
            entry["color"] = self.color
        if self.sheet:
            entry["sheet"] = self.sheet
        entry["time_s"] = round(self.timings.get("total", 0.0), 3)
        entry["timings_s"] = {k: round(v, 3) for k, v in self.timings.items()}
        return entry

    @classmethod
    def from_dict(cls, entry: dict) -> FileResult:
        """The result an :meth:`as_dict` entry describes (weights back in the styles'
        order; rounded as the entry holds them). Raises KeyError, TypeError or
        ValueError on an entry that is not one (any JSON: a record may be damaged)."""
        if not isinstance(entry, dict):
            raise TypeError(f"a result record is a JSON object, not {type(entry).__name__}")
        try:
            return cls._from_dict(entry)
        except AttributeError as exc:  # a field of the wrong kind (a list for an object)
            raise TypeError(str(exc)) from None

    @classmethod
    def _from_dict(cls, entry: dict) -> FileResult:
        losses = entry.get("single_style_losses") or {}
        weights = {str(w["style"]): float(w["weight"]) for w in entry.get("weights", [])}
        names = list(losses) or list(weights) or [str(n) for n in entry.get("style_names", [])]
        return cls(str(entry["photo"]), str(entry["source"]), entry.get("output"),
                   str(entry["status"]), error=str(entry.get("error", "")), names=names,
                   weights=[weights.get(name, 0.0) for name in names],
                   loss=None if entry.get("loss") is None else float(entry["loss"]),
                   vertex_losses=[float(losses[name]) for name in losses],
                   start=str(entry.get("fit_start", "")), sheet=entry.get("sheet"),
                   timings={k: float(v) for k, v in entry.get("timings_s", {}).items()},
                   color=dict(entry.get("color", {})), own_style=entry.get("own_style"),
                   palette=entry.get("target_palette"), outcome=entry.get("outcome"),
                   chart=entry.get("look_chart"))


@dataclass
class BatchResult:
    """Outcome of a batch: one FileResult per photo (graded, skipped, failed), the time,
    for a series its weights (``series``) and grade (``series_grade``, colour map), and
    what else was written (``report``: report.json, ``lut``: the series LUT), and how many
    of the batch's own photos the look was told content looks like (``own_photos``)."""

    results: list[FileResult]
    ignored: list[str]
    time_s: float
    series: FitSummary | None = None
    style_names: list[str] = field(default_factory=list)
    series_grade: Grade | None = None
    report: Path | None = None
    lut: Path | None = None
    own_photos: int = 0

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.results)
