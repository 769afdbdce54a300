"""Default settings of shape completion, in one light module (no numpy, no core).

The shape modules (``projection``, ``complete``, ``workflow``) use these; the command line
reads them here so that ``wbcgrade --help`` imports neither the core nor numba.
"""

from __future__ import annotations

DEFAULT_RESOLUTION = 64
DEFAULT_LOSS = "kl_reverse"
DEFAULT_N_ITER = 60
DEFAULT_MAX_ITER = 15

LOSS_NAMES = ("kl_reverse", "kl", "quadratic", "l1", "wasserstein")
"""Losses a projection accepts (names of the core's loss registry);
``kl_reverse`` is the default for shapes. A completion compares the input's
voxels only by default (``observed_only``), which the first four allow."""
