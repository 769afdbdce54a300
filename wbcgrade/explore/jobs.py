"""The slow jobs of the explore page, in one worker process at lower priority.

An exact colour map takes seconds (``apply``'s grids); the landscape of the
fit's loss over the polygon takes seconds too. Run in the server's process
they would share its cores and the core's thread pool with the live
preview, and a drag would stall behind them. They run instead in one worker
process (a fresh interpreter, so no lock or thread state is inherited and
no caller's ``__main__`` is imported again: it runs ``python -m
wbcgrade.explore._worker`` with one end of a socket pair) whose
priority is lowered (``nice`` 10, :mod:`._worker`): the operating system
gives the preview the cores first. It runs in its own session, so Ctrl-C in
the terminal reaches the server only, which stops it; when the server dies
the worker reads the end of its socket and exits.

Jobs are coalesced: a new "view" job (the exact map of what the page shows
after a move) replaces the view job still waiting, whose callers get
:class:`Superseded`; so do new "slopes" (the fast map's derivatives the
page extrapolates from) and "landscape" jobs. "export" jobs are never
replaced and go first. Exact maps are kept (least recently used, a few
dozen) with their offset from the fast map, for the preview's correction
and for repeated exports, and the last few slope sets. The worker is
started again if it dies.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path

from wbcgrade.explore.settings import Settings

__all__ = ["JobWorker", "Superseded", "JobError", "Reference"]

#: Exact maps kept (each 33^3 x 3 float32 twice: about 0.9 MB).
CACHE_SIZE = 32
#: Seconds the worker may take to start (imports, the style set sent over).
START_TIMEOUT_S = 300.0


class Superseded(Exception):
    """A newer job of the same kind replaced this one before it ran."""


class JobError(RuntimeError):
    """A job failed in the worker (one-line reason)."""


@dataclass
class Reference:
    """An exact map and its offset from the fast map at the same settings."""

    settings: Settings
    exact: object
    offset: object
    seconds: float


@dataclass
class _Job:
    kind: str  # "reference" or "losses"
    group: str  # "export", "view" or "landscape"
    key: object
    payload: object
    done: threading.Event = field(default_factory=threading.Event)
    result: object = None
    error: BaseException | None = None

    def finish(self, result=None, error: BaseException | None = None) -> None:
        self.result, self.error = result, error
        self.done.set()


_ORDER = ("export", "view", "slopes", "landscape")
#: Slope sets kept (each S LUTs: about 3 MB for seven styles).
SLOPES_CACHE_SIZE = 4


class JobWorker:
    """One worker process and the queue in front of it.

    Parameters
    ----------
    state : :meth:`wbcgrade.explore.engine.Session.grader_state`, sent to the
        worker when it starts.
    """

    def __init__(self, state: dict) -> None:
        self._state = state
        self._cond = threading.Condition()
        self._pending: dict[str, list[_Job]] = {group: [] for group in _ORDER}
        self._running: _Job | None = None
        self._cache: OrderedDict = OrderedDict()
        self._closed = False
        self._process = None
        self._connection = None
        self._starting = None  # a worker process still starting (killed by close)
        self._thread = threading.Thread(target=self._run, name="explore-jobs", daemon=True)

    # -- the caller's side -------------------------------------------------------------
    def start(self) -> JobWorker:
        """Start the worker process (in the background) and the dispatcher."""
        self._thread.start()
        return self

    def reference(self, settings: Settings, group: str = "view",
                  timeout: float | None = None) -> Reference:
        """The exact map of ``settings`` (cached, or computed; waits for it).

        Raises Superseded (a newer "view" job replaced this one), JobError,
        or TimeoutError.
        """
        return self._cached_or_run("reference", group, settings, timeout)

    def slopes(self, settings: Settings, timeout: float | None = None):
        """The fast map's slopes towards each style at ``settings`` (a "slopes" job; waits).

        Returns (S, n, n, n, 3) float32 (:meth:`wbcgrade.explore.engine.ExactGrader.slopes`).
        """
        return self._cached_or_run("slopes", "slopes", settings, timeout)

    def losses(self, rows: list[tuple[float, ...]], timeout: float | None = None) -> list[float]:
        """The fit's loss at each row of weights (a "landscape" job; waits)."""
        key = ("losses", tuple(rows))
        return self._wait(self._submit("losses", "landscape", key, list(rows)), timeout)

    def references(self, family: tuple) -> list[Reference]:
        """The exact maps known for one family of settings (most recent first)."""
        with self._cond:
            return [ref for key, ref in reversed(self._cache.items())
                    if key[0] == "reference" and ref.settings.family == family]

    def close(self) -> None:
        """Stop the worker and the dispatcher; waiting callers get JobError."""
        with self._cond:
            self._closed = True
            waiting = [job for jobs in self._pending.values() for job in jobs]
            for jobs in self._pending.values():
                jobs.clear()
            self._cond.notify_all()
        for job in waiting:
            job.finish(error=JobError("the explore server is stopping"))
        with self._cond:
            starting = self._starting
        if starting is not None:  # still importing: it would outlive the server a while
            starting.kill()
        self._stop_process()

    # -- inside ------------------------------------------------------------------------
    def _cached_or_run(self, kind: str, group: str, settings: Settings,
                       timeout: float | None):
        """The cached result of a job on ``settings``' map, else the job's (waits)."""
        key = (kind, settings.map_key)
        with self._cond:
            cached = self._cache.get(key)
            if cached is not None:
                self._cache.move_to_end(key)
                return cached
        return self._wait(self._submit(kind, group, key, settings), timeout)

    def _submit(self, kind: str, group: str, key, payload) -> _Job:
        with self._cond:
            if self._closed:
                raise JobError("the explore server is stopping")
            for job in [self._running, *self._pending["export"], *self._pending[group]]:
                if job is not None and job.key == key:
                    return job  # the same job is queued or running: wait for it
            job = _Job(kind, group, key, payload)
            if group != "export":  # coalesce: only the newest view / landscape job waits
                for old in self._pending[group]:
                    old.finish(error=Superseded())
                self._pending[group].clear()
            self._pending[group].append(job)
            self._cond.notify_all()
            return job

    @staticmethod
    def _wait(job: _Job, timeout: float | None):
        if not job.done.wait(timeout):
            raise TimeoutError("the job took too long")
        if job.error is not None:
            raise job.error
        return job.result

    def _next(self) -> _Job | None:
        with self._cond:
            while not self._closed:
                for group in _ORDER:
                    if self._pending[group]:
                        self._running = self._pending[group].pop(0)
                        return self._running
                self._cond.wait()
            return None

    def _trim(self) -> None:
        """Drop the least recently used results beyond the caches' sizes (lock held)."""
        for kind, size in (("reference", CACHE_SIZE), ("slopes", SLOPES_CACHE_SIZE)):
            keys = [key for key in self._cache if key[0] == kind]
            for key in keys[:max(0, len(keys) - size)]:
                del self._cache[key]

    def _start_process(self) -> None:
        process, connection = _spawn()
        with self._cond:
            self._starting = process
            closed = self._closed
        try:
            if closed:
                raise JobError("the explore server is stopping")
            connection.send(self._state)
            if not connection.poll(START_TIMEOUT_S):
                raise JobError("the worker did not start")
            status, _, _ = connection.recv()
            if status != "ready":
                raise JobError("the worker did not start")
        except BaseException:
            process.kill()
            process.wait()
            connection.close()
            with self._cond:
                self._starting = None
            raise
        with self._cond:
            self._starting = None
            self._process, self._connection = process, connection
            if self._closed:  # closed while starting
                self._stop_process_locked()

    def _stop_process_locked(self) -> None:
        process, connection = self._process, self._connection
        self._process = self._connection = None
        if process is not None:
            process.kill()
            process.wait()
        if connection is not None:
            connection.close()

    def _stop_process(self) -> None:
        with self._cond:
            self._stop_process_locked()

    def _call(self, job: _Job):
        """Send one job to the worker and wait for its answer (restart it once if it died)."""
        for attempt in range(2):
            try:
                if self._connection is None:
                    self._start_process()
                connection = self._connection
                if connection is None:
                    raise JobError("the explore server is stopping")
                connection.send((job.kind, job.payload))
                return connection.recv()
            except (EOFError, OSError, BrokenPipeError):
                self._stop_process()
                if self._closed or attempt == 1:
                    raise JobError("the worker stopped") from None
        raise JobError("the worker stopped")  # pragma: no cover - loop returns or raises

    def _run(self) -> None:
        try:
            self._start_process()
        except (JobError, OSError, EOFError):
            self._stop_process()  # started again by the first job
        while True:
            job = self._next()
            if job is None:
                return
            try:
                status, result, seconds = self._call(job)
            except JobError as exc:
                status, result, seconds = "error", str(exc), 0.0
            with self._cond:
                self._running = None
            if status != "ok":
                job.finish(error=JobError(result))
                continue
            if job.kind in ("reference", "slopes"):
                if job.kind == "reference":
                    result = Reference(job.payload, result["exact"], result["offset"], seconds)
                with self._cond:
                    self._cache[job.key] = result
                    self._trim()
            job.finish(result)


def _spawn() -> tuple[subprocess.Popen, Connection]:
    """Start ``python -m wbcgrade.explore._worker FD``; -> (process, our end of the socket)."""
    ours, theirs = socket.socketpair()
    package_root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH")) if p)
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "wbcgrade.explore._worker", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, env=env,
            start_new_session=True)
    except BaseException:
        ours.close()
        raise
    finally:
        theirs.close()
    return process, Connection(ours.detach())
