"""The look-map family: the smooth global colour maps a look is made of.

:class:`LookMap` is what a colourist's look is made of:
each output channel is the input channel plus a sum of smooth 1-D curves of
R, G, B and luma (``T_o(x) = x_o + sum_c f_oc(x_c) + g_o(Y)``). It holds
per-channel tone curves, any 3x3 matrix (saturation, white balance), an
ASC CDL grade followed by saturation exactly, and split toning by lightness
closely; it cannot repaint one hue into an unrelated one, so a look fitted
to a few style photos stays a look.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbcgrade.color.histogram import add_floor, grid_points, soft_histogram
from wbcgrade.color.look.statistics import LUMA
from wbcgrade.color.look.statistics import hats as _hats
from wbcgrade.color.mapping.remap import interpolate_lattice
from wbcgrade.core import GridGeometry, barycentric_coordinates

__all__ = ["LookMap", "fit_look_map", "push_histogram", "relaxed_correspondences",
           "look_coordinates", "look_correspondences", "fit_geometry"]


#: Knots of each 1-D curve, evenly spaced on [0, 1].
DEFAULT_KNOTS = 9

#: Settings chosen on ``benchmarks/look.py``: plan kernel (bins of a 32^3 grid),
#: KL relaxation of both marginals, curve smoothness and pull towards the prior
#: (of a pair's look: :func:`fit_pair`).
DEFAULT_WIDTH = 1.0
DEFAULT_RELAXATION = 0.01
DEFAULT_SMOOTHNESS = 0.03
DEFAULT_RIDGE = 0.01


@dataclass(frozen=True)
class LookMap:
    """A smooth global colour map: identity plus curves of R, G, B and luma per channel.

    ``T_o(x) = x_o + sum_j coefficients[o, j] * features_j(x)`` with the
    features the hat functions of each of R, G, B and luma (``knots`` each).

    Attributes
    ----------
    coefficients : (3, 4 * knots) float64; all zero is the identity.
    knots : knots per curve.
    """

    coefficients: np.ndarray
    knots: int = DEFAULT_KNOTS

    @classmethod
    def identity(cls, knots: int = DEFAULT_KNOTS) -> LookMap:
        return cls(np.zeros((3, 4 * knots)), knots)

    @staticmethod
    def features(rgb: np.ndarray, knots: int = DEFAULT_KNOTS) -> np.ndarray:
        """(N, 3) colours in [0, 1] -> (N, 4 * knots) feature matrix."""
        rgb = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
        luma = rgb @ LUMA
        return np.concatenate([_hats(rgb[:, 0], knots), _hats(rgb[:, 1], knots),
                               _hats(rgb[:, 2], knots), _hats(luma, knots)], axis=1)

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """Map colours: (..., 3) in [0, 1] -> (..., 3) float64 in [0, 1]."""
        rgb = np.asarray(rgb, dtype=np.float64)
        flat = rgb.reshape(-1, 3)
        out = flat + self.features(flat, self.knots) @ self.coefficients.T
        return np.clip(out, 0.0, 1.0).reshape(rgb.shape)

    def lattice(self, size: int = 33) -> np.ndarray:
        """The map sampled as a (size, size, size, 3) float32 lattice LUT (R slowest)."""
        return self(grid_points(size)).reshape(size, size, size, 3).astype(np.float32)

    def amplitude(self, size: int = 17) -> float:
        """Mean displacement |T(x) - x| over the colour cube (0 for the identity)."""
        points = grid_points(size)
        return float(np.mean(np.linalg.norm(self(points) - points, axis=1)))


def _second_difference(knots: int) -> np.ndarray:
    d = np.zeros((knots - 2, knots))
    for i in range(knots - 2):
        d[i, i:i + 3] = (1.0, -2.0, 1.0)
    return d


def fit_look_map(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                 prior: LookMap | None = None, smoothness: float = 3e-3,
                 ridge: float = 1e-3, knots: int = DEFAULT_KNOTS) -> LookMap:
    """The :class:`LookMap` that best moves ``sources`` onto ``targets`` (weighted least squares).

    Minimises ``sum_i w_i |T(x_i) - y_i|^2 + ridge |theta - theta_prior|^2
    + smoothness |D2 theta|^2`` (``D2``: second differences along each curve;
    the weights are normalised to sum 1, so both penalties are in colour
    units squared whatever the number of points).

    Parameters
    ----------
    sources, targets : (N, 3) colours in [0, 1].
    weights : (N,) non-negative.
    prior : the map the ridge pulls towards (default the identity).
    """
    sources = np.asarray(sources, dtype=np.float64).reshape(-1, 3)
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    weights = np.asarray(weights, dtype=np.float64).ravel()
    total = weights.sum()
    if not total > 0:
        return prior if prior is not None else LookMap.identity(knots)
    weights = weights / total
    if prior is None or prior.knots != knots:
        prior = LookMap.identity(knots)
    features = LookMap.features(sources, knots)
    n_features = features.shape[1]
    weighted = features * weights[:, None]
    gram = features.T @ weighted
    d2 = _second_difference(knots)
    block = d2.T @ d2
    penalty = np.zeros((n_features, n_features))
    for g in range(4):
        sl = slice(g * knots, (g + 1) * knots)
        penalty[sl, sl] = smoothness * block
    system = gram + penalty + ridge * np.eye(n_features)
    rhs = weighted.T @ (targets - sources) + ridge * prior.coefficients.T
    coefficients = np.linalg.solve(system, rhs).T
    return LookMap(coefficients, knots)


def push_histogram(hist: np.ndarray, look: LookMap, bins: int | None = None) -> np.ndarray:
    """The histogram of the colours of ``hist`` moved through ``look`` (soft binning).

    (n, n, n) -> (bins, bins, bins), default ``bins = n``; sums to 1.
    """
    n = hist.shape[0]
    flat = hist.ravel()
    keep = np.flatnonzero(flat > 0)
    points = grid_points(n)[keep]
    return soft_histogram(look(points), bins or n, flat[keep])


def relaxed_correspondences(source: np.ndarray, target: np.ndarray, width: float = 1.5,
                            relaxation: float = 0.01, n_iter: int = 300,
                            floor: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Where each colour of ``source`` goes under unbalanced transport to ``target``.

    Entropic transport on the (n, n, n) grid with both marginals relaxed by
    ``relaxation * KL`` (scalings raised to ``rho / (rho + gamma)``; Chizat et
    al. 2018), solved in the log domain.

    Parameters
    ----------
    source, target : (n, n, n) histograms.
    width : kernel standard deviation in bins.

    Returns
    -------
    projection : (n, n, n, 3) barycentric projection ``(K (b x)) / (K b)`` of every bin.
    kept : (n, n, n) share of each source bin's mass the plan moves (0..~1).
    """
    n = source.shape[0]
    geometry = GridGeometry.with_width((n,) * 3, width)
    tau = relaxation / (relaxation + geometry.gamma)
    log_p = np.log(add_floor(source / source.sum(), floor))
    log_q = np.log(add_floor(target / target.sum(), floor))
    f = np.zeros_like(log_p)
    g = np.zeros_like(log_q)
    for _ in range(n_iter):
        f_new = tau * (log_p - geometry.log_apply(g))
        g = tau * (log_q - geometry.log_apply(f_new))
        change = np.max(np.abs(f_new - f))
        f = f_new
        if change < 1e-6:
            break
    log_kb = geometry.log_apply(g)
    axis = np.linspace(0.0, 1.0, n)
    shifted = [axis.reshape(shape) + 1.0 for shape in ((n, 1, 1), (1, n, 1), (1, 1, n))]
    projection = np.stack(
        [np.exp(geometry.log_apply(g + np.log(np.broadcast_to(s, g.shape))) - log_kb) - 1.0
         for s in shifted], axis=-1)
    kept = np.exp(f + log_kb - log_p)
    return np.clip(projection, 0.0, 1.0), np.clip(kept, 0.0, 1.0)


