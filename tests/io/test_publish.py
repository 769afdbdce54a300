"""wbcgrade._publish: atomic publication from many threads, clean failures, one PNG writer."""

from __future__ import annotations

import os
import threading

import numpy as np
import OpenImageIO as oiio
import pytest

from wbcgrade._publish import TEMP_MARK, atomic_path, publish_bytes, write_png
from wbcgrade.brdf import io as brdf_io
from wbcgrade.brdf import merl
from wbcgrade.errors import InputError
from wbcgrade.shape.volume import write_volume


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _in_threads(function, n=8):
    errors = []
    barrier = threading.Barrier(n)

    def run(i):
        barrier.wait()
        try:
            function(i)
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors


def test_threads_writing_one_target_never_collide_or_leak(tmp_path):
    target = tmp_path / "out.bin"
    payloads = [bytes([i]) * 200_000 for i in range(8)]
    _in_threads(lambda i: publish_bytes(target, payloads[i]))
    assert target.read_bytes() in payloads  # one whole payload, never a mix
    assert _leftovers(tmp_path) == []


@pytest.mark.slow
def test_domain_writers_from_threads(tmp_path):
    directions = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    values = np.ones((2, 2, 3))
    table = np.ones((3, *merl.MERL_SHAPE))

    def write(i):
        brdf_io.write_sampled(tmp_path / "a.npz", values * (i + 1), directions)
        merl.write_merl(tmp_path / "a.binary", table)
        write_volume(tmp_path / "v.npy", np.full((2, 2, 2), float(i)))
        write_png(tmp_path / "a.png", np.full((4, 5, 3), i * 10, dtype=np.uint8))

    _in_threads(write, n=4)
    assert _leftovers(tmp_path) == []
    assert brdf_io.read_sampled(tmp_path / "a.npz")[0].shape == (2, 2, 3)


def test_failure_removes_the_temporary_and_keeps_the_target(tmp_path):
    target = tmp_path / "keep.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="writer failed"), atomic_path(target) as tmp:
        assert os.path.basename(tmp).startswith(f".keep{TEMP_MARK}")
        with open(tmp, "w") as handle:
            handle.write("half")
        raise RuntimeError("writer failed")
    assert target.read_text() == "old" and _leftovers(tmp_path) == []


def test_no_overwrite_and_unsafe_targets(tmp_path):
    target = tmp_path / "x.bin"
    publish_bytes(target, b"one", overwrite=False)
    with pytest.raises(InputError, match="file exists"):
        publish_bytes(target, b"two", overwrite=False)
    assert target.read_bytes() == b"one"
    os.mkfifo(tmp_path / "pipe.png")
    with pytest.raises(InputError, match="not a regular file"):
        write_png(tmp_path / "pipe.png", np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(InputError, match="output folder does not exist"):
        publish_bytes(tmp_path / "absent" / "x.bin", b"")
    assert _leftovers(tmp_path) == []


def test_png_writer_takes_uint8_and_unit_floats(tmp_path):
    write_png(tmp_path / "u.png", np.arange(24, dtype=np.uint8).reshape(2, 4, 3))
    write_png(tmp_path / "f.png", np.array([[0.0, 0.5, 2.0]]))  # grey, clipped
    grey = oiio.ImageBuf(str(tmp_path / "f.png"))
    assert grey.spec().nchannels == 1
    assert np.array_equal(grey.get_pixels(oiio.UINT8).ravel(), [0, 128, 255])
    back = oiio.ImageBuf(str(tmp_path / "u.png")).get_pixels(oiio.UINT8)
    assert np.array_equal(back, np.arange(24, dtype=np.uint8).reshape(2, 4, 3))
    with pytest.raises(InputError, match="NaN"):
        write_png(tmp_path / "n.png", np.full((2, 2, 3), np.nan))
    with pytest.raises(InputError, match="PNG needs"):
        write_png(tmp_path / "n.png", np.zeros((2, 2, 2)))
