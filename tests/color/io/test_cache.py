"""The colour domain's disk cache (wbcgrade.color.io.cache): any file name, a damaged entry
rebuilt, concurrent writers, and a folder that cannot be written."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wbcgrade.color.histogram import HistogramCache, soft_histogram
from wbcgrade.color.io import cache
from wbcgrade.color.options import DEFAULT_MAX_PIXELS

REPO = Path(__file__).resolve().parents[3]

ODD_NAMES = ["a photo with spaces.jpg", "\u00e9t\u00e9 \u5199\u771f \U0001f4f7.jpg",
             os.fsdecode(b"caf\xe9.jpg"), "x" * 251 + ".jpg", "-rf --no-cache.jpg"]


@pytest.mark.parametrize("name", ODD_NAMES)
def test_an_entry_is_kept_for_any_file_name(tmp_path, name):
    photo = tmp_path / name
    photo.write_bytes(b"pixels")
    store = HistogramCache(tmp_path / "cache")
    hist = soft_histogram(np.random.default_rng(0).random((50, 3)), 5)
    stored = store.put(photo, 5, hist)
    assert np.array_equal(store.get(photo, 5), stored)
    entries = list((tmp_path / "cache").iterdir())
    assert [len(p.name) for p in entries] == [36]  # a digest, whatever the photo's name
    other = tmp_path / ("_" + name[1:])  # a name one letter away is another entry
    other.write_bytes(b"pixels")
    assert store.get(other, 5) is None


@pytest.mark.parametrize("damage", [b"", b"garbage", b"PK\x03\x04 cut short", None])
def test_a_damaged_entry_is_a_miss_removed_then_rebuilt(tmp_path, damage):
    photo = tmp_path / "p.jpg"
    photo.write_bytes(b"pixels")
    store = HistogramCache(tmp_path / "cache")
    hist = soft_histogram(np.random.default_rng(1).random((50, 3)), 5)
    stored = store.put(photo, 5, hist)
    (entry,) = (tmp_path / "cache").iterdir()
    good = entry.read_bytes()
    entry.write_bytes(good[: len(good) // 2] if damage is None else damage)
    assert store.get(photo, 5) is None
    assert not entry.exists()  # removed: the next run does not read it again
    store.put(photo, 5, hist)
    assert np.array_equal(store.get(photo, 5), stored)


def test_an_entry_of_the_wrong_arrays_is_a_miss(tmp_path):
    photo = tmp_path / "p.jpg"
    photo.write_bytes(b"pixels")
    store = HistogramCache(tmp_path / "cache")
    cache.write_entry(store._key(photo, 5, DEFAULT_MAX_PIXELS), other=np.zeros(3))
    assert store.get(photo, 5) is None


@pytest.mark.parametrize("damage", ["nan", "negated", "swapped"])
def test_a_valid_archive_that_lies_is_a_miss_removed_then_rebuilt(tmp_path, damage):
    """Entries that are valid archives but not what their key says (NaN values, values
    changed and saved again, another photo's entry moved under this key): a miss, removed,
    and the value rebuilt, so one bad entry never poisons the runs after it."""
    photos = [tmp_path / "p.jpg", tmp_path / "q.jpg"]
    store = HistogramCache(tmp_path / "cache")
    stored = []
    for seed, photo in enumerate(photos):
        photo.write_bytes(b"pixels%d" % seed)
        hist = soft_histogram(np.random.default_rng(seed).random((50, 3)), 5)
        stored.append(store.put(photo, 5, hist))
    entry, other = (store._key(p, 5, DEFAULT_MAX_PIXELS) for p in photos)
    arrays = dict(np.load(entry))
    if damage == "swapped":
        entry.write_bytes(other.read_bytes())
    else:
        arrays["values"] = (np.full_like(arrays["values"], np.nan) if damage == "nan"
                            else -arrays["values"])
        with open(entry, "wb") as handle:
            np.savez(handle, **arrays)
    assert store.get(photos[0], 5) is None
    assert not entry.exists()
    store.put(photos[0], 5, soft_histogram(np.random.default_rng(0).random((50, 3)), 5))
    assert np.array_equal(store.get(photos[0], 5), stored[0])
    assert np.array_equal(store.get(photos[1], 5), stored[1])


def test_nan_its_writer_stored_is_read_back_but_nan_edited_in_is_a_miss(tmp_path):
    """Statistics with NaN by design (an empty lightness band) are a hit, not rebuilt on
    every run; NaN put into an entry afterwards, or inf anywhere, is still a miss."""
    path = tmp_path / "looks" / cache.entry_name("natural statistics")
    band_mean = np.array([[0.2, np.nan], [0.5, 0.7]])
    assert cache.write_entry(path, band_mean=band_mean, count=np.int64(3))
    read = cache.read_entry(path)
    assert read is not None and set(read) == {"band_mean", "count"}
    assert np.array_equal(read["band_mean"], band_mean, equal_nan=True)

    clean = tmp_path / "looks" / cache.entry_name("clean")
    assert cache.write_entry(clean, values=np.ones(3))
    arrays = dict(np.load(clean))
    arrays["values"] = np.array([1.0, np.nan, 1.0])
    arrays[cache.DIGEST_MEMBER] = np.frombuffer(
        cache._digest(clean.name, {"values": arrays["values"]}), np.uint8)
    with open(clean, "wb") as handle:  # NaN with a matching digest, but not the writer's
        np.savez(handle, **arrays)
    assert cache.read_entry(clean) is None and not clean.exists()
    infinite = tmp_path / "looks" / cache.entry_name("inf")
    assert cache.write_entry(infinite, values=np.array([np.nan, np.inf]))
    assert cache.read_entry(infinite) is None


def _write_many(args: tuple[str, int]) -> int:
    path, seed = args
    bad = 0
    for i in range(40):
        values = np.full(2000, seed * 1000 + i, dtype=np.int64)
        assert cache.write_entry(Path(path), values=values, seed=np.int64(seed))
        read = cache.read_entry(Path(path))  # another writer may have replaced it: whole
        if read is None or read["values"].shape != (2000,) \
                or not (read["values"] == read["values"][0]).all():
            bad += 1
    return bad


def test_concurrent_writers_leave_a_whole_entry(tmp_path):
    path = tmp_path / "cache" / "looks" / cache.entry_name("one key")
    with multiprocessing.get_context("spawn").Pool(4) as pool:
        bad = pool.map(_write_many, [(str(path), seed) for seed in range(4)])
    assert bad == [0, 0, 0, 0]  # no reader saw half an entry (nor lost one)
    final = cache.read_entry(path)
    assert final is not None and int(final["values"][0]) // 1000 == int(final["seed"])
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporaries left


def test_an_unwritable_folder_warns_once_and_the_value_is_still_returned(tmp_path, caplog,
                                                                          monkeypatch):
    monkeypatch.setattr(cache, "_WARNED", [])
    blocker = tmp_path / "a file"
    blocker.write_bytes(b"")
    store = HistogramCache(blocker / "cache")  # a folder inside a file: never writable
    photos = [tmp_path / f"{i}.jpg" for i in range(3)]
    hist = soft_histogram(np.random.default_rng(2).random((50, 3)), 5)
    for photo in photos:
        photo.write_bytes(b"pixels")
        assert store.put(photo, 5, hist).shape == (5, 5, 5)
        assert store.get(photo, 5) is None
    assert not cache.write_entry(cache.entry_path(blocker, "looks", "k"), a=np.zeros(2))
    warnings = [r for r in caplog.records if "not written" in r.getMessage()]
    assert len(warnings) == 1


@pytest.mark.slow
def test_the_default_grade_works_when_the_cache_folder_cannot_be_written(tmp_path, style_dir,
                                                                        photo):
    """The style path (histograms, the set's look, scene images: all three kinds)."""
    styles = style_dir
    blocker = tmp_path / "not a folder"
    blocker.write_bytes(b"")
    outputs = []
    for cache_dir in (blocker / "cache", tmp_path / "cache"):
        out = tmp_path / f"out{len(outputs)}.png"
        run = subprocess.run([sys.executable, "-m", "wbcgrade", "apply", str(photo),
                              "--style", str(styles), "-o", str(out)], cwd=REPO,
                             env=dict(os.environ, WBCGRADE_CACHE_DIR=str(cache_dir)),
                             capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        assert "Traceback" not in run.stderr
        outputs.append((out.read_bytes(), run.stderr))
    (unwritable, said), (cached, _) = outputs
    assert unwritable == cached  # the same picture with or without a cache
    assert len([ln for ln in said.splitlines() if "not written" in ln]) == 1, said
    kinds = {p.parent.name for p in (tmp_path / "cache").rglob("*.npz")}
    assert kinds == {"cache", "looks", "scenes"}  # all three kinds were written there


@pytest.mark.slow  # over 5 s of the fast tier: the whole suite runs it
def test_natural_folder_follows_no_cache_and_cache_dir(tmp_path, cli, monkeypatch):
    """``--natural DIR`` read its photos through the default cache whatever the command
    said: with ``--cache-dir`` they are cached there, with ``--no-cache`` nowhere."""
    from tests.color.conftest import SAMPLES, small_copy

    default = tmp_path / "default-cache"
    monkeypatch.setenv("WBCGRADE_CACHE_DIR", str(default))
    styles = tmp_path / "styles"
    styles.mkdir()
    for name in ("aitzgorri", "bridge"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", 32)
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "p.jpg", 32)

    def cached(folder):
        return sorted(p.name for p in folder.rglob("*.npz")) if folder.exists() else []

    for case, flags in (("chosen", ["--cache-dir", tmp_path / "chosen"]),
                        ("off", ["--no-cache"])):
        natural = tmp_path / f"natural-{case}"  # (a folder once read is kept in memory)
        natural.mkdir()
        for name in ("flower", "sunset", "coffee"):
            small_copy(SAMPLES / f"{name}.jpg", natural / f"{name}.jpg", 32)
        result = cli("apply", photo, "--style", styles, "--natural", natural, *flags,
                     "-o", tmp_path / f"{case}.jpg")
        assert result.exit_code == 0, result.output
        assert cached(default) == [], case
    assert len(cached(tmp_path / "chosen")) >= 2 + 3
