"""Colour-managed grading: input and working spaces through OpenColorIO (OpenImageIO's).

Small images and fast grade settings; no network. The Display P3 photo
carries a real ICC v4 matrix/TRC profile built here (Display P3 primaries
adapted to D50 with colour-science's Bradford transform, the sRGB curve as
a parametric curve), which littleCMS (Pillow) reads as a valid profile.
"""

from __future__ import annotations

import json
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.color.conftest import FAST_ARGS, SAMPLES, THREE_STYLES, small_copy, write_array
from wbcgrade.color import colorspace as cs
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.histogram import HistogramCache, image_histogram
from wbcgrade.color.io.images import read_image
from wbcgrade.color.presets import (
    load_preset,
    load_style_folder,
    resolve_preset,
    save_preset,
    styles_in_space,
)
from wbcgrade.errors import InputError, OptionError

AP1 = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
#: The colour tests' fast settings and a small colour map (each grade well under a second).
FAST = [*FAST_ARGS, "--map-size", "9"]


# --- a real ICC profile -------------------------------------------------------------------

def _s15(value: float) -> bytes:
    return struct.pack(">i", int(round(value * 65536)))


def _xyz(values) -> bytes:
    return b"XYZ \0\0\0\0" + b"".join(_s15(v) for v in values)


def _mluc(text: str) -> bytes:
    body = text.encode("utf-16-be")
    return (b"mluc\0\0\0\0" + struct.pack(">II", 1, 12) + b"enUS"
            + struct.pack(">II", len(body), 28) + body)


def icc_profile(description: str, primaries: str = "Display P3") -> bytes:
    """An ICC v4 RGB display profile (matrix/TRC, sRGB curve) with these primaries."""
    from wbcgrade.color._colour import colour

    space = colour.RGB_COLOURSPACES[primaries]
    d65 = colour.xy_to_XYZ(space.whitepoint)
    d50 = colour.xy_to_XYZ(np.array([0.3457, 0.3585]))
    cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(d65, d50, "Bradford")
    columns = cat @ space.matrix_RGB_to_XYZ
    curve = b"para\0\0\0\0" + struct.pack(">H", 3) + b"\0\0" + b"".join(
        _s15(v) for v in (2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045))
    tags = [(b"desc", _mluc(description)), (b"cprt", _mluc("CC0")),
            (b"wtpt", _xyz(d50)), (b"rXYZ", _xyz(columns[:, 0])),
            (b"gXYZ", _xyz(columns[:, 1])), (b"bXYZ", _xyz(columns[:, 2])),
            (b"rTRC", curve), (b"gTRC", curve), (b"bTRC", curve),
            (b"chad", b"sf32\0\0\0\0" + b"".join(_s15(v) for v in cat.ravel()))]
    offset = 128 + 4 + 12 * len(tags)
    table, data = b"", b""
    for signature, body in tags:
        body += b"\0" * (-len(body) % 4)
        table += signature + struct.pack(">II", offset + len(data), len(body))
        data += body
    size = offset + len(data)
    header = (struct.pack(">I", size) + b"\0\0\0\0" + bytes([4, 0x30, 0, 0]) + b"mntrRGB XYZ "
              + struct.pack(">6H", 2026, 1, 1, 0, 0, 0) + b"acsp" + b"\0" * 24
              + struct.pack(">I", 0) + _s15(0.9642) + _s15(1.0) + _s15(0.8249)
              + b"\0" * 48)
    assert len(header) == 128
    return header + struct.pack(">I", len(tags)) + table + data


def write_with_icc(path: Path, pixels: np.ndarray, profile: bytes, fmt: str = "uint16") -> Path:
    icc = np.frombuffer(profile, dtype=np.uint8)
    return write_array(path, pixels, fmt,
                       {"ICCProfile": (oiio.TypeDesc(f"uint8[{len(icc)}]"), icc)})


# --- names --------------------------------------------------------------------------------

