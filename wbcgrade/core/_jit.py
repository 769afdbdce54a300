"""``compiled``: numba's ``njit`` with an on-disk cache that can never fail a run,
and ``parallel=True`` functions that are safe to call from several threads.

numba's own ``cache=True`` raises when the cache cannot be written: a full
disk, a file-size limit (``ulimit -f``), a read-only or vanished cache folder.
A grade must not fail because a compiled function could not be *saved*, so
every compiled function of the package goes through this decorator: the cache
is used when it works, and a failed load or save only costs a compilation.

Threads. numba runs ``parallel=True`` functions on a *threading layer*:
``tbb`` or ``omp`` (GNU or Intel OpenMP) are thread-safe, ``workqueue`` (the
fallback, always present) is not: two threads inside parallel functions at
once abort the whole process ("Terminating: Nested parallel kernel launch
detected"). numba picks the first layer that loads, in the order of
``NUMBA_THREADING_LAYER`` / ``NUMBA_THREADING_LAYER_PRIORITY`` (by default
tbb, omp, workqueue; Linux with libgomp gets ``omp``, macOS without
``intel-openmp`` gets ``workqueue``). :func:`parallel_layer` predicts that
choice without launching anything; when it is ``workqueue``, ``compiled``
wraps every ``parallel=True`` function so that calls into them hold one
process-wide lock (they run one at a time, each still on all cores). The
package never changes numba's settings (they are the user's). A wrapped
function is an ordinary Python callable (attributes forward to the numba
dispatcher) and cannot be called from other compiled code; the package's
parallel functions are only called from Python. See docs/architecture.md
(threads).
"""

from __future__ import annotations

import functools
import importlib
import logging
import sys
import threading
from collections.abc import Callable
from typing import Any

import numba

__all__ = ["compiled", "parallel_layer", "in_bands", "numpy_first", "THREAD_SAFE_LAYERS"]

#: numba threading layers that accept parallel calls from several threads at once.
THREAD_SAFE_LAYERS = ("tbb", "omp")

#: Held while a parallel function runs, when the layer is not thread-safe.
_PARALLEL_LOCK = threading.Lock()

log = logging.getLogger(__name__)

try:  # numba's cache class; the decorator still works (uncached) without it
    from numba.core.caching import FunctionCache as _FunctionCache
except ImportError:  # pragma: no cover - other numba layouts
    _FunctionCache = None


if _FunctionCache is not None:

    class _BestEffortCache(_FunctionCache):
        """numba's function cache whose I/O errors are logged, not raised."""

        def load_overload(self, sig, target_context):
            try:
                return super().load_overload(sig, target_context)
            except (OSError, EOFError) as exc:
                log.debug("numba cache not read for %s: %s", self._name, exc)
                return None

        def save_overload(self, sig, data) -> None:
            try:
                super().save_overload(sig, data)
            except OSError as exc:
                log.debug("numba cache not written for %s: %s", self._name, exc)


def _layer_loads(name: str) -> bool:
    """Whether numba could load the threading layer ``name`` (as numba itself tries it)."""
    try:
        if name == "tbb":
            from numba.np.ufunc.parallel import _check_tbb_version_compatible

            _check_tbb_version_compatible()
            importlib.import_module("numba.np.ufunc.tbbpool")
        elif name == "omp":
            importlib.import_module("numba.np.ufunc.omppool")
        else:
            importlib.import_module("numba.np.ufunc.workqueue")
    except Exception:  # noqa: BLE001 - ImportError, an OSError of the loader, a bad TBB
        return False
    return True


@functools.lru_cache(maxsize=1)
def _predicted_layer() -> str:
    chosen = str(numba.config.THREADING_LAYER).lower()
    if chosen in ("tbb", "omp", "workqueue"):
        return chosen
    candidates = {
        "safe": ["tbb"],
        "threadsafe": ["tbb", "omp"],
        "forksafe": ["tbb", "workqueue"] if sys.platform.startswith("linux")  # not GNU omp
        else ["tbb", "omp", "workqueue"],
    }.get(chosen, list(numba.config.THREADING_LAYER_PRIORITY))
    for name in candidates:
        if _layer_loads(name):
            return name
    return "workqueue"  # numba would fail to launch; the lock costs nothing then


def parallel_layer() -> str:
    """The numba threading layer of ``parallel=True`` functions: 'tbb', 'omp' or 'workqueue'.

    The layer in use once a parallel function has run, numba's choice
    predicted from its settings and the libraries that load before that.
    """
    try:
        return numba.threading_layer()
    except ValueError:  # no parallel function has run yet
        return _predicted_layer()


class _Serialised:
    """A parallel numba function whose calls hold ``_PARALLEL_LOCK`` (workqueue layer)."""

    def __init__(self, dispatcher) -> None:
        self.dispatcher = dispatcher
        functools.update_wrapper(self, dispatcher.py_func)

    def __call__(self, *args, **kwargs):
        with _PARALLEL_LOCK:
            return self.dispatcher(*args, **kwargs)

    def __getattr__(self, name: str):
        return getattr(self.dispatcher, name)


def compiled(**options: Any) -> Callable[[Callable], Callable]:
    """Like ``numba.njit(cache=True, **options)``, but cache I/O errors never raise.

    With ``parallel=True`` on a threading layer that is not thread-safe
    (``workqueue``), calls are serialised by a process-wide lock (module
    docstring); on ``tbb`` and ``omp`` the numba dispatcher is returned as is.
    """
    options.pop("cache", None)

    def decorate(function: Callable) -> Callable:
        dispatcher = numba.njit(**options)(function)
        if _FunctionCache is not None:
            try:
                dispatcher._cache = _BestEffortCache(dispatcher.py_func)
            except (RuntimeError, OSError) as exc:  # no usable cache folder at all
                log.debug("numba cache off for %s: %s", function.__qualname__, exc)
        if options.get("parallel") and parallel_layer() not in THREAD_SAFE_LAYERS:
            return _Serialised(dispatcher)
        return dispatcher

    return decorate


def numpy_first(kernel: Callable, size: int, limit: int) -> bool:
    """Whether a numpy twin of compiled ``kernel`` (the same numbers, bit for bit) should
    do ``size`` items of work instead: the work is small (``size <= limit``) and the
    kernel has not run in this process yet. Its first call loads numba's compiler
    (about half a second, though the kernel is cached) or, after an install, compiles
    it (seconds): more than a small photo's whole grade. Once a kernel has run, it runs."""
    return size <= limit and not getattr(kernel, "overloads", None)


def in_bands(kernel: Callable, n: int, *args: Any, min_band: int = 8) -> None:
    """Run ``kernel(*args, lo, hi)`` over bands [lo, hi) covering range(n), in threads.

    For compiled ``nogil`` kernels that are serial (no ``parallel=True``): they
    compile several times faster than a ``prange`` loop (a first run after
    install pays the compilation), and the bands run at once on as many threads
    as numba would use (``numba.get_num_threads()``, the caller's setting). A
    band holds at least ``min_band`` items; one band runs on the calling thread.
    """
    bands = max(1, min(numba.get_num_threads(), n // max(1, min_band)))
    if bands == 1:
        kernel(*args, 0, n)
        return
    from concurrent.futures import ThreadPoolExecutor

    edges = [round(i * n / bands) for i in range(bands + 1)]
    with ThreadPoolExecutor(bands) as pool:
        for done in [pool.submit(kernel, *args, edges[i], edges[i + 1])
                     for i in range(bands)]:
            done.result()
