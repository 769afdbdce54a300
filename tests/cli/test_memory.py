"""wbcgrade.cli._memory: a short command's freed memory reused, not taken fresh from the kernel."""

import os
import subprocess
import sys

import pytest

_GLIBC = sys.platform.startswith("linux") and bool(os.confstr("CS_GNU_LIBC_VERSION"))

#: Page faults of a 64 MB array allocated, touched, freed, then allocated and touched again.
_AGAIN = """
import resource, sys
import numpy as np
from wbcgrade.cli._memory import keep_freed_memory
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

