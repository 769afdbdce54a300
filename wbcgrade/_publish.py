"""Publishing files atomically: one implementation for every domain (colour, BRDF, shape).

A file is never written in place. :func:`atomic_path` hands the writer a
temporary file in the target's own folder, with a unique name made by
:func:`tempfile.mkstemp` (``.<stem>.wbcgrade-tmp-XXXXXXXX<ext>``: no two
threads or processes can get the same one), locked (``flock``) by the writing
process while it exists. When the writer is done the data is flushed to disk
(``fsync``) and the temporary file is renamed onto the target
(``os.replace``, atomic on POSIX) and the folder entry flushed too. On any
failure, an exception, ``KeyboardInterrupt`` included, the temporary file is
removed and the target is untouched. A process killed mid-write (SIGKILL,
power loss) leaves at most the hidden, unlocked temporary file, never a
partial target; ``wbcgrade.color._files.remove_stale_temporaries`` recognises
the same names and locks and removes such leftovers.

- :func:`atomic_path`: context manager, the body writes to the yielded path.
- :func:`publish_bytes`: write a ``bytes`` object atomically.
- :func:`write_png`: the PNG writer (8-bit, OpenImageIO) of the BRDF and shape code.
- :func:`check_regular_target`: refuse to replace a device, pipe, socket or folder.
- :func:`check_output_path`: all the checks an output can get before any work.

With ``overwrite=False`` an existing target is never replaced, even one that
appears while the file is being written (published by a hard link, which
fails if the name exists). See ``docs/architecture.md`` (files and safety).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from wbcgrade.errors import InputError

__all__ = ["TEMP_MARK", "atomic_path", "publish_bytes", "write_png", "check_regular_target",
           "check_folder", "check_output_path"]

#: Marks the project's temporary files: ``.<stem>.wbcgrade-tmp-XXXXXXXX<ext>``.
TEMP_MARK = ".wbcgrade-tmp-"


def _read_umask() -> int:
    # Read once, at import: os.umask can only be read by setting it, which is
    # not safe once other threads create files.
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def check_regular_target(target: str | os.PathLike) -> None:
    """Raise InputError when ``target`` exists and is not a regular file.

    A device (``/dev/null``), a FIFO, a socket or a folder would be destroyed
    by a rename onto it.
    """
    target = Path(target)
    try:
        mode = target.stat().st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise InputError(f"{target}: cannot be checked ({exc.strerror})") from None
    if stat.S_ISDIR(mode):
        raise InputError(f"{target}: is a folder")
    if not stat.S_ISREG(mode):
        raise InputError(f"{target}: exists and is not a regular file (a device, pipe or "
                         "socket); refusing to replace it")


def check_folder(target: str | os.PathLike) -> Path:
    """The folder ``target`` goes into; InputError when it does not exist. -> the folder."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{folder}: output folder does not exist")
    return folder


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def check_output_path(target: str | os.PathLike, inputs: Iterable[str | os.PathLike] = (),
                      overwrite: bool = True) -> Path:
    """Check that ``target`` may be written, before any long computation. -> ``Path(target)``.

    Raises InputError when ``target`` is one of ``inputs`` (never allowed), a
    folder, exists and is not a regular file, exists and ``overwrite`` is
    False, or its folder is missing or not writable.
    """
    target = Path(target)
    for source in inputs:
        if source is not None and _same_file(Path(source), target):
            raise InputError(f"{target}: refusing to overwrite the input file")
    check_regular_target(target)
    if target.exists() and not overwrite:
        raise InputError(f"{target}: file exists (use --overwrite to replace it)")
    folder = check_folder(target)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{folder}: output folder is not writable")
    return target


def _fsync_path(path: str | os.PathLike, directory: bool = False) -> None:
    """Flush ``path``'s data (or a folder's entries) to disk; folders: best effort."""
    flags = os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0)
    try:
        fd = os.open(path, flags)
    except OSError:
        if directory:
            return
        raise
    try:
        os.fsync(fd)
    except OSError:
        if not directory:  # some file systems cannot sync folders; the data is synced
            raise
    finally:
        os.close(fd)


