"""The third hostile round (issue 31): sizes a file or an option sets are bounded before any
work, inputs are never replaced, malformed files are one line naming the file and what is
wrong, caches heal.

- 1: ``--regrain-radius 1e9`` (or ``"regrain": [1e9, 1e9]`` in a grade JSON) ran for hours
  in compiled code, deaf to Ctrl-C;
- 2: ``-o`` naming a style photo, or ``--lut`` naming the ``--look`` file, replaced it
  with ``--overwrite``;
- 4: small files declaring gigabytes (a preset of 60 styles of 256^3 bins, a compressed
  400^3 map, a ``.spi3d`` of 500^3, a ``.npy`` header of terabytes), ``--iterations 1e9``;
- 5: a ``.cube`` of ``LUT_3D_SIZE`` 0 or 1 gave a garbage photo (a read past the table);
- 6: tracebacks: wrong-typed grade JSON fields, a bare ``LUT_3D_SIZE``, a preset whose
  ``offsets`` is a structured array, a damaged or empty cache entry;
- 7: a style folder holding a name that is not UTF-8 failed with the cache on;
- 9: messages that named neither the file nor the fault.
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path

import numpy as np
import pytest

from tests.color.conftest import FAST_ARGS, SAMPLES, small_copy
from tests.conftest import run_cli as run
from wbcgrade.color.grade.saved_grade import load_look
from wbcgrade.color.mapping.remap import apply_color_map
from wbcgrade.color.options import FitOptions, RegrainOptions
from wbcgrade.color.presets import load_preset
from wbcgrade.errors import InputError, OptionError

REPO = Path(__file__).resolve().parents[2]



def refused(result, *words) -> str:
    """The one-line error of a refused run; it names every word in ``words``."""
    assert result.exit_code != 0, result.output
    assert not isinstance(result.exception, Exception) or isinstance(result.exception,
                                                                      SystemExit), \
        repr(result.exception)
    lines = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert len(lines) == 1, result.output
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


def in_small_memory(code: str, limit_gb: float = 2.0) -> subprocess.CompletedProcess:
    """``code`` in a Python of its own whose address space is held under ``limit_gb``."""
    prelude = textwrap.dedent(f"""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, ({int(limit_gb * 2 ** 30)},) * 2)
    """)
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], cwd=REPO,
                          capture_output=True, text=True, timeout=120)


@pytest.fixture
def photo(tmp_path):
    return small_copy(SAMPLES / "chelsea.jpg", tmp_path / "cat.png", width=48)


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> dict:
    """The saved grade of a small photo (``apply --save-grade``)."""
    folder = tmp_path_factory.mktemp("saved")
    photo = small_copy(SAMPLES / "chelsea.jpg", folder / "cat.png", width=48)
    result = run("apply", photo, "--preset", "warm", "-o", folder / "out.png",
                 "--save-grade", folder / "grade.json", *FAST_ARGS)
    assert result.exit_code == 0, result.output
    return json.loads((folder / "grade.json").read_text())


def _write_look(path: Path, entry: dict) -> Path:
    path.write_text(json.dumps(entry))
    return path


# ------------------------------------------------------------------ 1: the regrain hang


@pytest.mark.slow
def test_a_huge_regrain_radius_is_refused_and_the_library_bounds_its_window(tmp_path, saved):
    with pytest.raises(OptionError, match="at most 1"):
        RegrainOptions(radius=1e9)
    entry = dict(saved, regrain=[1e9, 1e9])
    with pytest.raises(InputError, match="regrain"):
        load_look(_write_look(tmp_path / "huge.json", entry))
    # the library itself: a window wider than the photo is the whole photo, done at once
    # (it ran for hours in compiled code); in a process of its own, so that the old code's
    # hang fails the test instead of holding the suite
    code = """
        import numpy as np
        from wbcgrade.color.mapping.regrain import regrain
        rng = np.random.default_rng(0)
        src = rng.random((40, 60, 3)).astype(np.float32)
        graded = np.clip(src * 0.8 + 0.1, 0, 1).astype(np.float32)
        whole = regrain(src, graded, radius=1.0)
        huge = regrain(src, graded, radius=1e9)
        print(float(np.abs(huge - whole).max()))
    """
    try:
        done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=REPO,
                              capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("regrain(radius=1e9) did not end within 60 s")
    assert done.returncode == 0, done.stderr
    assert float(done.stdout) == 0.0


@pytest.mark.slow
def test_the_regrain_radius_option_is_a_one_line_usage_error(tmp_path, photo):
    command = ["apply", photo, "--preset", "warm", "--regrain-radius", "1e9",
               "-o", tmp_path / "out.png", *FAST_ARGS]
    try:  # a process of its own: the old code's hang fails the test, not the suite
        done = subprocess.run([sys.executable, "-c", "from wbcgrade.cli import main; main()",
                               *map(str, command)], cwd=REPO, capture_output=True, text=True,
                              timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("apply --regrain-radius 1e9 did not end within 120 s")
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines() == [
        "Error: --regrain-radius must be at most 1 (a fraction of the photo's long side)"]
    assert not (tmp_path / "out.png").exists()


# ------------------------------------------------------------------ 2: inputs replaced


def test_an_output_naming_a_style_photo_is_refused_even_with_overwrite(tmp_path, photo):
    styles = tmp_path / "styles"
    styles.mkdir()
    for name in ("coffee", "flower"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", 40)
    before = (styles / "coffee.jpg").read_bytes()
    refused(run("apply", photo, "--style", styles, "-o", styles / "coffee.jpg", "--overwrite",
                *FAST_ARGS), "coffee.jpg", "input")
    assert (styles / "coffee.jpg").read_bytes() == before
    refused(run("apply", photo, "--style", styles, "-o", tmp_path / "out.png",
                "--lut", styles / "flower.jpg", "--overwrite", *FAST_ARGS))
    assert not (tmp_path / "out.png").exists()


@pytest.mark.slow
def test_the_look_file_is_never_replaced_by_lut(tmp_path, photo):
    look = tmp_path / "mylook.cube"
    run("apply", photo, "--preset", "warm", "-o", tmp_path / "a.png", "--lut", look,
        "--lut-size", "5", *FAST_ARGS)
    before = look.read_bytes()
    refused(run("apply", photo, "--look", look, "--lut", look, "--overwrite",
                "-o", tmp_path / "b.png"), "mylook.cube", "input")
    assert look.read_bytes() == before and not (tmp_path / "b.png").exists()
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"not looked at: the outputs are checked first")
    refused(run("video", clip, "--look", look, "--lut", look, "--overwrite",
                "-o", tmp_path / "out.mp4"), "mylook.cube", "input")
    assert look.read_bytes() == before


def test_an_output_leading_to_the_preset_is_refused(tmp_path, photo):
    """An output can only name a preset (.npz) through a link: it is resolved first."""
    preset = tmp_path / "mine.npz"
    preset.write_bytes((REPO / "tests" / "data" / "three_samples.npz").read_bytes())
    before = preset.read_bytes()
    (tmp_path / "out.png").symlink_to(preset)
    refused(run("apply", photo, "--preset", preset, "-o", tmp_path / "out.png", "--overwrite",
                *FAST_ARGS), "out.png", "input")
    assert preset.read_bytes() == before


# ------------------------------------------------------------------ 4: memory bombs


def _npz_member(name: str, header: dict, data: bytes = b"") -> tuple[str, bytes]:
    """A raw ``.npy`` member: any header, any data (the header may lie)."""
    text = repr(header).encode("latin1")
    pad = 64 - (10 + len(text) + 1) % 64
    body = b"\x93NUMPY\x01\x00" + (len(text) + pad + 1).to_bytes(2, "little") + text \
        + b" " * pad + b"\n"
    return name + ".npy", body + data


def _preset(path: Path, header: dict, arrays: dict[str, np.ndarray],
            raw: list[tuple[str, bytes]] = ()) -> Path:
    import io
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        members = {"header": np.frombuffer(json.dumps(header).encode(), np.uint8), **arrays}
        for name, array in members.items():
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, np.asarray(array), allow_pickle=False)
            archive.writestr(name + ".npy", buffer.getvalue())
        for name, data in raw:
            archive.writestr(name, data)
    return path


HEADER = {"format": "wbcgrade-preset", "version": 1, "bins": 8, "names": ["a", "b"]}
GOOD = {"index": np.array([0, 1, 2], np.int32), "values": np.ones(3, np.float32),
        "offsets": np.array([0, 1, 3], np.int64)}


def test_a_good_hand_made_preset_loads(tmp_path):
    """The writer below makes valid presets: the refusals that follow are the bombs'."""
    styles = load_preset(_preset(tmp_path / "ok.npz", HEADER, GOOD))
    assert styles.names == ["a", "b"] and styles.histograms.shape == (2, 8, 8, 8)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["styles", "tib_header", "compressed_look", "structured"])
