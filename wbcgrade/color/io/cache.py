"""The colour domain's disk cache: one folder, one key rule, one reader, one writer.

Three things are kept between runs, each in its own place under one cache folder
(:func:`cache_folder`):

- style photos' histograms (``color.histogram.HistogramCache``), and each re-binned
  onto the grids a grade asks for: at the folder's top, where they have always been;
- a style set's look and the natural palettes' statistics (``color.look``): ``looks/``;
- style photos prepared for scene matching (``color.look.scene``): ``scenes/``.

An entry is one ``.npz`` archive (no pickle) named by a digest of its key text
(:func:`entry_path`), so a key may hold any file name: unicode, spaces, a name
that is not UTF-8, a name longer than the file system allows. The key says
everything the value depends on (the file's path, size and time, the settings),
so a stale entry is never found, only left behind.

A cache never makes a run fail:

- :func:`read_entry` treats anything that is not a readable archive (garbage,
  zero bytes, cut short, too large) or does not match the digest of its name and
  content that :func:`write_entry` records (values changed, an entry copied under
  another key), or holds NaN, as a miss and removes it, so the value is
  computed again and a good entry written in its place; callers treat any error
  in using the arrays as a miss too;
- :func:`write_entry` writes through :func:`wbcgrade._publish.atomic_path` (a
  locked temporary beside the entry, renamed onto it), so a reader or a second
  writer never sees half an entry; a folder that cannot be written (read-only,
  full) is one warning line per process, and the run goes on.
"""

from __future__ import annotations

import hashlib
import io
import logging
import os
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from wbcgrade._publish import publish_bytes, remove_stale_temporaries
from wbcgrade.errors import InputError
from wbcgrade.limits import read_npz

if TYPE_CHECKING:  # numpy is imported where arrays are written
    import numpy as np

__all__ = ["default_cache_dir", "set_command_cache", "command_cache", "cache_folder",
           "key_bytes", "entry_name", "entry_path", "file_key", "read_entry", "write_entry"]

log = logging.getLogger(__name__)

#: Hex digits of an entry's name (128 bits of SHA-256 of its key).
NAME_DIGITS = 32


