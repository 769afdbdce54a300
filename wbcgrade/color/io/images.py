"""Read and write photos with OpenImageIO, keeping what a photographer cares about.

Reading applies the EXIF orientation, detects corrupt or truncated files
(OpenImageIO returns pixels for a truncated JPEG and only reports the problem
through ``ImageInput.has_error``), rejects NaN/inf pixels, and keeps the
metadata (EXIF, ICC profile, ...) for writing. A header announcing more pixels
than :func:`max_image_pixels` is refused before decoding. Writing keeps the
format, bit depth and metadata, encodes in memory (so a full disk cannot stop
an encoder half-way: libjpeg would end the process), copies the bytes to a
temporary file in the output folder, checks them (every writer error, the size,
the header read back) and only then renames the file into place; it never
replaces the input or anything that is not a regular file.

Pixel values: integer images (8/16-bit JPEG, PNG, TIFF) are read as
display-encoded values in [0, 1], float images (EXR, float TIFF) as they
are (scene-linear). Which colour space they are in and how they reach the
working space is not this module's business
(:mod:`wbcgrade.color.colorspace`). Orientation and alpha association use
OpenImageIO's own ``ImageBufAlgo.reorient``, ``unpremult`` and ``premult``.
Outputs are checked before any work by :func:`wbcgrade._publish.check_output_path`
(the one output checker); the writers here publish atomically and never
replace an existing file unless ``overwrite``.
"""

from __future__ import annotations

import contextlib
import os
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from wbcgrade._names import readable_name, writable_name, writer_name
from wbcgrade._publish import atomic_path, check_output_path
from wbcgrade.color.defaults import DEFAULT_MAX_IMAGE_PIXELS
from wbcgrade.color.io._quantise import to_uint8
from wbcgrade.color.io.raw import AP0_CHROMATICITIES, is_raw, read_raw
from wbcgrade.core import in_bands
from wbcgrade.errors import InputError, OptionError, first_line
from wbcgrade.limits import MEMORY_BUDGET, check_input_file

__all__ = [
    "Image",
    "read_image",
    "header_pixels",
    "write_image",
    "stage_image",
    "check_image_output",
    "max_image_pixels",
    "set_max_image_pixels",
    "DEFAULT_MAX_IMAGE_PIXELS",
    "orient",
    "WriteOptions",
    "BIT_DEPTHS",
    "output_type",
    "check_write_options",
]

_max_image_pixels: int | None = None

#: Metadata prefixes that are meaningful in any file format.
_GENERIC_PREFIXES = ("Exif", "GPS", "IPTC", "XMP")
_INTEGER_MAX = {"uint8": 255.0, "uint16": 65535.0, "uint32": 4294967295.0,
                "int8": 127.0, "int16": 32767.0, "int32": 2147483647.0}


@dataclass
class Image:
    """A decoded photo.

    Attributes
    ----------
    pixels : (H, W, C) float32
        Display-oriented pixels. Integer formats are scaled to [0, 1]; float
        formats keep their (scene-linear) values.
    spec : oiio.ImageSpec
        The file's spec (format, bit depth, metadata), as read.
    path : Path or None
        Where it came from.
    alpha_channel : int
        Index of the alpha channel in ``pixels``, or -1.
    """

    pixels: np.ndarray
    spec: oiio.ImageSpec
    path: Path | None = None
    alpha_channel: int = -1
    format_name: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def height(self) -> int:
        return self.pixels.shape[0]

    @property
    def width(self) -> int:
        return self.pixels.shape[1]

    @property
    def is_float(self) -> bool:
        """True for float pixel formats (EXR, float TIFF): scene-linear values."""
        return self.spec.format.basetype in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE)

    @property
    def color_channels(self) -> list[int]:
        """Indices of the colour channels (1 for grey, 3 for RGB)."""
        chans = [c for c in range(self.pixels.shape[2]) if c != self.alpha_channel]
        return chans[:3] if len(chans) >= 3 else chans[:1]

    def rgb(self) -> np.ndarray:
        """(H, W, 3) float32 colour values (grey replicated to three channels)."""
        chans = self.color_channels
        if len(chans) == 1:
            return np.repeat(self.pixels[:, :, chans[0]:chans[0] + 1], 3, axis=2)
        if chans == list(range(chans[0], chans[0] + 3)):  # a view: no copy
            return self.pixels[:, :, chans[0]:chans[0] + 3]
        # Fancy indexing gives a channel-planar array; copy it back to pixel order.
        return np.ascontiguousarray(self.pixels[:, :, chans])

    def alpha(self) -> np.ndarray | None:
        """(H, W) float32 alpha, or None."""
        if self.alpha_channel < 0:
            return None
        return self.pixels[:, :, self.alpha_channel]


#: OpenImageIO before 3.2 swaps EXIF orientations 5 and 7 in ``reorient``
#: (OpenImageIO issue #4661, fixed by PR #5350).
_REORIENT_SWAPS_5_7 = (oiio.VERSION_MAJOR, oiio.VERSION_MINOR) < (3, 2)


