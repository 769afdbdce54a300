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
partial target; the lock dies with the process, so
:func:`remove_stale_temporaries` (run before writing into a folder) can tell a
dead run's temporary from one a live run is writing, and removes only the
former.

- :func:`atomic_path`: context manager, the body writes to the yielded path.
- :func:`publish_bytes`: write a ``bytes`` object atomically.
- :func:`write_png`: the PNG writer (8-bit, OpenImageIO) of the BRDF and shape code.
- :func:`check_regular_target`: refuse to replace a device, pipe, socket or folder.
- :func:`check_output_path`: all the checks an output gets before any work,
  the only place outputs are checked; :func:`plan_outputs`: every output of
  a run at once (resolved, never an input, never two outputs in one file).
- :func:`remove_stale_temporaries`, :func:`remove_stale_beside`: remove what
  killed runs left (unlocked temporaries only).
- :func:`lock_folder`: one run's exclusive use of an output folder (``batch``).

One rule for every command: a run never replaces a file it did not write
unless it was asked to (``overwrite``). It is checked before any work
(:func:`check_output_path`) and again when publishing: with
``overwrite=False`` an existing target is never replaced, even one that
appears while the file is being written (published by a hard link, which
fails if the name exists). Outputs are resolved (``realpath``) before they
are checked, so a link cannot lead an output onto an input, and an output
meant to go under a folder (``root``: batch's output tree, a report
folder) must stay under it: a link inside the folder that leads out of it
is refused. See ``docs/architecture.md`` (files and safety).

>>> import os, tempfile
>>> from wbcgrade._publish import check_output_path, publish_bytes
>>> folder = tempfile.mkdtemp()
>>> target = publish_bytes(os.path.join(folder, "a.txt"), b"first")
>>> check_output_path(target)
Traceback (most recent call last):
...
wbcgrade.errors.InputError: ...a.txt: file exists (use --overwrite to replace it)
>>> check_output_path(target, overwrite=True) == target.resolve()
True
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import stat
import tempfile
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from wbcgrade._names import safe_text
from wbcgrade.errors import InputError, first_line

