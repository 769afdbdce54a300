"""End-to-end benchmark of ``wbcgrade apply`` at 128³ (issue 5), in one command.

Run ``python benchmarks/apply.py`` (``--help`` for options). It prints one table:

- ``apply``: wall time and peak resident memory of ``wbcgrade apply`` on the
  16-megapixel sample photo (``seeding_full.jpg`` beside the project, in
  ``shared/data/photos``) with ten style photos (the other photos there) at
  128³, their histograms cached (one unmeasured run fills a private cache;
  ``--no-cache`` measures the first run instead), and the time of each stage;
- ``--batch N``: ``wbcgrade batch --consistent`` over a folder of N copies of
  the photo (hard links), ``-j 1`` and ``-j 2``: photos per minute and peak
  memory (the largest of the command and its worker processes);
- ``--verify``: the same-answer check. From the fast path's weights, a few
  L-BFGS steps on the plain 128³ energy (same loss, same kernel, L = 60)
  must lower it by less than 2 %, and the photo graded with the refined
  weights must differ from the fast one by less than 2/255 on average;
- ``--floors``: what bounds each stage on this machine (median of 5): JPEG
  decode of the photo (to float32) and encode of its 8-bit codes (``apply``
  converts its float pixels to codes itself), one pass over its pixels (a
  clipped copy), the 128³ kernel product (float64, one histogram; a Sinkhorn
  iteration takes two, the barycentric projection three: nine axis
  products), the 64³ product and the fit's 16³ product of ten histograms
  (float32);
- ``--torch``: the gradient of the same energy at 64³ computed by our reverse
  pass and by PyTorch autograd through the unrolled iterations (CPU,
  ``pip install torch==2.13.0``), each in its own process: time, peak memory,
  their ratios, and how far the two gradients agree.

Each measured case runs in a fresh subprocess so that its peak memory
(``ru_maxrss``) is its own. The machine is shared: quote ratios and medians
from one run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_PHOTOS = ROOT.parent / "shared" / "data" / "photos"
STAGES = ("styles", "read", "fit", "histograms", "barycenter", "transfer", "remap", "write")


# --------------------------------------------------------------------------- helpers


def run_measured(command: list[str], env: dict | None = None) -> tuple[float, float, str]:
    """Run a command; (wall seconds, peak RSS in MB of that process, stdout).

    The peak is that of the process itself or, when it ran worker processes,
    of the largest of them (``ru_maxrss`` of its waited-for children).
    """
    start = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        process = subprocess.Popen(command, stdout=out, stderr=err,
                                   env=None if env is None else {**os.environ, **env})
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - start
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(), err.read().decode()
    if process.returncode != 0:
        raise SystemExit(f"failed ({process.returncode}): {' '.join(command)}\n{stderr[-2000:]}")
    return wall, usage.ru_maxrss / 1024.0, stdout


def style_folder(photos: Path, photo: Path, count: int, folder: Path) -> list[str]:
    """Link ``count`` style photos (not the input, nor its resized copies) into ``folder``."""
    candidates = sorted(p for p in photos.glob("*.jpg")
                        if not p.stem.startswith(photo.stem.split("_")[0]))
    if len(candidates) < count:
        raise SystemExit(f"only {len(candidates)} style photos in {photos}, need {count}")
    for path in candidates[:count]:
        (folder / path.name).symlink_to(path)
    return [p.stem for p in candidates[:count]]


def wbcgrade(*args: str) -> list[str]:
    return [sys.executable, "-c", "from wbcgrade.cli import main; main()", *args]


def read_8bit(path: Path) -> np.ndarray:
    from wbcgrade.color.io.images import read_image

    return np.asarray(read_image(path).pixels, dtype=np.float64)


# --------------------------------------------------------------------------- workers


def energy_problem(photo: Path, styles: Path, bins: int):
    """(target, style histograms, fit geometry at ``bins``, opts) of the apply pipeline."""
    from wbcgrade.color.colorspace import ColorEncoding
    from wbcgrade.color.histogram import add_floor, image_histogram
    from wbcgrade.color.io.images import read_image
    from wbcgrade.color.options import FitOptions, TransferOptions
    from wbcgrade.color.presets import load_style_folder
    from wbcgrade.core import GridGeometry

    opts, transfer = FitOptions(), TransferOptions()
    image = read_image(photo)
    encoded, _ = ColorEncoding.for_image(image).encode(image.rgb(), image.is_float)
    target = add_floor(image_histogram(encoded, bins, image.alpha(), transfer.max_pixels),
                       opts.floor)
    style_set = load_style_folder(styles, bins)
    hists = np.stack([add_floor(h, opts.floor) for h in style_set.histograms])
    gamma = opts.kernel_gamma  # the fit's kernel, fixed in colour units
    return target, hists, GridGeometry((bins,) * 3, gamma, np.float32), opts, style_set.names


def worker_verify(photo: Path, styles: Path, weights: list[float], steps: int) -> dict:
    """E(fast weights) at 128³, then L-BFGS from there; the best energy found.

    The weights are parametrised by a softmax, under which a weight at 0 has
    no gradient; L-BFGS therefore starts from the fast weights mixed with 2 %
    of uniform weights, so every style can gain weight, and the fast weights'
    own energy is evaluated exactly first.
    """
    from wbcgrade.core import BarycenterSolver, barycentric_coordinates, get_loss

    target, hists, geometry, opts, _ = energy_problem(photo, styles, 128)
    start = time.perf_counter()
    fast = np.asarray(weights) / np.sum(weights)
    solver = BarycenterSolver(hists, geometry, opts.n_iter)
    fast_energy, _ = get_loss(opts.loss).value_and_grad(solver.barycenter(fast), target,
                                                         geometry)
    init = 0.98 * fast + 0.02 / len(fast)
    result = barycentric_coordinates(target, hists, geometry, loss=opts.loss,
                                     n_iter=opts.n_iter, init_weights=init, max_iter=steps)
    refined = result.weights if result.loss < fast_energy else fast
    return {"fast_energy": float(fast_energy), "refined_energy": min(result.loss, fast_energy),
            "lbfgs_best": float(result.loss),
            "evaluations": result.n_evaluations + 1, "weights": [float(w) for w in refined],
            "seconds": time.perf_counter() - start, "backend": result.backend}


def worker_gradient(kind: str, photo: Path, styles: Path, bins: int, dtype: str) -> dict:
    target, hists, geometry, opts, _ = energy_problem(photo, styles, bins)
    geometry = geometry.with_dtype(np.dtype(dtype))
    weights = np.full(len(hists), 1.0 / len(hists))
    if kind == "ours":
        from wbcgrade.core import BarycenterSolver

        solver = BarycenterSolver(hists, geometry, opts.n_iter)
        start = time.perf_counter()
        value, grad, _ = solver.value_and_grad(weights, target, opts.loss)
        seconds, backend = time.perf_counter() - start, solver.last_backend
    else:
        value, grad, seconds = torch_gradient(hists, weights, target, geometry, opts.n_iter)
        backend = f"torch autograd, {dtype}"
    return {"value": float(value), "grad": [float(g) for g in grad], "seconds": seconds,
            "backend": backend}


def torch_gradient(hists, weights, target, geometry, n_iter):
    """The same energy's gradient by autograd through the L unrolled iterations."""
    import torch

    torch.set_flush_denormal(True)  # as fast as it can be (docs/architecture.md, Numerics)
    dtype = geometry.dtype
    K = torch.from_numpy(np.ascontiguousarray(geometry.kernels[0], dtype=dtype))
    H = torch.from_numpy(hists.astype(dtype))
    q = torch.from_numpy(target.astype(dtype))
    w = torch.tensor(weights.astype(dtype), requires_grad=True)

    def apply(x):  # separable Gibbs kernel over the three grid axes, S histograms
        x = torch.einsum("ij,sjkl->sikl", K, x)
        x = torch.einsum("jk,sikl->sijl", K, x)
        return torch.einsum("kl,sijl->sijk", K, x)

    start = time.perf_counter()
    b = torch.ones_like(H)
    for _ in range(n_iter):
        phi = apply(H / apply(b))
        P = torch.exp(torch.einsum("s,sijk->ijk", w, torch.log(phi)))
        b = P / phi
    loss = 0.5 * ((P.double() - q.double()) ** 2).sum()
    loss.backward()
    return float(loss), w.grad.double().numpy(), time.perf_counter() - start