def _buffer(pixels: np.ndarray, alpha_channel: int = -1) -> oiio.ImageBuf:
    """An ImageBuf holding (H, W, C) float32 pixels (alpha channel marked)."""
    buf = oiio.ImageBuf(np.ascontiguousarray(pixels, dtype=np.float32))
    if alpha_channel >= 0:
        buf.specmod().alpha_channel = int(alpha_channel)
    return buf


def _pixels(buf: oiio.ImageBuf, what: str) -> np.ndarray:
    if buf.has_error:
        raise InputError(f"{what} failed ({first_line(buf.geterror())})")
    out = np.asarray(buf.get_pixels(oiio.FLOAT), dtype=np.float32)
    return out.reshape(buf.spec().height, buf.spec().width, buf.spec().nchannels)


def orient(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """Apply an EXIF orientation (1..8) to (H, W, C) stored pixels -> display pixels
    (OpenImageIO's ``ImageBufAlgo.reorient``, on the calling thread)."""
    orientation = int(orientation) if 1 <= int(orientation) <= 8 else 1
    if orientation == 1:
        return pixels
    if _REORIENT_SWAPS_5_7 and orientation in (5, 7):
        orientation = 12 - orientation
    buf = _buffer(pixels)
    buf.specmod().attribute("Orientation", orientation)
    return _pixels(oiio.ImageBufAlgo.reorient(buf, nthreads=1), "reorienting the image")


def max_image_pixels() -> int:
    """The pixel count (width x height) above which :func:`read_image` refuses a file.

    :func:`set_max_image_pixels` wins, then ``$WBCGRADE_MAX_IMAGE_PIXELS``,
    then :data:`DEFAULT_MAX_IMAGE_PIXELS`.
    """
    if _max_image_pixels is not None:
        return _max_image_pixels
    text = os.environ.get("WBCGRADE_MAX_IMAGE_PIXELS", "").strip()
    if text:
        try:
            value = int(float(text))
        except ValueError:
            raise InputError(f"WBCGRADE_MAX_IMAGE_PIXELS={text!r} is not a number") from None
        if value >= 1:
            return value
        raise InputError(f"WBCGRADE_MAX_IMAGE_PIXELS={text!r} must be at least 1")
    return DEFAULT_MAX_IMAGE_PIXELS


def set_max_image_pixels(limit: int | None) -> None:
    """Set the decoding limit of this process (None: back to the environment/default)."""
    global _max_image_pixels
    if limit is not None and int(limit) < 1:
        raise InputError("the image pixel limit must be at least 1")
    _max_image_pixels = None if limit is None else int(limit)


#: Bytes a command spends on each pixel of a photo it reads (decoded values, the working
#: copies, the graded pixels, a report's sheet; measured: ``apply`` about 35, ``report``
#: about 78).
WORK_BYTES_PER_PIXEL = 80
#: Pixels per byte of file beyond which a photo whose work would pass the memory budget
#: is taken for a decompression bomb (camera JPEGs hold 1-3 pixels per byte, PNGs fewer;
#: a 571 kB PNG declaring 14000x14000 holds 343).
MAX_PIXELS_PER_FILE_BYTE = 10


def _check_pixel_count(path: Path, width: int, height: int, depth: int = 1) -> None:
    """InputError when the image's pixels are over :func:`max_image_pixels`, or when a small
    file declares more pixels than the memory budget allows (``limits.MEMORY_BUDGET``;
    unless the limit was raised: the file is trusted), before anything is decoded."""
    count = int(width) * int(height) * max(1, int(depth))
    limit = max_image_pixels()
    if count > limit:
        raise InputError(
            f"{path}: {width}x{height} is {count / 1e6:.1f} megapixels, over the "
            f"limit of {limit / 1e6:g} megapixels (a decompression bomb?); raise it with "
            f"{{max_image_pixels}} {count} if the file is trusted",
            fields=("max_image_pixels",))
    if count * WORK_BYTES_PER_PIXEL <= MEMORY_BUDGET or limit != DEFAULT_MAX_IMAGE_PIXELS:
        return
    try:
        size = os.path.getsize(path)
    except OSError:
        return
    if size * MAX_PIXELS_PER_FILE_BYTE < count:
        raise InputError(
            f"{path}: {width}x{height} ({count / 1e6:.1f} megapixels) from a "
            f"{size / 1e3:.0f} kB file could take up to "
            f"{count * WORK_BYTES_PER_PIXEL / 2 ** 30:.1f} GB to grade, more than the "
            f"{MEMORY_BUDGET / 2 ** 30:.1f} GB budget (a decompression bomb?); give "
            f"{{max_image_pixels}} {count} if the file is trusted",
            fields=("max_image_pixels",))


def _open_input(path: Path, config: oiio.ImageSpec | None = None) -> oiio.ImageInput:
    """OpenImageIO's reader of the regular file ``path`` (InputError for anything else: a
    FIFO or device, which could block for ever, or a file only OpenImageIO's synthetic
    ``null`` reader opens, which makes up pixels from the file's name)."""
    check_input_file(path)
    with readable_name(path) as name:  # a non-UTF-8 name: OpenImageIO's binding refuses it
        inp = oiio.ImageInput.open(name, config) if config is not None \
            else oiio.ImageInput.open(name)
    if inp is None:
        raise InputError(f"{path}: not a readable image "
                         f"({first_line(oiio.geterror(), 'unknown format')})")
    if inp.format_name() in _SYNTHETIC_READERS:
        inp.close()
        raise InputError(f"{path}: not a readable image (no image format recognised)")
    return inp


#: OpenImageIO readers that make pixels up instead of reading them from the file.
_SYNTHETIC_READERS = frozenset({"null"})


def image_extensions() -> set[str]:
    """Lower-case file extensions (with the dot) that OpenImageIO can read."""
    text = oiio.get_string_attribute("extension_list")
    exts = set()
    for entry in text.split(";"):
        _, _, names = entry.partition(":")
        exts.update(f".{e.strip().lower()}" for e in names.split(",") if e.strip())
    return exts


def header_pixels(path: str | os.PathLike) -> int:
    """Pixels of the image at ``path`` from its header, nothing decoded (0 when OpenImageIO
    reads no header there: :func:`read_image` says what is wrong with the file)."""
    try:
        inp = _open_input(Path(path))
    except (OSError, RuntimeError, ValueError):  # gone, a folder, a FIFO, not an image
        oiio.geterror()  # (cleared: not this function's error to report)
        return 0
    try:
        spec = inp.spec()
        return max(spec.width, 0) * max(spec.height, 0) * max(spec.depth, 1)
    finally:
        inp.close()


#: Integer pixel formats read as they are stored and scaled to [0, 1] with numpy: the float32
#: values OpenImageIO's own conversion gives (checked bit for bit), in half its time
#: (docs/benchmarks.md).
_INTEGER_SCALES = {oiio.UINT8: ("uint8", np.float32(1 / 255)),
                   oiio.UINT16: ("uint16", np.float32(1 / 65535))}


def _scaled(pixels: np.ndarray, scale: np.float32) -> np.ndarray:
    """``np.multiply(pixels, scale, dtype=np.float32)`` in bands on every core (numpy
    releases the interpreter lock: a 16-megapixel photo's 0.04-0.07 s in 0.02 s), the
    same values."""
    flat = np.ascontiguousarray(pixels).reshape(-1)
    out = np.empty(flat.shape, np.float32)

    def scale_band(lo: int, hi: int) -> None:
        np.multiply(flat[lo:hi], scale, out=out[lo:hi], dtype=np.float32)

    in_bands(scale_band, flat.shape[0], min_band=1 << 22)
    return out.reshape(np.shape(pixels))


#: Rows of 8/16-bit scanlines read at a time and scaled (:func:`_read_scaled`).
_SCALED_ROWS = 128


def _read_scaled(inp: oiio.ImageInput, spec: oiio.ImageSpec, stored: str,
                 scale: np.float32) -> np.ndarray | None:
    """The (H, W, C) float32 pixels of an 8/16-bit scanline image: read
    :data:`_SCALED_ROWS` rows at a time as they are stored and scaled into the float32
    array (``np.multiply(rows, scale, dtype=np.float32)``: :func:`_scaled`'s values),
    while the rows are in the cache; no full-size array of stored integers (a
    16-megapixel JPEG's 48 MB, fresh pages of the kernel's, and a pass over them). None
    when a read fails (the reader says why)."""
    height, width, channels = spec.height, spec.width, spec.nchannels
    out = np.empty((height, width, channels), np.float32)
    for lo in range(0, height, _SCALED_ROWS):
        hi = min(lo + _SCALED_ROWS, height)
        rows = inp.read_scanlines(0, 0, spec.y + lo, spec.y + hi, spec.z, 0, channels, stored)
        if rows is None or inp.has_error:
            return None
        np.multiply(np.asarray(rows).reshape(hi - lo, width, channels), scale,
                    out=out[lo:hi], dtype=np.float32)
    return out


def read_image(path: str | os.PathLike) -> Image:
    """Read a photo.

    Parameters
    ----------
    path : path of a JPEG, PNG, TIFF (8/16-bit or float), EXR, ... file.

    Returns
    -------
    Image with display-oriented float32 pixels (H, W, C).

    Raw camera files (DNG, CR2, NEF, ARW, ...) are demosaiced by LibRaw
    (:func:`wbcgrade.color.io.raw.read_raw`): scene-linear float pixels. CMYK
    JPEGs come back as RGB (through their CMYK ICC profile when they carry
    one), without the CMYK profile.

    Raises
    ------
    InputError
        Missing file, not an image, corrupt or truncated data, no colour
        channel, NaN or infinite pixels, more pixels than
        :func:`max_image_pixels` (checked from the header, before decoding).
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not an image")
    if is_raw(path):
        return _read_raw(path)
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # keep PNG/TIFF colours as stored
    inp = _open_input(path, config)
    try:
        spec = inp.spec()
        if spec.width <= 0 or spec.height <= 0 or spec.nchannels <= 0:
            raise InputError(f"{path}: empty image")
        _check_pixel_count(path, spec.width, spec.height, spec.depth)
        if spec.depth > 1:
            raise InputError(f"{path}: volume images are not supported")
        native = _INTEGER_SCALES.get(spec.format.basetype) if not spec.channelformats else None
        if native and spec.tile_width <= 0:  # scanlines: scaled as they are decoded
            pixels = _read_scaled(inp, spec, *native)
        else:
            pixels = inp.read_image(0, 0, 0, spec.nchannels, native[0] if native else "float")
        if pixels is None or inp.has_error:
            raise InputError(f"{path}: corrupt or truncated image "
                             f"({first_line(inp.geterror(), 'read failed')})")
        format_name = inp.format_name()
        spec = oiio.ImageSpec(spec)
    finally:
        inp.close()
    if native and pixels.dtype != np.float32:  # integers scaled here: the same float32
        pixels = _scaled(pixels, native[1])  # values, in half the time
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    if not native and not np.isfinite(pixels).all():
        raise InputError(f"{path}: image holds NaN or infinite pixel values")
    if _is_cmyk(spec):
        pixels, spec = _from_cmyk(path, pixels, spec)
    orientation = spec.get_int_attribute("Orientation", 1)
    pixels = np.ascontiguousarray(orient(pixels, orientation))
    alpha = spec.alpha_channel if 0 <= spec.alpha_channel < pixels.shape[2] else -1
    if alpha < 0 and spec.alpha_channel >= pixels.shape[2] and pixels.shape[2] in (2, 4):
        alpha = pixels.shape[2] - 1  # GIF: OpenImageIO counts its alpha as channel 4 of 4
    names = tuple(spec.channelnames)
    if alpha < 0 and spec.nchannels in (2, 4) and (
        format_name == "png" or (names and str(names[-1]).upper() in ("A", "ALPHA"))
    ):
        alpha = spec.nchannels - 1  # grey+alpha or RGBA without an explicit alpha name
    if alpha >= 0 and not spec.get_int_attribute("oiio:UnassociatedAlpha", 0):
        # EXR and associated TIFF store colour * alpha; in memory colour is unassociated.
        pixels = _pixels(oiio.ImageBufAlgo.unpremult(_buffer(pixels, alpha), nthreads=1),
                         f"{path}: dividing by alpha")
    return Image(pixels=pixels, spec=spec, path=path, alpha_channel=int(alpha),
                 format_name=format_name)


def _read_raw(path: Path) -> Image:
    """A raw camera file as a scene-linear float image tagged with the ACES AP0 primaries
    (:func:`wbcgrade.color.io.raw.read_raw`; the pixel limit checked before demosaicing)."""
    pixels, extra = read_raw(path, lambda width, height: _check_pixel_count(path, width, height))
    height, width = pixels.shape[:2]
    spec = oiio.ImageSpec(width, height, 3, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B")
    spec.attribute("chromaticities", oiio.TypeDesc("float[8]"), AP0_CHROMATICITIES)
    return Image(pixels=pixels, spec=spec, path=path, alpha_channel=-1, format_name="raw",
                 extra=extra)


def _icc_bytes(spec: oiio.ImageSpec) -> bytes | None:
    value = spec.getattribute("ICCProfile")
    return None if value is None else np.asarray(value, dtype=np.uint8).tobytes()


def _is_cmyk(spec: oiio.ImageSpec) -> bool:
    """Whether the file stored CMYK (OpenImageIO hands such JPEGs over as RGB)."""
    icc = _icc_bytes(spec)
    return (spec.get_string_attribute("jpeg:ColorSpace", "").upper() == "CMYK"
            or (icc is not None and icc[16:20] == b"CMYK"))


def _from_cmyk(path: Path, pixels: np.ndarray,
               spec: oiio.ImageSpec) -> tuple[np.ndarray, oiio.ImageSpec]:
    """RGB pixels and an RGB spec for a CMYK file.

    With a usable CMYK ICC profile the stored CMYK values are converted to
    sRGB by LittleCMS (Pillow's ``ImageCms``, relative colorimetric intent);
    otherwise OpenImageIO's own conversion (``(1 - C)(1 - K)``, ...) is kept.
    Either way the CMYK profile and the CMYK tag are dropped: the pixels
    are sRGB now.
    """
    icc = _icc_bytes(spec)
    if icc is not None and icc[16:20] == b"CMYK" and _valid_icc(spec.getattribute("ICCProfile")):
        converted = _cmyk_through_profile(path, icc, pixels.shape)
        if converted is not None:
            pixels = converted
    clean = oiio.ImageSpec(spec.width, spec.height, pixels.shape[2], spec.format)
    clean.channelnames = ("R", "G", "B")[:pixels.shape[2]] if pixels.shape[2] <= 3 \
        else spec.channelnames
    for attrib in spec.extra_attribs:
        if attrib.name == "ICCProfile" or attrib.name.startswith("ICCProfile:") \
                or attrib.name == "jpeg:ColorSpace":
            continue
        with contextlib.suppress(TypeError, ValueError, RuntimeError):
            clean.attribute(attrib.name, attrib.type, attrib.value)
    return pixels, clean


def _cmyk_through_profile(path: Path, icc: bytes, shape: tuple) -> np.ndarray | None:
    """The file's CMYK pixels converted to sRGB through its profile, or None if that fails."""
    import io

    try:
        from PIL import Image as PILImage
        from PIL import ImageCms
    except ImportError:  # pragma: no cover - pillow is a dependency
        return None
    try:
        with PILImage.open(path) as picture:
            if picture.mode != "CMYK" or (picture.height, picture.width) != shape[:2]:
                return None
            source = ImageCms.ImageCmsProfile(io.BytesIO(icc))
            rgb = ImageCms.profileToProfile(
                picture, source, ImageCms.createProfile("sRGB"),
                renderingIntent=ImageCms.Intent.RELATIVE_COLORIMETRIC, outputMode="RGB")
            return np.asarray(rgb, dtype=np.float32) / np.float32(255.0)
    except (OSError, ValueError, ImageCms.PyCMSError):
        return None


def check_image_output(out: str | os.PathLike) -> str:
    """Raise InputError unless OpenImageIO can write ``out``'s file type; -> format name."""
    out = Path(out)
    writer = oiio.ImageOutput.create(writer_name(out))
    if writer is None:
        detail = first_line(oiio.geterror(), "")
        raise InputError(f"{out}: cannot write this file type{f' ({detail})' if detail else ''}; "
                         "use e.g. .jpg, .png, .tif or .exr")
    return writer.format_name()


def _valid_icc(value) -> bool:
    """Cheap sanity check of an ICC blob (libpng crashes OpenImageIO on bad ones)."""
    data = np.asarray(value, dtype=np.uint8).tobytes()
    return (len(data) >= 128 and data[36:40] == b"acsp"
            and int.from_bytes(data[0:4], "big") == len(data))


def _output_spec(like: Image, height: int, width: int, nchannels: int,
                 out_format_name: str, alpha_channel: int,
                 pixel_type: oiio.TypeDesc | None = None) -> oiio.ImageSpec:
    pixel_type = like.spec.format if pixel_type is None else pixel_type
    spec = oiio.ImageSpec(width, height, nchannels, pixel_type)
    floats = pixel_type.basetype in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE)
    if nchannels == like.spec.nchannels:
        spec.channelnames = like.spec.channelnames
    elif nchannels >= 3:
        names = ["R", "G", "B"] + [f"channel{i}" for i in range(3, nchannels)]
        if 0 <= alpha_channel < nchannels:
            names[alpha_channel] = "A"
        spec.channelnames = tuple(names)
    spec.alpha_channel = alpha_channel if 0 <= alpha_channel < nchannels else -1
    same_format = out_format_name == like.format_name
    for attrib in like.spec.extra_attribs:
        name = attrib.name
        if name == "Orientation" or name.startswith("ICCProfile:"):
            continue
        if name == "ICCProfile":
            if _valid_icc(attrib.value):
                spec.attribute(name, attrib.type, attrib.value)
            continue
        prefix = name.split(":", 1)[0] if ":" in name else ""
        if name.startswith("oiio:") and name != "oiio:ColorSpace":
            continue
        if name == "chromaticities" and floats:  # the primaries of scene-linear values
            spec.attribute(name, attrib.type, attrib.value)
            continue
        if not same_format and prefix not in _GENERIC_PREFIXES and name not in (
                "Make", "Model", "Software", "Artist", "Copyright", "ImageDescription",
                "DateTime", "XResolution", "YResolution", "ResolutionUnit"):
            continue
        try:
            spec.attribute(name, attrib.type, attrib.value)
        except (TypeError, ValueError, RuntimeError):
            continue  # an attribute the binding cannot copy: drop it, not the photo
    spec.attribute("Orientation", 1)  # pixels are written display-oriented
    return spec


# ------------------------------------------------------------------ output options
#: ``bit_depth`` choices.
BIT_DEPTHS = ("8", "16", "float")
_DEPTH_TYPES = {"8": oiio.UINT8, "16": oiio.UINT16, "float": oiio.FLOAT}
#: The bit depths each writer holds (OpenImageIO format names); a format not
#: listed gets what it asks for and makes of it what its writer can.
_FORMAT_DEPTHS = {"jpeg": ("8",), "webp": ("8",), "bmp": ("8",), "targa": ("8",),
                  "png": ("8", "16"), "tiff": ("8", "16", "float"), "openexr": ("16", "float")}
#: Writers with a quality setting -> the prefix of OpenImageIO's ``Compression`` attribute.
_QUALITY_FORMATS = {"jpeg": "jpeg", "webp": "webp"}


@dataclass(frozen=True)
class WriteOptions:
    """How an image is encoded.

    Attributes
    ----------
    quality : 1-100, JPEG and WebP quality (None: for a JPEG, the input's quality when
        it is a JPEG whose quality can be read (:func:`jpeg_quality`), else
        :data:`DEFAULT_JPEG_QUALITY`; WebP: the writer's default); other formats are
        lossless and ignore it.
    bit_depth : "8", "16" or "float" (EXR: "16" is half float), or None:
        the input's where the output format holds it (a raw photo: 16-bit
        integers, float in EXR).
    """

    quality: int | None = None
    bit_depth: str | None = None

    def __post_init__(self) -> None:
        if self.quality is not None and (isinstance(self.quality, bool)
                                         or not 1 <= int(self.quality) <= 100):
            raise OptionError("{quality} must be between 1 and 100", "quality")
        if self.bit_depth is not None and self.bit_depth not in BIT_DEPTHS:
            raise OptionError(f"{{bit_depth}} must be one of {', '.join(BIT_DEPTHS)}", "bit_depth")


#: JPEG quality of an output when the input's cannot be read (not a JPEG, or no tables).
DEFAULT_JPEG_QUALITY = 95
#: The IJG's (libjpeg's) luminance quantisation table at quality 50, in natural (row)
#: order, as Pillow's ``quantization`` gives it.
_IJG_LUMA = (16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55,
             14, 13, 16, 24, 40, 57, 69, 56, 14, 17, 22, 29, 51, 87, 80, 62,
             18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
             49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99)


def jpeg_quality(path: str | os.PathLike | None) -> int | None:
    """The quality (1-100) a JPEG was saved at, estimated from its luminance quantisation
    table (the IJG scale whose table is nearest: exact for libjpeg's, Pillow's, OpenImageIO's
    and most editors' files); None when ``path`` is not a readable JPEG.

    >>> jpeg_quality("samples/chelsea.jpg") is None or 1 <= jpeg_quality("samples/chelsea.jpg")
    True
    """
    if path is None:
        return None
    try:
        from PIL import Image as PILImage

        with PILImage.open(path) as image:  # reads the header only
            if image.format != "JPEG":
                return None
            tables = getattr(image, "quantization", None) or {}
            luma = tables.get(0)
    except Exception:  # noqa: BLE001 - any unreadable file: no quality known
        return None
    if luma is None or len(luma) != 64:
        return None
    table = np.asarray(luma, dtype=np.float64)
    base = np.asarray(_IJG_LUMA, dtype=np.float64)
    best, best_error = None, np.inf
    for quality in range(1, 101):
        scale = 5000 / quality if quality < 50 else 200 - 2 * quality
        scaled = np.clip(np.floor((base * scale + 50) / 100), 1, 255)
        error = float(np.abs(scaled - table).sum())
        if error < best_error:
            best, best_error = quality, error
    return best


def _depth_of(pixel_type: oiio.TypeDesc) -> str:
    if pixel_type.basetype in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE):
        return "float"
    return "8" if pixel_type.basetype in (oiio.UINT8, oiio.INT8) else "16"


