"""``wbcgrade apply``: grade a photo towards the closest barycenter of style palettes."""

from __future__ import annotations

import json

import click

from wbcgrade.cli.grading_options import (
    LazyOptionsCommand,
    grading_options,
    lazy_options,
    look_option,
    lut_format_option,
    lut_size_option,
    space_options,
    take_grading_options,
    take_look,
    take_write_options,
    write_options,
)


def _warn(message: str) -> None:
    click.echo(f"Warning: {message}", err=True)


def _print_report(report, as_json: bool) -> None:
    if as_json:
        # the grade itself rides along: `apply --look` reads this JSON back without a fit
        click.echo(json.dumps(report.as_dict(saved_grade=True), indent=2))
        return
    grade = report.grade
    fit = grade.info.get("fit", {})
    start = report.fit_start
    if start != "preset":  # a preset's own look has no weights to speak of
        ranked = grade.ranked()
        width = max(len("style"), *(len(name) for name, _ in ranked))
        click.echo(f"{'style':<{width}}  weight")
        click.echo(f"{'-' * width}  ------")
        for name, weight in ranked:
            click.echo(f"{name:<{width}}  {weight:6.3f}")
    if start == "saved":
        saved = grade.info.get("saved_look", {})
        regrain = "regrained" if grade.regrain is not None else "no regrain"
        click.echo(f"grade: {saved.get('file')} applied as saved ({saved.get('kind')}, "
                   f"{regrain}; no fit)")
    elif start in ("preset", "scene", "look"):
        _print_look(start, grade.info.get("look", {}), len(grade.names))
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


def _print_look(start: str, look: dict, n_styles: int) -> None:
    if start == "preset":
        click.echo("look: the preset's own look, applied as it is")
    elif start == "scene":
        click.echo(f"look: read off the style photo of this scene ({look.get('match')}, "
                   f"confidence {look.get('confidence', 0):.2f})")
    else:
        confidence = look.get("confidence", 0.0)
        towards = (f", moved towards the palette grade of {look.get('match')} "
                   f"(confidence {confidence:.2f})" if confidence > 0 else "")
        click.echo(f"look: the look the {n_styles} styles share{towards}")


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
@lazy_options(look_option)
@lazy_options(write_options)
@click.option("--overwrite", is_flag=True, help="Replace existing output files (never PHOTO).")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("--report", "report_dir", type=click.Path(file_okay=False, path_type=str),
              default=None, help="Also write a palette weight report (JSON, CSV, PNG sheet, "
              "index.html) into this folder.")
@click.pass_context
def apply(ctx, photo, output, lut, lut_size, lut_format, look_path, overwrite, as_json,
          report_dir, **kwargs):
    """Grade PHOTO towards the barycenter of style palettes closest to its own.

    The style palettes come from a folder of photos (--style DIR) or a preset
    (--preset NAME_OR_FILE). The photo keeps its format, bit depth, EXIF and
    ICC profile. By default 8/16-bit photos are graded as sRGB (or the space
    their ICC profile names, converted) and float (EXR) photos in the
    sRGB-encoded domain; values above 1 keep their intensity and get the
    grade of their hue. --working-space (e.g. acescct) grades elsewhere;
    the output stays in the photo's own space. Raw camera files (DNG, CR2,
    NEF, ARW, ...) are demosaiced by LibRaw and graded in ACEScct. --look
    FILE applies a saved grade (the JSON of `apply --json`, or a LUT) with
    no fit.
    """
    from tqdm import tqdm

    from wbcgrade.cli._progress import bar_callbacks
    from wbcgrade.color.workflow import Progress, apply_photo

    encode = take_write_options(kwargs)
    options, source = take_grading_options(kwargs)
    look = take_look(ctx, look_path, kwargs, options)
    if look is None and options.fit.bins > 32:
        _warn(f"--fit-bins {options.fit.bins}: fits on large grids take minutes (default 16)")
    with tqdm(desc="styles" if look is None else "look", disable=None, leave=False) as bar:
        progress = Progress(warn=_warn, **bar_callbacks(bar))
        report = apply_photo(photo, source if look is None else look, options, output, lut,
                             lut_size, lut_format, overwrite, report_dir, progress, encode)
    if "own_style" in report.grade.info:
        from wbcgrade.color.presets import own_style_warning

        _warn(own_style_warning(str(photo), report.grade.info["own_style"]))
    _print_report(report, as_json)
    if report.report is not None and not as_json:
        click.echo(f"report: {report.report}")
