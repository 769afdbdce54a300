"""A smooth colour map fitted to the transport's correspondences: the grade as a 3-D LUT.

The barycentric projection of a narrow-kernel transport plan is close to the
exact optimal transport map, which is discontinuous between multi-modal
palettes: neighbouring input colours can go to distant outputs (split
colours, JPEG blocks and sensor noise turned into mosaic). Following the
regularised-map idea of Ferradans, Papadakis, Peyré and Aujol (2014), the
grade is instead the lattice LUT ``L`` (``size`` nodes per axis) whose
displacement ``d = L - x`` minimises

    sum_i w_i |d(x_i) - (T(x_i) - x_i)|^2
      + smoothness * |second differences of d|^2     (thin plate: curvature)
      + stiffness  * |first differences of d|^2      (local gain close to 1)

where ``x_i`` are the transfer grid's bins, ``T`` the raw map, ``d(x_i)`` the
trilinear interpolation of the lattice, and ``w_i`` the photo's colour
density (raised to ``density_power``, normalised to sum 1). Colours the photo
holds decide the map; elsewhere it continues smoothly. The penalty weights
are those of a 33-node lattice and are rescaled for other sizes so that they
weigh the same continuous energy. The system is sparse, symmetric positive
definite and badly conditioned far from the data, so it is solved
coarse-to-fine (5, 9, 17, 33 nodes: each level's solution, interpolated,
starts the next), each level by conjugate gradients preconditioned with a
multigrid V-cycle over the coarser lattices (three right-hand sides, one per
channel, at once).
"""

from __future__ import annotations

import importlib

import numpy as np

from wbcgrade.color.mapping.remap import identity_map
from wbcgrade.color.options import DEFAULT_MAP_SIZE, DEFAULT_SMOOTHNESS, DEFAULT_STIFFNESS
from wbcgrade.core import fast_cpu

__all__ = ["fit_smooth_map", "SmoothMapFitter", "interpolation_matrix", "DEFAULT_MAP_SIZE",
           "DEFAULT_SMOOTHNESS", "DEFAULT_STIFFNESS"]

class _OnFirstUse:
    """A module imported when first used: scipy.sparse takes ~0.4 s to import, which a
    look grade that never smooths a map (and a saved grade) should not pay."""

    def __init__(self, name: str) -> None:
        self._name = name

    def __getattr__(self, attribute: str):
        return getattr(importlib.import_module(self._name), attribute)


sp = _OnFirstUse("scipy.sparse")
_linalg = _OnFirstUse("scipy.sparse.linalg")

#: Relative residual the coarser lattices are solved to (they give the next its start).
_START_TOL = 1e-4
#: Coarsest lattices up to this many nodes are solved directly (the multigrid's bottom).
_DIRECT_NODES = 4096
#: Lattice size the penalty weights refer to; other sizes rescale them to the
#: same continuous energy (curvature x (size-1)/32, first differences / that).
REFERENCE_SIZE = 33


def interpolation_matrix(points: np.ndarray, size: int) -> sp.csr_matrix:
    """(N, size^3) trilinear interpolation weights of points in [0, 1]^3 on the lattice."""
    pos = np.clip(points, 0.0, 1.0) * (size - 1)
    base = np.minimum(pos.astype(np.int64), size - 2)
    frac = pos - base
    rows, cols, vals = [], [], []
    index = np.arange(len(points))
    for dr in (0, 1):
        wr = frac[:, 0] if dr else 1.0 - frac[:, 0]
        for dg in (0, 1):
            wg = wr * (frac[:, 1] if dg else 1.0 - frac[:, 1])
            for db in (0, 1):
                w = wg * (frac[:, 2] if db else 1.0 - frac[:, 2])
                node = ((base[:, 0] + dr) * size + base[:, 1] + dg) * size + base[:, 2] + db
                rows.append(index)
                cols.append(node)
                vals.append(w)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(len(points), size ** 3))


def _difference(n: int, order: int) -> sp.csr_matrix:
    eye = sp.eye(n, format="csr")
    out = eye
    for _ in range(order):
        out = (out[1:] - out[:-1]).tocsr()
    return out