def _pixel_type(format_name: str, like: Image, bit_depth: str | None,
                strict: bool = False) -> oiio.TypeDesc:
    """The pixel type written: ``bit_depth`` (else the input's; a raw photo's 16-bit
    integers, float in EXR), or the nearest the format holds (``strict``: OptionError)."""
    held = _FORMAT_DEPTHS.get(format_name)
    raw = bool(like.extra.get("raw"))
    if bit_depth is None and not raw and (held is None or _depth_of(like.spec.format) in held):
        return like.spec.format  # the input's own type (half float stays half)
    wanted = bit_depth or ("float" if raw and format_name == "openexr" else
                           "16" if raw else _depth_of(like.spec.format))
    if held is not None and wanted not in held:
        if strict:
            raise OptionError(f"{{bit_depth}} {bit_depth}: {format_name.upper()} files hold "
                              f"{' or '.join(held)} only", "bit_depth")
        order = {"8": 0, "16": 1, "float": 2}
        wanted = min(held, key=lambda d: abs(order[d] - order[wanted]))
    if format_name == "openexr" and wanted == "16":
        return oiio.TypeDesc(oiio.HALF)
    return oiio.TypeDesc(_DEPTH_TYPES[wanted])


def output_type(path: str | os.PathLike, like: Image,
                options: WriteOptions | None = None) -> oiio.TypeDesc:
    """The pixel type :func:`write_image` writes to ``path`` for an image like ``like``."""
    options = options or WriteOptions()
    return _pixel_type(check_image_output(path), like, options.bit_depth)


