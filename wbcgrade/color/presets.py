"""Style databases: a set of named style histograms, from a folder or a preset file.

Preset file format (version 1): a NumPy ``.npz`` archive read with
``allow_pickle=False`` holding

- ``header``: uint8 bytes of a UTF-8 JSON object ``{"format": "wbcgrade-preset",
  "version": 1, "bins": n, "names": [...], "width": w, "gamma": g,
  "description": "...", "space": "...", "working_space": "ACEScct",
  "ocio_config": "ocio://default", "provenance": {...}}``; ``working_space`` (an OpenColorIO
  colour space name) is the space whose unit cube the histograms cover;
  presets written before it existed lack it and mean sRGB-encoded Rec.709.
  Grading in another working space converts the histograms
  (:func:`styles_in_space`); ``provenance`` (optional) says how the styles
  were made (the shipped presets: the look and the photos it was applied to);
- ``index`` (int32) and ``values`` (float32): the non-zero bins of all styles,
  concatenated, with flat C-order indices into the (n, n, n) grid; a compact
  file (``save_preset(compact=True)``, the preset builder's ``compact``) stores
  uint16 indices (n <= 40) and float16 values scaled by 2**15, which the
  reader takes as they are (each style is renormalised on load);
- ``offsets`` (int64, S + 1): style s owns ``index[offsets[s]:offsets[s+1]]``;
- ``look`` (optional, float16 (m, m, m, 3), indexed [r, g, b], values in [0, 1]):
  the look the styles share, known exactly because the preset was made by
  applying it (a lattice LUT in the working space); the "look" grade applies
  it as it is instead of estimating it from the palettes.

Everything is checked on load and a broken or foreign file gives one clear
error. Shipped presets live in ``wbcgrade/color/presets_data/`` so that they
are installed with the package.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade._executor import cpu_count
from wbcgrade._publish import atomic_path, check_output_path
from wbcgrade.color.colorspace import (
    ColorEncoding,
    config_path,
    convert,
    default_working_space,
    resolve_space,
)
from wbcgrade.color.defaults import DEFAULT_PRESET_WIDTH
from wbcgrade.color.histogram import (
    DEFAULT_MAX_PIXELS,
    Deferred,
    HistogramCache,
    deferred_field,
    deferred_shape,
    from_sparse,
    grid_points,
    image_histogram,
    resample_histogram,
    soft_histogram,
    stack_from_sparse,
    to_sparse,
)
from wbcgrade.color.io.cache import command_cache
from wbcgrade.color.io.images import header_pixels, read_image
from wbcgrade.color.io.preset_names import (
    RETIRED_PRESETS,
    list_presets,
    resolve_preset,
    shipped_presets_dir,
)
from wbcgrade.color.io.raw import is_raw
from wbcgrade.color.mapping.remap import apply_color_map
from wbcgrade.errors import InputError, OptionError, Worded, worded_error
from wbcgrade.limits import (
    MAX_MAP_SIZE,
    check_histogram_cells,
    check_input_file,
    check_memory,
    parse_json,
    read_npz,
)

__all__ = [
    "StyleSet",
    "StyleSource",
    "look_in_space",
    "source_files",
    "SHIPPED_NATURALS",
    "load_styles",
    "load_style_folder",
    "save_preset",
    "load_preset",
    "resolve_preset",
    "list_presets",
    "shipped_presets_dir",
    "PRESET_FORMAT",
    "PRESET_VERSION",
    "RETIRED_PRESETS",
    "styles_in_space",
    "own_style",
    "own_style_warning",
]

log = logging.getLogger(__name__)

PRESET_FORMAT = "wbcgrade-preset"
PRESET_VERSION = 1
_IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".exr", ".hdr", ".bmp", ".webp",
                   ".tga", ".dpx", ".jp2", ".heic", ".avif", ".ppm", ".pgm", ".pnm"}


@dataclass
class StyleSet:
    """Named style histograms on one grid.

    Attributes
    ----------
    names : S style names (file stems).
    histograms : (S, n, n, n) float64, each summing to 1.
    source : folder or preset file they came from.
    width : kernel width (bins) recorded with a preset, or None.
    meta : the preset's header and what the set was made from, under string keys
        that only this class reads: the typed properties :attr:`working_space`,
        :attr:`look`, :attr:`converted_from`, :attr:`files` and :attr:`images` are
        what other modules use.
    """

    names: list[str]
    #: made when first read when the set was given a :class:`~wbcgrade.color.histogram.Deferred`
    #: (a folder read from the cache: a look grade may need only :meth:`at_bins`'s grids)
    histograms: np.ndarray = deferred_field()
    source: str = ""
    width: float | None = None
    description: str = ""
    meta: dict = field(default_factory=dict)
    _resampled: dict = field(default_factory=dict, repr=False, compare=False)
    _space: str | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def bins(self) -> int:
        return int(deferred_shape(self, "histograms")[1])

    def __getstate__(self) -> dict:
        """Pickled (a batch's workers, a copy) with its histograms made dense, once: kept."""
        self.histograms  # noqa: B018 - reading a deferred stack makes and keeps it
        return self.__dict__

    @property
    def working_space(self) -> str:
        """The colour space whose unit cube the histograms cover (config name; resolved
        once per set)."""
        if self._space is None:
            name = self.meta.get("working_space")
            self._space = (resolve_space(name, "working space of the styles") if name
                           else default_working_space())
        return self._space

    @property
    def look(self) -> np.ndarray | None:
        """(m, m, m, 3) the look a preset was made with (its own lattice), or None."""
        return self.meta.get("look")

    def cache_folder(self) -> Path | None:
        """Where what is computed from the set is cached: the folder it was read with (None:
        the command turned caching off), else the command's
        (:func:`wbcgrade.color.io.cache.command_cache`; None when caching is off)."""
        if "cache_dir" not in self.meta:
            folder, enabled = command_cache()
            return folder if enabled else None
        folder = self.meta["cache_dir"]
        return None if folder is None else Path(folder)

    @property
    def converted_from(self) -> str | None:
        """The working space the set was converted from (:func:`styles_in_space`), or None."""
        return self.meta.get("converted_from") or None

    @property
    def file_digest(self) -> str | None:
        """The SHA-1 of the preset file the set was read from, or None (a folder's set)."""
        return self.meta.get("file_digest")

    def subset(self, indices: Sequence[int]) -> StyleSet:
        """The styles at ``indices`` as a set of their own (their histograms; the working
        space and the cache folder kept)."""
        indices = list(indices)
        meta = {k: v for k, v in self.meta.items() if k in ("working_space", "cache_dir")}
        return StyleSet([self.names[i] for i in indices], self.histograms[indices],
                        self.source, self.width, self.description, meta)

    @property
    def files(self) -> tuple[str, ...]:
        """The style photos' files (a folder's set), in the order of ``names``; () else."""
        return tuple(self.meta.get("files") or ())

    @property
    def images(self) -> tuple:
        """The style photos themselves ((H, W, 3) working-space colours) of a set built
        from arrays; () else."""
        return tuple(self.meta.get("images") or ())

    def at_bins(self, bins: int, only: Sequence[int] | np.ndarray | None = None) -> np.ndarray:
        """(S, bins, bins, bins) histograms re-binned to another grid.

        ``only`` (style indices): just those, (len(only), bins, bins, bins); the
        others are not re-binned (a palette of one style needs one, not S).
        """
        if only is not None:
            only = np.asarray(only, dtype=np.int64)
            if bins == self.bins or bins in self._resampled:
                return self.at_bins(bins)[only]
            return np.stack([resample_histogram(self.histograms[i], bins) for i in only])
        if bins == self.bins:
            return self.histograms
        if bins not in self._resampled:  # resampled once per grid size
            self._resampled[bins] = np.stack([resample_histogram(h, bins)
                                              for h in self.histograms])
        return self._resampled[bins]


#: ``on_image(path, colours)``: told of each photo a folder's histograms are read from, with
#: its (H, W, 3) working-space colours (e.g. to prepare it for scene matching from the
#: same decode: :func:`wbcgrade.color.look.scene.keep_for_matching`).
ImageHook = Callable[[Path, np.ndarray], None]


def _photo_histogram(path: Path, bins: int, max_pixels: int,
                     working_space: str | None = None,
                     on_image: ImageHook | None = None) -> np.ndarray:
    image = read_image(path)
    encoding = ColorEncoding.for_image(image, None, working_space)  # each in its own space
    encoded, _ = encoding.encode(image.rgb(), image.is_float)
    if on_image is not None:
        on_image(path, encoded)
    try:
        return image_histogram(encoded, bins, image.alpha(), max_pixels)
    except InputError as exc:  # e.g. fully transparent: say which photo
        raise InputError(f"{path}: {exc}") from None


#: Photos a folder's histograms are read from at once, at most (threads: decoding, colour
#: conversion and binning release the GIL; docs/benchmarks.md).
READ_THREADS = 4
#: Megapixels of photos decoded at once, at most (a bigger photo is read alone): each holds
#: its pixels and their working-space copy while it is read (16 MP: ~0.5 GB, in ACEScct
#: ~1 GB), so four 50 MP photos at once would need four times one's memory.
READ_MEGAPIXELS = 48.0


class _Budget:
    """Megapixels in flight across threads: ``take`` waits until ``amount`` fits (or
    nothing else is in flight), ``give`` returns it."""

    def __init__(self, total: float) -> None:
        self.total, self.used = total, 0.0
        self.changed = threading.Condition()

    def take(self, amount: float) -> None:
        with self.changed:
            self.changed.wait_for(lambda: self.used <= 0 or self.used + amount <= self.total)
            self.used += amount

    def give(self, amount: float) -> None:
        with self.changed:
            self.used -= amount
            self.changed.notify_all()


def _megapixels(path: Path) -> float:
    """A photo's size from its header; a raw file (demosaiced in full) counts as the whole
    :data:`READ_MEGAPIXELS`."""
    return READ_MEGAPIXELS if is_raw(path) else header_pixels(path) / 1e6


def _read_histograms(files: list[Path], bins: int, cache: HistogramCache, max_pixels: int,
                     working: str, warn: Callable[[str], None],
                     progress: Callable[[int, int, str], None] | None,
                     on_image: ImageHook | None = None, where: str | os.PathLike = "styles",
                     resampled: Sequence[int] = ()) -> _FolderHistograms:
    """Histograms of the readable ``files`` (from ``cache`` when it holds them; the others
    skipped with a ``warn``ing) and their paths, in the order of ``files``; read in up to
    :data:`READ_THREADS` threads, :data:`READ_MEGAPIXELS` at a time.

    The stack is checked against the memory budget (``limits.check_memory``: InputError
    naming ``where``) and made dense when first read (:class:`_FolderHistograms`): each
    histogram is kept sparse, as the cache holds it, until then. With a cache, each photo's
    histogram
    re-binned onto the grids of ``resampled`` (:func:`resample_histogram`, as
    :meth:`StyleSet.at_bins` does it) is read from the cache too, or made and stored."""
    from concurrent.futures import ThreadPoolExecutor

    check_memory(f"the histograms of {len(files)} style photos at {bins}^3 bins",
                 len(files) * bins ** 3 * 8 * 2, where,  # (x2: what the grade makes of them)
                 "use fewer style photos or fewer {transfer.bins}", ("transfer.bins",))
    space = f"{config_path()}|{working}"
    budget = _Budget(READ_MEGAPIXELS)
    grids = sorted({int(n) for n in resampled if n != bins}) if cache.enabled else []

    def read(path: Path) -> tuple[tuple | None, dict, InputError | None]:
        hist = cache.get_sparse(path, bins, max_pixels, space)
        if hist is None:
            size = _megapixels(path)
            budget.take(size)
            try:
                dense = _photo_histogram(path, bins, max_pixels, working, on_image)
            except InputError as exc:
                return None, {}, exc
            finally:
                budget.give(size)
            # as later runs read it; kept sparse (a folder of hundreds of photos holds
            # its dense stack once, when it is read)
            hist = cache.put_sparse(path, bins, dense, max_pixels, space)
            del dense
        coarse = {}
        for at in grids:
            found = cache.get_resampled(path, bins, at, max_pixels, space)
            if found is None:
                found = resample_histogram(from_sparse(*hist, bins), at)
                cache.put_resampled(path, bins, at, found, max_pixels, space)
            coarse[at] = found
        return hist, coarse, None

    parts: list = []
    coarse_parts: dict[int, list[np.ndarray]] = {at: [] for at in grids}
    used: list[str] = []
    threads = max(1, min(READ_THREADS, cpu_count(), len(files)))
    pool = ThreadPoolExecutor(threads)
    try:
        if progress and files:
            progress(0, len(files), files[0].name)
        for number, (path, (hist, coarse, exc)) in enumerate(zip(files, pool.map(read, files))):
            if progress and number + 1 < len(files):
                progress(number + 1, len(files), files[number + 1].name)
            if exc is not None:
                if path.suffix.lower() in _IMAGE_SUFFIXES or "not a readable image" not in str(exc):
                    warn(worded_error(exc, "skipping ", whole=True))
                else:
                    warn(f"skipping {path.name}: not an image")
                continue
            parts.append(hist)
            for at in grids:
                coarse_parts[at].append(coarse[at])
            used.append(str(path))
            del hist
    finally:  # interrupted: the photos not started are not read
        pool.shutdown(wait=True, cancel_futures=True)
    if progress:
        progress(len(files), len(files), "")
    return _FolderHistograms(parts, bins, used,
                             {at: np.stack(found) for at, found in coarse_parts.items()
                              if len(found)})


@dataclass
class _FolderHistograms:
    """What :func:`_read_histograms` read: each photo's histogram (sparse, as the cache
    keeps it), the grid, the photos' paths and the stacks already re-binned."""

    parts: list
    bins: int
    used: list[str]
    resampled: dict[int, np.ndarray]

    def stack(self) -> Deferred:
        """The (S, bins, bins, bins) stack, made when first read
        (:func:`~wbcgrade.color.histogram.stack_from_sparse`)."""
        return Deferred((len(self.parts), *(self.bins,) * 3), stack_from_sparse, self.parts,
                        self.bins)


def photo_palettes(files: list[str | os.PathLike], bins: int,
                   *, cache: HistogramCache | None = None,
                   max_pixels: int = DEFAULT_MAX_PIXELS,
                   warn: Callable[[str], None] | None = None,
                   progress: Callable[[int, int, str], None] | None = None,
                   working_space: str | None = None) -> StyleSet | None:
    """Histograms of the readable photos among ``files`` (as :func:`load_style_folder`
    reads a folder's), named by file name (a raw and its JPEG may share a stem); None
    when none is readable."""
    cache = cache or HistogramCache(enabled=False)
    working = resolve_space(working_space) if working_space else default_working_space()
    read = _read_histograms([Path(f) for f in files], bins, cache, max_pixels, working,
                            warn or log.warning, progress)
    used = read.used
    if not used:
        return None
    return StyleSet(names=[Path(path).name for path in used], histograms=read.stack(),
                    _resampled=dict(read.resampled),
                    source="", meta={"working_space": working, "ocio_config": config_path(),
                                     "files": used})


def load_style_folder(folder: str | os.PathLike, bins: int,
                      *, cache: HistogramCache | None = None,
                      max_pixels: int = DEFAULT_MAX_PIXELS,
                      warn: Callable[[str], None] | None = None,
                      progress: Callable[[int, int, str], None] | None = None,
                      working_space: str | None = None,
                      on_image: ImageHook | None = None,
                      resampled: Sequence[int] = ()) -> StyleSet:
    """Histograms of every photo in a folder (not recursive), sorted by name.

    Files that are not readable images are skipped with a warning (passed to
    ``warn``, else logged). Histograms come from ``cache`` when it holds them.
    Each photo is converted from its own colour space (ICC profile, EXR
    metadata; :func:`wbcgrade.color.colorspace.detect_input_space`) into
    ``working_space`` (None: sRGB-encoded Rec.709) before its histogram.

    ``on_image``: told of each photo decoded (:data:`ImageHook`; not of those whose
    histogram was cached). ``resampled``: the grids :meth:`StyleSet.at_bins` will be
    asked for (e.g. the fit's), read from the cache with the histograms (the histograms
    themselves are then made dense only when read). Raises InputError when the folder is
    missing or holds no usable photo.
    """
    folder = Path(folder)
    if folder.is_file():
        raise InputError(f"{folder}: is a file; {{style_dir}} takes a folder of style photos "
                         "(put the photo in a folder of its own, or use {preset})",
                         fields=("style_dir", "preset"))
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: is not a folder (a FIFO or device?); {{style_dir}} takes "
                         "a folder of style photos", fields=("style_dir",))
    if not folder.is_dir():
        raise InputError(f"{folder}: style folder does not exist")
    warn = warn or log.warning
    cache = cache or HistogramCache(enabled=False)
    working = resolve_space(working_space) if working_space else default_working_space()
    files = sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))
    read = _read_histograms(files, bins, cache, max_pixels, working, warn, progress,
                            on_image, folder, resampled)
    used = read.used
    names = [Path(path).stem for path in used]
    if not used:
        raise InputError(f"{folder}: no readable photos in the style folder")
    if len(set(names)) != len(names):
        dupes = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"{folder}: several style photos share the name {dupes[0]!r}")
    return StyleSet(names=names, histograms=read.stack(), source=str(folder),
                    _resampled=dict(read.resampled),
                    meta={"working_space": working, "ocio_config": config_path(),
                          "files": used,
                          "cache_dir": str(cache.folder) if cache.enabled else None})


