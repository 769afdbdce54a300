"""``wbcgrade apply``: grade a photo towards the closest barycenter of style palettes."""

from __future__ import annotations

import json
import time

import click

from wbcgrade.cli.grading_options import (
    LazyOptionsCommand,
    grading_options,
    lazy_options,
    lut_format_option,
    lut_size_option,
    space_options,
    take_grading_options,
)


def _warn(message: str) -> None:
    click.echo(f"Warning: {message}", err=True)


def _print_report(report, as_json: bool) -> None:
    if as_json:
        click.echo(json.dumps(report.as_dict(), indent=2))
        return
    grade = report.grade
    ranked = grade.ranked()
    width = max(len("style"), *(len(name) for name, _ in ranked))
    click.echo(f"{'style':<{width}}  weight")
    click.echo(f"{'-' * width}  ------")
    for name, weight in ranked:
        click.echo(f"{name:<{width}}  {weight:6.3f}")
    fit = grade.info.get("fit", {})
    start = report.fit_start
    if grade.loss is None:
        click.echo("loss: - (weights given with --weights)")
    elif start == "given":
        click.echo(f"loss: {grade.loss:.4g} at the weights given with --weights")
    else:
        how = {"uniform": "fitted from uniform weights",
               "vertex-refit": "refitted from the best single style, which beat the fit "
                               "from uniform weights",
               "vertex": "the best single style: no fit beat it"}.get(start, start)
        click.echo(f"loss: {grade.loss:.4g} ({how}; {fit.get('evaluations', 0)} evaluations)")
        if not fit.get("converged", True):
            _warn("the weight fit stopped before converging (raise --max-iter)")
    sink = grade.info.get("sinkhorn", {})
    if sink and not sink.get("converged", True):
        _warn(f"the transfer Sinkhorn stopped at marginal error {sink['error']:.2g}")
    stages = ", ".join(f"{k} {v:.2f}s" for k, v in report.timings.items() if k != "total")
    click.echo(f"time: {stages} (total {report.timings['total']:.1f}s)")
    click.echo(f"wrote {report.output}" + (f" and {report.lut}" if report.lut else ""))


@click.command("apply", cls=LazyOptionsCommand)
@click.argument("photo", type=click.Path(dir_okay=False, path_type=str))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=str), default=None,
              help="Output photo [default: <stem>_graded.<ext> beside PHOTO].")
@grading_options
@space_options
@click.option("--lut", type=click.Path(dir_okay=False, path_type=str), default=None,
              help="Also write the grade as a 3-D LUT (.cube or .clf; its header names the "
                   "colour spaces it expects and produces).")
@lazy_options(lut_size_option)
@lazy_options(lut_format_option)
@click.option("--overwrite", is_flag=True, help="Replace existing output files (never PHOTO).")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("--report", "report_dir", type=click.Path(file_okay=False, path_type=str),
              default=None, help="Also write a palette weight report (JSON, CSV, PNG sheet, "
              "index.html) into this folder.")
def apply(photo, output, lut, lut_size, lut_format, overwrite, as_json, report_dir, **kwargs):
    """Grade PHOTO towards the barycenter of style palettes closest to its own.

    The style palettes come from a folder of photos (--style DIR) or a preset
    (--preset NAME_OR_FILE). The photo keeps its format, bit depth, EXIF and
    ICC profile. By default 8/16-bit photos are graded as sRGB (or the space
    their ICC profile names, converted) and float (EXR) photos in the
    sRGB-encoded domain; values above 1 keep their intensity and get the
    grade of their hue. --working-space (e.g. acescct) grades elsewhere;
    the output stays in the photo's own space.
    """
    from tqdm import tqdm

    from wbcgrade.cli._progress import load_styles_with_bar
    from wbcgrade.color.pipeline import check_outputs, grade_file

    opts, style_args = take_grading_options(kwargs)
    if opts.fit_bins > 32:
        _warn(f"--fit-bins {opts.fit_bins}: fits on large grids take minutes (default 16)")
    check_outputs(photo, output, lut, lut_size, overwrite, lut_format)
    if lut is not None and lut_format == "clf":
        from wbcgrade.color.lut import check_clf_support

        check_clf_support()  # before any work
    start = time.perf_counter()
    styles = load_styles_with_bar(opts, style_args, _warn)
    timings = {"styles": time.perf_counter() - start}

    with tqdm(desc="fit", unit="eval", disable=None, leave=False) as bar:
        def on_fit(n_eval, weights, value):
            bar.update(1)
            bar.set_postfix(loss=f"{value:.4g}")

        def on_stage(name):
            bar.set_description(name)

        report = grade_file(photo, styles, opts, output=output, lut=lut, lut_size=lut_size,
                            overwrite=overwrite, fit_callback=on_fit, stage=on_stage,
                            timings=timings, lut_format=lut_format)
    _print_report(report, as_json)
    if report_dir is not None:
        from wbcgrade.color.report import report_from_grade

        written = report_from_grade(report_dir, report, styles, opts)
        if not as_json:
            click.echo(f"report: {written}")
