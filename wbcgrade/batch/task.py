"""One photo of a batch: what every task needs, grading one file, reading its histograms.

These functions run in worker processes (local or Dask): they take the
task and the :class:`BatchContext` that the executor sends once to each
worker, and turn failures about the file into values, so that one bad photo
does not stop the others. A photo is graded and written by the same
:func:`wbcgrade.photos.workflow.grade_file` as ``wbcgrade apply``.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade.batch.plan import BatchTask
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import Grade, PhotoHistograms, photo_histograms
from wbcgrade.color.io.cache import command_cache, set_command_cache
from wbcgrade.color.io.images import (
    WriteOptions,
    check_image_output,
    max_image_pixels,
    read_image,
    set_max_image_pixels,
)
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.outcome import fit_start_word
from wbcgrade.color.palette.fit import FitSummary
from wbcgrade.color.presets import StyleSet
from wbcgrade.core import prefer_compiled
from wbcgrade.errors import WbcgradeError, first_line
from wbcgrade.photos.report import chart_record, palette_record, sheet_content, sheet_path
from wbcgrade.photos.results import FileResult
from wbcgrade.photos.sheet import write_sheet
from wbcgrade.photos.workflow import PhotoPlan, Progress, grade_file

__all__ = ["BatchContext", "run_task", "read_histograms", "setup_worker", "absolute_task",
           "absolute_context", "lost_task"]


@dataclass
class BatchContext:
    """What every task needs (sent once to each worker).

    Attributes
    ----------
    styles : the style set (None with a saved grade: ``shared`` is it).
    options : grading options.
    shared : the series grade or a saved grade, or None for one fit per photo.
    shared_fit : the series grade's weights and single-style losses (None for a saved one).
    sheet_dir : write a PNG sheet per photo here (None: no sheets).
    style_pictures : (h, w, 3) display thumbnails per style name, for sheets.
    write_outputs : False to grade in memory only (``wbcgrade report``).
    overwrite : replace existing outputs and sheets (checked before the run).
    replace_sheets : replace existing sheets (the report folder is the batch's own, from
        an earlier run: :func:`wbcgrade.photos.report.own_report`).
    max_image_pixels : decoding limit of every photo (the creating process's limit
        by default; sent to the workers with the rest).
    encode : JPEG/WebP quality and bit depth of the outputs.
    setting_names : how the command names the library's settings (setting -> flag) in what the
        records say (:attr:`wbcgrade.photos.progress.Progress.setting_names`); None: as the library.
    """

    styles: StyleSet | None
    options: GradeOptions
    shared: Grade | None = None
    shared_fit: FitSummary | None = None
    sheet_dir: Path | None = None
    style_pictures: dict[str, np.ndarray] | None = None
    write_outputs: bool = True
    overwrite: bool = False
    replace_sheets: bool = False
    max_image_pixels: int = field(default_factory=max_image_pixels)
    #: the command's cache (``cache.command_cache``), for the workers' own caches
    cache: tuple[Path, bool] = field(default_factory=command_cache)
    encode: WriteOptions = WriteOptions()
    setting_names: dict[str, str] | None = None

    @property
    def style_names(self) -> list[str]:
        """The styles' names (a saved grade's own names)."""
        return list(self.styles.names if self.styles is not None else self.shared.names)


def run_task(task: BatchTask, context: BatchContext,
             progress: Progress | None = None) -> FileResult:
    """Grade one photo and write its output (and sheet); failures become a 'failed' result.

    The output was checked when the batch was planned. Any error grading this one
    photo is its failure (an unexpected one named an internal error); only
    KeyboardInterrupt (and SystemExit) propagate.
    """
    start = time.perf_counter()
    if progress is None and context.setting_names is not None:  # a worker: the command's words
        progress = Progress(setting_names=context.setting_names)
    starting = getattr(progress, "photo", None)  # a batch's progress names the photo
    if starting is not None:
        starting(task.relative)
    result = FileResult(task.relative, str(task.source),
                        None if task.output is None else str(task.output), "failed")
    set_max_image_pixels(context.max_image_pixels)
    try:
        target = (task.target or task.output) if context.write_outputs else None
        replace = context.overwrite or task.replace  # replace: an unrecorded output healed
        plan = PhotoPlan(task.source, target, overwrite=replace,
                         encode=context.encode)
        if target is not None:
            check_image_output(target)  # before any work
            target.parent.mkdir(parents=True, exist_ok=True)
        report = grade_file(plan, context.styles, context.options, shared=context.shared,
                            progress=progress)
        fit = report.fit if report.fit is not None else context.shared_fit
        result.names = context.style_names
        if fit is None:  # a saved grade: its own weights, nothing fitted
            result.weights = [float(w) for w in report.grade.weights]
            result.loss = float(report.grade.loss or 0.0)
            result.start = report.fit_start
        else:
            result.weights = [float(w) for w in fit.weights]
            result.loss = float(fit.loss)
            result.vertex_losses = [float(v) for v in fit.vertex_losses]
            result.start = fit_start_word(report.grade.source, fit.start)
        result.timings = dict(report.timings)
        result.color = report.color
        result.own_style = report.grade.own_style
        result.outcome = None if report.outcome is None else report.outcome.as_dict()
        result.palette = palette_record(report.grade, report.graded.encoding)
        result.chart = chart_record(report.grade, report.graded.encoding)
        result.timings["total"] = time.perf_counter() - start
        if context.sheet_dir is not None:
            sheet = sheet_path(task.relative)
            write_sheet(context.sheet_dir / sheet,
                        sheet_content(result, report.graded, context.style_pictures),
                        overwrite=replace or context.replace_sheets)
            result.sheet = sheet.as_posix()
        result.status = "graded"
    except (WbcgradeError, ValueError, OSError, MemoryError) as exc:
        result.error = first_line(_in_words(exc, context.setting_names))
        result.status = "failed"
    except Exception as exc:  # noqa: BLE001 - a fault on one photo never stops the batch
        result.error = f"internal error ({type(exc).__name__}: {first_line(exc)})"
        result.status = "failed"
    result.timings["total"] = time.perf_counter() - start
    return result


def _in_words(exc: BaseException, names: dict[str, str] | None) -> object:
    """An error's message with the settings it names written as ``names`` says."""
    worded = getattr(exc, "worded", None)
    return exc if worded is None or names is None else worded(names)


