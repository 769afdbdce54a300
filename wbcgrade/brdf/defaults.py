"""Default settings of the BRDF fit, in one light module (no numpy, no core).

``wbcgrade.brdf.fit`` and ``wbcgrade.brdf.sampling`` use these and re-export
them; the command line reads them here so that ``wbcgrade --help`` imports
neither the core nor numba. Meanings of ``width``, ``tol`` and ``max_iter``:
``docs/architecture.md`` (names).
"""

from __future__ import annotations

DEFAULT_DIRECTIONS = 288
"""Number of hemisphere directions used by default (the paper's N)."""

DEFAULT_WIDTH = 1.5
"""Default kernel width (Gaussian standard deviation) in sample spacings."""

DEFAULT_LOSS = "sinkhorn-divergence"
DEFAULT_N_ITER = 60
DEFAULT_MAX_ITER = 30
DEFAULT_TOL = 1e-6
DEFAULT_FIT_DIRECTIONS = 16

BRDF_LOSSES = ("sinkhorn-divergence", "wasserstein", "quadratic", "l1", "kl")
"""Losses ``fit_brdf`` and ``wbcgrade brdf fit --loss`` accept (the default first)."""