def floors(photo: Path) -> list[tuple[str, str, str, str]]:
    """Median seconds of the operations that bound the stages (see the module doc)."""
    import OpenImageIO as oiio

    from wbcgrade.color.io.images import read_image
    from wbcgrade.core import GridGeometry
    from wbcgrade.core._cpu import fast_cpu

    def median_time(fn, repeats: int = 5) -> float:
        fn()
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            fn()
            times.append(time.perf_counter() - start)
        return statistics.median(times)

    from wbcgrade.color.io._quantise import to_uint8

    pixels = read_image(photo).pixels
    codes = to_uint8(pixels)  # apply converts to 8-bit codes itself (on every core)
    rows = [("floor: JPEG decode", f"{median_time(lambda: read_image(photo)):.2f} s", "",
             f"{pixels.shape[1]}x{pixels.shape[0]}, OpenImageIO, to float32")]
    with tempfile.TemporaryDirectory() as tmp:
        def encode():
            out = oiio.ImageOutput.create(str(Path(tmp) / "x.jpg"))
            spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, "uint8")
            out.open(str(Path(tmp) / "x.jpg"), spec)
            out.write_image(codes)
            out.close()
        rows.append(("floor: JPEG encode", f"{median_time(encode):.2f} s", "",
                     "the same 8-bit codes, quality 95 (OpenImageIO default)"))
    one_pass = median_time(lambda: np.clip(pixels, 0, 1))
    rows.append(("floor: one pass over the pixels", f"{one_pass:.2f} s", "",
                 "a clipped float32 copy (memory bandwidth)"))
    for bins, dtype, count in ((128, np.float64, 1), (64, np.float64, 1), (16, np.float32, 10)):
        geometry = GridGeometry((bins,) * 3, 2 * (1 / 31) ** 2, dtype)
        values = np.random.default_rng(0).random((count, *geometry.shape)).astype(dtype)
        operand = values[0] if count == 1 else values
        with fast_cpu():
            seconds = median_time(lambda g=geometry, x=operand: g.apply(x))
        rows.append((f"floor: kernel product {bins}³", f"{seconds * 1e3:.1f} ms", "",
                     f"{count} histogram(s), {np.dtype(dtype).name}, separable BLAS"))
    return rows


