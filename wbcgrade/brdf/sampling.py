"""Directions on the upper hemisphere and the squared geodesic cost between them.

Sampling scheme
---------------
``hemisphere_directions(n)`` returns a *spherical Fibonacci* point set restricted
to the upper hemisphere (z > 0): point ``i`` (``i = 0 .. n-1``) has

    z_i   = 1 - (i + 1/2) / n          (cos of the polar angle, from the pole down)
    phi_i = i * golden_angle           (golden_angle = pi * (3 - sqrt 5))
    (x, y) = sqrt(1 - z_i^2) * (cos phi_i, sin phi_i)

Because the area of a spherical zone is proportional to its height in z, the
points are equal-area: each represents a solid angle of ``2 pi / n`` steradians,
and their spacing is about ``sqrt(2 pi / n)`` radians (0.148 rad = 8.5 deg for
the paper's n = 288). No point lies exactly on the horizon (the lowest has
``z = 1/(2n)``). The local frame is the usual one of BRDF work: z is the
surface normal, x the tangent (the direction anisotropic models align with).

Cost and kernel width
---------------------
``geodesic_cost`` is the squared great-circle distance ``arccos(<x_i, x_j>)^2``
(in radians^2, from 0 to at most pi^2). ``default_gamma(n)`` sets the entropic
regularisation so that the Gibbs kernel ``exp(-C / gamma)`` is a Gaussian of
standard deviation 1.5 sample spacings: ``gamma = 2 * (1.5 * sqrt(2 pi / n))^2``
(0.098 rad^2 at n = 288).
"""

from __future__ import annotations

import numpy as np

from wbcgrade.brdf.defaults import DEFAULT_DIRECTIONS, DEFAULT_WIDTH
from wbcgrade.core import DenseGeometry
from wbcgrade.errors import InputError

__all__ = ["DEFAULT_DIRECTIONS", "DEFAULT_WIDTH", "hemisphere_directions", "sample_spacing",
           "default_gamma", "geodesic_distance", "geodesic_cost", "hemisphere_geometry",
           "spread_subset", "same_sampling"]

_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def hemisphere_directions(n: int = DEFAULT_DIRECTIONS) -> np.ndarray:
    """Equal-area spherical Fibonacci directions on the upper hemisphere.

    Parameters
    ----------
    n : int
        Number of directions (>= 2).

    Returns
    -------
    directions : ndarray, shape (n, 3)
        Unit vectors with z > 0, from the pole towards the horizon.
    """
    n = int(n)
    if n < 2:
        raise InputError(f"a hemisphere sampling needs at least 2 directions, got {n}")
    index = np.arange(n, dtype=np.float64)
    z = 1.0 - (index + 0.5) / n
    radius = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = np.mod(index * _GOLDEN_ANGLE, 2.0 * np.pi)
    return np.stack([radius * np.cos(phi), radius * np.sin(phi), z], axis=-1)


def sample_spacing(n: int) -> float:
    """Typical distance in radians between neighbouring directions, ``sqrt(2 pi / n)``."""
    return float(np.sqrt(2.0 * np.pi / n))


def default_gamma(n: int, width: float = DEFAULT_WIDTH) -> float:
    """Entropic regularisation for ``n`` directions: ``2 * (width * sqrt(2 pi / n))^2``.

    The Gibbs kernel ``exp(-d^2 / gamma)`` is then a Gaussian whose standard
    deviation is ``width`` sample spacings.
    """
    if width <= 0:
        raise InputError(f"the kernel width must be positive, got {width}")
    return 2.0 * (width * sample_spacing(n)) ** 2


def geodesic_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Great-circle distance in radians between unit vectors.

    Parameters
    ----------
    a : ndarray, shape (M, 3)
    b : ndarray, shape (K, 3)

    Returns
    -------
    distance : ndarray, shape (M, K)
        ``arccos(<a_i, b_j>)``, computed with ``arctan2(|a x b|, a . b)`` for
        accuracy near 0 and pi.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    dot = a @ b.T
    cross = np.linalg.norm(np.cross(a[:, None, :], b[None, :, :]), axis=-1)
    return np.arctan2(cross, dot)


def geodesic_cost(directions: np.ndarray) -> np.ndarray:
    """Squared geodesic distances between directions, the transport cost.

    Parameters
    ----------
    directions : ndarray, shape (N, 3)
        Unit vectors.

    Returns
    -------
    cost : ndarray, shape (N, N)
        Symmetric, zero on the diagonal, in radians^2.
    """
    distance = geodesic_distance(directions, directions)
    cost = distance * distance
    cost = 0.5 * (cost + cost.T)
    np.fill_diagonal(cost, 0.0)
    return cost


def hemisphere_geometry(
    n: int = DEFAULT_DIRECTIONS, gamma: float | None = None, directions: np.ndarray | None = None
):
    """The core geometry of a hemisphere sampling.

    Parameters
    ----------
    n : int
        Number of directions (ignored when ``directions`` is given).
    gamma : float, optional
        Entropic regularisation in radians^2; ``default_gamma(n)`` when omitted.
    directions : ndarray, shape (N, 3), optional
        The sampling; ``hemisphere_directions(n)`` when omitted.

    Returns
    -------
    geometry : wbcgrade.core.DenseGeometry
        Cost = squared geodesic distances, ``points`` = the directions.
    """
    if directions is None:
        directions = hemisphere_directions(n)
    directions = np.asarray(directions, dtype=np.float64)
    if gamma is None:
        gamma = default_gamma(len(directions))
    return DenseGeometry(cost=geodesic_cost(directions), gamma=float(gamma), points=directions)


def spread_subset(directions: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` well-spread directions (greedy farthest-point sampling).

    Starts from the direction closest to the pole and repeatedly adds the
    direction farthest (in geodesic distance) from those already chosen; the
    result is deterministic and sorted.

    Parameters
    ----------
    directions : ndarray, shape (N, 3)
    count : int
        Clipped to ``[1, N]``.

    Returns
    -------
    indices : ndarray of int, shape (count,)
    """
    directions = np.asarray(directions, dtype=np.float64)
    n = len(directions)
    count = int(min(max(count, 1), n))
    if count == n:
        return np.arange(n)
    chosen = [int(np.argmax(directions[:, 2]))]
    nearest = geodesic_distance(directions, directions[chosen])[:, 0]
    for _ in range(count - 1):
        index = int(np.argmax(nearest))
        chosen.append(index)
        nearest = np.minimum(nearest, geodesic_distance(directions, directions[[index]])[:, 0])
    return np.sort(np.asarray(chosen))


def same_sampling(a: np.ndarray, b: np.ndarray, atol: float = 1e-9) -> bool:
    """Whether two direction arrays describe the same sampling (same order)."""
    a = np.asarray(a)
    b = np.asarray(b)
    return a.shape == b.shape and bool(np.allclose(a, b, atol=atol, rtol=0.0))
