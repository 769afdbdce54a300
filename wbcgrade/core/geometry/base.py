"""The geometry interface: what every solver may ask of a set of bins and its kernel.

:class:`Geometry` is abstract: a kind of geometry implements ``apply``,
``log_apply``, ``cost_matrix``, ``points`` and ``log_apply_work``. The
*capabilities* below have defaults that every geometry gets; a kind that can
do better overrides them, and solvers only ever call these public methods
(no probing of private attributes, no test of the concrete class):

- :meth:`Geometry.log_apply_into`: the log-domain product written into a given
  array, possibly over its input (default: a copy of ``log_apply``'s result);
- :meth:`Geometry.signed_log_apply`: ``log |K x|`` and ``sign(K x)`` of signed
  values (default: the positive and negative parts separately);
- :attr:`Geometry.log_per_histogram` and :meth:`Geometry.log_apply_one`: whether
  one histogram's log product is cheap enough to run alone in a thread
  (default False; the default method works anyway), and that product;
- :attr:`Geometry.log_apply_rate`: entries per second and core of the log
  product, for cost estimates (default None: unknown);
- :meth:`Geometry.separable_factors`: the one-dimensional kernels and axis
  points of a separable kernel (default None);
- :attr:`Geometry.is_grid` and :meth:`Geometry.with_grid`: the same kind of
  geometry on a regular grid of another shape (default: not a grid).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import NDArray

from wbcgrade.core._cpu import fast_cpu, parallel_map

__all__ = ["Geometry", "PARALLEL_BINS"]


def _output(out: NDArray | None, like: NDArray) -> NDArray:
    """``out`` checked to be a C-contiguous float64 array shaped like ``like``, or a new one."""
    if out is None:
        return np.empty_like(like)
    if out.shape != like.shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError("out must be a C-contiguous float64 array of the values' shape")
    return out


def _gibbs(cost: NDArray, gamma: float, dtype: np.dtype) -> NDArray:
    """exp(-cost / gamma) in ``dtype``, with entries that would be denormal set to 0.

    Denormal operands make matrix products an order of magnitude slower on
    common CPUs; entries below the smallest normal number carry no usable mass.
    """
    kernel = np.exp(-np.asarray(cost, dtype=np.float64) / gamma)
    kernel[kernel < np.finfo(dtype).tiny] = 0.0
    return np.ascontiguousarray(kernel, dtype=dtype)


def _check_gamma(gamma: float) -> float:
    gamma = float(gamma)
    if not np.isfinite(gamma) or gamma <= 0:
        raise ValueError(f"gamma must be a positive finite number, got {gamma!r}")
    return gamma


#: Histograms smaller than this are computed in one thread: below ~50^3 bins the
#: threads' overhead costs more than they save (a 32^3 gradient with S = 10:
#: 0.67 s in one thread, 0.91 s in two).
PARALLEL_BINS = 1 << 17


def _apply_in_parallel(geometry: Geometry, values: NDArray, apply_block) -> NDArray:
    """Run ``apply_block(block, out)`` over the leading histograms, split across threads."""
    geometry._check_values(values)
    x = np.ascontiguousarray(values, dtype=geometry.dtype)
    lead = int(np.prod(x.shape[: x.ndim - geometry.ndim]))
    flat = x.reshape(lead, *geometry.shape)
    out = np.empty_like(flat)

    def work(lo: int, hi: int) -> None:
        apply_block(flat[lo:hi], out[lo:hi])

    with fast_cpu():
        if lead >= 2 and geometry.size >= PARALLEL_BINS:
            parallel_map(work, lead)
        else:
            work(0, lead)
    return out.reshape(x.shape)


class Geometry(ABC):
    """Bins, their ground cost, and the Gibbs kernel ``K = exp(-C / gamma)``.

    Attributes
    ----------
    shape : tuple of int
        Shape of one histogram on this geometry.
    gamma : float
        Entropic regularisation.
    dtype : numpy.dtype
        Precision of the scaling-domain kernel products.
    """

    shape: tuple[int, ...]
    gamma: float
    dtype: np.dtype

    @property
    def ndim(self) -> int:
        """Number of axes of one histogram."""
        return len(self.shape)

    @property
    def size(self) -> int:
        """Number of bins N."""
        return int(np.prod(self.shape))

    @property
    @abstractmethod
    def log_apply_work(self) -> int:
        """Kernel entries one ``log_apply`` visits per histogram (its cost)."""

    @property
    @abstractmethod
    def points(self) -> NDArray | None:
        """Bin coordinates, ``(N, d)`` in C order, or None when unknown."""

    @abstractmethod
    def apply(self, values: NDArray) -> NDArray:
        """Kernel product ``K x`` over the last ``ndim`` axes.

        Parameters
        ----------
        values : ndarray, shape (..., *shape)

        Returns
        -------
        ndarray, shape (..., *shape), in ``self.dtype``
        """

    def apply_into(self, block: NDArray, out: NDArray) -> None:
        """``out = K block`` for a block ``(k, *shape)``, in the calling thread.

        Solvers that spread independent histograms over their own threads call
        this; the default forwards to :meth:`apply`. ``out`` has the block's
        shape and ``self.dtype``.
        """
        out[...] = self.apply(block)

    @abstractmethod
    def log_apply(self, log_values: NDArray) -> NDArray:
        """Log-domain kernel product ``log(K exp(f))`` over the last ``ndim`` axes.

        Exact for any range of ``f`` (float64); ``-inf`` entries stand for zeros.

        Parameters
        ----------
        log_values : ndarray, shape (..., *shape)

        Returns
        -------
        ndarray, shape (..., *shape), float64
        """

    @abstractmethod
    def cost_matrix(self) -> NDArray:
        """The full ``(N, N)`` cost matrix (for tests and small problems only)."""

    def kernel_matrix(self) -> NDArray:
        """The full ``(N, N)`` Gibbs kernel (for tests and small problems only)."""
        return _gibbs(self.cost_matrix(), self.gamma, self.dtype)

    def with_dtype(self, dtype: np.dtype | type) -> Geometry:
        """The same geometry computing in another precision."""
        raise NotImplementedError

    # ----------------------------------------------------------- capabilities

    #: Whether :meth:`log_apply_one` on one histogram is cheap enough for a solver
    #: to run each histogram's whole log-domain recursion in its own thread.
    log_per_histogram: bool = False
    #: Kernel entries per second and core of :meth:`log_apply` (cost estimates
    #: before running the log domain), or None when unknown.
    log_apply_rate: float | None = None
    #: Whether the bins are a regular grid that :meth:`with_grid` can rebuild.
    is_grid: bool = False

    def log_apply_into(self, log_values: NDArray, out: NDArray) -> NDArray:
        """:meth:`log_apply` written into ``out`` (float64, C order, the values' shape).

        ``out`` may be ``log_values`` itself; geometries that can compute the
        product in place (grids) then save a whole array of memory. Returns ``out``.
        """
        out = _output(out, np.asarray(log_values))
        out[...] = self.log_apply(log_values)
        return out

    def signed_log_apply(self, log_abs: NDArray, signs: NDArray, out: NDArray | None = None,
                         out_signs: NDArray | None = None) -> tuple[NDArray, NDArray]:
        """``log |K x|`` and ``sign(K x)`` for ``x = signs * exp(log_abs)`` (float64).

        The reverse pass's adjoints change sign. Default: the positive and
        negative parts through :meth:`log_apply` separately, then combined.
        ``out`` and ``out_signs`` may be the inputs themselves.
        """
        log_abs = np.asarray(log_abs, dtype=np.float64)
        signs = np.asarray(signs, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            pos = self.log_apply(np.where(signs > 0, log_abs, -np.inf))
            neg = self.log_apply(np.where(signs < 0, log_abs, -np.inf))
            top = np.maximum(pos, neg)
            live = np.isfinite(top)
            diff = np.where(live, np.exp(pos - np.where(live, top, 0.0))
                            - np.exp(neg - np.where(live, top, 0.0)), 0.0)
            result = np.where(diff != 0, top + np.log(np.abs(diff)), -np.inf)
        out = _output(out, log_abs)
        out_signs = _output(out_signs, log_abs)
        out[...] = result
        out_signs[...] = np.sign(diff)
        return out, out_signs

    def log_apply_one(self, values: NDArray, out: NDArray, signs: NDArray | None = None,
                      out_signs: NDArray | None = None, needed: NDArray | None = None) -> int:
        """The log product of one histogram ``values`` (``self.shape``) into ``out``, in
        the calling thread; signed when ``signs`` is given (signs into ``out_signs``).

        ``needed`` (bool, ``self.shape``): only these results must be exact (the
        others may be left unspecified, possibly ``-inf``). ``out`` may be
        ``values``. Returns how many results were recomputed exactly after a
        first pass (0 by default).
        """
        if signs is None:
            self.log_apply_into(values, out)
        else:
            self.signed_log_apply(values, signs, out, out_signs)
        return 0

    def separable_factors(self) -> list[tuple[NDArray, NDArray]] | None:
        """``[(kernel (n_a, n_a), points (n_a,)), ...]`` per axis when the kernel is the
        product of one-dimensional kernels on axis points (a grid); else None."""
        return None

    def with_grid(self, shape: tuple[int, ...], gamma: float) -> Geometry:
        """The same kind of geometry on a regular grid of ``shape`` with ``gamma``
        (coarse-to-fine solvers). Raises TypeError for geometries that are not grids."""
        raise TypeError(f"{type(self).__name__} is not a regular grid: it cannot be rebuilt on "
                        "another grid")

    def _check_values(self, values: NDArray) -> None:
        if values.ndim < self.ndim or tuple(values.shape[values.ndim - self.ndim :]) != self.shape:
            raise ValueError(
                f"array of shape {values.shape} does not end with the geometry's shape {self.shape}"
            )

