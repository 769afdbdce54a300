"""``wbcgrade report`` on a finished batch against the batch itself, and the batch's JPEGs.

A folder of photos (default: the shipped ``samples/*.jpg``; ``--megapixels N`` resizes
each to N megapixels, its shape kept; ``--long-side N`` to that long side) is graded
with ``wbcgrade batch IN -o OUT`` twice: ``--preset kodak-2383`` (the README's shoot)
and ``--style STYLES`` (the README's style folder: coffee, flower and sunset); then
``wbcgrade report OUT -o REPORT`` reads each batch's results (nothing graded again:
sheets and the look report from the photos and their graded copies). Each command is a
fresh process timed end to end (start-up included, the package's bytecode compiled
first, as an installed package runs), ``--repeats`` times; printed, one row a batch:
the median wall and CPU seconds (user + system) of the batch and of its report, and
the report's share of the batch (the issue's target: at most 1/5). Then the preset
batch's JPEGs against their inputs: the quality each was written at (read back from
its quantisation tables) and its size relative to the input's (target: within 15 %).

    python benchmarks/report.py                     # the samples, as the README grades them
    python benchmarks/report.py --megapixels 16     # the same photos at 16 megapixels
    python benchmarks/report.py --cases preset      # the preset batch only
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def timed(*args: str) -> tuple[float, float]:
    """(wall, CPU) seconds of ``python -m wbcgrade ARGS`` run to completion."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "wbcgrade", *args], capture_output=True,
                         text=True, env=ENV)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if run.returncode != 0:
        sys.exit(f"wbcgrade {' '.join(args)} failed (exit {run.returncode}):\n"
                 f"{run.stderr[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


#: The commands' environment (set in main): this checkout, its own caches and bytecode.
ENV: dict[str, str] = {}
#: The README's style folder (its `apply --style` example).
STYLES = ("coffee.jpg", "flower.jpg", "sunset.jpg")


def prepare(source: Path, folder: Path, long_side: int | None = None,
            megapixels: float | None = None) -> list[Path]:
    """The photos, copied (or resized to ``megapixels``, else to ``long_side``, saved at
    quality 92) into ``folder``."""
    from PIL import Image

    folder.mkdir(parents=True)
    photos = []
    for path in sorted(source.glob("*.jpg")):
        target = folder / path.name
        if long_side is None and megapixels is None:
            shutil.copyfile(path, target)
        else:
            with Image.open(path) as image:
                scale = (long_side / max(image.size) if megapixels is None
                         else (megapixels * 1e6 / (image.width * image.height)) ** 0.5)
                image.convert("RGB").resize((round(image.width * scale),
                                             round(image.height * scale)),
                                            Image.Resampling.LANCZOS).save(target, quality=92)
        photos.append(target)
    return photos


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--photos", type=Path, default=ROOT / "samples")
    parser.add_argument("--long-side", type=int, default=None)
    parser.add_argument("--megapixels", type=float, default=None)
    parser.add_argument("--preset", default="kodak-2383")
    parser.add_argument("--cases", nargs="+", choices=("preset", "style"),
                        default=["preset", "style"])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    from wbcgrade.color.io.images import jpeg_quality

    with tempfile.TemporaryDirectory(prefix="wbcgrade-report-bench-") as tmp:
        work = Path(tmp)
        photos = prepare(args.photos, work / "in", args.long_side, args.megapixels)
        styles = work / "styles"
        styles.mkdir()
        for name in STYLES:
            shutil.copyfile(work / "in" / name, styles / name)
        ENV.update({key: value for key, value in os.environ.items()
                    if key != "PYTHONDONTWRITEBYTECODE"})
        ENV.update(PYTHONPATH=str(ROOT), WBCGRADE_CACHE_DIR=str(work / "cache"),
                   PYTHONPYCACHEPREFIX=str(work / "bytecode"))
        subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "wbcgrade")],
                       env=ENV, check=True, stdout=subprocess.DEVNULL)
        grades = {"preset": ["--preset", args.preset], "style": ["--style", str(styles)]}
        size = ("as shipped" if args.long_side is None and args.megapixels is None else
                f"{args.megapixels:g} megapixels" if args.megapixels else
                f"long side {args.long_side}")
        print(f"{len(photos)} photos ({size}), {args.repeats} runs, medians; "
              f"report / batch: wall (each run), CPU")
        print(f"{'batch':<20} {'batch wall':>10} {'CPU':>6} {'report wall':>11} {'CPU':>6}  "
              f"report / batch")
        for case in args.cases:
            batch, report = [], []
            for _ in range(args.repeats):
                shutil.rmtree(work / case, ignore_errors=True)
                shutil.rmtree(work / f"{case}-report", ignore_errors=True)
                batch.append(timed("batch", str(work / "in"), "-o", str(work / case),
                                   *grades[case]))
                report.append(timed("report", str(work / case), "-o",
                                    str(work / f"{case}-report")))
            ratios = [r[0] / b[0] for b, r in zip(batch, report)]
            cpu = [r[1] / b[1] for b, r in zip(batch, report)]
            label = f"--preset {args.preset}" if case == "preset" else "--style (3 photos)"
            print(f"{label:<20} {statistics.median(w for w, _ in batch):10.2f} "
                  f"{statistics.median(c for _, c in batch):6.2f} "
                  f"{statistics.median(w for w, _ in report):11.2f} "
                  f"{statistics.median(c for _, c in report):6.2f}  "
                  f"wall {statistics.median(ratios):.2f} "
                  f"({', '.join(f'{r:.2f}' for r in ratios)}), "
                  f"CPU {statistics.median(cpu):.2f}")
        if "preset" not in args.cases:
            return
        print(f"\n{'photo':<16} {'quality in':>10} {'out':>5} {'size out/in':>12}")
        sizes = []
        for photo in photos:
            graded = work / "preset" / photo.name
            sizes.append(graded.stat().st_size / photo.stat().st_size)
            print(f"{photo.name:<16} {jpeg_quality(photo) or '-':>10} "
                  f"{jpeg_quality(graded) or '-':>5} {sizes[-1]:12.2f}")
        print(f"size out/in: {min(sizes):.2f}-{max(sizes):.2f}")


if __name__ == "__main__":
    main()
