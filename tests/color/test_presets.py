"""Preset files: round trip, shipped presets, broken or foreign files."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from tests.color.conftest import SAMPLES
from wbcgrade.color.presets import (
    list_presets,
    load_preset,
    load_style_folder,
    resolve_preset,
    save_preset,
)
from wbcgrade.errors import InputError


def test_round_trip(tmp_path, style_dir):
    warnings = []
    (tmp_path / "styles").mkdir()
    styles = load_style_folder(style_dir, 12, warn=warnings.append)
    assert styles.names == ["aitzgorri", "coffee", "flower", "seeding"] and not warnings
    path = save_preset(tmp_path / "p.npz", styles, description="test")
    loaded = load_preset(path)
    assert loaded.names == styles.names and loaded.bins == 12
    assert loaded.description == "test" and loaded.width == 1.5
    np.testing.assert_allclose(loaded.histograms, styles.histograms, atol=1e-6)
    with pytest.raises(InputError, match="exists"):
        save_preset(path, styles)


def test_a_presets_dense_histograms_are_made_only_when_read(tmp_path, style_dir):
    """A preset keeps its histograms sparse until something reads the dense stack (a cached
    look grade reads only the shipped natural palettes' file digest: their 316 dense
    32^3 histograms, 83 MB, are never made); read, they are the file's, each summing to 1."""
    from wbcgrade.color.histogram import Deferred
    from wbcgrade.color.look.set_extraction import natural_palettes

    styles = load_style_folder(style_dir, 12)
    loaded = load_preset(save_preset(tmp_path / "p.npz", styles))
    assert isinstance(loaded.__dict__["_deferred_histograms"], Deferred)
    assert loaded.bins == 12 and len(loaded.names) == 4  # (the shape, without making it)
    assert isinstance(loaded.__dict__["_deferred_histograms"], Deferred)
    np.testing.assert_allclose(loaded.histograms, styles.histograms, atol=1e-6)
    np.testing.assert_allclose(loaded.histograms.sum(axis=(1, 2, 3)), 1.0, rtol=1e-12)
    assert isinstance(loaded.__dict__["_deferred_histograms"], np.ndarray)  # made once, kept
    natural = natural_palettes()
    assert isinstance(natural.__dict__["_deferred_histograms"], Deferred)
    assert natural.meta["file_digest"]


def test_compact_presets_hold_the_same_histograms_in_half_the_file(tmp_path, style_dir):
    styles = load_style_folder(style_dir, 32)
    full = save_preset(tmp_path / "full.npz", styles)
    compact = save_preset(tmp_path / "compact.npz", styles, compact=True)
    with np.load(compact) as data:
        assert data["index"].dtype == np.uint16 and data["values"].dtype == np.float16
    assert compact.stat().st_size < 0.75 * full.stat().st_size
    loaded = load_preset(compact)
    assert loaded.names == styles.names and loaded.bins == 32
    reference = load_preset(full).histograms
    np.testing.assert_allclose(loaded.histograms, reference, rtol=2e-3, atol=1e-12)
    # a grid too fine for 16-bit indices keeps 32-bit ones
    fine = save_preset(tmp_path / "fine.npz", load_style_folder(style_dir, 48), compact=True)
    with np.load(fine) as data:
        assert data["index"].dtype == np.int32 and data["values"].dtype == np.float16
    assert load_preset(fine).bins == 48


def test_natural_palettes_are_many_listed_photos_none_of_them_a_sample():
    import csv
    from pathlib import Path

    from wbcgrade.color.look import natural_palettes

    naturals = natural_palettes()
    names = set(naturals.names)
    assert len(names) == len(naturals.names) >= 300
    assert np.allclose(naturals.histograms.sum(axis=(1, 2, 3)), 1.0)
    assert not names & {p.stem for p in SAMPLES.glob("*.jpg")}  # the samples stay unseen
    root = Path(__file__).resolve().parents[2]
    with open(root / "presets" / "natural_corpus.csv", newline="", encoding="utf-8") as f:
        corpus = {row["name"]: row for row in csv.DictReader(f)}
    assert names == set(corpus)
    assert all(row["author"] and row["licence"] and row["source_package"]
               for row in corpus.values())
    table = (root / "wbcgrade" / "color" / "data" / "NATURAL.md").read_text(encoding="utf-8")
    assert all(f"| {name} |" in table for name in names)


