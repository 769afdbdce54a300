"""Grade every photo of a folder: planning, per-file work, local or distributed execution.

``plan_batch`` lists the photos under a folder and where each graded copy
goes (the tree is mirrored, file names and formats kept); ``run_batch`` grades
them one file per task, in this process, in ``jobs`` local processes
(``concurrent.futures.ProcessPoolExecutor``) or on a Dask distributed cluster
(``--scheduler``; optional extra ``wbcgrade[dask]``, the workers must see the
same paths). Each task reads, grades and writes one whole file; a file that
fails is recorded and the others go on.

Resuming: outputs are written atomically (temporary file + rename), so an
output that exists is complete; it is skipped when it is newer than its photo
and has the photo's pixel count (``force`` redoes it). Interrupting
(Ctrl-C) cancels the queued files, lets the running ones clean up their
temporary files, and removes any temporary file of this run that is left.
A run first removes the temporary files a killed run left in its output
folders (only unlocked ones: see :mod:`wbcgrade.color._files`). Local worker
processes end when their parent dies (``PR_SET_PDEATHSIG`` and a parent-pid
watch), so a killed batch does not go on writing. Paths sent to a Dask
cluster are made absolute first (its workers run in another folder).

Series mode (``consistent``): every photo's histogram is read first (also
those already done, so a resumed series gets the same grade), the pooled
palette gets one vertex-checked fit and one colour map
(:func:`wbcgrade.color.grading.series_grade`), and each task only applies it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import glob
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from wbcgrade.color._files import check_regular_target, is_unlocked, remove_stale_temporaries
from wbcgrade.color.grading import (
    NONZERO_THRESHOLD,
    FitSummary,
    PaletteSum,
    PhotoGrade,
    grade_photo,
    photo_histograms,
    series_grade,
)
from wbcgrade.color.imageio import (
    check_image_output,
    max_image_pixels,
    set_max_image_pixels,
    write_image,
)
from wbcgrade.color.presets import StyleSet
from wbcgrade.color.transfer import Grade, GradeOptions
from wbcgrade.errors import InputError, WbcgradeError

__all__ = ["BatchTask", "BatchPlan", "BatchContext", "FileResult", "BatchResult",
           "image_extensions", "plan_batch", "run_task", "run_batch", "output_is_complete",
           "batch_settings", "settings_changed", "write_settings", "remove_stale_outputs",
           "recheck_plan"]

Progress = Callable[["FileResult"], None]

#: File in the output folder recording the settings of the last batch run there.
SETTINGS_FILE = ".wbcgrade-batch.json"


def image_extensions() -> set[str]:
    """Lower-case file extensions (with the dot) that OpenImageIO can read."""
    text = oiio.get_string_attribute("extension_list")
    exts = set()
    for entry in text.split(";"):
        _, _, names = entry.partition(":")
        exts.update(f".{e.strip().lower()}" for e in names.split(",") if e.strip())
    return exts


@dataclass(frozen=True)
class BatchTask:
    """One photo: its path, the output path, and the path relative to the input folder."""

    source: Path
    output: Path | None
    relative: str


@dataclass
class BatchPlan:
    """What a batch will do.

    Attributes
    ----------
    tasks : photos to grade.
    done : photos whose output is already complete (skipped unless forced).
    ignored : relative paths of files that are not images (by extension).
    """

    tasks: list[BatchTask]
    done: list[BatchTask] = field(default_factory=list)
    ignored: list[str] = field(default_factory=list)

    @property
    def all_photos(self) -> list[BatchTask]:
        return sorted(self.tasks + self.done, key=lambda t: t.relative)


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder.resolve())
        return True
    except ValueError:
        return False


def output_is_complete(source: Path, output: Path) -> bool:
    """True when ``output`` exists, is not older than ``source`` and has its pixel count."""
    try:
        if not output.is_file() or output.stat().st_mtime_ns < source.stat().st_mtime_ns:
            return False
    except OSError:
        return False
    sizes = []
    for path in (source, output):
        inp = oiio.ImageInput.open(str(path))
        if inp is None:
            oiio.geterror()
            return False
        spec = inp.spec()
        sizes.append(spec.width * spec.height)
        inp.close()
    return sizes[0] == sizes[1]


def plan_batch(in_path: str | os.PathLike, out_dir: str | os.PathLike | None,
               recursive: bool = False, force: bool = False,
               exclude: Iterable[str | os.PathLike] = ()) -> BatchPlan:
    """List the photos under ``in_path`` (a folder, or one photo) and their outputs.

    Hidden files and anything inside ``out_dir`` or an ``exclude`` folder
    (e.g. a report folder) are left out. With
    ``out_dir`` None (a report only), nothing is written and nothing is
    skipped. Raises InputError when the folder is missing or the output
    folder is the input folder.
    """
    in_path = Path(in_path)
    if not in_path.exists():
        raise InputError(f"{in_path}: no such file or folder")
    out = Path(out_dir) if out_dir is not None else None
    if in_path.is_file():
        root, files = in_path.parent, [in_path]
    else:
        root = in_path
        pattern = root.rglob("*") if recursive else root.iterdir()
        files = sorted(p for p in pattern if p.is_file())
    if out is not None:
        if out.exists() and not out.is_dir():
            raise InputError(f"{out}: output path exists and is not a folder")
        if out.exists() and out.resolve() == root.resolve():
            raise InputError(f"{out}: the output folder must differ from the input folder")
    exts = image_extensions()
    skip_dirs = [Path(p) for p in exclude] + ([out] if out is not None else [])
    plan = BatchPlan(tasks=[])
    for path in files:
        rel = path.relative_to(root)
        if any(part.startswith(".") for part in rel.parts):
            continue
        if any(folder.exists() and _inside(path, folder) for folder in skip_dirs):
            continue
        if path.suffix.lower() not in exts:
            plan.ignored.append(rel.as_posix())
            continue
        task = BatchTask(path, None if out is None else out / rel, rel.as_posix())
        if task.output is not None and not force and output_is_complete(path, task.output):
            plan.done.append(task)
        else:
            plan.tasks.append(task)
    return plan


def recheck_plan(plan: BatchPlan, force: bool = False) -> BatchPlan:
    """Move tasks whose output became complete since planning to ``done`` (unless forced).

    Used once a run holds the output folder's lock: a run that finished in
    between is not redone.
    """
    if force:
        return plan
    tasks, done = [], list(plan.done)
    for task in plan.tasks:
        if task.output is not None and output_is_complete(task.source, task.output):
            done.append(task)
        else:
            tasks.append(task)
    return BatchPlan(tasks=tasks, done=done, ignored=list(plan.ignored))


def batch_settings(styles: StyleSet, opts: GradeOptions, consistent: bool) -> dict:
    """What determines the outputs of a batch (JSON-friendly)."""
    options = {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(opts).items()}
    return {"styles": styles.source, "style_names": list(styles.names), "options": options,
            "consistent": bool(consistent)}


def settings_changed(out_dir: str | os.PathLike, settings: dict) -> list[str]:
    """Names of the settings that differ from those recorded in ``out_dir`` (none if unrecorded)."""
    import json

    try:
        previous = json.loads((Path(out_dir) / SETTINGS_FILE).read_text("utf-8"))
    except (OSError, ValueError):
        return []
    if not isinstance(previous, dict):
        return []
    changed = [k for k in ("styles", "style_names", "consistent")
               if previous.get(k) != settings[k]]
    old = previous.get("options") if isinstance(previous.get("options"), dict) else {}
    changed += [k for k, v in settings["options"].items() if old.get(k) != v]
    return changed


def write_settings(out_dir: str | os.PathLike, settings: dict) -> None:
    """Record the settings of this run in ``out_dir`` (atomically)."""
    import json

    from wbcgrade.color._files import atomic_path

    path = Path(out_dir) / SETTINGS_FILE
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as handle:
        json.dump(settings, handle, indent=1)


@dataclass
class BatchContext:
    """What every task needs (sent once to each worker).

    Attributes
    ----------
    styles : the style set.
    opts : grading options.
    shared : the series grade (``--consistent``), or None for one fit per photo.
    shared_fit : its weights and single-style losses.
    force : replace existing outputs.
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
    force: bool = False
    sheet_dir: Path | None = None
    style_pictures: dict[str, np.ndarray] | None = None
    write_outputs: bool = True
    max_image_pixels: int = field(default_factory=max_image_pixels)


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
        if self.weights:
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
        if self.sheet:
            entry["sheet"] = self.sheet
        entry["time_s"] = round(self.timings.get("total", 0.0), 3)
        entry["timings_s"] = {k: round(v, 3) for k, v in self.timings.items()}
        return entry


