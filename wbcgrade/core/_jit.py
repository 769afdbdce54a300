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
import os
import sys
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["compiled", "parallel_layer", "in_bands", "numpy_first", "prefer_compiled",
           "compiled_preferred", "num_threads", "THREAD_SAFE_LAYERS"]

#: numba threading layers that accept parallel calls from several threads at once.
THREAD_SAFE_LAYERS = ("tbb", "omp")

#: Held while a parallel function runs, when the layer is not thread-safe.
_PARALLEL_LOCK = threading.Lock()

log = logging.getLogger(__name__)


@functools.lru_cache(maxsize=1)
def _best_effort_cache():
    """numba's function cache class whose I/O errors are logged, not raised (None: numba
    has no such class; the functions then run uncached)."""
    try:
        from numba.core.caching import FunctionCache
    except ImportError:  # pragma: no cover - other numba layouts
        return None

    class _BestEffortCache(FunctionCache):
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

    return _BestEffortCache


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
    import numba

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
    import numba

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


class _Kernel:
    """A compiled function whose numba dispatcher is made when it is first needed.

    Importing the package's modules defines their compiled functions; importing
    numba (0.1-0.3 s) and making the dispatchers waits until one of them is called
    (or an attribute of the dispatcher is read), so that commands and grades that
    run none of them never load numba. Then every function defined so far gets its
    dispatcher at once (:func:`_make_all`) and the module names bound to them are
    rebound to the dispatchers, so compiled code calling compiled code sees numba's
    own objects. Calls and attributes forward to the dispatcher.
    """

    def __init__(self, function: Callable, options: dict) -> None:
        self.py_func = function
        self._options = options
        self._dispatcher = None
        functools.update_wrapper(self, function)

    def build(self):
        """The numba dispatcher (or :class:`_Serialised` wrapper) of this function."""
        if self._dispatcher is None:
            _make_all()
        return self._dispatcher

    def _make(self, numba) -> None:
        function = self.py_func
        names = function.__globals__
        if "numba" in function.__code__.co_names:  # numba.prange, without numba at import
            names.setdefault("numba", numba)
        self._dispatcher = _dispatcher(function, self._options)
        if names.get(function.__name__) is self:
            names[function.__name__] = self._dispatcher

    def _rebind_callees(self) -> None:
        """Names this function reads that are bound to compiled functions of other modules
        (``from ... import kernel``): bound to their dispatchers."""
        names = self.py_func.__globals__
        for name in self.py_func.__code__.co_names:
            value = names.get(name)
            if isinstance(value, _Kernel):
                names[name] = value.build()

    def __call__(self, *args: Any, **kwargs: Any):
        return self.build()(*args, **kwargs)

    def __getattr__(self, name: str):
        if name.startswith("__") or name in ("_dispatcher", "_options", "py_func"):
            raise AttributeError(name)
        return getattr(self.build(), name)


#: Compiled functions defined before numba was needed (see :class:`_Kernel`).
_PENDING: list[_Kernel] = []
_MAKING = threading.RLock()
_made = False


def _make_all() -> None:
    """Import numba and make the dispatchers of every compiled function defined so far."""
    global _made
    with _MAKING:
        import numba

        _made = True
        pending = list(_PENDING)
        for kernel in pending:
            if kernel._dispatcher is None:
                kernel._make(numba)
        for kernel in pending:
            kernel._rebind_callees()
        del _PENDING[:len(pending)]


def _dispatcher(function: Callable, options: dict):
    import numba

    dispatcher = numba.njit(**options)(function)
    cache = _best_effort_cache()
    if cache is not None:
        try:
            dispatcher._cache = cache(dispatcher.py_func)
        except (RuntimeError, OSError) as exc:  # no usable cache folder at all
            log.debug("numba cache off for %s: %s", function.__qualname__, exc)
    if options.get("parallel") and parallel_layer() not in THREAD_SAFE_LAYERS:
        return _Serialised(dispatcher)
    return dispatcher


