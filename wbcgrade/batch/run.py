"""Running a batch: read a series' palettes, fit, grade every photo on an executor."""

from __future__ import annotations

import time
from collections.abc import Callable

from wbcgrade._executor import Executor
from wbcgrade.batch.plan import BatchPlan, remove_stale_outputs, remove_temporaries
from wbcgrade.batch.task import (
    BatchContext,
    absolute_context,
    absolute_task,
    lost_task,
    read_histograms,
    run_task,
    setup_worker,
)
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import PhotoHistograms, grade_histograms
from wbcgrade.color.histogram import PaletteSum
from wbcgrade.photos.results import BatchResult, FileResult
from wbcgrade.photos.workflow import Progress

__all__ = ["run_batch"]


def run_batch(plan: BatchPlan, context: BatchContext, *, consistent: bool = False,
              jobs: int = 1, scheduler: str | None = None,
              on_result: Callable[[FileResult], None] | None = None,
              progress: Progress | None = None,
              on_read: Callable[[int, int], None] | None = None) -> BatchResult:
    """Grade the photos of a plan; returns every photo's result (skipped ones included).

    Parameters
    ----------
    plan : from :func:`plan_batch` (its outputs checked; refused photos fail).
    context : styles, options, sheet folder, ...
    consistent : one grade for the whole series: every photo's histograms
        (also those already done, so a resumed series gets the same grade)
        pooled (:class:`wbcgrade.color.histogram.PaletteSum`), one pass of the
        grade path (:func:`wbcgrade.color.grade.grading.grade_histograms`), and each
        task only applies the grade.
    jobs : local worker processes (1: in this process).
    scheduler : Dask scheduler address (overrides ``jobs``).
    on_result : called with each FileResult as it finishes (progress bars).
    progress : fit and stage progress of the work done in this process.
    on_read : ``on_read(done, total)`` while a series reads its photos' histograms.
    """
    start = time.perf_counter()
    extra = [] if context.sheet_dir is None else [context.sheet_dir, context.sheet_dir / "sheets"]
    remove_stale_outputs(plan, extra)
    since = time.time_ns() - 1_000_000_000
    results: list[FileResult] = [
        FileResult(t.relative, str(t.source), str(t.output), "skipped",
                   timings={"total": 0.0}) for t in plan.done]
    results += [FileResult(t.relative, str(t.source), str(t.output), "failed", error=why,
                           timings={"total": 0.0}) for t, why in plan.refused]
    for result in results:
        if on_result:
            on_result(result)
    series, shared = None, None
    try:
        with Executor(context, jobs, scheduler, worker_setup=setup_worker,
                      to_remote=(absolute_task, absolute_context)) as executor:
            todo = list(plan.tasks)
            if consistent and todo:
                options = context.options
                fit_pool, pool = PaletteSum(), PaletteSum()
                photos, pending, unreadable = plan.all_photos, set(todo), set()
                for number, (task, value) in enumerate(executor.map_unordered(
                        read_histograms, photos, on_lost=lambda task, why: why)):
                    if on_read:
                        on_read(number + 1, len(photos))
                    if isinstance(value, str):
                        if task in pending:
                            unreadable.add(task)
                            failed = FileResult(
                                task.relative, str(task.source),
                                None if task.output is None else str(task.output), "failed",
                                error=value, timings={"total": 0.0})
                            results.append(failed)
                            if on_result:
                                on_result(failed)
                        continue
                    fit_pool.add(value.fit)
                    pool.add(value.transfer)
                todo = [task for task in todo if task not in unreadable]
                if todo:
                    encoding = ColorEncoding.of(None, options.spaces.working)
                    shared, series = grade_histograms(
                        PhotoHistograms(fit_pool.result(), pool.result()), context.styles,
                        options, encoding, progress.fit if progress else None,
                        progress.stage if progress else None)
                    context.shared, context.shared_fit = shared, series
                    executor.set_context(context)
            graded = executor.map_unordered(run_task, todo, local_kwargs={"progress": progress},
                                            on_lost=lost_task)
            for task, result in graded:
                # report the paths as the user gave them (Dask ran on absolute ones)
                result.source = str(task.source)
                result.output = None if task.output is None else str(task.output)
                results.append(result)
                if on_result:
                    on_result(result)
    except KeyboardInterrupt:
        remove_temporaries(plan.tasks, since)
        raise
    results.sort(key=lambda r: r.relative)
    return BatchResult(results, list(plan.ignored), time.perf_counter() - start, series,
                       context.style_names, shared)