def _along(op: sp.spmatrix, axis: int, size: int) -> sp.csr_matrix:
    eye = sp.eye(size, format="csr")
    mats = [eye, eye, eye]
    mats[axis] = op
    return sp.kron(sp.kron(mats[0], mats[1]), mats[2], format="csr")


def _regulariser(size: int, smoothness: float, stiffness: float) -> sp.csr_matrix:
    """Sum of the squared first and second differences (thin plate) as a quadratic form."""
    first = [_along(_difference(size, 1), a, size) for a in range(3)]
    form = sp.csr_matrix((size ** 3, size ** 3))
    if stiffness > 0:
        for op in first:
            form = form + stiffness * (op.T @ op)
    if smoothness > 0:
        for a in range(3):
            op = _along(_difference(size, 2), a, size)
            form = form + smoothness * (op.T @ op)
        for a in range(3):
            for b in range(a + 1, 3):
                op = _mixed(size, a, b)
                form = form + 2.0 * smoothness * (op.T @ op)
    return form.tocsr()


def _mixed(size: int, a: int, b: int) -> sp.csr_matrix:
    """Mixed second difference along axes a and b (on the (size-1)^2 x size cells)."""
    d1 = _difference(size, 1)
    eye = sp.eye(size, format="csr")
    mats = [eye, eye, eye]
    mats[a] = d1
    mats[b] = d1
    return sp.kron(sp.kron(mats[0], mats[1]), mats[2], format="csr")


