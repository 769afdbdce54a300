"""The MERL measured-BRDF binary format (Matusik et al. 2003).

File layout (little-endian): a header of three int32 dimensions
``(90, 90, 180)`` -- the numbers of bins in theta_half, theta_diff and
phi_diff -- then ``3 * 90 * 90 * 180`` float64 values, channel-major (all red,
then green, then blue), each channel stored in C order over
``(theta_half, theta_diff, phi_diff)``. A stored value times the channel
scale ``(1/1500, 1.15/1500, 1.66/1500)`` is the BRDF in 1/sr. Negative values
mark bins without a measurement.

The parametrisation is Rusinkiewicz's half/difference angles, binned as in
MERL's reference reader ``BRDFRead.cpp``: theta_half non-linearly
(index ``floor(sqrt(theta_half_deg * 90))``, finer near the specular peak),
theta_diff uniformly in 1-degree bins, phi_diff uniformly over [0, 180)
degrees (reciprocity folds phi_diff + 180 onto phi_diff). The format holds
isotropic BRDFs only (phi_half is dropped).

In this module a *table* is the float64 array of shape ``(3, 90, 90, 180)``
holding BRDF values (scales applied).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wbcgrade._publish import atomic_path
from wbcgrade.errors import InputError

MERL_SHAPE = (90, 90, 180)
"""Bins in (theta_half, theta_diff, phi_diff)."""

MERL_SCALES = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
"""Per-channel factors from stored values to BRDF values (red, green, blue)."""

_HEADER_BYTES = 3 * 4
_VALUE_COUNT = 3 * MERL_SHAPE[0] * MERL_SHAPE[1] * MERL_SHAPE[2]
MERL_FILE_BYTES = _HEADER_BYTES + 8 * _VALUE_COUNT
"""Size of a MERL file in bytes (34,992,012)."""


# -- reading and writing ----------------------------------------------------------------------


def read_merl(path: str | os.PathLike) -> np.ndarray:
    """Read a MERL ``.binary`` file.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    table : ndarray, shape (3, 90, 90, 180), float64
        BRDF values (channel scales applied); negative where the file has no
        measurement.

    Raises
    ------
    InputError
        Wrong file size, wrong header, or non-finite values.
    """
    path = Path(path)
    size = path.stat().st_size
    if size < _HEADER_BYTES:
        raise InputError(f"{path}: not a MERL BRDF file ({size} bytes, too short for a header)")
    with open(path, "rb") as handle:
        header = np.frombuffer(handle.read(_HEADER_BYTES), dtype="<i4")
        if tuple(int(v) for v in header) != MERL_SHAPE:
            raise InputError(
                f"{path}: not a MERL BRDF file (header dimensions {tuple(int(v) for v in header)}, "
                f"expected {MERL_SHAPE})"
            )
        if size != MERL_FILE_BYTES:
            raise InputError(
                f"{path}: wrong size for a MERL BRDF file ({size} bytes, expected "
                f"{MERL_FILE_BYTES}): truncated or not float64"
            )
        raw = np.frombuffer(handle.read(), dtype="<f8")
    if raw.size != _VALUE_COUNT:  # file changed while reading
        raise InputError(f"{path}: truncated MERL BRDF file")
    table = raw.reshape((3, *MERL_SHAPE)) * MERL_SCALES[:, None, None, None]
    bad = ~np.isfinite(table)
    if bad.any():
        raise InputError(f"{path}: MERL BRDF file holds {int(bad.sum())} NaN or infinite values")
    return table


def write_merl(path: str | os.PathLike, table: np.ndarray) -> Path:
    """Write a table as a MERL ``.binary`` file, atomically.

    Parameters
    ----------
    path : path-like
        Output file; written to a temporary file in the same folder, then renamed.
    table : ndarray, shape (3, 90, 90, 180)
        BRDF values; negative entries mean "no measurement".

    Returns
    -------
    path : Path
    """
    path = Path(path)
    table = np.asarray(table, dtype=np.float64)
    if table.shape != (3, *MERL_SHAPE):
        raise InputError(f"a MERL table has shape {(3, *MERL_SHAPE)}, got {table.shape}")
    if not np.isfinite(table).all():
        raise InputError("refusing to write a MERL file with NaN or infinite values")
    raw = np.ascontiguousarray(table / MERL_SCALES[:, None, None, None], dtype="<f8")
    with atomic_path(path) as temporary, open(temporary, "wb") as handle:
        handle.write(np.asarray(MERL_SHAPE, dtype="<i4").tobytes())
        handle.write(raw.tobytes())
    return path


# -- angles -----------------------------------------------------------------------------------


def _rotate_z(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([v[..., 0] * c - v[..., 1] * s, v[..., 0] * s + v[..., 1] * c, v[..., 2]], -1)


def _rotate_y(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([v[..., 0] * c + v[..., 2] * s, v[..., 1], v[..., 2] * c - v[..., 0] * s], -1)


def half_diff_angles(
    incoming: np.ndarray, outgoing: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rusinkiewicz half/difference angles of direction pairs.

    Parameters
    ----------
    incoming, outgoing : ndarray, shape (..., 3)
        Unit vectors in the local frame (z = normal).

    Returns
    -------
    theta_half, phi_half, theta_diff, phi_diff : ndarray, shape (...)
        Radians; the difference vector is ``incoming`` expressed in the frame
        of the half vector (rotations by -phi_half about z, then -theta_half about y).
    """
    incoming = np.asarray(incoming, dtype=np.float64)
    outgoing = np.asarray(outgoing, dtype=np.float64)
    half = incoming + outgoing
    norm = np.linalg.norm(half, axis=-1, keepdims=True)
    half = np.divide(half, norm, out=np.tile([0.0, 0.0, 1.0], half.shape[:-1] + (1,)),
                     where=norm > 1e-12)
    theta_half = np.arccos(np.clip(half[..., 2], -1.0, 1.0))
    phi_half = np.arctan2(half[..., 1], half[..., 0])
    diff = _rotate_y(_rotate_z(incoming, -phi_half), -theta_half)
    theta_diff = np.arccos(np.clip(diff[..., 2], -1.0, 1.0))
    phi_diff = np.arctan2(diff[..., 1], diff[..., 0])
    return theta_half, phi_half, theta_diff, phi_diff


