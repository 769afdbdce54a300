"""Core benchmark: kernel product, forward barycenter, gradient and fit on 3-D grids.

Run ``python benchmarks/core.py`` (options: ``--help``). Every case runs in a
fresh subprocess so that its peak resident memory (``ru_maxrss``) is its own;
the table shows the median wall time over the repeats and that peak.

Data (``--data``): ``blobs``, S smooth synthetic histograms on an n^3 grid
(each a mixture of three Gaussian blobs plus a small floor), which the plain
scaling path handles; ``photos``, colour histograms of the sample photos
(``shared/data/photos/*.jpg`` in name order: the first is the target, the next
S the inputs; ``wbcgrade.color.histogram.image_histogram`` at n bins), sparse
and far apart, which need the exact log domain. Kernel 1.5 bins wide, float64,
L unrolled iterations. "above inputs" is the peak resident memory minus what
the process held once its histograms were loaded.
The log domain's time budget is lifted for these runs
(``WBCGRADE_LOG_DOMAIN_BUDGET_S=inf``) so that they measure instead of refusing.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CASES = ("kernel", "forward", "gradient", "fit")
DATA = ("blobs", "photos")
PHOTOS = Path(__file__).resolve().parents[1] / "shared" / "data" / "photos"
if not PHOTOS.is_dir():  # a worktree beside the shared folder
    PHOTOS = Path(__file__).resolve().parents[2] / "shared" / "data" / "photos"


def make_histograms(n: int, count: int, seed: int = 0) -> np.ndarray:
    """``count`` mixtures of three Gaussian blobs on an n^3 grid, each summing to 1."""
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 1.0, n)
    out = np.empty((count, n, n, n))
    for s in range(count):
        h = np.zeros((n, n, n))
        for _ in range(3):
            c = rng.uniform(0.15, 0.85, 3)
            sd = rng.uniform(0.05, 0.15)
            gx, gy, gz = (np.exp(-((x - ci) ** 2) / (2 * sd**2)) for ci in c)
            h += rng.uniform(0.5, 1.0) * gx[:, None, None] * gy[None, :, None] * gz[None, None, :]
        h /= h.sum()
        h += 1e-6 / h.size
        out[s] = h / h.sum()
    return out


def photo_histograms(n: int, count: int, path: str) -> None:
    """Histograms of the first ``count`` sample photos at n bins, saved to ``path`` (.npy)."""
    from wbcgrade.color.histogram import image_histogram
    from wbcgrade.color.io.images import read_image

    files = sorted(glob.glob(str(PHOTOS / "*.jpg")))[:count]
    if len(files) < count:
        raise SystemExit(f"{count} photos needed in {PHOTOS}, found {len(files)}")
    np.save(path, np.stack([image_histogram(read_image(f).pixels[..., :3], n) for f in files]))


def worker(case: str, n: int, styles: int, iterations: int, repeats: int,
           data: str = "blobs", histograms: str = "") -> dict:
    from wbcgrade.core import (
        BarycenterSolver,
        GridGeometry,
        barycentric_coordinates,
    )

    geom = GridGeometry.with_width((n, n, n), 1.5)
    H = np.load(histograms) if data == "photos" else make_histograms(n, styles + 1)
    target, H = H[0], H[1:]
    inputs_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    weights = np.random.default_rng(1).dirichlet(np.ones(styles))
    solver = BarycenterSolver(H, geom, iterations)
    extra: dict = {}

    if case == "kernel":
        def run():
            geom.apply(solver.H)
    elif case == "forward":
        def run():
            solver.barycenter(weights)
    elif case == "gradient":
        def run():
            value, grad, _ = solver.value_and_grad(weights, target)
            if not np.all(np.isfinite(grad)):
                raise SystemExit("gradient is not finite")
    else:
        def run():
            fit = barycentric_coordinates(target, H, geom, n_iter=iterations)
            extra.update(evaluations=fit.n_evaluations, loss_drop=fit.initial_loss / fit.loss,
                         fit_backend=fit.backend)

    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {
        "median_s": statistics.median(times),
        "times_s": times,
        "peak_rss_mb": peak,
        "above_inputs_mb": peak - inputs_rss,
        "backend": extra.pop("fit_backend", solver.last_backend),
        **extra,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="32,64,128", help="grid sizes n (n^3 bins)")
    parser.add_argument("--cases", default=",".join(CASES), help="which cases to run")
    parser.add_argument(
        "--fit-sizes", default="32",
        help="sizes at which the full fit runs (64^3: ~30 gradients; 128^3: hours)",
    )
    parser.add_argument("--styles", type=int, default=10, help="number of histograms S")
    parser.add_argument("--iterations", type=int, default=60, help="barycenter iterations L")
    parser.add_argument("--repeats", type=int, default=3, help="repeats of the fast cases")
    parser.add_argument(
        "--data", default="blobs",
        help="histograms: blobs (scaling path), photos (log domain), or both: blobs,photos",
    )
    parser.add_argument("--worker", nargs=2, metavar=("CASE", "N"), help=argparse.SUPPRESS)
    parser.add_argument("--histograms", default="", help=argparse.SUPPRESS)
    args = parser.parse_args()

    if args.worker:
        case, n = args.worker[0], int(args.worker[1])
        repeats = 1 if case in ("gradient", "fit") and n >= 64 else args.repeats
        repeats = 1 if case == "fit" or (args.data == "photos" and n >= 128) else repeats
        print(json.dumps(worker(case, n, args.styles, args.iterations, repeats,
                                args.data, args.histograms)))
        return

    sizes = [int(s) for s in args.sizes.split(",")]
    fit_sizes = {int(s) for s in args.fit_sizes.split(",") if s}
    cases = [c for c in args.cases.split(",") if c]
    datas = [d for d in args.data.split(",") if d]
    if any(d not in DATA for d in datas):
        parser.error(f"--data takes {', '.join(DATA)}")
    print(f"S = {args.styles}, L = {args.iterations}, kernel 1.5 bins, float64")
    header = (f"{'case':<10}{'data':<8}{'grid':>6}{'median (s)':>12}{'peak RSS (MB)':>15}"
              f"{'above inputs':>14}{'runs':>6}  notes")
    print(header)
    print("-" * len(header))
    env = {**os.environ, "WBCGRADE_LOG_DOMAIN_BUDGET_S": "inf"}
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            for data in datas:
                histograms = ""
                if data == "photos":
                    histograms = os.path.join(tmp, f"photos{n}.npy")
                    photo_histograms(n, args.styles + 1, histograms)
                for case in cases:
                    row = f"{case:<10}{data:<8}{n:>5}³"
                    if case == "fit" and n not in fit_sizes:
                        print(f"{row}{'skipped':>12}{'':>15}{'':>14}{'':>6}  (--fit-sizes)")
                        continue
                    cmd = [sys.executable, __file__, "--worker", case, str(n),
                           "--styles", str(args.styles), "--iterations", str(args.iterations),
                           "--repeats", str(args.repeats), "--data", data,
                           "--histograms", histograms]
                    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
                    if proc.returncode != 0:
                        reason = (proc.stderr.strip().splitlines() or ["failed"])[-1]
                        print(f"{row}{'failed':>12}{'':>15}{'':>14}{'':>6}  {reason}")
                        continue
                    r = json.loads(proc.stdout.strip().splitlines()[-1])
                    notes = r["backend"]
                    if "evaluations" in r:
                        notes += f", {r['evaluations']} evaluations, loss /{r['loss_drop']:.1f}"
                    print(f"{row}{r['median_s']:>12.3f}{r['peak_rss_mb']:>15.0f}"
                          f"{r['above_inputs_mb']:>14.0f}{len(r['times_s']):>6}  {notes}",
                          flush=True)


if __name__ == "__main__":
    main()