def sheet_content(result: FileResult, graded: PhotoGrade,
                  style_pictures: dict[str, np.ndarray] | None = None):
    """The SheetContent of a graded photo (pictures, style tiles, palettes, losses)."""
    from wbcgrade.color.histogram import image_histogram
    from wbcgrade.color.imageio import encode_for_grading
    from wbcgrade.color.sheet import SheetContent, StyleTile, histogram_palette, thumbnail

    image = graded.image
    before, _ = encode_for_grading(image.rgb(), image.is_float)
    color = [c for c in range(graded.pixels.shape[2]) if c != graded.alpha_channel][:3]
    after, _ = encode_for_grading(graded.pixels[:, :, color], image.is_float)
    small_before = thumbnail(before, 300, 480)
    small_after = thumbnail(after, 300, 480)
    pictures = style_pictures or {}
    order = sorted(range(len(result.weights)), key=lambda i: -result.weights[i])
    tiles = [StyleTile(result.names[i], result.weights[i],
                       pictures.get(result.names[i], np.full((8, 8, 3), 0.5, np.float32)))
             for i in order if result.weights[i] >= NONZERO_THRESHOLD]
    bins = 16
    palettes = [("input", histogram_palette(image_histogram(before, bins))),
                ("barycenter", histogram_palette(graded.grade.barycenter)),
                ("output", histogram_palette(image_histogram(after, bins)))]
    best = int(np.argmin(result.vertex_losses))
    subtitle = (f"loss {result.loss:.4g}  |  best single style {result.names[best]}: "
                f"{result.vertex_losses[best]:.4g}  |  {result.n_nonzero} of {len(result.names)} "
                f"weights >= {NONZERO_THRESHOLD:g}  |  {result.timings.get('total', 0):.1f} s")
    return SheetContent(title=result.relative, subtitle=subtitle, before=small_before,
                        after=small_after, styles=tiles, palettes=palettes,
                        more_styles=len(result.weights) - len(tiles))


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
            from wbcgrade.color.sheet import write_sheet

            sheet = Path("sheets") / f"{task.relative}.png"
            write_sheet(context.sheet_dir / sheet, sheet_content(result, graded,
                                                                context.style_pictures))
            result.sheet = sheet.as_posix()
        result.status = "graded"
    except (WbcgradeError, ValueError, OSError, MemoryError) as exc:
        text = str(exc).strip().splitlines()
        result.error = text[0] if text else type(exc).__name__
        result.status = "failed"
    result.timings["total"] = time.perf_counter() - start
    return result


