"""Raw camera files (DNG, CR2, NEF, ARW, ...) through LibRaw (the ``rawpy`` binding).

A raw file holds the sensor's mosaic, not an image: LibRaw demosaics it
(AHD), applies the white balance the camera recorded ("as shot"), and
converts the camera's RGB into ACES2065-1 (linear, AP0 primaries, D60)
with the camera's own matrix, with no gamma, no automatic brightening and
16 bits per channel. :func:`read_raw` returns that as scene-linear float
pixels (1.0 = the sensor's white level), which
:func:`wbcgrade.color.io.images.read_image` tags with the AP0 chromaticities,
so the rest of the pipeline treats it like a linear EXR: its input space is ACES2065-1 and, unless
``spaces.working`` says otherwise, it is graded in ACEScct
(:data:`RAW_WORKING_SPACE`), whose cube holds the whole range of a raw.

Writing: float outputs (EXR, float TIFF) keep the linear ACES2065-1
values; integer outputs (JPEG, PNG, 8/16-bit TIFF) are sRGB-encoded
(:func:`wbcgrade.photos.output.output_pixels`); a 16-bit TIFF or PNG is
the default for a raw photo, 8-bit only for JPEG.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from wbcgrade.errors import InputError, first_line

__all__ = ["RAW_SUFFIXES", "RAW_WORKING_SPACE", "RAW_OUTPUT_SUFFIX", "AP0_CHROMATICITIES",
           "is_raw", "read_raw", "output_name"]

#: File endings read as raw camera files (lower case).
RAW_SUFFIXES = frozenset({
    ".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".raf", ".orf",
    ".rw2", ".pef", ".srw", ".raw", ".rwl", ".3fr", ".fff", ".iiq", ".erf", ".kdc", ".dcr",
    ".mrw", ".mos", ".mef", ".x3f", ".gpr",
})
#: The working space of a raw photo when ``spaces.working`` is not given.
RAW_WORKING_SPACE = "acescct"
#: What ``batch`` writes a raw photo as (no writer makes raw files): a 16-bit TIFF.
RAW_OUTPUT_SUFFIX = ".tif"
#: ACES AP0 primaries and white (rx, ry, gx, gy, bx, by, wx, wy), as EXR stores them.
AP0_CHROMATICITIES = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)


def is_raw(path: str | os.PathLike) -> bool:
    """Whether ``path``'s ending names a raw camera file (:data:`RAW_SUFFIXES`)."""
    return Path(path).suffix.lower() in RAW_SUFFIXES


def output_name(path: Path) -> Path:
    """The name of a photo's graded copy in a batch: a raw's as a TIFF, others unchanged."""
    return path.with_suffix(RAW_OUTPUT_SUFFIX) if is_raw(path) else path


def read_raw(path: str | os.PathLike,
             check_size: Callable[[int, int], None] | None = None) -> tuple[np.ndarray, dict]:
    """Demosaic a raw camera file into scene-linear ACES2065-1 pixels.

    Parameters
    ----------
    path : a raw file LibRaw reads (DNG, CR2, CR3, NEF, ARW, RAF, ORF, RW2, ...).
    check_size : ``check_size(width, height)`` called with the sensor's size
        before demosaicing; it raises to refuse the file (a pixel limit).

    Returns
    -------
    pixels : (H, W, 3) float32 linear ACES2065-1 (0 = black level, 1 =
        white level; display-oriented), primaries :data:`AP0_CHROMATICITIES`.
    extra : ``{"raw": {"white_balance": [...], "libraw": "X.Y.Z"}}``.

    :func:`wbcgrade.color.io.images.read_image` wraps this into an image.

    Raises
    ------
    InputError
        The file is not a raw LibRaw reads, or is truncated or corrupt.
    """
    import rawpy

    path = Path(path)
    try:
        with _libraw_messages() as said, rawpy.imread(str(path)) as raw:
            if check_size is not None:
                check_size(int(raw.sizes.width), int(raw.sizes.height))
            multipliers = [float(v) for v in raw.camera_whitebalance]
            rgb = raw.postprocess(output_color=rawpy.ColorSpace.ACES, gamma=(1, 1),
                                  no_auto_bright=True, output_bps=16, use_camera_wb=True,
                                  user_flip=None)
    except rawpy.LibRawError as exc:
        why = _reason(said(), path) or _text(exc) or type(exc).__name__
        raise InputError(f"{path}: not a readable raw file, or truncated or corrupt "
                         f"({why})") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the raw file ({first_line(exc)})") from None
    pixels = np.ascontiguousarray(rgb, dtype=np.float32) / np.float32(65535.0)
    extra = {"raw": {"white_balance": multipliers, "libraw": ".".join(
        str(v) for v in rawpy.libraw_version)}}
    return pixels, extra


def _text(exc: BaseException) -> str:
    """An exception's first line (rawpy's messages are bytes)."""
    value = exc.args[0] if exc.args else ""
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    return first_line(str(value), "")


def _reason(said: str, path: Path) -> str:
    """LibRaw's own words ("Unexpected end of file"), without the file name it prefixes."""
    line = first_line(said, "")
    prefix = f"{path}: "
    return line[len(prefix):] if line.startswith(prefix) else line


@contextlib.contextmanager
def _libraw_messages() -> Iterator[Callable[[], str]]:
    """Catch what LibRaw prints on the process's stderr (its data-error handler writes
    "FILE: Unexpected end of file" there); yields a function returning that text."""
    captured = ""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no stderr to catch: let LibRaw print
        yield lambda: captured
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield lambda: captured
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            captured = sink.read(4096).decode("utf-8", "replace")
