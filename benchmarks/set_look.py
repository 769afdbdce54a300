"""How long a new style folder's look takes: twelve style photos, nothing cached.

Run ``python benchmarks/set_look.py`` (``--help``). Writes twelve photos
(the benchmark photos beside a clone, else ``samples/``, repeated) into a
fresh folder as camera-sized JPEGs (``--megapixels``, default 16; 0: as they
are) and times, in a fresh cache folder, each stage of the first
``apply --style`` on it (median of ``--runs`` runs, each cold): reading the
style photos into histograms (and preparing them for scene matching from
the same decode, as ``apply`` does), the natural palettes' statistics (once
per cache folder; the second column has them cached, as every run after the
first on a machine does), the set's look itself, and the style photos'
scene images (read back, not decoded again); then, each in a fresh process
with an empty cache, the whole first ``wbcgrade apply --style`` on the folder
and the explorer's opening on it. Target: a new set's look in 5 s or less on
the project's 2-core machine.
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


def write_styles(files: list[Path], folder: Path, megapixels: float) -> None:
    """The style photos as a user's folder holds them: JPEGs of ``megapixels`` (0: copies)."""
    from PIL import Image

    folder.mkdir()
    for i, path in enumerate(files):
        target = folder / f"{i:02d}_{path.name}"
        if megapixels <= 0:
            shutil.copy(path, target)
            continue
        with Image.open(path) as image:
            scale = (megapixels * 1e6 / (image.width * image.height)) ** 0.5
            size = (round(image.width * scale), round(image.height * scale))
            image.convert("RGB").resize(size, Image.BICUBIC).save(target, quality=92)


def one_run(styles_dir: Path, warm_cache: Path | None) -> dict[str, float]:
    from wbcgrade.color.histogram import HistogramCache
    from wbcgrade.color.look import scene
    from wbcgrade.color.look import set_extraction as look
    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.presets import StyleSource, load_styles

    look._SET_LOOKS.clear()
    look._NATURAL_STATISTICS.clear()
    scene._IN_MEMORY.clear()
    with tempfile.TemporaryDirectory() as tmp:
        cache = warm_cache or Path(tmp) / "cache"
        fresh = Path(tmp) / "styles"  # a folder the cache has never seen
        shutil.copytree(styles_dir, fresh)
        times = {}
        start = time.perf_counter()
        source = StyleSource(str(fresh), None, HistogramCache(cache))
        styles = load_styles(source, 64, None, None, None,
                             scene.matching_hook(source, GradeOptions()))
        times["style histograms (and scene images)"] = time.perf_counter() - start
        start = time.perf_counter()
        naturals = look.natural_palettes()
        look.natural_statistics(naturals, styles)
        times["natural statistics"] = time.perf_counter() - start
        start = time.perf_counter()
        look.set_look_base(styles, naturals)
        times["set look"] = time.perf_counter() - start
        start = time.perf_counter()
        scene.style_scene_images(styles)
        times["style scene images, read back"] = time.perf_counter() - start
        times["total"] = sum(times.values())
        return times


def whole_commands(styles_dir: Path) -> dict[str, float]:
    """Wall time of the whole first ``wbcgrade apply --style`` on the folder and of the
    explorer's opening on it (its session and the look grade it opens on), each in a fresh
    process with an empty cache folder (imports included: what a user waits for)."""
    import os
    import subprocess

    photo = ROOT / "samples" / "chelsea.jpg"
    opening = ("from wbcgrade.explore.engine import load_session; import sys; "
               "load_session(sys.argv[1], style_dir=sys.argv[2]).look_grade()")
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, args in (
                ("first `apply --style` (command)",
                 ["-m", "wbcgrade", "apply", str(photo), "--style", str(styles_dir), "-o",
                  str(Path(tmp) / "out.jpg")]),
                ("explorer opening (session, look grade)",
                 ["-c", opening, str(photo), str(styles_dir)])):
            env = {**os.environ, "WBCGRADE_CACHE_DIR": str(Path(tmp) / name[:5])}
            start = time.perf_counter()
            subprocess.run([sys.executable, *args], check=True, env=env, cwd=ROOT,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            times[name] = time.perf_counter() - start
    return times


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--styles", type=int, default=12)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--megapixels", type=float, default=16.0,
                        help="size the style photos are written at (0: as they are)")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    with tempfile.TemporaryDirectory() as folder:
        styles_dir = Path(folder) / "styles"
        write_styles(style_photos(args.styles), styles_dir, args.megapixels)
        cold = [one_run(styles_dir, None) for _ in range(args.runs)]
        with tempfile.TemporaryDirectory() as tmp:
            one_run(styles_dir, Path(tmp))  # fills the natural statistics' cache
            warm = [one_run(styles_dir, Path(tmp)) for _ in range(args.runs)]
        whole = [whole_commands(styles_dir) for _ in range(args.runs)]
    size = f"{args.megapixels:g}-megapixel JPEGs" if args.megapixels > 0 else "as they are"
    print(f"\n{args.styles} style photos ({size}), median of {args.runs} runs (seconds)")
    print("| stage | cold (nothing cached) | natural statistics cached |")
    print("|---|---|---|")
    for stage in cold[0]:
        print(f"| {stage} | {np.median([r[stage] for r in cold]):.2f} | "
              f"{np.median([r[stage] for r in warm]):.2f} |")
    for stage in whole[0]:
        print(f"| {stage} | {np.median([r[stage] for r in whole]):.2f} | - |")


if __name__ == "__main__":
    main()
