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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbcgrade._executor import MAX_JOBS
from wbcgrade._publish import lock_folder, plan_outputs
from wbcgrade.batch.plan import BatchPlan, plan_batch, recheck_plan
from wbcgrade.batch.records import (
    RESULTS_FOLDER,
    read_record,
    remove_stale_records,
    write_record,
)
from wbcgrade.batch.run import run_batch
from wbcgrade.batch.settings import (
    SETTINGS_FILE,
    batch_settings,
    settings_changed,
    write_settings,
)
from wbcgrade.batch.task import BatchContext
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.saved_grade import look_batch_options, look_fit, look_styles
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
from wbcgrade.color.palette.fit import FitSummary
from wbcgrade.color.presets import (
    StyleSet,
    StyleSource,
    load_preset,
    load_styles,
    one_style_warning,
    photo_palettes,
    resolve_preset,
    save_preset,
    source_files,
)
from wbcgrade.core import prefer_compiled
from wbcgrade.errors import InputError, OptionError, Worded
from wbcgrade.photos.report import (
    own_report,
    plan_report,
    report_overwrite,
    sheet_from_files,
    sheet_path,
    style_pictures,
    write_report,
)
from wbcgrade.photos.results import BatchResult, FileResult
from wbcgrade.photos.results import FileResult as Result
from wbcgrade.photos.sheet import write_sheet
from wbcgrade.photos.workflow import Progress

__all__ = ["BatchProgress", "grade_folder", "report_folder", "report_batch_output",
           "recorded_batch"]


@dataclass(frozen=True)
class BatchProgress(Progress):
    """:class:`~wbcgrade.photos.workflow.Progress` with the batch's own callbacks.

    ``planned(n_photos)`` once the photos are known; ``result(FileResult)``
    as each photo finishes; ``read(done, total)`` while a series reads its
    photos' histograms; ``photo(relative)`` as a photo graded in this process starts.
    """

    planned: Callable[[int], None] | None = None
    result: Callable[[FileResult], None] | None = None
    read: Callable[[int, int], None] | None = None
    photo: Callable[[str], None] | None = None


def _load(source: StyleSource, options: GradeOptions, progress: Progress, plan: BatchPlan,
          consistent: bool) -> StyleSet:
    """The styles, each photo prepared for scene matching from the decode its histogram is
    read from where the photos are graded one by one (not ``consistent``: pooled)."""
    hook = None if consistent else matching_hook(source, options,
                                                 [task.source for task in plan.all_photos])
    styles = load_styles(source, options.transfer.bins, options.spaces.working, progress.warn,
                         progress.styles, hook)
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


def _run(plan: BatchPlan, styles: StyleSet, options: GradeOptions, consistent: bool,
         jobs: int, scheduler: str | None, report_dir: Path | None, write_outputs: bool,
         overwrite: bool, progress: BatchProgress,
         on_result: Callable[[FileResult], None] | None = None, look=None,
         encode=None) -> BatchResult:
    context = BatchContext(styles=styles, options=options, sheet_dir=report_dir,
                           write_outputs=write_outputs, overwrite=overwrite,
                           replace_sheets=write_outputs and own_report(report_dir))
    if look is not None:  # a saved grade (--look): every photo gets it, nothing is fitted
        context.shared, context.shared_fit = look, look_fit(look)
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


def _check_jobs(jobs: int) -> None:
    if not 1 <= jobs <= MAX_JOBS:
        raise OptionError(f"{{jobs}} must be between 1 and {MAX_JOBS}", "jobs")


