"""Volume files, densities and pictures."""

from __future__ import annotations

import builtins

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.shape.helpers import ball
from wbcgrade.errors import InputError
from wbcgrade.shape.render import Panel, contact_sheet, render_surface, write_png
from wbcgrade.shape.volume import (
    density_from_volume,
    read_volume,
    resample_volume,
    write_volume,
)


def test_npy_round_trip_and_density(tmp_path):
    volume = ball(10, 0.3)
    write_volume(tmp_path / "v.npy", volume)
    back = read_volume(tmp_path / "v.npy")
    np.testing.assert_array_equal(back, volume)
    density = density_from_volume(back, eps=1e-4)
    assert density.sum() == pytest.approx(1.0)
    inside, outside = density[5, 5, 5], density[0, 0, 0]
    assert outside / inside == pytest.approx(1e-4)


@pytest.mark.parametrize(
    "array, message",
    [
        (np.ones((4, 4)), "3-D"),
        (-np.ones((4, 4, 4)), "negative"),
        (np.full((4, 4, 4), np.nan), "NaN"),
        (np.zeros((4, 4, 4)), "all zero"),
    ],
)
def test_bad_volumes_are_refused(tmp_path, array, message):
    np.save(tmp_path / "bad.npy", array)
    with pytest.raises(InputError, match=message):
        read_volume(tmp_path / "bad.npy")


def test_unreadable_and_unknown_volumes(tmp_path):
    (tmp_path / "junk.npy").write_bytes(b"not numpy")
    with pytest.raises(InputError, match="unreadable"):
        read_volume(tmp_path / "junk.npy")
    (tmp_path / "v.raw").write_bytes(b"\0" * 8)
    with pytest.raises(InputError, match="unsupported"):
        read_volume(tmp_path / "v.raw")


def test_nifti_round_trip(tmp_path):
    pytest.importorskip("nibabel")
    volume = ball(9, 0.3) * 7.0
    for name in ("v.nii", "v.nii.gz"):
        write_volume(tmp_path / name, volume)
        np.testing.assert_allclose(read_volume(tmp_path / name), volume)


def test_nifti_without_nibabel_says_what_to_install(tmp_path, monkeypatch):
    real_import = builtins.__import__

    def no_nibabel(name, *args, **kwargs):
        if name == "nibabel":
            raise ImportError("no nibabel")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_nibabel)
    (tmp_path / "v.nii").write_bytes(b"\0" * 8)
    with pytest.raises(InputError, match="nibabel"):
        read_volume(tmp_path / "v.nii")


def test_resample_keeps_aspect():
    volume = np.ones((40, 20, 10))
    small = resample_volume(volume, 20)
    assert small.shape == (20, 10, 5)
    assert resample_volume(volume, 64) is volume


def test_render_and_contact_sheet(tmp_path):
    volume = ball(16, 0.3)
    image = render_surface(volume, 0.5, axis=2)
    assert image.shape == (16, 16, 3)
    assert image[8, 8].max() > 0.3 and image[0, 0].max() == 0.0
    sheet = contact_sheet(
        [Panel(volume, "ball", 0.5), Panel(volume * 3, "projection")], tile=64
    )
    assert sheet.ndim == 3 and sheet.shape[2] == 3
    write_png(tmp_path / "sheet.png", sheet)
    spec = oiio.ImageInput.open(str(tmp_path / "sheet.png")).spec()
    assert (spec.width, spec.height) == (sheet.shape[1], sheet.shape[0])
    with pytest.raises(InputError, match="folder"):
        write_png(tmp_path / "absent" / "x.png", sheet)
