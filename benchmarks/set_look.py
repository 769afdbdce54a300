"""How long a new style folder's look takes: twelve style photos, nothing cached.

Run ``python benchmarks/set_look.py`` (``--help``). Copies twelve photos
(the benchmark photos beside a clone, else ``samples/``, repeated) into a
fresh folder and times, in a fresh cache folder, each stage of the first
``apply --style`` on it (median of ``--runs`` runs, each cold): reading the
style photos into histograms, the natural palettes' statistics (once per
cache folder; the ``warm`` row has them cached, as every run after the
first on a machine does) and the set's look itself. Target: a new set's
look in 5 s or less on the project's 2-core machine.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PHOTOS = ROOT.parent / "shared" / "data" / "photos"


def style_photos(count: int) -> list[Path]:
    folder = PHOTOS if PHOTOS.is_dir() else ROOT / "samples"
    found = sorted(p for p in folder.glob("*.jpg") if "full" not in p.stem)
    if not found:
        raise SystemExit(f"no photos in {folder}")
    return [found[i % len(found)] for i in range(count)]


def one_run(files: list[Path], warm_cache: Path | None) -> dict[str, float]:
    from wbcgrade.color.histogram import HistogramCache
    from wbcgrade.color.look import set_extraction as look
    from wbcgrade.color.presets import load_style_folder

    look._SET_LOOKS.clear()
    look._NATURAL_STATISTICS.clear()
    with tempfile.TemporaryDirectory() as tmp:
        styles_dir = Path(tmp) / "styles"
        styles_dir.mkdir()
        for i, path in enumerate(files):
            shutil.copy(path, styles_dir / f"{i:02d}_{path.name}")
        cache = warm_cache or Path(tmp) / "cache"
        times = {}
        start = time.perf_counter()
        styles = load_style_folder(styles_dir, 64, cache=HistogramCache(cache / "hist"))
        styles.meta["cache_dir"] = str(cache)
        times["style histograms"] = time.perf_counter() - start
        start = time.perf_counter()
        naturals = look.natural_palettes()
        look._natural_statistics(naturals, styles)
        times["natural statistics"] = time.perf_counter() - start
        start = time.perf_counter()
        look.set_look_base(styles, naturals)
        times["set look"] = time.perf_counter() - start
        times["total"] = sum(times.values())
        return times


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--styles", type=int, default=12)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    files = style_photos(args.styles)
    cold = [one_run(files, None) for _ in range(args.runs)]
    with tempfile.TemporaryDirectory() as tmp:
        one_run(files, Path(tmp))  # fills the natural statistics' cache
        warm = [one_run(files, Path(tmp)) for _ in range(args.runs)]
    print(f"\n{args.styles} style photos, median of {args.runs} runs (seconds)")
    print("| stage | cold (nothing cached) | natural statistics cached |")
    print("|---|---|---|")
    for stage in cold[0]:
        print(f"| {stage} | {np.median([r[stage] for r in cold]):.2f} | "
              f"{np.median([r[stage] for r in warm]):.2f} |")


if __name__ == "__main__":
    main()
