"""Float pixels to 8-bit code values, as OpenImageIO converts them, on every core.

OpenImageIO converts float pixels to an 8-bit file's code values in one
thread: 0.25 s of the 0.33 s it took to encode the 16-megapixel sample as a
JPEG. This is the same conversion: the float32 product by 255, rounded,
clamped to [0, 255]; NaN becomes 0. Only exact halves (a product of exactly
k + 0.5) round differently between OpenImageIO releases: 3.0 rounds them up,
3.2 to even; the rule of the installed release is used (the tests compare
value for value with it). Probing OpenImageIO's conversion at run time is not
an option: it starts OpenImageIO's thread pool, which deadlocks the forked
child that encodes JPEGs under a file size limit (``imageio._encode_in_child``).
"""

from __future__ import annotations

import numpy as np

from wbcgrade.core import compiled, in_bands, numpy_first

__all__ = ["to_uint8", "HALVES_TO_EVEN"]


def _halves_to_even() -> bool:
    import OpenImageIO as oiio

    return (oiio.VERSION_MAJOR, oiio.VERSION_MINOR) >= (3, 2)


#: Whether exact halves round to even (OpenImageIO >= 3.2) rather than up.
HALVES_TO_EVEN = _halves_to_even()


@compiled(nogil=True, cache=True)
def _to_uint8(flat: np.ndarray, out: np.ndarray, half_even: bool, lo: int,
              hi: int) -> None:  # pragma: no cover - compiled
    for i in range(lo, hi):
        scaled = np.float64(flat[i] * np.float32(255.0))  # float32 product, as OpenImageIO's
        value = np.rint(scaled) if half_even else np.floor(scaled + 0.5)
        if not value > 0.0:  # negative or NaN
            out[i] = 0
        elif value >= 255.0:
            out[i] = 255
        else:
            out[i] = np.uint8(value)


def to_uint8(pixels: np.ndarray, half_even: bool | None = None) -> np.ndarray:
    """(..., C) float pixels in [0, 1] -> uint8 code values (OpenImageIO's conversion).

    ``half_even``: how exact halves round (default: as the installed
    OpenImageIO, :data:`HALVES_TO_EVEN`).
    """
    flat = np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1)
    half_even = HALVES_TO_EVEN if half_even is None else bool(half_even)
    if numpy_first(_to_uint8, flat.shape[0], _NUMPY_VALUES):
        return _to_uint8_numpy(flat, half_even).reshape(pixels.shape)
    out = np.empty(flat.shape, np.uint8)
    in_bands(_to_uint8, flat.shape[0], flat, out, half_even, min_band=65536)
    return out.reshape(pixels.shape)


#: Values up to which :func:`to_uint8` runs its numpy twin while ``_to_uint8`` has not run
#: in the process (see :func:`wbcgrade.core.numpy_first`).
_NUMPY_VALUES = 4_500_000  # (a 1.5-megapixel photo's three channels)


def _to_uint8_numpy(flat: np.ndarray, half_even: bool) -> np.ndarray:
    """``_to_uint8`` with numpy, value for value."""
    scaled = (flat * np.float32(255.0)).astype(np.float64)
    value = np.rint(scaled) if half_even else np.floor(scaled + 0.5)
    value[~(value > 0.0)] = 0.0  # negative or NaN
    return np.minimum(value, 255.0).astype(np.uint8)
