"""A grade as a 3-D LUT file: ``.cube`` or CLF.

:meth:`wbcgrade.color.grade.grading.Grade.lut` makes the table; this module writes
it. One ``.cube`` writer (:func:`write_cube`, colour-science's "Resolve
Cube" text written here, without importing colour-science: ``LUT_3D_SIZE``,
domain [0, 1], red varying fastest) serves every
command (a photo's LUT, a series' LUT, a clip's LUT) and
the temporary LUTs ffmpeg's ``lut3d`` reads. :func:`write_grade_lut` writes
a grade in a colour encoding and names its spaces in the header:

- a LUT in the working space (``apply``, ``batch``): its input and output
  are working-space colours (default sRGB-encoded Rec.709: the pixel values
  of 8/16-bit sRGB photos); when the working space is logarithmic (ACEScct,
  ACEScc) the ``.cube`` is Resolve's shaper form: a 1D shaper
  (``LUT_1D_INPUT_RANGE``) takes the linear partner (ACEScg) into the
  working space, then the 3D LUT grades: it expects linear ACEScg and
  produces ACEScct;
- a LUT baked in another encoding (``video``: the clip's code values): the
  lattice is in the input space, no shaper.

The CLF (Academy/ASC Common LUT Format, written by the ``opencolorio``
package: ``pip install 'wbcgrade[ocio]'``) holds the same operators, its
shaper a half-float-domain 1D LUT (exact at every half value).

>>> import numpy as np, tempfile, os
>>> from wbcgrade.color.mapping.lut import read_cube, write_cube
>>> from wbcgrade.color.mapping.remap import identity_map
>>> path = os.path.join(tempfile.mkdtemp(), "identity.cube")
>>> _ = write_cube(path, identity_map(5), title="identity")
>>> lut = read_cube(path)
>>> lut.size, bool(np.allclose(lut.table, identity_map(5), atol=1e-6))
(5, True)
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from wbcgrade._names import safe_text
from wbcgrade._publish import atomic_path
from wbcgrade.color._colour import colour_science
from wbcgrade.color.colorspace import ColorEncoding, config_line, convert
from wbcgrade.color.defaults import DEFAULT_LUT_SIZE
from wbcgrade.color.mapping.remap import apply_color_map, identity_map
from wbcgrade.errors import InputError, OptionError
from wbcgrade.limits import MAX_MAP_SIZE

__all__ = ["color_map_to_lut", "write_cube", "cube_text", "read_cube", "write_grade_lut",
           "lut_header",
           "shaper_table", "check_lut_path", "check_lut_size", "check_clf_support",
           "lut_format_of",
           "DEFAULT_LUT_SIZE", "LUT_FORMATS", "SHAPER_SIZE", "write_checked_lut"]

#: ``lut_format`` choices and the file name ending each needs.
LUT_FORMATS = {"cube": ".cube", "clf": ".clf"}
#: Entries of the ``.cube`` shaper (sampled evenly over its input range, as
#: Resolve reads it; see :func:`shaper_table` for its accuracy).
SHAPER_SIZE = 65536


def color_map_to_lut(color_map: np.ndarray, size: int = DEFAULT_LUT_SIZE,
                     strength: float = 1.0) -> np.ndarray:
    """Sample a colour map (n, n, n, 3) at a (size, size, size) grid -> (size, size, size, 3).

    The LUT entries are the map's trilinear interpolation at the LUT nodes
    (blended with the identity by ``strength``), so applying the LUT with
    trilinear interpolation approximates the grade to the LUT's resolution.
    """
    nodes = identity_map(check_lut_size(size))
    return np.clip(apply_color_map(nodes, color_map, strength), 0.0, 1.0)


def check_lut_size(size: int) -> int:
    """``size`` when it is a usable LUT size (2 to 129 nodes per axis, as a colour map's
    ``map.size``: a 256^3 table took 3.9 GB to bake), else OptionError. Checked whether or
    not a LUT is asked for (an option given is an option checked)."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) \
            or not 2 <= size <= MAX_MAP_SIZE:
        raise OptionError(f"{{lut_size}} must be between 2 and {MAX_MAP_SIZE}", "lut_size")
    return int(size)


