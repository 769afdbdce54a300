"""Saved grades (``apply --look``) and JPEG quality: speed, sameness and file size.

For each photo: ``wbcgrade apply PHOTO --preset warm --mode palette`` (or
``--style`` with ten photos, ``--styles-from``), the original run: fit,
transport, map, regrain; it saves the grade with ``--save-grade`` (an unmeasured first run also
writes it as ``--lut .cube``). Then ``apply PHOTO --look grade.json`` and
``--look grade.cube`` (the saved grade again, no fit). Each command is a
fresh process timed end to end (start-up included, as a user sees it),
writing a JPEG; the sameness is measured on the same runs writing lossless 8-bit BMPs. Printed
per photo: the three times, the looks' time as a fraction of the original's
(the issue's target: below 1/4), the largest difference from the original
photo in 8-bit codes (target: at most 1), and the size of a JPEG written
with ``--quality 90`` relative to the input JPEG (target: within 10 %).

    python benchmarks/saved_look.py                      # the shipped samples/*.jpg
    python benchmarks/saved_look.py --photo ../shared/data/photos/seeding_full.jpg --repeats 3
    python benchmarks/saved_look.py --photo ../shared/data/photos/seeding_full.jpg \
        --styles-from ../shared/data/photos --repeats 3   # the 10-style grade of apply.py

``--mode`` is passed to the original run (default ``palette``: the fitted grade
the issue's quarter-of-the-time target is about). With ``--mode look`` and a
preset that carries its own look (the shipped presets do), the original run
fits nothing either: it is itself the application of a saved look, so the
``--look`` runs take about 0.8 of its time by construction (they save only
reading the preset, the photo's histograms and the own-style check; the read,
the remap, the regrain and the write are the same work); ``--mode palette
look`` prints both rows per photo.

Times are the shortest of ``--repeats`` runs, wall and CPU (user + system,
of the command's process): on a shared machine the CPU ratio is the steadier.
Quote ratios, not absolute seconds.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

ROOT = Path(__file__).resolve().parents[1]
SHARED_PHOTO = ROOT.parent / "shared" / "data" / "photos" / "seeding_full.jpg"


def wbcgrade(*args: str) -> list[str]:
    exe = shutil.which("wbcgrade", path=str(Path(sys.executable).parent)) or "wbcgrade"
    return [exe, *args]


#: CPU seconds (user + system) of the last command :func:`timed` ran.
LAST_CPU = [0.0]


def timed(command: list[str], stdout=None) -> float:
    """Wall seconds of a command (its CPU seconds in ``LAST_CPU[0]``)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=stdout or subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, env=dict(os.environ, TQDM_DISABLE="1"))
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    LAST_CPU[0] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall


def codes(path: Path) -> np.ndarray:
    return np.round(oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT) * 255.0)