def fit_geometry(bins: int):
    """The core's grid geometry of a ``bins``^3 histogram as the look fits use it."""
    return GridGeometry((bins,) * 3, 2.0 * (1.5 / (bins - 1)) ** 2)


def look_coordinates(target: np.ndarray, palettes: np.ndarray, floor: float = 1e-4,
                     max_iter: int = 15) -> tuple[np.ndarray, float]:
    """KL barycentric coordinates of ``target`` (m, m, m) over ``palettes`` (K, m, m, m).

    Returns (weights (K,), loss).
    """
    bins = target.shape[0]
    result = barycentric_coordinates(
        add_floor(target, floor), np.stack([add_floor(h, floor) for h in palettes]),
        fit_geometry(bins), loss="kl", n_iter=30, max_iter=max_iter, tol=1e-5)
    return np.asarray(result.weights, dtype=np.float64), float(result.loss)


def look_correspondences(photo: np.ndarray, style: np.ndarray, look: LookMap, width: float,
                         relaxation: float):
    """Colours of ``photo`` (n^3 grid), where ``look`` then the relaxed plan to ``style`` send
    them, and the mass each moved: (points (N, 3), targets (N, 3), mass (N,), moved (N, 3))."""
    n = photo.shape[0]
    flat = photo.ravel()
    used = np.flatnonzero(flat > 1e-7)
    points = grid_points(n)[used]
    moved = look(points)
    projection, kept = relaxed_correspondences(push_histogram(photo, look), style, width,
                                               relaxation)
    mass = flat[used] * interpolate_lattice(kept[..., None], moved)[:, 0]
    return points, interpolate_lattice(projection, moved), mass, moved
