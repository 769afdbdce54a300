"""Re-gather the natural-palette photo corpus from the package registries.

The corpus (presets/natural_corpus.csv, one row a photo) names, for every photo,
the package and version it comes from (Debian bookworm), the file inside
that package, its author and licence. This script downloads those packages with
their ordinary client (``apt-get download``), unpacks them,
and writes every photo downscaled to a long side of at most 1024 px (JPEG quality
92) as ``OUT/photos/NAME.jpg``, with ``OUT/ATTRIBUTION.csv`` beside them.

Usage (from the repository root, as a user who may run apt-get)::

    python presets/gather_natural.py OUT [--cache DIR] [--table wbcgrade/color/data/NATURAL.md]
    sh presets/build_natural.sh OUT/photos

An ``original_file`` of the form ``PATH.rcc:INNER`` is a file inside a Qt resource
bundle (GCompris ships its images that way); ``PATH.edj:INNER`` is an image inside
an Edje file, unpacked with ``edje_decc`` (Debian package libedje-bin).
Only the photos' histograms are shipped in the repository, never the photos.
"""

from __future__ import annotations

import argparse
import csv
import io
import os
import struct
import subprocess
import sys
import tempfile
import zlib
from pathlib import Path

from PIL import Image

Image.MAX_IMAGE_PIXELS = None
MANIFEST = Path(__file__).with_name("natural_corpus.csv")
COLUMNS = ["name", "author", "licence", "source_package", "source_registry",
           "original_file", "original_size"]
LONG_SIDE = 1024
QUALITY = 92


def read_manifest(path: Path = MANIFEST) -> list[dict[str, str]]:
    """The corpus rows, in file order."""
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def rcc_member(bundle: bytes, inner: str) -> bytes:
    """One file of a Qt binary resource bundle (.rcc), by its path inside it."""
    if bundle[:4] != b"qres":
        raise ValueError("not a Qt resource bundle")
    version, tree, data, names = struct.unpack(">IIII", bundle[4:20])
    node_size = 14 if version == 1 else 22

    def name(offset: int) -> str:
        (length,) = struct.unpack(">H", bundle[names + offset:names + offset + 2])
        return bundle[names + offset + 6:names + offset + 6 + 2 * length].decode("utf-16-be")

    def find(index: int, parts: list[str]) -> bytes:
        node = tree + index * node_size
        _, flags = struct.unpack(">IH", bundle[node:node + 6])
        if not parts:
            (offset,) = struct.unpack(">I", bundle[node + 10:node + 14])
            (size,) = struct.unpack(">I", bundle[data + offset:data + offset + 4])
            blob = bundle[data + offset + 4:data + offset + 4 + size]
            if flags & 1:
                blob = zlib.decompress(blob[4:])
            elif flags & 4:
                import zstandard  # only bundles built with zstd need it

                blob = zstandard.ZstdDecompressor().decompress(blob)
            return blob
        if not flags & 2:
            raise KeyError("/".join(parts))
        count, first = struct.unpack(">II", bundle[node + 6:node + 14])
        for child in range(first, first + count):
            start = tree + child * node_size
            (name_offset,) = struct.unpack(">I", bundle[start:start + 4])
            if name(name_offset) == parts[0]:
                return find(child, parts[1:])
        raise KeyError("/".join(parts))

    return find(0, inner.strip("/").split("/"))


def fetch_debian(package: str, cache: Path) -> Path:
    """Unpacked tree of a Debian package (``name=version``), downloaded once."""
    name, _, version = package.partition("=")
    tree = cache / "tree" / package.replace(":", "%3a")
    if tree.is_dir():
        return tree
    debs = cache / "debs"
    debs.mkdir(parents=True, exist_ok=True)
    pattern = f"{name}_{version.replace(':', '%3a')}_*.deb"
    found = sorted(debs.glob(pattern))
    if not found:
        subprocess.run(["apt-get", "download", package], cwd=debs, check=True)
        found = sorted(debs.glob(pattern))
    tmp = Path(tempfile.mkdtemp(dir=cache))
    subprocess.run(["dpkg-deb", "-x", str(found[0]), str(tmp)], check=True)
    tree.parent.mkdir(parents=True, exist_ok=True)
    os.replace(tmp, tree)
    return tree


def load_photo(row: dict[str, str], cache: Path) -> Image.Image:
    """The row's original image, as an RGB PIL image."""
    if not row["source_registry"].startswith("Debian"):
        raise ValueError(f"unknown registry {row['source_registry']!r}")
    tree = fetch_debian(row["source_package"], cache)
    path, _, inner = row["original_file"].partition(":")
    if path.endswith(".rcc"):
        blob = rcc_member((tree / path).read_bytes(), inner)
        image = Image.open(io.BytesIO(blob))
    elif path.endswith(".edj"):
        out = cache / "edj" / Path(path).stem
        if not out.is_dir():
            out.parent.mkdir(parents=True, exist_ok=True)
            subprocess.run(["edje_decc", str(tree / path)], cwd=out.parent, check=True,
                           stdout=subprocess.DEVNULL)
        image = Image.open(out / inner)
    else:
        image = Image.open(tree / path)
    image.load()
    if image.mode in ("I;16", "I;16B", "I"):
        image = image.point(lambda v: v / 256).convert("L")
    return image.convert("RGB")


