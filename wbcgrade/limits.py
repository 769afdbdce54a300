"""Bounds on every size that a user or a file can set, checked before any work is done.

A small file can declare a huge size: a preset naming 60 styles of 256^3
bins (5.5 GB of histograms), a ``.spi3d`` declaring 500^3 entries, a
compressed 400^3 map in a grade JSON, a ``.npy`` header claiming terabytes,
``--iterations 1000000000``. Every reader and every option checks such sizes
here, before it allocates, and refuses them with one line naming the file
(or the option) and the bound. The bounds are far above what wbcgrade makes
itself, and they keep the memory of a run under about 2 GB for any input
file under a few megabytes.

>>> check_count("styles", 3, MAX_STYLES, "p.npz")
3
>>> check_count("styles", 10**6, MAX_STYLES, "p.npz")
Traceback (most recent call last):
...
wbcgrade.errors.InputError: p.npz: 1000000 styles, more than the 4096 wbcgrade reads
"""

from __future__ import annotations

import io
import json
import os
import stat
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

from wbcgrade.errors import InputError

if TYPE_CHECKING:  # numpy is imported where arrays are read (`wbcgrade --help` needs none)
    import numpy as np

__all__ = ["MAX_LUT_SIZE", "MAX_MAP_SIZE", "MAX_LUT_DOMAIN", "MAX_STYLES",
           "MAX_HISTOGRAM_CELLS", "MAX_ARRAY_BYTES",
           "MAX_REGRAIN_RADIUS", "MAX_BARYCENTER_ITERATIONS", "MIN_BYTES_PER_LUT_ENTRY",
           "MAX_ARCHIVE_BYTES", "MEMORY_BUDGET", "MAX_REGRAIN_EPS", "MIN_REGRAIN_EPS",
           "check_count", "check_lut_entries", "check_histogram_cells", "check_memory",
           "check_input_file", "parse_json", "read_npz", "read_npy"]

#: Nodes per axis of any 3-D LUT or colour map read or written (256^3 x 3 float32: 200 MB).
MAX_LUT_SIZE = 256
#: Nodes per axis of a colour map a grade holds or reads as a look (a saved grade's map, a
#: preset's look, a LUT file read as a look): as ``--map-size`` allows.
MAX_MAP_SIZE = 129
#: The largest magnitude of a LUT's domain bound (DOMAIN_MIN/MAX, spi1d ``From``).
MAX_LUT_DOMAIN = 1e6
#: Styles in one preset or style set.
MAX_STYLES = 4096
#: Histogram cells of a whole style set (styles x bins^3): 2^25 float64 cells are 256 MB
#: (e.g. 128 styles of 64^3 bins, or 2 of 256^3).
MAX_HISTOGRAM_CELLS = 2 ** 25
#: Bytes of any one array a file holds (a preset's index, a cache entry's values, ...).
MAX_ARRAY_BYTES = 256 * 2 ** 20
#: Bytes of all the arrays of one archive together (a preset, a cache entry).
MAX_ARCHIVE_BYTES = 512 * 2 ** 20
#: Bytes any one reader may allocate for what one input file declares (decoded pixels and
#: the work on them, a LUT's table, a map's nodes): a run's memory stays under about 2 GB.
MEMORY_BUDGET = 1536 * 2 ** 20
#: The regrain regulariser (squared encoded units; encoded values lie in [0, 1], so their
#: variance is at most 0.25): beyond the upper bound every pixel goes through the LUT
#: alike, below the lower one float32 cannot hold it.
MAX_REGRAIN_EPS = 1e4
MIN_REGRAIN_EPS = 1e-12
#: The regrain window's radius, a fraction of the photo's long side (1: the whole photo).
MAX_REGRAIN_RADIUS = 1.0
#: Barycenter iterations L (the fit keeps every iteration's state for its gradient).
MAX_BARYCENTER_ITERATIONS = 1000
#: The fewest bytes a text LUT can spend on one entry ("0 0 0" and a line end): a file
#: declaring more entries than its size can hold is refused before its table is made.
MIN_BYTES_PER_LUT_ENTRY = 6


