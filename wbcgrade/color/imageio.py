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

Pixel domains: integer images (8/16-bit JPEG, PNG, TIFF) are treated as
display-encoded values in [0, 1]. Float images (EXR, float TIFF) are treated as
scene-linear and graded in the sRGB-encoded domain (colour-science's sRGB
encoding); see :func:`encode_for_grading` for what happens above 1. That is
the default pair of colour spaces; other input and working spaces go through
OpenColorIO (:mod:`wbcgrade.color.colorspace`), whose state
:func:`decode_from_grading` also accepts.
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

from wbcgrade._publish import atomic_path, check_regular_target
from wbcgrade.errors import InputError

__all__ = [
    "Image",
    "read_image",
    "write_image",
    "stage_image",
    "check_output_path",
    "check_image_output",
    "max_image_pixels",
    "set_max_image_pixels",
    "DEFAULT_MAX_IMAGE_PIXELS",
    "encode_for_grading",
    "decode_from_grading",
    "orient",
]

#: Largest image (width x height) decoded by default: 200 megapixels, about 3 GB
#: of float32 RGBA pixels. Larger headers are refused before any decoding (a
#: decompression bomb would otherwise exhaust memory); ``--max-image-pixels``
#: or ``WBCGRADE_MAX_IMAGE_PIXELS`` raise it.
DEFAULT_MAX_IMAGE_PIXELS = 200_000_000
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


