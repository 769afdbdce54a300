"""BRDFs sampled on a hemisphere sampling, and the operations on them.

A *sampled BRDF* is an array ``values`` of shape ``(N, N, 3)``:
``values[a, b, c]`` is the BRDF (1/sr) of channel ``c`` for light arriving
from ``directions[a]`` and leaving towards ``directions[b]``, the same
``N`` hemisphere directions (see ``wbcgrade.brdf.sampling``) serving for
incoming and outgoing directions.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from wbcgrade.brdf.sampling import sample_spacing
from wbcgrade.errors import InputError


def check_values(values: np.ndarray, n: int | None = None, name: str = "BRDF") -> np.ndarray:
    """Validate a sampled BRDF: shape (N, N, 3), finite, non-negative; returns float64."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 3 or values.shape[0] != values.shape[1] or values.shape[2] != 3:
        raise InputError(f"{name}: a sampled BRDF has shape (N, N, 3), got {values.shape}")
    if n is not None and values.shape[0] != n:
        raise InputError(f"{name}: sampled on {values.shape[0]} directions, expected {n}")
    if not np.isfinite(values).all():
        raise InputError(f"{name}: holds NaN or infinite values")
    if (values < 0).any():
        raise InputError(f"{name}: holds negative values")
    return values


def interpolate(
    values: np.ndarray,
    directions: np.ndarray,
    incoming: np.ndarray,
    outgoing: np.ndarray,
    neighbours: int = 4,
) -> np.ndarray:
    """Evaluate a sampled BRDF at arbitrary direction pairs.

    Each query direction is spread over its ``neighbours`` nearest samples with
    Gaussian weights (standard deviation half a sample spacing, normalised);
    the value is ``sum_a sum_b w_a(incoming) w_b(outgoing) values[a, b]``.
    Directions below the horizon are mirrored above it.

    Parameters
    ----------
    values : ndarray, shape (N, N, 3)
    directions : ndarray, shape (N, 3)
    incoming, outgoing : ndarray, shape (..., 3)
        Unit vectors in the local frame.
    neighbours : int

    Returns
    -------
    result : ndarray, shape (..., 3)
    """
    values = np.asarray(values, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    incoming, outgoing = np.broadcast_arrays(np.asarray(incoming, dtype=np.float64),
                                             np.asarray(outgoing, dtype=np.float64))
    shape = incoming.shape[:-1]
    tree = cKDTree(directions)
    sigma = 0.5 * sample_spacing(len(directions))
    k = min(int(neighbours), len(directions))

    def weights(query: np.ndarray):
        query = query.reshape(-1, 3).copy()
        query[:, 2] = np.abs(query[:, 2])
        distance, index = tree.query(query, k=k)
        distance = distance.reshape(len(query), k)
        index = index.reshape(len(query), k)
        w = np.exp(-0.5 * (distance - distance[:, :1]) ** 2 / sigma**2)
        return w / w.sum(axis=1, keepdims=True), index

    w_in, i_in = weights(incoming)
    w_out, i_out = weights(outgoing)
    result = np.zeros((len(w_in), 3))
    for a in range(k):
        for b in range(k):
            result += (w_in[:, a] * w_out[:, b])[:, None] * values[i_in[:, a], i_out[:, b]]
    return result.reshape(*shape, 3)


def psnr(reference: np.ndarray, estimate: np.ndarray) -> float:
    """Peak signal-to-noise ratio in dB between two sampled BRDFs.

    ``10 log10(max(reference)^2 / mean((reference - estimate)^2))`` over all
    entries (incoming, outgoing, channel): the paper's "PSNR computed on BRDFs".
    """
    reference = np.asarray(reference, dtype=np.float64)
    estimate = np.asarray(estimate, dtype=np.float64)
    if reference.shape != estimate.shape:
        raise InputError(f"PSNR of arrays of shapes {reference.shape} and {estimate.shape}")
    mse = float(np.mean((reference - estimate) ** 2))
    peak = float(np.max(np.abs(reference)))
    if mse == 0.0:
        return float("inf")
    return 10.0 * np.log10(peak * peak / mse)


def decimation_mask(n_incoming: int, n_outgoing: int, keep: float, seed: int = 0) -> np.ndarray:
    """Which (incoming, outgoing) measurements a sparse acquisition keeps.

    Exactly ``round(keep * n_incoming * n_outgoing)`` pairs (at least one) are
    drawn without replacement with ``numpy.random.default_rng(seed)``; a kept
    pair keeps its three channels (one RGB measurement).

    Returns
    -------
    mask : ndarray of bool, shape (n_incoming, n_outgoing)
    """
    keep = float(keep)
    if not (0.0 < keep <= 1.0):
        raise InputError(f"--keep must be a fraction in (0, 1], got {keep}")
    total = n_incoming * n_outgoing
    count = max(1, int(round(keep * total)))
    mask = np.zeros(total, dtype=bool)
    mask[np.random.default_rng(seed).choice(total, size=count, replace=False)] = True
    return mask.reshape(n_incoming, n_outgoing)
