"""File names that are not UTF-8: what OpenImageIO's Python binding can be given instead.

POSIX file names are bytes; Python hands the ones that are not UTF-8 over as
``str`` holding lone surrogates (``'caf\\udce9.jpg'``), which OpenImageIO's
binding refuses with a ``TypeError``. Python's own file functions take them,
so only the calls into OpenImageIO need another name:

- :func:`readable_name`, :func:`writable_name`: ``/proc/self/fd/N`` of the
  file opened here (for reading OpenImageIO then picks the format from the
  contents);
- :func:`writer_name`: for choosing a writer (``ImageOutput.create`` looks at
  the extension only), a stand-in with the same extension;
- :func:`safe_text`: a name as text that can be printed and passed on
  (the undecodable bytes as ``\\xNN``), for temporary file names.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

__all__ = ["is_utf8", "readable_name", "writable_name", "writer_name", "safe_text"]


def is_utf8(name: str | os.PathLike) -> bool:
    """Whether ``name`` encodes as UTF-8 (no undecodable bytes)."""
    try:
        os.fspath(name).encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def safe_text(name: str | os.PathLike) -> str:
    """``name`` with its undecodable bytes written ``\\xNN`` (plain UTF-8 text)."""
    text = os.fspath(name)
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


@contextlib.contextmanager
def _fd_name(path: str | os.PathLike, flags: int) -> Iterator[str]:
    """``path`` itself when it is UTF-8, else ``/proc/self/fd/N`` of it opened with ``flags``."""
    if is_utf8(path) or not os.path.exists("/proc/self/fd"):
        yield os.fspath(path)
        return
    fd = os.open(path, flags)
    try:
        yield f"/proc/self/fd/{fd}"
    finally:
        os.close(fd)


def readable_name(path: str | os.PathLike) -> contextlib.AbstractContextManager[str]:
    """A name OpenImageIO can open for reading ``path``, valid inside the ``with``."""
    return _fd_name(path, os.O_RDONLY)


def writable_name(path: str | os.PathLike) -> contextlib.AbstractContextManager[str]:
    """A name OpenImageIO can open for writing the existing file ``path`` (an
    :func:`~wbcgrade._publish.atomic_path` temporary), valid inside the ``with``."""
    return _fd_name(path, os.O_WRONLY)


def writer_name(path: str | os.PathLike) -> str:
    """A name with ``path``'s extension for ``ImageOutput.create`` (which reads only that)."""
    text = os.fspath(path)
    return text if is_utf8(text) else "image" + safe_text(os.path.splitext(text)[1])

