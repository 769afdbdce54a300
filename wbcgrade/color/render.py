"""Graded pixels of a whole image: the grade applied to every colour channel.

Below the per-photo pipeline (:mod:`wbcgrade.color.grading`) and the file
layer (:mod:`wbcgrade.color.pipeline`), which both call it.
"""

from __future__ import annotations

import numpy as np

from wbcgrade.color.imageio import Image, decode_from_grading, encode_for_grading
from wbcgrade.color.transfer import Grade

__all__ = ["render"]


def render(image: Image, grade: Grade,
           encoded: tuple[np.ndarray, np.ndarray | None] | None = None) -> tuple[np.ndarray, int]:
    """Graded pixels of a whole image at full resolution.

    Colour channels go through the grade (in the encoded domain for float
    images); alpha and any extra channels pass through untouched. A grey
    photo becomes RGB (a grade may tint it). ``encoded`` may pass the
    ``encode_for_grading`` result the caller already has (it is not modified).

    Returns
    -------
    pixels : (H, W, C') float32 in the image's value convention.
    alpha_channel : index of alpha in ``pixels`` or -1.
    """
    pixels, scale = encoded if encoded is not None else encode_for_grading(image.rgb(),
                                                                            image.is_float)
    graded = decode_from_grading(grade.apply(pixels), scale)
    chans = image.color_channels
    if chans == [0, 1, 2] and image.pixels.shape[2] == 3:
        return graded, image.alpha_channel
    if len(chans) == 3:
        out = image.pixels.copy()
        out[:, :, chans] = graded
        return out, image.alpha_channel
    others = [c for c in range(image.pixels.shape[2]) if c not in chans]
    out = np.concatenate([graded, image.pixels[:, :, others]], axis=2)
    alpha = 3 + others.index(image.alpha_channel) if image.alpha_channel in others else -1
    return np.ascontiguousarray(out), alpha
