"""Atomic file writing: a temporary file beside the target, renamed into place."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from wbcgrade.errors import InputError


def _read_umask() -> int:
    # Read once, at import: os.umask can only be read by setting it, which is
    # not safe once other threads create files.
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def _umask() -> int:
    return _UMASK


def _publish(tmp: str, target: Path, overwrite: bool) -> None:
    """Move the finished temporary file onto ``target``.

    Without ``overwrite`` a hard link publishes it only if ``target`` still
    does not exist (a file that appeared during a long grade is never
    replaced); filesystems without hard links fall back to a last check.
    """
    if overwrite:
        os.replace(tmp, target)
        return
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise InputError(f"{target}: file exists (use --overwrite to replace it)") from None
    except OSError:
        if target.exists():
            raise InputError(f"{target}: file exists (use --overwrite to replace it)") from None
        os.replace(tmp, target)
        return
    os.unlink(tmp)


@contextlib.contextmanager
def atomic_path(
    target: str | os.PathLike, suffix: str = "", overwrite: bool = True
) -> Iterator[str]:
    """Yield a temporary path in ``target``'s folder; move it onto ``target`` on success.

    The temporary file gets the permissions a new file would get (mkstemp's
    are 0600) and is removed if the body raises. With ``overwrite=False`` an
    existing ``target`` is never replaced (InputError instead).
    """
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=suffix or target.suffix,
                               dir=folder)
    os.close(fd)
    try:
        os.chmod(tmp, 0o666 & ~_umask())
        yield tmp
        _publish(tmp, target, overwrite)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
