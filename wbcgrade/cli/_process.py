"""Process settings of a command that grades one photo and exits (``apply``).

**Freed memory kept for reuse** (glibc's ``malloc``), not returned: glibc serves every
block over 32 MB (a 16-megapixel photo's float32 pixels: 190 MB, the regrain's window
means: 84 MB) from pages of its own, returned when it is freed: the next such block takes
fresh pages from the kernel, which zeroes each of them on its first touch. On the 2-core
development machine those zeroed pages were a sixth of a 16-megapixel grade's CPU
(0.4-1.2 s of system time, `perf`); kept in the heap, a freed block is reused as it is
(system time 0.3 s). A command that grades one photo and exits asks for that here; a
long-lived process (the explorer) keeps glibc's defaults, which give freed memory back.

**No transparent huge pages** (``PR_SET_THP_DISABLE``): numpy asks for huge pages for
its large arrays, and where the kernel compacts memory to find one on the first touch
(``defrag`` "madvise", as here) a fault stalls: 0.03 to 0.45 s for a 16-megapixel
photo's float32 pixels, by how the other processes left memory. With 4 KB pages: 0.07 s
every time; a 16-megapixel look grade's system time 0.53 -> 0.29 s, wall 1.72 -> 1.45 s
(medians of 6 alternated runs).

**BLAS on the calling thread**: numpy's OpenBLAS starts a thread per core and, once a
product has used them, they spin waiting for the next one (``blas_thread_server``: 3.5 %
of a 16-megapixel grade's CPU, on the cores the regrain's own threads want). The
grade's products are small or already spread over the command's own threads (the scene
matching's descriptors; the core runs BLAS single-threaded: ``core.single_threaded_blas``).

Only a process that is a ``wbcgrade`` command (:func:`command_process`) changes them: a
longer-lived process running a command inside it (a test's click runner, a notebook)
keeps its own. Light: the standard library only.
"""

from __future__ import annotations

import ctypes
import os
import sys
from pathlib import Path

__all__ = ["command_process", "keep_freed_memory", "no_huge_pages", "single_blas_thread"]


def command_process() -> bool:
    """Whether this process is a ``wbcgrade`` command, which ends with it: the script
    (``argv[0]`` named ``wbcgrade``) or ``python -m wbcgrade`` (its ``__main__.py``); not
    a process that runs commands inside it (a test's click runner, a notebook)."""
    first = Path(sys.argv[0]) if sys.argv and sys.argv[0] else None
    return first is not None and (first.stem == "wbcgrade" or (
        first.name == "__main__.py" and first.parent.name == "wbcgrade"))


#: ``mallopt`` parameters (glibc's malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_MAX = -4
#: The free memory at the heap's top glibc may keep (the most ``mallopt`` takes: 2 GiB).
_KEEP_BYTES = 2 ** 31 - 1

_KEPT: list[bool] = []


def keep_freed_memory() -> bool:
    """Ask glibc's ``malloc`` to serve large blocks from its heap too (no block of pages of
    its own) and to keep freed memory there (trimmed above 2 GiB only), for the rest of
    the process: a large array freed and allocated again reuses pages already touched.
    The numbers computed do not change. -> whether glibc took it (False elsewhere: another
    C library or system, where nothing is changed). Once per process."""
    if _KEPT:
        return _KEPT[0]
    kept = False
    if sys.platform.startswith("linux"):
        try:
            if os.confstr("CS_GNU_LIBC_VERSION"):
                mallopt = ctypes.CDLL(None).mallopt
                mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
                mallopt.restype = ctypes.c_int
                kept = bool(mallopt(_M_MMAP_MAX, 0)) \
                    and bool(mallopt(_M_TRIM_THRESHOLD, _KEEP_BYTES))
        except (AttributeError, OSError, ValueError):  # not glibc: its defaults stay
            kept = False
    _KEPT.append(kept)
    return kept


#: The settings OpenBLAS reads for its threads when it loads (with numpy).
_BLAS_THREAD_SETTINGS = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def single_blas_thread() -> bool:
    """One OpenBLAS thread for this process (``OPENBLAS_NUM_THREADS=1``, read when numpy
    loads), unless a setting of the user's says how many or numpy is loaded already
    (nothing then changes). The products' numbers do not change: OpenBLAS splits a
    product's rows and columns between threads, not its sums. -> whether it was set."""
    if "numpy" in sys.modules or any(os.environ.get(name) for name in _BLAS_THREAD_SETTINGS):
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    return True


#: ``prctl`` options (linux/prctl.h).
_PR_SET_THP_DISABLE = 41
_PR_GET_THP_DISABLE = 42


def no_huge_pages() -> bool:
    """No transparent huge pages for the rest of this process (Linux ``prctl``): memory
    comes in 4 KB pages whatever numpy asks for. The numbers computed do not change.
    -> whether the kernel took it (False elsewhere)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
        prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong,
                          ctypes.c_ulong]
        prctl.restype = ctypes.c_int
        return prctl(_PR_SET_THP_DISABLE, 1, 0, 0, 0) == 0
    except (AttributeError, OSError):
        return False