def test_names_resolve_through_aliases_and_roles_case_insensitively():
    names = cs.space_names()
    for alias in ("srgb", "SRGB", "display-p3", "Display P3", "adobe-rgb", "ACEScg", "acescct",
                  "linear-rec709", "lin_rec709", "scene_linear"):
        assert cs.resolve_space(alias) in names
    assert cs.resolve_space("acescct") == cs.resolve_space("ACES - ACEScct")
    assert cs.resolve_space("linear-rec709") != cs.resolve_space("srgb")


def test_an_unknown_space_is_an_option_error_listing_the_valid_names():
    with pytest.raises(OptionError, match="no-such-space") as caught:
        cs.resolve_space("no-such-space", "--input-space")
    message = str(caught.value)
    assert "\n" not in message and "--input-space" in message
    assert cs.resolve_space("acescct") in message and "display-p3" in message


def test_unknown_space_on_the_command_line_is_one_line_without_traceback(tmp_path, photo, cli):
    result = cli("apply", str(photo), "--preset", "warm", "--working-space",
                 "Rec.9999", "-o", str(tmp_path / "o.jpg"), *FAST)
    assert result.exit_code != 0 and "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "Rec.9999" in lines[0] and "ACEScct" in lines[0]
    assert not (tmp_path / "o.jpg").exists()


# --- detection and the default path -------------------------------------------------------

def test_the_file_says_its_space(tmp_path):
    pixels = np.random.default_rng(0).random((8, 8, 3)).astype(np.float32)
    p3 = read_image(write_with_icc(tmp_path / "p3.png", pixels,
                                   icc_profile("Display P3 (wbcgrade test)")))
    adobe = read_image(write_with_icc(tmp_path / "a.tif", pixels,
                                      icc_profile("Adobe RGB (1998)", "Adobe RGB (1998)")))
    plain = read_image(write_array(tmp_path / "plain.png", pixels, "uint8"))
    acescg = read_image(write_array(tmp_path / "cg.exr", pixels, "float",
                                    {"chromaticities": (oiio.TypeDesc("float[8]"), AP1)}))
    linear = read_image(write_array(tmp_path / "lin.exr", pixels, "half"))
    assert cs.detect_input_space(p3)[0] == cs.resolve_space("display-p3")
    assert "Display P3" in cs.detect_input_space(p3)[1]
    assert cs.detect_input_space(adobe)[0] == cs.resolve_space("adobe-rgb")
    assert cs.detect_input_space(plain)[0] == cs.resolve_space("srgb")
    assert cs.detect_input_space(acescg)[0] == cs.resolve_space("acescg")
    assert cs.detect_input_space(linear)[0] == cs.resolve_space("linear-rec709")
    srgb = cs.resolve_space("srgb")
    for image, input_space in ((plain, srgb), (linear, cs.resolve_space("linear-rec709")),
                               (p3, cs.resolve_space("display-p3"))):
        encoding = ColorEncoding.for_image(image)
        assert (encoding.input, encoding.working) == (input_space, srgb)


def test_the_profile_is_a_valid_icc_profile():
    ImageCms = pytest.importorskip("PIL.ImageCms")
    import io

    profile = ImageCms.ImageCmsProfile(io.BytesIO(icc_profile("Display P3 (wbcgrade test)")))
    assert "Display P3" in ImageCms.getProfileDescription(profile)