def measure(photo: Path, folder: Path, styles: list[str], repeats: int = 1,
            mode: str = "palette") -> dict:
    """The three runs, interleaved ``repeats`` times (the shortest time of each), writing
    JPEGs as a user would; then, untimed, the same three writing 8-bit BMPs (lossless,
    so the comparison is not blurred by JPEG)."""
    out = folder / f"{photo.stem}-{mode}"
    out.mkdir()
    times: dict[str, list[float]] = {"original": [], "json": [], "cube": []}
    cpu: dict[str, list[float]] = {"original": [], "json": [], "cube": []}

    def original(suffix: str, *extra: str) -> float:
        return timed(wbcgrade("apply", str(photo), *styles, "--mode", mode, "-o",
                              str(out / f"original{suffix}"), "--save-grade",
                              str(out / "grade.json"), "--overwrite", *extra))

    def looked(kind: str, suffix: str, *extra: str) -> float:
        return timed(wbcgrade("apply", str(photo), "--look", str(out / f"grade.{kind}"),
                              "-o", str(out / f"{kind}{suffix}"), "--overwrite", *extra))

    # unmeasured: fills the style histogram cache (as a user's earlier runs have) and
    # writes the .cube (the timed runs save the grade with --save-grade only)
    original(".jpg", "--lut", str(out / "grade.cube"))
    for _ in range(repeats):
        times["original"].append(original(".jpg"))
        cpu["original"].append(LAST_CPU[0])
        for kind in ("json", "cube"):
            times[kind].append(looked(kind, ".jpg"))
            cpu[kind].append(LAST_CPU[0])
    row = {"photo": photo.name, "mode": mode, "original_s": min(times["original"]),
           **{f"{kind}_cpu": min(values) for kind, values in cpu.items()}}
    original(".bmp")
    for kind in ("json", "cube"):
        looked(kind, ".bmp")
        row[f"{kind}_s"] = min(times[kind])
        row[f"{kind}_max"] = float(np.abs(codes(out / f"{kind}.bmp")
                                          - codes(out / "original.bmp")).max())
    if photo.suffix.lower() in (".jpg", ".jpeg"):
        looked("cube", "_q90.jpg", "--quality", "90")
        row["q90_size"] = (out / "cube_q90.jpg").stat().st_size / photo.stat().st_size
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--photo", type=Path, action="append", default=None,
                        help="photo to measure (repeatable) [default: samples/*.jpg, and the "
                             "16 MP shared photo when it is there]")
    parser.add_argument("--preset", default="warm")
    parser.add_argument("--styles-from", type=Path, default=None, metavar="DIR",
                        help="grade with --style: N photos of DIR (not the photo itself), as "
                             "benchmarks/apply.py does, instead of --preset")
    parser.add_argument("--styles", type=int, default=10)
    parser.add_argument("--mode", nargs="+", choices=("palette", "look"), default=["palette"],
                        help="--mode of the original run (one row per photo and mode); "
                             "'look' with a preset that carries its own look is itself a "
                             "saved look applied, ratio ~0.8 by construction")
    parser.add_argument("--repeats", type=int, default=1,
                        help="runs of each command, interleaved; the shortest counts")
    args = parser.parse_args()
    photos = args.photo or sorted((ROOT / "samples").glob("*.jpg")) + (
        [SHARED_PHOTO] if SHARED_PHOTO.exists() else [])
    header = (f"{'photo':<22} {'mode':<7} {'original':>9} {'--look json':>12} {'--look cube':>12} "
              f"{'json/orig':>9} {'cube/orig':>9} {'CPU json/orig':>13} {'CPU cube/orig':>13} "
              f"{'max diff json':>13} {'max diff cube':>13} {'q90 size':>9}")
    print(header)
    print("-" * len(header))
    rows = []
    with tempfile.TemporaryDirectory(prefix="wbcgrade-bench-look-") as tmp:
        os.environ["WBCGRADE_CACHE_DIR"] = str(Path(tmp) / "cache")  # a private cache
        for photo, mode in ((photo, mode) for photo in photos for mode in args.mode):
            styles = ["--preset", args.preset]
            if args.styles_from is not None:
                from apply import style_folder  # benchmarks/apply.py's choice of styles

                folder = Path(tmp) / f"styles-{Path(photo).stem}-{mode}"
                folder.mkdir()
                style_folder(args.styles_from, Path(photo), args.styles, folder)
                styles = ["--style", str(folder)]
            row = measure(Path(photo), Path(tmp), styles, args.repeats, mode)
            rows.append(row)
            size = f"{row['q90_size']:.2f}" if "q90_size" in row else "-"
            print(f"{row['photo']:<22} {row['mode']:<7} {row['original_s']:8.2f}s "
                  f"{row['json_s']:11.2f}s "
                  f"{row['cube_s']:11.2f}s {row['json_s'] / row['original_s']:9.2f} "
                  f"{row['cube_s'] / row['original_s']:9.2f} "
                  f"{row['json_cpu'] / row['original_cpu']:13.2f} "
                  f"{row['cube_cpu'] / row['original_cpu']:13.2f} {row['json_max']:9.0f}/255 "
                  f"{row['cube_max']:9.0f}/255 {size:>9}", flush=True)
    # the target is about a fitted original; a --mode look original is a saved look itself
    fitted = [r for r in rows if r["mode"] == "palette"] or rows
    worst = max(max(r["json_s"], r["cube_s"]) / r["original_s"] for r in fitted)
    worst_cpu = max(max(r["json_cpu"], r["cube_cpu"]) / r["original_cpu"] for r in fitted)
    diff = max(max(r["json_max"], r["cube_max"]) for r in rows)
    sizes = [r["q90_size"] for r in rows if "q90_size" in r]
    print(f"\nworst look/original time ({fitted[0]['mode']} originals) {worst:.2f}, "
          f"CPU time {worst_cpu:.2f} (target < 0.25); "
          f"largest difference "
          f"{diff:.0f}/255 (target <= 1); --quality 90 size {min(sizes):.2f}-{max(sizes):.2f} "
          "of the input (target 0.90-1.10)")


if __name__ == "__main__":
    main()