def test_preset_bombs_are_one_line_under_2_gb(tmp_path, case):
    path = tmp_path / f"{case}.npz"
    if case == "styles":  # 60 styles of 256^3 bins: 8 GB of histograms from 3 kB
        names = [f"s{i}" for i in range(60)]
        _preset(path, dict(HEADER, bins=256, names=names),
                {"index": np.arange(60, dtype=np.int32), "values": np.ones(60, np.float32),
                 "offsets": np.arange(61, dtype=np.int64)})
    elif case == "tib_header":  # a member whose header claims 7.28 TiB
        arrays = {k: v for k, v in GOOD.items() if k != "values"}
        _preset(path, HEADER, arrays,
                [_npz_member("values", {"descr": "<f4", "fortran_order": False,
                                        "shape": (2 ** 41,)})])
    elif case == "compressed_look":  # 370 MB of float16 zeros in a few hundred kB
        n = 400
        look = np.lib.format.header_data_from_array_1_0(np.zeros((1, 1, 1, 3), np.float16))
        look["shape"] = (n, n, n, 3)
        _preset(path, HEADER, GOOD, [_npz_member("look", look, bytes(2 * 3 * n ** 3))])
    else:  # offsets as a structured array: a traceback before
        _preset(path, HEADER, dict(GOOD, offsets=np.zeros(3, dtype=[("a", "<i8"),
                                                                    ("b", "<f8")])))
    assert path.stat().st_size < 2 * 2 ** 20
    code = f"""
        from wbcgrade.color.presets import load_preset
        from wbcgrade.errors import InputError
        try:
            load_preset({str(path)!r})
        except InputError as exc:
            print(exc)
    """
    done = in_small_memory(code)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith(str(path)) and "not a valid wbcgrade preset" in done.stdout
    assert len(done.stdout.strip().splitlines()) == 1


