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
from wbcgrade.errors import InputError, NumericalError


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


_TABLE_RESOLUTION = (180, 720)  # polar x azimuth cells of the neighbour lookup table
_neighbour_tables: dict[tuple[bytes, int], tuple[np.ndarray, np.ndarray]] = {}


def _neighbour_table(directions: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Nearest ``k`` samples and their weights on a fine (theta, phi) grid (cached).

    Weights are Gaussian in the geodesic distance (standard deviation half a
    sample spacing), normalised; looking a query up in the table is O(1) and
    stands in for a k-d tree query, within 0.25 degrees.
    """
    key = (directions.tobytes(), k)
    if key not in _neighbour_tables:
        n_theta, n_phi = _TABLE_RESOLUTION
        theta = (np.arange(n_theta) + 0.5) * (0.5 * np.pi / n_theta)
        phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
        t, p = np.meshgrid(theta, phi, indexing="ij")
        grid = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
        distance, index = cKDTree(directions).query(grid.reshape(-1, 3), k=k)
        distance = distance.reshape(-1, k)
        index = index.reshape(-1, k)
        sigma = 0.5 * sample_spacing(len(directions))
        weight = np.exp(-0.5 * (distance**2 - distance[:, :1] ** 2) / sigma**2)
        weight /= weight.sum(axis=1, keepdims=True)
        if len(_neighbour_tables) > 8:
            _neighbour_tables.clear()
        _neighbour_tables[key] = (index, weight)
    return _neighbour_tables[key]


def _lookup(table: tuple[np.ndarray, np.ndarray], query: np.ndarray):
    n_theta, n_phi = _TABLE_RESOLUTION
    z = np.clip(np.abs(query[:, 2]), 0.0, 1.0)  # below the horizon: mirrored above it
    theta = np.arccos(z)
    phi = np.mod(np.arctan2(query[:, 1], query[:, 0]), 2.0 * np.pi)
    i = np.clip((theta / (0.5 * np.pi) * n_theta).astype(np.int64), 0, n_theta - 1)
    j = np.clip((phi / (2.0 * np.pi) * n_phi).astype(np.int64), 0, n_phi - 1)
    cell = i * n_phi + j
    index, weight = table
    return weight[cell], index[cell]


def interpolate(
    values: np.ndarray,
    directions: np.ndarray,
    incoming: np.ndarray,
    outgoing: np.ndarray,
    neighbours: int = 3,
) -> np.ndarray:
    """Evaluate a sampled BRDF at arbitrary direction pairs.

    Each query direction is spread over its ``neighbours`` nearest samples with
    Gaussian weights (standard deviation half a sample spacing, normalised);
    the value is ``sum_a sum_b w_a(incoming) w_b(outgoing) values[a, b]``.
    Directions below the horizon are mirrored above it. Neighbours are looked
    up in a cached table on a 0.5-degree (theta, phi) grid.

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
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    incoming, outgoing = np.broadcast_arrays(np.asarray(incoming, dtype=np.float64),
                                             np.asarray(outgoing, dtype=np.float64))
    shape = incoming.shape[:-1]
    k = min(int(neighbours), len(directions))
    table = _neighbour_table(directions, k)
    w_in, i_in = _lookup(table, incoming.reshape(-1, 3))
    w_out, i_out = _lookup(table, outgoing.reshape(-1, 3))
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
    peak = float(np.max(np.abs(reference))) if reference.size else 0.0
    if not np.isfinite(peak) or not np.all(np.isfinite(estimate)):
        raise NumericalError("PSNR of BRDFs holding NaN or infinite values")
    if peak == 0.0:
        return float("inf") if not np.any(estimate) else float("-inf")
    # Relative to the peak, so that huge but finite values do not overflow the squares.
    mse = float(np.mean((reference / peak - estimate / peak) ** 2))
    if mse == 0.0:
        return float("inf")
    return float(-10.0 * np.log10(mse))


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