def test_the_encoding_agrees_with_colour_science_and_opencolorio(tmp_path):
    """One engine for every pair: sRGB as colour-science encodes it, other spaces as the
    opencolorio package's own processor converts them; 8-bit sRGB is passed as it is."""
    from wbcgrade.color._colour import colour

    rng = np.random.default_rng(1)
    values = rng.random((6, 7, 3)).astype(np.float32)
    image = read_image(write_array(tmp_path / "a.png", values, "uint8"))
    encoded, state = ColorEncoding.for_image(image).encode(image.rgb(), image.is_float)
    assert np.array_equal(encoded, image.rgb()) and state.residual is None
    linear = (rng.random((6, 7, 3)) * 4 - 0.5).astype(np.float32)  # above 1 and below 0
    encoding = ColorEncoding.of("linear-rec709", "srgb")
    encoded, state = encoding.encode(linear, float_values=True)
    scale = np.maximum(np.maximum(linear, 0).max(axis=2, keepdims=True), 1.0)
    reference = colour.cctf_encoding(np.maximum(linear, 0) / scale, function="sRGB")
    assert np.abs(encoded - reference).max() < 2e-5
    np.testing.assert_allclose(encoding.decode(encoded, state), linear, rtol=1e-4, atol=1e-6)
    ocio = pytest.importorskip("PyOpenColorIO")
    config = ocio.Config.CreateFromFile("ocio://default")
    for source, target in (("ACEScg", "ACEScct"), ("sRGB Encoded P3-D65", "ACEScg"),
                           ("Linear Rec.709 (sRGB)", "ACEScct")):
        cpu = config.getProcessor(source, target).getDefaultCPUProcessor()
        colours = (rng.random((50, 3)) * 0.9).astype(np.float32)
        expected = np.array([cpu.applyRGB(list(map(float, c))) for c in colours])
        got = ColorEncoding.of(source, target).encode(colours)[0]
        inside = (expected > 1e-4).all(axis=1) & (expected < 1).all(axis=1)
        assert inside.mean() > 0.5
        np.testing.assert_allclose(got[inside], expected[inside], atol=2e-5)


def test_default_and_explicit_srgb_write_the_same_bytes(tmp_path, photo, cli):
    outs = []
    for extra in ([], ["--input-space", "sRGB", "--working-space", "srgb_tx"]):
        out = tmp_path / f"o{len(outs)}.jpg"
        result = cli("apply", str(photo), "--preset", "warm", "-o", str(out),
                     *FAST, *extra)
        assert result.exit_code == 0, result.output
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


# --- the same photo in two spaces grades to the same colours -----------------------------

@pytest.mark.slow
def test_a_display_p3_photo_and_its_srgb_copy_grade_alike(tmp_path, cli):
    srgb = read_image(small_copy(SAMPLES / "chelsea.jpg", tmp_path / "c.jpg", 64)).rgb()
    srgb = 0.05 + 0.9 * srgb  # away from the faces of the cube: inside both gamuts
    p3 = cs.convert(srgb, cs.resolve_space("srgb"), cs.resolve_space("display-p3"))
    assert np.abs(p3 - srgb).max() > 0.03  # really different numbers
    a = write_array(tmp_path / "srgb.png", srgb, "uint16")
    b = write_with_icc(tmp_path / "p3.png", p3, icc_profile("Display P3"))
    for src in (a, b):
        result = cli("apply", str(src), "--preset", "warm", "--json",
                     "-o", str(src.with_name(src.stem + "_g.png")), *FAST)
        assert result.exit_code == 0, result.output
    graded_srgb = read_image(tmp_path / "srgb_g.png").rgb()
    out_p3 = read_image(tmp_path / "p3_g.png")
    assert cs.detect_input_space(out_p3)[0] == cs.resolve_space("display-p3")  # ICC kept
    back = cs.convert(out_p3.rgb(), cs.resolve_space("display-p3"), cs.resolve_space("srgb"))
    assert np.abs(graded_srgb - read_image(a).rgb()).mean() > 5 / 255  # it was graded
    assert np.abs(back - graded_srgb).max() <= 1 / 255


# --- floats: ACEScg EXR round trip --------------------------------------------------------

def _acescg_exr(path: Path) -> Path:
    rgb = read_image(small_copy(SAMPLES / "chelsea.jpg", path.with_suffix(".jpg"), 48)).rgb()
    linear = cs.convert(rgb, cs.resolve_space("srgb"), cs.resolve_space("acescg")) * 2.0
    linear[:8, :8] *= 6.0  # highlights well above 1
    return write_array(path, linear, "float",
                       {"chromaticities": (oiio.TypeDesc("float[8]"), AP1)})