def check_write_options(path: str | os.PathLike, options: WriteOptions) -> None:
    """OptionError when ``path``'s format cannot hold ``options.bit_depth`` (before any work)."""
    if options.bit_depth is not None:
        format_name = check_image_output(path)
        like = Image(np.zeros((1, 1, 3), np.float32), oiio.ImageSpec(1, 1, 3, oiio.UINT8))
        _pixel_type(format_name, like, options.bit_depth, strict=True)


#: OpenImageIO formats whose library ends the whole process on a write error
#: (libjpeg's default error handler calls exit()).
_EXITING_FORMATS = frozenset({"jpeg"})


#: Messages of writers that report a failed write only through ``geterror()``.
_WRITE_ERROR = re.compile(r"write error|could only write|no space|file too large|"
                          r"disk full|short write", re.IGNORECASE)


def _encode_into(target: str, path: Path, spec: oiio.ImageSpec, data: np.ndarray) -> None:
    """Encode ``data`` with the writer for ``path``'s type into the file ``target``.

    Every error is checked: the return values and ``has_error`` raise OSError.
    Writers also report some failures only through ``geterror()`` while
    returning success (the PNG writer's short writes), and some harmless
    notes the same way (TIFF's optional EXIF directory): when ``geterror()``
    has anything to say, the whole file is decoded back and must read cleanly.
    """
    oiio.geterror()  # clear stale global errors of this thread
    out = oiio.ImageOutput.create(writer_name(path))
    if out is None:
        raise InputError(f"{path}: cannot write this file type "
                         f"({first_line(oiio.geterror(), 'unknown format')})")
    if not out.open(target, spec):
        raise OSError(f"{path}: cannot open for writing "
                      f"({first_line(out.geterror(), 'unknown error')})")
    ok = out.write_image(data)
    error = out.geterror()
    failed = out.has_error
    closed = out.close()
    error = "\n".join(e for e in (error, out.geterror(), oiio.geterror()) if e.strip())
    if not ok or not closed or failed:
        raise OSError(f"{path}: write failed ({first_line(error, 'unknown error')}; "
                      "disk full or file size limit?)")
    if _WRITE_ERROR.search(error):
        raise OSError(f"{path}: write failed ({first_line(error, 'write error')}; "
                      "disk full or file size limit?)")
    if error.strip():
        _verify_written(target, path, spec, decode=True, note=first_line(error, ""))


