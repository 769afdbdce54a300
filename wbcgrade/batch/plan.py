"""Which photos a batch grades, where each graded copy goes, and cleaning up after killed runs.

The input tree is mirrored under the output folder (file names and formats
kept). Every output is checked before any work by the one output checker
(:func:`wbcgrade._publish.check_output_path`): resolved through links, it
must stay inside the output folder and never be an input. An existing
output that is complete (outputs are published atomically: newer than its
photo, the photo's pixel count) is skipped; any other existing file is one
this run did not write, so it is refused (the photo fails, the others go
on) unless ``overwrite``, which redoes everything.
"""

from __future__ import annotations

import contextlib
import glob
import os
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from wbcgrade._publish import check_output_path, is_unlocked, remove_stale_temporaries
from wbcgrade.batch.records import read_record
from wbcgrade.color.io.images import header_pixels, image_extensions
from wbcgrade.color.io.raw import RAW_SUFFIXES, output_name
from wbcgrade.errors import InputError

__all__ = ["BatchTask", "BatchPlan", "image_extensions", "output_is_complete", "plan_batch",
           "recheck_plan", "remove_stale_outputs", "remove_temporaries"]


@dataclass(frozen=True)
class BatchTask:
    """One photo: its path, the output path (as the user named it), the path relative to
    the input folder, and the file the output resolves to (checked; what is written)."""

    source: Path
    output: Path | None
    relative: str
    target: Path | None = None
    #: the output is complete but no result records it (a run stopped between the two):
    #: graded again and replaced, so that the records heal
    replace: bool = False


@dataclass
class BatchPlan:
    """What a batch will do.

    Attributes
    ----------
    tasks : photos to grade (their outputs resolved and checked).
    done : photos whose output is already complete (skipped unless ``overwrite``).
    ignored : relative paths of files that are not images (by extension).
    refused : photos whose output may not be written, with the reason (an
        existing file this run did not write, a link out of the output
        folder, an input): they fail without being graded.
    """

    tasks: list[BatchTask]
    done: list[BatchTask] = field(default_factory=list)
    ignored: list[str] = field(default_factory=list)
    refused: list[tuple[BatchTask, str]] = field(default_factory=list)

    @property
    def all_photos(self) -> list[BatchTask]:
        return sorted(self.tasks + self.done, key=lambda t: t.relative)


def _overwrite(overwrite: bool, force: bool | None) -> bool:
    """``overwrite``, or the deprecated ``force`` keyword (with a DeprecationWarning)."""
    if force is None:
        return bool(overwrite)
    warnings.warn("force= is deprecated; use overwrite=", DeprecationWarning, stacklevel=3)
    return bool(overwrite or force)


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
    sizes = [header_pixels(path) for path in (source, output)]  # regular files only
    return sizes[0] == sizes[1] > 0


def plan_batch(in_path: str | os.PathLike, out_dir: str | os.PathLike | None,
               recursive: bool = False, overwrite: bool = False,
               exclude: Iterable[str | os.PathLike] = (), *,
               force: bool | None = None,
               reads: Iterable[str | os.PathLike] = ()) -> BatchPlan:
    """List the photos under ``in_path`` (a folder, or one photo) and their outputs.

    Hidden files and anything inside ``out_dir`` or an ``exclude`` folder
    (e.g. a report folder) are left out. With
    ``out_dir`` None (a report only), nothing is written and nothing is
    skipped. Raises InputError when the folder is missing or the output
    folder is the input folder. ``reads``: the other files the grade reads (style
    photos, presets, a saved look): an output naming one is refused, as one naming
    its own photo is. ``overwrite`` plans every photo, finished
    outputs included (``force`` is its former name, deprecated). Each
    output is resolved and checked (see the module docstring); a photo whose
    output may not be written is ``refused``.
    """
    overwrite = _overwrite(overwrite, force)
    reads = list(reads)
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
    exts = image_extensions() | RAW_SUFFIXES
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
        task = BatchTask(path, None if out is None else out / output_name(rel), rel.as_posix())
        if task.output is None:
            plan.tasks.append(task)
            continue
        heal = False
        try:  # links and inputs first: a link into the input tree is never "complete"
            check_output_path(task.output, [path, *reads], True, root=out, make_folders=True)
            if not overwrite and output_is_complete(path, task.output):
                if _recorded(out, task):
                    plan.done.append(task)
                    continue
                heal = True  # published, never recorded: graded again, records healed
            resolved = check_output_path(task.output, [path, *reads], overwrite or heal,
                                         root=out, make_folders=True)
        except InputError as exc:
            plan.refused.append((task, str(exc)))
            continue
        plan.tasks.append(BatchTask(path, task.output, task.relative, resolved, heal))
    return plan


def _recorded(out: Path, task: BatchTask) -> bool:
    """Whether a batch's result record of ``task`` is there and readable."""
    return read_record(out, task.relative) is not None


def recheck_plan(plan: BatchPlan, overwrite: bool = False, *,
                 force: bool | None = None,
                 out_dir: str | os.PathLike | None = None) -> BatchPlan:
    """Move tasks whose output became complete since planning to ``done`` (unless ``overwrite``).

    Used once a run holds the output folder's lock: a run that finished in
    between is not redone. With ``out_dir`` (the batch's output folder) a
    complete output counts only when its result is recorded there.
    """
    if _overwrite(overwrite, force):
        return plan
    tasks, done = [], list(plan.done)
    for task in plan.tasks:
        if task.output is not None and output_is_complete(task.source, task.output) and (
                out_dir is None or _recorded(Path(out_dir), task)):
            done.append(task)
        else:
            tasks.append(task)
    return BatchPlan(tasks=tasks, done=done, ignored=list(plan.ignored),
                     refused=list(plan.refused))


def _output_folders(tasks: Iterable[BatchTask]) -> dict[Path, set[str]]:
    folders: dict[Path, set[str]] = {}
    for task in tasks:
        for path in {task.output, task.target} - {None}:
            folders.setdefault(path.parent, set()).add(path.name)
    return folders


def remove_stale_outputs(plan: BatchPlan, extra_folders: Iterable[Path] = (),
                         min_age: float | None = None) -> list[Path]:
    """Remove the temporary files a killed run left beside this plan's outputs.

    Only the project's own temporaries that no live process holds locked
    are removed (see :func:`wbcgrade._publish.remove_stale_temporaries`);
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


def remove_temporaries(tasks: Iterable[BatchTask], since_ns: int) -> None:
    """Delete temporary files this run left beside the outputs (after an interrupt).

    Hidden ``.<stem>.*<ext>`` files of this run's outputs made since it
    started go, unless a live writer still holds them locked.
    """
    for task in tasks:
        output = task.target or task.output
        if output is None or not output.parent.is_dir():
            continue
        for tmp in output.parent.glob(
                f".{glob.escape(output.stem)}.*{glob.escape(output.suffix)}"):
            with contextlib.suppress(OSError):
                if tmp.stat().st_mtime_ns >= since_ns and is_unlocked(tmp, 0.0):
                    tmp.unlink()