@pytest.mark.slow
@pytest.mark.parametrize("working", ["acescct", "srgb"])
def test_an_acescg_exr_keeps_values_above_one(tmp_path, working, cli):
    src = _acescg_exr(tmp_path / "cg.exr")
    before = read_image(src).rgb()
    assert before.max() > 4
    out = tmp_path / f"g_{working}.exr"
    result = cli("apply", str(src), "--preset", "warm", "--working-space",
                 working, "-o", str(out), "--json", *FAST)
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["color"]["input_space"] == cs.resolve_space("acescg")
    assert report["color"]["working_space"] == cs.resolve_space(working)
    graded = read_image(out)
    assert graded.spec.getattribute("chromaticities") is not None
    after = graded.rgb()
    if working == "srgb":  # the exposure rule: highlights keep their intensity
        assert after.max() > 4 and np.mean(after > 1) > 0.5 * np.mean(before > 1)
    else:  # ACEScct holds the highlights; the grade maps them towards the palette's range
        assert after.max() > 1
    assert np.abs(after - before).mean() > 0.005  # graded
    # strength 0: the conversion there and back is the identity, values above 1 included
    same = tmp_path / f"s_{working}.exr"
    result = cli("apply", str(src), "--preset", "warm", "--working-space",
                 working, "--strength", "0", "--no-regrain", "-o", str(same),
                 *FAST)
    assert result.exit_code == 0, result.output
    np.testing.assert_allclose(read_image(same).rgb(), before, rtol=2e-4, atol=2e-5)


def test_out_of_gamut_colours_survive_an_identity_grade():
    encoding = ColorEncoding.of("display-p3", "srgb")
    p3 = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.5, 0.9]]], dtype=np.float32)
    encoded, state = encoding.encode(p3)
    assert encoded.min() >= 0 and encoded.max() <= 1 and state.residual is not None
    np.testing.assert_allclose(encoding.decode(encoded, state), p3, atol=1e-4)


# --- styles and presets carry their space --------------------------------------------------

def test_style_histograms_are_cached_per_working_space(tmp_path, style_dir):
    cache = HistogramCache(tmp_path / "cache")
    srgb = load_style_folder(style_dir, 16, cache=cache)
    cct = load_style_folder(style_dir, 16, cache=cache, working_space="acescct")
    assert srgb.working_space == cs.resolve_space("srgb")
    assert cct.working_space == cs.resolve_space("acescct")
    assert np.abs(srgb.histograms - cct.histograms).sum() > 0.5  # not the sRGB entries
    again = load_style_folder(style_dir, 16, cache=cache, working_space="ACEScct")
    # the first run uses the histograms as the cache keeps them (float32 values), so
    # every later run computes the same (a set's look, keyed by them, is found again)
    np.testing.assert_array_equal(again.histograms, cct.histograms)
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 2 * len(srgb.names)


def test_presets_record_their_working_space_and_convert(tmp_path, style_dir, cli):
    old = load_preset(THREE_STYLES)  # written before working spaces were recorded
    assert "working_space" not in old.meta and old.working_space == cs.resolve_space("srgb")
    srgb = load_style_folder(style_dir, 32)
    direct = load_style_folder(style_dir, 32, working_space="acescct")
    path = save_preset(tmp_path / "cct.npz", direct)
    saved = load_preset(path)
    assert saved.meta["working_space"] == cs.resolve_space("acescct")
    built = tmp_path / "built.npz"
    result = cli("preset", "build", str(style_dir), "-o", str(built),
                 "--working-space", "ACEScct", "--no-cache")
    assert result.exit_code == 0 and "ACEScct" in result.output, result.output
    assert load_preset(built).working_space == cs.resolve_space("acescct")
    converted = styles_in_space(srgb, "acescct")
    assert converted.working_space == cs.resolve_space("acescct")
    assert styles_in_space(srgb, "srgb") is srgb
    np.testing.assert_allclose(converted.histograms.sum(axis=(1, 2, 3)), 1.0)
    # bin centres moved through the conversion land near the photos' own ACEScct palette
    for conv, ref, orig in zip(converted.histograms, direct.histograms, srgb.histograms):
        assert np.abs(conv - ref).sum() < 0.5 * np.abs(orig - ref).sum()


