"""The gradient's memory model bounds what a gradient really allocates (tracemalloc)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from tests.core.helpers import blobs
from wbcgrade.core import BarycenterSolver, GridGeometry


@pytest.mark.parametrize("slots", [1, 4, 1000])
@pytest.mark.parametrize("method", ["scaling", "log"])
def test_the_memory_model_bounds_a_gradient(method, slots, rng):
    geom = GridGeometry.with_width((12, 12, 12), 1.5)
    H = blobs(geom.shape, 6, rng, width=0.12, floor=1e-6, components=2)
    q = H.mean(axis=0)
    solver = BarycenterSolver(H, geom, 12, checkpoint_bytes=slots * H.nbytes, method=method)
    estimate = solver.memory_bytes()
    solver.value_and_grad(np.full(6, 1 / 6), q)  # compiled functions loaded before measuring
    tracemalloc.start()
    try:
        solver.value_and_grad(np.full(6, 1 / 6), q)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert solver.last_backend.startswith(method)
    assert peak <= estimate, (peak / H.nbytes, estimate / H.nbytes)
    assert peak >= 0.4 * estimate  # a bound, not a guess several times too large