#: The widest Gibbs kernel a preset records, in bins (a grid has at most 256 of them).
MAX_KERNEL_WIDTH = 1e4


def check_preset_width(width: float) -> float:
    """``width`` as a float when it is a usable kernel width (finite, > 0 bins), else an
    OptionError naming the setting ``width``.

    Checked before a preset is built, since :func:`load_preset` refuses any other.
    """
    try:
        value = float(width)
    except (TypeError, ValueError):
        raise OptionError(f"{{width}} must be a number of bins, got {width!r}", "width") from None
    if not (np.isfinite(value) and 0 < value <= MAX_KERNEL_WIDTH):
        raise OptionError(f"{{width}} must be a positive, finite number of bins (at most "
                          f"{MAX_KERNEL_WIDTH:g}), got {width}", "width")
    return value


def save_preset(path: str | os.PathLike, styles: StyleSet, *, width: float = DEFAULT_PRESET_WIDTH,
                description: str = "", overwrite: bool = False,
                threshold: float = 1e-7, provenance: dict | None = None,
                look: np.ndarray | None = None, compact: bool = False) -> Path:
    """Write a style set as a preset file (atomically; see the module docstring).

    ``threshold`` drops bins holding less than that fraction of a style's mass
    (they are far below the fitting floor) to keep files small; ``provenance``
    (JSON-friendly) is recorded in the header as it is; ``look`` (m, m, m, 3):
    the look the styles were made with, as a lattice LUT in the working space.
    ``compact`` stores uint16 indices and float16 values (about half the size;
    each bin within 0.05 % of its value): for sets of hundreds of photos.
    """
    if look is not None:
        look = np.asarray(look)
        problem = _look_problem(look)
        if problem:
            raise InputError(f"look: {problem}")
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise InputError(f"{path}: preset file name must end in .npz")
    width = check_preset_width(width)
    check_output_path(path, overwrite=overwrite)
    bins = styles.bins
    gamma = 2.0 * (width / (bins - 1)) ** 2
    indices, values, offsets = [], [], [0]
    for hist in styles.histograms:
        index, vals = to_sparse(hist, threshold)
        indices.append(index)
        values.append(vals)
        offsets.append(offsets[-1] + len(index))
    # compact: 2**15 keeps every value of a normalised style, and each style's
    # sum (1 * 2**15), inside float16's normal range
    compact_index = compact and bins ** 3 <= np.iinfo(np.uint16).max + 1
    index_type = np.uint16 if compact_index else np.int32
    value_type, value_scale = (np.float16, 2.0 ** 15) if compact else (np.float32, 1.0)
    working = styles.working_space
    header = {"format": PRESET_FORMAT, "version": PRESET_VERSION, "bins": bins,
              "names": list(styles.names), "width": float(width), "gamma": gamma,
              "description": description, "space": f"{working}-encoded RGB",
              "working_space": working, "ocio_config": config_path()}
    if provenance:
        header["provenance"] = provenance
    with atomic_path(path, suffix=".npz.tmp", overwrite=overwrite) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(
                handle,
                header=np.frombuffer(json.dumps(header).encode("utf-8"), dtype=np.uint8),
                index=np.concatenate(indices).astype(index_type),
                values=(np.concatenate(values) * value_scale).astype(value_type),
                offsets=np.asarray(offsets, dtype=np.int64),
                **({} if look is None else {"look": look.astype(np.float16)}))
    return path