__all__ = ["TEMP_MARK", "LOCK_FILE", "atomic_path", "publish_bytes", "write_png", "encode_png",
           "check_regular_target", "check_folder", "check_output_path", "plan_outputs",
           "make_folders_for",
           "is_unlocked", "remove_stale_temporaries", "remove_stale_beside", "lock_folder"]

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
    except NotADirectoryError:  # a file where a folder of the path should be
        above = next(p for p in target.parents if p.exists())
        raise InputError(f"{above}: is a file, not a folder; cannot write {target} "
                         "under it") from None
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
        return os.path.realpath(a) == os.path.realpath(b) or (
            a.exists() and b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def _inside(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def check_output_path(target: str | os.PathLike, inputs: Iterable[str | os.PathLike] = (),
                      overwrite: bool = False, root: str | os.PathLike | None = None,
                      make_folders: bool = False) -> Path:
    """Check that ``target`` may be written, before any work. -> the resolved target.

    The one output checker. ``target`` is resolved (``os.path.realpath``:
    links followed) and refused (InputError) when it is one of ``inputs``
    (never allowed, ``overwrite`` or not), a folder, an existing file that is
    not a regular one (a device, pipe or socket), an existing file and
    ``overwrite`` is False (a run never replaces what it did not write unless
    asked), or its folder is missing (unless ``make_folders``: then the
    nearest existing one) or not writable. With ``root`` (the folder the
    output belongs under: a batch's output tree, a report folder), the
    resolved target must lie under the resolved ``root``: a link that leads
    out of it is refused.
    """
    given = Path(target)
    resolved = Path(os.path.realpath(given))
    for source in inputs:
        if source is not None and _same_file(Path(source), given):
            raise InputError(f"{given}: refusing to overwrite the input file")
    if root is not None and not _inside(str(resolved), os.path.realpath(root)):
        raise InputError(f"{given}: leads out of the output folder {root} through a link "
                         f"(to {resolved}); refusing to write there")
    check_regular_target(resolved)
    if resolved.exists() and not overwrite:
        raise InputError(f"{given}: file exists (use --overwrite to replace it)")
    folder = resolved.parent
    if make_folders:
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        if folder.exists() and not folder.is_dir():
            raise InputError(f"{folder}: is a file, not a folder; cannot write {given} "
                             "under it")
    if not folder.is_dir():
        raise InputError(f"{check_folder(given)}: output folder does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{given.parent if str(given.parent) else Path('.')}: output folder "
                         "is not writable")
    return resolved


def make_folders_for(*targets: str | os.PathLike | None) -> None:
    """Create the missing folders of ``targets`` (planned with ``make_folders``), just
    before they are written: ``-o new/folder/photo.jpg`` makes ``new/folder``. A file in
    the way is an InputError (a file is never replaced by a folder)."""
    for target in targets:
        if target is None:
            continue
        folder = Path(target).parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except (FileExistsError, NotADirectoryError):
            raise InputError(f"{folder}: is a file, not a folder") from None


def plan_outputs(targets: Iterable[str | os.PathLike | None],
                 inputs: Iterable[str | os.PathLike] = (), overwrite: bool = False,
                 root: str | os.PathLike | None = None,
                 make_folders: bool = False) -> list[Path | None]:
    """Every output of a run checked at once (:func:`check_output_path`), before any work.

    Returns the resolved targets in the same order (None stays None). Two
    targets that resolve to the same file are refused: one run never writes
    a file twice. Temporary files that killed runs left beside them are
    removed (:func:`remove_stale_beside`).
    """
    inputs = [source for source in inputs if source is not None]
    planned: list[Path | None] = []
    seen: dict[Path, Path] = {}
    for target in targets:
        if target is None:
            planned.append(None)
            continue
        resolved = check_output_path(target, inputs, overwrite, root, make_folders)
        if resolved in seen:
            raise InputError(f"{target}: the same file as {seen[resolved]}; every output "
                             "must be a different file")
        seen[resolved] = Path(target)
        planned.append(resolved)
    remove_stale_beside(*(p for p in planned if p is not None and p.parent.is_dir()))
    return planned


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
                overwrite: bool = True, sync: bool = True) -> Iterator[str]:
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
    sync : bool
        False: skip the flushes to disk (a cache entry, which its reader checks and
        rebuilds when a crash damaged it); the rename is atomic all the same.

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
    fd, tmp = tempfile.mkstemp(prefix=f".{safe_text(target.stem)[:100]}{TEMP_MARK}",
                               suffix=safe_text(suffix or target.suffix), dir=folder)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # tells a cleaner this file is live
        os.chmod(tmp, 0o666 & ~_UMASK)
        yield tmp
        if sync:
            _fsync_path(tmp)
        _publish(tmp, target, overwrite)
        if sync:
            _fsync_path(folder, directory=True)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if type(exc) in _PLAIN_OS_ERRORS and exc.errno is not None \
                and exc.filename in (None, tmp):  # a full disk: say which file
            raise type(exc)(exc.errno, exc.strerror, str(target)) from None
        raise
    finally:
        os.close(fd)


#: Errors re-raised naming the target when the writer's own error named no file (or the
#: hidden temporary one): a full disk during ``write()`` says only "[Errno 28]".
_PLAIN_OS_ERRORS = (OSError, PermissionError, FileNotFoundError)


def publish_bytes(target: str | os.PathLike, data: bytes, overwrite: bool = True,
                  sync: bool = True) -> Path:
    """Write ``data`` to ``target`` atomically (see :func:`atomic_path`). -> ``target``."""
    target = Path(target)
    with atomic_path(target, overwrite=overwrite, sync=sync) as tmp, open(tmp, "wb") as handle:
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
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.UINT8)
    publish_bytes(target, encode_png(target, np.ascontiguousarray(pixels), spec),
                  overwrite=overwrite)
    return target


