"""Set looks in the generator's own world: how much of a look can S style photos show?

Run ``python benchmarks/set_simulation.py`` (``--help``; about five minutes). No photo
and no benchmark look is used: every set is made of the shipped natural palettes
(``wbcgrade/color/data/natural.npz``) pushed through a random edit of the generator
the set look's prior is learned from (``wbcgrade.color.look.edits.random_edit``;
one set in seven has no edit). Each set's look is found as ``apply --style`` finds
it (``statistics_set_look``) and judged on three other palettes' colours
(16^3 bins, mass-weighted): recovered = 1 - dE2000(look, edit) / dE2000(colours, edit)
where the edit moves them by over 1 dE, else how far the look moves them. A quarter
of the natural palettes (drawn once) makes the sets and the judged palettes; the
rest is the content model they are judged against, as the shipped palettes are for
a user's photos.

Since the prior was learned from this generator and these palettes, this is the
estimate's best case: what is not recovered here is not in the statistics of S
photos. A second kind of set has no look but shares its content: a palette and its
``S - 1`` nearest neighbours in the look statistics (three similar wallpapers, three
clip-art objects on white), the hardest "no look" there is.

Prints, per set size: looks (mean, 5th percentile and worst recovered), sets without
a look (mean and largest move, random and similar content) and the reported share
against the recovered fraction.

``--ceilings`` adds, per set size and per how far the edit moves the held-out palettes
(1-3, 3-6, over 6 dE2000), the look recovered by three estimates from the same sets:
the shipped one; the posterior mean applied in full (no jackknife share: the Bayes
estimate, best where its prior and noise are right, as they are here); and the
statistics measured against the style palettes' own statistics before the edit
(content cancelled: what the look's family could show with no content noise at all).
``--edit-sizes LO,HI`` draws the edits' overall size log-uniformly from LO to HI
(default the generator's own, 0.15 to 1.5; ``0.6,1.5`` keeps to strong looks).
"""

from __future__ import annotations

import argparse
import contextlib
import sys

import colour
import numpy as np
from tqdm import tqdm

from wbcgrade.color.histogram import resample_histogram
from wbcgrade.color.look import set_extraction as se
from wbcgrade.color.look.edits import random_edit
from wbcgrade.color.look.prior import push_edit
from wbcgrade.color.look.statistics import (
    look_differences,
    look_from_differences,
    tinted_statistics,
)
from wbcgrade.color.presets import StyleSet

#: Held-out palettes a set's look is judged on, and their grid.
EVALUATED = 3
EVALUATION_BINS = 16
#: Share of the random sets that have no edit at all.
NO_EDIT = 1.0 / 7.0
#: An edit moving the held-out colours less than this (mean dE2000) counts as no look.
LOOK_SIZE = 1.0


def _lab(rgb: np.ndarray) -> np.ndarray:
    return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(np.clip(rgb, 0.0, 1.0)))


def _delta_e(a: np.ndarray, b: np.ndarray, weights: np.ndarray) -> float:
    return float(weights @ colour.delta_E(a, b, method="CIE 2000"))


def _judge(look, edit, palettes: np.ndarray) -> list[tuple[float, float, float]]:
    """[(edit's move, error, look's move) in mean dE2000] on each held-out palette."""
    rows = []
    for hist in palettes:
        colors, masses = se._histogram_colors(resample_histogram(hist, EVALUATION_BINS))
        weights = masses / masses.sum()
        before, truth, found = _lab(colors), _lab(edit(colors)), _lab(look(colors))
        rows.append((_delta_e(before, truth, weights), _delta_e(found, truth, weights),
                     _delta_e(found, before, weights)))
    return rows


def _set_look(content: StyleSet, hists: np.ndarray):
    """The set look of ``hists`` (S, 32, 32, 32) against the ``content`` palettes."""
    styles = StyleSet([f"style{i}" for i in range(len(hists))], hists, "simulation",
                      meta={"cache_dir": None, "working_space": content.working_space})
    return se.statistics_set_look(styles, content)


#: The estimates ``--ceilings`` compares (see the module's docstring).
ESTIMATES = ("shipped", "posterior in full", "content cancelled")
#: Bands of how far an edit moves a held-out palette (mean dE2000), for ``--ceilings``.
MOVE_BANDS = ((1.0, 3.0), (3.0, 6.0), (6.0, np.inf))


@contextlib.contextmanager
def _estimate(kind: str, before: StyleSet | None = None):
    """The set look found as ``kind`` (:data:`ESTIMATES`) while the block runs: the
    posterior's jackknife share left out, or the styles' statistics measured against
    ``before``'s (the same palettes before the edit) instead of the natural palettes'."""
    shipped = se.posterior_statistics_look

    def in_full(*args, **kwargs):
        return shipped(*args, **{**kwargs, "jackknife_colors": None})

    def cancelled(styles, naturals, *args, **kwargs):
        centre = tinted_statistics(before.at_bins(se.MAP_BINS), naturals)
        return look_from_differences(look_differences(styles, centre))

    se.posterior_statistics_look = {"shipped": shipped, "posterior in full": in_full,
                                    "content cancelled": cancelled}[kind]
    try:
        yield
    finally:
        se.posterior_statistics_look = shipped


