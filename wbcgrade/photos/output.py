"""What is written for a graded photo: grey stays grey, scene-linear pixels in integer files
are display-encoded.

Two decisions between the graded pixels and the file
(:func:`wbcgrade.photos.workflow.grade_file` calls them):

- a grey photo (one colour channel) is written grey: :func:`grey_of` takes
  the luma of its graded colours (a grade may tint it; the tint is dropped);
- scene-linear pixels (an EXR, a raw photo) written into an integer file
  (JPEG, PNG, 8/16-bit TIFF; :func:`wbcgrade.color.io.images.output_type`)
  are converted from their linear space into sRGB-encoded Rec.709, as an
  integer file without a profile is read (:func:`output_pixels`). Float
  files keep the linear values (and their primaries).
"""

from __future__ import annotations

import os

import numpy as np

from wbcgrade.color.colorspace import (
    REC709_LUMA,
    SYCC_LUMA,
    ColorEncoding,
    convert,
    default_working_space,
)
from wbcgrade.color.io.images import Image, WriteOptions, output_type

__all__ = ["grey_of", "output_pixels"]


def grey_of(rgb: np.ndarray, linear: bool = False) -> np.ndarray:
    """(..., 3) colours -> (...,) grey: sYCC luma of encoded values, or with ``linear``
    the Rec.709 luminance of linear ones."""
    weights = np.asarray(REC709_LUMA if linear else SYCC_LUMA, dtype=np.float32)
    return np.asarray(rgb, dtype=np.float32) @ weights


def output_pixels(pixels: np.ndarray, alpha_channel: int, image: Image,
                  encoding: ColorEncoding, path: str | os.PathLike,
                  options: WriteOptions | None = None) -> np.ndarray:
    """The pixels to write to ``path``: graded pixels of ``image`` (its value convention).

    Float pixels written into an integer file are converted from
    ``encoding.input`` (their linear space) into sRGB-encoded Rec.709;
    anything else is returned as it is. Alpha and extra channels pass.
    """
    if not image.is_float:
        return pixels
    kind = output_type(path, image, options).basetype
    import OpenImageIO as oiio

    if kind in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE):
        return pixels
    display = default_working_space()
    chans = [c for c in range(pixels.shape[2]) if c != alpha_channel]
    out = np.array(pixels, dtype=np.float32, copy=True)
    if len(chans) >= 3:
        chans = chans[:3]
        out[:, :, chans] = convert(np.ascontiguousarray(pixels[:, :, chans]), encoding.input,
                                   display)
    elif chans:
        grey = np.repeat(pixels[:, :, chans[0]:chans[0] + 1], 3, axis=2)
        out[:, :, chans[0]] = convert(grey, encoding.input, display)[:, :, 0]
    return out
