"""Contact sheet of set looks: six style photos a look, with and without one original.

Run ``python benchmarks/set_sheet.py`` (about a minute at the default 384 px). For each
photographer's look of ``benchmarks/_looks.py`` (muted-cool, faded-warm, punchy,
split-tone), six of the look benchmark's photos graded with the look are the style
photos; three other photos are graded by the default grade towards them (as
``apply --style`` grades) and by the look learned with one style photo's original given
(as ``apply --style DIR --originals ODIR`` grades). Writes ``sheet.png`` (photo | truth |
set look | one original, each labelled with its recovered fraction, 1 - dE2000(out,
truth) / dE2000(photo, truth)) and ``crops.png`` (2x crops of skin, sky and whites) to
``--out``, and prints the figures.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _looks import LOOKS, PHOTOGRAPHER_LOOKS  # noqa: E402
from look import DEFAULT_PHOTOS, delta_e, lab, read_photo  # noqa: E402
from set_calibration import grade  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STYLES = ["china", "life", "rocket", "wine", "fig", "brushes"]
#: The photos graded, and a 64 px region of each shown at 2x: (what, top, left) as shares.
GRADED = {"grace_hopper": ("skin", 0.25, 0.40), "picosdeeuropa": ("sky", 0.05, 0.35),
          "kleiber": ("whites", 0.55, 0.75)}


def to_8bit(img: np.ndarray) -> np.ndarray:
    return np.round(np.clip(img, 0.0, 1.0) * 255.0) / 255.0


def one_original_grade(styles: list[np.ndarray], original: np.ndarray):
    """The grade ``look learn`` gives from the style photos, the first with its original."""
    import OpenImageIO as oiio

    from wbcgrade.color.grade.look_files import learned_grade

    with tempfile.TemporaryDirectory() as tmp:
        originals, edited = Path(tmp) / "originals", Path(tmp) / "edited"
        originals.mkdir()
        edited.mkdir()
        for name, style in zip(STYLES, styles):
            oiio.ImageBuf((style * 255).round().astype(np.uint8)).write(str(edited / f"{name}.png"))
        oiio.ImageBuf((original * 255).round().astype(np.uint8)).write(
            str(originals / f"{STYLES[0]}.png"))
        found, _ = learned_grade(originals, edited)
    return found


def tile(img: np.ndarray, width: int) -> Image.Image:
    height = int(img.shape[0] * width / img.shape[1])
    return Image.fromarray((to_8bit(img) * 255).astype(np.uint8)).resize((width, height))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=384, help="long side in px")
    parser.add_argument("--photo-dir", type=Path, default=DEFAULT_PHOTOS)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "set_sheet")
    args = parser.parse_args()
    photos = {n: read_photo(args.photo_dir / f"{n}.jpg", args.size)
              for n in STYLES + list(GRADED)}
    rows, crops = [], []
    print("| look | photo | set look (strength) | one original |")
    print("|---|---|---|---|")
    for look_name in PHOTOGRAPHER_LOOKS:
        look = LOOKS[look_name].apply
        styles = [to_8bit(look(photos[n])) for n in STYLES]
        learned = one_original_grade(styles, photos[STYLES[0]])
        for name, (what, top, left) in GRADED.items():
            photo = photos[name]
            truth = to_8bit(look(photo))
            by_set, strength = grade(photo, styles, STYLES)
            outs = [to_8bit(by_set), to_8bit(learned.apply(photo.astype(np.float32)))]
            before = delta_e(lab(photo), lab(truth))
            recovered = [1.0 - delta_e(lab(o), lab(truth)) / before for o in outs]
            print(f"| {look_name} | {name} | {recovered[0]:+.2f} ({strength:.2f}) "
                  f"| {recovered[1]:+.2f} |")
            label = (f"{look_name}, {name}: set look {recovered[0]:+.2f} (strength "
                     f"{strength:.2f}), one original {recovered[1]:+.2f}  "
                     "[photo | truth | set look | one original]")
            images = [photo, truth, *outs]
            rows.append((label, images))
            y, x = int(top * photo.shape[0]), int(left * photo.shape[1])
            crops.append((f"{look_name}: {what}", [
                tile(img[y:y + 64, x:x + 64], 128) for img in images]))
    args.out.mkdir(parents=True, exist_ok=True)
    width = 220
    height = max(tile(images[0], width).size[1] for _, images in rows)
    sheet = Image.new("RGB", (4 * (width + 4), len(rows) * (height + 16)), "white")
    draw = ImageDraw.Draw(sheet)
    for i, (label, images) in enumerate(rows):
        draw.text((2, i * (height + 16)), label, fill="black")
        for j, img in enumerate(images):
            sheet.paste(tile(img, width), (j * (width + 4), i * (height + 16) + 14))
    sheet.save(args.out / "sheet.png")
    board = Image.new("RGB", (4 * 132, len(crops) * 146), "white")
    draw = ImageDraw.Draw(board)
    for i, (label, tiles) in enumerate(crops):
        draw.text((2, i * 146), label, fill="black")
        for j, t in enumerate(tiles):
            board.paste(t, (j * 132, i * 146 + 14))
    board.save(args.out / "crops.png")
    print(f"wrote {args.out / 'sheet.png'}, {args.out / 'crops.png'}")


if __name__ == "__main__":
    main()
