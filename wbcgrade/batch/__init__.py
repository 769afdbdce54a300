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

from wbcgrade.batch.plan import (
    BatchPlan,
    BatchTask,
    image_extensions,
    output_is_complete,
    plan_batch,
    recheck_plan,
    remove_stale_outputs,
)
from wbcgrade.batch.run import run_batch
from wbcgrade.batch.settings import (
    SETTINGS_FILE,
    batch_settings,
    settings_changed,
    write_settings,
)
from wbcgrade.batch.task import BatchContext, run_task
from wbcgrade.batch.workflow import BatchProgress, grade_folder, report_folder
from wbcgrade.photos.results import BatchResult, FileResult

__all__ = ["BatchTask", "BatchPlan", "BatchContext", "FileResult", "BatchResult",
           "image_extensions", "plan_batch", "run_task", "run_batch", "output_is_complete",
           "batch_settings", "settings_changed", "write_settings", "remove_stale_outputs",
           "recheck_plan", "SETTINGS_FILE", "BatchProgress", "grade_folder", "report_folder"]