def _look_problem(look: np.ndarray) -> str | None:
    """What is wrong with a preset's look, or None when it is an (m, m, m, 3) lattice
    (m >= 2) of finite floats in [0, 1]."""
    if (look.ndim != 4 or look.shape[3] != 3 or not look.shape[0] == look.shape[1]
            == look.shape[2] >= 2 or not np.issubdtype(look.dtype, np.floating)):
        return "the look must be an (m, m, m, 3) lattice"
    if not np.all(np.isfinite(look)) or look.min() < 0 or look.max() > 1:
        return "the look's values must be finite, in [0, 1]"
    return None


#: The arrays a preset holds (``look``: optional).
_PRESET_MEMBERS = frozenset({"header", "index", "values", "offsets", "look"})


def _check_members(path: Path, raw: bytes) -> None:
    """A preset's missing arrays named before anything is read (a foreign archive)."""
    import io
    import zipfile

    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as archive:
            names = {n[:-4] for n in archive.namelist() if n.endswith(".npy")}
    except (zipfile.BadZipFile, OSError, ValueError):
        return  # read_npz says what is wrong
    missing = {"header", "index", "values", "offsets"} - names
    if missing:
        raise _bad(path, f"missing {', '.join(sorted(missing))}")


def _bad(path: Path, why: str) -> InputError:
    return InputError(f"{path}: not a valid wbcgrade preset ({why})")


