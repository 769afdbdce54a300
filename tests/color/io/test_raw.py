"""Raw camera files: a DNG made here (a Bayer mosaic with a known ramp) is read by LibRaw,
graded end to end and keeps its tonal range; bad raws get a one-line error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.color.conftest import FAST_ARGS
from tests.conftest import run_cli as run
from wbcgrade.color.colorspace import ColorEncoding, canonical
from wbcgrade.color.io.images import read_image
from wbcgrade.color.mapping.lut import write_cube
from wbcgrade.color.mapping.remap import identity_map
from wbcgrade.errors import InputError

tifffile = pytest.importorskip("tifffile")
WHITE = 65535


def write_dng(path: Path, mosaic: np.ndarray, white: int = WHITE) -> Path:
    """A minimal DNG 1.4: one raw (CFA, RGGB) image, 16-bit, identity colour matrix, neutral
    white balance as shot (the tags LibRaw needs to demosaic it)."""
    tags = [
        (50706, "B", 4, (1, 4, 0, 0), True),           # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),           # DNGBackwardVersion
        (50708, "s", 0, "wbcgrade test camera", True),  # UniqueCameraModel
        (33421, "H", 2, (2, 2), True),                 # CFARepeatPatternDim
        (33422, "B", 4, (0, 1, 1, 2), True),           # CFAPattern: RGGB
        (50710, "B", 3, (0, 1, 2), True),              # CFAPlaneColor
        (50711, "H", 1, 1, True),                      # CFALayout: rectangular
        (50714, "H", 1, 0, True),                      # BlackLevel
        (50717, "H", 1, white, True),                  # WhiteLevel
        (50721, "2i", 9, (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), True),
        (50778, "H", 1, 21, True),                     # CalibrationIlluminant1: D65
        (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True),    # AsShotNeutral
    ]
    tifffile.imwrite(path, np.asarray(mosaic, dtype=np.uint16), photometric=32803,
                     extratags=tags, subfiletype=0, compression=None, metadata=None)
    return path


def ramp_mosaic(height: int = 48, width: int = 512) -> np.ndarray:
    """A grey ramp from black to the white level, left to right (every photosite)."""
    return np.round(np.linspace(0.0, 1.0, width)[None, :] * WHITE).repeat(height, 0)



def test_raw_reads_as_scene_linear_aces(tmp_path):
    image = read_image(write_dng(tmp_path / "ramp.dng", ramp_mosaic()))
    assert image.is_float and image.format_name == "raw" and image.pixels.shape == (48, 512, 3)
    grey = image.pixels[24, :, 1]
    # linear, no gamma, no brightening: the ramp comes back as a ramp from 0 to 1
    assert grey[0] < 0.005 and grey[-1] > 0.99
    middle = grey[100:400]
    expected = np.linspace(0, 1, 512)[100:400]
    assert np.abs(middle - expected).max() < 0.02
    assert len(np.unique(middle)) == len(middle)  # 16-bit, every step kept
    encoding = ColorEncoding.for_image(image)
    assert encoding.input == canonical("aces2065-1") and encoding.working == canonical("acescct")


@pytest.mark.slow
def test_raw_grades_end_to_end_keeping_its_tonal_range(tmp_path, style_dir):
    dng = write_dng(tmp_path / "ramp.dng", ramp_mosaic())
    before = dng.read_bytes()
    for name in ("graded.tif", "graded.exr"):
        result = run("apply", dng, "--style", style_dir, "-o", tmp_path / name, *FAST_ARGS)
        assert result.exit_code == 0, result.output
    assert dng.read_bytes() == before
    tif = oiio.ImageInput.open(str(tmp_path / "graded.tif"))
    assert tif.spec().format == oiio.UINT16 and tif.spec().nchannels == 3  # 16-bit by default
    codes = tif.read_image(0, 0, 0, 3, oiio.UINT16)[24]
    tif.close()
    # sRGB-encoded 16-bit: the ramp keeps far more than 8-bit's 256 levels, from near black
    # to near white, and stays in order (the grade is monotone in lightness)
    luma = codes.astype(np.float64) @ [0.299, 0.587, 0.114]
    assert len(np.unique(codes[:, 1])) > 400
    assert luma[-4:].mean() - luma[:4].mean() > 0.7 * 65535
    assert np.all(np.diff(luma[8:-8]) > -0.002 * 65535)
    exr = read_image(tmp_path / "graded.exr")
    assert exr.is_float and exr.spec.getattribute("chromaticities") is not None
    linear = exr.pixels[24, :, 1]
    # float: the darkest steps stay apart (no 8-bit floor) and the top stays near 1
    assert linear[-1] > 0.5 and 0 <= linear[2] < linear[6] < linear[12] < 0.05
    assert len(np.unique(linear)) > 500
    # through an identity look the whole range comes out: black to white, 16-bit steps
    identity = write_cube(tmp_path / "identity.cube", identity_map(2))
    result = run("apply", dng, "--look", identity, "-o", tmp_path / "same.tif")
    assert result.exit_code == 0, result.output
    same = read_image(tmp_path / "same.tif").pixels[24, :, 1]
    result = run("apply", dng, "--look", identity)  # no -o: a TIFF beside the raw
    assert result.exit_code == 0, result.output
    assert read_image(tmp_path / "ramp_graded.tif").spec.format == oiio.UINT16
    assert same[0] < 0.06 and same[-1] > 0.99 and len(np.unique(same)) > 480


@pytest.mark.parametrize("damage", ["truncated", "garbage"])
def test_bad_raw_gets_one_line_error(tmp_path, damage):
    dng = write_dng(tmp_path / "ramp.dng", ramp_mosaic())
    bad = tmp_path / "bad.nef"
    bad.write_bytes(dng.read_bytes()[:3000] if damage == "truncated" else b"not a raw" * 50)
    with pytest.raises(InputError, match="bad.nef"):
        read_image(bad)
    result = run("apply", bad, "--preset", "warm", "-o", tmp_path / "out.jpg")
    assert result.exit_code != 0
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: ") and "bad.nef" in lines[0]
    assert "Traceback" not in result.output and not (tmp_path / "out.jpg").exists()


@pytest.mark.slow
def test_batch_grades_raw_photos_into_tiffs(tmp_path, style_dir):
    folder = tmp_path / "shoot"
    folder.mkdir()
    write_dng(folder / "ramp.dng", ramp_mosaic(32, 128))
    small = read_image(write_dng(tmp_path / "x.dng", ramp_mosaic(32, 128)))
    assert small.pixels.shape == (32, 128, 3)
    for consistent in ([], ["--consistent"]):
        out = tmp_path / f"out{len(consistent)}"
        result = run("batch", folder, "-o", out, "--style", style_dir, *consistent, *FAST_ARGS)
        assert result.exit_code == 0, result.output
        assert "graded 1," in result.output
        graded = read_image(out / "ramp.tif")
        assert graded.spec.format == oiio.UINT16 and graded.pixels.shape == (32, 128, 3)
