"""Core benchmark: kernel product, forward barycenter, gradient and fit on 3-D grids.

Run ``python benchmarks/core.py`` (options: ``--help``). Every case runs in a
fresh subprocess so that its peak resident memory (``ru_maxrss``) is its own;
the table shows the median wall time over the repeats and that peak.

Data: S smooth synthetic histograms on an n^3 grid (each a mixture of three
Gaussian blobs plus a small floor, as in DESIGN.md §4), kernel 1.5 bins wide,
float64, L unrolled iterations.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time

import numpy as np

CASES = ("kernel", "forward", "gradient", "fit")


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


def worker(case: str, n: int, styles: int, iterations: int, repeats: int) -> dict:
    from wbcgrade.core import (
        BarycenterSolver,
        GridGeometry,
        barycentric_coordinates,
    )

    geom = GridGeometry.with_width((n, n, n), 1.5)
    H = make_histograms(n, styles + 1)
    target, H = H[0], H[1:]
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
    return {
        "median_s": statistics.median(times),
        "times_s": times,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
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
    parser.add_argument("--worker", nargs=2, metavar=("CASE", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args()

    if args.worker:
        case, n = args.worker[0], int(args.worker[1])
        repeats = 1 if case in ("gradient", "fit") and n >= 64 else args.repeats
        repeats = 1 if case == "fit" else repeats
        print(json.dumps(worker(case, n, args.styles, args.iterations, repeats)))
        return

    sizes = [int(s) for s in args.sizes.split(",")]
    fit_sizes = {int(s) for s in args.fit_sizes.split(",") if s}
    cases = [c for c in args.cases.split(",") if c]
    print(f"S = {args.styles}, L = {args.iterations}, kernel 1.5 bins, float64")
    header = f"{'case':<10}{'grid':>6}{'median (s)':>12}{'peak RSS (MB)':>15}{'runs':>6}  notes"
    print(header)
    print("-" * len(header))
    for n in sizes:
        for case in cases:
            if case == "fit" and n not in fit_sizes:
                print(f"{case:<10}{n:>5}³{'skipped':>12}{'':>15}{'':>6}  (--fit-sizes)")
                continue
            cmd = [sys.executable, __file__, "--worker", case, str(n),
                   "--styles", str(args.styles), "--iterations", str(args.iterations),
                   "--repeats", str(args.repeats)]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                reason = (proc.stderr.strip().splitlines() or ["failed"])[-1]
                print(f"{case:<10}{n:>5}³{'failed':>12}{'':>15}{'':>6}  {reason}")
                continue
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            notes = r["backend"]
            if "evaluations" in r:
                notes += f", {r['evaluations']} evaluations, loss /{r['loss_drop']:.1f}"
            print(f"{case:<10}{n:>5}³{r['median_s']:>12.3f}{r['peak_rss_mb']:>15.0f}"
                  f"{len(r['times_s']):>6}  {notes}", flush=True)


if __name__ == "__main__":
    main()