def test_shipped_presets_are_looks_of_photos_outside_the_samples():
    names = [name for name, _ in list_presets()]
    assert {"kodak-2383", "teal-orange", "bleach-bypass", "faded", "warm"} <= set(names)
    samples = {p.stem for p in SAMPLES.glob("*.jpg")}
    for name in names:
        styles = load_preset(resolve_preset(name))
        assert styles.histograms.shape[0] == len(styles.names) >= 2
        assert np.allclose(styles.histograms.sum(axis=(1, 2, 3)), 1.0)
        provenance = styles.meta["provenance"]
        assert provenance["look"] and set(provenance["photos"]) == set(styles.names)
        assert not samples & set(styles.names)  # no sample photo is graded towards itself
    with pytest.raises(InputError, match="unknown preset 'nope'.*kodak-2383"):
        resolve_preset("nope")
    with pytest.raises(InputError, match="'landscape'.*no longer shipped.*looks.*teal-orange"):
        resolve_preset("landscape")
    with pytest.raises(InputError, match="no such preset file"):
        resolve_preset("missing/file.npz")


def _write_npz(path, **arrays):
    np.savez(path, **arrays)
    return path


def _header(**changes):
    header = {"format": "wbcgrade-preset", "version": 1, "bins": 4, "names": ["a"]}
    header.update(changes)
    return np.frombuffer(json.dumps(header).encode(), np.uint8)


@pytest.mark.parametrize("case, message", [
    ("garbage", "unreadable archive"),
    ("zip", "missing"),
    ("foreign", "missing"),
    ("pickled", "unreadable archive"),
    ("no-json", "header is not JSON"),
    ("tag", "unknown format tag"),
    ("version", "format version 99"),
    ("index", "bin index out of range"),
    ("negative", "negative or non-finite"),
    ("offsets", "inconsistent"),
    ("width", "bad kernel width"),  # 1e300 was taken (every file field bounded)
    ("extra", "unknown member 'extra'"),  # 255 MB members were read
])
def test_broken_presets_give_one_clear_error(tmp_path, case, message):
    path = tmp_path / "bad.npz"
    good = {"index": np.array([0, 5]), "values": np.array([0.5, 0.5], np.float32),
            "offsets": np.array([0, 2])}
    if case == "garbage":
        path.write_bytes(b"\x00garbage" * 10)
    elif case == "zip":
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr("readme.txt", "hello")
    elif case == "foreign":
        _write_npz(path, weights=np.ones(3))
    elif case == "pickled":
        np.savez(path, header=np.array([{"evil": 1}], dtype=object), **good)
    elif case == "no-json":
        _write_npz(path, header=np.frombuffer(b"\xff\xfe", np.uint8), **good)
    elif case == "tag":
        _write_npz(path, header=_header(format="other"), **good)
    elif case == "version":
        _write_npz(path, header=_header(version=99), **good)
    elif case == "index":
        _write_npz(path, header=_header(), **{**good, "index": np.array([0, 64])})
    elif case == "negative":
        _write_npz(path, header=_header(), **{**good, "values": np.array([1.0, -0.5])})
    elif case == "offsets":
        _write_npz(path, header=_header(), **{**good, "offsets": np.array([0, 1])})
    elif case == "width":
        _write_npz(path, header=_header(width=1e300), **good)
    elif case == "extra":
        _write_npz(path, header=_header(), extra=np.zeros(4), **good)
    with pytest.raises(InputError, match=message) as info:
        load_preset(path)
    assert "\n" not in str(info.value) and "not a valid wbcgrade preset" in str(info.value)


