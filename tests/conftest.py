"""Shared test fixtures."""

import os
import shutil
import tempfile

import numpy as np
import pytest
from click.testing import CliRunner, Result

#: The thread counts of OpenBLAS, OpenMP (numba's parallel kernels) and numba, set for the
#: workers of a run on several cores (:func:`pytest_configure`).
THREAD_SETTINGS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                   "NUMBA_NUM_THREADS")


def pytest_configure(config):
    """Tests run side by side (pytest-xdist's ``-n``, in ``pyproject.toml``): each worker's
    BLAS, OpenMP and numba get their share of the cores (unless set already), so that the
    workers do not oversubscribe them (OpenBLAS's threads busy-wait: docs/architecture.md,
    threads). The core's own pool (``WBCGRADE_THREADS``) keeps its size, so that its threaded
    paths run as in one process. Set here, in the process that starts the workers, before it
    starts them: the libraries read these when they load."""
    workers = _workers(config)
    if workers < 2 or os.environ.get("PYTEST_XDIST_WORKER"):
        return
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    for name in THREAD_SETTINGS:
        os.environ.setdefault(name, str(max(1, cores // workers)))


def _workers(config) -> int:
    """How many workers pytest-xdist runs the tests on (``-n``, at most ``--maxprocesses``);
    0 when the tests run in this process."""
    workers = getattr(config.option, "numprocesses", None)
    if not isinstance(workers, int):
        return 0
    return min(workers, getattr(config.option, "maxprocesses", None) or workers)


def pytest_sessionfinish(session, exitstatus):
    """A passing session's temporary folder is removed at its end (not each test's as it
    passes, as ``tmp_path_retention_policy = "failed"`` does: a later test then gets the
    same path, and OpenColorIO's file cache, keyed by path, served it the former file)."""
    factory = getattr(session.config, "_tmp_path_factory", None)
    basetemp = getattr(factory, "_basetemp", None)
    if exitstatus == 0 and basetemp is not None and getattr(factory, "_given_basetemp",
                                                            None) is None:
        shutil.rmtree(basetemp, ignore_errors=True)


#: Tier ("fast": not marked slow, "slow") -> [tests run, seconds of their set-up, call and
#: tear-down], printed at the end of the run (:func:`pytest_terminal_summary`).
_TIER_TIMES = {"fast": [0, 0.0], "slow": [0, 0.0]}


def pytest_runtest_logreport(report):
    tier = _TIER_TIMES["slow" if "slow" in report.keywords else "fast"]
    tier[1] += report.duration
    tier[0] += report.when == "call"


def pytest_terminal_summary(terminalreporter):
    """One line with the time of the fast tier (``-m "not slow"``) and of the whole run, so
    that a run of the whole suite (``.ci/run``) also says what the fast tier takes. With the
    tests on several workers the controller sums the workers' reports; a worker prints
    nothing."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        return
    (fast, fast_s), (slow, slow_s) = _TIER_TIMES["fast"], _TIER_TIMES["slow"]
    if fast + slow == 0:  # nothing ran (--collect-only)
        return
    terminalreporter.write_line(
        f"test time: fast tier {fast} tests {fast_s:.0f} s, slow {slow} tests {slow_s:.0f} s, "
        f"together {fast_s + slow_s:.0f} s (the tests' own set-up, call and tear-down, "
        f"summed{_per_worker(terminalreporter.config, fast_s, slow_s)})")


def _per_worker(config, fast_s: float, slow_s: float) -> str:
    """With the tests on several workers (pytest-xdist), their share of each: about the wall
    time of each tier."""
    workers = _workers(config)
    if workers < 2:
        return ""
    return (f" over {workers} workers: {fast_s / workers:.0f} s and {slow_s / workers:.0f} s "
            "a worker")


@pytest.fixture(scope="session", autouse=True)
def _system_temporary_folder_in_basetemp(tmp_path_factory):
    """Every temporary file of the session (``tempfile``, and ``$TMPDIR`` for the commands
    the tests start) goes under pytest's own folder, removed when every test passed
    (:func:`pytest_sessionfinish`): a run of the suite leaves nothing in the system's
    temporary folder (issue 31: it left about 590 MB there)."""
    folder = tmp_path_factory.mktemp("system-tmp")
    before_env, before = os.environ.get("TMPDIR"), tempfile.tempdir
    os.environ["TMPDIR"], tempfile.tempdir = str(folder), str(folder)
    yield folder
    tempfile.tempdir = before
    if before_env is None:
        os.environ.pop("TMPDIR", None)
    else:
        os.environ["TMPDIR"] = before_env


def run_cli(*args: object, env: dict[str, str] | None = None) -> Result:
    """``wbcgrade ARGS...`` run in this process through click's runner, every argument made a
    string (paths too); ``env`` sets environment variables for the run. Returns click's
    ``Result`` (``exit_code``, ``output``, ``exception``). Module-level helpers call this;
    tests take the :func:`cli` fixture."""
    from wbcgrade.cli import main  # here, so that collecting the doctests imports no CLI

    return CliRunner(env=env).invoke(main, [str(a) for a in args])


@pytest.fixture
def cli():
    """The command line: ``cli("apply", photo, "--preset", "warm")`` runs ``wbcgrade apply
    ...`` in this process and returns click's ``Result`` (see :func:`run_cli`)."""
    return run_cli


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
