"""BRDF files: MERL ``.binary`` and wbcgrade's sampled ``.npz``, and databases of them.

Two formats are read and written, chosen by the file suffix:

- ``.binary`` (also ``.merl``): the MERL format (``wbcgrade.brdf.merl``),
  isotropic, resampled onto the hemisphere sampling when read. Writing a
  sampled BRDF to it evaluates the BRDF at every MERL bin centre (phi_half = 0)
  by interpolation, so anisotropy is lost.
- ``.npz``: a sampled BRDF as it is fitted, lossless and anisotropic-capable:
  ``values`` (N, N, 3) float64, ``directions`` (N, 3) float64, ``format`` =
  ``"wbcgrade-brdf-sampled-1"``, ``name``. Its sampling must match the one
  in use (no resampling), otherwise reading fails with a clear error.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from wbcgrade._publish import publish_bytes
from wbcgrade.brdf import merl
from wbcgrade.brdf.sampled import check_values, interpolate
from wbcgrade.brdf.sampling import same_sampling
from wbcgrade.errors import InputError
from wbcgrade.limits import read_npz

SAMPLED_FORMAT = "wbcgrade-brdf-sampled-1"
MERL_SUFFIXES = (".binary", ".merl")
SAMPLED_SUFFIXES = (".npz",)
BRDF_SUFFIXES = MERL_SUFFIXES + SAMPLED_SUFFIXES


def read_sampled(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a sampled ``.npz`` BRDF.

    Returns
    -------
    values : ndarray, shape (N, N, 3)
    directions : ndarray, shape (N, 3)
    """
    path = Path(path)
    archive = read_npz(path)  # every member's size and type checked before it is read
    fmt = str(archive["format"]) if "format" in archive else None
    if fmt != SAMPLED_FORMAT or "values" not in archive or "directions" not in archive:
        raise InputError(f"{path}: not a wbcgrade sampled BRDF (.npz with format "
                         f"{SAMPLED_FORMAT!r}, values and directions)")
    try:
        values = np.asarray(archive["values"], dtype=np.float64)
        directions = np.asarray(archive["directions"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{path}: unreadable sampled BRDF ({exc})") from None
    if directions.ndim != 2 or directions.shape[1] != 3 or not np.isfinite(directions).all():
        raise InputError(f"{path}: directions must be finite with shape (N, 3), "
                         f"got {directions.shape}")
    values = check_values(values, len(directions), name=str(path))
    return values, directions


def write_sampled(path: str | os.PathLike, values: np.ndarray, directions: np.ndarray,
                  name: str = "") -> Path:
    """Write a sampled BRDF (N, N, 3) with its directions (N, 3) to ``.npz``, atomically."""
    path = Path(path)
    values = check_values(values, len(directions), name="BRDF to write")
    buffer = io.BytesIO()
    np.savez_compressed(buffer, values=values, directions=np.asarray(directions, np.float64),
                        format=np.str_(SAMPLED_FORMAT), name=np.str_(name))
    publish_bytes(path, buffer.getvalue())
    return path


def load_brdf(path: str | os.PathLike, directions: np.ndarray) -> np.ndarray:
    """Read a BRDF file onto a hemisphere sampling.

    Parameters
    ----------
    path : path-like
        ``.binary``/``.merl`` (resampled) or ``.npz`` (must use ``directions``).
    directions : ndarray, shape (N, 3)

    Returns
    -------
    values : ndarray, shape (N, N, 3)
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in MERL_SUFFIXES:
        return merl.resample_merl(merl.read_merl(path), directions)
    if suffix in SAMPLED_SUFFIXES:
        values, own = read_sampled(path)
        if not same_sampling(own, directions):
            raise InputError(
                f"{path}: sampled on a different set of {len(own)} directions than the "
                f"{len(directions)} in use (mismatched samplings; pass --directions {len(own)} "
                "or resample the file)"
            )
        return values
    raise InputError(f"{path}: unknown BRDF format {suffix!r} (expected one of "
                     f"{', '.join(BRDF_SUFFIXES)})")


def save_brdf(path: str | os.PathLike, values: np.ndarray, directions: np.ndarray,
              name: str = "") -> Path:
    """Write a sampled BRDF (N, N, 3) to ``.npz`` (lossless) or MERL ``.binary`` (isotropic)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in SAMPLED_SUFFIXES:
        return write_sampled(path, values, directions, name=name)
    if suffix in MERL_SUFFIXES:
        values = check_values(values, len(directions), name="BRDF to write")
        table = merl.tabulate_merl(lambda i, o: interpolate(values, directions, i, o))
        return merl.write_merl(path, table)
    raise InputError(f"{path}: unknown BRDF format {suffix!r} (expected one of "
                     f"{', '.join(BRDF_SUFFIXES)})")


def database_files(folder: str | os.PathLike) -> list[Path]:
    """BRDF files of a database folder, sorted by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder of BRDF files")
    files = sorted(
        p for p in folder.iterdir()
        if p.is_file() and p.suffix.lower() in BRDF_SUFFIXES and not p.name.startswith(".")
    )
    if not files:
        raise InputError(f"{folder}: no BRDF files ({', '.join(BRDF_SUFFIXES)}) in it")
    return files


def load_database(
    folder: str | os.PathLike, directions: np.ndarray, exclude: os.PathLike | None = None
) -> tuple[list[str], np.ndarray]:
    """Read every BRDF file of a folder onto one sampling.

    Parameters
    ----------
    folder : path-like
    directions : ndarray, shape (N, 3)
    exclude : path-like, optional
        A file to leave out (the measurement, when it lies in the folder).

    Returns
    -------
    names : list of str, length S
        File stems.
    values : ndarray, shape (S, N, N, 3)
    """
    files = database_files(folder)
    if exclude is not None:
        excluded = Path(exclude).resolve()
        files = [p for p in files if p.resolve() != excluded]
    if not files:
        raise InputError(f"{folder}: no BRDF files left once the measurement is left out")
    stems = [p.stem for p in files]
    if len(set(stems)) != len(stems):
        raise InputError(f"{folder}: two database files share a name; keep one format per name")
    values = np.stack([load_brdf(p, directions) for p in files])
    return stems, values