# --- LUTs ---------------------------------------------------------------------------------

@pytest.mark.slow
def test_luts_name_their_spaces(tmp_path, photo, cli):
    from wbcgrade.color._colour import colour

    for working, name in (("srgb", "plain.cube"), ("acescct", "shaper.cube")):
        lut = tmp_path / name
        result = cli("apply", str(photo), "--preset", "warm", "--working-space",
                     working, "--lut", str(lut), "--lut-size", "9",
                     "-o", str(tmp_path / f"{name}.jpg"), *FAST)
        assert result.exit_code == 0, result.output
        header = [line for line in lut.read_text().splitlines() if line.startswith("#")]
        space = cs.resolve_space(working)
        assert any(line.startswith("# input space: ") and
                   cs.resolve_space(cs.linear_partner(space) if working == "acescct" else space)
                   in line for line in header)
        assert f"# output space: {space}" in header
        assert any("OpenColorIO config" in line for line in header)
        read = colour.read_LUT(str(lut))
        if working == "acescct":
            assert "LUT_1D_INPUT_RANGE" in lut.read_text()
            shaper = read[0]
            assert read[1].size == 9 and shaper.domain[1, 0] > 200  # ACEScct's 1.0 is ~222.9 linear
            probe = np.array([0.18, 1.0, 8.0])
            np.testing.assert_allclose(
                shaper.apply(np.repeat(probe[:, None], 3, axis=1))[:, 0],
                cs.convert(np.repeat(probe[:, None], 3, axis=1), "ACEScg", space)[:, 0],
                atol=1e-4)
        else:
            assert read.size == 9


@pytest.mark.slow
def test_clf_lut_or_a_clear_message(tmp_path, photo, monkeypatch, cli):
    lut = tmp_path / "g.clf"
    args = ["apply", str(photo), "--preset", "warm", "--working-space", "acescct", "--lut",
            str(lut), "--lut-format", "clf", "--lut-size", "9", "-o", str(tmp_path / "o.jpg"),
            *FAST]
    try:
        import PyOpenColorIO  # noqa: F401
    except ImportError:
        result = cli(*args)
        assert result.exit_code != 0 and "pip install" in result.output
        assert not lut.exists() and not (tmp_path / "o.jpg").exists()
        return
    result = cli(*args)
    assert result.exit_code == 0, result.output
    root = ET.parse(lut).getroot()
    text = " ".join(e.text or "" for e in root.iter() if e.tag.endswith("Description"))
    assert "input space: ACEScg" in text and "output space: ACEScct" in text
    monkeypatch.setitem(__import__("sys").modules, "PyOpenColorIO", None)
    result = cli(*args[:-len(FAST)], "--overwrite", *FAST)
    assert result.exit_code != 0 and "pip install" in result.output


def test_grade_array_in_a_working_space():
    from wbcgrade.color.grade.grading import grade_array
    from wbcgrade.color.options import GradeOptions

    rgb = np.random.default_rng(3).random((24, 32, 3)).astype(np.float32)
    styles = load_preset(resolve_preset("warm"))
    opts = GradeOptions(bins=16, fit_bins=8, max_iter=10, n_iter=30, map_size=9,
                        working_space="acescct")
    graded, grade = grade_array(rgb, styles, opts)
    assert graded.shape == rgb.shape and np.isfinite(graded).all()
    assert 0.01 < np.abs(graded - rgb).mean() < 0.3
    with pytest.raises(OptionError, match="spaces.working: unknown colour space 'nope'"):
        ColorEncoding.of(None, "nope")