def compiled(**options: Any) -> Callable[[Callable], Callable]:
    """Like ``numba.njit(cache=True, **options)``, but cache I/O errors never raise, and
    numba is imported when a compiled function is first used (:class:`_Kernel`), not
    when its module is.

    With ``parallel=True`` on a threading layer that is not thread-safe
    (``workqueue``), calls are serialised by a process-wide lock (module
    docstring); on ``tbb`` and ``omp`` the numba dispatcher is used as is.
    A function may read ``numba.prange`` without its module importing numba.
    """
    options.pop("cache", None)

    def decorate(function: Callable) -> Callable:
        kernel = _Kernel(function, options)
        with _MAKING:
            _PENDING.append(kernel)
            if _made or "numba" in sys.modules:  # numba is loaded: the dispatcher now
                _make_all()
                return kernel._dispatcher
        return kernel

    return decorate


def num_threads() -> int:
    """The threads numba's parallel code uses (``numba.get_num_threads()``); numba's
    default (``$NUMBA_NUM_THREADS``, else the usable cores) while numba is not loaded."""
    if "numba" in sys.modules:
        return sys.modules["numba"].get_num_threads()
    setting = os.environ.get("NUMBA_NUM_THREADS", "").strip()
    if setting.isdigit() and int(setting) > 0:
        return int(setting)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


#: Work each numpy twin has done in this process (see :func:`numpy_first`), by kernel.
_TWIN_WORK: dict[int, int] = {}
#: A twin takes work while its total stays under this many times its per-call limit.
_TWIN_BUDGET = 4


_prefer_compiled = False


def prefer_compiled() -> None:
    """From now on in this process, compiled kernels run even on small work (no numpy
    twins, :func:`numpy_first`): for a process about to grade many photos (a batch),
    which pays numba's start once and then runs the faster kernels."""
    global _prefer_compiled
    _prefer_compiled = True


def compiled_preferred() -> bool:
    """Whether :func:`prefer_compiled` was called in this process."""
    return _prefer_compiled


def numpy_first(kernel: Callable, size: int, limit: int) -> bool:
    """Whether a numpy twin of compiled ``kernel`` (the same numbers, bit for bit) should
    do ``size`` items of work instead: the work is small (``size <= limit``), the
    kernel has not run in this process yet, no other kernel has (numba's compiler is
    then loaded: this kernel's first call costs only its cache), and the twin's work so
    far stays under ``4 * limit``. A process's first kernel call loads numba's compiler
    (about half a second, though the kernel is cached) or, after an install, compiles it
    (seconds): more than a small photo's whole grade; a process that grades many small
    photos (a batch) pays that once and runs the faster kernel from then on."""
    if size > limit or _prefer_compiled or _made:
        return False
    if not (isinstance(kernel, _Kernel) and kernel._dispatcher is None) \
            and getattr(kernel, "overloads", None):
        return False  # the kernel has run: it is the faster one now
    done = _TWIN_WORK.get(id(kernel), 0) + size
    if done > _TWIN_BUDGET * limit:
        return False
    _TWIN_WORK[id(kernel)] = done
    return True


def in_bands(kernel: Callable, n: int, *args: Any, min_band: int = 8) -> None:
    """Run ``kernel(*args, lo, hi)`` over bands [lo, hi) covering range(n), in threads.

    For compiled ``nogil`` kernels that are serial (no ``parallel=True``): they
    compile several times faster than a ``prange`` loop (a first run after
    install pays the compilation), and the bands run at once on as many threads
    as numba would use (``numba.get_num_threads()``, the caller's setting). A
    band holds at least ``min_band`` items; one band runs on the calling thread.
    """
    bands = max(1, min(num_threads(), n // max(1, min_band)))
    if bands == 1:
        kernel(*args, 0, n)
        return
    from concurrent.futures import ThreadPoolExecutor

    edges = [round(i * n / bands) for i in range(bands + 1)]
    with ThreadPoolExecutor(bands) as pool:
        for done in [pool.submit(kernel, *args, edges[i], edges[i + 1])
                     for i in range(bands)]:
            done.result()
