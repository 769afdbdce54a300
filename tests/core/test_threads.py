"""The core from several threads at once: the same answers as one after another.

Covers the process-wide state the core touches (the BLAS thread count, set
once for all threads inside ``fast_cpu`` and restored by the last one out)
and numba's parallel functions (serialised by ``compiled`` on the
``workqueue`` threading layer, which would otherwise abort the process).
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import threading

import numba
import numpy as np
import pytest
from threadpoolctl import threadpool_info

from tests.conftest import THREAD_SETTINGS
from tests.core.helpers import blobs
from wbcgrade.color.mapping.remap import apply_color_map, identity_map
from wbcgrade.core import (
    GridGeometry,
    _cpu,
    barycenter,
    barycentric_coordinates,
    fast_cpu,
    multiscale_sinkhorn,
    sinkhorn,
)
from wbcgrade.core._jit import THREAD_SAFE_LAYERS, compiled, parallel_layer

N_THREADS = 4
#: The environment of a fresh interpreter whose BLAS and numba have a thread per core, as a
#: user's do (the test run's workers share the cores: tests/conftest.py).
ALL_CORES = {name: value for name, value in os.environ.items() if name not in THREAD_SETTINGS}


def _jobs():
    """Four small problems, one per entry point; each returns an array."""
    rng = np.random.default_rng(3)
    geometry = GridGeometry.with_width((8, 8, 8), 1.5)
    fine = GridGeometry.with_width((16, 16, 16), 3.0)  # solved on 8^3 first
    histograms = blobs((8, 8, 8), 3, rng, components=2)
    truth = np.array([0.6, 0.3, 0.1])
    target = barycenter(histograms, truth, geometry, n_iter=20)
    table = identity_map(9, np.float32) ** 1.3
    colors = rng.random((50_000, 3)).astype(np.float32)
    pair = blobs((16, 16, 16), 2, rng, components=2)
    return {
        "barycenter": lambda: barycenter(histograms, [0.2, 0.5, 0.3], geometry, n_iter=20),
        "coordinates": lambda: barycentric_coordinates(
            target, histograms, geometry, n_iter=20, max_iter=8).weights,
        "sinkhorn": lambda: sinkhorn(histograms[0], histograms[1], geometry, tol=1e-8).log_b,
        "multiscale": lambda: multiscale_sinkhorn(pair[0], pair[1], fine, coarsest=8,
                                                  tol=1e-8).log_b,
        "remap": lambda: apply_color_map(colors, table),
    }


def _blas_threads():
    return [(lib["internal_api"], lib["num_threads"]) for lib in threadpool_info()
            if lib["user_api"] == "blas"]


def test_four_threads_get_the_sequential_answers():
    jobs = _jobs()
    expected = {name: job() for name, job in jobs.items()}
    blas_before = _blas_threads()
    results: dict[tuple[int, str], np.ndarray] = {}
    errors: list[BaseException] = []
    barrier = threading.Barrier(N_THREADS)

    def run(index: int) -> None:
        barrier.wait()
        try:
            names = list(jobs)
            for name in names[index:] + names[:index]:  # each thread in its own order
                for _ in range(2):
                    results[index, name] = jobs[name]()
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(N_THREADS)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors
    for (index, name), value in results.items():
        np.testing.assert_allclose(value, expected[name], rtol=1e-10, atol=1e-12,
                                   err_msg=f"thread {index}, {name}")
    assert len(results) == N_THREADS * len(jobs)
    assert _blas_threads() == blas_before  # restored once the last thread left


# Four threads in and out of fast_cpu, overlapping (the sleep lets the others enter and
# leave meanwhile). A per-call save/restore of the BLAS limit fails this: the first thread
# out restores the old count while others are still inside, and the last one leaves BLAS
# at 1 thread for good. Run in a fresh interpreter: once the core has run in the main
# thread, OpenBLAS thread counts set from other threads were seen not to read back.
_OVERLAP = """
import threading, time
import numpy as np
import scipy.linalg
from threadpoolctl import threadpool_info
from wbcgrade.core._cpu import fast_cpu

