"""Saved grades ("looks"): a grade written once, applied again to other photos with no fit.

A grade is its colour map (a lattice LUT in the working space), the working
space, the strength and the regrain settings (:class:`~wbcgrade.color.grade.grading.Grade`).
Two files hold one:

- the JSON :func:`save_grade` writes (:func:`look_dict`; or a report's JSON,
  whose ``"saved_grade"`` entry holds it): the map itself (16-bit codes,
  within 0.002/255, compressed: ~150 kB for 33³), its working space,
  strength, regrain settings, style names and weights. Applied again it
  gives the same photo, regrain included;
- a 3-D LUT (``.cube``, ``.clf``, or any LUT colour-science reads:
  ``.spi3d``, ``.csp``, ...). wbcgrade's own LUTs name the space they
  work in in their header (``output space: ...``), and the ``.cube``
  shaper of a logarithmic working space is skipped: the 3-D table is the
  map. Other LUTs are taken to work on ``working_space`` values (default
  sRGB-encoded Rec.709, the pixel values of ordinary photos) and are
  sampled on a 33³ lattice. A LUT has no regrain settings: the caller
  chooses (``apply`` regrains by default, as a fresh grade does, so a
  ``.cube`` of :func:`~wbcgrade.color.mapping.lut.write_grade_lut` gives back the same photo).

:func:`load_look` reads either into a Grade; ``grade.apply`` then moves the
pixels through it (the remap and regrain stages of a fresh grade, no
histograms, no fit, no transport).

>>> import numpy as np
>>> from wbcgrade.color.grade.grading import Grade
>>> from wbcgrade.color.mapping.remap import identity_map
>>> grade = Grade(("warm",), np.ones(1), identity_map(5) * np.float32(0.9), working="w")
>>> back = look_from_dict(look_dict(grade), "example")
>>> float(np.abs(back.color_map - grade.color_map).max()) < 1e-5, back.working, back.names
(True, 'w', ('warm',))
"""

from __future__ import annotations

import base64
import json
import os
import re
import zlib
from pathlib import Path

import numpy as np

from wbcgrade._publish import publish_bytes
from wbcgrade.color._colour import colour_science
from wbcgrade.color.colorspace import default_working_space, resolve_space
from wbcgrade.color.grade.grading import Grade
from wbcgrade.color.mapping.lut import check_clf_support
from wbcgrade.color.mapping.remap import identity_map
from wbcgrade.color.outcome import SavedFrom
from wbcgrade.errors import InputError, OptionError, first_line
from wbcgrade.limits import (
    MAX_LUT_DOMAIN,
    MAX_MAP_SIZE,
    MAX_REGRAIN_EPS,
    MAX_REGRAIN_RADIUS,
    MAX_STYLES,
    MIN_REGRAIN_EPS,
    check_count,
    check_input_file,
    check_lut_entries,
    parse_json,
)

__all__ = ["LOOK_FORMAT", "LOOK_SUFFIXES", "look_dict", "look_from_dict", "load_look", "save_grade",
           "saved_name", "look_batch_options", "SAMPLED_LUT_SIZE"]

#: The ``format`` tag of a saved grade.
LOOK_FORMAT = "wbcgrade-look"
_VERSION = 1
#: LUT file endings :func:`load_look` reads (besides ``.json``).
LOOK_SUFFIXES = (".cube", ".clf", ".spi3d", ".spi1d", ".csp", ".3dl")
#: Bytes of a LUT file read as a look (a 129^3 table as text takes about 60 MB).
_MAX_LUT_FILE_BYTES = 256 * 2 ** 20
#: Lattice size on which a LUT that is not a plain 3-D table is sampled.
SAMPLED_LUT_SIZE = 33


#: Steps of a saved map between its smallest and largest value (16-bit codes).
_CODES = 65535


def _encode_array(values: np.ndarray) -> dict:
    """An (m, m, m, 3) map as text: 16-bit codes between its extremes (an error below
    0.002/255 for a map in [0, 1]), differenced along the first two axes, the bytes of
    each code split into two planes, zlib, base64 (about a third of the float32 bytes)."""
    data = np.asarray(values, dtype=np.float64)
    low, high = float(data.min()), float(data.max())
    span = high - low if high > low else 1.0
    codes = np.round((data - low) / span * _CODES).astype(np.int32)
    steps = np.diff(np.diff(codes, axis=0, prepend=0), axis=1, prepend=0)
    steps = np.mod(steps, 65536).astype("<u2")  # differences modulo 2^16: exact back
    planes = steps.view(np.uint8).reshape(-1, 2).T.tobytes()
    return {"shape": list(data.shape), "low": low, "high": high,
            "encoding": "uint16-delta2-planes-zlib-base64",
            "data": base64.b64encode(zlib.compress(planes, 9)).decode("ascii")}


