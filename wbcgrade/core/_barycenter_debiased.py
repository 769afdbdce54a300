"""Debiased entropic barycenters: a barycenter without the kernel's blur.

The entropic barycenter (:func:`wbcgrade.core.barycenter`) is blurred by about one
kernel width: the barycenter of a single histogram is that histogram
convolved with the Gibbs kernel, so parts a few bins thin (a cow's legs at
64^3 voxels) sink below any iso-level that keeps the body's size. The debiased barycenter
(Janati, Cuturi, Gramfort, "Debiased Sinkhorn barycenters", ICML 2020) adds
one scaling ``d`` to the iterations of the core's barycenter
(docs/architecture.md, wbcgrade.core.barycenter):

    phi_s = K^T ( p_s / (K b_s) )
    P     = d * prod_s phi_s ** w_s
    b_s   = P / phi_s
    d     = sqrt( d * P / (K d) )

and is a fixed point at ``P = p`` for a single histogram ``p``. It has no
gradient here: weights are fitted with the ordinary barycenter
(:func:`wbcgrade.core.barycentric_coordinates`) and the debiased one draws
the result without the blur (the shapes' fitted shape, docs/shapes.md).
"""

from __future__ import annotations

import logging

import numpy as np

from wbcgrade.core.geometry import Geometry

log = logging.getLogger(__name__)


def debiased_barycenter(
    histograms: np.ndarray, weights: np.ndarray, geometry: Geometry, n_iter: int = 60
) -> np.ndarray:
    """Debiased entropic barycenter after ``n_iter`` iterations.

    Parameters
    ----------
    histograms : (S, *geometry.shape) positive histograms, each summing to 1.
    weights : (S,) on the simplex.
    geometry : the grid and its kernel (the one the weights were fitted on).
    n_iter : iterations.

    Returns
    -------
    (*geometry.shape) float64 array summing to about 1. Weights below 1e-4
    of the largest are dropped (the rest renormalised). Computed with
    scalings, and in the log domain (``geometry.log_apply``, slower) when a
    scaling leaves the float64 range.
    """
    histograms = np.asarray(histograms, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    used = weights > 1e-4 * weights.max()  # a zero weight leaves P unchanged
    histograms, weights = histograms[used], weights[used] / weights[used].sum()
    with np.errstate(all="ignore"):
        result = _scaling(histograms, weights, geometry, n_iter)
    if np.all(np.isfinite(result)) and result.sum() > 0:
        return result
    log.info("debiased barycenter: scalings out of range, recomputing in the log domain")
    return _log_domain(histograms, weights, geometry, n_iter)


def _scaling(histograms, weights, geometry, n_iter):
    b = np.ones_like(histograms)
    d = np.ones(histograms.shape[1:])
    phi = np.empty_like(histograms)
    product = d
    for _ in range(n_iter):
        for s in range(len(histograms)):
            phi[s] = geometry.apply(histograms[s] / geometry.apply(b[s]))
        product = d * np.exp(np.tensordot(weights, np.log(phi), axes=1))
        b = product / phi
        d = np.sqrt(d * product / geometry.apply(d))
    return product


def _log_domain(histograms, weights, geometry, n_iter):
    log_p = np.log(histograms)
    log_b = np.zeros_like(histograms)
    log_d = np.zeros(histograms.shape[1:])
    log_phi = np.empty_like(histograms)
    log_product = log_d
    for _ in range(n_iter):
        for s in range(len(histograms)):
            log_phi[s] = geometry.log_apply(log_p[s] - geometry.log_apply(log_b[s]))
        log_product = log_d + np.tensordot(weights, log_phi, axes=1)
        log_b = log_product - log_phi
        log_d = 0.5 * (log_d + log_product - geometry.log_apply(log_d))
    return np.exp(log_product)