@pytest.mark.slow
def test_a_compressed_huge_map_in_a_grade_json_is_refused_before_it_is_inflated(tmp_path,
                                                                                saved):
    import base64

    n = 400  # 6 GB once decoded, 500 kB as written
    entry = copy.deepcopy(saved)
    entry["map"].update(shape=[n, n, n, 3], data=base64.b64encode(
        zlib.compress(bytes(2 * 3 * n ** 3), 9)).decode())
    path = _write_look(tmp_path / "bomb.json", entry)
    assert path.stat().st_size < 2 * 2 ** 20
    done = in_small_memory(f"""
        from wbcgrade.color.grade.saved_grade import load_look
        from wbcgrade.errors import InputError
        try:
            load_look({str(path)!r})
        except InputError as exc:
            print(exc)
    """)
    assert done.returncode == 0, done.stderr[-2000:]
    assert str(path) in done.stdout and "400^3" in done.stdout


@pytest.mark.slow
def test_a_spi3d_declaring_500_cubed_is_refused_before_its_table_is_made(tmp_path):
    path = tmp_path / "big.spi3d"
    path.write_text("SPILUT 1.0\n3 3\n500 500 500\n0 0 0 0.5 0.5 0.5\n")
    done = in_small_memory(f"""
        from wbcgrade.color.grade.saved_grade import load_look
        from wbcgrade.errors import InputError
        try:
            load_look({str(path)!r})
        except InputError as exc:
            print(exc)
    """)
    assert done.returncode == 0, done.stderr[-2000:]
    assert str(path) in done.stdout and "500" in done.stdout


def test_barycenter_iterations_are_bounded():
    with pytest.raises(OptionError, match="fit.n_iter"):
        FitOptions(n_iter=1_000_000_000)
    assert FitOptions(n_iter=1000).n_iter == 1000


# ------------------------------------------------------------------ 5, 9: .cube headers


@pytest.mark.parametrize("text, words", [
    ("LUT_3D_SIZE 0\n", ["size of 0", "between 2 and 129"]),
    ("LUT_3D_SIZE 1\n0.1 0.2 0.9\n", ["size of 1"]),
    ("LUT_3D_SIZE\n0 0 0\n", ["line 1", "LUT_3D_SIZE", "whole number"]),
    ("LUT_3D_SIZE abc\n" + "0 0 0\n" * 8, ["line 1", "'abc'"]),
    ("LUT_3D_SIZE 2\nDOMAIN_MIN a b c\n" + "0 0 0\n" * 8, ["line 2", "DOMAIN_MIN", "'a b c'"]),
    ("", ["no LUT_3D_SIZE"]),
    ("LUT_3D_SIZE 2\n" + "0.000 0.000 0.000\n" * 5, ["8 rows", "has 5"]),
    ("LUT_3D_SIZE 100\n0 0 0\n", ["cannot hold"]),
])
def test_a_malformed_cube_is_one_line_naming_the_file_and_the_fault(tmp_path, photo, text,
                                                                     words):
    path = tmp_path / "bad.cube"
    path.write_text(text)
    with pytest.raises(InputError, match="bad.cube") as caught:
        load_look(path)
    message = str(caught.value)
    assert message.startswith(str(path)) and all(w in message for w in words), message
    refused(run("apply", photo, "--look", path, "-o", tmp_path / "out.png"), "bad.cube")
    assert not (tmp_path / "out.png").exists()


