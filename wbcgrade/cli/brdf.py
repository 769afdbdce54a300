"""``wbcgrade brdf``: infer a BRDF from sparse measurements (paper §5.2)."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np
from tqdm import tqdm

from wbcgrade.brdf import analytic, io, merl, render, sampled, sampling
from wbcgrade.brdf.fit import (
    BRDF_LOSSES,
    DEFAULT_FIT_DIRECTIONS,
    DEFAULT_LOSS,
    DEFAULT_MAX_ITER,
    DEFAULT_N_ITER,
    DEFAULT_TOL,
    fit_brdf,
)
from wbcgrade.errors import NumericalError


@click.group("brdf")
def brdf() -> None:
    """Reflectance (BRDF) as a Wasserstein barycenter of a BRDF database.

    A measured BRDF is explained by weights on a database of BRDFs; the fitted
    BRDF is their barycenter. It works from a fraction of the measurements
    (--keep simulates a sparse acquisition).
    """


@brdf.command("synth")
@click.option("-o", "--output", "folder", type=click.Path(file_okay=False),
              help="Folder to write the database into (created if needed).")
@click.option("--count", default=6, show_default=True, type=click.IntRange(1, 64),
              help="Number of materials (the first of the built-in catalogue).")
@click.option("--material", "materials", multiple=True, metavar="NAME",
              help="Write these materials instead (repeatable; see --list).")
@click.option("--list", "list_only", is_flag=True, help="List the material names and exit.")
@click.option("--directions", default=sampling.DEFAULT_DIRECTIONS, show_default=True,
              type=click.IntRange(8, 2000),
              help="Hemisphere directions of the .npz files written for anisotropic materials.")
def synth(folder: str | None, count: int, materials: tuple[str, ...], list_only: bool,
          directions: int) -> None:
    """Write a database of analytic BRDFs (GGX metals and plastics, Ward, Lambert).

    Isotropic materials are written as MERL .binary files; anisotropic ones
    (Ward) as sampled .npz files, since the MERL format cannot hold anisotropy.
    """
    if list_only:
        held_out = {m.name for m in analytic.held_out_materials()}
        for name in analytic.all_material_names():
            click.echo(f"{name}{'  (held out of --count databases)' if name in held_out else ''}")
        return
    if folder is None:
        raise click.UsageError("Missing option '-o' / '--output'.")
    chosen = ([analytic.material_by_name(n) for n in materials] if materials
              else analytic.default_materials(count))
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    dirs = sampling.hemisphere_directions(directions)
    written = []
    for index, material in enumerate(tqdm(chosen, desc="synth", unit="BRDF", leave=False,
                                                   disable=None)):
        stem = material.name if materials else f"{index + 1:02d}-{material.name}"
        if material.isotropic:
            path = merl.write_merl(out / f"{stem}.binary", merl.tabulate_merl(material.evaluate))
        else:
            path = io.write_sampled(out / f"{stem}.npz", analytic.sample_material(material, dirs),
                                    dirs, name=material.name)
        written.append(path)
    for path in written:
        click.echo(str(path))


def _default_output(measured: Path, keep: float | None) -> Path:
    tag = "" if keep is None else f"-keep{keep * 100:g}"
    return Path.cwd() / f"{measured.stem}{tag}-fit.binary"


@brdf.command("fit")
@click.argument("measured", type=click.Path(exists=True, dir_okay=False))
@click.option("--database", required=True, type=click.Path(exists=True, file_okay=False),
              help="Folder of BRDF files (.binary MERL or .npz sampled).")
@click.option("--keep", "keeps", type=click.FloatRange(0.0, 1.0, min_open=True),
              multiple=True,
              help="Keep only this random fraction of the measurements (simulated sparse "
                   "acquisition); repeat for several fits side by side, e.g. --keep 0.25 "
                   "--keep 0.1 --keep 0.05 (the paper's Figure 6).")
@click.option("--seed", default=0, show_default=True, help="Seed of the decimation.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Fitted BRDF (.binary MERL or .npz) [default: ./<MEASURED>[-keepK]-fit.binary].")
@click.option("--png", type=click.Path(dir_okay=False), default=None,
              help="Comparison picture [default: OUTPUT with .png].")
@click.option("--no-png", is_flag=True, help="Do not render the comparison picture.")
@click.option("--compare/--no-compare", default=True, show_default=True,
              help="With --keep, also fit the full measurement for comparison.")
@click.option("--loss", type=click.Choice(BRDF_LOSSES), default=DEFAULT_LOSS,
              show_default=True,
              help="Fit loss: sinkhorn-divergence is the entropic Wasserstein loss without "
                   "its entropic bias; wasserstein is the paper's (biased: it favours blurry "
                   "BRDFs); quadratic is the fastest.")
@click.option("--directions", default=sampling.DEFAULT_DIRECTIONS, show_default=True,
              type=click.IntRange(8, 2000), help="Hemisphere sampling size N.")
@click.option("--fit-directions", default=DEFAULT_FIT_DIRECTIONS, show_default=True,
              type=click.IntRange(0, 2000),
              help="Incoming directions (well spread) whose rows fit the weights; 0 = all N.")
@click.option("--width", default=sampling.DEFAULT_WIDTH, show_default=True,
              type=click.FloatRange(0.1, 20.0),
              help="Kernel width in sample spacings (sets gamma).")
@click.option("--n-iter", default=DEFAULT_N_ITER, show_default=True,
              type=click.IntRange(1, 10000), help="Barycenter iterations.")
@click.option("--max-iter", default=DEFAULT_MAX_ITER, show_default=True,
              type=click.IntRange(1, 1000), help="L-BFGS iterations at most.")
@click.option("--tol", default=DEFAULT_TOL, show_default=True, type=click.FloatRange(0, 1),
              help="Stop when an L-BFGS iteration lowers the energy (1 at uniform weights) by "
                   "less than this.")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
def fit(measured: str, database: str, keeps: tuple[float, ...], seed: int, output: str | None,
        png: str | None, no_png: bool, compare: bool, loss: str, directions: int,
        fit_directions: int, width: float, n_iter: int, max_iter: int, tol: float,
        as_json: bool) -> None:
    """Fit MEASURED (a BRDF file) with weights on the BRDFs of --database.

    Prints the weights and the PSNR of each fit against the full measurement,
    writes the fitted BRDF (from the first --keep's decimated measurement
    when --keep is given) and a picture: spheres rendered with the reference,
    the full fit and the decimated fits.
    """
    measured_path = Path(measured)
    keep = keeps[0] if keeps else None
    out = Path(output) if output else _default_output(measured_path, keep)
    png_path = None if no_png else (Path(png) if png else out.with_suffix(".png"))
    inputs = {measured_path.resolve(), *(p.resolve() for p in io.database_files(database))}
    for target in (out, png_path):
        if target is not None and target.resolve() in inputs:
            raise click.BadParameter(f"{target} is an input; choose another output",
                                     param_hint="-o/--png")
    if out.suffix.lower() not in io.BRDF_SUFFIXES:
        raise click.BadParameter(f"{out}: use a .binary or .npz suffix", param_hint="-o")
    from wbcgrade.color.imageio import check_output_path

    for target in (out, png_path):  # before any work: folder, writability, a regular file
        if target is not None:
            check_output_path(target, overwrite=True)

    dirs = sampling.hemisphere_directions(directions)
    geometry = sampling.hemisphere_geometry(directions, sampling.default_gamma(directions, width))
    reference = io.load_brdf(measured_path, dirs)
    names, base = io.load_database(database, dirs, exclude=measured_path)
    subset = None if fit_directions in (0, directions) else sampling.spread_subset(
        dirs, fit_directions)

    runs: list[tuple[str, np.ndarray | None]] = []
    for fraction in keeps:
        runs.append((f"keep {fraction * 100:g}%",
                     sampled.decimation_mask(directions, directions, fraction, seed)))
    if not keeps or compare:
        runs.insert(0, ("full", None))
    results = []
    for label, mask in runs:
        with tqdm(desc=f"fit ({label})", unit="eval", leave=False, disable=None) as bar:
            def progress(n, weights, value, bar=bar):
                bar.update(1)
                bar.set_postfix(loss=f"{value:.4g}")

            result = fit_brdf(reference, base, geometry, mask=mask, loss=loss, n_iter=n_iter,
                              max_iter=max_iter, tol=tol, fit_incoming=subset,
                              callback=progress)
        psnr = sampled.psnr(reference, result.values)
        if np.isnan(psnr):
            raise NumericalError(f"the {label} fit of {measured_path} has no defined PSNR")
        results.append((label, result, psnr))

    label, final, _ = results[1] if keeps and compare else results[0]
    io.save_brdf(out, final.values, dirs, name=f"{measured_path.stem} {label} fit")
    if png_path is not None:
        renderings = [render.render_sphere(reference, dirs)]
        captions = [["reference", measured_path.stem[:30], "(all measurements)"]]
        for label, result, psnr in results:
            renderings.append(render.render_sphere(result.values, dirs))
            shown = [(n, w) for n, w in _ranked(names, result.weights)[:3] if w >= 0.005]
            captions.append([f"fit, {label}", f"PSNR {psnr:.1f} dB",
                             *(f"{w * 100:.0f}%  {name}"[:31] for name, w in shown)])
        render.write_png(png_path, render.comparison_image(renderings, captions,
                                                           caption_lines=5))

    for label, result, _ in results:
        if not result.converged:
            click.echo(f"Warning: the {label} fit stopped before converging (raise --max-iter)",
                       err=True)
    if as_json:
        number = _json_number
        click.echo(json.dumps({
            "measured": str(measured_path),
            "database": names,
            "directions": directions,
            "fit_directions": directions if subset is None else len(subset),
            "gamma": number(geometry.gamma),
            "loss": loss,
            "fits": [{
                "label": label,
                "kept_fraction": result.kept_fraction,
                "weights": dict(zip(names, (float(w) for w in result.weights), strict=True)),
                "psnr_db": number(psnr),  # null: an exact fit (infinite PSNR)
                "loss": number(result.loss),
                "initial_loss": number(result.initial_loss),
                "n_evaluations": result.n_evaluations,
                "converged": result.converged,
                "time_s": round(result.time_s, 3),
            } for label, result, psnr in results],
            "output": str(out),
            "png": None if png_path is None else str(png_path),
        }, indent=2, allow_nan=False))
        return
    _print_table(names, results, loss)
    click.echo(f"wrote {out}" + ("" if png_path is None else f" and {png_path}"))


def _json_number(value: float) -> float | None:
    """``value`` as a float for JSON, None where it is not finite (JSON has no NaN or inf)."""
    value = float(value)
    return value if np.isfinite(value) else None


def _ranked(names: list[str], weights: np.ndarray) -> list[tuple[str, float]]:
    """(name, weight) pairs, largest weight first."""
    order = np.argsort(-np.asarray(weights), kind="stable")
    return [(names[i], float(weights[i])) for i in order]


def _print_table(names: list[str], results: list, loss: str) -> None:
    """Weights (sorted by the first fit's), PSNR, loss, evaluations and time, one column a fit."""
    order = [names.index(name) for name, _ in _ranked(names, results[0][1].weights)]
    rows = [("material", [label for label, _, _ in results])]
    rows += [(names[i], [f"{r.weights[i]:.3f}" for _, r, _ in results]) for i in order]
    rows += [
        ("PSNR vs measurement", [f"{p:.2f} dB" for _, _, p in results]),
        (f"loss ({loss})", [f"{r.loss:.4g}" for _, r, _ in results]),
        ("  at uniform weights", [f"{r.initial_loss:.4g}" for _, r, _ in results]),
        ("evaluations", [str(r.n_evaluations) for _, r, _ in results]),
        ("time", [f"{r.time_s:.1f}s" for _, r, _ in results]),
    ]
    first = max(len(name) for name, _ in rows)
    width = max(10, *(len(cell) for _, cells in rows for cell in cells))
    for i, (name, cells) in enumerate(rows):
        click.echo(f"{name:<{first}}" + "".join(f"  {cell:>{width}}" for cell in cells))
        if i == 0:
            click.echo("-" * first + f"  {'-' * width}" * len(cells))