def _levels(size: int) -> list[int]:
    """Nested lattice sizes, coarsest first (size, (size-1)/2+1, ... down to >= 5)."""
    sizes = [size]
    while (sizes[-1] - 1) % 2 == 0 and (sizes[-1] - 1) // 2 + 1 >= 5:
        sizes.append((sizes[-1] - 1) // 2 + 1)
    return sizes[::-1]


class _Multigrid:
    """V-cycle preconditioner over the nested lattices (coarsest solved directly).

    ``systems[l]`` is the lattice ``sizes[l]``'s own (rediscretised) system and
    ``prolong[l]`` the trilinear interpolation from lattice ``l - 1`` to ``l``;
    restriction is its transpose. Two damped-Jacobi sweeps before and after
    the coarse correction keep the cycle symmetric, so it preconditions
    conjugate gradients.
    """

    sweeps = 2
    #: Jacobi damping times the largest eigenvalue of D^-1 A (bounded by Gershgorin).
    damping = 4.0 / 3.0

    def __init__(self, systems: list[sp.csr_matrix], prolong: list[sp.csr_matrix | None]):
        self.systems, self.prolong = systems, prolong
        self.inv_diag, self.omega = [], []
        for a in systems:
            diag = a.diagonal()
            diag = np.where(diag > 0, diag, 1.0)
            self.inv_diag.append((1.0 / diag)[:, None])
            bound = float((abs(a).sum(axis=1).A1 / diag).max())  # >= max eig of D^-1 A
            self.omega.append(self.damping / bound)
        self.coarsest = np.linalg.inv(systems[0].toarray())

    def cycle(self, level: int, r: np.ndarray) -> np.ndarray:
        if level == 0:
            return self.coarsest @ r
        a, d, w = self.systems[level], self.inv_diag[level], self.omega[level]
        x = w * d * r
        for _ in range(self.sweeps - 1):
            x += w * d * (r - a @ x)
        p = self.prolong[level]
        x += p @ self.cycle(level - 1, p.T @ (r - a @ x))
        for _ in range(self.sweeps):
            x += w * d * (r - a @ x)
        return x


def _jacobi_cg(system: sp.csr_matrix, rhs: np.ndarray, start: np.ndarray, tol: float,
               max_iter: int) -> np.ndarray:
    """Conjugate gradients with a Jacobi preconditioner, one column at a time."""
    diag = system.diagonal()
    precond = sp.diags(1.0 / np.where(diag > 0, diag, 1.0))
    out = np.empty_like(rhs)
    for c in range(rhs.shape[1]):
        out[:, c], _ = _linalg.cg(system, rhs[:, c], x0=start[:, c], rtol=tol, maxiter=max_iter,
                          M=precond)
    return out


def _solve(multigrid: _Multigrid, level: int, rhs: np.ndarray, start: np.ndarray,
           tol: float, max_iter: int) -> np.ndarray:
    """Conjugate gradients on lattice ``level``, preconditioned by a V-cycle, for the
    three columns of ``rhs`` at once (each with its own steps), to ``|r| <= tol |rhs|``."""
    system = multigrid.systems[level]
    if level == 0:
        return multigrid.coarsest @ rhs
    x = np.array(start, dtype=np.float64)
    r = rhs - system @ x
    goal = tol * np.sqrt((rhs * rhs).sum(axis=0))
    z = multigrid.cycle(level, r)
    d = z.copy()
    rz = (r * z).sum(axis=0)
    for _ in range(max_iter):
        active = np.sqrt((r * r).sum(axis=0)) > goal
        if not active.any():
            break
        ad = system @ d
        dad = (d * ad).sum(axis=0)
        alpha = np.where(active & (dad > 0), rz / np.where(dad > 0, dad, 1.0), 0.0)
        x += alpha * d
        r -= alpha * ad
        z = multigrid.cycle(level, r)
        rz_next = (r * z).sum(axis=0)
        beta = np.where(rz > 0, rz_next / np.where(rz > 0, rz, 1.0), 0.0)
        d = z + beta * d
        rz = rz_next
    return x


def _data(density: np.ndarray, density_power: float = 1.0
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bins the photo holds: ``(indices (N,), points (N, 3), weights (N,) summing to 1)``."""
    n = density.shape[0]
    weights = np.power(np.clip(density, 0.0, None), density_power).ravel()
    if not weights.sum() > 0:
        raise ValueError("density is empty")
    keep = np.flatnonzero(weights > weights.max() * 1e-9)
    return keep, identity_map(n, np.float64).reshape(-1, 3)[keep], \
        weights[keep] / weights[keep].sum()


def _system(points: np.ndarray, weights: np.ndarray, level: int, smoothness: float,
            stiffness: float) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """The interpolation matrix B (N, level^3) and the normal equations' matrix on a lattice.

    The penalties approximate one continuous energy: they are rescaled from the
    reference lattice (REFERENCE_SIZE nodes) to this lattice's spacing.
    """
    ratio = (level - 1) / (REFERENCE_SIZE - 1)
    B = interpolation_matrix(points, level)
    system = (B.T @ sp.diags(weights) @ B
              + _regulariser(level, smoothness * ratio, stiffness / ratio)).tocsr()
    return B, (system + sp.eye(level ** 3) * 1e-12).tocsr()


def _check(size: int, smoothness: float, stiffness: float) -> None:
    if size < 2:
        raise ValueError("size must be at least 2")
    if smoothness < 0 or stiffness < 0 or smoothness + stiffness <= 0:
        raise ValueError("smoothness and stiffness must be >= 0, not both 0")


class SmoothMapFitter:
    """:func:`fit_smooth_map` for many raw maps of one photo, on a small lattice.

    The fit is linear in the raw map: its matrix depends only on the photo's
    density, the lattice and the penalties, so it is factored once
    (Cholesky) and every :meth:`fit` is a product and two triangular solves
    (about a millisecond for 9^3 nodes, where :func:`fit_smooth_map` builds
    and solves the system anew in tens). The answer is the system's exact
    solution (:func:`fit_smooth_map`'s conjugate gradients stop within 1e-4/255
    of it). For lattices up to 16^3 nodes (``explore``'s live preview).

    Parameters
    ----------
    density : (n, n, n) non-negative weight of each bin (the photo's histogram).
    size, smoothness, stiffness, density_power : as :func:`fit_smooth_map`.
    """

    def __init__(self, density: np.ndarray, size: int = 9,
                 smoothness: float = DEFAULT_SMOOTHNESS, stiffness: float = DEFAULT_STIFFNESS,
                 density_power: float = 1.0) -> None:
        from scipy.linalg import cho_factor

        n = density.shape[0]
        if density.shape != (n, n, n):
            raise ValueError("density must be (n, n, n)")
        _check(size, smoothness, stiffness)
        if size ** 3 > _DIRECT_NODES:
            raise ValueError(f"a lattice of {size}^3 nodes is too large to factor; "
                             "use fit_smooth_map")
        self.bins, self.size = n, size
        self._keep, self._points, weights = _data(density, density_power)
        B, system = _system(self._points, weights, size, smoothness, stiffness)
        self._project = (B.T @ sp.diags(weights)).tocsr()
        self._factor = cho_factor(system.toarray())

    def fit(self, raw_map: np.ndarray) -> np.ndarray:
        """(n, n, n, 3) raw map -> (size, size, size, 3) float32 smooth map, clipped to [0, 1]."""
        from scipy.linalg import cho_solve


        n, size = self.bins, self.size
        if raw_map.shape != (n, n, n, 3):
            raise ValueError(f"raw_map must be ({n}, {n}, {n}, 3)")
        target = raw_map.reshape(-1, 3)[self._keep].astype(np.float64) - self._points
        with fast_cpu():  # a small solve: OpenBLAS's threads would cost 20x more on a busy machine
            disp = cho_solve(self._factor, self._project @ target)
        lattice = identity_map(size, np.float64) + disp.reshape(size, size, size, 3)
        return np.clip(lattice, 0.0, 1.0).astype(np.float32)


def fit_smooth_map(raw_map: np.ndarray, density: np.ndarray, size: int = DEFAULT_MAP_SIZE,
                   smoothness: float = DEFAULT_SMOOTHNESS, stiffness: float = DEFAULT_STIFFNESS,
                   density_power: float = 1.0, tol: float = 1e-6,
                   max_iter: int = 200) -> np.ndarray:
    """Fit a smooth lattice colour map to a raw map, weighted by the photo's colours.

    Parameters
    ----------
    raw_map : (n, n, n, 3) new colour of each transfer-grid bin (bins at
        ``linspace(0, 1, n)``), e.g. the barycentric projection of a plan.
    density : (n, n, n) non-negative weight of each bin (the photo's histogram).
    size : nodes per axis of the fitted map (>= 2).
    smoothness, stiffness : weights of the curvature and first-difference
        penalties on the displacement (see the module docstring); >= 0.
    density_power : the data weights are ``density ** density_power``.
    tol, max_iter : conjugate-gradient stopping rule (relative residual) on the
        finest lattice; at 1e-6 the map is within 1e-4/255 of a converged solve.

    Returns
    -------
    (size, size, size, 3) float32 colour map, values clipped to [0, 1].
    """
    n = raw_map.shape[0]
    if raw_map.shape != (n, n, n, 3) or density.shape != (n, n, n):
        raise ValueError("raw_map must be (n, n, n, 3) and density (n, n, n)")
    _check(size, smoothness, stiffness)
    keep, points, weights = _data(density, density_power)
    target = raw_map.reshape(-1, 3)[keep].astype(np.float64) - points
    systems, prolong, rhs_by_level = [], [], []
    levels = _levels(size)
    for i, level in enumerate(levels):
        B, system = _system(points, weights, level, smoothness, stiffness)
        systems.append(system)
        rhs_by_level.append(B.T @ (weights[:, None] * target))
        nodes = identity_map(level, np.float64).reshape(-1, 3)
        prolong.append(None if i == 0 else interpolation_matrix(nodes, levels[i - 1]))
    disp = None
    if levels[0] ** 3 <= _DIRECT_NODES:
        multigrid = _Multigrid(systems, prolong)
        for i in range(len(levels)):  # coarser levels only give the next one its start
            start = np.zeros_like(rhs_by_level[i]) if disp is None else prolong[i] @ disp
            level_tol = tol if i == len(levels) - 1 else max(tol, _START_TOL)
            disp = _solve(multigrid, i, rhs_by_level[i], start, level_tol, max_iter)
    else:  # no small lattice below this size (e.g. 32 nodes): Jacobi-preconditioned CG
        for i in range(len(levels)):
            rhs = rhs_by_level[i]
            if disp is None:
                mass = np.asarray(systems[i].sum(axis=1)).ravel()
                start = rhs / np.maximum(mass, 1e-300)[:, None]
            else:
                start = prolong[i] @ disp
            disp = _jacobi_cg(systems[i], rhs, start, tol, 2 * max_iter)
    lattice = identity_map(size, np.float64) + disp.reshape(size, size, size, 3)
    return np.clip(lattice, 0.0, 1.0).astype(np.float32)