def test_the_remap_refuses_a_map_of_one_node():
    """A (1, 1, 1, 3) map made the interpolation read past the table: garbage, exit 0."""
    with pytest.raises(ValueError, match="n >= 2"):
        apply_color_map(np.full((4, 4, 3), 0.5, np.float32), np.zeros((1, 1, 1, 3)))


# ------------------------------------------------------------------ 6, 9: grade JSON fields


@pytest.mark.slow
@pytest.mark.parametrize("field, value, words", [
    ("version", None, ['"version"', "null"]),
    ("version", "x", ['"version"', '"x"']),
    ("names", 5, ['"names"']),
    ("weights", {"a": 1}, ['"weights"']),
    ("loss", [1], ["loss"]),
    ("regrain", {"a": 1}, ["regrain"]),
    ("strength", "strong", ["strength"]),
    ("working_space", 3, ["working space"]),
])
def test_a_wrong_typed_grade_json_field_is_one_line(tmp_path, saved, photo, field, value,
                                                    words):
    path = _write_look(tmp_path / "grade.json", dict(saved, **{field: value}))
    with pytest.raises(InputError, match="grade.json") as caught:
        load_look(path)
    assert str(caught.value).startswith(str(path))
    assert all(w in str(caught.value) for w in words), caught.value
    refused(run("apply", photo, "--look", path, "-o", tmp_path / "out.png"), "grade.json")


def test_a_saved_grade_still_reads_back(tmp_path, saved):
    grade = load_look(_write_look(tmp_path / "grade.json", saved))
    assert grade.color_map.shape[3] == 3 and grade.regrain == tuple(saved["regrain"])


# ------------------------------------------------------------------ 6, 7: caches


@pytest.fixture
def styles(tmp_path) -> Path:
    folder = tmp_path / "styles"
    folder.mkdir()
    for name in ("coffee", "flower", "sunset"):
        small_copy(SAMPLES / f"{name}.jpg", folder / f"{name}.jpg", 40)
    return folder


@pytest.mark.slow
@pytest.mark.parametrize("damage", [b"garbage", b"", b"PK\x03\x04 cut short"])
def test_a_damaged_cache_entry_is_rebuilt_not_a_failure(tmp_path, photo, styles, damage, cli):
    cache = tmp_path / "cache"
    args = ["--mode", "palette", "--bins", "16", "--fit-bins", "8", "--max-iter", "10",
            "--iterations", "30"]
    env = {"WBCGRADE_CACHE_DIR": str(cache)}
    first = cli("apply", str(photo), "--style", str(styles),
                "-o", str(tmp_path / "a.png"), *args, env=env)
    assert first.exit_code == 0, first.output
    entries = sorted(cache.rglob("*.npz"))
    assert len(entries) >= 3
    good = {path: path.read_bytes() for path in entries}
    for path in entries:
        path.write_bytes(damage)
    again = cli("apply", str(photo), "--style", str(styles),
                "-o", str(tmp_path / "b.png"), *args, env=env)
    assert again.exit_code == 0, again.output
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    for path in entries:  # healed: each entry rewritten as a good one
        assert path.read_bytes()[:2] == b"PK" and len(path.read_bytes()) > 100
        assert np.load(path).files == np.load(__import__("io").BytesIO(good[path])).files


@pytest.mark.slow
def test_a_style_folder_with_a_name_that_is_not_utf8_works_with_the_cache(tmp_path, photo,
                                                                           styles):
    name = os.fsdecode(b"caf\xe9.jpg")
    os.rename(styles / "sunset.jpg", styles / name)
    cache = tmp_path / "cache"
    script = ("import sys; from wbcgrade.cli import main; main()")
    env = dict(os.environ, WBCGRADE_CACHE_DIR=str(cache))
    for command in (["apply", photo, "--style", styles, "-o", tmp_path / "out.png",
                     "--mode", "palette", "--fit-bins", "8", "--max-iter", "5"],
                    ["preset", "build", styles, "-o", tmp_path / "p.npz", "--bins", "16"]):
        done = subprocess.run([sys.executable, "-c", script, *map(str, command)], cwd=REPO,
                              capture_output=True, env=env, timeout=300)
        assert done.returncode == 0, done.stderr.decode("utf-8", "replace")
        assert b"Traceback" not in done.stderr
    assert (tmp_path / "out.png").is_file() and (tmp_path / "p.npz").is_file()
    # two bin counts, every photo cached; and each histogram of the grade on its fit grid
    assert len(list(cache.glob("*.npz"))) == 3 * 2 + 3