def _plan_report(report_dir: Path | None, plan: BatchPlan, overwrite: bool) -> None:
    if report_dir is not None:
        plan_report(report_dir, [task.relative for task in plan.tasks],
                    [task.source for task in plan.all_photos], overwrite)


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
    _check_jobs(jobs)
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
    _plan_report(report_dir, plan, overwrite or own)
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
        if look is None:
            styles = _load(source, options, progress, plan, consistent)
        else:
            styles = look_styles(look, str(None if look.saved is None else look.saved.file))
        settings = batch_settings(styles, options, consistent)
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
            encoding = ColorEncoding.of(options.spaces.input, options.spaces.working)
            result.lut = write_checked_lut(lut, lut_format, grade, encoding, lut_size,
                                           title=f"wbcgrade series {Path(in_dir).name}",
                                           comments=[f"wbcgrade series grade of {in_dir}: "
                                                     f"{ranked}"],
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
    A ``target`` that is a batch's output folder (:func:`recorded_batch`) is
    reported from the batch's records (:func:`report_batch_output`).
    """
    progress = progress or BatchProgress()
    _check_jobs(jobs)
    target = Path(target)
    out = Path(report_dir) if report_dir else default_report_dir(target)
    recorded = recorded_batch(target)
    if recorded is not None:
        return report_batch_output(target, out, recorded, source, options,
                                   recursive=recursive, overwrite=overwrite, progress=progress)
    plan = plan_batch(target, None, recursive=recursive, exclude=[out])
    if not plan.tasks:
        if target.is_file():
            raise InputError(f"{target}: not an image file (by its extension)")
        raise InputError(f"{target}: no photos found")
    overwrite = report_overwrite(out, overwrite)  # a stopped report is finished in place
    _plan_report(out, plan, overwrite)
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


def recorded_batch(folder: str | os.PathLike) -> dict | None:
    """The settings a batch recorded in its output folder ``folder``, when it holds
    results recorded for ``wbcgrade report`` (else None)."""
    import json

    folder = Path(folder)
    if not (folder / RESULTS_FOLDER).is_dir():
        return None
    try:
        settings = json.loads((folder / SETTINGS_FILE).read_text("utf-8"))
    except (OSError, ValueError, RecursionError):  # (RecursionError: nested too deep)
        return None
    if not isinstance(settings, dict) or not isinstance(settings.get("style_names"), list):
        return None
    return settings


def _recorded_styles(recorded: str, names: list[str]) -> StyleSet:
    """The styles a batch recorded, for the sheets' pictures: the preset when it is still
    there with these names, else the names alone (a folder's pictures are its photos)."""
    if Path(recorded).is_file():
        try:
            styles = load_preset(recorded)
            if styles.names == names:
                return styles
        except InputError:
            pass
    return StyleSet(names, np.ones((len(names), 1, 1, 1)), recorded)


def _same_styles(given: StyleSource, recorded: str) -> bool:
    if given.style_dir is not None:
        return Path(given.style_dir).resolve() == Path(recorded).resolve()
    try:
        return resolve_preset(given.preset).resolve() == Path(recorded).resolve()
    except InputError:
        return False


def _given_options(options: GradeOptions, recorded: dict) -> list[str]:
    """Options set to something else than their default and than the batch recorded."""
    import json

    given = json.loads(json.dumps(options.flat(), default=float))
    default = json.loads(json.dumps(GradeOptions().flat(), default=float))
    return [k for k, v in given.items() if v != default.get(k) and v != recorded.get(k)]


def report_batch_output(folder: str | os.PathLike, report_dir: str | os.PathLike,
                        settings: dict, source: StyleSource | None = None,
                        options: GradeOptions | None = None, *, recursive: bool = False,
                        overwrite: bool = False,
                        progress: BatchProgress | None = None) -> BatchResult:
    """The report of a batch's output folder from what the batch recorded: nothing is graded.

    Every graded copy under ``folder`` is reported with the weights, losses
    and timings its batch recorded (:mod:`wbcgrade.batch.records`) and a
    sheet made from the photo and its graded copy. A copy without a record
    fails (the report says so). ``source`` and ``options`` are those given to
    ``wbcgrade report``: styles other than the batch's are refused, other
    options are ignored with a warning.
    """
    progress = progress or BatchProgress()
    folder, report_dir = Path(folder), Path(report_dir)
    recorded_styles = str(settings.get("styles", ""))
    flat = settings.get("options") if isinstance(settings.get("options"), dict) else {}
    if source is not None and (source.style_dir, source.preset) != (None, None) \
            and not _same_styles(source, recorded_styles):
        raise InputError(f"{folder} holds the graded copies of a `wbcgrade batch` with the styles "
                         f"{recorded_styles}; its report reads the batch's results: leave out "
                         "{style_dir}/{preset} (or report the photos' own folder to grade them "
                         "again)", fields=("style_dir", "preset"))
    ignored = _given_options(options, flat) if options is not None else []
    if ignored and progress.warn:
        progress.warn(f"{', '.join(ignored[:4])}: ignored, the report shows the batch's grades "
                      f"(made with the options it recorded in {folder / SETTINGS_FILE})")
    plan = plan_batch(folder, None, recursive=recursive, exclude=[report_dir])
    if not plan.tasks:
        raise InputError(f"{folder}: no graded photos found"
                         + ("" if recursive else " (use {recursive} for sub-folders)"),
                         fields=("recursive",), path=folder)
    _plan_report(report_dir, plan, overwrite)
    if progress.planned:
        progress.planned(len(plan.tasks))
    start = time.perf_counter()
    names = [str(n) for n in settings["style_names"]]
    styles = _recorded_styles(recorded_styles, names)
    pictures = style_pictures(styles)
    report_dir.mkdir(parents=True, exist_ok=True)

    def reported(task) -> tuple[Result, str | None]:
        """A photo's recorded result and its sheet (made from its files) -> (result, why
        it has no sheet)."""
        result = read_record(folder, task.relative)
        if result is None:
            return Result(task.relative, "", str(task.source), "failed",
                          error=f"no result recorded by the batch in "
                                f"{folder / RESULTS_FOLDER}"), None
        result.output = str(task.source)
        sheet = sheet_path(task.relative)
        try:
            write_sheet(report_dir / sheet, sheet_from_files(result, pictures),
                        overwrite=overwrite)
            result.sheet = sheet.as_posix()
        except (InputError, ValueError, OSError) as exc:
            return result, f"{task.relative}: no sheet ({exc})"
        return result, None

    # the sheets in threads (reading, resizing, encoding release the GIL), told in order
    from concurrent.futures import ThreadPoolExecutor

    results = []
    with ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1))) as pool:
        for task, (result, why) in zip(plan.tasks, pool.map(reported, plan.tasks)):
            if progress.photo:
                progress.photo(task.relative)
            if why is not None and progress.warn:
                progress.warn(why)
            results.append(result)
            if progress.result:
                progress.result(result)
    series = None
    if isinstance(settings.get("series_weights"), dict):
        weights = settings["series_weights"]
        series = FitSummary(np.array([float(weights.get(n, 0.0)) for n in names]),
                            float(settings.get("series_loss", 0.0)), np.zeros(len(names)),
                            "recorded")
    result = BatchResult(results, list(plan.ignored), time.perf_counter() - start, series, names)
    mode = "consistent" if settings.get("consistent") else "per-photo"
    result.report = write_report(report_dir, result, styles, flat, f"{mode} (batch results)",
                                 overwrite)
    return result