def check_count(what: str, count: int, most: int, where: str | os.PathLike) -> int:
    """``count`` when it is at most ``most``, else InputError naming ``where``."""
    if count > most:
        raise InputError(f"{where}: {count} {what}, more than the {most} wbcgrade reads")
    return int(count)


def check_memory(what: str, nbytes: int, where: str | os.PathLike,
                 hint: str = "", fields: tuple[str, ...] = ()) -> int:
    """``nbytes`` when it is within :data:`MEMORY_BUDGET`, else InputError naming ``where``
    (checked before allocating ``what``); ``fields``: the settings ``hint`` names."""
    if nbytes > MEMORY_BUDGET:
        raise InputError(f"{where}: {what} would take {nbytes / 2 ** 20:.0f} MB, more than "
                         f"the {MEMORY_BUDGET / 2 ** 20:.0f} MB wbcgrade allows one input"
                         + (f"; {hint}" if hint else ""), fields=fields)
    return int(nbytes)


_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def check_input_file(path: str | os.PathLike, what: str = "file") -> Path:
    """``path`` as a Path when it names a regular file (links followed), else InputError:
    missing, a folder, or a FIFO, device or socket (which could block a read for ever
    or never end). Every input file is checked so before it is opened."""
    path = Path(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{path}: no such {what}", path=path) from None
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or exc})", path=path) \
            from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError(f"{path}: is a folder, not a {what}", path=path)
    if not stat.S_ISREG(info.st_mode):
        kind = next((name for test, name in _KINDS if test(info.st_mode)), "not a regular file")
        raise InputError(f"{path}: is {kind}, not a regular {what}; wbcgrade reads regular "
                         "files only", path=path)
    return path


def parse_json(text: str | bytes, where: str | os.PathLike) -> object:
    """``json.loads(text)``, every failure an InputError naming ``where``: not JSON, and
    nesting too deep for the parser (200,000 brackets: a RecursionError)."""
    try:
        return json.loads(text)
    except RecursionError:
        raise InputError(f"{where}: not a readable JSON file (nested too deeply)") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"{where}: not a readable JSON file ({exc})") from None


def check_lut_entries(size: int, path: str | os.PathLike, dims: int = 3,
                      most: int | None = None) -> int:
    """``size`` (nodes per axis of a ``dims``-D text LUT ``path``) when it is between 2 and
    ``most`` (default :data:`MAX_LUT_SIZE`; 1-D: 65536) and the file is large enough to
    hold its entries; else InputError naming the file."""
    most = most if most is not None else MAX_LUT_SIZE if dims == 3 else 65536
    if not 2 <= size <= most:
        raise InputError(f"{path}: a {dims}-D LUT size of {size}; it must be between 2 and "
                         f"{most}")
    try:
        available = os.path.getsize(path)
    except OSError:
        available = None
    if available is not None and size ** dims * MIN_BYTES_PER_LUT_ENTRY > available:
        raise InputError(f"{path}: declares a {'x'.join([str(size)] * dims)} LUT, but the file "
                         f"({available} bytes) cannot hold its {size ** dims} entries")
    return int(size)


def check_histogram_cells(styles: int, bins: int, where: str | os.PathLike) -> None:
    """InputError unless ``styles`` histograms of ``bins``^3 cells fit
    :data:`MAX_STYLES` and :data:`MAX_HISTOGRAM_CELLS`."""
    check_count("styles", styles, MAX_STYLES, where)
    if styles * bins ** 3 > MAX_HISTOGRAM_CELLS:
        raise InputError(f"{where}: {styles} styles of {bins}^3 bins are "
                         f"{styles * bins ** 3} histogram cells, more than the "
                         f"{MAX_HISTOGRAM_CELLS} wbcgrade reads")


