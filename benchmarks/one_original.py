"""One original, which photo: how a look learned from one before/after pair depends on the pair.

Run ``python benchmarks/one_original.py`` (``--help``; about ten minutes at 384 px).
The protocol of ``benchmarks/learn.py --originals 1`` (twelve edited photos, the first
with its original, nine other photos graded; recovered = 1 - dE2000(out, truth) /
dE2000(photo, truth)), but each look is learned once with each of ``--originals`` as the
one original (the shuffled ring of ``learn.py`` turned to start at it). The default
originals run from a purple sea, the Hubble field and a pale bridge (few of the colours
natural photos hold) to a portrait and two still lifes (most of them).

Prints a row per look and original (mean and worst photo), then per group of looks
(tuned / held out, as in ``learn.py``): the mean, the mean of the worst photos, the share
of (look, original) with a photo graded worse than doing nothing, and the lowest photo.
Each row also gives what the original's colours can carry at most: the true look applied
where they are (the learner's support of them, ``look/learn.py``'s ``_support``) and no
change elsewhere ("on its colours", mean and worst photo): what is beyond it has to be
guessed, from the pair's extrapolation or from the graded photos without originals.

``--advised``: each case is learned again with the original the learner asks for
(``look learn``'s advice) beside the first, where it asks for one; prints what was asked
for and the mean and worst photo then, and per group the share of cases with a photo
under +0.50 (the advice followed, or the look as learned where nothing was asked).

``--no-look``: the edited photos are the photos themselves (a pair and a set with no look
in them); prints, per original, the mean and largest CIEDE2000 by which the learned look
moves the nine other photos (it should change nothing).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from learn import (  # noqa: E402
    EXCLUDED,
    HELD_OUT,
    MONOCHROME,
    SHARED,
    SHUFFLE_SEED,
    TUNED,
    apply_hald,
    hald_table,
    learn,
    learned_beside,
    score,
    to_8bit,
)
from look import delta_e, lab, read_photo  # noqa: E402

ORIGINALS = ("infinite_sea", "hubble_deep_field", "bridge", "coffee", "flower",
             "grace_hopper", "china", "brushes")
STYLE_PHOTOS = 12


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--looks", default=None,
                        help="comma list (default the colour looks of learn.py)")
    parser.add_argument("--originals", default=",".join(ORIGINALS))
    parser.add_argument("--size", type=int, default=384, help="long side of the photos")
    parser.add_argument("--no-look", action="store_true",
                        help="edited photos with no look: how far the learned look moves photos")
    parser.add_argument("--advised", action="store_true",
                        help="also learn with the original the learner asks for beside the first")
    args = parser.parse_args()
    looks = (args.looks.split(",") if args.looks
             else [lk for lk in TUNED + HELD_OUT if lk not in MONOCHROME])
    names = sorted(p.stem for p in (SHARED / "photos").glob("*.jpg") if p.stem not in EXCLUDED)
    order = [names[i] for i in np.random.default_rng(SHUFFLE_SEED).permutation(len(names))]
    photos = {n: read_photo(SHARED / "photos" / f"{n}.jpg", args.size) for n in names}
    if args.no_look:
        no_look(photos, order, args.originals.split(","))
        return
    rows = []
    print(f"{'look':26s} {'original':18s} {'mean':>6s} {'worst':>6s}   on its colours"
          + ("   asks for         mean  worst" if args.advised else ""))
    for look in looks:
        table = hald_table(SHARED / "looks" / f"{look}.png")
        for first in args.originals.split(","):
            turn = order.index(first)
            ring = order[turn:] + order[:turn]
            with tempfile.TemporaryDirectory(prefix="wbcgrade-one-") as tmp:
                grade, _, report = learn(Path(tmp), photos, ring[:STYLE_PHOTOS], table,
                                         "plain", 1)
                recovered, _ = score(grade, photos, ring[STYLE_PHOTOS:], table)
                asked = report.original_to_add
                followed = recovered  # (nothing asked: the look stays as learned)
                if args.advised and asked is not None:
                    followed = learned_beside(Path(tmp), photos, ring[:STYLE_PHOTOS],
                                              asked["name"], ring[STYLE_PHOTOS:], table,
                                              "advised")
            carried = on_its_colours(photos, first, ring[STYLE_PHOTOS:], table)
            group = "tuned" if look in TUNED else "held-out"
            rows.append((group, float(np.mean(recovered)), float(np.min(recovered)),
                         float(np.mean(carried)), float(np.mean(followed)),
                         float(np.min(followed))))
            line = (f"{look:26s} {first:18s} {rows[-1][1]:+6.3f} {rows[-1][2]:+6.3f}   "
                    f"{rows[-1][3]:+6.3f} {np.min(carried):+6.3f}")
            if args.advised:
                line += (f"   {asked['name'] if asked else '(nothing)':15s} "
                         f"{rows[-1][4]:+6.3f} {rows[-1][5]:+6.3f}")
            print(line, flush=True)
    print()
    for group in ("tuned", "held-out"):
        picked = np.array([r[1:] for r in rows if r[0] == group])
        if len(picked):
            print(f"{group:9s}: mean {picked[:, 0].mean():+.3f}, mean of the worst photos "
                  f"{picked[:, 1].mean():+.3f}, a photo worse than nothing in "
                  f"{np.mean(picked[:, 1] < 0):.0%} of {len(picked)}, lowest photo "
                  f"{picked[:, 1].min():+.2f}; the true look on the original's colours "
                  f"{picked[:, 2].mean():+.3f}")
            if args.advised:
                print(f"{'':9s}  with the original asked for (where one is): mean "
                      f"{picked[:, 3].mean():+.3f}, mean of the worst photos "
                      f"{picked[:, 4].mean():+.3f}, a photo under +0.50 in "
                      f"{np.mean(picked[:, 4] < 0.5):.0%} of {len(picked)}, lowest photo "
                      f"{picked[:, 4].min():+.2f}")


def on_its_colours(photos: dict, original: str, names: list[str], table: np.ndarray
                   ) -> list[float]:
    """Recovered per photo of ``names`` by the true look applied where ``original``'s colours
    are (the learner's support of them) and no change elsewhere."""
    from wbcgrade.color.look.learn import _support
    from wbcgrade.color.mapping.remap import interpolate_lattice

    colours = photos[original].reshape(-1, 3).astype(np.float64)
    support = _support(colours, np.full(len(colours), 1.0 / len(colours)))[..., None]
    out = []
    for name in names:
        photo = photos[name]
        flat = photo.reshape(-1, 3).astype(np.float64)
        truth = apply_hald(table, photo)
        near = interpolate_lattice(support, flat)
        carried = (flat + near * (truth.reshape(-1, 3) - flat)).reshape(photo.shape)
        truth_lab = lab(to_8bit(truth))
        out.append(1.0 - delta_e(lab(to_8bit(carried)), truth_lab)
                   / delta_e(lab(photo), truth_lab))
    return out


def no_look(photos: dict, order: list[str], originals: list[str]) -> None:
    """Each original with edited photos that are the photos themselves: the table of how
    far (CIEDE2000, mean and largest over the nine other photos) the learned look moves."""
    axis = np.linspace(0.0, 1.0, 64)
    blue, green, red = np.meshgrid(axis, axis, axis, indexing="ij")
    identity = np.stack([red, green, blue], axis=-1)  # a Hald table [b, g, r] -> (r, g, b)
    print(f"{'original':18s} {'mean dE':>8s} {'largest':>8s}")
    moved_all = []
    for first in originals:
        turn = order.index(first)
        ring = order[turn:] + order[:turn]
        with tempfile.TemporaryDirectory(prefix="wbcgrade-one-") as tmp:
            grade, _, _ = learn(Path(tmp), photos, ring[:STYLE_PHOTOS], identity, "plain", 1)
            moved = [delta_e(lab(to_8bit(grade.apply(photos[n].astype(np.float32)))),
                             lab(to_8bit(photos[n]))) for n in ring[STYLE_PHOTOS:]]
        moved_all += moved
        print(f"{first:18s} {np.mean(moved):8.3f} {np.max(moved):8.3f}", flush=True)
    print(f"\nno look: mean {np.mean(moved_all):.3f} dE2000, largest {np.max(moved_all):.3f} "
          f"(over {len(moved_all)} graded photos)")


if __name__ == "__main__":
    main()
