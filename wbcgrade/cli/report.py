"""``wbcgrade report``: which styles make up the grade of each photo (nothing is graded on disk)."""

from __future__ import annotations

import time
from pathlib import Path

import click

from wbcgrade.cli.batch import load_styles_with_progress, print_summary, run_with_progress
from wbcgrade.cli.grading_options import (
    LazyOptionsCommand,
    grading_options,
    space_options,
    take_grading_options,
)
from wbcgrade.errors import InputError


def _default_report_dir(target: Path) -> Path:
    target = target.resolve()
    return target.with_name(f"{target.stem if target.is_file() else target.name}_report")


@click.command("report", cls=LazyOptionsCommand)
@click.argument("target", metavar="PHOTO_OR_DIR",
                type=click.Path(exists=True, path_type=str))
@click.option("-o", "--output-dir", "report_dir", default=None,
              type=click.Path(file_okay=False, path_type=str),
              help="Report folder [default: <name>_report beside PHOTO_OR_DIR].")
@grading_options
@space_options
@click.option("-r", "--recursive", is_flag=True, help="Descend into sub-folders.")
@click.option("--consistent", is_flag=True,
              help="Report the one series grade (pooled palette) instead of one fit per photo.")
@click.option("-j", "--jobs", type=int, default=1, show_default=True,
              help="Fit photos in N local processes.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Send the photos to a Dask distributed scheduler (needs wbcgrade[dask]).")
@click.pass_context
def report(ctx, target, report_dir, recursive, consistent, jobs, scheduler, **kwargs):
    """Palette weight report of a photo or a folder of photos.

    Writes REPORT_DIR/report.json (per photo: the weights sorted with style
    names, the fitted loss and the loss of the best single style, the number
    of weights >= 0.001, the time), weights.csv (one row a photo, one column a
    style), a PNG sheet per photo in sheets/ and index.html.
    """
    from wbcgrade.color.batch import plan_batch
    from wbcgrade.color.report import write_report

    opts, style_args = take_grading_options(kwargs)
    target_path = Path(target)
    out = Path(report_dir) if report_dir else _default_report_dir(target_path)
    plan = plan_batch(target_path, None, recursive=recursive, exclude=[out])
    if not plan.tasks:
        if target_path.is_file():
            raise InputError(f"{target}: not an image file (by its extension)")
        raise InputError(f"{target}: no photos found")
    start = time.perf_counter()
    styles = load_styles_with_progress(opts, style_args)
    out.mkdir(parents=True, exist_ok=True)  # only once the styles are known to load
    result = run_with_progress(plan, styles, opts, consistent=consistent, jobs=jobs,
                               scheduler=scheduler, report_dir=str(out),
                               write_outputs=False)
    result.time_s = time.perf_counter() - start
    path = write_report(out, result, styles, opts, "consistent" if consistent else "per-photo")
    print_summary(result, verb="reported")
    click.echo(f"report: {path.parent / 'index.html'}")
    if result.count("failed"):
        ctx.exit(1)