def _publish(tmp: str, target: Path, overwrite: bool) -> None:
    """Move the finished temporary file onto ``target``."""
    check_regular_target(target)
    if overwrite:
        os.replace(tmp, target)
        return
    try:
        os.link(tmp, target)  # fails if target appeared meanwhile: never replaced
    except FileExistsError:
        raise InputError(f"{target}: file exists (use --overwrite to replace it)") from None
    except OSError:  # a file system without hard links: a last check, then rename
        if target.exists():
            raise InputError(f"{target}: file exists (use --overwrite to replace it)") from None
        os.replace(tmp, target)
        return
    os.unlink(tmp)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike, suffix: str = "",
                overwrite: bool = True) -> Iterator[str]:
    """Yield a temporary path beside ``target``; on success publish it as ``target``.

    Parameters
    ----------
    target : path-like
        The file to create or replace. Its folder must exist (InputError otherwise).
    suffix : str
        Extension of the temporary file (default: ``target``'s), for writers
        that pick the format by extension.
    overwrite : bool
        False: an existing ``target`` is never replaced (InputError).

    The temporary file exists (empty, permissions as a new file's under the
    umask) when the body starts; the body may write it by path or replace it.
    When the body returns, the file is fsynced, renamed onto ``target`` and
    the folder fsynced. If the body or the publication raises, the temporary
    file is removed and the exception propagates. Safe to use from several
    threads and processes at once (names come from ``tempfile.mkstemp``).
    """
    target = Path(target)
    check_regular_target(target)
    folder = check_folder(target)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem[:100]}{TEMP_MARK}",
                               suffix=suffix or target.suffix, dir=folder)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # tells a cleaner this file is live
        os.chmod(tmp, 0o666 & ~_UMASK)
        yield tmp
        _fsync_path(tmp)
        _publish(tmp, target, overwrite)
        _fsync_path(folder, directory=True)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    finally:
        os.close(fd)


def publish_bytes(target: str | os.PathLike, data: bytes, overwrite: bool = True) -> Path:
    """Write ``data`` to ``target`` atomically (see :func:`atomic_path`). -> ``target``."""
    target = Path(target)
    with atomic_path(target, overwrite=overwrite) as tmp, open(tmp, "wb") as handle:
        handle.write(data)
    return target


def write_png(target: str | os.PathLike, image: np.ndarray, overwrite: bool = True) -> Path:
    """Write an 8-bit PNG atomically with OpenImageIO.

    Parameters
    ----------
    target : path-like
    image : ndarray, shape (H, W), (H, W, 1), (H, W, 3) or (H, W, 4)
        ``uint8`` values as they are, or floats in [0, 1] (rounded to
        ``0..255``, clipped; NaN is refused).
    overwrite : bool

    Returns
    -------
    target : Path

    Raises
    ------
    InputError
        Bad array (shape, NaN) or missing output folder.
    OSError
        OpenImageIO could not write the file (one-line message).
    """
    import OpenImageIO as oiio

    target = Path(target)
    pixels = np.asarray(image)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.ndim != 3 or pixels.shape[2] not in (1, 3, 4) or 0 in pixels.shape:
        raise InputError(f"{target}: a PNG needs an (H, W[, 1|3|4]) image, got {image.shape}")
    if pixels.dtype != np.uint8:
        pixels = np.asarray(pixels, dtype=np.float64)
        if np.isnan(pixels).any():
            raise InputError(f"{target}: the image holds NaN values")
        pixels = np.clip(np.round(pixels * 255.0), 0, 255).astype(np.uint8)
    pixels = np.ascontiguousarray(pixels)
    with atomic_path(target, suffix=".png", overwrite=overwrite) as tmp:
        output = oiio.ImageOutput.create(tmp)
        if output is None:
            raise OSError(f"{target}: cannot create a PNG writer ({_first_line(oiio.geterror())})")
        spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.UINT8)
        ok = output.open(tmp, spec) and output.write_image(pixels)
        error = output.geterror()
        output.close()
        if not ok:
            raise OSError(f"{target}: cannot write the PNG ({_first_line(error)})")
    return target


def _first_line(text: str) -> str:
    lines = str(text).strip().splitlines()
    return lines[0] if lines else "unknown error"
