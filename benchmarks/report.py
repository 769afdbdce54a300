"""``wbcgrade report`` on a finished batch against the batch itself, and the batch's JPEGs.

A folder of photos (default: the shipped ``samples/*.jpg``; ``--long-side N`` resizes
them, e.g. 4900 for 16-megapixel photos) is graded with ``wbcgrade batch IN -o OUT
--preset kodak-2383`` (the README's shoot), then ``wbcgrade report OUT -o REPORT`` reads
the batch's results (nothing graded again: sheets and the look report from the photos and
their graded copies). Each command is a fresh process timed end to end (start-up
included), ``--repeats`` times; printed: the median wall and CPU seconds (user + system)
of each, and the report's share of the batch (the issue's target: at most 1/5). Then the
graded JPEGs against their inputs: the quality each was written at (read back from its
quantisation tables) and its size relative to the input's (target: within 15 %).

    python benchmarks/report.py                     # the samples, as the README grades them
    python benchmarks/report.py --long-side 4900    # the same photos at 16 megapixels
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
                         text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if run.returncode != 0:
        sys.exit(f"wbcgrade {' '.join(args)} failed:\n{run.stderr[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def prepare(source: Path, folder: Path, long_side: int | None) -> list[Path]:
    """The photos, copied (or resized to ``long_side``, saved at quality 92) into
    ``folder``."""
    from PIL import Image

    folder.mkdir(parents=True)
    photos = []
    for path in sorted(source.glob("*.jpg")):
        target = folder / path.name
        if long_side is None:
            shutil.copyfile(path, target)
        else:
            with Image.open(path) as image:
                scale = long_side / max(image.size)
                image.convert("RGB").resize((round(image.width * scale),
                                             round(image.height * scale)),
                                            Image.Resampling.LANCZOS).save(target, quality=92)
        photos.append(target)
    return photos


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--photos", type=Path, default=ROOT / "samples")
    parser.add_argument("--long-side", type=int, default=None)
    parser.add_argument("--preset", default="kodak-2383")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    from wbcgrade.color.io.images import jpeg_quality

    with tempfile.TemporaryDirectory(prefix="wbcgrade-report-bench-") as tmp:
        work = Path(tmp)
        photos = prepare(args.photos, work / "in", args.long_side)
        cache = {"WBCGRADE_CACHE_DIR": str(work / "cache")}
        os.environ.update(cache)
        batch, report = [], []
        for _ in range(args.repeats):
            shutil.rmtree(work / "out", ignore_errors=True)
            shutil.rmtree(work / "report", ignore_errors=True)
            batch.append(timed("batch", str(work / "in"), "-o", str(work / "out"),
                               "--preset", args.preset))
            report.append(timed("report", str(work / "out"), "-o", str(work / "report")))
        size = "as shipped" if args.long_side is None else f"long side {args.long_side}"
        print(f"{len(photos)} photos ({size}), batch --preset {args.preset}, "
              f"{args.repeats} runs, medians")
        print(f"{'command':<10} {'wall s':>7} {'CPU s':>7}")
        for name, runs in (("batch", batch), ("report", report)):
            print(f"{name:<10} {statistics.median(w for w, _ in runs):7.2f} "
                  f"{statistics.median(c for _, c in runs):7.2f}")
        ratios = [r[0] / b[0] for b, r in zip(batch, report)]
        cpu = [r[1] / b[1] for b, r in zip(batch, report)]
        print(f"report / batch: wall {statistics.median(ratios):.2f} "
              f"(runs {', '.join(f'{r:.2f}' for r in ratios)}), CPU {statistics.median(cpu):.2f}")
        print(f"\n{'photo':<16} {'quality in':>10} {'out':>5} {'size out/in':>12}")
        sizes = []
        for photo in photos:
            graded = work / "out" / photo.name
            sizes.append(graded.stat().st_size / photo.stat().st_size)
            print(f"{photo.name:<16} {jpeg_quality(photo) or '-':>10} "
                  f"{jpeg_quality(graded) or '-':>5} {sizes[-1]:12.2f}")
        print(f"size out/in: {min(sizes):.2f}-{max(sizes):.2f}")


if __name__ == "__main__":
    main()
