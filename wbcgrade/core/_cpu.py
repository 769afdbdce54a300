"""CPU settings that make kernel products fast and predictable.

Two facts measured on the target machines (docs/architecture.md, threads):

- Products whose operands or results are denormal run 10-100 times slower;
  with the CPU's flush-to-zero / denormals-are-zero flags set they do not.
  Values below 2.2e-308 carry no usable mass for us, so inside core
  computations the flags are set (and restored afterwards).
- OpenBLAS's own threads busy-wait and collapse when the machine is shared
  or the matrices are small (a 32^3 forward pass took 3x-15x longer). The core
  therefore runs BLAS single-threaded and spreads independent histograms over
  its own small thread pool (numpy releases the GIL inside products).
- numpy asks the kernel for transparent huge pages for its large arrays; where
  the kernel compacts memory to find them on the first touch ("madvise"
  defrag), the core's many fresh temporaries stall: the 64^3 gradient spent
  3-4.5 s of system time (of ~15 s CPU), 1 s without. Inside core
  computations numpy's request is off (process-wide, with the BLAS limit); the
  numbers computed do not change.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import platform
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor

import threadpoolctl
from threadpoolctl import ThreadpoolController

__all__ = ["fast_cpu", "single_threaded_blas", "n_workers", "parallel_map"]

_FLUSH_FLAGS = 0x8040  # MXCSR: flush-to-zero (bit 15) | denormals-are-zero (bit 6)


class _FloatEnvironment(ctypes.Structure):
    """glibc's x86-64 ``fenv_t`` (32 bytes): the x87 environment, then the SSE MXCSR."""

    _fields_ = [("x87", ctypes.c_uint8 * 28), ("mxcsr", ctypes.c_uint32)]


def _glibc_libm() -> ctypes.CDLL | None:
    """glibc's maths library on x86-64, whose ``fegetenv``/``fesetenv`` read and write this
    thread's MXCSR (and leave the x87 state as they found it); None elsewhere (other
    architectures or C libraries, whose ``fenv_t`` differs: the flags keep their defaults)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return None
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return None
        libm = ctypes.CDLL("libm.so.6")
    except (AttributeError, ValueError, OSError):  # pragma: no cover - not glibc
        return None
    for function in (libm.fegetenv, libm.fesetenv):
        function.argtypes = [ctypes.POINTER(_FloatEnvironment)]
        function.restype = ctypes.c_int
    return libm


_LIBM = _glibc_libm()


def _get_flags() -> int:
    """This thread's MXCSR (x86-64 glibc; 0 elsewhere)."""
    if _LIBM is None:  # pragma: no cover - not x86-64 glibc
        return 0
    environment = _FloatEnvironment()
    _LIBM.fegetenv(ctypes.byref(environment))
    return environment.mxcsr


def _set_flags(value: int) -> None:
    """Set this thread's MXCSR (x86-64 glibc; nothing elsewhere)."""
    if _LIBM is None:  # pragma: no cover - not x86-64 glibc
        return
    environment = _FloatEnvironment()
    _LIBM.fegetenv(ctypes.byref(environment))
    environment.mxcsr = value
    _LIBM.fesetenv(ctypes.byref(environment))


_controller: ThreadpoolController | None = None
_pool: ThreadPoolExecutor | None = None
_lock = threading.Lock()

# Single-threaded BLAS is process-wide state (one OpenBLAS thread count for all
# threads). It is set by the first thread to enter ``fast_cpu`` and restored by
# the last one to leave: a per-call save/restore would, with overlapping calls
# from several threads, restore the caller's count while another thread is
# still inside (or leave BLAS at 1 thread for good).
_blas_lock = threading.Lock()
_blas_users = 0
_blas_limiter = None


def n_workers() -> int:
    """Threads the core uses for independent kernel products.

    All usable cores (at most 16), or ``$WBCGRADE_THREADS`` when set (e.g. by
    a process pool that runs several gradings side by side).
    """
    setting = os.environ.get("WBCGRADE_THREADS", "").strip()
    if setting.isdigit() and int(setting) > 0:
        return min(int(setting), 64)
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, 16))


def _flush_denormals_in_this_thread() -> None:
    _set_flags(int(_get_flags()) | _FLUSH_FLAGS)