def _decode_array(entry: dict, where: str) -> np.ndarray:
    try:
        if not isinstance(entry, dict) or not isinstance(entry.get("shape"), list):
            raise ValueError("no shape")
        shape = tuple(_integer(n) for n in entry["shape"])
        if entry.get("encoding") != "uint16-delta2-planes-zlib-base64" or len(shape) != 4:
            raise ValueError("unknown encoding")
        if shape[3] != 3 or not shape[0] == shape[1] == shape[2] >= 2:
            raise InputError(f"{where}: the saved colour map has shape {shape}, "
                             "not (m, m, m, 3)")
        if shape[0] > MAX_MAP_SIZE:
            raise InputError(f"{where}: the saved colour map is {shape[0]}^3, larger than "
                             f"the {MAX_MAP_SIZE}^3 wbcgrade reads")
        low, high = _number(entry["low"]), _number(entry["high"])
        if low > high or max(abs(low), abs(high)) > MAX_LUT_DOMAIN:
            raise InputError(f"{where}: the saved colour map's \"low\" {low:g} and "
                             f"\"high\" {high:g} must be in order, within "
                             f"±{MAX_LUT_DOMAIN:g}")
        if not isinstance(entry["data"], str):
            raise ValueError("its data is not text")
        count = int(np.prod(shape))
        inflate = zlib.decompressobj()  # at most the declared size is ever inflated
        planes = inflate.decompress(base64.b64decode(entry["data"]), 2 * count)
        if len(planes) != 2 * count or inflate.unconsumed_tail:
            raise ValueError("its size does not match its shape")
        steps = np.frombuffer(planes, dtype=np.uint8).reshape(2, count).T.copy()
        steps = steps.view("<u2").reshape(shape)
        # the sums modulo 2^16, in uint16 (wrapping is exact): a quarter of int64's memory
        codes = np.cumsum(np.cumsum(steps, axis=1, dtype=np.uint16), axis=0, dtype=np.uint16)
        span = high - low if high > low else 1.0
        values = (low + codes * (span / _CODES)).astype(np.float32)
    except InputError:
        raise
    except (KeyError, TypeError, ValueError, zlib.error) as exc:
        raise InputError(f"{where}: the saved colour map is damaged ({exc})") from None
    if not np.isfinite(values).all():
        raise InputError(f"{where}: the saved colour map is damaged")
    return values


def _integer(value) -> int:
    """``value`` when it is a whole number (a JSON int, or a float such as 33.0), else
    ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not float(value).is_integer():
        raise ValueError(f"{value!r} is not a whole number")
    return int(value)


def _number(value) -> float:
    """``value`` as a finite float (a JSON number), else ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not np.isfinite(value):
        raise ValueError(f"{value!r} is not a finite number")
    return float(value)


def look_dict(grade: Grade) -> dict:
    """A grade as a JSON-friendly dict that :func:`look_from_dict` turns back into it."""
    return {"format": LOOK_FORMAT, "version": _VERSION, "working_space": grade.working,
            "strength": float(grade.strength),
            "regrain": None if grade.regrain is None else [float(v) for v in grade.regrain],
            "regrain_follow": float(grade.regrain_follow),
            "names": list(grade.names), "weights": [float(w) for w in grade.weights],
            "loss": None if grade.loss is None else float(grade.loss),
            "map": _encode_array(grade.color_map)}


def save_grade(path: str | os.PathLike, grade: Grade, overwrite: bool = False) -> Path:
    """Write ``grade`` as JSON (what :func:`load_look` reads), with its
    outcome when it has one, atomically; an existing file only with ``overwrite``."""
    entry = look_dict(grade)
    if grade.outcome is not None:
        entry["outcome"] = grade.outcome.as_dict()
    path = Path(path)
    publish_bytes(path, json.dumps(entry, indent=1).encode("utf-8"), overwrite=overwrite)
    return path


