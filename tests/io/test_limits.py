"""wbcgrade.limits (issue 31, family 4): an array file's header is checked before anything is
allocated; a ``.npy`` claiming 7.28 TiB, a structured or object dtype, a member larger than the
bound are one InputError naming the file, read under a 2 GB address space."""

from __future__ import annotations

import io
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from wbcgrade.errors import InputError
from wbcgrade.limits import read_npy, read_npz

REPO = Path(__file__).resolve().parents[2]


def _npy(header: dict, data: bytes = b"") -> bytes:
    text = repr(header).encode("latin1")
    pad = 64 - (10 + len(text) + 1) % 64
    return (b"\x93NUMPY\x01\x00" + (len(text) + pad + 1).to_bytes(2, "little") + text
            + b" " * pad + b"\n" + data)


TIB = {"descr": "<f8", "fortran_order": False, "shape": (1_000_000, 1_000_000)}  # 7.28 TiB


def test_plain_arrays_read_back(tmp_path):
    values = np.arange(24, dtype=np.float32).reshape(2, 3, 4)
    np.save(tmp_path / "a.npy", values)
    assert np.array_equal(read_npy(tmp_path / "a.npy"), values)
    np.save(tmp_path / "f.npy", np.asfortranarray(values))
    assert np.array_equal(read_npy(tmp_path / "f.npy"), values)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, a=values, s=np.array("text"))
    arrays = read_npz(buffer.getvalue(), "x.npz")
    assert np.array_equal(arrays["a"], values) and str(arrays["s"]) == "text"


@pytest.mark.parametrize("header, words", [
    (TIB, "more than"),
    ({"descr": [("a", "<i8"), ("b", "<f8")], "fortran_order": False, "shape": (3,)},
     "not plain numbers"),
    ({"descr": "|O", "fortran_order": False, "shape": (3,)}, "pickled Python objects"),
])
def test_a_lying_or_foreign_npy_header_is_refused_before_allocation(tmp_path, header, words):
    path = tmp_path / "bomb.npy"
    path.write_bytes(_npy(header, bytes(64)))
    with pytest.raises(InputError, match=words) as caught:
        read_npy(path)
    assert str(caught.value).startswith(str(path))
    archive = tmp_path / "bomb.npz"
    with zipfile.ZipFile(archive, "w") as out:
        out.writestr("values.npy", _npy(header, bytes(64)))
    with pytest.raises(InputError, match=words):
        read_npz(archive)


def test_a_volume_npy_claiming_terabytes_is_one_line_under_2_gb(tmp_path):
    path = tmp_path / "volume.npy"
    path.write_bytes(_npy({"descr": "<f8", "fortran_order": False,
                           "shape": (10_000, 10_000, 10_000)}, bytes(4096)))
    code = f"""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, ({2 << 30},) * 2)
        from wbcgrade.errors import InputError
        from wbcgrade.shape.volume import read_volume
        try:
            read_volume({str(path)!r})
        except InputError as exc:
            print(exc)
    """
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith(str(path)) and "more than" in done.stdout


@pytest.mark.slow  # over 5 s of the fast tier: the whole suite runs it
def test_one_memory_budget_for_archives_pixels_luts_and_style_sets(tmp_path, monkeypatch):
    """Archives in total (members of 255 MB each) and unknown preset members, a small PNG
    declaring a huge image, a second size line of a ``.spi3d``, a style set past the
    budget: refused before anything is allocated."""
    import OpenImageIO as oiio

    from wbcgrade import limits
    from wbcgrade.color.grade.saved_grade import load_look
    from wbcgrade.color.io.images import read_image
    from wbcgrade.color.presets import load_preset, load_style_folder, shipped_presets_dir

    bomb = io.BytesIO()
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in "abc":
            with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                member.write(_npy({"descr": "|u1", "fortran_order": False,
                                   "shape": (255 * 2 ** 20,)}))
                for _ in range(255):
                    member.write(bytes(2 ** 20))
    with pytest.raises(InputError, match="from one archive"):
        read_npz(bomb.getvalue(), "bomb.npz")
    preset = sorted(shipped_presets_dir().glob("*.npz"))[0]
    extra = tmp_path / "extra.npz"
    extra.write_bytes(preset.read_bytes())
    with zipfile.ZipFile(extra, "a") as archive:
        archive.writestr("junk.npy", _npy({"descr": "|u1", "fortran_order": False,
                                           "shape": (4,)}, bytes(4)))
    with pytest.raises(InputError, match="unknown member 'junk'"):
        load_preset(extra)
    oiio.ImageBuf(np.zeros((4100, 5000, 1), np.uint8)).write(str(tmp_path / "flat.png"))
    with pytest.raises(InputError, match="budget"):
        read_image(tmp_path / "flat.png")
    (tmp_path / "two.spi3d").write_text("SPILUT 1.0\n3 3\n2 2 2\n" + "0 0 0 0 0 0\n" * 8
                                        + "400 400 400\n")
    with pytest.raises(InputError, match="400"):
        load_look(tmp_path / "two.spi3d")
    styles = tmp_path / "styles"
    styles.mkdir()
    for number in range(3):
        oiio.ImageBuf(np.full((4, 4, 3), 40 * number, np.uint8)).write(
            str(styles / f"s{number}.png"))
    monkeypatch.setattr(limits, "MEMORY_BUDGET", 2 * 64 ** 3 * 8 * 2)
    with pytest.raises(InputError, match="3 style photos"):
        load_style_folder(styles, 64)
