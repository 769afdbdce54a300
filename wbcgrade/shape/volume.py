"""Volumes (``.npy``, NIfTI) and the densities the core fits.

A *volume* is a non-negative 3-D array (an occupancy, an MRI intensity); a
*density* is that volume turned into a histogram the core can fit: a floor
``eps`` (relative to the volume's maximum) is added so that the KL loss is
defined everywhere, and the result is normalised to sum 1.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from wbcgrade._publish import publish_bytes
from wbcgrade.errors import InputError, first_line
from wbcgrade.limits import read_npy

VOLUME_SUFFIXES = (".npy", ".nii", ".nii.gz")
"""File suffixes read as volumes."""

DEFAULT_EPS = 1e-4
"""Density outside a shape, relative to the density inside (paper §5.3)."""


def volume_suffix(path: str | os.PathLike) -> str:
    """The volume suffix of ``path`` (``.npy``, ``.nii`` or ``.nii.gz``), else ``''``."""
    name = str(path).lower()
    for suffix in (".nii.gz", ".nii", ".npy"):
        if name.endswith(suffix):
            return suffix
    return ""


def read_volume(path: str | os.PathLike) -> np.ndarray:
    """Read a 3-D volume from ``.npy`` or NIfTI (``.nii``, ``.nii.gz``; needs nibabel).

    Returns
    -------
    (X, Y, Z) float64 array, finite and non-negative.

    Raises
    ------
    InputError
        Missing or unreadable file, not 3-D, non-finite or negative values,
        or all zero.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such volume file")
    suffix = volume_suffix(path)
    if suffix == ".npy":
        data = read_npy(path)  # its header's size checked before anything is allocated
    elif suffix in (".nii", ".nii.gz"):
        nibabel = _import_nibabel()
        try:
            data = np.asarray(nibabel.load(str(path)).get_fdata(dtype=np.float64))
        except Exception as exc:
            raise InputError(f"{path}: unreadable NIfTI file ({first_line(exc)})") from exc
    else:
        raise InputError(
            f"{path}: unsupported volume format; use one of {', '.join(VOLUME_SUFFIXES)}"
        )
    data = np.squeeze(np.asarray(data))
    if data.ndim != 3:
        raise InputError(f"{path}: expected a 3-D volume, got shape {data.shape}")
    if not np.issubdtype(data.dtype, np.number) or np.iscomplexobj(data):
        raise InputError(f"{path}: expected real numbers, got dtype {data.dtype}")
    data = data.astype(np.float64)
    if not np.all(np.isfinite(data)):
        raise InputError(f"{path}: the volume holds NaN or infinite values")
    if data.min() < 0:
        raise InputError(f"{path}: the volume holds negative values (min {data.min():.3g})")
    if data.max() <= 0:
        raise InputError(f"{path}: the volume is all zero")
    return data


def write_volume(path: str | os.PathLike, volume: np.ndarray) -> None:
    """Write ``volume`` atomically as ``.npy`` (or NIfTI with an identity affine)."""
    path = Path(path)
    suffix = volume_suffix(path)
    volume = np.ascontiguousarray(volume)
    if suffix == ".npy":
        buffer = io.BytesIO()
        np.save(buffer, volume, allow_pickle=False)
        publish_bytes(path, buffer.getvalue())
    elif suffix in (".nii", ".nii.gz"):
        nibabel = _import_nibabel()
        image = nibabel.Nifti1Image(volume.astype(np.float32), affine=np.eye(4))
        data = image.to_bytes()
        if suffix == ".nii.gz":
            import gzip

            data = gzip.compress(data)
        publish_bytes(path, data)
    else:
        raise InputError(f"{path}: unsupported volume format; use .npy, .nii or .nii.gz")


def resample_volume(volume: np.ndarray, max_size: int) -> np.ndarray:
    """Shrink ``volume`` so its largest axis has ``max_size`` voxels (aspect kept).

    Volumes already small enough are returned unchanged. Uses
    ``skimage.transform.resize`` with anti-aliasing; mass is not preserved
    (densities are normalised afterwards anyway).
    """
    from skimage.transform import resize

    if max_size < 2:
        raise InputError(f"resolution must be at least 2, got {max_size}")
    largest = max(volume.shape)
    if largest <= max_size:
        return volume
    shape = tuple(max(2, round(size * max_size / largest)) for size in volume.shape)
    return np.clip(resize(volume, shape, order=1, anti_aliasing=True), 0.0, None)


def density_from_volume(volume: np.ndarray, eps: float = DEFAULT_EPS) -> np.ndarray:
    """Histogram (same shape, sums to 1) from a non-negative volume.

    ``density ∝ v / max(v) * (1 - eps) + eps``: an occupancy in [0, 1] becomes
    a uniform density inside and ``eps`` times that density outside.
    """
    volume = np.asarray(volume, dtype=np.float64)
    peak = float(volume.max())
    if not np.isfinite(peak) or peak <= 0:
        raise InputError("the volume is empty (no positive value)")
    if not 0.0 < eps < 1.0:
        raise InputError(f"eps must be in (0, 1), got {eps}")
    density = volume / peak * (1.0 - eps) + eps
    return density / density.sum()


def _import_nibabel():
    try:
        import nibabel
    except ImportError as exc:
        raise InputError(
            "reading NIfTI volumes needs nibabel: pip install 'wbcgrade[nifti]' (or nibabel)"
        ) from exc
    return nibabel

