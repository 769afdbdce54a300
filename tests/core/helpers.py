"""Independent reference implementations and synthetic data for the core tests."""

from __future__ import annotations

import numpy as np


def dense_barycenter(histograms, weights, cost, gamma, n_iter):
    """The forward iteration with an explicit N x N kernel (no truncation, no batching)."""
    K = np.exp(-cost / gamma)
    H = histograms.reshape(len(histograms), -1)
    H = H / H.sum(axis=1, keepdims=True)
    b = np.ones_like(H)
    for _ in range(n_iter):
        phi = np.stack([K.T @ (h / (K @ bs)) for h, bs in zip(H, b)])
        P = np.exp(np.einsum("s,sn->n", weights, np.log(phi)))
        b = P / phi
    return P


def blobs(shape, n, rng, width=0.12, floor=0.0, components=1):
    """n histograms on a grid of ``shape``, each a mixture of Gaussian blobs.

    With one component all histograms are translates of one another, and the
    barycenter only depends on the weighted mean of their centres; use
    ``components >= 2`` (random widths) when weights must be identifiable.
    """
    axes = np.meshgrid(*[np.linspace(0, 1, k) for k in shape], indexing="ij")
    out = []
    for _ in range(n):
        h = np.full(shape, float(floor))
        for _ in range(components):
            centre = rng.uniform(0.2, 0.8, size=len(shape))
            sd = width if components == 1 else width * rng.uniform(0.6, 1.4)
            d2 = sum((ax - c) ** 2 for ax, c in zip(axes, centre))
            h += rng.uniform(0.5, 1.0) * np.exp(-d2 / (2 * sd**2))
        out.append(h / h.sum())
    return np.stack(out)


def finite_difference(f, w, eps=1e-7):
    """Central differences of a scalar function along each coordinate of w."""
    grad = np.zeros_like(w)
    for s in range(len(w)):
        e = np.zeros_like(w)
        e[s] = eps
        grad[s] = (f(w + e) - f(w - e)) / (2 * eps)
    return grad
