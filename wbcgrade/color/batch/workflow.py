"""The ``batch`` and ``report`` commands' workflows: a folder of photos, end to end.

:func:`grade_folder` (``wbcgrade batch``): plan every output before any
work (the graded copies, the series LUT, the report's files), take the
output folder's lock, load the styles, say which recorded settings changed,
run the batch (:func:`wbcgrade.color.batch.run.run_batch`), and write the
settings record, the report and the series LUT. :func:`report_folder`
(``wbcgrade report``): the same run with nothing written but the report.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from wbcgrade._publish import lock_folder, plan_outputs
from wbcgrade.color.batch.plan import BatchPlan, plan_batch, recheck_plan
from wbcgrade.color.batch.results import BatchResult, FileResult
from wbcgrade.color.batch.run import run_batch
from wbcgrade.color.batch.settings import batch_settings, settings_changed, write_settings
from wbcgrade.color.batch.task import BatchContext
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.lut import (
    DEFAULT_LUT_SIZE,
    check_clf_support,
    check_lut_path,
    check_lut_size,
    lut_format_of,
    write_grade_lut,
)
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.presets import StyleSet, StyleSource, load_styles
from wbcgrade.color.workflow import Progress
from wbcgrade.errors import InputError, OptionError

__all__ = ["BatchProgress", "grade_folder", "report_folder"]


@dataclass(frozen=True)
class BatchProgress(Progress):
    """:class:`~wbcgrade.color.workflow.Progress` with the batch's own callbacks.

    ``planned(n_photos)`` once the photos are known; ``result(FileResult)``
    as each photo finishes; ``read(done, total)`` while a series reads its
    photos' histograms.
    """

    planned: Callable[[int], None] | None = None
    result: Callable[[FileResult], None] | None = None
    read: Callable[[int, int], None] | None = None


def _load(source: StyleSource, options: GradeOptions, progress: Progress) -> StyleSet:
    styles = load_styles(source, options.transfer.bins, options.spaces.working, progress.warn,
                         progress.styles)
    options.check_styles(len(styles.names))
    return styles


def _run(plan: BatchPlan, styles: StyleSet, options: GradeOptions, consistent: bool,
         jobs: int, scheduler: str | None, report_dir: Path | None, write_outputs: bool,
         overwrite: bool, progress: BatchProgress, look=None, encode=None) -> BatchResult:
    context = BatchContext(styles=styles, options=options, sheet_dir=report_dir,
                           write_outputs=write_outputs, overwrite=overwrite)
    if look is not None:  # a saved grade (--look): every photo gets it, nothing is fitted
        from wbcgrade.color.saved_look import look_fit

        context.shared, context.shared_fit = look, look_fit(look)
    if encode is not None:
        context.encode = encode
    if report_dir is not None:
        from wbcgrade.color.report import style_pictures

        report_dir.mkdir(parents=True, exist_ok=True)
        context.style_pictures = style_pictures(styles)
    in_process = scheduler is None and jobs == 1
    return run_batch(plan, context, consistent=consistent, jobs=jobs, scheduler=scheduler,
                     on_result=progress.result,
                     progress=progress if in_process or consistent else None,
                     on_read=progress.read)


def _check_jobs(jobs: int) -> None:
    if jobs < 1:
        raise OptionError("jobs must be at least 1", "jobs")


def _plan_report(report_dir: Path | None, plan: BatchPlan, overwrite: bool) -> None:
    if report_dir is not None:
        from wbcgrade.color.report import plan_report

        plan_report(report_dir, [task.relative for task in plan.tasks],
                    [task.source for task in plan.all_photos], overwrite)


def grade_folder(in_dir: str | os.PathLike, out_dir: str | os.PathLike, source: StyleSource,
                 options: GradeOptions, *, recursive: bool = False, consistent: bool = False,
                 overwrite: bool = False, jobs: int = 1, scheduler: str | None = None,
                 report_dir: str | os.PathLike | None = None,
                 lut: str | os.PathLike | None = None, lut_size: int = DEFAULT_LUT_SIZE,
                 lut_format: str | None = None,
                 progress: BatchProgress | None = None, look=None,
                 encode=None) -> BatchResult:
    """``wbcgrade batch``: grade every photo under ``in_dir`` into ``out_dir``.

    Outputs are written atomically; a rerun skips photos whose output is
    complete (``overwrite`` redoes them), refuses to replace any other file,
    and removes the temporary files of a killed run. One run at a time may
    write into ``out_dir``. With ``consistent`` the whole series shares one
    grade, also written as a LUT to ``lut``; with ``report_dir`` the palette
    weight report is written there. Returns the result (``result.lut`` None
    when no photo was graded, so no series grade was made). ``look``: a saved
    grade (:func:`wbcgrade.color.saved_look.load_look`) applied to every photo
    instead of a fit; ``encode``: JPEG/WebP quality and bit depth of the outputs.
    """
    progress = progress or BatchProgress()
    _check_jobs(jobs)
    if look is not None:
        from wbcgrade.color.saved_look import look_batch_options

        options = look_batch_options(options, look, consistent, lut, report_dir)
    report_dir = None if report_dir is None else Path(report_dir)
    if lut is not None:
        if not consistent:
            raise InputError("--lut needs --consistent (one grade for the series); per-photo "
                             "LUTs come from `wbcgrade apply --lut`")
        lut_format = lut_format_of(lut, lut_format)
        lut = check_lut_path(lut, lut_format)
        check_lut_size(lut_size)
        if lut_format == "clf":
            check_clf_support()
    plan = plan_batch(in_dir, out_dir, recursive=recursive, overwrite=overwrite,
                      exclude=[report_dir] if report_dir else [])
    if not plan.tasks and not plan.done and not plan.refused:
        raise InputError(f"{in_dir}: no photos found" + ("" if recursive else
                                                         " (use --recursive for sub-folders)"))
    if lut is not None:
        lut = plan_outputs([lut], [t.source for t in plan.all_photos], overwrite)[0]
    if consistent and options.spaces.working is None:  # one working space for the series
        from dataclasses import replace

        from wbcgrade.color.raw import RAW_WORKING_SPACE, is_raw

        if any(is_raw(t.source) for t in plan.all_photos):
            options = replace(options, spaces=replace(options.spaces, working=RAW_WORKING_SPACE))
    _plan_report(report_dir, plan, overwrite)
    if progress.planned:
        progress.planned(len(plan.tasks) + len(plan.done) + len(plan.refused))
    try:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out_dir}: cannot create the output folder ({exc.strerror})") from None
    with lock_folder(out_dir, "batch"):  # one run at a time per output folder
        plan = recheck_plan(plan, overwrite)  # a run that held the lock may have finished some
        start = time.perf_counter()
        if look is None:
            styles = _load(source, options, progress)
        else:
            from wbcgrade.color.saved_look import look_styles

            styles = look_styles(look, str(dict(look.info).get("look", {}).get("file")))
        settings = batch_settings(styles, options, consistent)
        changed = settings_changed(out_dir, settings)
        if changed and plan.done and progress.warn:
            progress.warn(f"{len(plan.done)} finished output(s) in {out_dir} were made with other "
                          f"settings ({', '.join(changed[:4])}); they are kept — use --overwrite "
                          "to redo them")
        result = _run(plan, styles, options, consistent, jobs, scheduler, report_dir, True,
                      overwrite, progress, look, encode)
        if result.count("graded"):
            write_settings(out_dir, settings)
        result.time_s = time.perf_counter() - start
        if report_dir is not None:
            from wbcgrade.color.report import write_report

            result.report = write_report(report_dir, result, styles, options,
                                         "consistent" if consistent else "per-photo", overwrite)
        if lut is not None and result.series_grade is not None:
            grade = result.series_grade
            ranked = ", ".join(f"{n} {w:.3f}" for n, w in grade.ranked())
            result.lut = write_grade_lut(lut, grade, ColorEncoding.of(None, options.spaces.working),
                                         lut_size, lut_format,
                                         title=f"wbcgrade series {Path(in_dir).name}",
                                         comments=[f"wbcgrade series grade of {in_dir}: {ranked}"],
                                         overwrite=overwrite)
    return result


def default_report_dir(target: str | os.PathLike) -> Path:
    """``<name>_report`` beside a photo or a folder."""
    target = Path(target).resolve()
    return target.with_name(f"{target.stem if target.is_file() else target.name}_report")


def report_folder(target: str | os.PathLike, report_dir: str | os.PathLike | None,
                  source: StyleSource, options: GradeOptions, *, recursive: bool = False,
                  consistent: bool = False, overwrite: bool = False, jobs: int = 1,
                  scheduler: str | None = None,
                  progress: BatchProgress | None = None) -> BatchResult:
    """``wbcgrade report``: which styles make up the grade of each photo (no photo written).

    Writes ``report_dir`` (default ``<name>_report`` beside ``target``):
    report.json, weights.csv, a sheet per photo and index.html; existing
    files are replaced only with ``overwrite`` (checked before any work).
    """
    progress = progress or BatchProgress()
    _check_jobs(jobs)
    target = Path(target)
    out = Path(report_dir) if report_dir else default_report_dir(target)
    plan = plan_batch(target, None, recursive=recursive, exclude=[out])
    if not plan.tasks:
        if target.is_file():
            raise InputError(f"{target}: not an image file (by its extension)")
        raise InputError(f"{target}: no photos found")
    _plan_report(out, plan, overwrite)
    if progress.planned:
        progress.planned(len(plan.tasks))
    start = time.perf_counter()
    styles = _load(source, options, progress)
    result = _run(plan, styles, options, consistent, jobs, scheduler, out, False, overwrite,
                  progress)
    result.time_s = time.perf_counter() - start
    from wbcgrade.color.report import write_report

    result.report = write_report(out, result, styles, options,
                                 "consistent" if consistent else "per-photo", overwrite)
    return result
