"""Issue 45's table in one command: how soon each command answers, beside its goal.

    python benchmarks/speed.py                  # every row, one run each
    python benchmarks/speed.py --only palette   # rows whose label contains TEXT
    python benchmarks/speed.py --finite-128     # also: the core gradient at 128³ is finite
    python benchmarks/speed.py --repeats 3      # the warm rows: medians of 3 (a loaded machine)

Every command runs in a fresh interpreter, as the ``wbcgrade`` script does, and is
timed end to end (start-up included). Rows:

- a mistake answered (``apply missing.jpg --preset warm``), beyond Python's own start;
- the README's first grade (``apply samples/chelsea.jpg --preset warm``) with empty
  caches (numba's and wbcgrade's), then the same grade again;
- the paper's palette grade: ``apply samples/sunset.jpg --preset warm --mode palette``
  (six style palettes, 128³, 0.70 MP), first with empty caches (numba compiles its
  kernels, as after an install), then again, saving its grade with ``--save-grade``;
  then that saved grade (``--look grade.json``, no fit) and its share of the fit's time;
- 16 MP, ten styles, histograms cached: ``apply seeding_full.jpg --style DIR`` (the ten
  style photos ``benchmarks/apply.py`` takes), after one unmeasured run;
- ``look learn``, twelve pairs, four of them cropped JPEG exports: the photos of
  ``shared/data/photos`` with the Fuji Velvia Hald CLUT applied (``benchmarks/learn.py``'s
  helpers);
- the core gradient at 64³, S = 10, L = 60 (``benchmarks/core.py``'s blobs, float64:
  the precision these scalings need; they span 1e-52..1e43).

The machine is shared: the load average before and after is printed, and each row's CPU
seconds (user + system, every thread of the command) beside its wall time; quote ratios.
The package's bytecode is compiled first (as an install does), so that no row pays for
compiling modules changed since their ``.pyc`` (``PYTHONDONTWRITEBYTECODE``).
"""

from __future__ import annotations

import argparse
import compileall
import json
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
#: the development data: ``shared/data`` in the checkout or in a folder above it (a
#: worktree beside or below the shared folder)
SHARED = next((folder / "shared" / "data" for folder in (ROOT, *ROOT.parents)
               if (folder / "shared" / "data").is_dir()), ROOT / "shared" / "data")
PHOTOS = SHARED / "photos"
SAMPLES = ROOT / "samples"
_RUN = "import sys; from wbcgrade.cli import main; sys.argv[0] = 'wbcgrade'; main()"


#: CPU seconds (user + system, all threads) of the last command :func:`timed` ran: the
#: steadier figure on a shared machine.
LAST_CPU = [0.0]


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(args: list[str], env: dict[str, str], expect_ok: bool = True) -> tuple[float, str]:
    """(wall seconds, stdout) of ``wbcgrade ARGS`` in a fresh interpreter (its CPU seconds
    in ``LAST_CPU[0]``)."""
    start, cpu = time.perf_counter(), _children_cpu()
    done = subprocess.run([sys.executable, "-c", _RUN, *args], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    seconds = time.perf_counter() - start
    LAST_CPU[0] = _children_cpu() - cpu
    if (done.returncode == 0) != expect_ok:
        raise SystemExit(f"wbcgrade {' '.join(args)} exited {done.returncode}:\n"
                         f"{done.stdout[-2000:]}{done.stderr[-2000:]}")
    return seconds, done.stdout


#: Runs of each warm row (``--repeats``): the row shows the median wall and CPU seconds.
REPEATS = [1]


def repeated(args: list[str], env: dict[str, str]) -> tuple[float, str]:
    """:func:`timed` ``REPEATS[0]`` times: (median wall seconds, the last stdout); the
    median CPU seconds in ``LAST_CPU[0]``."""
    walls, cpus, out = [], [], ""
    for _ in range(REPEATS[0]):
        seconds, out = timed(args, env)
        walls.append(seconds)
        cpus.append(LAST_CPU[0])
    LAST_CPU[0] = statistics.median(cpus)
    return statistics.median(walls), out


def python_start(env: dict[str, str]) -> float:
    times = []
    for _ in range(3):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], env=env, check=True)
        times.append(time.perf_counter() - start)
    return sorted(times)[1]


