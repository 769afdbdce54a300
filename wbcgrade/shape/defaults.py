"""Default settings of shape completion, in one light module (no numpy, no core).

``wbcgrade.shape.complete`` uses these and re-exports them; the command line
reads them here so that ``wbcgrade --help`` imports neither the core nor numba.
"""

from __future__ import annotations

DEFAULT_RESOLUTION = 64
DEFAULT_LOSS = "kl_reverse"
"""Default loss of a projection (``shape project``, :func:`wbcgrade.shape.complete.project`)."""

DEFAULT_COMPLETION_LOSS = "kl_observed"
"""Default loss of a completion (``shape complete``): KL on the observed voxels only."""
DEFAULT_N_ITER = 60
DEFAULT_MAX_ITER = 15

LOSS_NAMES = ("kl_observed", "kl_reverse", "kl", "quadratic", "l1", "wasserstein")
"""Losses a projection accepts: ``kl_observed`` (:data:`wbcgrade.shape.complete.KL_OBSERVED`)
and names of the core's loss registry."""
