"""``wbcgrade brdf``: infer a BRDF from sparse measurements (paper §5.2).

Parsing, progress and printing only; the work is ``wbcgrade.brdf.workflow``.
Heavy modules (numpy, the core) are imported inside the commands, so that
``wbcgrade --help`` stays fast.
"""

from __future__ import annotations

import json

import click

from wbcgrade.brdf.defaults import (
    BRDF_LOSSES,
    DEFAULT_DIRECTIONS,
    DEFAULT_FIT_DIRECTIONS,
    DEFAULT_LOSS,
    DEFAULT_MAX_ITER,
    DEFAULT_N_ITER,
    DEFAULT_TOL,
    DEFAULT_WIDTH,
)
from wbcgrade.cli.grading_options import table_options
from wbcgrade.limits import MAX_BARYCENTER_ITERATIONS


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
@table_options("materials")
@click.option("--list", "list_only", is_flag=True, help="List the material names and exit.")
@click.option("--directions", default=DEFAULT_DIRECTIONS, show_default=True,
              type=click.IntRange(8, 2000),
              help="Hemisphere directions of the .npz files written for anisotropic materials.")
def synth(folder: str | None, count: int, materials: tuple[str, ...], list_only: bool,
          directions: int) -> None:
    """Write a database of analytic BRDFs (GGX metals and plastics, Ward, Lambert).

    Isotropic materials are written as MERL .binary files; anisotropic ones
    (Ward) as sampled .npz files, since the MERL format cannot hold anisotropy.
    """
    from tqdm import tqdm

    from wbcgrade.brdf import analytic
    from wbcgrade.brdf.workflow import write_database

    if list_only:
        held_out = {m.name for m in analytic.held_out_materials()}
        for name in analytic.all_material_names():
            click.echo(f"{name}{'  (held out of --count databases)' if name in held_out else ''}")
        return
    if folder is None:
        raise click.UsageError("Missing option '-o' / '--output'.")
    with tqdm(desc="synth", unit="BRDF", leave=False, disable=None) as bar:
        def progress(done: int, total: int, name: str) -> None:
            bar.total = total
            bar.update(done - bar.n)

        written = write_database(folder, materials, count=count, directions=directions,
                                 progress=progress)
    for path in written:
        click.echo(str(path))


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
@table_options("output", help="Fitted BRDF (.binary MERL or .npz) [default: "
                              "./<MEASURED>[-keepK]-fit.binary].")
@table_options("png")
@click.option("--no-png", is_flag=True, help="Do not render the comparison picture.")
@click.option("--compare/--no-compare", default=True, show_default=True,
              help="With --keep, also fit the full measurement for comparison.")
@click.option("--loss", type=click.Choice(BRDF_LOSSES), default=DEFAULT_LOSS,
              show_default=True,
              help="Fit loss: sinkhorn-divergence is the entropic Wasserstein loss without "
                   "its entropic bias; wasserstein is the paper's (biased: it favours blurry "
                   "BRDFs); quadratic is the fastest.")
@click.option("--directions", default=DEFAULT_DIRECTIONS, show_default=True,
              type=click.IntRange(8, 2000), help="Hemisphere sampling size N.")
@click.option("--fit-directions", default=DEFAULT_FIT_DIRECTIONS, show_default=True,
              type=click.IntRange(0, 2000),
              help="Incoming directions (well spread) whose rows fit the weights; 0 = all N.")
@click.option("--width", default=DEFAULT_WIDTH, show_default=True,
              type=click.FloatRange(0.1, 20.0),
              help="Kernel width in sample spacings (sets gamma).")
@click.option("--iterations", "--n-iter", "n_iter", default=DEFAULT_N_ITER, show_default=True,
              type=click.IntRange(1, MAX_BARYCENTER_ITERATIONS),
              help="Barycenter iterations L (--n-iter: its former name).")
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
    from tqdm import tqdm

    from wbcgrade.brdf.workflow import fit_measurement

    bars: dict[str, tqdm] = {}

    def progress(label, n, weights, value) -> None:
        if label not in bars:
            for bar in bars.values():
                bar.close()
            bars[label] = tqdm(desc=f"fit ({label})", unit="eval", leave=False, disable=None)
        bars[label].update(1)
        bars[label].set_postfix(loss=f"{value:.4g}")

    try:
        result = fit_measurement(
            measured, database, keeps=keeps, seed=seed, output=output, png=png, no_png=no_png,
            compare=compare, loss=loss, directions=directions, fit_directions=fit_directions,
            width=width, n_iter=n_iter, max_iter=max_iter, tol=tol, progress=progress)
    finally:
        for bar in bars.values():
            bar.close()

    for run in result.runs:
        if not run.fit.converged:
            click.echo(f"Warning: the {run.label} fit stopped before converging "
                       "(raise --max-iter)", err=True)
    if as_json:
        click.echo(json.dumps(result.as_dict(), indent=2, allow_nan=False))
        return
    _print_table(result)
    click.echo(f"wrote {result.output}" + ("" if result.png is None else f" and {result.png}"))


def _print_table(result) -> None:
    """Weights (sorted by the first fit's), PSNR, loss, evaluations and time, one column a fit."""
    from wbcgrade.brdf.workflow import ranked

    names, runs = result.names, result.runs
    order = [names.index(name) for name, _ in ranked(names, runs[0].fit.weights)]
    rows = [("material", [run.label for run in runs])]
    rows += [(names[i], [f"{run.fit.weights[i]:.3f}" for run in runs]) for i in order]
    rows += [
        ("PSNR vs measurement", [f"{run.psnr:.2f} dB" for run in runs]),
        (f"loss ({result.loss})", [f"{run.fit.loss:.4g}" for run in runs]),
        ("  at uniform weights", [f"{run.fit.initial_loss:.4g}" for run in runs]),
        ("evaluations", [str(run.fit.n_evaluations) for run in runs]),
        ("time", [f"{run.fit.time_s:.1f}s" for run in runs]),
    ]
    first = max(len(name) for name, _ in rows)
    width = max(10, *(len(cell) for _, cells in rows for cell in cells))
    for i, (name, cells) in enumerate(rows):
        click.echo(f"{name:<{first}}" + "".join(f"  {cell:>{width}}" for cell in cells))
        if i == 0:
            click.echo("-" * first + f"  {'-' * width}" * len(cells))