def learn_pairs(folder: Path, count: int = 12, cropped: int = 4) -> tuple[Path, Path]:
    """BEFORE and AFTER folders: ``count`` photos and their Velvia look; ``cropped`` of the
    afters resized to 60 %, cropped and written as JPEG exports."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from learn import apply_hald, hald_table, resized_cropped, to_8bit, write_8bit

    from wbcgrade.color.io.images import read_image

    table = hald_table(SHARED / "looks" / "fuji_velvia_50.png")
    names = sorted(p.stem for p in PHOTOS.glob("*.jpg") if p.stem != "seeding_full")[:count]
    before, after = folder / "before", folder / "after"
    before.mkdir()
    after.mkdir()
    for number, name in enumerate(names):
        rgb = read_image(PHOTOS / f"{name}.jpg").pixels[..., :3].astype("float64")
        write_8bit(before / f"{name}.png", rgb)
        looked = to_8bit(apply_hald(table, rgb))
        if number < cropped:
            import cv2
            import numpy as np

            small = np.round(np.clip(resized_cropped(looked), 0, 1) * 255).astype(np.uint8)
            cv2.imwrite(str(after / f"{name}.jpg"), small[..., ::-1],
                        [cv2.IMWRITE_JPEG_QUALITY, 92])
        else:
            write_8bit(after / f"{name}.png", looked)
    return before, after


def core_gradient(n: int) -> tuple[float, str]:
    """(seconds, backend) of one core gradient, S = 10, L = 60, blobs, float64: the median
    of ``REPEATS[0]`` processes (their median CPU seconds in ``LAST_CPU[0]``)."""
    walls, cpus, backend = [], [], ""
    for _ in range(REPEATS[0]):
        cpu = _children_cpu()
        done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "core.py"),
                               "--worker", "gradient", str(n), "--repeats", "1"],
                              capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep
                                   + os.environ.get("PYTHONPATH", "")})
        cpus.append(_children_cpu() - cpu)
        if done.returncode != 0:
            LAST_CPU[0] = cpus[-1]
            return float("nan"), (done.stderr.strip().splitlines() or ["failed"])[-1]
        result = json.loads(done.stdout.strip().splitlines()[-1])
        walls.append(result["median_s"])
        backend = result["backend"]
    LAST_CPU[0] = statistics.median(cpus)
    return statistics.median(walls), backend + ", gradient finite"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="rows whose label contains this text")
    parser.add_argument("--finite-128", action="store_true",
                        help="also run the core gradient at 128³ (minutes) and check it")
    parser.add_argument("--repeats", type=int, default=1,
                        help="runs of each warm row (medians; the empty-cache rows run once)")
    ns = parser.parse_args()
    REPEATS[0] = max(1, ns.repeats)
    rows: list[tuple[str, ...]] = []

    def row(label: str, seconds: float, goal: str, notes: str = "") -> None:
        rows.append((label, f"{seconds:.2f}", f"{LAST_CPU[0]:.2f}", goal, notes))
        print(f"  {label}: {seconds:.2f} s (CPU {LAST_CPU[0]:.2f} s) {notes}", flush=True)

    def wanted(label: str) -> bool:
        return ns.only.lower() in label.lower()

    # the package's bytecode, as an install writes it: with PYTHONDONTWRITEBYTECODE set (as on
    # the development machine), stale .pyc files would make every command compile the
    # modules changed since (0.1-0.3 s), which no installed wbcgrade does
    compileall.compile_dir(str(ROOT / "wbcgrade"), quiet=1)
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    with tempfile.TemporaryDirectory(prefix="wbcgrade-speed-") as tmp:
        tmp = Path(tmp)
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp / "numba"),
               "WBCGRADE_CACHE_DIR": str(tmp / "cache"), "TQDM_DISABLE": "1",
               "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT),
                                                           os.environ.get("PYTHONPATH")]))}
        if wanted("mistake"):
            bare = python_start(env)
            seconds, _ = timed(["apply", str(tmp / "missing.jpg"), "--preset", "warm"], env,
                               expect_ok=False)
            row("a mistake answered, beyond Python's start", seconds - bare, "<= 0.4 (0.15)",
                f"(Python's start {bare:.2f} s)")
        readme = ["apply", str(SAMPLES / "chelsea.jpg"), "--preset", "warm", "-o",
                  str(tmp / "chelsea.jpg"), "--overwrite"]
        if wanted("readme"):
            row("the README's first grade, empty caches", timed(readme, env)[0], "<= 3")
            row("the README's grade again", repeated(readme, env)[0], "<= 1.5")
        grade = tmp / "grade.json"
        fit_seconds = None
        if wanted("palette") or wanted("saved"):
            palette = ["apply", str(SAMPLES / "sunset.jpg"), "--preset", "warm", "--mode",
                       "palette", "-o", str(tmp / "palette.jpg"), "--overwrite"]
            env = {**env, "NUMBA_CACHE_DIR": str(tmp / "numba-palette")}
            if wanted("palette"):  # numba's kernels compiled by this run (as after install)
                seconds, _ = timed(palette, {**env, "WBCGRADE_CACHE_DIR": str(tmp / "new")})
                row("palette grade, first run (empty caches)", seconds, "-")
            else:  # compile the kernels (a photo this size runs the compiled remap)
                timed([*palette, "--bins", "32"], env)
            fit_seconds, _ = repeated([*palette, "--save-grade", str(grade)], env)
            row("palette grade (128³, six styles), 0.70 MP", fit_seconds, "<= 10")
        if wanted("saved") and fit_seconds:
            seconds, _ = repeated(["apply", str(SAMPLES / "sunset.jpg"), "--look", str(grade),
                                   "-o", str(tmp / "saved.jpg"), "--overwrite"], env)
            row("a saved grade (--look grade.json)", seconds, "<= 1.5, <= 1/4 of the fit",
                f"({seconds / fit_seconds:.2f} of the fit)")
        if wanted("16 MP"):
            styles = tmp / "styles"
            styles.mkdir()
            for path in sorted(p for p in PHOTOS.glob("*.jpg")
                               if not p.stem.startswith("seeding"))[:10]:
                (styles / path.name).symlink_to(path)
            args = ["apply", str(PHOTOS / "seeding_full.jpg"), "--style", str(styles),
                    "-o", str(tmp / "full.jpg"), "--overwrite", "--json"]
            timed(args, env)  # fills the histogram cache
            seconds, out = repeated(args, env)
            timings = json.loads(out)["timings_s"]
            stages = ", ".join(f"{k} {v:.2f}" for k, v in timings.items()
                               if k != "total" and v >= 0.05)
            row("16 MP, ten styles, cached", seconds, "<= 1.5", f"({stages})")
        if wanted("look learn"):
            before, after = learn_pairs(tmp)
            seconds, _ = repeated(["look", "learn", str(before), str(after), "-o",
                                   str(tmp / "look.cube"), "--overwrite"], env)
            row("look learn, twelve pairs (four cropped JPEGs)", seconds, "<= 10")
            shutil.rmtree(before)
            shutil.rmtree(after)
        if wanted("core gradient"):
            seconds, notes = core_gradient(64)
            row("core gradient, 64³, S = 10, L = 60", seconds, "<= 7.8 (torch, float32)",
                f"({notes})")
            if ns.finite_128:
                seconds, notes = core_gradient(128)
                row("core gradient, 128³ (finite)", seconds, "finite", f"({notes})")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print()
    header = ("row", "wall s", "CPU s", "goal (wall s)", "notes")
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    print("  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip())
    print("-" * (sum(widths) + 6))
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip())


if __name__ == "__main__":
    main()
