"""The ``apply`` command's workflow: plan every output, load the styles, grade, report.

Above :mod:`wbcgrade.color.workflow` (one photo file end to end) and
:mod:`wbcgrade.color.report` (the palette weight report), which it joins.
"""

from __future__ import annotations

import os
import time

from wbcgrade.color.imageio import WriteOptions
from wbcgrade.color.lut import DEFAULT_LUT_SIZE
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.presets import StyleSource, load_styles
from wbcgrade.color.report import plan_report, report_from_grade
from wbcgrade.color.workflow import GradeReport, Progress, grade_file, plan_photo

__all__ = ["apply_photo"]


def apply_photo(photo: str | os.PathLike, source: StyleSource, options: GradeOptions,
                output: str | os.PathLike | None = None, lut: str | os.PathLike | None = None,
                lut_size: int = DEFAULT_LUT_SIZE, lut_format: str | None = None,
                overwrite: bool = False, report_dir: str | os.PathLike | None = None,
                progress: Progress | None = None,
                encode: WriteOptions | None = None) -> GradeReport:
    """``wbcgrade apply``: grade ``photo`` towards the styles of ``source`` and write it.

    Every output (the graded photo, the LUT, the report's files) is planned
    and checked before any work; then the styles are loaded, the photo is
    graded and written (:func:`grade_file`) and, with ``report_dir``, the
    palette weight report is written (:func:`wbcgrade.color.report.report_from_grade`).
    ``encode``: JPEG/WebP quality and bit depth of the graded photo.
    """
    progress = progress or Progress()
    plan = plan_photo(photo, output, lut, lut_size, lut_format, overwrite, encode=encode)
    if report_dir is not None:
        plan_report(report_dir, [plan.photo.name], [plan.photo], overwrite)
    start = time.perf_counter()
    styles = load_styles(source, options.transfer.bins, options.spaces.working, progress.warn,
                         progress.styles)
    report = grade_file(plan, styles, options, progress=progress,
                        timings={"styles": time.perf_counter() - start})
    if report_dir is not None:
        report.report = report_from_grade(report_dir, report, styles, options, overwrite)
    return report
