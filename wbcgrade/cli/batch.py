"""``wbcgrade batch``: grade every photo of a folder (and the runner ``report`` shares)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

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
from wbcgrade.errors import InputError

if TYPE_CHECKING:  # the colour library imports the core: only inside the commands
    from wbcgrade.color.batch import BatchPlan, BatchResult
    from wbcgrade.color.presets import StyleSet
    from wbcgrade.color.transfer import GradeOptions


def _warn(message: str) -> None:
    click.echo(f"Warning: {message}", err=True)


def load_styles_with_progress(opts: GradeOptions, style_args: dict) -> StyleSet:
    """Load the style set with a progress bar over style photos."""
    from wbcgrade.cli._progress import load_styles_with_bar

    if opts.fit_bins > 32:
        _warn(f"--fit-bins {opts.fit_bins}: fits on large grids take minutes per photo "
              "(default 16)")
    styles = load_styles_with_bar(opts, style_args, _warn)
    opts.validate(len(styles.names))
    return styles


def run_with_progress(plan: BatchPlan, styles: StyleSet, opts: GradeOptions, *,
                      consistent: bool, jobs: int, scheduler: str | None,
                      report_dir: str | None, write_outputs: bool) -> BatchResult:
    """Run a batch with a tqdm bar over files (and one over the fit stages in-process)."""
    from tqdm import tqdm

    from wbcgrade.color.batch import BatchContext, run_batch

    if jobs < 1:
        raise InputError("--jobs must be at least 1")
    context = BatchContext(styles=styles, opts=opts,
                           sheet_dir=None if report_dir is None else Path(report_dir),
                           write_outputs=write_outputs)
    if report_dir is not None:
        from wbcgrade.color.report import style_pictures

        Path(report_dir).mkdir(parents=True, exist_ok=True)
        context.style_pictures = style_pictures(styles)
    total = len(plan.tasks) + len(plan.done)
    local = scheduler is None and jobs == 1
    with tqdm(total=total, desc="photos", unit="photo", disable=None, position=0) as files, \
            tqdm(desc="fit", unit="eval", disable=None, leave=False, position=1) as fit_bar:
        failed = []

        def on_result(result):
            if result.status == "failed":
                failed.append(result.relative)
                files.set_postfix(failed=len(failed), refresh=False)
            files.update(1)

        def on_fit(n_eval, weights, value):
            fit_bar.update(1)
            fit_bar.set_postfix(loss=f"{value:.4g}")

        def on_read(done, total):
            fit_bar.set_description("palettes")
            fit_bar.total = total
            fit_bar.n = done
            fit_bar.refresh()

        def on_stage(name):
            if name in ("read", "fit"):
                fit_bar.reset()
            fit_bar.set_description(name)

        return run_batch(plan, context, consistent=consistent, jobs=jobs, scheduler=scheduler,
                         on_result=on_result,
                         fit_callback=on_fit if local or consistent else None,
                         stage=on_stage if local or consistent else None,
                         on_read=on_read)


def print_summary(result: BatchResult, verb: str = "graded") -> None:
    """One summary line, then the failures and the ignored files."""
    line = (f"{verb} {result.count('graded')}, skipped {result.count('skipped')}, "
            f"failed {result.count('failed')} in {result.time_s:.1f} s")
    if result.ignored:
        line += f" ({len(result.ignored)} non-image file{'s' * (len(result.ignored) > 1)} ignored)"
    click.echo(line)
    for item in result.results:
        if item.status == "failed":
            click.echo(f"  failed   {item.relative}: {item.error}")
    for name in result.ignored:
        click.echo(f"  ignored  {name} (not an image)")
    if result.series is not None:
        ranked = sorted(zip(result.style_names, result.series.weights), key=lambda p: -p[1])
        click.echo("series weights: " + ", ".join(f"{n} {w:.3f}" for n, w in ranked[:6]))


@click.command("batch", cls=LazyOptionsCommand)
@click.argument("in_dir", type=click.Path(exists=True, file_okay=False, path_type=str))
@click.option("-o", "--output-dir", "out_dir", required=True,
              type=click.Path(file_okay=False, path_type=str),
              help="Folder for the graded copies (the input tree is mirrored).")
@grading_options
@space_options
@click.option("-r", "--recursive", is_flag=True, help="Descend into sub-folders.")
@click.option("--consistent", is_flag=True,
              help="One grade for the whole series: one fit on the pooled palette of all "
                   "photos and one colour map for every photo (costs about one fit).")
@click.option("--overwrite", is_flag=True,
              help="Replace existing outputs: redo photos whose output is already complete "
                   "(and replace an existing --lut file).")
@click.option("--force", "force_alias", is_flag=True, hidden=True,
              help="Deprecated alias of --overwrite.")
@click.option("-j", "--jobs", type=int, default=1, show_default=True,
              help="Grade photos in N local processes.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Send the photos to a Dask distributed scheduler (e.g. tcp://host:8786); "
                   "needs `pip install 'wbcgrade[dask]'` and the same paths on the workers.")
@click.option("--report", "report_dir", type=click.Path(file_okay=False, path_type=str),
              default=None, help="Also write the palette weight report into this folder.")
@click.option("--lut", type=click.Path(dir_okay=False, path_type=str), default=None,
              help="With --consistent: also write the series grade as a 3-D LUT (.cube or "
                   ".clf; its header names the colour spaces).")
@lazy_options(lut_size_option)
@lazy_options(lut_format_option)
@click.pass_context
def batch(ctx, in_dir, out_dir, recursive, consistent, overwrite, force_alias, jobs, scheduler,
          report_dir, lut, lut_size, lut_format, **kwargs):
    """Grade every photo in IN_DIR into OUT_DIR, keeping formats, bit depth and metadata.

    Each photo gets its own barycentric coordinates, or with --consistent the
    whole series shares one. Outputs are written atomically; a rerun skips
    photos whose output is complete (--overwrite redoes them) and removes the
    temporary files of a killed run. One run at a time may write into OUT_DIR.
    Files that are not images (by extension) are ignored; unreadable photos
    and failed writes (e.g. a full disk) are reported and make the exit
    status 1.
    """
    from wbcgrade._publish import lock_folder
    from wbcgrade.color.batch import (
        batch_settings,
        plan_batch,
        recheck_plan,
        settings_changed,
        write_settings,
    )
    from wbcgrade.color.imageio import check_output_path
    from wbcgrade.color.lut import check_clf_support, check_lut_path, write_grade_lut

    if force_alias:
        _warn("--force is deprecated; use --overwrite")
    overwrite = overwrite or force_alias
    opts, style_args = take_grading_options(kwargs)
    if lut is not None:
        if not consistent:
            raise InputError("--lut needs --consistent (one grade for the series); per-photo "
                             "LUTs come from `wbcgrade apply --lut`")
        check_lut_path(lut, lut_format)
        if lut_format == "clf":
            check_clf_support()
        if Path(lut).exists() and not overwrite:
            raise InputError(f"{lut}: file exists (use --overwrite to replace it)")
        check_output_path(lut, overwrite=True)  # folder, writability, a regular file
        if not 2 <= lut_size <= 256:
            raise InputError("--lut-size must be between 2 and 256")
    plan = plan_batch(in_dir, out_dir, recursive=recursive, overwrite=overwrite,
                      exclude=[report_dir] if report_dir else [])
    if not plan.tasks and not plan.done:
        raise InputError(f"{in_dir}: no photos found" + ("" if recursive else
                                                         " (use --recursive for sub-folders)"))
    try:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out_dir}: cannot create the output folder ({exc.strerror})") from None
    with lock_folder(out_dir, "batch"):  # one run at a time per output folder
        plan = recheck_plan(plan, overwrite)  # a run that held the lock may have finished some
        start = time.perf_counter()
        styles = load_styles_with_progress(opts, style_args)
        settings = batch_settings(styles, opts, consistent)
        changed = settings_changed(out_dir, settings)
        if changed and plan.done:
            _warn(f"{len(plan.done)} finished output(s) in {out_dir} were made with other "
                  f"settings ({', '.join(changed[:4])}); they are kept — use --overwrite to redo "
                  "them")
        result = run_with_progress(plan, styles, opts, consistent=consistent, jobs=jobs,
                                   scheduler=scheduler, report_dir=report_dir,
                                   write_outputs=True)
        if result.count("graded"):
            write_settings(out_dir, settings)
        result.time_s = time.perf_counter() - start
        if report_dir is not None:
            from wbcgrade.color.report import write_report

            path = write_report(report_dir, result, styles, opts,
                                "consistent" if consistent else "per-photo")
            click.echo(f"report: {path.parent / 'index.html'}")
        print_summary(result)
        if lut is not None:
            grade = result.series_grade
            if grade is None:
                click.echo("LUT not written: no photo was graded (use --overwrite to redo the "
                           "series)")
            else:
                from wbcgrade.color.colorspace import spaces_for

                ranked = ", ".join(f"{n} {w:.3f}" for n, w in grade.ranked())
                write_grade_lut(lut, grade.color_map, spaces_for(None, opts.working_space),
                                lut_size, grade.strength, lut_format,
                                title=f"wbcgrade series {Path(in_dir).name}",
                                comments=[f"wbcgrade series grade of {in_dir}: {ranked}"],
                                overwrite=True)
                click.echo(f"wrote {lut}")
    if result.count("failed"):
        ctx.exit(1)