def look_from_dict(entry: dict, where: str = "look") -> Grade:
    """The Grade a :func:`look_dict` describes (``where`` names it in errors).

    Every field is checked (type and range) before the map is decoded; a field of
    the wrong kind is an InputError naming it, never a TypeError.
    """
    if not isinstance(entry, dict) or entry.get("format") != LOOK_FORMAT:
        raise InputError(f"{where}: not a saved wbcgrade grade")
    version = entry.get("version", 0)
    if isinstance(version, bool) or not isinstance(version, int):
        raise InputError(f"{where}: the saved grade's \"version\" must be a whole number, "
                         f"not {json.dumps(version)}")
    if version > _VERSION:
        raise InputError(f"{where}: saved by a newer wbcgrade (format version "
                         f"{version}); upgrade to read it")
    names = entry.get("names") or ["look"]
    if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
        raise InputError(f"{where}: the saved grade's \"names\" must be a list of style "
                         "names")
    check_count("style names", len(names), MAX_STYLES, where)
    weights = entry.get("weights") or [1.0] * len(names)
    try:
        if not isinstance(weights, list):
            raise ValueError
        weights = np.array([_number(w) for w in weights], dtype=np.float64)
    except ValueError:
        raise InputError(f"{where}: the saved grade's \"weights\" must be a list of "
                         "numbers") from None
    if weights.shape != (len(names),):
        weights = np.full(len(names), 1.0 / len(names))
    regrain, strength, loss = entry.get("regrain"), entry.get("strength", 1.0), entry.get("loss")
    try:
        strength = _number(strength)
        if not 0 <= strength <= 1:
            raise ValueError
    except ValueError:
        raise InputError(f"{where}: the saved strength must be a number in [0, 1]") from None
    if regrain is not None:
        try:
            if not isinstance(regrain, list) or len(regrain) != 2:
                raise ValueError
            regrain = (_number(regrain[0]), _number(regrain[1]))
            if not (0 < regrain[0] <= MAX_REGRAIN_RADIUS
                    and MIN_REGRAIN_EPS <= regrain[1] <= MAX_REGRAIN_EPS):
                raise ValueError
        except ValueError:
            raise InputError(f"{where}: the saved regrain settings must be [radius, eps] with "
                             f"0 < radius <= {MAX_REGRAIN_RADIUS:g} (a fraction of the long "
                             f"side) and {MIN_REGRAIN_EPS:g} <= eps <= {MAX_REGRAIN_EPS:g}"
                             ) from None
    try:
        loss = None if loss is None else _number(loss)
    except ValueError:
        raise InputError(f"{where}: the saved loss must be a number or null") from None
    follows = entry.get("regrain_follow", 0.0)  # (grades saved before it: 0)
    try:
        follows = _number(follows)
        if not 0 <= follows <= 1:
            raise ValueError
    except ValueError:
        raise InputError(f"{where}: the saved \"regrain_follow\" must be a number in "
                         "[0, 1]") from None
    working = entry.get("working_space")
    if working is not None and not isinstance(working, str):
        raise InputError(f"{where}: the saved working space must be a colour space name")
    color_map = _decode_array(entry.get("map", {}), where)
    return Grade(names=tuple(names), weights=weights, color_map=color_map,
                 working=working or "", strength=strength, regrain=regrain, loss=loss,
                 info={"saved_look": {"file": where, "kind": "json"}},
                 saved=SavedFrom(where, "json"), regrain_follow=follows)


def _header_space(lines: list[str]) -> str | None:
    """The space a wbcgrade LUT works in: its header's ``output space: NAME``."""
    for line in lines:
        found = re.match(r"\s*output space:\s*(.+?)\s*$", str(line))
        if found:
            return found.group(1)
    return None


def _resolve(name: str, path: Path, option: str) -> str:
    return resolve_space(name, option, path)


