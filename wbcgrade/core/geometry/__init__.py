"""Geometries: where the bins sit and how the Gibbs kernel ``K = exp(-C / gamma)`` acts.

A geometry is the only object that knows how to apply its kernel; solvers
never look inside it (the OTT-JAX split): what a solver may ask of a
geometry is the public interface of :class:`Geometry`, capabilities
included (per-histogram log products, separable factors, coarser grids),
each with a default. Two kinds share it:

- :class:`GridGeometry` (``grid.py``): bins on a regular grid with points at
  ``linspace(0, 1, n)`` on each axis and squared Euclidean cost. The kernel is
  separable, so applying it costs one small matrix product per axis.
- :class:`DenseGeometry` (``dense.py``): an explicit ``(N, N)`` cost matrix
  (for example squared geodesic distances on a sphere).

Both apply the kernel in the scaling domain (``apply``, fast) and in the log
domain (``log_apply``, exact for any dynamic range), and both are symmetric,
which the reverse pass of the barycenter relies on. On grids the log-domain
product is itself made of BLAS products of shifted lines, checked and
repaired where underflow could matter (``logsum.py``); the dense geometry
computes a log-sum-exp per entry. Grid resampling (``resampling.py``):
:func:`resample_grid` for masses, :func:`refine_grid` for function values.
"""

from wbcgrade.core.geometry.base import PARALLEL_BINS, Geometry
from wbcgrade.core.geometry.dense import DenseGeometry
from wbcgrade.core.geometry.grid import GridGeometry
from wbcgrade.core.geometry.resampling import binning_matrix, refine_grid, resample_grid

__all__ = ["Geometry", "GridGeometry", "DenseGeometry", "refine_grid", "resample_grid",
           "binning_matrix", "PARALLEL_BINS"]