def _ceiling_table(sizes: list[int], rows: list[tuple]) -> None:
    """Print the looks recovered by each estimate, per set size and band of the move."""
    print("\nLooks recovered by how far the edit moves a held-out palette: the shipped "
          "estimate, the posterior in full, the content cancelled")
    print("| S | move dE | held-out palettes | " + " | ".join(ESTIMATES) + " |")
    print("|---|---|---|" + "---|" * len(ESTIMATES))
    table = np.array(rows)  # (size, move, recovered per estimate ...)
    for size in sizes:
        for lo, hi in MOVE_BANDS:
            pick = (table[:, 0] == size) & (table[:, 1] >= lo) & (table[:, 1] < hi)
            if pick.any():
                band = f"{lo:.0f}-{hi:.0f}" if np.isfinite(hi) else f"over {lo:.0f}"
                values = " | ".join(f"{v:+.3f}" for v in table[pick, 2:].mean(axis=0))
                print(f"| {size} | {band} | {int(pick.sum())} | {values} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="3,6,12", help="style photos per set")
    parser.add_argument("--trials", type=int, default=60, help="random sets per size")
    parser.add_argument("--similar", type=int, default=15,
                        help="sets of similar content without a look, per size")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--ceilings", action="store_true",
                        help="also the posterior in full and the content cancelled, by move")
    parser.add_argument("--edit-sizes", default=None, metavar="LO,HI",
                        help="the edits' overall size, log-uniform (default 0.15,1.5)")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    span = None if args.edit_sizes is None else np.log([float(v) for v in
                                                        args.edit_sizes.split(",")])
    naturals = se.natural_palettes()
    rng = np.random.default_rng(args.seed)
    drawn = rng.permutation(len(naturals.names))
    count = len(drawn) // 4  # the palettes sets are made of; the rest is the content model
    content = naturals.subset(np.sort(drawn[count:]))
    content.meta["cache_dir"] = None
    hists = naturals.at_bins(32, only=drawn[:count])
    statistics = se.natural_statistics(content, None)
    vectors = np.stack([look_differences(
        se.palette_statistics(hists[i:i + 1]), statistics, min_styles=1).vector()
        for i in range(count)])
    vectors /= vectors.std(axis=0) + 1e-12
    looks, random_null, similar_null = [], [], []  # (size, share, rows)
    ceilings = []  # (size, move, recovered by each of ESTIMATES)
    bar = tqdm(total=len(sizes) * (args.trials + args.similar), desc="sets", file=sys.stderr)
    for size in sizes:
        for _ in range(args.trials):
            edit = (lambda x: np.asarray(x, dtype=np.float64)) if rng.random() < NO_EDIT \
                else random_edit(rng, None if span is None else float(np.exp(rng.uniform(*span))))
            picked = rng.choice(count, size + EVALUATED, replace=False)
            styles, held = picked[:size], picked[size:]
            pushed = np.stack([push_edit(hists[i], edit) for i in styles])
            result = _set_look(content, pushed)
            judged = _judge(result.look, edit, hists[held])
            for moved, error, found in judged:
                if moved > LOOK_SIZE:
                    looks.append((size, result.share, 1.0 - error / moved))
                elif moved < 0.3:
                    random_null.append((size, found))
            if args.ceilings and any(moved > LOOK_SIZE for moved, _, _ in judged):
                before = StyleSet([f"style{i}" for i in range(size)], hists[styles], "before",
                                  meta={"cache_dir": None,
                                        "working_space": content.working_space})
                others = []
                for kind in ESTIMATES[1:]:
                    with _estimate(kind, before):
                        others.append(_judge(_set_look(content, pushed).look, edit,
                                             hists[held]))
                for (moved, error, _), *rest in zip(judged, *others):
                    if moved > LOOK_SIZE:
                        ceilings.append((size, moved, 1.0 - error / moved,
                                         *(1.0 - e / moved for _, e, _ in rest)))
            bar.update(1)
        for _ in range(args.similar):
            anchor = rng.integers(count)
            styles = np.argsort(np.sum((vectors - vectors[anchor]) ** 2, axis=1))[:size]
            held = rng.choice(np.setdiff1d(np.arange(count), styles), EVALUATED, replace=False)
            result = _set_look(content, hists[styles])
            similar_null += [(size, found) for _, _, found in
                             _judge(result.look, lambda x: x, hists[held])]
            bar.update(1)
    bar.close()
    print(f"\nSet looks in the generator's world: {args.trials} random sets a size "
          f"({NO_EDIT:.0%} without an edit), {args.similar} sets of similar content")
    print("| S | looks: held-out palettes | recovered mean | 5th pct | worst "
          "| no look, random: mean / largest move dE | similar content: mean / largest dE"
          " / over 1.5 |")
    print("|---|---|---|---|---|---|---|")
    for size in sizes:
        rec = np.array([r for s, _, r in looks if s == size])
        null = np.array([m for s, m in random_null if s == size] or [0.0])
        similar = np.array([m for s, m in similar_null if s == size] or [0.0])
        print(f"| {size} | {len(rec)} | {rec.mean():+.3f} | {np.percentile(rec, 5):+.2f} | "
              f"{rec.min():+.2f} | {null.mean():.2f} / {null.max():.2f} | "
              f"{similar.mean():.2f} / {similar.max():.2f} / {np.mean(similar > 1.5):.0%} |")
    print("\nCalibration (every look): reported share against recovered")
    print("| share | held-out palettes | mean recovered |")
    print("|---|---|---|")
    edges = [0.0, 0.05, 0.1, 0.3, 0.5, 0.7, 1.01]
    for lo, hi in zip(edges[:-1], edges[1:]):
        v = [r for _, share, r in looks if lo <= share < hi]
        if v:
            print(f"| {lo:.2f}-{min(hi, 1.0):.2f} | {len(v)} | {np.mean(v):+.3f} |")
    if ceilings:
        _ceiling_table(sizes, ceilings)


if __name__ == "__main__":
    main()