def test_histograms_live_on_the_unit_cube_of_the_working_space():
    rgb = np.linspace(0, 1, 300, dtype=np.float32).reshape(10, 10, 3)
    encoded, _ = ColorEncoding.of("srgb", "acescct").encode(rgb)
    hist = image_histogram(encoded, 16)
    assert np.isclose(hist.sum(), 1.0)
    # sRGB [0, 1] sits in about [0.07, 0.55] of ACEScct's cube
    assert 0.05 < encoded.min() and encoded.max() < 0.56


@pytest.mark.slow
def test_the_report_records_the_spaces_and_shows_srgb_pictures(tmp_path, cli):
    src = _acescg_exr(tmp_path / "cg.exr")
    result = cli("report", str(src), "--preset", "warm", "--working-space",
                 "acescct", "-o", str(tmp_path / "rep"), *FAST)
    assert result.exit_code == 0, result.output
    document = json.loads((tmp_path / "rep" / "report.json").read_text())
    assert document["color"]["working_space"] == cs.resolve_space("acescct")
    assert document["color"]["ocio_version"]
    entry = document["photos"][0]
    assert entry["color"]["input_space"] == cs.resolve_space("acescg")
    assert entry["color"]["input_space_from"] == "EXR chromaticities"
    sheet = read_image(tmp_path / "rep" / entry["sheet"]).rgb()
    assert sheet.shape[0] > 100 and 0.05 < sheet.mean() < 0.95


def test_ocio_environment_variable_names_the_config(tmp_path, monkeypatch, cli):
    monkeypatch.setenv("OCIO", str(tmp_path / "missing.ocio"))
    assert cs.config_path() == str(tmp_path / "missing.ocio")
    with pytest.raises(InputError, match=r"missing.ocio \(\$OCIO\) could not be read "
                                         r"\(Requested non-existent"):
        cs.resolve_space("acescct")
    garbage = tmp_path / "garbage.ocio"  # issue 21, case 15: not "unknown colour space"
    garbage.write_text("ocio_profile_version: [\n")
    monkeypatch.setenv("OCIO", str(garbage))
    result = cli("apply", "x.jpg", "--preset", "warm", "--working-space",
                 "acescct", "-o", str(tmp_path / "o.jpg"))
    assert result.exit_code != 0 and "unknown colour space" not in result.output
    assert result.output.startswith(f"Error: OpenColorIO config {garbage} ($OCIO) could not "
                                    "be read") and "unset OCIO" in result.output
    monkeypatch.delenv("OCIO")
    assert cs.config_path() == cs.DEFAULT_CONFIG and cs.resolve_space("acescct")


# --- lightness in the working space's own terms ----------------------------------------------

def _oklab_lightness(acescg: np.ndarray) -> np.ndarray:
    """Oklab L of linear ACEScg colours (colour-science: AP1 -> XYZ, CAT02 to D65)."""
    from wbcgrade.color._colour import colour

    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    xyz = colour.RGB_to_XYZ(acescg, "ACEScg", illuminant=d65,
                            chromatic_adaptation_transform="CAT02")
    return colour.XYZ_to_Oklab(xyz)[..., 0]


