"""Grid resampling: masses re-binned (:func:`resample_grid`), function values
interpolated (:func:`refine_grid`), on grids whose points sit at ``linspace(0, 1, n)``."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["refine_grid", "resample_grid", "binning_matrix"]


def refine_grid(values: ArrayLike, shape: tuple[int, ...]) -> NDArray:
    """Values of a *function* on a regular grid, interpolated (multilinearly) on another grid.

    For masses (histograms, densities) use :func:`resample_grid`, which keeps
    the total mass; this one keeps the values (a constant stays that constant).
    Both grids span the same box with points at ``linspace(0, 1, n)`` on each
    axis (:class:`GridGeometry`'s convention), so corner points coincide.
    Used to carry log-scalings from a coarse grid to a finer one as a warm
    start; ``-inf`` entries (vanished scalings) become the smallest finite value.

    Parameters
    ----------
    values : array_like, shape (..., *coarse_shape)
    shape : tuple of int
        The new grid's shape (same number of axes as ``coarse_shape``).

    Returns
    -------
    ndarray, shape (..., *shape), float64
    """
    x = np.array(values, dtype=np.float64)
    d = len(shape)
    if x.ndim < d or any(n < 2 for n in x.shape[x.ndim - d :]) or any(n < 2 for n in shape):
        raise ValueError(f"cannot refine an array of shape {x.shape} to {shape}")
    finite = np.isfinite(x)
    if not finite.all():
        x[~finite] = x[finite].min() if finite.any() else 0.0
    return np.ascontiguousarray(_interpolate(x, shape))


def _interpolate(x: NDArray, shape: tuple[int, ...]) -> NDArray:
    """``x`` (..., *grid) linearly interpolated onto ``shape`` (corners aligned), float64.

    One gather-and-blend pass per axis whose length changes; an axis of one
    point is constant along that axis (repeated).
    """
    lead = x.ndim - len(shape)
    for k, n_out in enumerate(shape):
        axis, n_in = lead + k, x.shape[lead + k]
        if n_in == n_out:
            continue
        if n_in == 1:
            x = np.repeat(x, n_out, axis=axis)
            continue
        # New point i sits at i (n_in - 1) / (n_out - 1) of the old grid, between
        # old points base and base + 1.
        pos = np.arange(n_out) * ((n_in - 1) / (n_out - 1))
        base = np.minimum(pos.astype(np.int64), n_in - 2)
        frac = (pos - base).reshape([-1 if a == axis else 1 for a in range(x.ndim)])
        x = np.take(x, base, axis=axis) * (1.0 - frac) + np.take(x, base + 1, axis=axis) * frac
    return x


def binning_matrix(n: int, m: int) -> NDArray:
    """``(m, n)``: how the masses at ``n`` grid points split over the two nearest of ``m``.

    Points at ``linspace(0, 1, n)`` and ``linspace(0, 1, m)``. Each column holds
    the linear-interpolation weights of one old point between its two
    neighbours on the new grid (it sums to 1): the matrix is the transpose
    (adjoint) of linear interpolation from the ``m``-point grid to the
    ``n``-point one, so it keeps the total mass and the mean position.
    """
    if m == 1:
        return np.ones((1, n))
    pos = np.linspace(0.0, 1.0, n) * (m - 1)
    base = np.minimum(pos.astype(np.int64), m - 2)
    frac = pos - base
    matrix = np.zeros((m, n))
    matrix[base, np.arange(n)] += 1.0 - frac
    matrix[base + 1, np.arange(n)] += frac
    return matrix


def resample_grid(values: ArrayLike, shape: tuple[int, ...], mass: float | None = None) -> NDArray:
    """Masses (histograms, densities) on a regular grid, re-binned onto a grid of another shape.

    For values of a *function* use :func:`refine_grid`; this one keeps the
    total mass. Both grids span the same box with points at ``linspace(0, 1,
    n)`` on each axis (corners aligned); any number of axes, each coarsened
    or refined independently:

    - along an axis that gets coarser, each old point's mass is split between
      its two nearest new points with linear-interpolation weights
      (:func:`binning_matrix`, the adjoint of linear interpolation): the total
      mass and the mean position are kept exactly (to rounding);
    - along an axis that gets finer, the density is interpolated linearly
      (moving the masses themselves would leave empty bins between them).

    The result is then clipped at 0 and rescaled to the total ``mass``.

    Parameters
    ----------
    values : array_like, shape (..., *old_shape)
        Non-negative, finite; leading axes hold independent histograms.
    shape : tuple of int
        The new grid's shape (as many axes as ``old_shape``, each >= 1).
    mass : float, optional
        Total mass of each resampled histogram; default each input's own total
        (``mass=1.0`` normalises). A histogram whose shape does not change is
        returned as a float64 copy, rescaled only when ``mass`` is given.

    Returns
    -------
    ndarray, shape (..., *shape), float64

    Examples
    --------
    >>> import numpy as np
    >>> from wbcgrade.core import resample_grid
    >>> resample_grid(np.array([0.0, 1.0, 0.0, 0.0, 1.0]), (3,)).tolist()  # mass 2 kept
    [0.5, 0.5, 1.0]
    """
    x = np.asarray(values, dtype=np.float64)
    shape = tuple(int(n) for n in shape)
    d = len(shape)
    if d == 0 or x.ndim < d or any(n < 1 for n in shape) or 0 in x.shape[x.ndim - d:]:
        raise ValueError(f"cannot resample an array of shape {x.shape} to the grid {shape}")
    if not np.all(np.isfinite(x)) or np.any(x < 0):
        raise ValueError("resample_grid takes finite, non-negative masses")
    if mass is not None and not (np.isfinite(mass) and mass >= 0):
        raise ValueError(f"mass must be a non-negative number, got {mass!r}")
    if x.ndim == d:  # as computed: its memory order fixes the rounding of later sums
        return _resample_one(x, shape, mass)
    lead = x.shape[: x.ndim - d]
    flat = x.reshape(-1, *x.shape[x.ndim - d:])
    return np.stack([_resample_one(h, shape, mass) for h in flat]).reshape(*lead, *shape)


def _resample_one(hist: NDArray, shape: tuple[int, ...], mass: float | None) -> NDArray:
    """:func:`resample_grid` of one histogram (its checks done)."""
    total = float(hist.sum()) if mass is None else float(mass)
    if hist.shape == shape:
        if mass is None:
            return hist.copy()
        out = hist
    else:
        out = hist
        for axis, (n, m) in enumerate(zip(hist.shape, shape)):
            if m < n:  # coarser: soft-bin the masses (separable: one matrix per axis)
                out = np.moveaxis(np.tensordot(binning_matrix(n, m), out, axes=(1, axis)), 0,
                                  axis)
        if any(m > n for n, m in zip(out.shape, shape)):  # finer: interpolate the density
            out = _interpolate(out, shape)
        out = np.clip(out, 0.0, None)
    current = out.sum()
    if current == 0:
        if total == 0:
            return np.zeros(shape)
        raise ValueError("cannot give an empty histogram a positive mass")
    return out / current * total
