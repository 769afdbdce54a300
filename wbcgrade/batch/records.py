"""What a batch found for each photo, kept in its output folder for ``wbcgrade report``.

As each photo is graded, its result (weights, losses, timings, the palette it
was moved towards, the colour spaces; :meth:`FileResult.as_dict`) is written
to ``OUT/.wbcgrade-results/<photo path>.json`` (atomically, by the process
that runs the batch). ``wbcgrade report OUT`` reads these records and the
settings record (:mod:`wbcgrade.batch.settings`) instead of grading the
photos again. A photo skipped by a rerun keeps the record of the run that
graded it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from wbcgrade._publish import atomic_path, remove_stale_temporaries
from wbcgrade.photos.results import FileResult

__all__ = ["RESULTS_FOLDER", "record_path", "write_record", "read_record",
           "remove_stale_records"]

#: Folder in a batch's output folder holding one JSON record per graded photo.
RESULTS_FOLDER = ".wbcgrade-results"


def record_path(out_dir: str | os.PathLike, relative: str) -> Path:
    """The record of a photo (its path relative to the batch's input folder)."""
    return Path(out_dir) / RESULTS_FOLDER / f"{relative}.json"


def write_record(out_dir: str | os.PathLike, result: FileResult) -> Path:
    """Record a graded photo's result in ``out_dir`` (replacing an earlier record).

    Paths are stored absolute, so that the record is read the same from any folder.
    """
    entry = result.as_dict()
    entry["source"] = os.path.abspath(result.source)
    if result.output is not None:
        entry["output"] = os.path.abspath(result.output)
    path = record_path(out_dir, result.relative)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, overwrite=True) as tmp, open(tmp, "w", encoding="utf-8") as handle:
        json.dump(entry, handle, indent=1, default=float)
    return path


def read_record(out_dir: str | os.PathLike, relative: str) -> FileResult | None:
    """The recorded result of a photo, or None when there is none (or it is unreadable)."""
    try:
        entry = json.loads(record_path(out_dir, relative).read_text("utf-8"))
        return FileResult.from_dict(entry)
    except (OSError, ValueError, KeyError, TypeError, RecursionError):  # (nested too deep)
        return None


def remove_stale_records(out_dir: str | os.PathLike) -> list[Path]:
    """Remove the temporary record files a killed batch left in ``out_dir``'s records
    (those no live process holds locked; see
    :func:`wbcgrade._publish.remove_stale_temporaries`); -> the removed paths."""
    root = Path(out_dir) / RESULTS_FOLDER
    removed: list[Path] = []
    if not root.is_dir():
        return removed
    for folder, _, _ in os.walk(root):
        removed += remove_stale_temporaries(folder)
    return removed