def blas():
    return tuple(lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas")

before = blas()
inside = set()
def run():
    for _ in range(40):
        with fast_cpu():
            time.sleep(0.0005)
            inside.add(blas())
threads = [threading.Thread(target=run) for _ in range(4)]
for t in threads: t.start()
for t in threads: t.join()
print(sorted(inside) == [(1,) * len(before)], blas() == before)
"""


@pytest.mark.slow
def test_overlapping_fast_cpu_calls_keep_blas_single_threaded_and_restore_it():
    run = subprocess.run([sys.executable, "-c", _OVERLAP], capture_output=True, text=True,
                         env=ALL_CORES, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["True", "True"]


# The same, in one fixed order: thread A enters (and sets the limit), thread B enters,
# A leaves, then B leaves and must restore the count that A saved. threadpoolctl 3.8
# ignores limits set by any thread but the first one that set them, which left BLAS
# single-threaded for good here (B's restore, made while A is alive, was ignored).
_HANDOVER = """
import threading
import numpy as np
import scipy.linalg
from threadpoolctl import threadpool_info
from wbcgrade.core._cpu import fast_cpu

def blas():
    return tuple(lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas")

before = blas()
a_in, b_in, a_out, b_out = (threading.Event() for _ in range(4))
seen = []
def a():
    with fast_cpu():
        a_in.set()
        b_in.wait()
    a_out.set()
    b_out.wait()  # A stays alive while B restores
def b():
    a_in.wait()
    with fast_cpu():
        b_in.set()
        a_out.wait()
        seen.append(blas())
    seen.append(blas())
    b_out.set()
threads = [threading.Thread(target=a), threading.Thread(target=b)]
for t in threads: t.start()
for t in threads: t.join()
print(seen[0] == (1,) * len(before), seen[1] == before, max(before) > 1)
"""


@pytest.mark.slow
def test_the_last_thread_out_restores_the_count_the_first_one_saved():
    run = subprocess.run([sys.executable, "-c", _HANDOVER], capture_output=True, text=True,
                         env=ALL_CORES, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    inside_single, restored, multi = run.stdout.split()
    assert inside_single == "True"
    if multi == "True":  # with one core there is nothing to restore
        assert restored == "True"


def test_a_parallel_function_keeps_the_dispatcher_on_a_thread_safe_layer():
    @compiled(parallel=True)
    def total(x):  # pragma: no cover - compiled
        s = 0.0
        for i in numba.prange(x.shape[0]):
            s += x[i]
        return s

    assert total(np.ones(10)) == 10.0
    layer = parallel_layer()
    assert layer in ("tbb", "omp", "workqueue")
    assert hasattr(total, "py_func")  # a numba dispatcher, or the lock wrapper forwarding
    assert (type(total).__name__ == "_Serialised") == (layer not in THREAD_SAFE_LAYERS)


# Four threads in the package's parallel remap at once on numba's workqueue layer:
# it aborts the process ("Concurrent access has been detected") unless calls are serialised.
_WORKQUEUE = """
import threading
import numpy as np
import numba
from wbcgrade.color.mapping.remap import apply_color_map, identity_map
table = identity_map(9, np.float32) ** 1.3
colors = np.random.default_rng(0).random((500_000, 3)).astype(np.float32)  # the kernel, not numpy
expected = apply_color_map(colors, table)
same = []
def run():
    for _ in range(10):
        same.append(bool(np.array_equal(apply_color_map(colors, table), expected)))
threads = [threading.Thread(target=run) for _ in range(4)]
for t in threads: t.start()
for t in threads: t.join()
print(numba.threading_layer(), len(same), all(same))
"""


@pytest.mark.slow
def test_workqueue_layer_is_serialised_not_aborted():
    env = {**ALL_CORES, "NUMBA_THREADING_LAYER": "workqueue"}
    run = subprocess.run([sys.executable, "-c", _WORKQUEUE], capture_output=True, text=True,
                         env=env, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["workqueue", "40", "True"]


# The CPU's flush-to-zero / denormals-are-zero flags, per thread: set inside fast_cpu and
# restored after, not seen by a thread already running meanwhile, set for good in the core's
# pool threads; and set without loading numba (it cost ~0.6 s per process when it did).
_FLAGS = """
import sys, threading
import numpy as np
from wbcgrade.core import fast_cpu
from wbcgrade.core._cpu import parallel_map

def flushed():  # a denormal result (1e-310), and a product of a denormal operand
    return bool((np.array([1e-300]) * 1e-10)[0] == 0), bool((np.array([5e-310]) * 2)[0] == 0)

entered, checked, other = threading.Event(), threading.Event(), []
def bystander():
    entered.wait()
    other.append(flushed())
    checked.set()
thread = threading.Thread(target=bystander)
thread.start()
outside = flushed()
with fast_cpu():
    entered.set()
    inside = flushed()
    checked.wait()
after = flushed()
thread.join()
pool = []
parallel_map(lambda lo, hi: pool.append(flushed()), 2)
print(outside == after == other[0] == (False, False), inside == (True, True),
      pool == [(True, True)] * 2, "numba" not in sys.modules)
"""


def test_fast_cpu_flushes_denormals_in_its_own_thread_without_loading_numba():
    env = {**os.environ, "WBCGRADE_THREADS": "2"}
    run = subprocess.run([sys.executable, "-c", _FLAGS], capture_output=True, text=True,
                         env=env, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["True", "True", "True", "True"]


def test_the_flags_are_read_from_glibcs_floating_point_environment():
    """x86-64 glibc's ``fenv_t`` is 32 bytes with MXCSR last; its default masks every
    exception (bits 7-12) and leaves the flags off."""
    assert ctypes.sizeof(_cpu._FloatEnvironment) == 32
    if _cpu._LIBM is None:
        pytest.skip("not x86-64 glibc: the flags are left as they are")
    flags = _cpu._get_flags()
    assert flags & 0x1F80 == 0x1F80
    with fast_cpu():
        assert _cpu._get_flags() == flags | 0x8040
    assert _cpu._get_flags() == flags


_SINGLE_BLAS = """
import sys
import numpy as np
import scipy.linalg
from threadpoolctl import threadpool_info
from wbcgrade.core import single_threaded_blas

def blas():
    return tuple(lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas")

before = blas()
with single_threaded_blas():
    inside = blas()
print(inside == (1,) * len(before), blas() == before, max(before) > 1,
      "numba" not in sys.modules)
"""


@pytest.mark.slow
def test_single_threaded_blas_restores_the_count_and_leaves_numba_unloaded():
    """What scene matching runs its products under: BLAS on one thread inside, the count
    restored after, and no compiled code loaded for it."""
    run = subprocess.run([sys.executable, "-c", _SINGLE_BLAS], capture_output=True, text=True,
                         env=ALL_CORES, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["True", "True", "True", "True"]


def test_core_computations_ask_numpy_for_no_huge_pages_and_give_the_setting_back():
    """Inside fast_cpu / single_threaded_blas (nested, from two threads) numpy's request
    for transparent huge pages is off; the caller's setting, on or off, comes back when the
    last one leaves."""
    from numpy._core import multiarray

    from wbcgrade.core._cpu import fast_cpu, single_threaded_blas

    switch = multiarray._set_madvise_hugepage

    def current() -> bool:
        value = switch(True)
        switch(value)
        return bool(value)

    original = current()
    try:
        for setting in (True, False):
            switch(setting)
            seen = []
            inside = threading.Event()
            leave = threading.Event()

            def worker(inside, leave, seen):
                with single_threaded_blas():
                    inside.set()
                    leave.wait(10)
                    seen.append(current())

            thread = threading.Thread(target=worker, args=(inside, leave, seen))
            thread.start()
            inside.wait(10)
            with fast_cpu():
                seen.append(current())
                with fast_cpu():
                    seen.append(current())
            seen.append(current())  # the worker is still inside
            leave.set()
            thread.join(10)
            assert seen == [False, False, False, False]
            assert current() is setting
    finally:
        switch(original)
