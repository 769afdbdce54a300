"""Fused element-wise passes of the barycenter iterations (numba, GIL released).

Each pass reads its arrays once instead of the several numpy passes (and
temporaries) the same arithmetic takes, and counts the range facts the
scaling domain needs to know it is still exact. Loops are written without
branches so that they vectorise; the math flags allow re-association (for
sums) but keep inf and NaN meaningful, since the checks rely on them.
2-D arrays are ``(S, M)`` (histograms by bins); passes that take ``lo, hi``
work on bins ``lo:hi`` so that threads can share one call's work.
"""

from __future__ import annotations

import numpy as np

from wbcgrade.core._jit import compiled

_OPTS = {"nogil": True, "cache": True, "error_model": "numpy",
         "fastmath": {"reassoc", "contract", "nsz"}}


@compiled(**_OPTS)
def ratio(h, kb, out, high):  # pragma: no cover - compiled
    """``out = h / kb`` (0 where ``kb`` vanished); returns how many bins lost mass.

    A bin "loses mass" when ``h > 0`` but the ratio is 0, above ``high``,
    inf or NaN: the scaling domain cannot represent it.
    """
    bad = 0
    for i in range(h.size):
        x = h[i]
        k = kb[i]
        v = x / k
        v = v if k > 0.0 else 0.0
        out[i] = v
        bad += (x > 0.0) & (not ((v > 0.0) & (v <= high)))
    return bad


@compiled(**_OPTS)
def weighted_log_sum(log_phi, weights, out, lo, hi, log_low, log_high):  # pragma: no cover
    """``out[i] = sum_s w_s log_phi[s, i]`` for i in lo:hi (zero weights skipped).

    Returns (entries that are -inf, finite entries outside [log_low, log_high]).
    """
    vanished = 0
    outside = 0
    dest = out[lo:hi]
    for i in range(dest.size):
        dest[i] = 0.0
    for s in range(log_phi.shape[0]):
        w = weights[s]
        row = log_phi[s, lo:hi]
        for i in range(row.size):  # range checks
            v = row[i]
            vanished += v == -np.inf
            outside += (v > -np.inf) & ((v < log_low) | (v > log_high))
        if w != 0.0:
            for i in range(row.size):
                dest[i] += w * row[i]
    return vanished, outside


@compiled(**_OPTS)
def divide_rows(P, phi, out, lo, hi, limit):  # pragma: no cover - compiled
    """``out[s, i] = P[i] / phi[s, i]`` (0 where phi vanished), i in lo:hi; returns #overflows.

    ``P`` has the dtype of ``phi`` and ``out``.
    """
    bad = 0
    num = P[lo:hi]
    for s in range(phi.shape[0]):
        row = phi[s, lo:hi]
        dest = out[s, lo:hi]
        for i in range(row.size):
            f = row[i]
            v = num[i] / f
            v = v if f > 0.0 else 0.0 * f
            bad += not (v < limit)
            dest[i] = v
    return bad


@compiled(**_OPTS)
def reverse_in(weight, g, r, phi, out):  # pragma: no cover - compiled
    """``out = (weight g - r) / phi`` (0 where phi vanished); ``r`` may be empty (= 0)."""
    if r.size > 0:
        for i in range(phi.size):
            f = phi[i]
            v = (weight * g[i] - r[i]) / f
            out[i] = v if f > 0.0 else 0.0
    else:
        for i in range(phi.size):
            f = phi[i]
            v = (weight * g[i]) / f
            out[i] = v if f > 0.0 else 0.0


@compiled(**_OPTS)
def reverse_mid(y, h, kb):  # pragma: no cover - compiled
    """``y *= a / kb`` with ``a = h / kb`` (never ``h / kb**2``, which leaves the range)."""
    for i in range(y.size):
        k = kb[i]
        v = (y[i] * (h[i] / k)) / k
        y[i] = v if k > 0.0 else 0.0


@compiled(**_OPTS)
def reverse_out(v, b, out):  # pragma: no cover - compiled
    """``out = -(v * b)`` in float64; returns the number of non-finite results."""
    bad = 0
    for i in range(v.size):
        x = -(np.float64(v[i]) * np.float64(b[i]))
        out[i] = x
        bad += not (np.abs(x) < np.inf)
    return bad


@compiled(**_OPTS)
def dot_log(log_phi, g):  # pragma: no cover - compiled
    """``sum_i log_phi[i] g[i]`` over bins where g != 0; returns (value, bins with -inf there)."""
    acc = 0.0
    bad = 0
    for i in range(g.size):
        x = g[i]
        v = np.float64(log_phi[i])
        used = x != 0.0
        finite = v > -np.inf
        acc += v * x if used & finite else 0.0
        bad += used & (not finite)
    return acc, bad


@compiled(**_OPTS)
def l1_residual(a, kb, target):  # pragma: no cover - compiled
    """``sum_i |a_i kb_i - target_i|``: a Sinkhorn marginal's L1 error, in one pass."""
    acc = 0.0
    for i in range(a.size):
        acc += np.abs(np.float64(a[i]) * np.float64(kb[i]) - np.float64(target[i]))
    return acc


@compiled(**_OPTS)
def relaxed_ratio(h, kb, out, omega, power, high):  # pragma: no cover - compiled
    """``out = out^(1 - omega) (h / kb)^(omega power)``, over-relaxed Sinkhorn update.

    ``out`` holds the previous scaling; where it is 0 (first update) or
    ``omega == 1`` the plain ``(h / kb)^power`` is written. 0 where ``kb``
    vanished. Returns how many bins with ``h > 0`` got a scaling that is 0,
    above ``high``, inf or NaN.
    """
    bad = 0
    for i in range(h.size):
        x = h[i]
        k = kb[i]
        prev = out[i]
        v = x / k if k > 0.0 else 0.0
        if v > 0.0:
            if prev > 0.0 and omega != 1.0:
                v = np.exp((1.0 - omega) * np.log(prev) + omega * power * np.log(v))
            elif power != 1.0:
                v = v ** power
        out[i] = v
        bad += (x > 0.0) & (not ((v > 0.0) & (v <= high)))
    return bad
