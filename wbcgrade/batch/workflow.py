"""The ``batch`` and ``report`` commands' workflows: a folder of photos, end to end.

:func:`grade_folder` (``wbcgrade batch``): plan every output before any
work (the graded copies, the series LUT, the report's files), take the
output folder's lock, load the styles, say which recorded settings changed,
run the batch (:func:`wbcgrade.batch.run.run_batch`), record each
photo's result as it is graded (:mod:`wbcgrade.batch.records`), and
write the settings record, the report and the series LUT.
:func:`report_folder` (``wbcgrade report``): the same run with nothing
written but the report; on a batch's output folder it reads the batch's
records instead (:func:`report_batch_output`: nothing is graded).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

from wbcgrade._publish import lock_folder, plan_outputs
from wbcgrade.batch.plan import BatchPlan, plan_batch, recheck_plan
from wbcgrade.batch.recorded import (  # (re-exported: report_folder's own)
    check_jobs,
    default_report_dir,
    plan_batch_report,
    recorded_batch,
    report_batch_output,
    report_recorded,
)
from wbcgrade.batch.records import (
    RESULTS_FOLDER,
    remove_stale_records,
    write_record,
)
from wbcgrade.batch.run import run_batch
from wbcgrade.batch.settings import (
    batch_settings,
    settings_changed,
    write_settings,
)
from wbcgrade.batch.task import BatchContext
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import style_grids
from wbcgrade.color.grade.saved_grade import look_batch_options, saved_name
from wbcgrade.color.io.raw import RAW_WORKING_SPACE, is_raw
from wbcgrade.color.look.scene import matching_hook
from wbcgrade.color.look.set_extraction import MAP_BINS, OWN_PHOTOS_PROVENANCE, colour_photos
from wbcgrade.color.look.statistics import MIN_OWN_PHOTOS
from wbcgrade.color.mapping.lut import (
    DEFAULT_LUT_SIZE,
    check_clf_support,
    check_lut_path,
    check_lut_size,
    lut_format_of,
    write_checked_lut,
)
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.presets import (
    StyleSet,
    StyleSource,
    load_styles,
    one_style_warning,
    photo_palettes,
    save_preset,
    source_files,
)
from wbcgrade.core import prefer_compiled
from wbcgrade.errors import InputError, OptionError, Worded
from wbcgrade.photos.progress import BatchProgress, Progress
from wbcgrade.photos.report import (
    own_report,
    report_overwrite,
    style_pictures,
    write_report,
)
from wbcgrade.photos.results import BatchResult, FileResult

__all__ = ["BatchProgress", "grade_folder", "report_folder", "report_batch_output",
           "recorded_batch", "report_recorded", "default_report_dir"]


def _load(source: StyleSource, options: GradeOptions, progress: Progress, plan: BatchPlan,
          consistent: bool) -> StyleSet:
    """The styles, each photo prepared for scene matching from the decode its histogram is
    read from where the photos are graded one by one (not ``consistent``: pooled)."""
    hook = None if consistent else matching_hook(source, options,
                                                 [task.source for task in plan.all_photos])
    styles = load_styles(source, options.transfer.bins, options.spaces.working, progress.warn,
                         progress.styles, hook, resampled=style_grids(options))
    options.check_styles(len(styles.names))
    message = one_style_warning(source, styles, options.map.builder)
    if message is not None and progress.warn is not None:
        progress.warn(message)
    return styles


def _recorder(out_dir: Path, progress: BatchProgress) -> Callable[[FileResult], None]:
    """``on_result`` that records each graded photo in ``out_dir``, then tells ``progress``."""
    unrecorded: list[str] = []

    def on_result(result: FileResult) -> None:
        if result.status == "graded":
            try:
                write_record(out_dir, result)
            except OSError as exc:  # the photo is written; only `report`'s shortcut is lost
                if not unrecorded and progress.warn:
                    progress.warn(f"cannot record the results in {out_dir / RESULTS_FOLDER} "
                                  f"({exc.strerror or exc}); `wbcgrade report` will grade "
                                  "those photos again")
                unrecorded.append(result.relative)
        if progress.result:
            progress.result(result)

    return on_result


def _run(plan: BatchPlan, styles: StyleSet | None, options: GradeOptions, consistent: bool,
         jobs: int, scheduler: str | None, report_dir: Path | None, write_outputs: bool,
         overwrite: bool, progress: BatchProgress,
         on_result: Callable[[FileResult], None] | None = None, look=None,
         encode=None) -> BatchResult:
    context = BatchContext(styles=styles, options=options, sheet_dir=report_dir,
                           write_outputs=write_outputs, overwrite=overwrite,
                           replace_sheets=write_outputs and own_report(report_dir),
                           setting_names=None if progress.setting_names is None
                           else dict(progress.setting_names))
    if look is not None:  # a saved grade (--look): every photo gets it, nothing is fitted
        context.shared = look
    if encode is not None:
        context.encode = encode
    if report_dir is not None:
        report_dir.mkdir(parents=True, exist_ok=True)
        context.style_pictures = style_pictures(styles)
    if len(plan.tasks) > 1:  # many grades: numba's start once, then its faster kernels
        prefer_compiled()
    in_process = scheduler is None and jobs == 1
    return run_batch(plan, context, consistent=consistent, jobs=jobs, scheduler=scheduler,
                     on_result=on_result or progress.result,
                     progress=progress if in_process or consistent else None,
                     on_read=progress.read)


#: Where a batch keeps its own photos' palettes (its content model), in the output folder.
OWN_PHOTOS_FILE = ".wbcgrade-own-photos.npz"


def own_photos_content(options: GradeOptions, in_dir: str | os.PathLike, plan: BatchPlan,
                       out_dir: str | os.PathLike, source: StyleSource | None = None,
                       look=None, progress: BatchProgress | None = None
                       ) -> tuple[GradeOptions, int]:
    """The batch's own photos beside the shipped palettes as the look's content model:
    the photos being graded show, together, what ungraded content looks like in this
    collection (:func:`wbcgrade.color.look.statistics.own_photos_blend`). Only for a style
    folder's look (the look mode; not a preset, a saved grade, ``map.natural`` named, or
    the batch's own folder as the styles), with at least
    :data:`~wbcgrade.color.look.statistics.MIN_OWN_PHOTOS` readable colour photos directly
    in ``in_dir``. Their palettes are read once, here, and kept in ``out_dir`` as a preset
    marked as own photos (:data:`OWN_PHOTOS_FILE`), which ``map.natural`` then names (an
    absolute path: every worker reads that file, not the photos). Returns the options and
    how many photos that is (0: not used)."""
    from dataclasses import replace


    if (look is not None or options.map.natural is not None or options.map.builder != "look"
            or source is None or source.style_dir is None):
        return options, 0
    folder = Path(in_dir).resolve()
    if Path(source.style_dir).resolve() == folder:
        return options, 0
    files = [task.source for task in plan.all_photos
             if Path(task.source).resolve().parent == folder]
    if len(files) < MIN_OWN_PHOTOS:
        return options, 0
    read = None if progress is None or progress.read is None else (
        lambda done, total, _name: progress.read(done, total))
    own = photo_palettes(files, MAP_BINS, cache=source.cache, warn=lambda _message: None,
                         progress=read)
    own = None if own is None else colour_photos(own)  # (black and white: not content)
    if own is None or len(own.names) < MIN_OWN_PHOTOS:
        return options, 0
    target = Path(out_dir).resolve() / OWN_PHOTOS_FILE
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        save_preset(target, own, overwrite=True, threshold=0.0,
                    provenance={OWN_PHOTOS_PROVENANCE: str(folder)},
                    description="the photos a batch grades: its content model")
    except (OSError, InputError) as exc:
        if progress is not None and progress.warn:
            progress.warn(f"cannot keep the photos' palettes in {target} ({exc}); the look is "
                          "measured against the shipped palettes alone")
        return options, 0
    return replace(options, map=replace(options.map, natural=str(target))), len(own.names)


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
    grade, also written as a LUT to ``lut``; with ``report_dir`` the report is
    written there (a report an earlier run wrote there is updated, as the photos are
    resumed: :func:`wbcgrade.photos.report.own_report`). Returns the result (``result.lut`` None
    when no photo was graded, so no series grade was made). ``look``: a saved
    grade (:func:`wbcgrade.color.grade.saved_grade.load_look`) applied to every photo
    instead of a fit; ``encode``: JPEG/WebP quality and bit depth of the outputs.
    """
    progress = progress or BatchProgress()
    check_jobs(jobs)
    if look is not None:
        options = look_batch_options(options, look, consistent, lut, report_dir)
    report_dir = None if report_dir is None else Path(report_dir)
    check_lut_size(lut_size)
    if lut is not None:
        if not consistent:
            raise OptionError("{lut} needs {consistent} (one grade for the series); per-photo "
                              "LUTs come from `wbcgrade apply --lut`", "lut",
                              also=("consistent",))
        lut_format = lut_format_of(lut, lut_format)
        lut = check_lut_path(lut, lut_format)
        if lut_format == "clf":
            check_clf_support()
    reads = source_files(None if look is not None else source, options.map.natural, look)
    plan = plan_batch(in_dir, out_dir, recursive=recursive, overwrite=overwrite,
                      exclude=[report_dir] if report_dir else [], reads=reads)
    if not plan.tasks and not plan.done and not plan.refused:
        raise InputError(f"{in_dir}: no photos found" + ("" if recursive else
                                                         " (use {recursive} for sub-folders)"),
                         fields=("recursive",), path=in_dir)
    if lut is not None:
        lut = plan_outputs([lut], [*(t.source for t in plan.all_photos), *reads], overwrite)[0]
    if consistent and options.spaces.working is None:  # one working space for the series
        from dataclasses import replace


        if any(is_raw(t.source) for t in plan.all_photos):
            options = replace(options, spaces=replace(options.spaces, working=RAW_WORKING_SPACE))
    # the report of an earlier run into this folder is updated as the photos are resumed
    own = own_report(report_dir)
    plan_batch_report(report_dir, plan, overwrite or own)
    if progress.planned:
        progress.planned(len(plan.tasks) + len(plan.done) + len(plan.refused))
    try:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out_dir}: cannot create the output folder ({exc.strerror})") from None
    with lock_folder(out_dir, "batch"):  # one run at a time per output folder
        # a run that held the lock may have finished some
        plan = recheck_plan(plan, overwrite, out_dir=out_dir)
        remove_stale_records(out_dir)  # what a killed run left half-written
        start = time.perf_counter()
        options, own_photos = own_photos_content(options, in_dir, plan, out_dir, source, look,
                                                 progress)
        styles = None if look is not None else _load(source, options, progress, plan,
                                                        consistent)
        settings = (batch_settings(styles.source, styles.names, options, consistent)
                    if look is None else
                    batch_settings(saved_name(look), look.names, options, consistent))
        changed = settings_changed(out_dir, settings)
        if changed and plan.done and progress.warn:
            progress.warn(Worded(f"{len(plan.done)} finished output(s) in {out_dir} were made "
                                 f"with other settings ({', '.join(changed[:4])}); they are "
                                 "kept — use {overwrite} to redo them", ("overwrite",)))
        if plan.tasks or recorded_batch(out_dir) is None:
            # recorded before the first photo: a run stopped at any moment leaves outputs
            # whose settings are known (a rerun and `report OUT` read them)
            write_settings(out_dir, settings)
        result = _run(plan, styles, options, consistent, jobs, scheduler, report_dir, True,
                      overwrite, progress, _recorder(Path(out_dir), progress), look, encode)
        if result.count("graded") and result.series is not None:
            settings["series_weights"] = dict(zip(styles.names,
                                                  map(float, result.series.weights)))
            settings["series_loss"] = float(result.series.loss)
            write_settings(out_dir, settings)
        result.time_s = time.perf_counter() - start
        result.own_photos = own_photos
        if report_dir is not None:
            result.report = write_report(report_dir, result, styles, options,
                                         "consistent" if consistent else "per-photo",
                                         overwrite or own)
        if lut is not None and result.series_grade is not None:
            grade = result.series_grade
            ranked = ", ".join(f"{n} {w:.3f}" for n, w in grade.ranked())
            # baked for the photos' space (--input-space, else sRGB), as video bakes its clips'
            encoding = ColorEncoding.of(options.spaces.input,
                                        options.spaces.working).named(progress.setting_names)
            result.lut = write_checked_lut(lut, lut_format, grade, encoding, lut_size,
                                           title=f"wbcgrade series {Path(in_dir).name}",
                                           comments=[f"wbcgrade series grade of {in_dir}: "
                                                     f"{ranked}"],
                                           overwrite=overwrite)
    return result