@dataclass
class BatchResult:
    """Outcome of a batch: one FileResult per photo (graded, skipped, failed), the time,
    and for a series its weights (``series``) and grade (``series_grade``, colour map)."""

    results: list[FileResult]
    ignored: list[str]
    time_s: float
    series: FitSummary | None = None
    style_names: list[str] = field(default_factory=list)
    series_grade: Grade | None = None

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.results)


# ----------------------------------------------------------------------------- executors

_WORKER_CONTEXT: BatchContext | None = None
_WORKER_INTERRUPTED = False


#: How often a worker checks that its parent process is still alive (seconds).
PARENT_WATCH_S = 1.0


def _watch_parent(parent: int) -> None:
    while True:
        time.sleep(PARENT_WATCH_S)
        if os.getppid() != parent:
            os._exit(1)  # the batch is gone: write nothing more (temporaries are cleaned later)


def _die_with_parent(parent: int) -> None:
    """End this worker as soon as the process ``parent`` dies (even by SIGKILL).

    ``PR_SET_PDEATHSIG`` (Linux) kills it at once; a daemon thread watching
    the parent pid covers other systems and the case the signal was missed.
    """
    with contextlib.suppress(Exception):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                     name="wbcgrade-parent-watch").start()


def _init_worker(context: BatchContext, threads: int, parent: int | None = None) -> None:
    """Process-pool initializer: die with the parent, keep the context, cap threads."""
    global _WORKER_CONTEXT
    if parent is not None:
        _die_with_parent(parent)
    _WORKER_CONTEXT = context
    set_max_image_pixels(context.max_image_pixels)
    os.environ["WBCGRADE_THREADS"] = str(max(1, threads))  # the core's kernel-product threads
    with contextlib.suppress(ImportError):
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    with contextlib.suppress(Exception):
        import numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _run_in_worker(task: BatchTask) -> FileResult:
    global _WORKER_INTERRUPTED
    assert _WORKER_CONTEXT is not None
    if _WORKER_INTERRUPTED:  # Ctrl-C reached this worker: start no queued file
        raise KeyboardInterrupt
    try:
        return run_task(task, _WORKER_CONTEXT)
    except KeyboardInterrupt:
        _WORKER_INTERRUPTED = True
        raise


def _histograms_in_worker(task: BatchTask, bins: tuple[int, ...], max_pixels: int,
                          max_image: int | None = None) -> dict[int, np.ndarray] | str:
    if max_image is not None:
        set_max_image_pixels(max_image)
    try:
        return photo_histograms(task.source, bins, max_pixels)
    except (WbcgradeError, ValueError, OSError, MemoryError) as exc:
        text = str(exc).strip().splitlines()
        return text[0] if text else type(exc).__name__


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


