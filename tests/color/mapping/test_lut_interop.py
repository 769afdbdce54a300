"""Every LUT kind ``apply --lut`` writes, applied by the tools that read it (issue 21, case 16).

A photo is graded with ``--no-regrain`` (a LUT holds the whole grade then) and
its LUT written; the LUT is then applied to the same photo by colour-science,
OpenColorIO (the ``opencolorio`` package, 2.6) and ffmpeg's ``lut3d`` (the
``imageio-ffmpeg`` binary), and each result compared with the graded photo.

- plain ``.cube`` (sRGB working space: the LUT takes and gives sRGB code
  values): all three read it;
- shaper ``.cube`` (ACEScct working space: a 1D shaper from linear ACEScg,
  then the 3D table, giving ACEScct): colour-science and OpenColorIO read it
  (OpenColorIO 2.6 used to refuse it: ``Unsupported tag: 'TITLE'``); ffmpeg's
  ``lut3d`` has no 1D shaper and used to read the shaper's entries as the 3D
  table (116/255 off on a ramp, silently): it must now refuse the file;
- CLF (ACEScct): OpenColorIO reads it (colour-science 0.4 and ffmpeg read no CLF).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.color.conftest import FAST_ARGS, SAMPLES, small_copy
from tests.conftest import run_cli
from wbcgrade.color import colorspace as cs
from wbcgrade.color.io.images import read_image

ocio = pytest.importorskip("PyOpenColorIO")
FAST = [*FAST_ARGS, "--map-size", "17", "--no-regrain"]


@pytest.fixture(scope="module")
def photo(tmp_path_factory) -> Path:
    """A small lossless (PNG) copy of the chelsea sample."""
    return small_copy(SAMPLES / "chelsea.jpg", tmp_path_factory.mktemp("lut") / "chelsea.png")


def graded_with_lut(photo: Path, folder: Path, working: str, name: str) -> tuple[Path, Path]:
    out, lut = folder / f"{name}.png", folder / name
    result = run_cli("apply", str(photo), "--preset", "warm", "-o", str(out),
                     "--working-space", working, "--lut", str(lut),
                     *(["--lut-format", "clf"] if name.endswith(".clf")
                       else []), *FAST)
    assert result.exit_code == 0, result.output
    return out, lut


def pixels(path: Path) -> np.ndarray:
    return read_image(path).pixels[..., :3].astype(np.float32)


def with_ocio(lut: Path, rgb: np.ndarray) -> np.ndarray:
    transform = ocio.FileTransform(src=str(lut), interpolation=ocio.INTERP_TETRAHEDRAL)
    processor = ocio.Config.CreateRaw().getProcessor(transform).getDefaultCPUProcessor()
    out = np.ascontiguousarray(rgb, dtype=np.float32).copy()
    processor.applyRGB(out)
    return out


def with_colour(lut: Path, rgb: np.ndarray) -> np.ndarray:
    from wbcgrade.color._colour import colour

    return np.asarray(colour.read_LUT(str(lut)).apply(rgb), dtype=np.float32)


def with_ffmpeg(lut: Path, photo: Path, out: Path) -> subprocess.CompletedProcess:
    from imageio_ffmpeg import get_ffmpeg_exe

    return subprocess.run([get_ffmpeg_exe(), "-hide_banner", "-loglevel", "error", "-y", "-i",
                           str(photo), "-vf", f"lut3d=file={lut.name}:interp=tetrahedral",
                           "-frames:v", "1", str(out)], cwd=lut.parent, capture_output=True,
                          text=True, timeout=60)


def error_255(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    gap = np.abs(np.asarray(a, np.float64) - b) * 255
    return float(gap.max()), float(gap.mean())


@pytest.mark.slow
def test_a_plain_cube_reads_alike_in_colour_ocio_and_ffmpeg(photo, tmp_path):
    graded, lut = graded_with_lut(photo, tmp_path, "srgb", "plain.cube")
    source, expected = pixels(photo), pixels(graded)
    assert error_255(source, expected)[1] > 5  # it did grade
    for name, applied in (("colour", with_colour(lut, source)),
                          ("ocio", with_ocio(lut, source))):
        worst, mean = error_255(applied, expected)
        assert worst < 1.5 and mean < 0.4, (name, worst, mean)  # measured 0.5-0.8, 0.25
    run = with_ffmpeg(lut, photo, tmp_path / "ffmpeg.png")
    assert run.returncode == 0, run.stderr
    worst, mean = error_255(pixels(tmp_path / "ffmpeg.png"), expected)
    assert worst < 1.5 and mean < 0.6, ("ffmpeg", worst, mean)  # 1.0, 0.51 (8-bit output)


def _through_acescg(photo: Path, lut: Path, apply) -> np.ndarray:
    """The photo into linear ACEScg, through the LUT (-> ACEScct), back to sRGB, clipped to
    [0, 1] as the graded photo's 8-bit file is (saturated reds leave sRGB's gamut)."""
    acescct = cs.resolve_space("acescct")
    linear = cs.convert(pixels(photo), "sRGB Encoded Rec.709 (sRGB)", cs.linear_partner(acescct))
    return np.clip(cs.convert(apply(lut, linear), acescct, "sRGB Encoded Rec.709 (sRGB)"), 0, 1)


@pytest.mark.slow
def test_a_shaper_cube_reads_right_in_colour_and_ocio_and_ffmpeg_refuses_it(photo, tmp_path):
    graded, lut = graded_with_lut(photo, tmp_path, "acescct", "shaper.cube")
    expected = pixels(graded)
    assert error_255(pixels(photo), expected)[1] > 5
    for name, apply in (("colour", with_colour), ("ocio", with_ocio)):
        worst, mean = error_255(_through_acescg(photo, lut, apply), expected)
        assert worst < 2 and mean < 0.4, (name, worst, mean)  # measured 0.6-1.3, 0.24-0.28
    run = with_ffmpeg(lut, photo, tmp_path / "ffmpeg.png")
    assert run.returncode != 0 and not (tmp_path / "ffmpeg.png").exists()
    assert "Invalid data" in run.stderr


@pytest.mark.slow
def test_a_clf_reads_right_in_ocio(photo, tmp_path):
    graded, lut = graded_with_lut(photo, tmp_path, "acescct", "grade.clf")
    worst, mean = error_255(_through_acescg(photo, lut, with_ocio), pixels(graded))
    assert worst < 2 and mean < 0.4, (worst, mean)  # measured 1.3, 0.28
