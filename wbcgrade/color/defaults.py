"""Default settings of the colour library, in one light module (no numpy, no OpenImageIO).

:mod:`wbcgrade.color.io.images`, :mod:`wbcgrade.color.mapping.lut` and
:mod:`wbcgrade.color.presets` use these and re-export them; the command line
reads them here, so that the command line's help and its mistakes import no numerics.
"""

from __future__ import annotations

#: Largest image (width x height) decoded by default: 200 megapixels, about 3 GB
#: of float32 RGBA pixels. Larger headers are refused before any decoding (a
#: decompression bomb would otherwise exhaust memory); ``max_image_pixels``
#: or ``WBCGRADE_MAX_IMAGE_PIXELS`` raise it.
DEFAULT_MAX_IMAGE_PIXELS = 200_000_000
#: Nodes per axis of the 3-D LUTs written (``lut_size``).
DEFAULT_LUT_SIZE = 33
#: Width (in bins) of the Gibbs kernel recorded in presets when none is given.
DEFAULT_PRESET_WIDTH = 1.5
#: Fewer of the user's own photos than this say too little of their content and are not
#: used by the set look (a median of four own photos: film looks' worst photo -0.32 in the
#: harness of :data:`wbcgrade.color.look.statistics.OWN_PHOTO_NOISE`).
MIN_OWN_PHOTOS = 6
