"""``wbcgrade report``: which styles make up the grade of each photo (nothing is graded on disk)."""

from __future__ import annotations

import click

from wbcgrade.cli.batch import batch_progress, print_summary, warn_fit_bins
from wbcgrade.cli.grading_options import (
    LazyOptionsCommand,
    check_photo,
    grading_options,
    space_options,
    table_options,
    take_grading_options,
)


@click.command("report", cls=LazyOptionsCommand)
@click.argument("target", metavar="PHOTO_OR_DIR",
                type=click.Path(path_type=str))  # the library checks it (exit 1)
@table_options("out_dir", help="Report folder [default: <name>_report beside PHOTO_OR_DIR].")
@grading_options
@space_options
@table_options("recursive")
@table_options("consistent", help="Report the one series grade (pooled palette) instead of "
                                  "one fit per photo.")
@table_options("jobs", help="Fit photos in N local processes.")
@table_options("scheduler")
@table_options("overwrite", help="Replace the files of an existing report in the report folder.")
@click.pass_context
def report(ctx, target, out_dir, recursive, consistent, jobs, scheduler, overwrite,
           **kwargs):
    """What the grade does to a photo or a folder (weights with --mode palette).

    Writes REPORT_DIR/report.json (per photo: what the grade did: its
    source, strength and the photo's change; for a palette grade also the
    weights sorted with style names, the fitted loss and the loss of the
    best single style, the number of weights >= 0.001; the time),
    weights.csv (one row a photo: a palette grade's weights, one column a
    style, then the grade's source, strength and change), a PNG sheet per
    photo in sheets/ and index.html.
    """
    check_photo(target, "no such file or folder")  # (exit 1, before numpy loads)
    from wbcgrade.batch.recorded import report_recorded

    options, source = take_grading_options(kwargs)
    warn_fit_bins(options)
    with batch_progress("reported") as progress:
        # a batch's output folder: its results read (the grade's modules never load)
        result = report_recorded(target, out_dir, source, options, recursive=recursive,
                                 overwrite=overwrite, jobs=jobs, progress=progress)
        if result is None:
            from wbcgrade.batch import report_folder

            result = report_folder(target, out_dir, source, options, recursive=recursive,
                                   consistent=consistent, overwrite=overwrite, jobs=jobs,
                                   scheduler=scheduler, progress=progress)
    print_summary(result, verb="reported")
    click.echo(f"report: {result.report.parent / 'index.html'}")
    if result.count("failed"):
        ctx.exit(1)