def default_cache_dir() -> Path:
    """``$WBCGRADE_CACHE_DIR``, else ``$XDG_CACHE_HOME/wbcgrade``, else ``~/.cache/wbcgrade``."""
    env = os.environ.get("WBCGRADE_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "wbcgrade"


#: The running command's cache folder, or that it has none (:func:`set_command_cache`).
_COMMAND: dict[str, object] = {}


def set_command_cache(folder: str | os.PathLike | None = None, enabled: bool = True) -> None:
    """Set the cache of this process's command: ``folder`` (None: :func:`default_cache_dir`)
    and whether caching is on. Every cache without a folder of its own follows it (a
    style set's, the natural palettes', a batch worker's: ``map.natural``'s too).
    ``set_command_cache()`` goes back to the defaults."""
    _COMMAND.clear()
    if folder is not None or not enabled:
        _COMMAND.update(folder=None if folder is None else Path(folder), enabled=bool(enabled))


def command_cache() -> tuple[Path, bool]:
    """(the folder, whether caching is on) of this process's command
    (:func:`set_command_cache`; default: :func:`default_cache_dir`, on)."""
    folder = _COMMAND.get("folder")
    return (Path(folder) if folder is not None else default_cache_dir(),
            bool(_COMMAND.get("enabled", True)))


def cache_folder(styles=None) -> Path | None:
    """The cache folder of a StyleSet (its own, ``StyleSet.cache_folder``, when it was read
    with one), else the command's (:func:`command_cache`); None when caching is off."""
    own = getattr(styles, "cache_folder", None)
    if own is not None:
        return own()
    folder, enabled = command_cache()
    return folder if enabled else None


def key_bytes(text: str) -> bytes:
    """``text`` as bytes for a cache key: UTF-8, a path's undecodable bytes (``caf\\udce9``,
    a POSIX name that is not UTF-8) as they were on disk."""
    return text.encode("utf-8", "surrogateescape")


def entry_name(key: str) -> str:
    """The file name of the entry keyed by ``key`` (any text): ``<32 hex digits>.npz``.

    >>> entry_name("a photo.jpg") == entry_name("a photo.jpg") != entry_name("a photo.JPG")
    True
    >>> len(entry_name("\\u00e9" * 10000))
    36
    """
    return hashlib.sha256(key_bytes(key)).hexdigest()[:NAME_DIGITS] + ".npz"


def entry_path(folder: str | os.PathLike | None, kind: str, key: str) -> Path | None:
    """Where the entry of ``kind`` (a subfolder: ``"looks"``, ``"scenes"``; ``""``: the
    folder's top) keyed by ``key`` lives under ``folder``; None when ``folder`` is None
    (caching is off)."""
    if folder is None:
        return None
    return Path(folder) / kind / entry_name(key) if kind else Path(folder) / entry_name(key)


def file_key(path: str | os.PathLike) -> str:
    """The part of a key that names a file as it is now: its absolute path, modification
    time and size (an edited or replaced file gets another key). OSError when it is gone."""
    path = Path(path)
    stat = path.stat()
    return f"{path.resolve()}|{stat.st_mtime_ns}|{stat.st_size}"


#: The member of an entry holding :func:`_digest` of its name and arrays.
DIGEST_MEMBER = "wbcgrade_digest"
#: The member (inside the digest) marking an entry whose writer stored NaN itself: the
#: statistics of an empty lightness band, a look's unknown losses. Such an entry is read
#: back as written; NaN in an entry without it (or inf in any) still makes it unusable.
NAN_MEMBER = "wbcgrade_holds_nan"


def _digest(name: str, arrays: dict[str, np.ndarray]) -> bytes:
    """SHA-256 of an entry's file name (itself the digest of its key) and of every array
    (name, type, shape, bytes): an entry moved under another key, or whose values were
    changed, no longer matches."""
    import numpy as np

    digest = hashlib.sha256(key_bytes(name))
    for member in sorted(arrays):
        array = np.ascontiguousarray(arrays[member])
        digest.update(f"|{member}|{array.dtype.str}|{array.shape}|".encode())
        digest.update(array.tobytes())
    return digest.digest()


def read_entry(path: str | os.PathLike | None) -> dict[str, np.ndarray] | None:
    """The arrays of an entry, or None when there is none or it is unusable (then removed,
    so that the caller computes the value again and writes a good entry in its place).

    Unusable: not a readable archive, larger than the archive bounds, without the digest
    :func:`write_entry` records or not matching it (values changed, an entry copied
    under another key), or holding infinite numbers, or NaN its writer did not store."""
    import numpy as np

    if path is None or not os.path.isfile(path):
        return None
    try:
        arrays = read_npz(path)
        recorded = arrays.pop(DIGEST_MEMBER, None)
        if recorded is None or recorded.dtype != np.uint8 \
                or recorded.tobytes() != _digest(Path(path).name, arrays):
            raise InputError(f"{path}: does not match its digest")
        holds_nan = arrays.pop(NAN_MEMBER, None) is not None
        for array in arrays.values():
            if array.dtype.kind in "fc" and not np.isfinite(array).all() \
                    and not (holds_nan and not np.isinf(array).any()):
                raise InputError(f"{path}: holds NaN or infinite values")
        return arrays
    except InputError:
        try:
            os.unlink(path)
        except OSError:
            pass
        return None


_WARNED: list[str] = []  # the folder a write first failed in (one warning per process)
_SWEPT: set[str] = set()
_LOCK = threading.Lock()


def write_entry(path: str | os.PathLike | None, compress: bool = False,
                **arrays: np.ndarray) -> bool:
    """Write an entry atomically (best effort). -> whether it was written.

    The archive is made in memory first (a full disk cannot leave a half-written
    ZipFile open), then published with :func:`wbcgrade._publish.publish_bytes`
    without the flushes to disk: an entry a crash damages is found damaged and
    rebuilt. A failed write is logged once per process (the cache folder is one); temporaries a
    killed run left in it are removed the first time a process writes there.
    ``compress``: deflate the arrays (histograms are sparse and shrink well). NaN in the
    arrays is recorded as the writer's (:data:`NAN_MEMBER`): read back as it is, where an
    entry holding NaN it was not written with is a miss.
    """
    if path is None:
        return False
    import numpy as np  # here, as above: a command that only checks its cache loads no numpy

    path = Path(path)
    folder = str(path.parent)
    try:
        data = io.BytesIO()
        if any(np.asarray(a).dtype.kind in "fc" and np.isnan(a).any() for a in arrays.values()):
            arrays = {**arrays, NAN_MEMBER: np.ones(1, np.uint8)}
        digest = np.frombuffer(_digest(path.name, arrays), dtype=np.uint8)
        (np.savez_compressed if compress else np.savez)(data, **arrays,
                                                         **{DIGEST_MEMBER: digest})
        path.parent.mkdir(parents=True, exist_ok=True)
        with _LOCK:
            sweep = folder not in _SWEPT
            _SWEPT.add(folder)
        if sweep:
            remove_stale_temporaries(path.parent)
        publish_bytes(path, data.getvalue(), sync=False)
        return True
    except (OSError, InputError, ValueError) as exc:
        with _LOCK:
            first = not _WARNED
            if first:
                _WARNED.append(folder)
        if first:  # one line per run, not one per style photo
            reason = getattr(exc, "strerror", None) or str(exc)
            log.warning("cache %s not written (%s); going on without it", folder, reason)
        return False
