"""Set-look calibration: is a look shown by 3, 6 or 12 style photos applied as far as they show it?

Run ``python benchmarks/set_calibration.py`` (``--help``; about two minutes at the
default 256 px). For each look (default the photographers' looks of
``benchmarks/_looks.py``: muted-cool, faded-warm, punchy, split-tone, on which no
setting was chosen) and each set size, ``--reps`` random partitions of the look
benchmark's photos: the look applied to S photos is the style set, four other
photos are graded by the default grade (``grade_array`` with the style images,
as ``apply --style`` grades) and compared with the look applied to them
(recovered = 1 - dE2000(out, truth) / dE2000(photo, truth)). Sets with no look
(S ungraded photos; and the three warmest, most colourful photos) give how far
the grade moves photos when there is nothing to find (mean dE2000 of out against
the photo; every photo should stay under 1.5). ``--warm K``: also every three of the
``K`` warmest, most colourful photos (default 6: twenty sets of similar content, the
hardest sets without a look), each grading four others; the largest change and the
share of graded photos moved over 1.5 dE2000.

Prints a table per set size (mean and worst recovered per look, the strength the
grade reported) and a calibration table: the reported strength, binned, against
the mean recovered fraction.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _looks import LOOKS, PHOTOGRAPHER_LOOKS  # noqa: E402
from look import DEFAULT_PHOTOS, EXCLUDED, delta_e, lab, read_photo  # noqa: E402


def grade(photo: np.ndarray, styles: list[np.ndarray], names: list[str]):
    """The default grade of ``photo`` towards style images: (graded, reported strength)."""
    from wbcgrade.color.colorspace import default_working_space
    from wbcgrade.color.grade.grading import grade_array
    from wbcgrade.color.histogram import image_histogram
    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.presets import StyleSet

    opts = GradeOptions()
    hists = np.stack([image_histogram(np.asarray(s, np.float32), opts.transfer.bins, None,
                                      opts.transfer.max_pixels) for s in styles])
    styles_set = StyleSet(names=list(names), histograms=hists, source="calibration",
                          meta={"working_space": default_working_space(),
                                "images": [np.asarray(s, np.float32) for s in styles]})
    graded, result = grade_array(np.asarray(photo, np.float32), styles_set, opts)
    look = result.info.get("look", {}) or {}
    return np.clip(graded, 0.0, 1.0), float(look.get("set_strength", np.nan))


def colourful_warm(photos: dict[str, np.ndarray], count: int) -> list[str]:
    """The ``count`` photos whose pixels are warmest and most saturated."""
    def score(rgb):
        return float(np.mean(rgb[..., 0] - rgb[..., 2]) + np.mean(np.ptp(rgb, axis=-1)))
    return sorted(photos, key=lambda n: -score(photos[n]))[:count]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--looks", default=",".join(PHOTOGRAPHER_LOOKS))
    parser.add_argument("--sizes", default="3,6,12", help="style photos per set")
    parser.add_argument("--reps", type=int, default=2, help="partitions per look and size")
    parser.add_argument("--graded", type=int, default=4, help="photos graded per set")
    parser.add_argument("--size", type=int, default=256, help="long side in px")
    parser.add_argument("--photo-dir", type=Path, default=DEFAULT_PHOTOS)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--warm", type=int, default=6,
                        help="every three of the K warmest, most colourful photos (0: none)")
    args = parser.parse_args()
    names = sorted(p.stem for p in args.photo_dir.glob("*.jpg") if p.stem not in EXCLUDED)
    photos = {n: read_photo(args.photo_dir / f"{n}.jpg", args.size) for n in names}
    looks = [lk for lk in args.looks.split(",") if lk]
    sizes = [int(s) for s in args.sizes.split(",")]
    rng = np.random.default_rng(args.seed)
    rows = []  # (size, look, photo, value, strength)
    for size in sizes:
        sets = [(look, rep) for look in looks for rep in range(args.reps)]
        sets += [("(no look)", rep) for rep in range(args.reps)]
        if size == 3:
            sets.append(("(warm, colourful)", 0))
        for look, _ in sets:
            order = list(rng.permutation(names))
            if look == "(warm, colourful)":
                chosen = colourful_warm(photos, 3)
                order = chosen + [n for n in order if n not in chosen]
            style_names, graded = order[:size], order[size:size + args.graded]
            apply = None if look.startswith("(") else LOOKS[look].apply
            styles = [photos[n] if apply is None else np.clip(apply(photos[n]), 0, 1)
                      for n in style_names]
            styles = [np.round(s * 255) / 255 for s in styles]
            for name in graded:
                photo = photos[name]
                out, strength = grade(photo, styles, style_names)
                if apply is None:
                    value = delta_e(lab(out), lab(photo))
                else:
                    truth = np.round(np.clip(apply(photo), 0, 1) * 255) / 255
                    value = 1.0 - delta_e(lab(out), lab(truth)) / delta_e(lab(photo), lab(truth))
                rows.append((size, look, name, value, strength))
            print(f"  S={size:2d} {look:18s} done", file=sys.stderr, flush=True)
    print(f"\nSet looks, {args.size} px, {args.reps} partitions a look, "
          f"{args.graded} photos graded a set")
    print(f"| {'look':18s} | " + " | ".join(f"S={s:<2d} mean (worst) strength" for s in sizes)
          + " |")
    print("|" + "---|" * (len(sizes) + 1))
    for look in looks + ["(all looks)", "(no look)", "(warm, colourful)"]:
        cells = []
        for size in sizes:
            sel = [r for r in rows if r[0] == size and (
                r[1] == look or (look == "(all looks)" and not r[1].startswith("(")))]
            if not sel:
                cells.append(f"{'':>30s}")
                continue
            v, s = np.array([r[3] for r in sel]), np.array([r[4] for r in sel])
            worst = v.max() if look.startswith("(") and look != "(all looks)" else v.min()
            unit = " dE" if look.startswith("(") and look != "(all looks)" else "   "
            cells.append(f"{v.mean():+.2f} ({worst:+.2f}){unit} {np.nanmean(s):.2f}".rjust(30))
        print(f"| {look:18s} | " + " | ".join(cells) + " |")
    if args.warm >= 3:
        moves = []
        for trio in itertools.combinations(colourful_warm(photos, args.warm), 3):
            others = [n for n in names if n not in trio]
            styles = [np.round(photos[n] * 255) / 255 for n in trio]
            for name in rng.choice(others, args.graded, replace=False):
                out, _ = grade(photos[name], styles, list(trio))
                moves.append(delta_e(lab(out), lab(photos[name])))
            print(f"  warm {', '.join(trio)}: {max(moves[-args.graded:]):.2f} dE",
                  file=sys.stderr, flush=True)
        moves = np.array(moves)
        print(f"\nEvery three of the {args.warm} warmest, most colourful photos (no look), "
              f"{args.graded} others graded each: mean change {moves.mean():.2f} dE, largest "
              f"{moves.max():.2f} dE, {np.mean(moves > 1.5):.0%} of {len(moves)} graded "
              f"photos over 1.5 dE")
    print("\nCalibration (every look photo): reported strength against recovered")
    print("| strength | photos | mean recovered |")
    print("|---|---|---|")
    looked = [r for r in rows if not r[1].startswith("(")]
    edges = [0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 1.01]
    for lo, hi in zip(edges[:-1], edges[1:]):
        v = [r[3] for r in looked if lo <= r[4] < hi]
        if v:
            print(f"| {lo:.1f}-{min(hi, 1.0):.1f} | {len(v)} | {np.mean(v):+.2f} |")


if __name__ == "__main__":
    main()
