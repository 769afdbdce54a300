"""The refit from the best single style, run ahead beside the fit from uniform weights,
gives the sequential answer and progress calls, and stops when it is not needed."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

import wbcgrade.color.palette.fit as fitting
from wbcgrade.color.options import FitOptions


def _problem(kind: str):
    rng = np.random.default_rng(0)
    styles = rng.random((3, 6, 6, 6)) ** 8
    styles /= styles.sum(axis=(1, 2, 3), keepdims=True)
    if kind == "vertex":  # one L-BFGS step from uniform weights cannot beat style 1 alone
        photo, opts = styles[1] * 0.97 + styles[0] * 0.03, FitOptions(bins=6, max_iter=1,
                                                                       n_iter=10)
    else:  # a blend: the fit from uniform weights wins, the refit is not needed
        photo, opts = styles.mean(axis=0), FitOptions(bins=6, max_iter=5, n_iter=10)
    return photo, styles, opts


def _run(monkeypatch, photo, styles, opts, ahead: bool):
    monkeypatch.setattr(fitting, "_speculate", lambda *bins: ahead)
    calls = []
    summary = fitting.fit_weights(
        photo, styles, opts, lambda n, w, v: calls.append((n, w.copy(), v)))
    return summary, calls


@pytest.mark.parametrize("kind", ["vertex", "uniform"])
def test_fit_ahead_gives_the_sequential_answer(monkeypatch, kind):
    photo, styles, opts = _problem(kind)
    seq, seq_calls = _run(monkeypatch, photo, styles, opts, ahead=False)
    fast, fast_calls = _run(monkeypatch, photo, styles, opts, ahead=True)
    assert seq.start == fast.start
    assert (seq.start == "uniform") == (kind == "uniform")
    assert np.array_equal(seq.weights, fast.weights) and seq.loss == fast.loss
    assert np.array_equal(seq.vertex_losses, fast.vertex_losses) and seq.info == fast.info
    assert len(seq_calls) == len(fast_calls)
    for (n, w, v), (n2, w2, v2) in zip(seq_calls, fast_calls):
        assert n == n2 and np.array_equal(w, w2) and v == v2


def test_an_unneeded_refit_stops(monkeypatch):
    photo, styles, opts = _problem("uniform")
    summary, _ = _run(monkeypatch, photo, styles, opts, ahead=True)
    assert summary.start == "uniform"
    deadline = time.monotonic() + 10.0
    while any(t.name.startswith("refit-ahead") for t in threading.enumerate()):
        assert time.monotonic() < deadline, "the refit ran on"
        time.sleep(0.01)


def test_the_default_grid_fits_in_one_thread(monkeypatch):
    """On the default 16³ grid an evaluation is mostly Python: a refit in a second thread
    would share the interpreter lock and slow the fit, so none runs ahead there."""
    monkeypatch.setattr("wbcgrade.core.n_workers", lambda: 2)
    assert not fitting._speculate(FitOptions().bins)
    assert fitting._speculate(fitting.SPECULATE_BINS)
