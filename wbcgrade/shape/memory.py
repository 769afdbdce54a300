"""What a fit needs in memory, and a refusal before it starts when that is too much."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from wbcgrade.core.barycenter import DEFAULT_CHECKPOINT_BYTES, gradient_memory
from wbcgrade.errors import InputError
from wbcgrade.shape.defaults import DEFAULT_N_ITER


def estimate_memory(
    shape: Sequence[int],
    n_shapes: int,
    n_iter: int = DEFAULT_N_ITER,
    checkpoint_bytes: int = DEFAULT_CHECKPOINT_BYTES,
) -> int:
    """Bytes a fit needs, roughly: the core's gradient (working arrays and stored
    scalings, :func:`wbcgrade.core.barycenter.gradient_memory`) plus the inputs,
    the voxelisation and the outputs (about S + 8 volumes).
    """
    n_voxels = int(np.prod([int(n) for n in shape], dtype=np.float64))
    core = gradient_memory(n_voxels, int(n_shapes), int(n_iter), int(checkpoint_bytes))
    return int(core + 8 * n_voxels * (int(n_shapes) + 8))


def available_memory() -> int | None:
    """Bytes of memory available to this process (Linux ``MemAvailable``), or None."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(
    shape: Sequence[int],
    n_shapes: int,
    n_iter: int = DEFAULT_N_ITER,
    available: int | None = None,
) -> int:
    """Refuse a fit that would not fit in memory; return the estimate in bytes.

    Raises :class:`InputError` when the estimate exceeds 80% of the available
    memory (``available`` bytes, default: what the system reports).
    """
    needed = estimate_memory(shape, n_shapes, n_iter)
    if available is None:
        available = available_memory()
    if available is not None and needed > 0.8 * available:
        dims = "x".join(str(int(n)) for n in shape)
        raise InputError(
            f"a {dims} grid with {n_shapes} shapes needs about {needed / 2**30:.1f} GiB, "
            f"more than the {available / 2**30:.1f} GiB available; lower --resolution"
        )
    return needed
