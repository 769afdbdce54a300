"""Grade every photo of a folder: planning, per-file work, local or distributed execution.

``plan_batch`` lists the photos under a folder and where each graded copy
goes (the tree is mirrored, file names and formats kept); ``run_batch`` grades
them one file per task, in this process, in ``jobs`` local processes or on a
Dask distributed cluster (``--scheduler``; optional extra ``wbcgrade[dask]``,
the workers must see the same paths), through
:class:`wbcgrade._executor.Executor`. Each task reads, grades and writes one
whole file; a file that fails is recorded and the others go on.

Resuming: outputs are written atomically (temporary file + rename), so an
output that exists is complete; it is skipped when it is newer than its photo
and has the photo's pixel count (``overwrite`` redoes it). Interrupting
(Ctrl-C) cancels the queued files, lets the running ones clean up their
temporary files, and removes any temporary file of this run that is left.
A run first removes the temporary files a killed run left in its output
folders (only unlocked ones: see :mod:`wbcgrade._publish`). Local worker
processes end when their parent dies (``PR_SET_PDEATHSIG`` and a parent-pid
watch), so a killed batch does not go on writing. Paths sent to a Dask
cluster are made absolute first (its workers run in another folder).

Series mode (``consistent``): every photo's histogram is read first (also
those already done, so a resumed series gets the same grade), the pooled
palette takes the one grade path once
(:func:`wbcgrade.color.grade.grading.grade_histograms`), and each task only applies it.

Modules: ``plan`` (which photos, where their outputs go, checked;
stale temporaries), ``settings`` (what the outputs depend on, recorded in
the output folder), ``results`` (``FileResult``, ``BatchResult``), ``task``
(one photo, in a worker: :func:`wbcgrade.photos.workflow.grade_file`),
``run`` (``run_batch``), ``workflow`` (the ``batch`` and ``report``
commands: :func:`grade_folder`, :func:`report_folder`). Executors are
:mod:`wbcgrade._executor`.
"""

from __future__ import annotations

import importlib

#: Name -> the module that defines it (of this package, or a full name), loaded on first
#: use (PEP 562): ``wbcgrade report`` on a batch's results imports ``recorded`` and never
#: the grade.
_NAMES = {
    "BatchPlan": "plan", "BatchTask": "plan", "image_extensions": "plan",
    "output_is_complete": "plan", "plan_batch": "plan", "recheck_plan": "plan",
    "remove_stale_outputs": "plan",
    "BatchResult": "wbcgrade.photos.results", "FileResult": "wbcgrade.photos.results",
    "run_batch": "run",
    "SETTINGS_FILE": "settings", "batch_settings": "settings",
    "settings_changed": "settings", "write_settings": "settings",
    "BatchContext": "task", "run_task": "task",
    "BatchProgress": "wbcgrade.photos.progress", "grade_folder": "workflow",
    "report_folder": "workflow",
}

__all__ = ["BatchTask", "BatchPlan", "BatchContext", "FileResult", "BatchResult",
           "image_extensions", "plan_batch", "run_task", "run_batch", "output_is_complete",
           "batch_settings", "settings_changed", "write_settings", "remove_stale_outputs",
           "recheck_plan", "SETTINGS_FILE", "BatchProgress", "grade_folder", "report_folder"]


def __getattr__(name: str):
    """Load a name of the package on first use (``wbcgrade.batch.plan_batch``)."""
    try:
        module = _NAMES[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module if "." in module
                                            else f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