def load_preset(path: str | os.PathLike) -> StyleSet:
    """Read and validate a preset file, or a shipped preset by name (``"warm"``) -> StyleSet
    (raises InputError with the reason)."""
    if isinstance(path, str) and not Path(path).exists():
        path = resolve_preset(path)  # a shipped name; else "no such preset file"
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such preset file")
    check_input_file(path, "preset file")  # a FIFO or device is refused unopened
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise _bad(path, f"unreadable file: {exc.strerror or exc}") from None
    if not raw.startswith(b"PK"):  # else numpy talks of pickles and allow_pickle
        raise _bad(path, "unreadable archive: not a zip (.npz) file")
    _check_members(path, raw)
    try:
        data = read_npz(raw, path, names=_PRESET_MEMBERS)  # any other member: refused
    except InputError as exc:
        raise _bad(path, "unreadable archive: " + str(exc).removeprefix(f"{path}: ")) \
            from None
    missing = {"header", "index", "values", "offsets"} - set(data)
    if missing:
        raise _bad(path, f"missing {', '.join(sorted(missing))}")
    header_bytes = data["header"]
    index, values, offsets = data["index"], data["values"], data["offsets"]
    look = data.get("look")
    try:
        if header_bytes.dtype != np.uint8:
            raise ValueError
        header = parse_json(header_bytes.tobytes(), path)
        if not isinstance(header, dict):
            raise ValueError
    except (ValueError, UnicodeDecodeError):
        raise _bad(path, "header is not JSON") from None
    if header.get("format") != PRESET_FORMAT:
        raise _bad(path, "unknown format tag")
    if header.get("version") != PRESET_VERSION:
        raise _bad(path, f"format version {header.get('version')!r}, "
                         f"this wbcgrade reads version {PRESET_VERSION}")
    bins, names = header.get("bins"), header.get("names")
    if not isinstance(bins, int) or not 2 <= bins <= 256:
        raise _bad(path, "bad bins")
    if (not isinstance(names, list) or not names
            or not all(isinstance(n, str) and n for n in names)):
        raise _bad(path, "bad style names")
    try:
        check_histogram_cells(len(names), bins, path)
    except InputError as exc:
        raise _bad(path, str(exc).removeprefix(f"{path}: ")) from None
    width = header.get("width")
    if width is not None and not (isinstance(width, (int, float)) and not isinstance(width, bool)
                                  and 0 < width <= MAX_KERNEL_WIDTH):
        raise _bad(path, f"bad kernel width (a number of bins in (0, {MAX_KERNEL_WIDTH:g}])")
    working = header.get("working_space")
    if working is not None and not (isinstance(working, str) and working):
        raise _bad(path, "bad working space")
    if not (np.issubdtype(index.dtype, np.integer) and np.issubdtype(values.dtype, np.floating)
            and np.issubdtype(offsets.dtype, np.integer)):
        raise _bad(path, "wrong array types")
    if (offsets.ndim != 1 or len(offsets) != len(names) + 1 or offsets[0] != 0
            or np.any(np.diff(offsets) <= 0) or offsets[-1] != len(index)
            or index.shape != values.shape or index.ndim != 1):
        raise _bad(path, "inconsistent histogram arrays")
    if len(index) and (index.min() < 0 or index.max() >= bins ** 3):
        raise _bad(path, "bin index out of range")
    if not np.all(np.isfinite(values)) or np.any(values < 0):
        raise _bad(path, "negative or non-finite histogram values")
    parts = []
    for s in range(len(names)):
        part = slice(int(offsets[s]), int(offsets[s + 1]))
        if not values[part].sum() > 0:
            raise _bad(path, f"style {names[s]!r} is empty")
        parts.append((index[part], values[part]))
    # as from_sparse makes each, in one array, when first read (a cached look grade reads
    # only the file's digest of the shipped natural palettes: their 83 MB dense stack
    # cost it 0.05-0.3 s)
    hists = Deferred((len(names), bins, bins, bins), stack_from_sparse, parts, bins)
    meta = dict(header)
    # what the file holds, for keys of what is computed from it (not the dense histograms)
    meta["file_digest"] = hashlib.sha1(raw).hexdigest()
    if look is not None:
        if look.ndim == 4 and look.shape[0] > MAX_MAP_SIZE:
            raise _bad(path, f"its look is {look.shape[0]}^3, more than the {MAX_MAP_SIZE}^3 "
                             "wbcgrade reads")
        meta["look"] = look.astype(np.float32)
        problem = _look_problem(meta["look"])
        if problem:
            raise _bad(path, problem)
    return StyleSet(names=list(names), histograms=hists, source=str(path),
                    width=None if width is None else float(width),
                    description=str(header.get("description", "")), meta=meta)