def _plain_cube(path: Path) -> tuple[np.ndarray, str | None] | None:
    """A ``.cube`` whose 3-D table covers [0, 1] (with no 1-D part, or wbcgrade's shaper),
    read directly (colour-science takes a second to import); None for any other kind.

    The keywords' values are checked first (InputError naming the file and the line
    for a missing or unusable one, a size out of range, or a size the file is too
    small to hold), so colour-science, when it reads the other kinds, never meets
    a size it would allocate gigabytes for.
    """
    try:
        text = path.read_text("utf-8-sig")  # a UTF-8 byte order mark is no keyword
    except UnicodeDecodeError:
        return None
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    comments, rows, size, size_1d, plain = [], [], 0, 0, True
    domains: dict[str, list[float]] = {}
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line:
            continue
        if line.startswith("#"):
            comments.append(line[1:].strip())
            continue
        key, *fields = line.split()
        if key[0].isdigit() or key[0] in "-+.":
            rows.append(line)
        elif key in ("LUT_3D_SIZE", "LUT_1D_SIZE"):
            if len(fields) != 1 or not fields[0].isascii() or not fields[0].isdigit():
                raise InputError(f"{path}: line {number}: {key} must be followed by one "
                                 f"whole number, not {' '.join(fields) or 'nothing'!r}")
            if key == "LUT_3D_SIZE":
                size = check_lut_entries(int(fields[0]), path, 3, MAX_MAP_SIZE)
            else:
                size_1d = check_lut_entries(int(fields[0]), path, 1)
        elif key in ("DOMAIN_MIN", "DOMAIN_MAX", "LUT_3D_INPUT_RANGE", "LUT_1D_INPUT_RANGE"):
            try:
                values = [float(v) for v in fields]
                if len(values) not in (2, 3) or not np.isfinite(values).all() \
                        or np.abs(values).max() > MAX_LUT_DOMAIN:
                    raise ValueError
            except ValueError:
                raise InputError(f"{path}: line {number}: {key} must be followed by two or "
                                 f"three finite numbers within ±{MAX_LUT_DOMAIN:g}, not "
                                 f"{' '.join(fields) or 'nothing'!r}") from None
            domains[key] = values
            if key != "LUT_1D_INPUT_RANGE" and values not in ([0.0] * 3, [1.0] * 3,
                                                               [0.0, 1.0]):
                plain = False
        elif key != "TITLE":
            plain = False
    _check_domains(path, domains)
    space = _header_space(comments)
    if not size:
        if size_1d and not rows[size_1d:]:
            raise InputError(f"{path}: a 1-D LUT (LUT_1D_SIZE) with no 3-D table; a look "
                             "must be a 3-D LUT (LUT_3D_SIZE)")
        raise InputError(f"{path}: not a 3-D .cube LUT (it has no LUT_3D_SIZE line)")
    if not plain or (size_1d and space is None):
        return None
    if len(rows) != size_1d + size ** 3:
        raise InputError(f"{path}: LUT_3D_SIZE {size}"
                         + (f" and LUT_1D_SIZE {size_1d}" if size_1d else "")
                         + f" need {size_1d + size ** 3} rows of three numbers, "
                         f"the file has {len(rows)}")
    try:
        values = np.array(" ".join(rows[size_1d:]).split(), dtype=np.float64)
    except ValueError:
        raise InputError(f"{path}: the LUT's rows hold something other than numbers") \
            from None
    if values.size != 3 * size ** 3:
        raise InputError(f"{path}: the LUT's rows must hold three numbers each")
    # red varies fastest in a .cube: the rows are [b, g, r] in C order
    table = values.reshape(size, size, size, 3).transpose(2, 1, 0, 3)
    return np.ascontiguousarray(table, dtype=np.float32), space


def _check_domains(path: Path, domains: dict[str, list[float]]) -> None:
    """InputError unless each input range of a ``.cube`` runs upwards on every channel
    (DOMAIN_MIN below DOMAIN_MAX, an INPUT_RANGE's low below its high)."""
    pairs = [(domains.get("DOMAIN_MIN", [0.0] * 3), domains.get("DOMAIN_MAX", [1.0] * 3),
              "DOMAIN_MIN", "DOMAIN_MAX")]
    pairs += [(values[:1] * 3, values[-1:] * 3, key, key) for key, values in domains.items()
              if key.endswith("INPUT_RANGE") and len(values) == 2]
    for low, high, first, second in pairs:
        if len(low) != 3 or len(high) != 3 or not all(a < b for a, b in zip(low, high)):
            raise InputError(f"{path}: {first} and {second} give an empty or reversed input "
                             "range (each low value must be below its high one)")