def encode_png(target: str | os.PathLike, pixels: np.ndarray, spec) -> bytes:
    """The PNG file of ``pixels`` (``spec``: an OpenImageIO ImageSpec), encoded in memory.

    Every error of the writer is an OSError naming ``target`` (the PNG writer reports a
    short write only through ``geterror()``); the bytes are then published by Python
    (:func:`publish_bytes`), whose write errors (a full disk, a file size limit) are
    ordinary exceptions: no truncated file is ever published."""
    import OpenImageIO as oiio

    oiio.geterror()  # clear stale errors of this thread
    output = oiio.ImageOutput.create("image.png")
    if output is None:
        raise OSError(f"{target}: cannot create a PNG writer ({first_line(oiio.geterror())})")
    if hasattr(os, "memfd_create"):
        fd = os.memfd_create("wbcgrade-png", os.MFD_CLOEXEC)
        name = f"/proc/self/fd/{fd}"
    else:  # pragma: no cover - not Linux
        fd, name = tempfile.mkstemp(suffix=".png")
    try:
        ok = output.open(name, spec) and output.write_image(pixels)
        error = output.geterror()
        closed = output.close()
        error = "\n".join(e for e in (error, output.geterror(), oiio.geterror()) if e.strip())
        if not ok or not closed or error.strip():
            raise OSError(f"{target}: cannot write the PNG ({first_line(error, 'write error')}; "
                          "disk full or file size limit?)")
        size = os.fstat(fd).st_size
        data = os.pread(fd, size, 0)
        if len(data) != size or not data.startswith(b"\x89PNG"):
            raise OSError(f"{target}: cannot write the PNG (the encoder wrote {len(data)} of "
                          f"{size} bytes)")
        return data
    finally:
        os.close(fd)
        if not name.startswith("/proc/"):  # pragma: no cover - not Linux
            os.unlink(name)


# --------------------------------------------------------------------- stale files, locks

#: Lock file a run keeps in an output folder it has exclusive use of.
LOCK_FILE = ".wbcgrade.lock"
#: A temporary file younger than this is never removed (it may be just created and
#: not yet locked by its writer).
MIN_STALE_AGE_S = 10.0
#: Temporaries of the previous naming (``.<stem>.XXXXXXXX<ext>``, no lock) are removed
#: only when this old.
OLD_PATTERN_AGE_S = 60.0

_TEMP_RE = re.compile(r"^\..*" + re.escape(TEMP_MARK) + r"[A-Za-z0-9_]{8}")
_MKSTEMP_CHARS = "[a-z0-9_]{8}"


def is_unlocked(path: str | os.PathLike, min_age: float = MIN_STALE_AGE_S) -> bool:
    """True when ``path`` is older than ``min_age`` and no live process holds its lock."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or time.time() - info.st_mtime < min_age:
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                return False  # a live run is writing it
            raise
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


def remove_stale_temporaries(folder: str | os.PathLike, targets: Iterable[str] = (),
                             min_age: float = MIN_STALE_AGE_S) -> list[Path]:
    """Remove temporary files that a killed run left in ``folder``; -> removed paths.

    Removes ``.<stem>.wbcgrade-tmp-XXXXXXXX...`` files no live process holds
    locked (and older than ``min_age`` seconds, so a file just being created
    is safe). Temporaries of the previous naming (``.<stem>.XXXXXXXX<ext>``),
    which carry no lock, are removed only for the file names in ``targets``
    and only when older than a minute. Other files are never touched.
    """
    folder = Path(folder)
    old = [re.compile("^" + re.escape(f".{Path(name).stem}.") + _MKSTEMP_CHARS
                      + re.escape(Path(name).suffix) + r"(\.tmp)?$") for name in set(targets)]
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        name = entry.name
        if not name.startswith("."):
            continue
        if _TEMP_RE.match(name):
            age = min_age
        elif any(pattern.match(name) for pattern in old):
            age = max(min_age, OLD_PATTERN_AGE_S)
        else:
            continue
        path = folder / name
        if is_unlocked(path, age):
            with contextlib.suppress(OSError):
                path.unlink()
                removed.append(path)
    return removed


def remove_stale_beside(*targets: Path | None) -> None:
    """:func:`remove_stale_temporaries` in the folder of each output about to be written."""
    for target in targets:
        if target is not None:
            target = Path(target)
            remove_stale_temporaries(target.parent if str(target.parent) else Path("."),
                                     [target.name])


@contextlib.contextmanager
def lock_folder(folder: str | os.PathLike, what: str = "run") -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (a hidden lock file in it) for the body.

    A second run asking for the same folder gets an InputError naming the
    process that holds it. The lock is released when the body ends or the
    process dies (SIGKILL included); the lock file itself is left in place.
    """
    folder = Path(folder)
    path = folder / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o666 & ~_UMASK)
    except OSError as exc:
        raise InputError(f"{folder}: cannot lock the output folder ({exc.strerror})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            holder = os.pread(fd, 64, 0).decode("ascii", "replace").strip()
            who = f" (pid {holder})" if holder.isdigit() else ""
            raise InputError(f"{folder}: another wbcgrade {what}{who} is writing into this "
                             "folder; wait for it to finish or choose another output "
                             "folder") from None
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield path
    finally:
        os.close(fd)