def _file_size_limit() -> int | None:
    """The soft RLIMIT_FSIZE of this process in bytes, or None when unlimited."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    except (ImportError, OSError, ValueError):
        return None
    return None if soft == resource.RLIM_INFINITY else int(soft)


def _encode_in_child(fd: int, path: Path, spec: oiio.ImageSpec, data: np.ndarray) -> None:
    """Encode into the memory file ``fd`` in a forked child process.

    Used for formats whose library exits the process on a write error, when a
    file size limit could be reached: the child dies instead of this process,
    which reports an OSError. OpenImageIO's thread pool is stopped while the
    child is forked (``threads`` 1, then restored): the child's ``exit()``
    would otherwise wait forever for pool threads that only the parent has.
    """
    import select
    import signal

    read_end, write_end = os.pipe()
    threads = oiio.get_int_attribute("threads")
    oiio.attribute("threads", 1)
    pid = os.fork()
    if pid != 0:
        oiio.attribute("threads", threads)
    if pid == 0:  # pragma: no cover - child process (coverage does not follow it)
        code = 0
        try:
            os.close(read_end)
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 2)  # libjpeg prints its message before exiting: ours is enough
            _encode_into(f"/proc/self/fd/{fd}", path, spec, data)
        except BaseException as exc:  # noqa: BLE001 - report anything to the parent
            os.write(write_end, str(exc).encode("utf-8", "replace")[:2000])
            code = 3
        os._exit(code)
    os.close(write_end)
    chunks, deadline = [], time.monotonic() + 120 + data.nbytes / 5e6
    try:
        while True:
            ready, _, _ = select.select([read_end], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                os.kill(pid, signal.SIGKILL)
                raise OSError(f"{path}: write failed (the encoder did not finish)")
            chunk = os.read(read_end, 4096)
            if not chunk:
                break
            chunks.append(chunk)
    finally:
        os.close(read_end)
        _, status = os.waitpid(pid, 0)
    message = b"".join(chunks).decode("utf-8", "replace")
    if status != 0:
        if message.startswith(f"{path}: "):
            raise OSError(message)
        raise OSError(f"{path}: write failed ({first_line(message, 'the encoder stopped')}; "
                      "disk full or file size limit?)")


def _encode(path: Path, spec: oiio.ImageSpec, data: np.ndarray, format_name: str) -> int:
    """Encode the image into an anonymous in-memory file; -> its descriptor (caller closes).

    Encoding in memory means a full disk can never stop an encoder half-way
    (libjpeg would end the process); the bytes are copied to disk afterwards
    by Python, whose errors are ordinary exceptions.
    """
    fd = os.memfd_create("wbcgrade-encode", os.MFD_CLOEXEC)
    try:
        limit = _file_size_limit()
        bound = 6 * spec.image_bytes() + (1 << 20)  # worst-case encoded size, metadata
        if format_name in _EXITING_FORMATS and limit is not None and bound > limit:
            _encode_in_child(fd, path, spec, data)
        else:
            _encode_into(f"/proc/self/fd/{fd}", path, spec, data)
    except BaseException:
        os.close(fd)
        raise
    return fd


def _copy_encoded(fd: int, tmp: str, path: Path) -> None:
    """Copy the encoded bytes of ``fd`` into ``tmp``, flush them to disk, check the size."""
    size = os.fstat(fd).st_size
    out = os.open(tmp, os.O_WRONLY | os.O_TRUNC | os.O_CLOEXEC)
    try:
        offset = 0
        while offset < size:
            sent = os.sendfile(out, fd, offset, min(size - offset, 1 << 30))
            if sent == 0:
                break
            offset += sent
        os.fsync(out)
        written = os.fstat(out).st_size
    except OSError as exc:
        raise OSError(f"{path}: write failed ({exc.strerror or exc}; disk full or file size "
                      "limit?)") from None
    finally:
        os.close(out)
    if written != size:
        raise OSError(f"{path}: write failed ({written} of {size} bytes written)")


def _verify_written(tmp: str, path: Path, spec: oiio.ImageSpec, decode: bool = False,
                    note: str = "") -> None:
    """Re-open the written file and check its header (and with ``decode`` its pixels)."""
    why = f" ({note})" if note else ""
    with readable_name(tmp) as name:
        inp = oiio.ImageInput.open(name)
    if inp is None:
        raise OSError(f"{path}: write failed, the file does not read back"
                      f"{why or ' (' + first_line(oiio.geterror(), 'unreadable') + ')'}")
    try:
        got = inp.spec()
        if (got.width, got.height, got.nchannels) != (spec.width, spec.height, spec.nchannels):
            raise OSError(f"{path}: write failed, the file does not read back as written{why}")
        if decode:
            pixels = inp.read_image(0, 0, 0, got.nchannels, got.format)
            if pixels is None or inp.has_error:
                raise OSError(f"{path}: write failed, the file does not decode"
                              f"{why or ' (' + first_line(inp.geterror(), 'corrupt') + ')'}; "
                              "disk full or file size limit?")
    finally:
        inp.close()


def _prepare(path: Path, pixels: np.ndarray, like: Image, alpha_channel: int | None,
             options: WriteOptions | None = None,
             format_name: str | None = None) -> tuple[oiio.ImageSpec, np.ndarray, str]:
    if pixels.ndim != 3:
        raise InputError("pixels must be (H, W, C)")
    options = options or WriteOptions()
    height, width, nchannels = pixels.shape
    format_name = format_name or check_image_output(path)
    alpha = like.alpha_channel if alpha_channel is None else alpha_channel
    spec = _output_spec(like, height, width, nchannels, format_name, alpha,
                        _pixel_type(format_name, like, options.bit_depth))
    quality = options.quality
    if quality is None and format_name == "jpeg":  # the input's quality, else 95
        quality = jpeg_quality(like.path) or DEFAULT_JPEG_QUALITY
    if quality is not None and format_name in _QUALITY_FORMATS:
        spec.erase_attribute("CompressionQuality")  # an input's own setting: not this one
        spec.attribute("Compression", f"{_QUALITY_FORMATS[format_name]}:{quality}")
    if 0 <= alpha < nchannels:
        # In memory colour is unassociated; EXR stores it multiplied by alpha.
        if format_name == "openexr":
            pixels = _pixels(oiio.ImageBufAlgo.premult(_buffer(pixels, alpha), nthreads=1),
                             f"{path}: multiplying by alpha")
        else:
            spec.attribute("oiio:UnassociatedAlpha", 1)
    if spec.format.basetype == oiio.UINT8:  # converted here on every core (OIIO's: one)
        return spec, to_uint8(pixels), format_name
    if spec.format.basetype not in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE):
        pixels = np.clip(pixels, 0.0, 1.0)
    return spec, np.ascontiguousarray(pixels, dtype=np.float32), format_name


@contextlib.contextmanager
def stage_image(path: str | os.PathLike, pixels: np.ndarray, like: Image,
                overwrite: bool = False, alpha_channel: int | None = None,
                options: WriteOptions | None = None, *,
                format_name: str | None = None) -> Iterator[Path]:
    """Write the image to a temporary file; publish it when the ``with`` body succeeds.

    Same arguments as :func:`write_image`; ``path`` was checked before any
    work (:func:`wbcgrade._publish.plan_outputs`), and ``format_name`` is what
    :func:`check_image_output` found then (None: found here). The file is complete and
    checked when the body runs (write other outputs there: if the body
    raises, the image is not published and its temporary file is removed).
    An existing file is replaced only with ``overwrite``.
    """
    path = Path(path)
    spec, data, format_name = _prepare(path, pixels, like, alpha_channel, options, format_name)
    # encoded in memory first where the system can (Linux): see _encode
    fd = _encode(path, spec, data, format_name) if hasattr(os, "memfd_create") else None
    try:
        with atomic_path(path, overwrite=overwrite) as tmp:
            _write_encoded(fd, tmp, path, spec, data)
            yield path
    finally:
        if fd is not None:
            os.close(fd)


def _write_encoded(fd: int | None, tmp: str, path: Path, spec: oiio.ImageSpec,
                   data: np.ndarray) -> None:
    """Fill the temporary file: the bytes encoded in ``fd``, or (no memory files) an
    encoder writing it directly; then check what was written."""
    if fd is None:  # pragma: no cover - not Linux
        with writable_name(tmp) as name:  # a non-UTF-8 folder: see wbcgrade._names
            _encode_into(name, path, spec, data)
    else:
        _copy_encoded(fd, tmp, path)
    _verify_written(tmp, path, spec)


def write_image(path: str | os.PathLike, pixels: np.ndarray, like: Image,
                overwrite: bool = False, alpha_channel: int | None = None,
                options: WriteOptions | None = None) -> Path:
    """Write pixels with the format, bit depth and metadata of ``like``.

    Parameters
    ----------
    path : output file; its extension picks the file format.
    pixels : (H, W, C) float32, same value convention as ``Image.pixels``
        (integer formats: [0, 1], rounded to the nearest code value).
    like : the image whose spec (bit depth, EXIF, ICC, ...) is kept.
    overwrite : replace an existing file (never the input).
    alpha_channel : index of alpha in ``pixels`` (default: ``like``'s).
    options : JPEG/WebP quality and the bit depth (default: ``like``'s where
        the format holds it; :func:`output_type`).

    ``path`` is checked first (:func:`wbcgrade._publish.check_output_path`:
    never ``like``'s own file). The image is encoded in memory, copied to a
    temporary file in the same folder, checked (size, header) and renamed
    into place; a full disk or a file size limit raises OSError and leaves
    nothing behind.
    """
    path = check_output_path(path, [like.path], overwrite)
    with stage_image(path, pixels, like, overwrite, alpha_channel, options) as written:
        pass
    return written