def report_folder(target: str | os.PathLike, report_dir: str | os.PathLike | None,
                  source: StyleSource, options: GradeOptions, *, recursive: bool = False,
                  consistent: bool = False, overwrite: bool = False, jobs: int = 1,
                  scheduler: str | None = None,
                  progress: BatchProgress | None = None) -> BatchResult:
    """``wbcgrade report``: which styles make up the grade of each photo (no photo written).

    Writes ``report_dir`` (default ``<name>_report`` beside ``target``):
    report.json, weights.csv, a sheet per photo and index.html; existing
    files are replaced only with ``overwrite`` (checked before any work).
    A ``target`` that is a batch's output folder (:func:`recorded_batch`) is
    reported from the batch's records (:func:`report_batch_output`).
    """
    progress = progress or BatchProgress()
    recorded = report_recorded(target, report_dir, source, options, recursive=recursive,
                               overwrite=overwrite, jobs=jobs, progress=progress)
    if recorded is not None:  # a batch's output folder: its results, read
        return recorded
    target = Path(target)
    out = Path(report_dir) if report_dir else default_report_dir(target)
    plan = plan_batch(target, None, recursive=recursive, exclude=[out])
    if not plan.tasks:
        if target.is_file():
            raise InputError(f"{target}: not an image file (by its extension)")
        raise InputError(f"{target}: no photos found")
    overwrite = report_overwrite(out, overwrite)  # a stopped report is finished in place
    plan_batch_report(out, plan, overwrite)
    if progress.planned:
        progress.planned(len(plan.tasks))
    start = time.perf_counter()
    own_photos = 0
    if target.is_dir():  # the look measured as `batch` measures it
        options, own_photos = own_photos_content(options, target, plan, out, source, None,
                                                 progress)
    styles = _load(source, options, progress, plan, consistent)
    result = _run(plan, styles, options, consistent, jobs, scheduler, out, False, overwrite,
                  progress)
    result.time_s = time.perf_counter() - start
    result.own_photos = own_photos
    result.report = write_report(out, result, styles, options,
                                 "consistent" if consistent else "per-photo", overwrite)
    return result
