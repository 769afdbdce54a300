r"""Two-marginal entropic optimal transport (Sinkhorn) and the barycentric projection map.

Solves ``min_pi <C, pi> - gamma H(pi)`` subject to ``pi 1 = p``, ``pi^T 1 = q``
by alternate scalings (Cuturi 2013): the plan is ``pi = diag(a) K diag(b)``
with ``a = p / K b`` and ``b = q / K a``. With ``relaxation = rho`` the second
marginal is only asked to be close to ``q``, ``+ rho KL(pi^T 1 | q)`` in the
objective (unbalanced transport, Chizat, Peyré, Schmitzer, Vialard 2018):
``b = (q / K a) ** (rho / (rho + gamma))``, so mass of ``q`` that ``p`` has no
use for is left out instead of being forced onto ``p``. Iterations stop when the L1 error on
the first marginal falls below ``tol`` (the second is exact after each
update). The scaling domain is used first; when scalings under- or overflow
the solver restarts in the log domain, which is exact for any range.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wbcgrade.core import _kernels, _validation
from wbcgrade.core._cpu import fast_cpu, parallel_map
from wbcgrade.core.geometry import PARALLEL_BINS, Geometry
from wbcgrade.errors import ConvergenceWarning, NumericalError

__all__ = ["SinkhornResult", "SinkhornLevel", "sinkhorn", "barycentric_projection"]

log = logging.getLogger(__name__)

_FLOAT64_MAX = float(np.finfo(np.float64).max)


class SinkhornLevel(NamedTuple):
    """One solve of a multiscale run (:func:`wbcgrade.core.multiscale_sinkhorn`)."""

    shape: tuple[int, ...]
    gamma: float
    n_iter: int
    error: float
    method: str


@dataclass(frozen=True)
class SinkhornResult:
    """Scalings of an entropic transport plan ``pi = diag(a) K diag(b)``.

    Attributes
    ----------
    log_a, log_b : ndarray, shape (*batch, *geometry.shape)
        Logarithms of the scalings (``-inf`` where the marginal is zero).
    n_iter : int
        Iterations run.
    error : float
        Largest L1 error on the first marginal over the batch.
    converged : bool
        Whether ``error <= tol``.
    errors : tuple of float
        The error at each convergence check, the last one included (the
        successful attempt's, after any fallback).
    method : str
        ``"scaling"`` or ``"log"``: the domain that computed it.
    levels : tuple of SinkhornLevel
        From :func:`~wbcgrade.core.multiscale_sinkhorn`: every solve (grid
        shape, gamma, iterations, error, domain), coarsest first, this one
        last; empty from :func:`sinkhorn`.
    """

    log_a: NDArray
    log_b: NDArray
    n_iter: int
    error: float
    converged: bool
    errors: tuple[float, ...] = ()
    method: str = "scaling"
    levels: tuple[SinkhornLevel, ...] = ()


class _Unsafe(Exception):
    pass


def _marginal_error(p_est: NDArray, p: NDArray, geometry: Geometry) -> float:
    axes = tuple(range(p.ndim - geometry.ndim, p.ndim))
    return float(np.abs(p_est - p).sum(axis=axes).max())


def _rows(x: NDArray, geometry: Geometry) -> NDArray:
    """(*batch, *shape) -> (batch, N) view."""
    return x.reshape(-1, geometry.size)


def _l1_error(a: NDArray, Kb: NDArray, p: NDArray, geometry: Geometry) -> float:
    """Largest L1 error ``|a K b - p|`` over the batch (one fused pass per problem)."""
    return max(_kernels.l1_residual(ar, kr, pr)
               for ar, kr, pr in zip(_rows(a, geometry), _rows(Kb, geometry),
                                     _rows(p, geometry)))


def _update(num: NDArray, den: NDArray, out: NDArray, geometry: Geometry,
            omega: float = 1.0, power: float = 1.0) -> bool:
    """``out = out^(1 - omega) (num / den)^(omega power)`` (0 where den vanished; the
    plain ``(num / den)^power`` where ``out`` is 0), fused; False when a bin with mass
    gets a scaling that is 0, inf or NaN (the scaling domain cannot go on)."""
    if not out.flags.c_contiguous:
        raise ValueError("out must be C-contiguous")
    bad: list[int] = []
    for nr, dr, orow in zip(_rows(num, geometry), _rows(den, geometry), _rows(out, geometry)):
        def work(lo: int, hi: int, nr=nr, dr=dr, orow=orow) -> None:
            bad.append(_kernels.relaxed_ratio(nr[lo:hi], dr[lo:hi], orow[lo:hi], omega, power,
                                              _FLOAT64_MAX))

        if nr.size >= PARALLEL_BINS and (omega != 1.0 or power != 1.0):
            parallel_map(work, nr.size)  # exp and log per bin: worth the threads
        else:
            work(0, nr.size)
    return sum(bad) == 0


#: Over-relaxation speeds up the local convergence only: iterations are plain until
#: the marginal error is below this (a cold start overshoots otherwise).
_RELAX_BELOW = 0.05


class _Diverged(Exception):
    """Over-relaxed iterations stopped converging (the plain ones always do)."""


def _watch(errors: list[float], error: float, omega: float) -> None:
    """Raise _Diverged when over-relaxed iterations go astray: the error non-finite,
    10x above its best, or no new best for 30 checks (relaxed errors oscillate, by up
    to ~5x, on their way down)."""
    if omega != 1.0 and errors:
        best = min(errors)
        if (not np.isfinite(error) or error > 10.0 * best
                or (len(errors) >= 30 and min(errors[-30:]) > best and error > best)):
            raise _Diverged(f"marginal error {error:.3g}")
    errors.append(error)


def _scaling(p, q, geometry, tol, max_iter, init_log_b, check_every, power, omega=1.0):
    # C order throughout: the fused passes work on flat views of these arrays.
    p, q = np.ascontiguousarray(p), np.ascontiguousarray(q)
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
        b = np.ones(q.shape) if init_log_b is None else np.exp(init_log_b, order="C")
        if not np.all(np.isfinite(b)):
            raise _Unsafe("initial scalings overflow")
        a = np.zeros(p.shape)
        error, it, errors, step = np.inf, 0, [], 1.0
        for it in range(1, max_iter + 1):
            Kb = np.ascontiguousarray(geometry.apply(b), dtype=np.float64)
            if it > 1 and (it % check_every == 0 or it == max_iter):
                error = _l1_error(a, Kb, p, geometry)
                if error <= tol:
                    it -= 1
                    break
                step = omega if error <= _RELAX_BELOW or step != 1.0 else 1.0
                _watch(errors, error, step)
            if not _update(p, Kb, a, geometry, step):
                raise (_Diverged if step != 1.0 else _Unsafe)(
                    "K b vanishes or overflows where p has mass")
            Ka = np.ascontiguousarray(geometry.apply(a), dtype=np.float64)
            if not _update(q, Ka, b, geometry, step, power):
                raise (_Diverged if step != 1.0 else _Unsafe)(
                    "K a vanishes or overflows where q has mass")
        else:
            Kb = np.ascontiguousarray(geometry.apply(b), dtype=np.float64)
            error = _l1_error(a, Kb, p, geometry)
        return np.log(a), np.log(b), it, error, errors + [error]


def _relax(old: NDArray, new: NDArray, omega: float) -> NDArray:
    """``(1 - omega) old + omega new`` in the log domain (-inf stays -inf)."""
    if omega == 1.0:
        return new
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(old) & np.isfinite(new), (1.0 - omega) * old + omega * new,
                        new)


def _log_domain(p, q, geometry, tol, max_iter, init_log_b, check_every, power, omega=1.0):
    with np.errstate(divide="ignore", invalid="ignore"):
        log_p, log_q = np.log(p), np.log(q)
        log_b = np.zeros_like(q) if init_log_b is None else np.array(init_log_b, dtype=np.float64)
        log_a = np.full_like(p, -np.inf)
        error, it, errors, step = np.inf, 0, [], 1.0
        for it in range(1, max_iter + 1):
            log_Kb = geometry.log_apply(log_b)
            if it > 1 and (it % check_every == 0 or it == max_iter):
                error = _marginal_error(np.exp(log_a + log_Kb), p, geometry)
                if error <= tol:
                    it -= 1
                    break
                step = omega if error <= _RELAX_BELOW or step != 1.0 else 1.0
                _watch(errors, error, step)
            log_a = _relax(log_a, log_p - log_Kb, step)
            log_b = _relax(log_b, power * (log_q - geometry.log_apply(log_a)), step)
        else:
            error = _marginal_error(np.exp(log_a + geometry.log_apply(log_b)), p, geometry)
        return log_a, log_b, it, error, errors + [error]


def sinkhorn(
    p: ArrayLike,
    q: ArrayLike,
    geometry: Geometry,
    tol: float = 1e-6,
    max_iter: int = 1000,
    init_log_b: ArrayLike | None = None,
    check_every: int = 5,
    relaxation: float | None = None,
    overrelaxation: float = 1.0,
    method: str = "auto",
    warn: bool = True,
) -> SinkhornResult:
    """Entropic optimal transport between ``p`` and ``q`` on ``geometry``.

    Parameters
    ----------
    p, q : array_like, shape (*batch, *geometry.shape)
        Non-negative marginals; each is normalised to sum 1. A leading batch
        holds independent problems.
    geometry : Geometry
        Supplies the kernel ``K = exp(-C / gamma)``.
    tol : float, default 1e-6
        Stop when the L1 error on the first marginal is at most ``tol``.
    max_iter : int, default 1000
    init_log_b : array_like, optional
        Warm start for ``log b`` (e.g. from a previous, coarser solve).
    check_every : int, default 5
        Iterations between convergence checks.
    relaxation : float, optional
        ``rho > 0``: the second marginal is relaxed by ``rho KL(pi^T 1 | q)``
        (in the units of the cost; ``rho -> inf`` is balanced transport). The
        first marginal stays exact, so ``error`` still measures convergence.
    overrelaxation : float, default 1.0
        ``omega`` in (0, 2): each scaling moves to ``old^(1 - omega) new^omega``
        (over-relaxed Sinkhorn; Thibault et al. 2017, Lehmann et al. 2021). The
        fixed point is the same; with a narrow kernel, ``omega`` near 1.7 takes
        2-4 times fewer iterations. Iterations are plain until the error is
        below 0.05; relaxed ones are not guaranteed to converge: when the error
        grows (10x above its best, or no new best for 30 checks) or the
        scalings break down, the solve starts again with plain iterations.
    method : {"auto", "scaling", "log"}, default "auto"
        ``"scaling"``: plain kernel products only (``NumericalError`` when the
        scalings under- or overflow); ``"log"``: the exact log domain from the
        start; ``"auto"``: scaling, then the log domain if needed.
    warn : bool, default True
        Issue a :class:`~wbcgrade.errors.ConvergenceWarning` when ``max_iter``
        iterations end above ``tol``.

    Returns
    -------
    SinkhornResult

    References
    ----------
    Cuturi (2013), Sinkhorn distances: lightspeed computation of optimal transport.

    Examples
    --------
    >>> import numpy as np
    >>> from wbcgrade.core import GridGeometry, barycentric_projection, sinkhorn
    >>> x = np.linspace(0, 1, 30)
    >>> p, q = np.exp(-(x - 0.3) ** 2 / 0.01), np.exp(-(x - 0.7) ** 2 / 0.01)
    >>> geometry = GridGeometry.with_width(30, 1.0)
    >>> result = sinkhorn(p / p.sum(), q / q.sum(), geometry, tol=1e-6)
    >>> moved = barycentric_projection(result, geometry)  # where each bin's mass goes
    >>> result.converged, round(float(moved[9, 0] - x[9]), 1)  # 0.3 goes to about 0.7
    (True, 0.4)
    """
    p = _validation.histograms(p, geometry, "p")
    q = _validation.histograms(q, geometry, "q")
    if p.shape != q.shape:
        raise ValueError(f"p and q must have the same shape, got {p.shape} and {q.shape}")
    if init_log_b is not None and np.shape(init_log_b) != q.shape:
        raise ValueError(f"init_log_b must have shape {q.shape}, got {np.shape(init_log_b)}")
    if int(max_iter) < 1:
        raise ValueError("max_iter must be at least 1")
    if relaxation is not None and not (np.isfinite(relaxation) and relaxation > 0):
        raise ValueError("relaxation must be a positive number (or None for balanced transport)")
    if not (np.isfinite(overrelaxation) and 0 < overrelaxation < 2):
        raise ValueError("overrelaxation must be in (0, 2)")
    solvers = {"auto": (_scaling, _log_domain), "scaling": (_scaling,), "log": (_log_domain,)}
    if method not in solvers:
        raise ValueError(f"method must be 'auto', 'scaling' or 'log', got {method!r}")
    power = 1.0 if relaxation is None else float(relaxation / (relaxation + geometry.gamma))
    args = (p, q, geometry, float(tol), int(max_iter), init_log_b, max(1, int(check_every)),
            power)
    omegas = [float(overrelaxation)] + ([1.0] if overrelaxation != 1.0 else [])
    result = None
    with fast_cpu():
        for solve in solvers[method]:
            try:
                for omega in omegas:
                    try:
                        result = solve(*args, omega=omega)
                        break
                    except _Diverged as why:
                        log.info("sinkhorn: over-relaxation %.3g diverged (%s); plain "
                                 "iterations", omega, why)
                break
            except _Unsafe as why:
                if method == "scaling":
                    raise NumericalError(
                        f"sinkhorn: the scaling domain cannot represent this problem ({why}); "
                        "use method='log' or 'auto'") from None
                log.info("sinkhorn: scaling domain unsafe (%s); using the log domain", why)
    log_a, log_b, n_iter, error, errors = result
    converged = bool(error <= tol)
    if warn and not converged:
        warnings.warn(ConvergenceWarning(
            f"sinkhorn stopped after {n_iter} iterations with marginal error {error:.3g} "
            f"> tol {tol:g}"), stacklevel=2)
    name = "scaling" if solve is _scaling else "log"
    return SinkhornResult(log_a, log_b, n_iter, error, converged, tuple(errors), name)


def barycentric_projection(
    result: SinkhornResult, geometry: Geometry, values: ArrayLike | None = None
) -> NDArray:
    """Barycentric projection of a plan: where each bin's mass goes, on average.

    ``T(x_i) = sum_j pi_ij x_j / sum_j pi_ij = (K (b x))_i / (K b)_i``, defined
    on every bin (also where ``p`` is zero) and smooth.

    Parameters
    ----------
    result : SinkhornResult
        Plan between p and q (no batch axes).
    geometry : Geometry
    values : array_like, shape (N, d), optional
        What to average; default ``geometry.points``.

    Returns
    -------
    ndarray, shape (*geometry.shape, d)
    """
    if result.log_b.shape != geometry.shape:
        raise ValueError("barycentric_projection takes a single (unbatched) plan")
    x = geometry.points if values is None else np.asarray(values, dtype=np.float64)
    if x is None:
        raise ValueError("this geometry has no points: pass values=")
    if x.ndim != 2 or x.shape[0] != geometry.size:
        raise ValueError(f"values must have shape ({geometry.size}, d), got {x.shape}")
    fields = np.moveaxis(x.reshape(*geometry.shape, -1), -1, 0)
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        b = np.exp(result.log_b)
        if values is None and _separable(geometry) and np.all(np.isfinite(b)):
            weight, moved = _grid_projection(b, geometry)
            if np.all(weight > 0) and np.all(np.isfinite(moved)):
                return moved / weight[..., None]
        elif np.all(np.isfinite(b)):
            scaled = geometry.apply(np.concatenate([b[None], b[None] * fields])).astype(np.float64)
            weight, moved = scaled[0], scaled[1:]
            if np.all(weight > 0) and np.all(np.isfinite(moved)):
                return np.moveaxis(moved / weight, 0, -1)
        # Log domain: average positive parts; shift fields so they are positive.
        shift = x.min(axis=0) - 1.0
        positive = fields - shift.reshape(-1, *([1] * geometry.ndim))
        log_weight = geometry.log_apply(result.log_b)
        moved = np.exp(geometry.log_apply(result.log_b[None] + np.log(positive)) - log_weight)
        return np.moveaxis(moved, 0, -1) + shift


def _separable(geometry: Geometry) -> bool:
    """A float64 3-D geometry whose kernel is three axis kernels (a grid's)."""
    return (geometry.ndim == 3 and geometry.dtype == np.float64
            and geometry.separable_factors() is not None)


def _grid_projection(b: NDArray, geometry: Geometry) -> tuple[NDArray, NDArray]:
    """``K b`` and ``K (b x)`` (x: each bin's grid coordinates) on a 3-D grid.

    The kernel is a product of axis kernels ``K = K0 K1 K2`` and coordinate
    ``a`` varies along axis ``a`` only, so ``K (b x_a)`` is ``K b`` with
    ``K_a`` replaced by ``K_a diag(x_a)``: sharing the partial products takes
    9 axis products instead of 12 (four full kernel products).

    Returns
    -------
    weight : (*shape) ``K b``
    moved : (*shape, 3) ``K (b x_a)`` for a = 0, 1, 2
    """
    n0, n1, n2 = geometry.shape
    factors = geometry.separable_factors()
    K0, K1, K2 = (kernel for kernel, _ in factors)
    X0, X1, X2 = (kernel * x[None, :] for kernel, x in factors)

    def along(kernel: NDArray, values: NDArray, axis: int, out: NDArray) -> NDArray:
        if axis == 0:
            flat, target = values.reshape(n0, -1), out.reshape(n0, -1)

            def work(lo: int, hi: int) -> None:
                np.matmul(kernel[lo:hi], flat, out=target[lo:hi])
        elif axis == 1:
            def work(lo: int, hi: int) -> None:
                np.matmul(kernel, values[lo:hi], out=out[lo:hi])
        else:
            def work(lo: int, hi: int) -> None:
                np.matmul(values[lo:hi].reshape(-1, n2), kernel.T,
                          out=out[lo:hi].reshape(-1, n2))
        parallel_map(work, n0)
        return out

    moved = np.empty((n0, n1, n2, 3))
    with fast_cpu():
        v = along(K2, b, 2, np.empty_like(b))                       # K2 b
        t = along(K1, v, 1, np.empty_like(b))                       # K1 K2 b
        weight = along(K0, t, 0, np.empty_like(b))                  # K b
        scratch = along(X0, t, 0, np.empty_like(b))                 # K0 X0 K1 K2 b
        moved[..., 0] = scratch
        along(K0, along(X1, v, 1, t), 0, scratch)                   # K0 K1 X1 K2 b
        moved[..., 1] = scratch
        w = along(X2, b, 2, v)                                      # K2 X2 b
        along(K0, along(K1, w, 1, t), 0, scratch)                   # K0 K1 K2 X2 b
        moved[..., 2] = scratch
    return weight, moved