def write_photo(image: Image.Image, target: Path) -> None:
    """Downscale to a long side of at most 1024 px and write atomically (JPEG q92)."""
    if max(image.size) > LONG_SIDE:
        scale = LONG_SIDE / max(image.size)
        size = (max(1, round(image.width * scale)), max(1, round(image.height * scale)))
        image = image.resize(size, Image.LANCZOS)
    tmp = target.with_name("." + target.name + ".tmp")
    image.save(tmp, "JPEG", quality=QUALITY)
    os.replace(tmp, target)


def write_attribution(rows: list[dict[str, str]], target: Path) -> None:
    """ATTRIBUTION.csv of the given rows, written atomically."""
    tmp = target.with_name("." + target.name + ".tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, target)


TABLE_HEAD = """# Natural palettes

`natural.npz` holds the colour histograms (32³ bins, sRGB-encoded, stored
compact: 16-bit bins) of the {count} ungraded photos below. Look extraction
(`wbcgrade/color/look/set_extraction.py`) uses them as its model of what ungraded palettes look
like. Only the histograms are shipped, never the photos.

The photos come from Debian (bookworm) packages; `presets/natural_corpus.csv`
names each one's package, version and file, and `presets/gather_natural.py`
fetches them again (then `sh presets/build_natural.sh CORPUS/photos` rebuilds
the file). Licences are those the packages' `debian/copyright` (or, for KDE
Plasma wallpapers, their `metadata` files) give for each file; where a package
gives no per-file credit, the package's own licence and authors are named.

None of them is one of the sample photos in `samples/` (nor of the photos the
look benchmark grades), so no look is ever learnt from the photos it is measured
on. The 21 photos of the earlier, smaller set are no longer used: astronaut,
coffee, chelsea, rocket, hubble_deep_field, grace_hopper, china, flower,
aitzgorri, picosdeeuropa, life, sunset, friends, fig, brushes, wine, seeding,
bridge, dragonfly, kleiber, infinite_sea.

| photo | author | licence | source package | file |
|---|---|---|---|---|
"""


def write_table(rows: list[dict[str, str]], target: Path) -> None:
    """The provenance table (wbcgrade/color/data/NATURAL.md) of the corpus rows."""
    def cell(text: str) -> str:
        return text.replace("|", "/").strip()

    lines = [TABLE_HEAD.format(count=len(rows))]
    for row in rows:
        lines.append(f"| {row['name']} | {cell(row['author'])} | {cell(row['licence'])} | "
                     f"{cell(row['source_package'])} | {cell(row['original_file'])} |\n")
    tmp = target.with_name("." + target.name + ".tmp")
    tmp.write_text("".join(lines), encoding="utf-8")
    os.replace(tmp, target)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="folder to write photos/ and ATTRIBUTION.csv into")
    parser.add_argument("--cache", type=Path,
                        default=Path(tempfile.gettempdir()) / "wbcgrade-natural-cache",
                        help="where downloaded packages are kept between runs")
    parser.add_argument("--manifest", type=Path, default=MANIFEST)
    parser.add_argument("--force", action="store_true", help="rewrite photos that already exist")
    parser.add_argument("--prune", action="store_true",
                        help="remove photos/*.jpg that the manifest does not list")
    parser.add_argument("--table", type=Path,
                        help="also write the provenance table (NATURAL.md) here")
    args = parser.parse_args(argv)
    rows = read_manifest(args.manifest)
    if args.table:
        write_table(rows, args.table)
    photos = args.out / "photos"
    photos.mkdir(parents=True, exist_ok=True)
    args.cache.mkdir(parents=True, exist_ok=True)
    done, failed = [], 0
    for row in rows:
        target = photos / f"{row['name']}.jpg"
        try:
            if args.force or not target.exists():
                write_photo(load_photo(row, args.cache), target)
            done.append(row)
        except Exception as error:  # one bad source must not stop the others
            failed += 1
            print(f"{row['name']}: {error}", file=sys.stderr)
        if len(done) % 25 == 0:
            write_attribution(done, args.out / "ATTRIBUTION.csv")
    write_attribution(done, args.out / "ATTRIBUTION.csv")
    if args.prune:
        listed = {f"{row['name']}.jpg" for row in rows}
        for stale in photos.glob("*.jpg"):
            if stale.name not in listed:
                stale.unlink()
    print(f"{len(done)} photos in {photos}, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
