"""Choosing the domain (``method=``), error traces, and warnings when a solve stops early."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from wbcgrade.core import BarycenterSolver, GridGeometry, barycenter, sinkhorn
from wbcgrade.errors import ConvergenceWarning, NumericalError


def _far_apart(n: int = 40):
    """Two narrow, far-apart bumps: plain scalings underflow with a narrow kernel."""
    x = np.arange(n)
    H = np.stack([np.exp(-((x - 4) ** 2) / 3.0), np.exp(-((x - n + 5) ** 2) / 3.0)])
    H[H < 1e-12] = 0.0
    return H, GridGeometry.with_width(n, 0.6)


def test_sinkhorn_method_picks_the_domain_and_scaling_only_refuses_what_it_cannot_do():
    H, geom = _far_apart()
    auto = sinkhorn(H[0], H[1], geom, tol=1e-9, max_iter=20_000)
    assert auto.method == "log" and auto.converged
    log = sinkhorn(H[0], H[1], geom, tol=1e-9, max_iter=20_000, method="log")
    np.testing.assert_array_equal(log.log_b, auto.log_b)
    with pytest.raises(NumericalError, match="method='log'"):
        sinkhorn(H[0], H[1], geom, method="scaling")
    smooth = sinkhorn(H[0] + 0.1, H[1] + 0.1, GridGeometry.with_width(40, 3.0), tol=1e-9,
                      method="scaling")
    assert smooth.method == "scaling" and smooth.converged
    with pytest.raises(ValueError, match="method must be"):
        sinkhorn(H[0], H[1], geom, method="fast")


def test_sinkhorn_traces_its_error_and_warns_when_it_stops_above_tol():
    H, _ = _far_apart()
    geom = GridGeometry.with_width(40, 3.0)
    p, q = H[0] + 0.01, H[1] + 0.01
    done = sinkhorn(p, q, geom, tol=1e-10, max_iter=5000, check_every=1)
    assert done.errors[-1] == done.error and len(done.errors) >= 2
    assert done.errors[-1] < done.errors[0]
    with pytest.warns(ConvergenceWarning, match="sinkhorn stopped after 3 iterations"):
        early = sinkhorn(p, q, geom, tol=1e-12, max_iter=3, check_every=1)
    assert not early.converged
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sinkhorn(p, q, geom, tol=1e-12, max_iter=3, warn=False)


def test_barycenter_method_picks_the_domain():
    H, geom = _far_apart()
    auto_solver = BarycenterSolver(H, geom, 30)
    P = auto_solver.barycenter([0.5, 0.5])
    assert auto_solver.last_backend == "log"
    np.testing.assert_allclose(barycenter(H, [0.5, 0.5], geom, 30, method="log"), P,
                               rtol=1e-12, atol=1e-300)
    with pytest.raises(NumericalError, match="method='log'"):
        barycenter(H, [0.5, 0.5], geom, 30, method="scaling")
    with pytest.raises(ValueError, match="method must be"):
        BarycenterSolver(H, geom, 30, method="exact")


def test_barycenter_solve_traces_changes_and_warns_when_unconverged():
    H, _ = _far_apart()
    geom = GridGeometry.with_width(40, 3.0)
    solver = BarycenterSolver(H + 0.01, geom, 30)
    done = solver.solve([0.3, 0.7], tol=1e-9, max_iter=5000)
    assert done.converged and done.changes[-1] == done.change
    assert len(done.changes) == done.n_iter - 1
    with pytest.warns(ConvergenceWarning, match="after 3 iterations"):
        early = solver.solve([0.3, 0.7], tol=1e-12, max_iter=3)
    assert not early.converged
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solver.solve([0.3, 0.7], tol=1e-12, max_iter=3, warn=False)
