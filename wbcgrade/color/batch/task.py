"""One photo of a batch: what every task needs, grading one file, reading its histograms.

These functions run in worker processes (local or Dask): they take the
task and the :class:`BatchContext` that the executor sends once to each
worker, and turn failures about the file into values, so that one bad photo
does not stop the others.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade._publish import check_regular_target
from wbcgrade.color.batch.plan import BatchTask
from wbcgrade.color.batch.results import FileResult
from wbcgrade.color.grading import FitSummary, grade_photo, photo_histograms
from wbcgrade.color.imageio import (
    check_image_output,
    max_image_pixels,
    set_max_image_pixels,
    write_image,
)
from wbcgrade.color.presets import StyleSet
from wbcgrade.color.transfer import Grade, GradeOptions
from wbcgrade.errors import WbcgradeError

__all__ = ["BatchContext", "run_task", "read_histograms", "setup_worker", "absolute_task",
           "absolute_context"]


@dataclass
class BatchContext:
    """What every task needs (sent once to each worker).

    Attributes
    ----------
    styles : the style set.
    opts : grading options.
    shared : the series grade (``--consistent``), or None for one fit per photo.
    shared_fit : its weights and single-style losses.
    sheet_dir : write a PNG sheet per photo here (None: no sheets).
    style_pictures : (h, w, 3) display thumbnails per style name, for sheets.
    write_outputs : False to grade in memory only (``wbcgrade report``).
    max_image_pixels : decoding limit of every photo (the creating process's limit
        by default; sent to the workers with the rest).
    """

    styles: StyleSet
    opts: GradeOptions
    shared: Grade | None = None
    shared_fit: FitSummary | None = None
    sheet_dir: Path | None = None
    style_pictures: dict[str, np.ndarray] | None = None
    write_outputs: bool = True
    max_image_pixels: int = field(default_factory=max_image_pixels)




def run_task(task: BatchTask, context: BatchContext,
             callback: Callable[[int, np.ndarray, float], None] | None = None,
             stage: Callable[[str], None] | None = None) -> FileResult:
    """Grade one photo and write its output (and sheet); failures become a 'failed' result.

    Only errors about this file (unreadable, corrupt, unwritable) are caught;
    KeyboardInterrupt and programming errors propagate.
    """
    start = time.perf_counter()
    result = FileResult(task.relative, str(task.source),
                        None if task.output is None else str(task.output), "failed")
    set_max_image_pixels(context.max_image_pixels)
    try:
        if context.write_outputs and task.output is not None:  # before any work
            check_image_output(task.output)
            check_regular_target(task.output)
        graded = grade_photo(task.source, context.styles, context.opts, context.shared,
                             callback, stage)
        fit = graded.fit if graded.fit is not None else context.shared_fit
        result.names = list(context.styles.names)
        result.weights = [float(w) for w in fit.weights]
        result.loss = float(fit.loss)
        result.vertex_losses = [float(v) for v in fit.vertex_losses]
        result.start = fit.start
        result.timings = dict(graded.timings)
        result.color = graded.spaces.as_dict() if graded.spaces is not None else {}
        if context.write_outputs and task.output is not None:
            if stage:
                stage("write")
            t0 = time.perf_counter()
            task.output.parent.mkdir(parents=True, exist_ok=True)
            write_image(task.output, graded.pixels, graded.image, overwrite=True,
                        alpha_channel=graded.alpha_channel)
            result.timings["write"] = time.perf_counter() - t0
        result.timings["total"] = time.perf_counter() - start
        if context.sheet_dir is not None:
            from wbcgrade.color.report import sheet_content
            from wbcgrade.color.sheet import write_sheet

            sheet = Path("sheets") / f"{task.relative}.png"
            write_sheet(context.sheet_dir / sheet,
                        sheet_content(result, graded, context.style_pictures))
            result.sheet = sheet.as_posix()
        result.status = "graded"
    except (WbcgradeError, ValueError, OSError, MemoryError) as exc:
        text = str(exc).strip().splitlines()
        result.error = text[0] if text else type(exc).__name__
        result.status = "failed"
    result.timings["total"] = time.perf_counter() - start
    return result


def read_histograms(task: BatchTask, context: BatchContext,
                    bins: tuple[int, ...]) -> dict[int, np.ndarray] | str:
    """The photo's histograms ``{bins: (bins, bins, bins)}``, or its one-line error."""
    set_max_image_pixels(context.max_image_pixels)
    try:
        return photo_histograms(task.source, bins, context.opts.max_pixels,
                                context.opts.input_space, context.opts.working_space)
    except (WbcgradeError, ValueError, OSError, MemoryError) as exc:
        text = str(exc).strip().splitlines()
        return text[0] if text else type(exc).__name__


def setup_worker(context: BatchContext) -> None:
    """Run once in each local worker process: the decoding limit of the parent."""
    set_max_image_pixels(context.max_image_pixels)


def absolute_task(task: BatchTask) -> BatchTask:
    """The task with absolute paths (Dask workers run in another folder)."""
    return dataclasses.replace(task, source=Path(os.path.abspath(task.source)),
                               output=None if task.output is None
                               else Path(os.path.abspath(task.output)))


def absolute_context(context: BatchContext) -> BatchContext:
    """The context with an absolute sheet folder (Dask workers run in another folder)."""
    if context.sheet_dir is None:
        return context
    return dataclasses.replace(context, sheet_dir=Path(os.path.abspath(context.sheet_dir)))