def orient(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """Apply an EXIF orientation (1..8) to (H, W, C) stored pixels -> display pixels."""
    ops = {
        1: lambda a: a,
        2: lambda a: a[:, ::-1],
        3: lambda a: a[::-1, ::-1],
        4: lambda a: a[::-1, :],
        5: lambda a: a.transpose(1, 0, 2),
        6: lambda a: np.rot90(a, k=-1),
        7: lambda a: a[::-1, ::-1].transpose(1, 0, 2),
        8: lambda a: np.rot90(a, k=1),
    }
    return ops.get(int(orientation), ops[1])(pixels)


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


def _check_pixel_count(path: Path, spec: oiio.ImageSpec) -> None:
    count = int(spec.width) * int(spec.height) * max(1, int(spec.depth))
    limit = max_image_pixels()
    if count > limit:
        raise InputError(
            f"{path}: {spec.width}x{spec.height} is {count / 1e6:.1f} megapixels, over the "
            f"limit of {limit / 1e6:g} megapixels (a decompression bomb?); raise it with "
            f"--max-image-pixels {count} if the file is trusted")


def read_image(path: str | os.PathLike) -> Image:
    """Read a photo.

    Parameters
    ----------
    path : path of a JPEG, PNG, TIFF (8/16-bit or float), EXR, ... file.

    Returns
    -------
    Image with display-oriented float32 pixels (H, W, C).

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
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # keep PNG/TIFF colours as stored
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        reason = oiio.geterror().strip().splitlines()
        detail = reason[0] if reason else "unknown format"
        raise InputError(f"{path}: not a readable image ({detail})")
    try:
        spec = inp.spec()
        if spec.width <= 0 or spec.height <= 0 or spec.nchannels <= 0:
            raise InputError(f"{path}: empty image")
        _check_pixel_count(path, spec)
        if spec.depth > 1:
            raise InputError(f"{path}: volume images are not supported")
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        if pixels is None or inp.has_error:
            message = inp.geterror().strip().splitlines()
            detail = message[0] if message else "read failed"
            raise InputError(f"{path}: corrupt or truncated image ({detail})")
        format_name = inp.format_name()
        spec = oiio.ImageSpec(spec)
    finally:
        inp.close()
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    if not np.isfinite(pixels).all():
        raise InputError(f"{path}: image holds NaN or infinite pixel values")
    orientation = spec.get_int_attribute("Orientation", 1)
    pixels = np.ascontiguousarray(orient(pixels, orientation))
    alpha = spec.alpha_channel
    if alpha < 0 and spec.nchannels in (2, 4) and (
        format_name == "png" or str(spec.channelnames[-1]).upper() in ("A", "ALPHA")
    ):
        alpha = spec.nchannels - 1  # grey+alpha or RGBA without an explicit alpha name
    if alpha >= 0 and not spec.get_int_attribute("oiio:UnassociatedAlpha", 0):
        _unpremultiply(pixels, int(alpha))  # EXR and associated TIFF store colour * alpha
    return Image(pixels=pixels, spec=spec, path=path, alpha_channel=int(alpha),
                 format_name=format_name)


def _colour_channels(nchannels: int, alpha: int) -> list[int]:
    return [c for c in range(nchannels) if c != alpha]


def _unpremultiply(pixels: np.ndarray, alpha: int) -> None:
    """Colour / alpha where alpha > 0, in place: pixels hold unassociated colour."""
    a = pixels[:, :, alpha]
    safe = np.where(a > 0, a, 1.0)
    for c in _colour_channels(pixels.shape[2], alpha):
        pixels[:, :, c] /= safe


def _premultiply(pixels: np.ndarray, alpha: int) -> np.ndarray:
    out = pixels.copy()
    for c in _colour_channels(pixels.shape[2], alpha):
        out[:, :, c] *= pixels[:, :, alpha]
    return out


def encode_for_grading(rgb: np.ndarray, is_float: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """Map pixel values into the [0, 1] encoded cube the histograms live in.

    Integer images are already encoded: values are clipped to [0, 1]. Float
    (scene-linear) images go through colour-science's sRGB encoding. Values
    above 1 are handled by exposure: each pixel whose largest channel m exceeds
    1 is divided by m, graded like the in-range colour of the same hue, and
    multiplied back by m in :func:`decode_from_grading`, so highlights keep
    their intensity above 1 and only their colour is graded. Negative values
    are clipped to 0.

    Parameters
    ----------
    rgb : (H, W, 3) float32
    is_float : whether the values are scene-linear floats.

    Returns
    -------
    encoded : (H, W, 3) float32 in [0, 1]
    scale : (H, W, 1) float32 per-pixel exposure factor (>= 1), or None.
    """
    if not is_float:
        return np.clip(rgb, 0.0, 1.0, dtype=np.float32), None
    from wbcgrade.color._colour import colour

    linear = np.maximum(rgb, 0.0)
    scale = np.maximum(linear.max(axis=2, keepdims=True), 1.0).astype(np.float32)
    encoded = colour.cctf_encoding(linear / scale, function="sRGB")
    return np.clip(encoded, 0.0, 1.0).astype(np.float32), scale


def decode_from_grading(encoded: np.ndarray, scale) -> np.ndarray:
    """Inverse of :func:`encode_for_grading` ((H, W, 3) float32 -> pixel values).

    ``scale`` is the second value :func:`encode_for_grading` returned, or the
    state of a colour-managed conversion
    (:func:`wbcgrade.color.colorspace.to_working`), which converts back into
    the photo's own colour space.
    """
    if hasattr(scale, "decode"):  # colorspace.WorkingState
        return scale.decode(encoded)
    if scale is None:
        return encoded.astype(np.float32, copy=False)
    from wbcgrade.color._colour import colour

    linear = colour.cctf_decoding(np.clip(encoded, 0.0, 1.0), function="sRGB")
    return (linear * scale).astype(np.float32)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def check_output_path(out: str | os.PathLike, inputs: list[str | os.PathLike] = (),
                      overwrite: bool = False) -> Path:
    """Check early that ``out`` may be written (before any long computation).

    Raises InputError if ``out`` is one of ``inputs`` (never allowed), exists
    and ``overwrite`` is False, exists and is not a regular file (a device such
    as /dev/null, a pipe, a folder), or its folder is missing or not writable.
    """
    out = Path(out)
    for src in inputs:
        if src is not None and _same_file(Path(src), out):
            raise InputError(f"{out}: refusing to overwrite the input file")
    if out.is_dir():
        raise InputError(f"{out}: is a folder")
    check_regular_target(out)
    if out.exists() and not overwrite:
        raise InputError(f"{out}: file exists (use --overwrite to replace it)")
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{folder}: output folder does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{folder}: output folder is not writable")
    return out


def check_image_output(out: str | os.PathLike) -> str:
    """Raise InputError unless OpenImageIO can write ``out``'s file type; -> format name."""
    out = Path(out)
    writer = oiio.ImageOutput.create(str(out))
    if writer is None:
        message = oiio.geterror().strip().splitlines()
        detail = f" ({message[0]})" if message else ""
        raise InputError(f"{out}: cannot write this file type{detail}; use e.g. .jpg, .png, "
                         ".tif or .exr")
    return writer.format_name()


def _valid_icc(value) -> bool:
    """Cheap sanity check of an ICC blob (libpng crashes OpenImageIO on bad ones)."""
    data = np.asarray(value, dtype=np.uint8).tobytes()
    return (len(data) >= 128 and data[36:40] == b"acsp"
            and int.from_bytes(data[0:4], "big") == len(data))


def _output_spec(like: Image, height: int, width: int, nchannels: int,
                 out_format_name: str, alpha_channel: int) -> oiio.ImageSpec:
    spec = oiio.ImageSpec(width, height, nchannels, like.spec.format)
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


#: OpenImageIO formats whose library ends the whole process on a write error
#: (libjpeg's default error handler calls exit()).
_EXITING_FORMATS = frozenset({"jpeg"})


def _first_line(text: str, default: str) -> str:
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return lines[0] if lines else default


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
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise InputError(f"{path}: cannot write this file type "
                         f"({_first_line(oiio.geterror(), 'unknown format')})")
    if not out.open(target, spec):
        raise OSError(f"{path}: cannot open for writing "
                      f"({_first_line(out.geterror(), 'unknown error')})")
    ok = out.write_image(data)
    error = out.geterror()
    failed = out.has_error
    closed = out.close()
    error = "\n".join(e for e in (error, out.geterror(), oiio.geterror()) if e.strip())
    if not ok or not closed or failed:
        raise OSError(f"{path}: write failed ({_first_line(error, 'unknown error')}; "
                      "disk full or file size limit?)")
    if _WRITE_ERROR.search(error):
        raise OSError(f"{path}: write failed ({_first_line(error, 'write error')}; "
                      "disk full or file size limit?)")
    if error.strip():
        _verify_written(target, path, spec, decode=True, note=_first_line(error, ""))


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
    which reports an OSError.
    """
    import select
    import signal

    read_end, write_end = os.pipe()
    pid = os.fork()
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
        raise OSError(f"{path}: write failed ({_first_line(message, 'the encoder stopped')}; "
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
    inp = oiio.ImageInput.open(tmp)
    if inp is None:
        raise OSError(f"{path}: write failed, the file does not read back"
                      f"{why or ' (' + _first_line(oiio.geterror(), 'unreadable') + ')'}")
    try:
        got = inp.spec()
        if (got.width, got.height, got.nchannels) != (spec.width, spec.height, spec.nchannels):
            raise OSError(f"{path}: write failed, the file does not read back as written{why}")
        if decode:
            pixels = inp.read_image(0, 0, 0, got.nchannels, got.format)
            if pixels is None or inp.has_error:
                raise OSError(f"{path}: write failed, the file does not decode"
                              f"{why or ' (' + _first_line(inp.geterror(), 'corrupt') + ')'}; "
                              "disk full or file size limit?")
    finally:
        inp.close()


def _prepare(path: Path, pixels: np.ndarray, like: Image,
             alpha_channel: int | None) -> tuple[oiio.ImageSpec, np.ndarray, str]:
    if pixels.ndim != 3:
        raise InputError("pixels must be (H, W, C)")
    height, width, nchannels = pixels.shape
    format_name = check_image_output(path)
    alpha = like.alpha_channel if alpha_channel is None else alpha_channel
    spec = _output_spec(like, height, width, nchannels, format_name, alpha)
    if 0 <= alpha < nchannels:
        # In memory colour is unassociated; EXR stores it multiplied by alpha.
        if format_name == "openexr":
            pixels = _premultiply(pixels, alpha)
        else:
            spec.attribute("oiio:UnassociatedAlpha", 1)
    if spec.format.basetype == oiio.UINT8:  # converted here on every core (OIIO's: one)
        from wbcgrade.color._quantise import to_uint8

        return spec, to_uint8(pixels), format_name
    if spec.format.basetype not in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE):
        pixels = np.clip(pixels, 0.0, 1.0)
    return spec, np.ascontiguousarray(pixels, dtype=np.float32), format_name


@contextlib.contextmanager
def stage_image(path: str | os.PathLike, pixels: np.ndarray, like: Image,
                overwrite: bool = False, alpha_channel: int | None = None) -> Iterator[Path]:
    """Write the image to a temporary file; publish it when the ``with`` body succeeds.

    Same arguments as :func:`write_image`. The file is complete and checked
    when the body runs (write other outputs there: if the body raises, the
    image is not published and its temporary file is removed).
    """
    path = check_output_path(path, [like.path], overwrite)
    spec, data, format_name = _prepare(path, pixels, like, alpha_channel)
    if not hasattr(os, "memfd_create"):  # pragma: no cover - not Linux
        with atomic_path(path, overwrite=overwrite) as tmp:
            _encode_into(tmp, path, spec, data)
            _verify_written(tmp, path, spec)
            yield path
        return
    fd = _encode(path, spec, data, format_name)
    try:
        with atomic_path(path, overwrite=overwrite) as tmp:
            _copy_encoded(fd, tmp, path)
            _verify_written(tmp, path, spec)
            yield path
    finally:
        os.close(fd)


def write_image(path: str | os.PathLike, pixels: np.ndarray, like: Image,
                overwrite: bool = False, alpha_channel: int | None = None) -> Path:
    """Write pixels with the format, bit depth and metadata of ``like``.

    Parameters
    ----------
    path : output file; its extension picks the file format.
    pixels : (H, W, C) float32, same value convention as ``Image.pixels``
        (integer formats: [0, 1], rounded to the nearest code value).
    like : the image whose spec (bit depth, EXIF, ICC, ...) is kept.
    overwrite : replace an existing file (never the input).
    alpha_channel : index of alpha in ``pixels`` (default: ``like``'s).

    The image is encoded in memory, copied to a temporary file in the same
    folder, checked (size, header) and renamed into place; a full disk or a
    file size limit raises OSError and leaves nothing behind.
    """
    with stage_image(path, pixels, like, overwrite, alpha_channel) as written:
        pass
    return written