def styles_in_space(styles: StyleSet, working_space: str) -> StyleSet:
    """The styles' histograms in another working space (the same set when already there).

    Each non-empty bin's centre is converted from the styles' working space
    into ``working_space`` (OpenColorIO, :func:`wbcgrade.color.colorspace.convert`)
    and its mass soft-binned again at the same grid size
    (:func:`wbcgrade.color.histogram.soft_histogram`). Colours that fall
    outside the new unit cube are clipped onto its faces (e.g. an sRGB-built
    preset's highlights in a linear working space); a logarithmic working
    space such as ACEScct holds every sRGB colour. The converted set is
    kept on ``styles`` (converted once per working space).
    """

    source = styles.working_space
    if working_space == source:  # a config name already (the encoding's, a set's)
        return styles
    working = resolve_space(working_space)
    if working == source:
        return styles
    key = ("space", working)
    if key not in styles._resampled:
        centres = grid_points(styles.bins)
        hists = []
        for hist in styles.histograms:
            flat = hist.ravel()
            keep = np.flatnonzero(flat > 0)
            moved = convert(centres[keep], source, working)
            hists.append(soft_histogram(moved, styles.bins, flat[keep]))
        meta = {**styles.meta, "working_space": working, "converted_from": source}
        if styles.look is not None:  # the same look, converted (not re-extracted)
            meta["look"] = look_in_space(styles.look, source, working,
                                         max(65, styles.look.shape[0]))
        styles._resampled[key] = StyleSet(list(styles.names), np.stack(hists), styles.source,
                                          styles.width, styles.description, meta)
    return styles._resampled[key]


