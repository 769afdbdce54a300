"""``wbcgrade apply``: grade a photo with the look of a preset or of style photos."""

from __future__ import annotations

import json
import os
import time

import click

from wbcgrade.cli.grading_options import (
    LazyOptionsCommand,
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


def _warn(message: str) -> None:
    click.echo(f"Warning: {flag_text(message)}", err=True)


def _wall_timings(report, started: float, graded_from: float, learned: float = 0.0) -> None:
    """The report's times with start-up (the command's start to the grade's, less the
    ``learned`` seconds a look took to learn from --originals) first and the total the wall
    time since the command started (:func:`wbcgrade.cli._clock.command_started`)."""
    import time

    total = time.perf_counter() - started
    stages = {k: v for k, v in report.timings.items() if k != "total"}
    learn = {"learning the look": learned} if learned else {}
    report.timings = {"start-up": graded_from - started - learned, **learn, **stages,
                      "total": total}


def _print_report(report, as_json: bool) -> None:
    if as_json:  # a few KB: the grade itself goes to --save-grade FILE
        click.echo(json.dumps(report.as_dict(), indent=2, default=float))
        return
    grade, outcome = report.grade, report.outcome
    if outcome is not None and outcome.palette is not None:  # weights mean something here
        print_palette_fit(outcome.palette)
    if outcome is not None:
        for line in outcome.lines():
            click.echo(line)
    if grade.transport is not None and not grade.transport.converged:
        _warn(f"the transfer Sinkhorn stopped at marginal error {grade.transport.error:.2g}")
    stages = ", ".join(f"{k} {v:.2f}s" for k, v in report.timings.items() if k != "total")
    click.echo(f"time: {stages} (total {report.timings['total']:.1f}s)")
    click.echo(f"wrote {report.output}" + (f" and {report.lut}" if report.lut else ""))


def print_palette_fit(palette) -> None:
    """The weight table and the loss of a palette grade (:class:`PaletteFit`)."""
    from wbcgrade.color.outcome import FitStart

    width = max(len("style"), *(len(name) for name in palette.names))
    click.echo(f"{'style':<{width}}  weight")
    click.echo(f"{'-' * width}  ------")
    for name, weight in zip(palette.names, palette.weights):
        click.echo(f"{name:<{width}}  {weight:6.3f}")
    if palette.start is FitStart.GIVEN:
        click.echo(f"loss: {palette.loss:.4g} at the weights given with --weights")
        return
    how = {FitStart.UNIFORM: "fitted from uniform weights",
           FitStart.VERTEX_REFIT: "refitted from the best single style, which beat the fit "
                                  "from uniform weights",
           FitStart.VERTEX: "the best single style: no fit beat it"}.get(palette.start,
                                                                        palette.start.value)
    best = (f"; best single style {palette.best_single[0]} {palette.best_single[1]:.4g}"
            if palette.best_single is not None else "")
    click.echo(f"loss: {palette.loss:.4g} ({how}; {palette.evaluations} evaluations{best})")
    if not palette.converged:
        _warn("the weight fit stopped before converging (raise --max-iter)")


@click.command("apply", cls=LazyOptionsCommand)
@click.argument("photo", type=click.Path(path_type=str))  # the library checks it (exit 1)
@table_options("output", help="Output photo [default: <stem>_graded.<ext> beside PHOTO].")
@grading_options
@space_options
@table_options("lut", help="Also write the grade as a 3-D LUT (.cube or .clf; its header "
                           "names the colour spaces it expects and produces).")
@lazy_options(lut_size_option)
@lazy_options(lut_format_option)
@lazy_options(look_option)
@lazy_options(write_options)
@table_options("overwrite", help="Replace existing output files (never PHOTO).")
@table_options("as_json", help="Print the report as JSON (what the grade did; no colour map).")
@table_options("save_grade")
@table_options("report_dir", help="Also write a report (what the grade did; a palette grade's "
                                  "weights): JSON, CSV, a PNG sheet and index.html, into this "
                                  "folder.")
@click.pass_context
def apply(ctx, photo, output, lut, lut_size, lut_format, look_path, overwrite, as_json,
          save_grade, report_dir, **kwargs):
    """Grade PHOTO with the look of a preset or of a folder of style photos.

    PHOTO is the photo to grade (JPEG, PNG, TIFF, EXR or a camera raw file);
    it is only read. The look comes from a shipped preset (--preset), the
    style photos of a folder (--style DIR: the look they share, or the look of
    the one that shows PHOTO's own scene) or a saved grade (--look FILE). The
    graded copy keeps the photo's format, bit depth, EXIF and ICC profile; the
    terminal says where the look came from, its strength and how much the
    colours moved.

    --mode palette instead moves PHOTO's colours onto the closest blend of
    the style palettes (the barycentric weights are reported). By default
    8/16-bit photos are graded as sRGB (or the space their ICC profile
    names, converted) and float (EXR) photos in the sRGB-encoded domain;
    values above 1 keep their intensity and get the grade of their hue.
    --working-space (e.g. acescct) grades elsewhere; the output stays in the
    photo's own space. Raw camera files (DNG, CR2, NEF, ARW, ...) are
    demosaiced by LibRaw and graded in ACEScct. --look FILE applies a saved
    grade (the JSON of `apply --save-grade`, or a LUT) with no fit.
    """
    from wbcgrade.cli import _process
    from wbcgrade.cli._clock import command_started

    started = command_started()
    settle = _process.command_process()  # (not in a longer-lived process: its own settings)
    if settle:
        _process.single_blas_thread()  # (before numpy loads, with the options)
    options, source = take_grading_options(kwargs, photo=photo)
    if settle:  # one photo, then the process ends: its freed pages reused, 4 KB pages
        _process.keep_freed_memory()
        _process.no_huge_pages()
    encode = take_write_options(kwargs)
    read_ahead = None
    if look_path is None and not kwargs.get("originals_dir") and os.path.isfile(photo):
        # the photo decoded (and its keypoints found) on another core while the grade's
        # modules import and its styles load: the options are checked, the photo is there
        from wbcgrade.photos.read_ahead import ReadAhead

        read_ahead = ReadAhead.for_grade(photo, source, options)
    from wbcgrade.cli._progress import bar_callbacks, progress_bar
    from wbcgrade.photos.workflow import Progress, apply_photo

    learning = time.perf_counter() if kwargs.get("originals_dir") else None
    look = take_look(ctx, look_path, kwargs, options)
    learned = 0.0 if learning is None else time.perf_counter() - learning  # --originals
    if look is None and options.fit.bins > 32:
        _warn(f"--fit-bins {options.fit.bins}: fits on large grids take minutes (default 16)")
    graded_from = time.perf_counter()
    with progress_bar(desc="styles" if look is None else "look", leave=False) as bar:
        progress = Progress(warn=_warn, setting_names=flag_of, **bar_callbacks(bar))
        try:
            report = apply_photo(photo, source if look is None else look, options,
                                 output=output, lut=lut, lut_size=lut_size,
                                 lut_format=lut_format, overwrite=overwrite,
                                 report_dir=report_dir, progress=progress, encode=encode,
                                 save_grade=save_grade,
                                 read_ahead=read_ahead if look is None else None)
        except BaseException:
            if read_ahead is not None:  # (the process exits once its decoder is done)
                read_ahead.cancel()
            raise
    if report.grade.own_style is not None:
        from wbcgrade.color.presets import own_style_warning

        outcome = report.grade.outcome
        _warn(own_style_warning(str(photo), report.grade.own_style,
                                palette=outcome is None or outcome.palette is not None))
    _wall_timings(report, started, graded_from, learned)
    _print_report(report, as_json)
    if report.report is not None and not as_json:
        click.echo(f"report: {report.report}")
    if save_grade is not None and not as_json:
        click.echo(f"grade saved: {save_grade}")
