"""`--look`: a grade saved by `apply --json` or `apply --lut`, applied again with no fit,
gives back the same photo (within 1/255); batch and video take it too."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.color.conftest import FAST_ARGS, SAMPLES, small_copy
from tests.conftest import run_cli as run
from wbcgrade.color.io.images import read_image


def codes(path) -> np.ndarray:
    return np.round(read_image(path).pixels * 255)


@pytest.fixture
def photo(tmp_path):
    return small_copy(SAMPLES / "chelsea.jpg", tmp_path / "cat.png", width=160)


@pytest.mark.slow
@pytest.mark.parametrize("space", [None, "acescct"])
def test_look_from_json_cube_and_clf_reproduces_the_grade(tmp_path, photo, style_dir, space):
    spaces = [] if space is None else ["--working-space", space]
    result = run("apply", photo, "--style", style_dir, "-o", tmp_path / "original.png",
                 "--lut", tmp_path / "grade.cube", "--save-grade", tmp_path / "grade.json",
                 *spaces, *FAST_ARGS)
    assert result.exit_code == 0, result.output
    assert json.loads((tmp_path / "grade.json").read_text())["format"] == "wbcgrade-look"
    result = run("apply", photo, "--style", style_dir, "-o", tmp_path / "original2.png",
                 "--lut", tmp_path / "grade.clf", *spaces, *FAST_ARGS)
    assert result.exit_code == 0, result.output  # the format follows the ending: no --lut-format
    original = codes(tmp_path / "original.png")
    other = small_copy(SAMPLES / "coffee.jpg", tmp_path / "coffee.png", width=160)
    for saved in ("grade.json", "grade.cube", "grade.clf"):
        out = tmp_path / f"again_{saved}.png"
        result = run("apply", photo, "--look", tmp_path / saved, "-o", out)
        assert result.exit_code == 0, result.output
        assert "no fit" in result.output and "fit " not in result.output.split("time:")[-1]
        assert np.abs(codes(out) - original).max() <= 1, saved  # within 1/255, regrain too
        # another photo takes the same grade (nothing is refitted on it)
        result = run("apply", other, "--look", tmp_path / saved, "-o",
                     tmp_path / f"coffee_{saved}.png")
        assert result.exit_code == 0, result.output
    assert np.abs(codes(tmp_path / "coffee_grade.json.png")
                  - codes(tmp_path / "coffee_grade.cube.png")).max() <= 1


@pytest.mark.slow
def test_look_flags_and_refusals(tmp_path, photo, style_dir):
    result = run("apply", photo, "--style", style_dir, "-o", tmp_path / "original.png",
                 "--lut", tmp_path / "grade.cube", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    look = tmp_path / "grade.cube"
    plain = tmp_path / "plain.png"
    assert run("apply", photo, "--look", look, "--no-regrain", "-o", plain).exit_code == 0
    half = tmp_path / "half.png"
    assert run("apply", photo, "--look", look, "--no-regrain", "--strength", 0.5,
               "-o", half).exit_code == 0
    source = codes(photo)
    # strength 0.5 is half way between the photo and the LUT's grade
    assert np.abs(codes(half) - (source + codes(plain)) / 2).max() <= 1
    assert np.abs(codes(plain) - source).mean() > 2
    for args, word in ((["--preset", "warm"], "--preset"), (["--style", style_dir], "--style")):
        result = run("apply", photo, "--look", look, *args, "-o", tmp_path / "x.png")
        assert result.exit_code != 0 and word in result.output
    damaged = tmp_path / "damaged.json"
    damaged.write_text('{"saved_grade": {"format": "wbcgrade-look", "map": {"data": "!!"}}}')
    for bad in (damaged, tmp_path / "missing.json", tmp_path / "grade.txt"):
        (tmp_path / "grade.txt").write_text("x")
        result = run("apply", photo, "--look", bad, "-o", tmp_path / "x.png")
        lines = [line for line in result.output.splitlines() if line.strip()]
        assert result.exit_code != 0 and len(lines) == 1 and lines[0].startswith("Error: ")
    assert not (tmp_path / "x.png").exists()


@pytest.mark.slow
def test_batch_takes_a_look(tmp_path, photo, style_dir):
    result = run("apply", photo, "--style", style_dir, "-o", tmp_path / "original.png",
                 "--save-grade", tmp_path / "grade.json", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    folder = tmp_path / "in"
    folder.mkdir()
    photo.replace(folder / photo.name)
    result = run("batch", folder, "-o", tmp_path / "out", "--look", tmp_path / "grade.json")
    assert result.exit_code == 0, result.output
    assert np.abs(codes(tmp_path / "out" / photo.name)
                  - codes(tmp_path / "original.png")).max() <= 1
    result = run("batch", folder, "-o", tmp_path / "out2", "--look", tmp_path / "grade.json",
                 "--consistent")
    assert result.exit_code != 0 and "--consistent" in result.output


@pytest.mark.slow
def test_video_takes_a_look(tmp_path):
    from wbcgrade.color.mapping.lut import write_cube
    from wbcgrade.color.mapping.remap import identity_map

    darker = write_cube(tmp_path / "darker.cube", identity_map(9) * np.float32(0.5))
    out = tmp_path / "clip.mp4"
    result = run("video", SAMPLES / "clip.mp4", "--look", darker, "-o", out)
    assert result.exit_code == 0, result.output
    assert out.stat().st_size > 1000 and f"grade: the saved grade {darker}" in result.output
    assert "darker 1.000" not in result.output  # a saved LUT is not a style with a weight


def test_cube_files_read_back_as_written(tmp_path, rng):
    from wbcgrade.color.grade.saved_grade import SAMPLED_LUT_SIZE, load_look
    from wbcgrade.color.mapping.lut import write_cube

    table = rng.random((5, 5, 5, 3))
    path = write_cube(tmp_path / "r.cube", table)
    look = load_look(path)
    assert look.color_map.shape == (5, 5, 5, 3)
    assert np.abs(look.color_map - table).max() < 1e-6  # indexed [r, g, b] as written
    # another domain: read by colour-science and sampled on the [0, 1] cube
    text = path.read_text().replace("LUT_3D_SIZE 5",
                                    "LUT_3D_SIZE 5\nDOMAIN_MIN 0 0 0\nDOMAIN_MAX 2 2 2")
    (tmp_path / "wide.cube").write_text(text)
    wide = load_look(tmp_path / "wide.cube")
    assert wide.color_map.shape == (SAMPLED_LUT_SIZE,) * 3 + (3,)
    assert np.abs(wide.color_map[-1, -1, -1] - table[2, 2, 2]).max() < 1e-5  # 1.0 is mid-domain


def test_lut_readers_take_3dl_and_a_bom_and_refuse_degenerate_domains(tmp_path):
    """``.3dl`` (documented) is read; a ``.cube`` with a UTF-8 byte order mark is read; a
    reversed or enormous domain, a ``.spi1d`` ``From 0.0 0.0``, a CLF holding NaN, a saved
    map whose low is above its high: refused, each with a line naming the file."""
    import itertools
    import zlib

    from wbcgrade.color.grade.saved_grade import load_look
    from wbcgrade.errors import InputError

    n = 17
    lines = [" ".join(str(round(i * 1023 / (n - 1))) for i in range(n))]
    lines += [f"{round(r * 4095 / (n - 1))} {round(g * 4095 / (n - 1))} "
              f"{round(b * 4095 / (n - 1) / 2)}" for r, g, b in itertools.product(range(n),
                                                                               repeat=3)]
    (tmp_path / "half_blue.3dl").write_text("\n".join(lines) + "\n")
    table = load_look(tmp_path / "half_blue.3dl").color_map
    assert abs(float(table[-1, -1, -1, 2]) - 0.5) < 0.01 and float(table[-1, -1, -1, 0]) > 0.99
    rows = "\n".join(f"{r} {g} {b}" for b in (0, 1) for g in (0, 1) for r in (0, 1))
    (tmp_path / "bom.cube").write_text("\ufeffLUT_3D_SIZE 2\n" + rows + "\n")
    assert load_look(tmp_path / "bom.cube").color_map.shape == (2, 2, 2, 3)
    bad = {"reversed.cube": "LUT_3D_SIZE 2\nDOMAIN_MIN 1 1 1\nDOMAIN_MAX 0 0 0\n" + rows,
           "huge.cube": "LUT_3D_SIZE 2\nDOMAIN_MIN -1e308 -1e308 -1e308\n"
                        "DOMAIN_MAX 1e308 1e308 1e308\n" + rows,
           "flat.spi1d": "Version 1\nFrom 0.0 0.0\nLength 2\nComponents 1\n{\n0.0\n1.0\n}\n",
           "nan.clf": '<?xml version="1.0" ?>\n<ProcessList id="x" compCLFversion="3">\n'
                      '<Matrix inBitDepth="32f" outBitDepth="32f"><Array dim="3 3">\n'
                      'nan 0 0\n0 1 0\n0 0 1\n</Array></Matrix>\n</ProcessList>\n'}
    for name, text in bad.items():
        (tmp_path / name).write_text(text + "\n")
        with pytest.raises(InputError, match=name.replace(".", r"\.")):
            load_look(tmp_path / name)
    saved = {"format": "wbcgrade-look", "version": 1, "working_space": "sRGB",
             "map": {"shape": [2, 2, 2, 3], "low": 1.0, "high": 0.0,
                     "encoding": "uint16-delta2-planes-zlib-base64",
                     "data": __import__("base64").b64encode(zlib.compress(bytes(48))).decode()}}
    (tmp_path / "swapped.json").write_text(json.dumps(saved))
    with pytest.raises(InputError, match="low"):
        load_look(tmp_path / "swapped.json")


def test_a_saved_grade_with_an_unusable_regrain_eps_is_refused(tmp_path):
    """``"regrain": [0.005, 1e300]`` made an all-black photo with exit 0."""
    from wbcgrade.color.grade.grading import Grade
    from wbcgrade.color.grade.saved_grade import load_look, look_dict
    from wbcgrade.color.mapping.remap import identity_map
    from wbcgrade.errors import InputError

    entry = look_dict(Grade(("a",), np.ones(1), identity_map(3), working="sRGB",
                            regrain=(0.005, 0.04)))
    for eps in (1e300, 1e-300):
        entry["regrain"] = [0.005, eps]
        (tmp_path / "g.json").write_text(json.dumps(entry))
        with pytest.raises(InputError, match="eps <="):
            load_look(tmp_path / "g.json")


def test_json_nested_200000_deep_is_one_line_not_a_traceback(tmp_path):
    """A saved grade or a preset header of 200,000 nested brackets raised RecursionError."""
    from wbcgrade.color.grade.saved_grade import load_look
    from wbcgrade.color.presets import load_preset, shipped_presets_dir
    from wbcgrade.errors import InputError

    deep = "[" * 200_000 + "]" * 200_000
    (tmp_path / "deep.json").write_text(deep)
    with pytest.raises(InputError, match="nested too deeply"):
        load_look(tmp_path / "deep.json")
    arrays = dict(np.load(sorted(shipped_presets_dir().glob("*.npz"))[0]))
    arrays["header"] = np.frombuffer(deep.encode(), np.uint8)
    np.savez(tmp_path / "deep.npz", **arrays)
    with pytest.raises(InputError, match="header is not JSON"):
        load_preset(tmp_path / "deep.npz")
