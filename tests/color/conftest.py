"""Fixtures for the colour tests: small photos written to temporary folders."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from wbcgrade.color.options import GradeOptions

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
STYLE_PHOTOS = ("aitzgorri", "coffee", "flower", "seeding")
#: A preset of three sample photos (coffee, flower, sunset; 32^3, no working space recorded):
#: the former shipped "warm" preset, kept for tests that need three styles or an old file.
THREE_STYLES = Path(__file__).resolve().parents[1] / "data" / "three_samples.npz"


def small_copy(src: Path, dst: Path, width: int = 96) -> Path:
    """Write a downscaled copy of a photo (keeps the tests fast)."""
    buf = oiio.ImageBuf(str(src))
    spec = buf.spec()
    height = max(1, round(spec.height * width / spec.width))
    small = oiio.ImageBufAlgo.resample(buf, roi=oiio.ROI(0, width, 0, height, 0, 1, 0, 3))
    assert small.write(str(dst)), small.geterror()
    return dst


def write_array(path: Path, pixels: np.ndarray, fmt: str, attribs: dict | None = None) -> Path:
    """Write (H, W, C) float pixels with OpenImageIO in the given format."""
    height, width, channels = pixels.shape
    spec = oiio.ImageSpec(width, height, channels, fmt)
    for name, value in (attribs or {}).items():
        if isinstance(value, tuple):
            spec.attribute(name, value[0], value[1])
        else:
            spec.attribute(name, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    assert out.write_image(np.ascontiguousarray(pixels, dtype=np.float32))
    out.close()
    return path


@pytest.fixture(scope="session")
def style_dir(tmp_path_factory) -> Path:
    """A folder of four small style photos."""
    folder = tmp_path_factory.mktemp("styles")
    for name in STYLE_PHOTOS:
        small_copy(SAMPLES / f"{name}.jpg", folder / f"{name}.jpg")
    return folder


@pytest.fixture
def photo(tmp_path) -> Path:
    """A small copy of the chelsea sample (not among the styles)."""
    return small_copy(SAMPLES / "chelsea.jpg", tmp_path / "chelsea.jpg")


@pytest.fixture
def fast_options() -> GradeOptions:
    """Small grids so a whole grade takes a fraction of a second."""
    return GradeOptions(mode="palette", bins=16, fit_bins=8, max_iter=10, n_iter=30)


FAST_ARGS = ["--mode", "palette", "--bins", "16", "--fit-bins", "8", "--max-iter", "10",
             "--iterations", "30", "--no-cache"]


def grade_of(rgb, styles, options):
    """The grade of sRGB-encoded pixels (H, W, 3) in the default working space."""
    from wbcgrade.color.colorspace import ColorEncoding
    from wbcgrade.color.grade.grading import grade_encoded

    return grade_encoded(np.asarray(rgb, np.float32), styles, options, ColorEncoding.of())[0]
