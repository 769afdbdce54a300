"""Safe file writing: temporary files renamed into place, stale temporaries, folder locks.

Every output goes through :func:`atomic_path`: a hidden temporary file
``.<stem>.wbcgrade-tmp-XXXXXXXX<ext>`` in the target's folder, locked
(``flock``) by the process writing it and renamed onto the target only once
it is complete. A process killed mid-write (SIGKILL, power loss) leaves at
most such a temporary file, never a partial output; the lock dies with the
process, so :func:`remove_stale_temporaries` (run by the next ``apply`` /
``batch`` / ``report`` into the same folder) can tell a dead run's temporary
from one a live run is writing, and removes only the former.

:func:`lock_folder` gives one run exclusive use of an output folder (``batch``).
:func:`atomic_path`, the temporary-file mark and the regular-file check are
:mod:`wbcgrade._publish`'s, shared with the BRDF and shape writers (re-exported
here with the colour-side stale-file cleaner and folder lock).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import stat
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

from wbcgrade._publish import _UMASK, TEMP_MARK, atomic_path, check_regular_target
from wbcgrade.errors import InputError

__all__ = ["atomic_path", "check_regular_target", "remove_stale_temporaries",
           "remove_stale_beside", "is_unlocked", "lock_folder", "TEMP_MARK", "LOCK_FILE"]

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


def _umask() -> int:
    return _UMASK


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
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o666 & ~_umask())
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