def write_cube(path: str | os.PathLike, table: np.ndarray, title: str = "wbcgrade",
               comments: list[str] | None = None, overwrite: bool = False,
               shaper: tuple[np.ndarray, tuple[float, float]] | None = None) -> Path:
    """Write a (size, size, size, 3) table, indexed [r, g, b], as a .cube file (atomically).

    ``shaper``: ``(curve (k,), (low, high))``, a 1D shaper over ``[low, high]``
    before the 3D table (Resolve's shaper form). Never replaces an existing
    file unless ``overwrite``. The text is :func:`cube_text`'s.
    """
    path = Path(path)
    if path.suffix.lower() != ".cube":
        raise InputError(f"{path}: LUT file name must end in .cube")
    text = cube_text(table, title, comments, shaper)
    with atomic_path(path, suffix=".cube", overwrite=overwrite) as tmp, \
            open(tmp, "w", encoding="utf-8") as handle:
        handle.write(text)
    return path


def cube_text(table: np.ndarray, title: str = "wbcgrade", comments: list[str] | None = None,
              shaper: tuple[np.ndarray, tuple[float, float]] | None = None) -> str:
    """The ``.cube`` text of a (size, size, size, 3) table: colour-science's "Resolve Cube"
    form byte for byte (``TITLE``, ``# `` comments, ``LUT_3D_SIZE``, rows with red varying
    fastest, 6 decimals; with a shaper 7 decimals, ``LUT_1D_SIZE``,
    ``LUT_1D_INPUT_RANGE`` and the header of :func:`_shaper_header_for_readers`),
    written here: colour-science takes one to two seconds to import, on every LUT written
    run (tests/color/mapping/test_lut_interop.py compares the two).
    """
    table = np.asarray(table, dtype=np.float64)
    size = table.shape[0]
    if table.ndim != 4 or table.shape != (size, size, size, 3) or not 2 <= size <= 256:
        raise ValueError(f"a .cube table must be (n, n, n, 3) with 2 <= n <= 256, "
                         f"not {table.shape}")
    title = safe_text(title)  # a header naming a non-UTF-8 file: its bytes as \xNN
    notes = [f"# {safe_text(line)}" for line in comments or []]
    decimals = 6 if shaper is None else 7
    cube = _rows(table.transpose(2, 1, 0, 3).reshape(-1, 3), decimals)  # red fastest
    if shaper is None:
        return "\n".join([f'TITLE "{title}"', *notes, f"LUT_3D_SIZE {size}", cube]) + "\n"
    curve, (low, high) = shaper
    curve = np.asarray(curve, dtype=np.float64)
    if not 2 <= len(curve) <= 65536:
        raise ValueError(f"a .cube shaper has 2 to 65536 entries, not {len(curve)}")
    header = [f'TITLE "{title} - grade"', *notes, f"LUT_1D_SIZE {len(curve)}"]
    if (low, high) != (0, 1):
        header.append(f"LUT_1D_INPUT_RANGE {low:0.7f} {high:0.7f}")
    header.append(f"LUT_3D_SIZE {size}")
    ramp = _rows(np.repeat(curve[:, None], 3, axis=1), decimals)
    return "\n".join(_shaper_header_for_readers(header) + [ramp, "", cube]) + "\n"


def _rows(values: np.ndarray, decimals: int) -> str:
    """(N, 3) numbers as N lines of three fixed-point numbers (no final line end)."""
    row = " ".join([f"%0.{decimals}f"] * 3)
    return "\n".join([row] * len(values)) % tuple(values.ravel().tolist())


def _shaper_header_for_readers(header: list[str]) -> list[str]:
    """A shaper ``.cube``'s header such that every reader either reads it right or
    refuses it: no ``TITLE`` (OpenColorIO's Resolve reader refuses the tag; the title
    stays as a comment), and ``LUT_3D_SIZE`` before the 1D keywords (ffmpeg's ``lut3d``,
    which has no shaper, then stops at ``LUT_1D_SIZE`` with "Invalid data" instead of
    reading the shaper's entries as the 3D table). OpenColorIO and colour-science take
    the keywords in any order (tests/color/mapping/test_lut_interop.py)."""
    size_3d = [line for line in header if line.startswith("LUT_3D_SIZE")]
    out = []
    for line in header:
        if line.startswith("TITLE"):
            line = "# title: " + line[5:].strip().strip('"')
        elif line.startswith("LUT_3D_SIZE"):
            continue
        elif line.startswith("LUT_1D_SIZE"):
            out += size_3d
        out.append(line)
    return out


