"""wbcgrade.cli._process: a short command's freed memory reused, not taken fresh from the
kernel; no huge pages; one BLAS thread."""

import os
import subprocess
import sys

import pytest

_GLIBC = sys.platform.startswith("linux") and bool(os.confstr("CS_GNU_LIBC_VERSION"))

#: Page faults of a 64 MB array allocated, touched, freed, then allocated and touched again.
_AGAIN = """
import resource, sys
import numpy as np
from wbcgrade.cli._process import keep_freed_memory
if sys.argv[1] == "keep":
    assert keep_freed_memory()
block = np.ones(64 << 20, np.uint8)
del block
faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
block = np.ones(64 << 20, np.uint8)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults)
"""


def _faults_again(mode: str) -> int:
    done = subprocess.run([sys.executable, "-c", _AGAIN, mode], capture_output=True,
                          text=True, check=True)
    return int(done.stdout.split()[-1])


@pytest.mark.skipif(not _GLIBC, reason="glibc's malloc only")
def test_a_freed_block_is_reused_without_fresh_pages():
    # glibc's default: a 64 MB block has pages of its own, fresh each time (32 faults of
    # 2 MB huge pages at the least); kept: the freed block's pages, touched already
    assert _faults_again("default") >= 16
    assert _faults_again("keep") < 16


#: OpenBLAS's threads in a process that calls single_blas_thread() (or not) first.
_BLAS = """
import os, sys
for name in ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.pop(name, None)
from wbcgrade.cli._process import single_blas_thread
if sys.argv[1] == "single":
    assert single_blas_thread()
import numpy as np
from threadpoolctl import threadpool_info
print(max(i["num_threads"] for i in threadpool_info() if i["internal_api"] == "openblas"))
"""


def _blas_threads(mode: str) -> int:
    done = subprocess.run([sys.executable, "-c", _BLAS, mode], capture_output=True, text=True,
                          check=True)
    return int(done.stdout.split()[-1])


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: one thread anyway")
def test_single_blas_thread_before_numpy_loads():
    assert _blas_threads("default") > 1
    assert _blas_threads("single") == 1


def test_single_blas_thread_leaves_a_users_setting(monkeypatch):
    from wbcgrade.cli._process import single_blas_thread

    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")  # (numpy is loaded here too)
    assert not single_blas_thread()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "3"


_THP = """
import ctypes, sys
from wbcgrade.cli._process import no_huge_pages
if sys.argv[1] == "small":
    assert no_huge_pages()
print(ctypes.CDLL(None).prctl(42, 0, 0, 0, 0))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux's prctl only")
def test_no_huge_pages_for_the_process():
    def disabled(mode: str) -> int:
        done = subprocess.run([sys.executable, "-c", _THP, mode], capture_output=True,
                              text=True, check=True)
        return int(done.stdout.split()[-1])

    assert disabled("default") == 0
    assert disabled("small") == 1


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux's prctl only")
def test_a_command_run_inside_another_process_leaves_its_settings(tmp_path, monkeypatch):
    """``wbcgrade apply`` run by click's runner in this process (a test, a notebook) sets
    neither the process's BLAS thread count nor its huge pages (nor malloc's settings,
    behind the same test); the command line (``argv[0]`` the script, or ``python -m
    wbcgrade``) is a command's own process."""
    import ctypes

    from tests.color.conftest import SAMPLES
    from tests.conftest import run_cli
    from wbcgrade.cli._process import command_process

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    result = run_cli("apply", SAMPLES / "chelsea.jpg", "--preset", "warm", "-o",
                     tmp_path / "graded.jpg")
    assert result.exit_code == 0, result.output
    assert "OPENBLAS_NUM_THREADS" not in os.environ
    assert ctypes.CDLL(None).prctl(42, 0, 0, 0, 0) == 0
    assert not command_process()
    for first in ("/usr/bin/wbcgrade", "/site-packages/wbcgrade/__main__.py", "wbcgrade"):
        monkeypatch.setattr(sys, "argv", [first, "apply"])
        assert command_process()
    monkeypatch.setattr(sys, "argv", ["/site-packages/pytest/__main__.py"])
    assert not command_process()