@pytest.mark.slow
@pytest.mark.parametrize("working", ["acescct", "srgb"])
def test_preserve_luminance_keeps_lightness_in_any_working_space(tmp_path, working, cli):
    """An ACEScg EXR with highlights above 1: --preserve-luminance keeps each pixel's
    lightness to 1 % in ACEScct as in the default space (it once decoded ACEScct values
    as sRGB); without it the same grade moves lightness far more."""
    src = _acescg_exr(tmp_path / "cg.exr")
    before = read_image(src).rgb()
    lightness = _oklab_lightness(before)
    changes = {}
    for extra in ([], ["--preserve-luminance"]):
        out = tmp_path / f"g{len(changes)}.exr"
        result = cli("apply", str(src), "--preset", "warm",
                     "--working-space", working, "-o", str(out), *extra,
                     *FAST_ARGS)
        assert result.exit_code == 0, result.output
        after = read_image(out).rgb()
        changes[bool(extra)] = np.abs(_oklab_lightness(after) - lightness) / lightness
    # kept to 1 % (90 % of the pixels; it was 1.6 % in ACEScct, reading ACEScct as sRGB)
    assert changes[True].mean() < 0.01 and np.percentile(changes[True], 90) < 0.01
    assert changes[False].mean() > 3 * changes[True].mean()


@pytest.mark.slow
def test_monotone_maps_are_monotone_in_the_working_spaces_luma():
    """--monotone orders the map by the working encoding's own luma: sYCC's BT.601
    weights for sRGB, the AP1 primaries' luminance for ACEScct."""
    from wbcgrade.color.grade.grading import grade_array
    from wbcgrade.color.options import GradeOptions

    srgb, cct = ColorEncoding.of(), ColorEncoding.of(None, "acescct")
    np.testing.assert_allclose(srgb.luma_weights, [0.299, 0.587, 0.114])
    np.testing.assert_allclose(cct.luma_weights, [0.27, 0.67, 0.06], atol=0.01)
    rgb = read_image(SAMPLES / "chelsea.jpg").rgb()[::8, ::8]
    styles = load_preset(resolve_preset("warm"))
    _, grade = grade_array(rgb, styles, GradeOptions(mode="palette", bins=16, fit_bins=8,
                                                     max_iter=10, n_iter=30, map_size=9,
                                                     working_space="acescct"))
    luma = grade.color_map.astype(np.float64) @ cct.luma_weights
    for axis in range(3):
        assert np.diff(luma, axis=axis).min() > -1e-5


def test_a_peak_is_searched_once_then_read_back(tmp_path, monkeypatch):
    """The exposure peak of a working space (four colour conversions) is kept in the
    cache folder: a later process reads the same number without converting; a damaged
    file only costs a search."""
    monkeypatch.setenv("WBCGRADE_CACHE_DIR", str(tmp_path))
    working = cs.default_working_space()
    linear = cs.linear_partner(working)
    searched = cs._search_peak(linear, working)
    cs._peak.cache_clear()
    assert cs.peak(linear, working) == searched
    assert (tmp_path / "peaks.json").is_file()

    def no_conversion(*args):
        raise AssertionError("converted again")

    cs._peak.cache_clear()  # a new process: the number comes from the file
    monkeypatch.setattr(cs, "convert", no_conversion)
    assert cs.peak(linear, working) == searched
    (tmp_path / "peaks.json").write_text("{not json", encoding="utf-8")
    cs._peak.cache_clear()
    monkeypatch.undo()
    monkeypatch.setenv("WBCGRADE_CACHE_DIR", str(tmp_path))
    assert cs.peak(linear, working) == searched
    cs._peak.cache_clear()


def test_an_encodings_source_names_the_setting_and_a_caller_writes_its_flag():
    """A space the caller named: the library says ``spaces.input``; the command line (its
    flags through the option table) says ``--input-space``, in JSON and LUT headers too."""
    from wbcgrade.cli.option_table import flag_of
    from wbcgrade.color.mapping.lut import lut_header

    given = cs.ColorEncoding.of("sRGB", "acescct")
    assert given.source == "spaces.input" and given.as_dict()["input_space_from"] == "spaces.input"
    named = given.named(flag_of)
    assert named.as_dict()["input_space_from"] == "--input-space"
    assert any(line.endswith("(--input-space)") for line in lut_header(named))
    assert named.named(flag_of) == named and cs.ColorEncoding.of().named(flag_of).source == \
        "default"