def directions_from_half_diff(
    theta_half: np.ndarray, phi_half: np.ndarray, theta_diff: np.ndarray, phi_diff: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Incoming and outgoing unit vectors, shape (..., 3), from half/difference angles."""
    theta_half, phi_half, theta_diff, phi_diff = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta_half, phi_half, theta_diff, phi_diff))
    )
    diff = np.stack(
        [np.sin(theta_diff) * np.cos(phi_diff), np.sin(theta_diff) * np.sin(phi_diff),
         np.cos(theta_diff)], -1,
    )
    incoming = _rotate_z(_rotate_y(diff, theta_half), phi_half)
    half = np.stack(
        [np.sin(theta_half) * np.cos(phi_half), np.sin(theta_half) * np.sin(phi_half),
         np.cos(theta_half)], -1,
    )
    outgoing = 2.0 * np.sum(incoming * half, axis=-1, keepdims=True) * half - incoming
    return incoming, outgoing


def merl_bin_indices(
    incoming: np.ndarray, outgoing: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MERL bin of each direction pair, as in ``BRDFRead.cpp``.

    Returns
    -------
    i_theta_half, i_theta_diff, i_phi_diff : ndarray of int, shape (...)
    """
    n_half, n_diff, n_phi = MERL_SHAPE
    theta_half, _, theta_diff, phi_diff = half_diff_angles(incoming, outgoing)
    degrees = theta_half / (np.pi / 2.0) * n_half
    i_half = np.floor(np.sqrt(np.clip(degrees * n_half, 0.0, None))).astype(np.int64)
    i_diff = np.floor(theta_diff / (np.pi / 2.0) * n_diff).astype(np.int64)
    phi_diff = np.where(phi_diff < 0.0, phi_diff + np.pi, phi_diff)
    i_phi = np.floor(phi_diff / np.pi * n_phi).astype(np.int64)
    return (np.clip(i_half, 0, n_half - 1), np.clip(i_diff, 0, n_diff - 1),
            np.clip(i_phi, 0, n_phi - 1))


def merl_bin_centres() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angles (radians) at the centres of the MERL bins.

    Returns
    -------
    theta_half : ndarray, shape (90,)
        ``(i + 1/2)^2 / 90`` degrees (the non-linear binning).
    theta_diff : ndarray, shape (90,)
        ``j + 1/2`` degrees.
    phi_diff : ndarray, shape (180,)
        ``k + 1/2`` degrees.
    """
    n_half, n_diff, n_phi = MERL_SHAPE
    theta_half = np.deg2rad((np.arange(n_half) + 0.5) ** 2 / n_half)
    theta_diff = np.deg2rad((np.arange(n_diff) + 0.5) * 90.0 / n_diff)
    phi_diff = np.deg2rad((np.arange(n_phi) + 0.5) * 180.0 / n_phi)
    return theta_half, theta_diff, phi_diff


def lookup_merl(table: np.ndarray, incoming: np.ndarray, outgoing: np.ndarray) -> np.ndarray:
    """BRDF values of a MERL table at direction pairs (nearest bin, as MERL's reader).

    Parameters
    ----------
    table : ndarray, shape (3, 90, 90, 180)
    incoming, outgoing : ndarray, shape (..., 3)
        Unit vectors in the local frame.

    Returns
    -------
    values : ndarray, shape (..., 3)
        Bins without a measurement (negative) read as 0.
    """
    i_half, i_diff, i_phi = merl_bin_indices(incoming, outgoing)
    values = table[:, i_half, i_diff, i_phi]
    return np.moveaxis(np.clip(values, 0.0, None), 0, -1)


def tabulate_merl(brdf: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """Evaluate a BRDF at the centre of every MERL bin (with phi_half = 0).

    Parameters
    ----------
    brdf : callable ``(incoming (..., 3), outgoing (..., 3)) -> values (..., 3)``
        Must accept bin centres whose directions dip below the horizon (the
        MERL grid has such bins near grazing angles) and return finite values.

    Returns
    -------
    table : ndarray, shape (3, 90, 90, 180)
    """
    theta_half, theta_diff, phi_diff = merl_bin_centres()
    table = np.empty((3, *MERL_SHAPE))
    th_d, ph_d = np.meshgrid(theta_diff, phi_diff, indexing="ij")
    for i, angle in enumerate(theta_half):  # one theta_half slice at a time keeps memory small
        incoming, outgoing = directions_from_half_diff(angle, 0.0, th_d, ph_d)
        values = np.asarray(brdf(incoming, outgoing), dtype=np.float64)
        table[:, i] = np.moveaxis(values, -1, 0)
    if not np.isfinite(table).all():
        raise InputError("the BRDF returned NaN or infinite values on the MERL grid")
    return table


def resample_merl(table: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Resample a MERL table onto a hemisphere sampling.

    Parameters
    ----------
    table : ndarray, shape (3, 90, 90, 180)
    directions : ndarray, shape (N, 3)
        Used for both the incoming and the outgoing direction.

    Returns
    -------
    values : ndarray, shape (N, N, 3)
        ``values[a, b, c]`` = BRDF for light arriving from ``directions[a]``
        and leaving towards ``directions[b]``, channel ``c``.
    """
    directions = np.asarray(directions, dtype=np.float64)
    incoming = np.broadcast_to(directions[:, None, :], (len(directions), len(directions), 3))
    outgoing = np.broadcast_to(directions[None, :, :], incoming.shape)
    return lookup_merl(table, incoming, outgoing)
