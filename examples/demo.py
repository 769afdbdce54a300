"""The core on synthetic data, end to end, in a few seconds.

Builds S Gaussian blobs on a SIZE^3 grid, takes their Wasserstein barycenter
for random weights, and fits the weights back from it with
``wbcgrade.core.barycentric_coordinates``. Run from anywhere once wbcgrade
is installed::

    python examples/demo.py                      # 16^3 grid, 4 histograms
    python examples/demo.py --size 8 --styles 3 --iterations 15 --json

(This was the ``wbcgrade demo`` command; the product CLI grades photos,
BRDFs and shapes. Architecture: docs/architecture.md.)
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from wbcgrade.core import GridGeometry, barycenter, barycentric_coordinates


def blob(shape: tuple[int, ...], centre: np.ndarray, width: float) -> np.ndarray:
    """A normalised Gaussian blob on the grid ``linspace(0, 1, n)`` per axis, shape ``shape``."""
    axes = np.meshgrid(*[np.linspace(0, 1, n) for n in shape], indexing="ij")
    h = np.exp(-sum((a - c) ** 2 for a, c in zip(axes, centre)) / (2 * width**2))
    h[h < 1e-12] = 0.0
    return h / h.sum()


def run(size: int = 16, styles: int = 4, iterations: int = 40, seed: int = 0) -> dict:
    """Recover known weights; -> true and fitted weights (S,), L1 error, loss, evaluations."""
    if size < 4 or styles < 2 or iterations < 1:
        raise ValueError("need --size >= 4, --styles >= 2 and --iterations >= 1")
    rng = np.random.default_rng(seed)
    shape = (size,) * 3
    geometry = GridGeometry.with_width(shape, 1.5)
    histograms = np.stack([blob(shape, rng.uniform(0.2, 0.8, 3), 0.12) for _ in range(styles)])
    truth = rng.dirichlet(np.ones(styles))
    target = barycenter(histograms, truth, geometry, n_iter=iterations)
    fit = barycentric_coordinates(target, histograms, geometry, n_iter=iterations)
    return {
        "true_weights": truth.tolist(), "fitted_weights": fit.weights.tolist(),
        "l1_error": float(np.abs(fit.weights - truth).sum()), "loss": fit.loss,
        "initial_loss": fit.initial_loss, "evaluations": fit.n_evaluations,
        "time_s": fit.time_s, "geometry": repr(geometry),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=16, help="grid bins per axis (3-D grid)")
    parser.add_argument("--styles", type=int, default=4, help="number of input histograms S")
    parser.add_argument("--iterations", type=int, default=40, help="barycenter iterations L")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args(argv)
    try:
        result = run(args.size, args.styles, args.iterations, args.seed)
    except ValueError as exc:
        parser.error(str(exc))
    if args.json:
        print(json.dumps({k: v for k, v in result.items() if k != "geometry"}, indent=2))
        return 0
    print(f"{'input':>6}  {'true':>7}  {'fitted':>7}")
    for s, (t, f) in enumerate(zip(result["true_weights"], result["fitted_weights"])):
        print(f"{s:>6}  {t:7.4f}  {f:7.4f}")
    print(f"L1 error {result['l1_error']:.2e}, loss {result['initial_loss']:.3e} -> "
          f"{result['loss']:.3e}, {result['evaluations']} evaluations in "
          f"{result['time_s']:.1f} s ({result['geometry']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