def _check_declared_size(path: Path) -> None:
    """InputError when a LUT file colour-science reads declares a table its size cannot hold
    (a 40-byte ``.spi3d`` declaring 500^3 entries), before colour-science allocates it."""
    try:
        size = os.path.getsize(path)
        if size > _MAX_LUT_FILE_BYTES:
            raise InputError(f"{path}: {size} bytes, more than the {_MAX_LUT_FILE_BYTES} a "
                             "LUT file read as a look may hold")
        with open(path, "rb") as handle:
            lines = handle.read().decode("ascii", "replace").splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    suffix = path.suffix.lower()
    # every line the reader takes for a size is checked (a second size line counts too)
    for number, line in enumerate(lines, 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        whole = all(v.isascii() and v.isdigit() for v in parts)
        if suffix == ".spi3d" and len(parts) == 3:  # SPILUT 1.0 / 3 3 / n n n
            if number == 3 and not whole:
                raise InputError(f"{path}: line 3 must give the LUT's three sizes")
            if whole and len(set(parts)) != 1 and number == 3:
                raise InputError(f"{path}: a 3-D LUT must have the same size on every axis, "
                                 f"not {' x '.join(parts)}")
            if whole and len(set(parts)) == 1:
                check_lut_entries(int(parts[0]), path, 3, MAX_MAP_SIZE)
        elif suffix == ".spi1d" and parts[0] == "Length" and len(parts) == 2:
            if not (parts[1].isascii() and parts[1].isdigit()):
                raise InputError(f"{path}: Length must be a whole number")
            check_lut_entries(int(parts[1]), path, 1)
        elif suffix == ".spi1d" and parts[0] == "From":
            try:
                low, high = (float(v) for v in parts[1:])
                if not (abs(low) <= MAX_LUT_DOMAIN and abs(high) <= MAX_LUT_DOMAIN
                        and low < high):
                    raise ValueError
            except ValueError:
                raise InputError(f"{path}: line {number}: From must give two finite numbers, "
                                 "the first below the second") from None
        elif suffix == ".csp" and whole:  # sizes: of a pre-LUT (one number), the 3-D table
            if len(parts) == 1:
                check_lut_entries(int(parts[0]), path, 1)
            elif len(parts) == 3 and len(set(parts)) == 1 and int(parts[0]) > 1:
                check_lut_entries(int(parts[0]), path, 3, MAX_MAP_SIZE)


def _cube_look(path: Path) -> tuple[np.ndarray, str | None]:
    """(the table on the [0, 1] working cube, the space named in the header or None)."""
    if path.suffix.lower() == ".cube":
        plain = _plain_cube(path)
        if plain is not None:
            return plain
    _check_declared_size(path)
    colour = colour_science()

    try:
        lut = colour.read_LUT(str(path))
    except Exception as exc:  # noqa: BLE001 - colour-science raises many kinds
        why = str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: not a readable LUT ({why})") from None
    parts = list(lut) if isinstance(lut, colour.LUTSequence) else [lut]
    comments = [c for part in parts for c in (getattr(part, "comments", None) or [])]
    space = _header_space(comments)
    last = parts[-1]
    unit = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    if isinstance(last, colour.LUT3D) and np.allclose(last.domain, unit) and (
            len(parts) == 1 or space is not None):
        # a plain table, or wbcgrade's shaper form (the shaper maps the linear partner
        # into the working space; the table is the map)
        return np.asarray(last.table, dtype=np.float32), space
    nodes = identity_map(SAMPLED_LUT_SIZE).astype(np.float64)
    return np.asarray(lut.apply(nodes), dtype=np.float32), space


def _clf_look(path: Path) -> tuple[np.ndarray, str | None]:
    """A CLF or ``.3dl`` (Autodesk/Flame/Lustre) LUT read by OpenColorIO: (the table on the
    working cube, the space its header names or None). Numbers that are not finite in the
    file are refused (OpenColorIO would carry them through silently)."""
    kind = "CLF" if path.suffix.lower() == ".clf" else "LUT"
    try:
        ocio = check_clf_support()
    except InputError:
        raise InputError(f"{path}: reading a {path.suffix} look needs the opencolorio "
                         "package: pip install 'wbcgrade[ocio]'") from None
    if kind == "LUT":
        _check_declared_size(path)
    try:
        text = path.read_text("utf-8", errors="replace")
        if len(text) > _MAX_LUT_FILE_BYTES:
            raise InputError(f"{path}: more than the {_MAX_LUT_FILE_BYTES} bytes a LUT file "
                             "read as a look may hold")
        values = re.sub(r"<Description>.*?</Description>|<!--.*?-->|#[^\n]*", " ", text,
                        flags=re.S)
        if re.search(r"(?<![A-Za-z])[-+]?(nan|inf(inity)?)(?![A-Za-z])", values, re.I):
            raise InputError(f"{path}: the {kind} holds NaN or infinite values")
        group = ocio.Config.CreateRaw().getProcessor(
            ocio.FileTransform(src=str(path), interpolation=ocio.INTERP_LINEAR)
        ).createGroupTransform()
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - OpenColorIO raises its own Exception
        raise InputError(f"{path}: not a readable {kind} ({first_line(exc)})") from None
    space = _header_space(re.findall(r"<Description>(.*?)</Description>", text, re.S))
    transforms = list(group)
    if space is not None and transforms and isinstance(transforms[-1], ocio.Lut3DTransform):
        size = transforms[-1].getGridSize()
        table = np.asarray(transforms[-1].getData(), dtype=np.float32).reshape(size, size,
                                                                              size, 3)
        return table, space
    processor = ocio.Config.CreateRaw().getProcessor(group).getDefaultCPUProcessor()
    nodes = np.ascontiguousarray(identity_map(SAMPLED_LUT_SIZE), dtype=np.float32)
    flat = nodes.reshape(-1, 3).copy()
    processor.applyRGB(flat)
    return flat.reshape(nodes.shape), space


def load_look(path: str | os.PathLike, working_space: str | None = None) -> Grade:
    """Read a saved grade: a ``.json`` from :func:`save_grade` (or a report's JSON: its
    ``"saved_grade"``), or a 3-D LUT (:data:`LOOK_SUFFIXES`).

    Parameters
    ----------
    path : the file.
    working_space : the space a LUT without wbcgrade's header works in
        (default sRGB-encoded Rec.709); a saved JSON names its own.

    Returns
    -------
    Grade whose ``color_map`` is the saved map (a LUT's table, strength 1 and
    no regrain settings: the caller decides), ``working`` the config's name
    of its space, ``saved`` the file and its kind (also in ``info``, for the JSON),
    ``source`` SAVED.
    """
    path = check_input_file(path)  # a FIFO or device is refused unopened
    suffix = path.suffix.lower()
    if suffix == ".json":
        try:
            data = parse_json(path.read_bytes(), path)
        except OSError as exc:
            raise InputError(f"{path}: not a readable JSON file ({exc})") from None
        entry = data.get("saved_grade") if isinstance(data, dict) and "saved_grade" in data \
            else data
        if not isinstance(entry, dict) or entry.get("format") != LOOK_FORMAT:
            raise InputError(f"{path}: holds no saved grade (write one with "
                             "`wbcgrade apply PHOTO ... {save_grade} grade.json`)",
                             fields=("save_grade",))
        grade = look_from_dict(entry, str(path))
        space = grade.working or default_working_space()
        return Grade(grade.names, grade.weights, grade.color_map,
                     _resolve(space, path, "working space"), grade.strength, grade.regrain,
                     grade.loss, info=grade.info, saved=grade.saved,
                     regrain_follow=grade.regrain_follow)
    if suffix not in LOOK_SUFFIXES:
        raise InputError(f"{path}: a saved grade must end in .json or one of "
                         f"{', '.join(LOOK_SUFFIXES)}")
    table, space = _clf_look(path) if suffix in (".clf", ".3dl") else _cube_look(path)
    if not np.isfinite(table).all():
        raise InputError(f"{path}: the LUT holds NaN or infinite values")
    if space is not None:
        space = _resolve(space, path, "the space its header names")
    elif working_space:
        space = _resolve(working_space, path, "spaces.working")
    else:
        space = default_working_space()
    kind = suffix.lstrip(".")
    return Grade(names=(path.stem,), weights=np.ones(1), color_map=table, working=space,
                 info={"saved_look": {"file": str(path), "kind": kind}},
                 saved=SavedFrom(str(path), kind))


def saved_name(grade: Grade | None) -> str:
    """What a saved grade is called where a style set is called by its folder: its file."""
    return str(grade.saved.file) if grade is not None and grade.saved is not None \
        else "saved grade"


def look_batch_options(options, look: Grade, consistent: bool = False, lut=None,
                       report_dir=None):
    """The options of a batch (or clip) graded with a saved grade: its working space.

    ``consistent``, ``lut`` and ``report_dir`` make no sense with one (it is
    already one grade for every photo, and there are no styles): OptionError.
    """
    from dataclasses import replace


    for given, name in ((consistent, "consistent"), (lut is not None, "lut"),
                        (report_dir is not None, "report_dir")):
        if given:
            raise OptionError(f"{{{name}}} does not go with {{look}} (a saved grade is already one "
                              "grade for every photo, with no styles to report)", name,
                              also=("look",))
    return replace(options, spaces=replace(options.spaces, working=look.working))
