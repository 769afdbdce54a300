"""The ``video`` command's workflow: plan every output, load the styles, grade, report.

Above :mod:`wbcgrade.video.workflow` (a clip graded end to end) and
:mod:`wbcgrade.video.report` (contact sheets and report.json), which it joins.
"""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import replace

from wbcgrade.color.grade.saved_grade import look_batch_options
from wbcgrade.color.options import GradeOptions, RegrainOptions
from wbcgrade.color.presets import StyleSource, load_styles, source_files
from wbcgrade.video.report import plan_video_report, write_video_report
from wbcgrade.video.workflow import (
    VideoProgress,
    VideoResult,
    VideoSettings,
    grade_planned,
    plan_video,
)

__all__ = ["grade_clip"]


def grade_clip(source: str | os.PathLike, output: str | os.PathLike | None,
               styles: StyleSource, options: GradeOptions, *, settings: VideoSettings | None = None,
               lut: str | os.PathLike | None = None, overwrite: bool = False,
               report_dir: str | os.PathLike | None = None,
               progress: VideoProgress | None = None, look=None) -> VideoResult:
    """``wbcgrade video``: plan every output, load the styles, grade the clip, write the report.

    The clip's grade is a LUT: ``options.regrain`` is turned off. The report
    (a contact sheet per shot and report.json, :mod:`wbcgrade.video.report`)
    never replaces files it did not write unless ``overwrite``. The clip, its
    LUTs and the report are published together once all are written: a
    failure in any (a full disk under the LUT, a report folder that cannot be
    written) publishes none. ``look``: a saved grade
    (:func:`wbcgrade.color.grade.saved_grade.load_look`) applied to every frame
    instead of a fit (``styles`` is not read).
    """
    settings = settings or VideoSettings()
    progress = progress or VideoProgress()
    reads = source_files(None if look is not None else styles, options.map.natural, look)
    source, output, lut = plan_video(source, output, lut, settings, overwrite, reads)
    if report_dir is not None:
        plan_video_report(report_dir, [source, *reads], overwrite)
    if options.regrain.enabled:
        options = replace(options, regrain=RegrainOptions(enabled=False))
    start = time.perf_counter()
    if look is None:
        loaded = load_styles(styles, options.transfer.bins, options.spaces.working,
                             progress.warn, progress.styles)
    else:
        options = look_batch_options(options, look, report_dir=report_dir)
        loaded = None
    with contextlib.ExitStack() as stack:  # every output published together, or none
        result = grade_planned(source, output, lut=lut, styles=loaded, options=options,
                               settings=settings, overwrite=overwrite, progress=progress,
                               timings={"styles": time.perf_counter() - start}, stack=stack,
                               look=look)
        if report_dir is not None:
            result.report = write_video_report(report_dir, result, loaded, overwrite, stack)
    return result
