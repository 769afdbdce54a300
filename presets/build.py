"""Build the shipped presets: known looks applied to a neutral set of photos.

Run from the repository root (an offline step; wbcgrade itself only reads the
``.npz`` files it writes)::

    python presets/build.py PHOTO_FOLDER [--sheets DIR]

``PHOTO_FOLDER`` holds the ungraded photos named in :data:`PHOTOS` (their
authors, licences and sources are in ``presets/README.md``). Each preset is
one look of ``benchmarks/_looks.py`` (the look benchmark's, so both use the
same definitions: two ACES LMTs in CLF shipped in ``colour-clf-io`` and
applied with OpenColorIO, and an ASC CDL and curve grades defined there)
applied to every photo, quantised to 8 bits like a saved JPEG; the preset
holds the histograms of the looked photos (32^3 bins, sRGB-encoded Rec.709),
never the photos. Its header records the look's source and the photos
(``provenance``), which ``wbcgrade preset list --json`` shows.

``--sheets DIR`` also writes ``DIR/<preset>.png``: the looked photos of each
preset side by side (check a rebuilt preset by eye). ``--try PHOTO`` (with
``--sheets``) grades PHOTO with every shipped preset, in the default palette
mode and in ``--mode look``, into ``DIR/try_<photo>.png``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]  # this tree's wbcgrade

from _looks import LOOKS  # noqa: E402

#: The neutral photos (ungraded, varied content: a portrait, buildings and
#: water, a mountain meadow, a forest stream, dogs on grey wood, a warm
#: interior). None of them is among ``samples/``, so a sample photo graded
#: with a shipped preset is never graded towards itself.
PHOTOS = ("grace_hopper", "china", "picosdeeuropa", "life", "friends", "wine")

#: Preset name: (look in ``benchmarks/_looks.py``, one line for ``preset list``).
PRESETS = {
    "kodak-2383": ("kodak2383", "film print: the Kodak 2383 print emulation LMT (ACES, CLF)"),
    "arri-k1s1": ("arri-k1s1", "camera look: ARRI K1S1 Rec.709 at EI 800 (ACES LMT, CLF)"),
    "warm": ("cdl-warm", "warm and slightly muted (ASC CDL)"),
    "teal-orange": ("teal-orange", "teal shadows, orange highlights, more contrast"),
    "bleach-bypass": ("bleach-bypass", "bleach bypass: hard contrast, little colour"),
    "faded": ("faded-film", "faded print: lifted blue-green blacks, cream whites, less colour"),
}

#: Long side of the photos as graded (they are stored at 1024 px or less).
SIZE = 1024
BINS = 32
#: Nodes per axis of the look lattice stored with each preset (the grade's own map size).
LOOK_SIZE = 33


def read_photo(path: Path) -> np.ndarray:
    """(H, W, 3) float64 sRGB-encoded in [0, 1], long side at most :data:`SIZE`."""
    from PIL import Image

    with Image.open(path) as image:
        image = image.convert("RGB")
        image.thumbnail((SIZE, SIZE), Image.LANCZOS)
        return np.asarray(image, dtype=np.float64) / 255.0


def to_8bit(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) float in [0, 1] -> uint8 (rounded, clipped)."""
    return np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)


def contact_sheet(pictures: list[tuple[str, np.ndarray | None]], path: Path, tile: int = 320,
                  columns: int = 3, title: str = "") -> Path:
    """A grid of labelled pictures ((H, W, 3) uint8 or float in [0, 1]; None: an empty
    cell), each fitted into ``tile`` x ``tile``, rows as high as their tallest picture,
    saved as PNG."""
    from PIL import Image, ImageDraw

    thumbs = []
    for name, picture in pictures:
        if picture is None:
            thumbs.append((name, None))
            continue
        image = Image.fromarray(picture if picture.dtype == np.uint8 else to_8bit(picture))
        image.thumbnail((tile, tile), Image.LANCZOS)
        thumbs.append((name, image))
    label, top = 18, 24 if title else 0
    rows = [thumbs[i:i + columns] for i in range(0, len(thumbs), columns)]
    heights = [max((im.height for _, im in row if im is not None), default=0) + label
               for row in rows]
    sheet = Image.new("RGB", (columns * tile, top + sum(heights)), "white")
    draw = ImageDraw.Draw(sheet)
    if title:
        draw.text((6, 6), title, fill="black")
    y = top
    for row, height in zip(rows, heights):
        for column, (name, image) in enumerate(row):
            if image is not None:
                sheet.paste(image, (column * tile, y))
            draw.text((column * tile + 4, y + height - label + 3), name, fill="black")
        y += height
    path.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(path)
    return path