def read_cube(path: str | os.PathLike):
    """Read a .cube file with colour-science (returns a ``colour.LUT3D``)."""
    colour = colour_science()

    return colour.read_LUT(str(path))


def lut_format_of(path: str | os.PathLike, lut_format: str | None = None,
                  option: str = "lut") -> str:
    """The LUT format of ``path``: ``lut_format`` when given, else the one its ending names
    (``.cube`` or ``.clf``, :data:`LUT_FORMATS`); OptionError naming the setting ``option``
    (the one that gave ``path``) for any other ending."""
    if lut_format is not None:
        return lut_format
    suffix = Path(path).suffix.lower()
    for name, ending in LUT_FORMATS.items():
        if suffix == ending:
            return name
    raise OptionError(f"{path}: {{{option}}} file name must end in "
                      f"{' or '.join(LUT_FORMATS.values())} (the format follows the ending)",
                      option, path=path)


def check_lut_path(path: str | os.PathLike, lut_format: str | None = None) -> Path:
    """``path`` as a Path when its ending suits ``lut_format`` (None: any LUT ending,
    :func:`lut_format_of`), else InputError."""
    path = Path(path)
    if lut_format is None:
        lut_format = lut_format_of(path)
    if lut_format not in LUT_FORMATS:
        raise OptionError(f"{{lut_format}} must be one of {', '.join(LUT_FORMATS)}", "lut_format")
    suffix = LUT_FORMATS[lut_format]
    if path.suffix.lower() != suffix:
        raise OptionError(f"{path}: LUT file name must end in {suffix} ({{lut_format}} "
                          f"{lut_format})", "lut_format", path=path)
    return path


def shaper_table(encoding, size: int = SHAPER_SIZE) -> tuple[np.ndarray, tuple[float, float]]:
    """The 1D shaper of a logarithmic working space, sampled for a ``.cube``.

    Returns ``(table (size,) float64, (low, high))``: ``table[i]`` is the
    working-space value of the linear grey ``low + i (high - low) / (size -
    1)``; ``low`` and ``high`` are the linear values the working space
    encodes as 0 and 1 (ACEScct: about -0.0069 and 222.9), so the shaper
    covers exactly the 3D LUT's input cube.
    """
    high = float(encoding.peak)
    ramp = -np.geomspace(1e-6, 1.0, 2049)[::-1]  # the low end: the grey encoded as 0
    enc = convert(np.repeat(ramp[:, None], 3, axis=1), encoding.linear, encoding.working)[:, 0]
    below = np.flatnonzero(enc <= 0.0)
    low = float(ramp[below[-1]]) if len(below) else float(ramp[0])
    grey = np.linspace(low, high, size)
    table = convert(np.repeat(grey[:, None], 3, axis=1), encoding.linear, encoding.working)[:, 0]
    return np.clip(table.astype(np.float64), 0.0, 1.0), (low, high)


def lut_header(encoding, shaper: bool = False) -> list[str]:
    """Comment lines naming the spaces a LUT expects and produces, and the config."""
    if encoding.input != encoding.working:  # baked in the input's code values
        lines = [f"input space: {encoding.input} ({encoding.source})",
                 f"output space: {encoding.input}",
                 f"working space: {encoding.working} (where the grade was fitted)"]
    else:
        expects = (f"{encoding.linear} (linear; the 1D shaper encodes it as {encoding.working})"
                   if shaper else f"{encoding.working} (values in [0, 1])")
        lines = [f"input space: {expects}", f"output space: {encoding.working}"]
    return [*lines, config_line()]


