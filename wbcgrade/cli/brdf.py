"""``wbcgrade brdf``: infer a BRDF from sparse measurements (paper §5.2).

Parsing, progress and printing only; the work is ``wbcgrade.brdf.workflow``.
Heavy modules (numpy, the core) are imported inside the commands, so that
``wbcgrade --help`` stays fast.
"""

from __future__ import annotations

import json

import click

from wbcgrade.cli.grading_options import table_options


@click.group("brdf")
def brdf() -> None:
    """Reflectance (BRDF) as a Wasserstein barycenter of a BRDF database.

    A measured BRDF is explained by weights on a database of BRDFs; the fitted
    BRDF is their barycenter. It works from a fraction of the measurements
    (--keep simulates a sparse acquisition).
    """


@brdf.command("synth")
@table_options("folder", "count", "materials", "list_only")
@table_options("directions", help="Hemisphere directions of the .npz files written for "
                                  "anisotropic materials.")
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
@click.argument("measured", type=click.Path(dir_okay=False))
@table_options("brdf_database", "keeps", "seed")
@table_options("output", help="Fitted BRDF (.binary MERL or .npz) [default: "
                              "./<MEASURED>[-keepK]-fit.binary].")
@table_options("png", "no_png", "compare", "brdf_loss", "directions", "fit_directions",
               "brdf_width", "brdf_n_iter", "brdf_max_iter", "tol", "as_json")
def fit(measured: str, brdf_database: str, keeps: tuple[float, ...], seed: int,
        output: str | None, png: str | None, no_png: bool, compare: bool, brdf_loss: str,
        directions: int, fit_directions: int, brdf_width: float, brdf_n_iter: int,
        brdf_max_iter: int, tol: float, as_json: bool) -> None:
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
            measured, brdf_database, keeps=keeps, seed=seed, output=output, png=png,
            no_png=no_png, compare=compare, loss=brdf_loss, directions=directions,
            fit_directions=fit_directions, width=brdf_width, n_iter=brdf_n_iter,
            max_iter=brdf_max_iter, tol=tol, progress=progress)
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