# --------------------------------------------------------------------------- main


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--photo", type=Path, default=DEFAULT_PHOTOS / "seeding_full.jpg")
    parser.add_argument("--photos", type=Path, default=DEFAULT_PHOTOS,
                        help="folder the style photos are taken from")
    parser.add_argument("--styles", type=int, default=10)
    parser.add_argument("--mode", choices=("look", "palette"), default="look",
                        help="the grade measured (--verify checks a palette grade's weights: "
                             "it needs --mode palette)")
    parser.add_argument("--repeats", type=int, default=1, help="apply runs (median)")
    parser.add_argument("--no-cache", action="store_true",
                        help="measure apply without cached style histograms")
    parser.add_argument("--batch", type=int, default=0, metavar="N",
                        help="also measure batch --consistent on N copies of the photo")
    parser.add_argument("--verify", action="store_true", help="run the same-answer check")
    parser.add_argument("--verify-steps", type=int, default=3, help="L-BFGS iterations at 128³")
    parser.add_argument("--floors", action="store_true",
                        help="also measure what bounds each stage")
    parser.add_argument("--torch", action="store_true", help="compare with PyTorch autograd")
    parser.add_argument("--torch-bins", type=int, default=64,
                        help="grid of the float32 speed comparison")
    parser.add_argument("--agree-bins", type=int, default=32,
                        help="grid of the float64 agreement check")
    parser.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.verify and args.mode != "palette":
        parser.error("--verify checks a palette grade's weights: add --mode palette")

    if args.worker:
        kind, *rest = args.worker
        if kind == "verify":
            photo, styles, weights, steps = rest
            result = worker_verify(Path(photo), Path(styles), json.loads(weights), int(steps))
        else:
            photo, styles, bins, dtype = rest
            result = worker_gradient(kind, Path(photo), Path(styles), int(bins), dtype)
        print(json.dumps(result))
        return

    if not args.photo.is_file():
        raise SystemExit(f"{args.photo}: no such photo (use --photo)")
    rows: list[tuple[str, str, str, str]] = []
    with tempfile.TemporaryDirectory(prefix="wbcgrade-bench-") as tmp:
        tmp = Path(tmp)
        styles = tmp / "styles"
        styles.mkdir()
        names = style_folder(args.photos, args.photo, args.styles, styles)
        print(f"photo {args.photo.name}, {len(names)} styles: {', '.join(names)}", flush=True)

        fast = tmp / "fast.jpg"
        cache_args = ["--no-cache"] if args.no_cache else ["--cache-dir", str(tmp / "cache")]
        cache_args += ["--mode", args.mode]
        if not args.no_cache:  # fill the histogram cache (not measured)
            run_measured(wbcgrade("apply", str(args.photo), "--style", str(styles), "-o",
                                  str(tmp / "warm.jpg"), *cache_args))
        walls, peaks, report = [], [], {}
        for _ in range(max(1, args.repeats)):
            fast.unlink(missing_ok=True)
            wall, peak, out = run_measured(wbcgrade("apply", str(args.photo), "--style",
                                                    str(styles), "-o", str(fast), "--json",
                                                    *cache_args))
            walls.append(wall)
            peaks.append(peak)
            report = json.loads(out)
        timings = report["timings_s"]
        stages = ", ".join(f"{k} {timings[k]:.2f}" for k in STAGES if k in timings)
        startup = statistics.median(walls) - timings["total"]
        cached = "histograms not cached" if args.no_cache else "histograms cached"
        rows.append(("apply, 128³, end to end", f"{statistics.median(walls):.1f} s",
                     f"{max(peaks):.0f} MB", f"{len(walls)} run(s), {cached}; "
                     "target <= 10 s, <= 2 GB"))
        rows.append(("  stages (s)", "", "", f"{stages}; start-up and imports {startup:.2f}"))

        if args.floors:
            rows.extend(floors(args.photo))

        if args.batch > 0:
            shoot = tmp / "shoot"
            shoot.mkdir()
            for i in range(args.batch):
                os.link(args.photo, shoot / f"photo_{i:03d}{args.photo.suffix}")
            for jobs in (1, 2):
                out_dir = tmp / f"batch_j{jobs}"
                print(f"batch --consistent, {args.batch} photos, -j {jobs} ...", flush=True)
                wall, peak, _ = run_measured(wbcgrade("batch", str(shoot), "-o", str(out_dir),
                                                      "--style", str(styles), "--consistent",
                                                      "-j", str(jobs), *cache_args))
                rows.append((f"batch --consistent -j {jobs}", f"{wall:.1f} s", f"{peak:.0f} MB",
                             f"{args.batch} photos of {args.photo.name}: "
                             f"{60 * args.batch / wall:.1f} photos/min"))
        if args.verify:
            by_name = {entry["style"]: entry["weight"] for entry in report["weights"]}
            fast_weights = [by_name[name] for name in names]
            print("verify: L-BFGS on the plain 128³ energy from the fast weights ...", flush=True)
            wall, peak, out = run_measured([sys.executable, __file__, "--worker", "verify",
                                            str(args.photo), str(styles),
                                            json.dumps(fast_weights), str(args.verify_steps)])
            check = json.loads(out)
            drop = (check["fast_energy"] - check["refined_energy"]) / check["fast_energy"]
            refined = tmp / "refined.jpg"
            weights_text = ",".join(f"{w:.12g}" for w in check["weights"])
            run_measured(wbcgrade("apply", str(args.photo), "--style", str(styles), "-o",
                                  str(refined), "--mode", "palette", "--weights", weights_text,
                                  "--no-cache"))
            diff = np.abs(read_8bit(fast) - read_8bit(refined)).mean() * 255.0
            rows.append(("verify: 128³ energy drop", f"{wall:.0f} s", f"{peak:.0f} MB",
                         f"{100 * drop:.4f} % (E = {check['fast_energy']:.6e} at the fast "
                         f"weights, best of {check['evaluations']} evaluations "
                         f"{check['lbfgs_best']:.6e}; {check['backend']}; must be < 2 %)"))
            rows.append(("verify: image difference", "", "",
                         f"{diff:.3f}/255 mean (must be < 2/255)"))

        if args.torch:
            for bins, dtype in ((args.torch_bins, "float32"), (args.agree_bins, "float64")):
                results = {}
                for kind in ("ours", "torch"):
                    print(f"gradient at {bins}³, {dtype}: {kind} ...", flush=True)
                    _, peak, out = run_measured([sys.executable, __file__, "--worker", kind,
                                                 str(args.photo), str(styles), str(bins), dtype])
                    results[kind] = json.loads(out) | {"peak": peak}
                ours, theirs = results["ours"], results["torch"]
                g1, g2 = np.array(ours["grad"]), np.array(theirs["grad"])
                if np.all(np.isfinite(g2)):
                    agree = f"gradients agree to {np.abs(g1 - g2).max() / np.abs(g1).max():.1e}"
                else:
                    agree = "autograd's gradient is NaN/inf (ours is finite)" if np.all(
                        np.isfinite(g1)) else "both gradients non-finite"
                for kind, r in (("ours", ours), ("torch", theirs)):
                    rows.append((f"gradient {bins}³ {dtype}, {kind}", f"{r['seconds']:.1f} s",
                                 f"{r['peak']:.0f} MB", r["backend"]))
                rows.append(("  ours / torch", f"{ours['seconds'] / theirs['seconds']:.2f}",
                             f"{ours['peak'] / theirs['peak']:.2f}", agree))

    widths = [max(len(r[i]) for r in rows + [("case", "time", "peak RSS", "notes")])
              for i in range(4)]
    header = ("case", "time", "peak RSS", "notes")
    print()
    print("  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip())
    print("-" * (sum(widths) + 6))
    for row in rows:
        print("  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip())


if __name__ == "__main__":
    main()
