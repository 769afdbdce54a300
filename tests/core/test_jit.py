"""Compiled functions keep working when numba's on-disk cache cannot be written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

# Compiles a fresh function (and the package's trilinear remap) under a file-size
# limit of 0 bytes with an empty cache folder: every cache write fails with EFBIG.
_SCRIPT = """
import resource
resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))
import numpy as np
from wbcgrade.core._jit import compiled
from wbcgrade.color.mapping.remap import apply_color_map

@compiled(nogil=True)
def twice(x):
    return 2.0 * x

from wbcgrade.color.mapping.remap import identity_map
identity = identity_map(5, np.float64)
colors = np.random.default_rng(0).random((7, 3))
print(twice(21.0), float(np.abs(apply_color_map(colors, identity) - colors).max()) < 1e-6)
"""


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="RLIMIT_FSIZE is POSIX")
def test_a_cache_that_cannot_be_written_costs_a_compilation_not_the_run(tmp_path: Path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    run = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True,
                         env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["42.0", "True"]
