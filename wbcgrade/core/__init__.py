"""The mathematical core: arrays in, arrays and small result objects out.

No files, no printing, no colours: geometry and grid resampling, barycenter
(+ gradient; debiased), losses (masked ones too), Sinkhorn (single-grid and
multiscale) and barycentric coordinates; and the tools the domains' own
kernels use: ``compiled`` (numba with a cache that never fails a run),
``in_bands`` (a kernel over bands of rows on every core), ``fast_cpu``,
``single_threaded_blas`` and ``n_workers`` (the core's threads; docs/architecture.md,
threads).
"""

from wbcgrade.core._barycenter_debiased import debiased_barycenter
from wbcgrade.core._cpu import fast_cpu, n_workers, single_threaded_blas
from wbcgrade.core._jit import (
    compiled,
    compiled_preferred,
    in_bands,
    num_threads,
    numpy_first,
    prefer_compiled,
)
from wbcgrade.core.barycenter import (
    BarycenterResult,
    BarycenterSolver,
    barycenter,
    barycenter_gradient,
    gradient_memory,
)
from wbcgrade.core.coordinates import (
    CoordinatesResult,
    barycentric_coordinates,
    mixture_coordinates,
    softmax,
)
from wbcgrade.core.geometry import (
    DenseGeometry,
    Geometry,
    GridGeometry,
    refine_grid,
    resample_grid,
)
from wbcgrade.core.losses import LOSSES, Loss, get_loss, register_loss
from wbcgrade.core.masked import RowSubsetGeometry, masked_loss
from wbcgrade.core.multiscale import multiscale_sinkhorn
from wbcgrade.core.sinkhorn import SinkhornResult, barycentric_projection, sinkhorn

__all__ = [
    "Geometry",
    "GridGeometry",
    "DenseGeometry",
    "refine_grid",
    "resample_grid",
    "barycenter",
    "barycenter_gradient",
    "BarycenterSolver",
    "BarycenterResult",
    "debiased_barycenter",
    "barycentric_coordinates",
    "mixture_coordinates",
    "CoordinatesResult",
    "softmax",
    "Loss",
    "LOSSES",
    "get_loss",
    "register_loss",
    "sinkhorn",
    "multiscale_sinkhorn",
    "SinkhornResult",
    "barycentric_projection",
    "gradient_memory",
    "RowSubsetGeometry",
    "masked_loss",
    "compiled",
    "compiled_preferred",
    "in_bands",
    "num_threads",
    "numpy_first",
    "prefer_compiled",
    "fast_cpu",
    "single_threaded_blas",
    "n_workers",
]