def lost_task(task: BatchTask, reason: str) -> FileResult:
    """The failed result of a photo whose worker process died (``reason``)."""
    return FileResult(task.relative, str(task.source),
                      None if task.output is None else str(task.output), "failed",
                      error=reason, timings={"total": 0.0})


def read_histograms(task: BatchTask, context: BatchContext) -> PhotoHistograms | str:
    """The photo's histograms on the fit and transfer grids, or its one-line error."""
    set_max_image_pixels(context.max_image_pixels)
    options = context.options
    try:
        image = read_image(task.source)
        encoding = ColorEncoding.for_image(image, options.spaces.input, options.spaces.working)
        encoded, _ = encoding.encode(image.rgb(), image.is_float)
        return photo_histograms(encoded, options, image.alpha())
    except (WbcgradeError, ValueError, OSError, MemoryError) as exc:
        return first_line(_in_words(exc, context.setting_names))
    except Exception as exc:  # noqa: BLE001 - a fault on one photo never stops the batch
        return f"internal error ({type(exc).__name__}: {first_line(exc)})"


def setup_worker(context: BatchContext) -> None:
    """Run once in each local worker process: the decoding limit and the cache of the
    parent's command; compiled kernels rather than their numpy twins (a worker grades many
    photos)."""
    set_max_image_pixels(context.max_image_pixels)
    set_command_cache(*context.cache)
    prefer_compiled()


def absolute_task(task: BatchTask) -> BatchTask:
    """The task with absolute paths (Dask workers run in another folder)."""
    def absolute(path: Path | None) -> Path | None:
        return None if path is None else Path(os.path.abspath(path))

    return dataclasses.replace(task, source=absolute(task.source),
                               output=absolute(task.output), target=absolute(task.target))


def absolute_context(context: BatchContext) -> BatchContext:
    """The context with an absolute sheet folder (Dask workers run in another folder)."""
    if context.sheet_dir is None:
        return context
    return dataclasses.replace(context, sheet_dir=Path(os.path.abspath(context.sheet_dir)))
