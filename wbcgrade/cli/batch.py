"""``wbcgrade batch``: grade every photo of a folder (and the progress bars ``report`` shares)."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING

import click

from wbcgrade.cli.grading_options import (
    LazyOptionsCommand,
    check_photo,
    grading_options,
    lazy_options,
    look_option,
    lut_format_option,
    lut_size_option,
    space_options,
    table_options,
    take_grading_options,
    take_look,
    take_write_options,
    write_options,
)
from wbcgrade.cli.option_table import flag_of, flag_text

if TYPE_CHECKING:  # the colour library imports the core: only inside the commands
    from wbcgrade.batch import BatchProgress, BatchResult, FileResult
    from wbcgrade.color.options import GradeOptions


def _warn(message: str) -> None:
    click.echo(f"Warning: {flag_text(message)}", err=True)


#: Weights shown on a photo's line (the largest ones).
SHOWN_WEIGHTS = 4


def photo_line(result: FileResult, verb: str = "graded") -> str:
    """One line about a finished photo: what happened, its name, and for a graded one
    what the grade did (a palette grade: its largest weights and the fit's loss) and the
    time it took. ``verb`` says what was done to a graded photo ("reported": `report`
    drew it, the time is its grade's)."""
    if result.status == "skipped":
        return f"skipped  {result.relative} (its output is complete)"
    took = result.timings.get("total", 0.0)
    # a report says how long the grade took, not how long the report did
    took = f"{took:.1f} s" if verb == "graded" else f"(graded in {took:.1f} s)"
    if result.status != "graded":
        return f"{result.status:<8} {result.relative}: {result.error}"
    outcome = result.grade_outcome
    if outcome is not None and outcome.palette is None:  # a look: no weights to show
        from wbcgrade.color.outcome import change_words

        what, strength = outcome.source_words()
        strength_words = "" if strength is None else f", strength {strength:.2f}"
        said = f"{what}{strength_words}, colours move {change_words(outcome.mean_change)}"
        if outcome.unchanged:
            said += f" (essentially unchanged: {outcome.reason})"
        return f"{verb:<8} {result.relative}: {said}  {took}"
    ranked = sorted(zip(result.names, result.weights), key=lambda pair: -pair[1])
    shown = ", ".join(f"{name} {weight:.3f}" for name, weight in ranked[:SHOWN_WEIGHTS]
                      if weight >= 0.0005)
    rest = sum(weight >= 0.0005 for _, weight in ranked[SHOWN_WEIGHTS:])
    if rest:
        shown += f" (+{rest} more)"
    loss = "" if result.loss is None else f"  loss {result.loss:.4g}"
    return f"{verb:<8} {result.relative}: {shown}{loss}  {took}"


@contextlib.contextmanager
def batch_progress(verb: str = "graded") -> Iterator[BatchProgress]:
    """Two tqdm bars: photos (with the failures counted), and what the work done in this
    process is doing (the photo's name and stage, or the series' palettes being read).
    Each finished photo also gets a line on stdout (:func:`photo_line`; above the bars
    on a terminal, the record of the run in a log), and a photo graded towards its own
    palette a warning."""
    from tqdm import tqdm

    from wbcgrade.cli._progress import bar_callbacks
    from wbcgrade.color.presets import own_style_warning
    from wbcgrade.photos.progress import BatchProgress

    with tqdm(desc="photos", unit="photo", disable=None, position=0) as files, \
            tqdm(desc="styles", disable=None, leave=False, position=1) as bar:
        failed = []

        def on_result(result):
            if result.status == "failed":
                failed.append(result.relative)
                files.set_postfix(failed=len(failed), refresh=False)
            tqdm.write(photo_line(result, verb), file=sys.stdout)
            if result.own_style:
                tqdm.write("Warning: " + own_style_warning(
                    result.relative, result.own_style,
                    palette=not result.outcome or result.has_weights), file=sys.stderr)
            files.update(1)

        def on_planned(total):
            files.total = total
            files.refresh()

        def on_read(done, total):
            bar.set_description("reading the photos' palettes")
            bar.total = total
            bar.n = done
            bar.refresh()

        yield BatchProgress(warn=_warn, setting_names=flag_of, planned=on_planned,
                            result=on_result, read=on_read,
                            **bar_callbacks(bar, photos=True))


def warn_fit_bins(options: GradeOptions) -> None:
    if options.fit.bins > 32:
        _warn(f"--fit-bins {options.fit.bins}: fits on large grids take minutes per photo "
              "(default 16)")


def print_summary(result: BatchResult, verb: str = "graded") -> None:
    """One summary line, then the failures and the ignored files."""
    line = (f"{verb} {result.count('graded')}, skipped {result.count('skipped')}, "
            f"failed {result.count('failed')} in {result.time_s:.1f} s")
    if result.ignored:
        line += f" ({len(result.ignored)} non-image file{'s' * (len(result.ignored) > 1)} ignored)"
    click.echo(line)
    if result.own_photos and result.count("graded"):
        click.echo(f"content: the look was measured against {result.own_photos} photos of the "
                   "folder beside the shipped palettes (--natural shipped: the shipped palettes "
                   "alone)")
    for item in result.results:
        if item.status == "failed":
            click.echo(f"  failed   {item.relative}: {item.error}")
    for name in result.ignored:
        click.echo(f"  ignored  {name} (not an image)")
    outcome = None if result.series_grade is None else result.series_grade.outcome
    if outcome is not None and outcome.palette is None:
        click.echo("series grade: " + outcome.headline("the series").removeprefix("grade: "))
    elif result.series is not None:
        ranked = sorted(zip(result.style_names, result.series.weights), key=lambda p: -p[1])
        click.echo("series weights: " + ", ".join(f"{n} {w:.3f}" for n, w in ranked[:6]))


@click.command("batch", cls=LazyOptionsCommand)
@click.argument("in_dir", type=click.Path(path_type=str))  # the library checks it (exit 1)
@table_options("out_dir", required=True,
               help="Folder for the graded copies (the input tree is mirrored).")
@grading_options
@space_options
@table_options("recursive")
@table_options("consistent", help="One grade for the whole series: one fit on the pooled "
                                  "palette of all photos and one colour map for every photo "
                                  "(costs about one fit).")
@table_options("overwrite", help="Replace existing outputs: redo photos whose output is already "
                                 "complete (and replace an existing --lut file).")
@table_options("force_alias")
@table_options("jobs")
@table_options("scheduler",
               help="Send the photos to a Dask distributed scheduler (e.g. tcp://host:8786); "
                    "needs `pip install 'wbcgrade[dask]'` and the same paths on the workers.")
@table_options("report_dir", help="Also write the palette weight report into this folder.")
@table_options("lut", help="With --consistent: also write the series grade as a 3-D LUT (.cube "
                           "or .clf; its header names the colour spaces).")
@lazy_options(lut_size_option)
@lazy_options(lut_format_option)
@lazy_options(look_option)
@lazy_options(write_options)
@click.pass_context
def batch(ctx, in_dir, out_dir, recursive, consistent, overwrite, force_alias, jobs, scheduler,
          report_dir, lut, lut_size, lut_format, look_path, **kwargs):
    """Grade every photo in IN_DIR into OUT_DIR, keeping formats, bit depth and metadata.

    Each photo gets its own grade (the preset's or the style photos' look,
    or with --mode palette its own blend of their palettes), or with
    --consistent the whole series shares one. Outputs are written atomically; a rerun skips
    photos whose output is complete (--overwrite redoes them) and removes the
    temporary files of a killed run. One run at a time may write into OUT_DIR.
    Files that are not images (by extension) are ignored; unreadable photos
    and failed writes (e.g. a full disk) are reported and make the exit
    status 1. --look FILE applies a saved grade (the JSON of `apply --save-grade`,
    or a LUT) to every photo with no fit.
    """
    check_photo(in_dir, "no such file or folder")  # (exit 1, before numpy loads)
    from wbcgrade.batch import grade_folder

    if force_alias:
        _warn("--force is deprecated; use --overwrite")
    encode = take_write_options(kwargs)
    options, source = take_grading_options(kwargs)
    look = take_look(ctx, look_path, kwargs, options)
    if look is None:
        warn_fit_bins(options)
    with batch_progress() as progress:
        result = grade_folder(in_dir, out_dir, source, options, recursive=recursive,
                              consistent=consistent, overwrite=overwrite or force_alias,
                              jobs=jobs, scheduler=scheduler, report_dir=report_dir, lut=lut,
                              lut_size=lut_size, lut_format=lut_format, progress=progress,
                              look=look, encode=encode)
    if result.report is not None:
        click.echo(f"report: {result.report.parent / 'index.html'}")
    print_summary(result)
    if lut is not None:
        if result.lut is None:
            click.echo("LUT not written: no photo was graded (use --overwrite to redo the "
                       "series)")
        else:
            click.echo(f"wrote {lut}")
    if result.count("failed"):
        ctx.exit(1)