def write_grade_lut(path: str | os.PathLike, grade, encoding: ColorEncoding | None = None,
                    size: int = DEFAULT_LUT_SIZE,
                    lut_format: str | None = None, title: str = "wbcgrade",
                    comments: list[str] | None = None, overwrite: bool = False) -> Path:
    """Write a :class:`~wbcgrade.color.grade.grading.Grade` as a LUT whose header names its spaces.

    Parameters
    ----------
    grade : the grade (its map lives in ``encoding.working``).
    encoding : a :class:`~wbcgrade.color.colorspace.ColorEncoding`: its input
        is what the LUT takes and gives (the working space itself: a LUT in
        the working space, with a shaper when it is logarithmic; another
        space: the grade baked in its code values, :meth:`Grade.lut`). None:
        the grade's own working space in and out.
    lut_format : "cube" (colour-science) or "clf" (the ``opencolorio`` package);
        None: the one ``path``'s ending names.
    """
    if encoding is None:
        encoding = ColorEncoding.of(grade.working or None, grade.working or None)
    lut_format = lut_format_of(path, lut_format)
    return write_checked_lut(check_lut_path(path, lut_format), lut_format, grade, encoding,
                             size, title=title, comments=comments, overwrite=overwrite)


def write_checked_lut(path: Path, lut_format: str, grade, encoding,
                      size: int = DEFAULT_LUT_SIZE, *, title: str = "wbcgrade",
                      comments: list[str] | None = None, overwrite: bool = False) -> Path:
    """:func:`write_grade_lut` of a path and format checked before any work
    (:func:`check_lut_path`, e.g. by a photo's plan): nothing is checked again."""
    baked = encoding.input != encoding.working
    table = grade.lut(size, encoding if baked else None)
    shaper = not baked and encoding.logarithmic
    notes = [safe_text(line) for line in list(comments or []) + lut_header(encoding, shaper)]
    title = safe_text(title)
    if lut_format == "clf":
        return _write_clf(path, table, encoding, shaper, title, notes, overwrite)
    return write_cube(path, table, title=title, comments=notes, overwrite=overwrite,
                      shaper=shaper_table(encoding) if shaper else None)


def check_clf_support():
    """The ``PyOpenColorIO`` module, or InputError saying how to install it."""
    try:
        import PyOpenColorIO as ocio
    except ImportError:
        raise OptionError("{lut_format} clf needs the opencolorio package: "
                          "pip install 'wbcgrade[ocio]' (or: pip install opencolorio)",
                          "lut_format") from None
    return ocio


def _write_clf(path: Path, table: np.ndarray, encoding, shaper: bool, title: str,
               notes: list[str], overwrite: bool) -> Path:
    ocio = check_clf_support()
    group = ocio.GroupTransform()
    metadata = group.getFormatMetadata()
    metadata.setName(title)
    metadata.setID(title)
    for note in notes:
        metadata.addChildElement("Description", note)
    if shaper:  # every half-float value: exact wherever a half is
        halves = np.arange(65536, dtype=np.uint16).view(np.float16).astype(np.float32)
        finite = np.isfinite(halves)
        values = np.zeros(65536, dtype=np.float32)
        values[finite] = convert(np.repeat(halves[finite, None], 3, axis=1), encoding.linear,
                                 encoding.working)[:, 0]
        values[~finite & (halves > 0)] = values[finite].max()
        values[~finite & ~(halves > 0)] = values[finite].min()
        curve = ocio.Lut1DTransform()
        curve.setInputHalfDomain(True)
        curve.setLength(65536)
        curve.setData(np.ascontiguousarray(np.repeat(values[:, None], 3, axis=1)).ravel())
        group.appendTransform(curve)
    size = table.shape[0]
    cube = ocio.Lut3DTransform()
    cube.setGridSize(size)
    # OpenColorIO orders 3D LUT entries with blue varying fastest: [r, g, b] in C order.
    cube.setData(np.ascontiguousarray(table, dtype=np.float32).ravel())
    group.appendTransform(cube)
    text = group.write(formatName="Academy/ASC Common LUT Format",
                       config=ocio.Config.CreateRaw())
    with atomic_path(path, suffix=".clf", overwrite=overwrite) as tmp, \
            open(tmp, "w", encoding="utf-8") as handle:
        handle.write(text)
    return path
