"""``wbcgrade report`` on a batch's output folder: the report from what the batch recorded.

:func:`recorded_batch` tells a batch's output folder (its settings and results
recorded, :mod:`wbcgrade.batch.records`); :func:`report_batch_output` writes its
report from them: nothing is graded, each sheet is made from small decodes of the photo
and its graded copy. The module imports no grade (no fit, no look, no colour map):
:func:`report_recorded` is what the command calls first, before the grade's modules load.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from wbcgrade._executor import MAX_JOBS
from wbcgrade.batch.plan import BatchPlan, plan_batch
from wbcgrade.batch.records import RESULTS_FOLDER, read_record
from wbcgrade.batch.settings import SETTINGS_FILE
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.palette.fit import FitSummary
from wbcgrade.color.presets import StyleSet, StyleSource, load_preset, resolve_preset
from wbcgrade.errors import InputError, OptionError
from wbcgrade.photos.progress import BatchProgress
from wbcgrade.photos.report import (
    plan_report,
    sheet_from_files,
    sheet_path,
    style_pictures,
    write_report,
)
from wbcgrade.photos.results import BatchResult
from wbcgrade.photos.results import FileResult as Result
from wbcgrade.photos.sheet import write_sheet

__all__ = ["default_report_dir", "recorded_batch", "report_batch_output", "report_recorded",
           "check_jobs", "plan_batch_report"]


def default_report_dir(target: str | os.PathLike) -> Path:
    """``<name>_report`` beside a photo or a folder."""
    target = Path(target).resolve()
    return target.with_name(f"{target.stem if target.is_file() else target.name}_report")


def check_jobs(jobs: int) -> None:
    """Raise OptionError unless ``jobs`` is a number of local processes a batch may use."""
    if not 1 <= jobs <= MAX_JOBS:
        raise OptionError(f"{{jobs}} must be between 1 and {MAX_JOBS}", "jobs")


def plan_batch_report(report_dir: Path | None, plan: BatchPlan, overwrite: bool) -> None:
    """Check before any work that the report of ``plan``'s photos may be written into
    ``report_dir`` (None: no report), as :func:`wbcgrade.photos.report.plan_report` does."""
    if report_dir is not None:
        plan_report(report_dir, [task.relative for task in plan.tasks],
                    [task.source for task in plan.all_photos], overwrite)


def report_recorded(target: str | os.PathLike, report_dir: str | os.PathLike | None,
                    source: StyleSource | None = None, options: GradeOptions | None = None, *,
                    recursive: bool = False, overwrite: bool = False, jobs: int = 1,
                    progress: BatchProgress | None = None) -> BatchResult | None:
    """:func:`report_batch_output` of ``target`` when it is a batch's output folder
    (:func:`recorded_batch`; ``report_dir`` None: ``<name>_report`` beside it), else None
    (nothing done: its photos are to be graded,
    :func:`wbcgrade.batch.workflow.report_folder`)."""
    check_jobs(jobs)
    recorded = recorded_batch(target)
    if recorded is None:
        return None
    out = Path(report_dir) if report_dir else default_report_dir(target)
    return report_batch_output(target, out, recorded, source, options, recursive=recursive,
                               overwrite=overwrite, progress=progress)


def recorded_batch(folder: str | os.PathLike) -> dict | None:
    """The settings a batch recorded in its output folder ``folder``, when it holds
    results recorded for ``wbcgrade report`` (else None)."""
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
    plan_batch_report(report_dir, plan, overwrite)
    if progress.planned:
        progress.planned(len(plan.tasks))
    start = time.perf_counter()
    names = [str(n) for n in settings["style_names"]]
    styles = StyleSet(names, np.ones((len(names), 1, 1, 1)), recorded_styles)  # (the names)
    # made (the preset read) only when a sheet shows them: a preset's look shows none
    pictures = _OnFirstUse(lambda: style_pictures(_recorded_styles(recorded_styles, names)))
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
                                 overwrite, _recorded_color(results))
    return result


#: What a photo's record says of the colour config it was graded with (ColorEncoding.info).
_COLOR_KEYS = ("ocio_config", "ocio_config_name", "ocio_version", "openimageio_version",
               "working_space")


def _recorded_color(results) -> dict | None:
    """The colour config and working space the batch graded with, as its first record with
    them says (None: none says, the report names those in use now)."""
    for result in results:
        if isinstance(result.color, dict) and all(k in result.color for k in _COLOR_KEYS):
            return {k: result.color[k] for k in _COLOR_KEYS}
    return None


class _OnFirstUse(Mapping):
    """A mapping made by ``make()`` when it is first read (by any thread, once)."""

    def __init__(self, make: Callable[[], Mapping]):
        self._make, self._value, self._lock = make, None, threading.Lock()

    def _mapping(self) -> Mapping:
        with self._lock:
            if self._value is None:
                self._value = self._make()
            return self._value

    def __getitem__(self, key):
        return self._mapping()[key]

    def __iter__(self):
        return iter(self._mapping())

    def __len__(self) -> int:
        return len(self._mapping())