def look_in_space(look: np.ndarray, source: str, working: str,
                  size: int | None = None) -> np.ndarray:
    """A look lattice made in one working space, as the same look in another.

    Each node y of a ``size``^3 lattice (default the look's own size) of
    ``working`` is converted into ``source`` (x), moved by the look there
    (colours outside ``source``'s unit cube keep their offset from it: the look
    of the nearest colour inside), and converted back: the lattice holds
    ``to_working(look(x))``, clipped to the unit cube. Applied to a colour,
    the converted look gives (up to interpolation) what the original gives to
    the same colour in its own space.

    Parameters
    ----------
    look : (m, m, m, 3) the look's lattice in ``source`` (config names).
    source, working : colour space names (:func:`resolve_space`).
    size : nodes per axis of the result (default m).

    Returns
    -------
    (size, size, size, 3) float32 lattice in ``working``.
    """
    size = int(size or look.shape[0])
    nodes = grid_points(size).astype(np.float32)
    there = convert(nodes, working, source)
    inside = np.clip(there, 0.0, 1.0)
    moved = apply_color_map(inside, np.asarray(look, dtype=np.float32)) + (there - inside)
    back = convert(moved, source, working)
    return np.clip(back, 0.0, 1.0).reshape(size, size, size, 3).astype(np.float32)