def read_npz(source: str | os.PathLike | bytes, where: str | os.PathLike | None = None,
             max_bytes: int = MAX_ARRAY_BYTES, *, names: frozenset[str] | set[str] | None = None,
             max_total: int = MAX_ARCHIVE_BYTES) -> dict[str, np.ndarray]:
    """Every array of a NumPy ``.npz`` archive (a path or its bytes), checked before it is read.

    Each member's ``.npy`` header is read first: its dtype must be a plain number, bool
    or string type (no objects, no structured records) and its size at most
    ``max_bytes`` (so a header claiming terabytes, or a small compressed member
    that would decompress to gigabytes, is refused before any allocation).

    Returns
    -------
    dict name -> array (names without ``.npy``). Raises InputError naming
    ``where`` (default: the path) for anything else.
    """
    where = where if where is not None else (source if not isinstance(source, bytes)
                                              else "archive")
    handle = io.BytesIO(source) if isinstance(source, bytes) else check_input_file(source)
    arrays: dict[str, np.ndarray] = {}
    try:
        with zipfile.ZipFile(handle) as archive:
            members = archive.infolist()
            check_count("archive members", len(members), 64, where)
            for info in members:
                if not info.filename.endswith(".npy"):
                    continue  # not an array (numpy writes none such)
                if names is not None and info.filename[:-4] not in names:
                    raise InputError(f"{where}: holds an unknown member "
                                     f"{info.filename[:-4][:80]!r}")
            total = sum(info.file_size for info in members if info.filename.endswith(".npy"))
            if total > max_total + 4096 * len(members):
                raise InputError(f"{where}: its arrays would take {total} bytes, more than "
                                 f"the {max_total} wbcgrade reads from one archive")
            used = 0
            for info in members:
                if not info.filename.endswith(".npy"):
                    continue  # not an array (numpy writes none such)
                name = info.filename[:-4]
                if info.file_size > max_bytes + 4096:
                    raise InputError(f"{where}: its array {name!r} would take "
                                     f"{info.file_size} bytes, more than the {max_bytes} "
                                     "wbcgrade reads")
                with archive.open(info) as member:  # within what the others left
                    arrays[name] = _read_member(member, name, where,
                                                min(max_bytes, max_total - used))
                used += arrays[name].nbytes
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zipfile.LargeZipFile,
            NotImplementedError, RuntimeError) as exc:  # RuntimeError: an encrypted member
        detail = str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{where}: not a readable .npz archive ({detail})") from None
    return arrays


def read_npy(path: str | os.PathLike, max_bytes: int = MAX_ARRAY_BYTES) -> np.ndarray:
    """The array of a ``.npy`` file, its header checked first (as :func:`read_npz`'s members):
    a header claiming more bytes than ``max_bytes`` (or than the file holds: 7 TiB in a
    few bytes) is an InputError naming the file, before any allocation."""
    check_input_file(path)
    try:
        with open(path, "rb") as handle:
            return _read_member(handle, Path(path).name, path, max_bytes)
    except InputError:
        raise
    except (OSError, ValueError, EOFError) as exc:
        detail = str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: not a readable .npy file ({detail})") from None


def _read_member(member, name: str, where, max_bytes: int) -> np.ndarray:
    import numpy as np

    fmt = np.lib.format
    version = fmt.read_magic(member)
    if version == (1, 0):
        shape, fortran, dtype = fmt.read_array_header_1_0(member)
    elif version == (2, 0):
        shape, fortran, dtype = fmt.read_array_header_2_0(member)
    else:
        raise InputError(f"{where}: its array {name!r} has an unknown .npy version {version}")
    if dtype.hasobject:
        raise InputError(f"{where}: its array {name!r} holds pickled Python objects, which "
                         "are never loaded")
    if dtype.fields is not None or dtype.subdtype is not None or dtype.kind not in "biufcSU":
        raise InputError(f"{where}: its array {name!r} has the type {dtype}, not plain numbers")
    count = int(np.prod(shape, dtype=object))
    if count * dtype.itemsize > max_bytes:
        raise InputError(f"{where}: its array {name!r} declares {count * dtype.itemsize} "
                         f"bytes (shape {shape}), more than the {max_bytes} wbcgrade reads")
    data = member.read(count * dtype.itemsize)
    if len(data) != count * dtype.itemsize:
        raise InputError(f"{where}: its array {name!r} is cut short")
    array = np.frombuffer(data, dtype=dtype, count=count)
    array = array.reshape(shape[::-1]).transpose() if fortran else array.reshape(shape)
    return array.copy()
