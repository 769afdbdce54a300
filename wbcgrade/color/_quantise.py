"""Float pixels to 8-bit code values, as OpenImageIO converts them, on every core.

OpenImageIO converts float pixels to an 8-bit file's code values in one
thread: 0.25 s of the 0.33 s it took to encode the 16-megapixel sample as a
JPEG. This is the same conversion (tested value for value against
OpenImageIO's): the float32 product by 255, rounded half up, clamped to
[0, 255]; NaN becomes 0.
"""

from __future__ import annotations

import numba
import numpy as np

from wbcgrade.core._jit import compiled

__all__ = ["to_uint8"]


@compiled(parallel=True, cache=True)
def _to_uint8(flat: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    for i in numba.prange(flat.shape[0]):
        scaled = flat[i] * np.float32(255.0)  # float32 product, as OpenImageIO's
        value = np.floor(np.float64(scaled) + 0.5)
        if not value > 0.0:  # negative or NaN
            out[i] = 0
        elif value >= 255.0:
            out[i] = 255
        else:
            out[i] = np.uint8(value)


def to_uint8(pixels: np.ndarray) -> np.ndarray:
    """(..., C) float pixels in [0, 1] -> uint8 code values (OpenImageIO's conversion)."""
    flat = np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1)
    out = np.empty(flat.shape, np.uint8)
    _to_uint8(flat, out)
    return out.reshape(pixels.shape)