#: How long to wait for a Dask scheduler to answer.
DASK_CONNECT_TIMEOUT = "20s"


def _dask_client(address: str):
    try:
        from dask.distributed import Client
    except ImportError:
        raise InputError("--scheduler needs Dask: pip install 'wbcgrade[dask]' "
                         "(dask[distributed])") from None
    try:
        return Client(address, timeout=DASK_CONNECT_TIMEOUT)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address} ({exc})") from None


class _Executor:
    """Run a function over tasks: in process, in a local process pool, or on Dask.

    ``map_unordered`` yields (task, result) pairs as they finish.
    """

    def __init__(self, context: BatchContext, jobs: int = 1, scheduler: str | None = None):
        self.context, self.jobs, self.scheduler = context, max(1, int(jobs)), scheduler
        self.pool: ProcessPoolExecutor | None = None
        self.client = None
        self.context_future = None

    def __enter__(self) -> _Executor:
        if self.scheduler is not None:
            self.client = _dask_client(self.scheduler)
            self.context_future = self.client.scatter(_absolute_context(self.context),
                                                      broadcast=True)
        elif self.jobs > 1:
            import multiprocessing

            threads = max(1, _cpu_count() // self.jobs)
            self.pool = ProcessPoolExecutor(
                self.jobs, mp_context=multiprocessing.get_context("spawn"),
                initializer=_init_worker, initargs=(self.context, threads, os.getpid()))
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
        if self.client is not None:
            self.client.close()

    def set_shared(self, grade: Grade, summary: FitSummary) -> None:
        """Install the series grade in the context (re-sent to workers)."""
        self.context.shared, self.context.shared_fit = grade, summary
        if self.pool is not None:
            import multiprocessing

            self.pool.shutdown(wait=True)
            threads = max(1, _cpu_count() // self.jobs)
            self.pool = ProcessPoolExecutor(
                self.jobs, mp_context=multiprocessing.get_context("spawn"),
                initializer=_init_worker, initargs=(self.context, threads, os.getpid()))
        if self.client is not None:
            self.context_future = self.client.scatter(_absolute_context(self.context),
                                                      broadcast=True)

    def grade(self, tasks: Iterable[BatchTask], callback=None,
              stage=None) -> Iterator[tuple[BatchTask, FileResult]]:
        tasks = list(tasks)
        if self.client is not None:
            yield from self._dask(tasks, run_task, self.context_future)
        elif self.pool is not None:
            yield from self._pool(tasks, _run_in_worker)
        else:
            for task in tasks:
                yield task, run_task(task, self.context, callback, stage)

    def histograms(self, tasks: Iterable[BatchTask],
                   bins: tuple[int, ...]) -> Iterator[tuple[BatchTask, object]]:
        tasks = list(tasks)
        max_pixels = self.context.opts.max_pixels
        if self.client is not None:
            yield from self._dask(tasks, _histograms_in_worker, bins, max_pixels,
                                  self.context.max_image_pixels)
        elif self.pool is not None:
            yield from self._pool(tasks, _histograms_in_worker, bins, max_pixels)
        else:
            for task in tasks:
                yield task, _histograms_in_worker(task, bins, max_pixels)

    def _pool(self, tasks, function, *args):
        futures = {self.pool.submit(function, task, *args): task for task in tasks}
        try:
            pending = set(futures)
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()

    def _dask(self, tasks, function, *args):
        from dask.distributed import as_completed

        # Workers run in another folder (often on another machine): send absolute paths.
        futures = {self.client.submit(function, _absolute_task(task), *args, pure=False): task
                   for task in tasks}
        try:
            for future in as_completed(list(futures)):
                task, value = futures[future], future.result()
                if isinstance(value, FileResult):  # report the paths as the user gave them
                    value.source = str(task.source)
                    value.output = None if task.output is None else str(task.output)
                yield task, value
        finally:
            self.client.cancel(list(futures))


def _absolute_task(task: BatchTask) -> BatchTask:
    return dataclasses.replace(task, source=Path(os.path.abspath(task.source)),
                               output=None if task.output is None
                               else Path(os.path.abspath(task.output)))


def _absolute_context(context: BatchContext) -> BatchContext:
    if context.sheet_dir is None:
        return context
    return dataclasses.replace(context, sheet_dir=Path(os.path.abspath(context.sheet_dir)))


def _output_folders(tasks: Iterable[BatchTask]) -> dict[Path, set[str]]:
    folders: dict[Path, set[str]] = {}
    for task in tasks:
        if task.output is not None:
            folders.setdefault(task.output.parent, set()).add(task.output.name)
    return folders


def remove_stale_outputs(plan: BatchPlan, extra_folders: Iterable[Path] = (),
                         min_age: float | None = None) -> list[Path]:
    """Remove the temporary files a killed run left beside this plan's outputs.

    Only the project's own temporaries that no live process holds locked
    are removed (see :func:`wbcgrade.color._files.remove_stale_temporaries`);
    -> the removed paths.
    """
    folders = _output_folders(plan.tasks + plan.done)
    for folder in extra_folders:
        folders.setdefault(Path(folder), set())
    removed: list[Path] = []
    for folder, names in folders.items():
        if folder.is_dir():
            kwargs = {} if min_age is None else {"min_age": min_age}
            removed += remove_stale_temporaries(folder, names, **kwargs)
    return removed


def _remove_temporaries(tasks: Iterable[BatchTask], since_ns: int) -> None:
    """Delete temporary files this run left beside the outputs (after an interrupt).

    Hidden ``.<stem>.*<ext>`` files of this run's outputs made since it
    started go, unless a live writer still holds them locked.
    """
    for task in tasks:
        if task.output is None or not task.output.parent.is_dir():
            continue
        for tmp in task.output.parent.glob(
                f".{glob.escape(task.output.stem)}.*{glob.escape(task.output.suffix)}"):
            with contextlib.suppress(OSError):
                if tmp.stat().st_mtime_ns >= since_ns and is_unlocked(tmp, 0.0):
                    tmp.unlink()


def run_batch(plan: BatchPlan, context: BatchContext, consistent: bool = False,
              jobs: int = 1, scheduler: str | None = None,
              on_result: Progress | None = None,
              fit_callback: Callable[[int, np.ndarray, float], None] | None = None,
              stage: Callable[[str], None] | None = None,
              on_read: Callable[[int, int], None] | None = None) -> BatchResult:
    """Grade the photos of a plan; returns every photo's result (skipped ones included).

    Parameters
    ----------
    plan : from :func:`plan_batch`.
    context : styles, options, sheet folder, ...
    consistent : one grade for the whole series (see the module docstring).
    jobs : local worker processes (1: in this process).
    scheduler : Dask scheduler address (overrides ``jobs``).
    on_result : called with each FileResult as it finishes (progress bars).
    fit_callback, stage : progress of fits run in this process.
    on_read : ``on_read(done, total)`` while a series reads its photos' histograms.
    """
    start = time.perf_counter()
    extra = [] if context.sheet_dir is None else [context.sheet_dir, context.sheet_dir / "sheets"]
    remove_stale_outputs(plan, extra)
    since = time.time_ns() - 1_000_000_000
    results: list[FileResult] = [
        FileResult(t.relative, str(t.source), str(t.output), "skipped",
                   timings={"total": 0.0}) for t in plan.done]
    for result in results:
        if on_result:
            on_result(result)
    series, shared = None, None
    try:
        with _Executor(context, jobs, scheduler) as executor:
            todo = list(plan.tasks)
            if consistent and todo:
                opts = context.opts
                bins = tuple(sorted({opts.fit_bins, opts.bins}))
                fit_pool, pool = PaletteSum(), PaletteSum()
                photos, pending, unreadable = plan.all_photos, set(todo), set()
                for number, (task, value) in enumerate(executor.histograms(photos, bins)):
                    if on_read:
                        on_read(number + 1, len(photos))
                    if isinstance(value, str):
                        failed = FileResult(task.relative, str(task.source),
                                            None if task.output is None else str(task.output),
                                            "failed", error=value, timings={"total": 0.0})
                        if task in pending:
                            unreadable.add(task)
                            results.append(failed)
                            if on_result:
                                on_result(failed)
                        continue
                    fit_pool.add(value[opts.fit_bins])
                    pool.add(value[opts.bins])
                todo = [task for task in todo if task not in unreadable]
                if todo:
                    shared, series = series_grade(fit_pool.result(), pool.result(),
                                                  context.styles, opts, fit_callback, stage)
                    executor.set_shared(shared, series)
            for _task, result in executor.grade(todo, fit_callback, stage):
                results.append(result)
                if on_result:
                    on_result(result)
    except KeyboardInterrupt:
        _remove_temporaries(plan.tasks, since)
        raise
    results.sort(key=lambda r: r.relative)
    return BatchResult(results, list(plan.ignored), time.perf_counter() - start, series,
                       list(context.styles.names), shared)