@dataclass(frozen=True)
class StyleSource:
    """Where a command's styles come from: a folder of photos or a preset (exactly one).

    ``cache``: the style histogram cache (a folder's histograms; None: none).
    """

    style_dir: str | None = None
    preset: str | None = None
    cache: HistogramCache | None = None

    @property
    def name(self) -> str:
        return str(self.style_dir if self.style_dir is not None else self.preset)


def load_styles(source: StyleSource, bins: int, working_space: str | None = None,
                warn: Callable[[str], None] | None = None,
                progress: Callable[[int, int, str], None] | None = None,
                on_image: ImageHook | None = None,
                resampled: Sequence[int] = ()) -> StyleSet:
    """The styles a command names: a folder's histograms at ``bins`` (cached) or a preset.

    The histograms are those of ``working_space`` (None: sRGB-encoded
    Rec.709): style photos are converted from their own spaces before
    binning; a preset built in another working space is converted
    (:func:`styles_in_space`). ``resampled``: a folder's grids also kept in its
    cache (:func:`load_style_folder`).
    """
    if (source.style_dir is None) == (source.preset is None):
        raise OptionError("give exactly one of {style_dir} DIR or {preset} NAME_OR_FILE",
                          "style_dir", also=("preset",))
    if source.preset is not None:
        styles = load_preset(resolve_preset(source.preset))
        if working_space is None and "working_space" not in styles.meta:
            return styles  # sRGB-encoded Rec.709 on both sides
        return styles_in_space(styles, working_space or default_working_space())
    return load_style_folder(source.style_dir, bins, cache=source.cache, warn=warn,
                             progress=progress, working_space=working_space,
                             on_image=on_image, resampled=resampled)