def _get_pool() -> ThreadPoolExecutor:
    global _pool
    with _lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(
                n_workers(), "wbcgrade", initializer=_flush_denormals_in_this_thread
            )
        return _pool


def _take_blas_control() -> None:
    """Let this thread change OpenBLAS's thread count.

    threadpoolctl (3.8 and later) lets only the first thread that set an
    OpenBLAS limit change it again and silently ignores the others. Our
    reference count already serialises the process-wide setting, so whichever
    thread sets or restores it (under ``_blas_lock``) takes control first and
    gives it back afterwards.
    """
    controller = getattr(threadpoolctl, "OpenBLASController", None)
    clear = getattr(controller, "clear_controlling_thread", None)
    if clear is not None:
        clear(force=True)


def _huge_pages(enabled: bool) -> bool | None:
    """Set numpy's request for transparent huge pages (its large arrays' ``madvise``);
    -> the previous setting, None where this numpy has no such switch."""
    try:
        from numpy._core import multiarray
    except ImportError:  # pragma: no cover - numpy < 2
        from numpy.core import multiarray
    switch = getattr(multiarray, "_set_madvise_hugepage", None)
    return None if switch is None else bool(switch(enabled))


_huge_pages_before: bool | None = None


def _enter_single_threaded_blas() -> None:
    global _controller, _blas_users, _blas_limiter, _huge_pages_before
    with _blas_lock:
        if _blas_users == 0:
            if _controller is None:
                _controller = ThreadpoolController()
            _take_blas_control()
            _blas_limiter = _controller.limit(limits=1, user_api="blas")
            _huge_pages_before = _huge_pages(False)
        _blas_users += 1


def _leave_single_threaded_blas() -> None:
    global _blas_users, _blas_limiter, _huge_pages_before
    with _blas_lock:
        _blas_users -= 1
        if _blas_users == 0:
            if _huge_pages_before is not None:
                _huge_pages(_huge_pages_before)
                _huge_pages_before = None
            if _blas_limiter is not None:
                limiter, _blas_limiter = _blas_limiter, None
                _take_blas_control()
                limiter.restore_original_limits()
                _take_blas_control()  # leave it free for the caller's own limits


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Single-threaded BLAS and no huge pages for numpy's arrays (process-wide,
    reference-counted with :func:`fast_cpu`'s), restored when the last thread inside
    leaves; the CPU flags untouched. For callers that
    spread independent products over their own threads: OpenBLAS's threads busy-wait
    between products (scene matching on a shared 2-core machine: 0.78 s of CPU on two
    threads against 0.40 s on one)."""
    _enter_single_threaded_blas()
    try:
        yield
    finally:
        _leave_single_threaded_blas()


@contextlib.contextmanager
def fast_cpu() -> Iterator[None]:
    """Single-threaded BLAS, no huge pages for numpy's arrays and flushed denormals in
    this thread, restored on exit.

    Safe from several threads at once: the BLAS limit (process-wide) is set
    when the first thread enters and restored when the last one leaves
    (reference-counted under a lock); the flush-to-zero flags (MXCSR) belong
    to each thread and are saved and restored per call. See
    docs/architecture.md (threads).
    """
    _enter_single_threaded_blas()
    try:
        old = int(_get_flags())
        _set_flags(old | _FLUSH_FLAGS)
        try:
            yield
        finally:
            _set_flags(old)
    finally:
        _leave_single_threaded_blas()


def parallel_map(function: Callable[[int, int], None], n_items: int) -> None:
    """Call ``function(start, stop)`` on contiguous slices of ``range(n_items)`` in parallel."""
    workers = min(n_workers(), n_items)
    # Inside a pool worker (nested parallelism) the slices run in this thread:
    # waiting on the same pool from one of its threads could deadlock.
    if workers <= 1 or threading.current_thread().name.startswith("wbcgrade"):
        function(0, n_items)
        return
    bounds = [round(i * n_items / workers) for i in range(workers + 1)]
    futures = [
        _get_pool().submit(function, lo, hi) for lo, hi in zip(bounds[:-1], bounds[1:]) if hi > lo
    ]
    for future in futures:
        future.result()
