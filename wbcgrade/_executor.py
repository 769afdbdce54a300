"""Run one function over many independent items: here, in local processes, or on Dask.

Shared by the domains' many-file commands (colour ``batch`` and ``report``,
shape ``complete`` and ``project`` when given ``--jobs``). The function is
called as ``function(item, context, *args)``: ``context`` is what every item
needs (styles, options, a reference shape), sent once to each worker rather
than with every item.

- ``jobs=1``, no scheduler: in this process, in order, with ``local_kwargs``
  (progress callbacks, which cannot cross processes).
- ``jobs>1``: a local ``ProcessPoolExecutor`` (``spawn``). Workers end when
  their parent dies (``PR_SET_PDEATHSIG`` and a parent-pid watch), cap their
  own threads (the machine's cores shared between the workers), and start
  no queued item once Ctrl-C has reached them.
- ``scheduler``: a Dask distributed cluster (optional extra
  ``wbcgrade[dask]``); the context is scattered once to every worker, and
  ``to_remote`` rewrites items and context for machines that run in another
  folder (absolute paths).

Results come back as ``(item, result)`` pairs as they finish (unordered).
Exceptions raised by ``function`` propagate; functions that must not stop a
run (one bad file) return their failure as a value instead.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from wbcgrade.errors import InputError, OptionError

__all__ = ["Executor", "cpu_count", "release_cached_objects", "DASK_CONNECT_TIMEOUT", "MAX_JOBS",
           "PARENT_WATCH_S"]

#: Local worker processes at most (a pool of more cannot even be made: its semaphores).
MAX_JOBS = 256

#: How long to wait for a Dask scheduler to answer.
DASK_CONNECT_TIMEOUT = "20s"

#: How often a worker checks that its parent process is still alive (seconds).
PARENT_WATCH_S = 1.0

#: What an item whose worker process died failed with (``map_unordered``'s ``on_lost``).
_LOST_REASON = ("its worker process died (killed, out of memory, or a crash in a library); "
                "the other photos went on")

_WORKER_CONTEXT: Any = None
_WORKER_INTERRUPTED = False


def cpu_count() -> int:
    """Cores this process may run on (its affinity mask where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _watch_parent(parent: int) -> None:
    while True:
        time.sleep(PARENT_WATCH_S)
        if os.getppid() != parent:
            os._exit(1)  # the run is gone: write nothing more (temporaries are cleaned later)


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


def release_cached_objects() -> None:
    """Empty the ``functools`` caches of the loaded wbcgrade modules and collect garbage.

    Run at a worker's exit (``atexit``, before the interpreter tears its
    modules down): library objects held in those caches (OpenImageIO's
    ``ColorConfig`` and colour processors, in :mod:`wbcgrade.color.colorspace`)
    are freed while their bindings still exist, so no binding reports them
    as leaked at exit ("nanobind: leaked ..." lines that look like a crash).
    """
    for name, module in list(sys.modules.items()):
        if not name.startswith("wbcgrade") or module is None:
            continue
        for value in list(vars(module).values()):
            clear = getattr(value, "cache_clear", None)
            if callable(clear) and getattr(value, "__module__", None) == name:
                with contextlib.suppress(Exception):
                    clear()
    gc.collect()


def _init_worker(context: Any, threads: int, parent: int | None,
                 setup: Callable[[Any], None] | None) -> None:
    """Process-pool initializer: die with the parent, keep the context, cap threads,
    release cached library objects at exit (:func:`release_cached_objects`)."""
    global _WORKER_CONTEXT
    atexit.register(release_cached_objects)
    if parent is not None:
        _die_with_parent(parent)
    _WORKER_CONTEXT = context
    os.environ["WBCGRADE_THREADS"] = str(max(1, threads))  # the core's kernel-product threads
    with contextlib.suppress(ImportError):
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    with contextlib.suppress(Exception):
        import numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    if setup is not None:
        setup(context)


def _call_in_worker(function: Callable, item: Any, *args: Any) -> Any:
    """Run one item in a pool worker with the worker's context."""
    global _WORKER_INTERRUPTED
    if _WORKER_INTERRUPTED:  # Ctrl-C reached this worker: start no queued item
        raise KeyboardInterrupt
    try:
        return function(item, _WORKER_CONTEXT, *args)
    except KeyboardInterrupt:
        _WORKER_INTERRUPTED = True
        raise


def _dask_client(address: str):
    try:
        from dask.distributed import Client
    except ImportError:
        raise OptionError("{scheduler} needs Dask: pip install 'wbcgrade[dask]' "
                          "(dask[distributed])", "scheduler") from None
    try:
        return Client(address, timeout=DASK_CONNECT_TIMEOUT)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address} ({exc})") from None