def one_style_warning(source: StyleSource, styles: StyleSet, mode: str) -> Worded | None:
    """The one-line warning for a look (``mode`` "look") taken from a folder of a single
    style photo, or None: one photo cannot show which of its colours are the look."""
    if source.style_dir is None or mode != "look" or len(styles.names) != 1:
        return None
    return Worded(f"{source.style_dir}: one style photo; its look is told from what it shows "
                  "by that photo alone (add photos that share the look for a surer one, or "
                  "use {map.builder} palette to move the colours towards this photo's)",
                  ("map.builder",))


#: ``map.natural`` naming the shipped natural palettes alone (a batch otherwise also reads
#: its own photos: :func:`wbcgrade.batch.workflow.own_photos_content`).
SHIPPED_NATURALS = "shipped"


def source_files(source: StyleSource | None = None, natural: str | os.PathLike | None = None,
                 look=None) -> list[Path]:
    """Every file a grade reads besides the photo: the style folder's files (or the preset),
    the natural palettes (``natural``: a preset file or a folder of photos; else, or
    :data:`SHIPPED_NATURALS`, the shipped ones) and a saved ``look``'s file.

    They are inputs: an output naming one of them is refused, ``overwrite`` or not
    (:func:`wbcgrade._publish.plan_outputs`). A preset name that resolves to no file
    adds nothing (loading it reports that).
    """
    files: list[Path] = []
    if source is not None and source.style_dir is not None:
        folder = Path(source.style_dir)
        if folder.is_dir():
            files += [p for p in folder.iterdir() if p.is_file()]
    elif source is not None and source.preset is not None:
        try:
            files.append(resolve_preset(source.preset))
        except InputError:
            pass
    if natural is not None and str(natural) == SHIPPED_NATURALS:
        natural = None
    if natural is not None and Path(natural).is_dir():  # the user's own ungraded photos
        files += [p for p in Path(natural).iterdir() if p.is_file()]
    elif natural is not None:  # checked here, whether the grade ends up using it or not
        files.append(check_input_file(natural, "natural palettes file or folder"))
    else:
        files.append(Path(__file__).with_name("data") / "natural.npz")
    saved = getattr(look, "saved", None)
    if saved is not None and saved.file:
        files.append(Path(saved.file))
    return files


#: A photo is graded towards itself when one style holds at least this weight ...
OWN_STYLE_WEIGHT = 0.8
#: ... and that style's palette is within this total variation distance of the
#: photo's (half the L1 distance of the two histograms on the fit grid). The
#: same photo resized or saved again is within 0.1 on 16^3 bins; a look applied
#: to it (a film print LMT, a CDL) moves it 0.27 or more, another photo 0.68 or more.
OWN_STYLE_DISTANCE = 0.15


def own_style(photo_hist: np.ndarray, style_hists: np.ndarray, names: Sequence[str],
              weights: np.ndarray) -> dict | None:
    """Whether a grade takes a photo towards its own palette (the photo is one of the styles).

    Parameters
    ----------
    photo_hist : (n, n, n) the photo's histogram.
    style_hists : (S, n, n, n) the styles' histograms on the same grid.
    names : S style names.
    weights : (S,) the grade's weights.

    Returns
    -------
    None, or ``{"style": name, "weight": w, "distance": d}`` when the largest
    weight is at least :data:`OWN_STYLE_WEIGHT` and that style's palette is
    within :data:`OWN_STYLE_DISTANCE` (total variation) of the photo's.
    """
    weights = np.asarray(weights, dtype=np.float64)
    top = int(np.argmax(weights))
    if weights[top] < OWN_STYLE_WEIGHT or photo_hist.shape != style_hists.shape[1:]:
        return None
    photo = photo_hist / max(float(photo_hist.sum()), 1e-300)
    style = style_hists[top] / max(float(style_hists[top].sum()), 1e-300)
    distance = 0.5 * float(np.abs(photo - style).sum())
    if distance > OWN_STYLE_DISTANCE:
        return None
    return {"style": str(names[top]), "weight": float(weights[top]), "distance": distance}


def own_style_warning(photo: str, found: dict, palette: bool = True) -> str:
    """The one-line warning for :func:`own_style`'s finding about ``photo``: in a palette
    grade's words (its weight, the palettes' distance), or for a look grade
    (``palette=False``) in a photographer's."""
    if not palette:
        return (f"{photo} is itself one of the style photos ({found['style']!r}): it is "
                "graded with its own look, so little changes; leave it out of the style "
                "folder")
    return (f"{photo} is graded towards its own palette (style {found['style']!r} has weight "
            f"{found['weight']:.3f} and a palette {found['distance']:.3f} from the photo's): "
            "it is one of the styles, so little changes; leave it out of the style set")
