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


def blobs(shape, n, rng, width=0.12, floor=0.0):
    """n histograms, each a Gaussian blob at a random position on a grid of ``shape``."""
    axes = np.meshgrid(*[np.linspace(0, 1, k) for k in shape], indexing="ij")
    out = []
    for _ in range(n):
        centre = rng.uniform(0.2, 0.8, size=len(shape))
        d2 = sum((ax - c) ** 2 for ax, c in zip(axes, centre))
        h = np.exp(-d2 / (2 * width**2)) + floor
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