def _same(value: Any) -> Any:
    return value


class Executor:
    """Map ``function(item, context, *args)`` over items: in process, local processes or Dask.

    Parameters
    ----------
    context : what every item needs (picklable when ``jobs > 1`` or on Dask).
    jobs : local worker processes (1: in this process).
    scheduler : Dask scheduler address (overrides ``jobs``).
    worker_setup : ``worker_setup(context)`` run once in each local worker after
        its threads are capped (module-level function: it is pickled).
    to_remote : ``(item -> item, context -> context)`` applied before sending to
        Dask workers (e.g. absolute paths); identity by default.

    Use as a context manager; ``map_unordered`` yields ``(item, result)`` pairs.
    """

    def __init__(self, context: Any, jobs: int = 1, scheduler: str | None = None,
                 worker_setup: Callable[[Any], None] | None = None,
                 to_remote: tuple[Callable[[Any], Any], Callable[[Any], Any]] | None = None):
        if int(jobs) > MAX_JOBS:
            raise OptionError(f"{{jobs}} must be between 1 and {MAX_JOBS}", "jobs")
        self.context, self.jobs, self.scheduler = context, max(1, int(jobs)), scheduler
        self.worker_setup = worker_setup
        self.item_to_remote, self.context_to_remote = to_remote or (_same, _same)
        self.pool: ProcessPoolExecutor | None = None
        self.client = None
        self.context_future = None

    @property
    def in_process(self) -> bool:
        """True when items run in this process (no pool, no cluster)."""
        return self.pool is None and self.client is None

    def _start_pool(self) -> None:
        import multiprocessing

        threads = max(1, cpu_count() // self.jobs)
        self.pool = ProcessPoolExecutor(
            self.jobs, mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(self.context, threads, os.getpid(), self.worker_setup))

    def __enter__(self) -> Executor:
        if self.scheduler is not None:
            self.client = _dask_client(self.scheduler)
            self.context_future = self.client.scatter(self.context_to_remote(self.context),
                                                      broadcast=True)
        elif self.jobs > 1:
            self._start_pool()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.pool is not None:
            if exc_type is not None and issubclass(exc_type, KeyboardInterrupt):
                self._stop_workers()
            self.pool.shutdown(wait=True, cancel_futures=True)
        if self.client is not None:
            self.client.close()

    def _stop_workers(self, grace_s: float = 1.0) -> None:
        """End the pool's workers now: the run was interrupted (Ctrl-C, SIGTERM).

        A worker that only the parent was told to stop (SIGTERM to the parent, not
        to its process group) would otherwise finish its photo and start the ones
        queued for it, publishing outputs after the signal that no result records
        (the pool's shutdown waited for them: 23 s). Each gets SIGTERM, then
        SIGKILL after ``grace_s``; the caller removes what they had half-written.
        """
        processes = list((getattr(self.pool, "_processes", None) or {}).values())
        _quiet_broken_pool_thread()
        for process in processes:
            with contextlib.suppress(Exception):
                process.terminate()
        deadline = time.monotonic() + grace_s
        for process in processes:
            with contextlib.suppress(Exception):
                process.join(max(0.0, deadline - time.monotonic()))
                if process.is_alive():
                    process.kill()
                    process.join(1.0)

    def set_context(self, context: Any) -> None:
        """Replace the context (local workers are restarted, Dask gets it again)."""
        self.context = context
        if self.pool is not None:
            self.pool.shutdown(wait=True)
            self._start_pool()
        if self.client is not None:
            self.context_future = self.client.scatter(self.context_to_remote(context),
                                                      broadcast=True)

    def map_unordered(self, function: Callable, items: Iterable[Any], *args: Any,
                      local_kwargs: dict | None = None,
                      on_lost: Callable[[Any, str], Any] | None = None
                      ) -> Iterator[tuple[Any, Any]]:
        """Yield ``(item, function(item, context, *args))`` as each finishes.

        ``function`` must be a module-level function when it runs in other
        processes. ``local_kwargs`` are passed only when running in this process.
        Queued items are cancelled when the caller stops iterating or an
        exception (Ctrl-C included) propagates.

        ``on_lost(item, reason)``: the result of an item whose local worker process
        died (killed, out of memory, a crash in a library): the pool is started
        again and the other items go on; an item is lost only when it alone was
        running when its worker died (:meth:`_pool`). None: the pool's
        ``BrokenProcessPool`` propagates.
        """
        items = list(items)
        if self.client is not None:
            yield from self._dask(items, function, args)
        elif self.pool is not None:
            yield from self._pool(items, function, args, on_lost)
        else:
            for item in items:
                yield item, function(item, self.context, *args, **(local_kwargs or {}))

    def _pool(self, items: list, function: Callable, args: tuple,
              on_lost: Callable[[Any, str], Any] | None = None):
        """The items on the local pool. When a worker dies, every unfinished item fails with
        ``BrokenProcessPool``: the pool is started again, the items that were running are
        tried again one at a time (the one that dies alone is lost: ``on_lost``), the
        others as before; an item caught in two deaths is tried alone too."""
        from concurrent.futures.process import BrokenProcessPool

        queue = list(range(len(items)))  # indices still to run together
        alone: list[int] = []  # indices to run one at a time
        strikes = [0] * len(items)
        while queue or alone:
            if alone:
                batch = [alone.pop(0)]
            else:
                batch, queue = queue, []
            futures = {self.pool.submit(_call_in_worker, function, items[i], *args): i
                       for i in batch}
            broken: list[int] = []
            running: set[int] = set()
            try:
                pending = set(futures)
                while pending:
                    running |= {futures[f] for f in pending if f.running()}
                    done, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        try:
                            result = future.result()
                        except BrokenProcessPool:
                            if on_lost is None:
                                raise
                            broken.append(futures[future])
                            continue
                        yield items[futures[future]], result
            finally:
                for future in futures:
                    future.cancel()
            if not broken:
                continue
            self._restart_broken_pool()
            if len(batch) == 1:
                yield items[batch[0]], on_lost(items[batch[0]], _LOST_REASON)
                continue
            for index in sorted(broken):
                strikes[index] += 1
                if index in running or strikes[index] > 1:
                    alone.append(index)
                else:
                    queue.append(index)

    def _restart_broken_pool(self) -> None:
        """Replace a pool whose worker died by a fresh one (its workers start on demand)."""
        _quiet_broken_pool_thread()
        with contextlib.suppress(Exception):
            self.pool.shutdown(wait=True, cancel_futures=True)
        self._start_pool()

    def _dask(self, items: list, function: Callable, args: tuple):
        from dask.distributed import as_completed

        futures = {self.client.submit(function, self.item_to_remote(item), self.context_future,
                                      *args, pure=False): item
                   for item in items}
        try:
            for future in as_completed(list(futures)):
                yield futures[future], future.result()
        finally:
            self.client.cancel(list(futures))


def _quiet_broken_pool_thread() -> None:
    """Let the pool's manager thread find its workers gone without a traceback.

    Python 3.11's ``ProcessPoolExecutor`` marks every pending future failed when a
    worker dies, cancelled ones included, which raises ``InvalidStateError`` in
    that thread (printed as "Exception in thread ..."): an interrupted run stops
    its workers on purpose, so that error says nothing and is not printed.
    """
    import concurrent.futures
    import threading

    previous = threading.excepthook
    if getattr(previous, "_wbcgrade_quiet", False):
        return

    def hook(args) -> None:
        if isinstance(args.exc_value, concurrent.futures.InvalidStateError):
            return
        previous(args)

    hook._wbcgrade_quiet = True  # type: ignore[attr-defined]
    threading.excepthook = hook