def build(folder: Path, out: Path, sheets: Path | None) -> None:
    from PIL import Image

    from wbcgrade.color.histogram import grid_points
    from wbcgrade.color.presets import load_style_folder, save_preset

    missing = [name for name in PHOTOS if not (folder / f"{name}.jpg").is_file()]
    if missing:
        raise SystemExit(f"{folder}: missing {', '.join(missing)} (see presets/README.md)")
    photos = {name: read_photo(folder / f"{name}.jpg") for name in PHOTOS}
    for preset, (look_name, description) in PRESETS.items():
        look = LOOKS[look_name]
        looked = {name: to_8bit(look.apply(rgb)) for name, rgb in photos.items()}
        with tempfile.TemporaryDirectory() as tmp:
            for name, pixels in looked.items():
                Image.fromarray(pixels).save(Path(tmp) / f"{name}.png")
            styles = load_style_folder(tmp, BINS)
        styles.source = preset
        provenance = {"look": look_name, "look_source": look.source(),
                      "photos": list(PHOTOS), "photo_size": SIZE,
                      "built_by": "presets/build.py (sources: presets/README.md)"}
        # the look itself, known exactly: its lattice LUT on sRGB-encoded colours (the
        # preset's working space), which the "look" grade applies as it is
        points = grid_points(LOOK_SIZE).reshape(LOOK_SIZE ** 2, LOOK_SIZE, 3)
        lattice = np.clip(look.apply(points), 0.0, 1.0).reshape((LOOK_SIZE,) * 3 + (3,))
        path = save_preset(out / f"{preset}.npz", styles, description=description,
                           overwrite=True, provenance=provenance, look=lattice)
        print(f"{path}: {len(styles.names)} styles, {path.stat().st_size / 1024:.0f} KiB")
        if sheets is not None:
            contact_sheet(list(looked.items()), sheets / f"{preset}.png",
                          title=f"preset {preset}: {description}")


def try_presets(photo: Path, sheets: Path, size: int = 512) -> Path:
    """Grade ``photo`` (downscaled to ``size``) with every shipped preset in both modes."""
    from wbcgrade.color.grade.grading import grade_array
    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.presets import list_presets, load_preset

    rgb = read_photo(photo)
    if max(rgb.shape[:2]) > size:
        from PIL import Image

        image = Image.fromarray(to_8bit(rgb))
        image.thumbnail((size, size), Image.LANCZOS)
        rgb = np.asarray(image, dtype=np.float64) / 255.0
    pictures: list[tuple[str, np.ndarray | None]] = [(f"{photo.stem} (input)", rgb),
                                                     ("", None)]
    for name, path in list_presets():
        styles = load_preset(path)
        for mode in ("palette", "look"):
            graded, grade = grade_array(rgb, styles, GradeOptions(mode=mode))
            top = max(zip(grade.weights, styles.names))
            pictures.append((f"{name}, {mode} (top: {top[1]} {top[0]:.2f})", graded))
            print(f"{name} {mode}: mean change {np.abs(graded - rgb).mean() * 255:.1f}/255")
    return contact_sheet(pictures, sheets / f"try_{photo.stem}.png", tile=400, columns=2,
                         title=f"{photo.name} graded with each shipped preset: palette mode, "
                               "look mode")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("photos", type=Path, help="folder holding the photos of PHOTOS")
    parser.add_argument("--out", type=Path, default=ROOT / "wbcgrade" / "color" / "presets_data")
    parser.add_argument("--sheets", type=Path, default=None,
                        help="also write a contact sheet of each preset's looked photos here")
    parser.add_argument("--try", dest="try_photo", type=Path, default=None, metavar="PHOTO",
                        help="with --sheets: grade PHOTO with every shipped preset (both "
                             "modes) instead of building")
    args = parser.parse_args()
    if args.try_photo is not None:
        if args.sheets is None:
            parser.error("--try needs --sheets DIR")
        print(try_presets(args.try_photo, args.sheets))
        return
    build(args.photos, args.out, args.sheets)


if __name__ == "__main__":
    main()