def test_style_folder_skips_non_images_and_rejects_empty(tmp_path, style_dir):
    folder = tmp_path / "mixed"
    folder.mkdir()
    (folder / "notes.txt").write_text("not a photo")
    (folder / "broken.jpg").write_bytes(b"\xff\xd8\xff garbage")
    with pytest.raises(InputError, match="no readable photos"):
        load_style_folder(folder, 8, warn=lambda m: None)
    (folder / "coffee.jpg").write_bytes((style_dir / "coffee.jpg").read_bytes())
    warnings = []
    styles = load_style_folder(folder, 8, warn=warnings.append)
    assert styles.names == ["coffee"] and len(warnings) == 2
    with pytest.raises(InputError, match="does not exist"):
        load_style_folder(tmp_path / "nowhere", 8)



def test_own_style_is_found_only_for_the_photo_itself_at_a_large_weight(tmp_path):
    from tests.color.conftest import small_copy
    from wbcgrade.color.histogram import image_histogram
    from wbcgrade.color.io.images import read_image
    from wbcgrade.color.presets import own_style

    def hist(rgb):
        return image_histogram(np.asarray(rgb, np.float32), 16)

    coffee = read_image(SAMPLES / "coffee.jpg").rgb()
    photo = hist(coffee)
    warm = np.clip(coffee * np.array([1.1, 1.0, 0.85]) + 0.03, 0, 1)  # a mild grade of it
    styles = np.stack([hist(read_image(SAMPLES / "flower.jpg").rgb()), hist(coffee[::3, ::3]),
                       hist(warm)])
    names = ["flower", "coffee", "coffee_warm"]
    found = own_style(photo, styles, names, [0.0, 0.95, 0.05])
    assert found["style"] == "coffee" and found["weight"] == 0.95 and found["distance"] < 0.1
    assert own_style(photo, styles, names, [0.3, 0.5, 0.2]) is None  # a blend, not itself
    assert own_style(photo, styles, names, [0.0, 0.0, 1.0]) is None  # its graded version
    assert own_style(photo, styles, names, [1.0, 0.0, 0.0]) is None  # another photo
    small = read_image(small_copy(SAMPLES / "coffee.jpg", tmp_path / "coffee.png", 96)).rgb()
    assert own_style(hist(small), styles, names, [0, 1, 0])["style"] == "coffee"


@pytest.mark.slow
def test_apply_warns_in_one_line_when_the_photo_is_one_of_the_styles(tmp_path, cli):

    from tests.color.conftest import FAST_ARGS, small_copy

    styles = tmp_path / "styles"
    styles.mkdir()
    for name in ("coffee", "flower", "sunset"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", 96)
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "mine.jpg", 64)
    result = cli("apply", str(photo), "--style", str(styles), "-o",
                 str(tmp_path / "out.jpg"), *FAST_ARGS)
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if "own palette" in line]
    assert len(warnings) == 1
    assert warnings[0].startswith(f"Warning: {photo} is graded towards its own palette "
                                  "(style 'coffee' has weight ")
    other = small_copy(SAMPLES / "chelsea.jpg", tmp_path / "cat.jpg", 64)
    result = cli("apply", str(other), "--style", str(styles), "-o",
                 str(tmp_path / "cat_out.jpg"), *FAST_ARGS)
    assert result.exit_code == 0 and "own palette" not in result.stderr
    # the default grade (a look: the style photo of its scene, as large as the style photos
    # for the scene to be matched) says it without a palette grade's weight and distance
    photo = small_copy(SAMPLES / "coffee.jpg", tmp_path / "mine96.jpg", 96)
    result = cli("apply", str(photo), "--style", str(styles), "-o",
                 str(tmp_path / "look_out.jpg"), "--no-cache")
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if "coffee" in line]
    assert warnings == [f"Warning: {photo} is itself one of the style photos ('coffee'): it "
                        "is graded with its own look, so little changes; leave it out of the "
                        "style folder"]
