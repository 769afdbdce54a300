"""``wbcgrade video``: grade a clip with one grade per clip (or per shot), applied by ffmpeg."""

from __future__ import annotations

import json

import click

from wbcgrade.cli.grading_options import (
    LazyOptionsCommand,
    grading_options_except,
    lazy_options,
    look_option,
    lut_size_option,
    table_options,
    take_grading_options,
    take_look,
)
from wbcgrade.cli.option_table import flag_of, flag_text

#: Grading options a LUT cannot carry (regrain looks at each pixel's neighbours).
_NOT_FOR_VIDEO = ("regrain", "regrain_radius", "regrain_eps")


def _warn(message: str) -> None:
    click.echo(f"Warning: {flag_text(message)}", err=True)


def _print_result(result, as_json: bool) -> None:
    if as_json:
        click.echo(json.dumps(result.as_dict(), indent=2, default=float))
        return
    info = result.info
    kinds = {kind: info.streams.count(kind) for kind in info.streams}
    streams = ", ".join(f"{count} {kind}" for kind, count in kinds.items())
    fps = f"{info.fps:.3f}".rstrip("0").rstrip(".")
    click.echo(f"{info.path.name}: {info.width}x{info.height}, {fps} fps, {info.frames} frames "
               f"({info.duration:.1f} s), {info.pix_fmt} pixels, streams: {streams}")
    encoding = result.encoding
    from wbcgrade.color.colorspace import default_working_space

    if encoding is not None and (encoding.input != encoding.working
                                 or encoding.working != default_working_space()):
        click.echo(f"colour: {encoding.input} ({encoding.source}), graded in {encoding.working}")
    for number, shot in enumerate(result.shots, start=1):
        outcome = shot.grade.outcome
        if outcome is not None and outcome.palette is None:  # a look: no weights to show
            where = f"shot {number} (frames {shot.first}-{shot.last}) " \
                if len(result.shots) > 1 else ""
            for line in outcome.lines("this clip" if len(result.shots) == 1 else "the shot"):
                click.echo(where + line)
            continue
        ranked = ", ".join(f"{n} {w:.3f}" for n, w in shot.grade.ranked()[:6])
        where = (f"shot {number} (frames {shot.first}-{shot.last})" if len(result.shots) > 1
                 else "weights")
        click.echo(f"{where}: {ranked}  (loss {shot.fit.loss:.4g}, "
                   f"{len(shot.samples)} sampled frames)")
        if not shot.fit.converged:
            _warn("the weight fit stopped before converging (raise --max-iter)")
    stages = ", ".join(f"{k} {v:.2f}s" for k, v in result.timings.items() if k != "total")
    click.echo(f"time: {stages} (total {result.timings['total']:.1f}s)")
    written = [str(result.output), *map(str, result.luts)]
    click.echo(f"wrote {', '.join(written)} ({result.encoder}, {result.pix_fmt})")


@click.command("video", cls=LazyOptionsCommand)
@click.argument("clip", type=click.Path(path_type=str))  # the library checks it (exit 1)
@table_options("output", help="Graded clip [default: <stem>_graded.<ext> beside CLIP].")
@grading_options_except(*_NOT_FOR_VIDEO)
@table_options("per_shot")
@table_options("sample_every", "cut_threshold", "blend_frames", "codec", "crf")
@table_options("lut", help="Also write the grade as a 3-D LUT (.cube); with several shots, "
                           "<stem>_shotNN.cube per shot.")
@lazy_options(lut_size_option)
@lazy_options(look_option)
@table_options("input_space",
               help="Colour space of the clip's code values (an OpenColorIO name, alias or "
                    "role, or srgb, display-p3, linear-rec709, acescct, ...; case ignored) "
                    "[default: from its tags: PQ (smpte2084) with BT.2020 primaries is the "
                    "config's Rec.2100-PQ space; BT.709, BT.601, untagged and other SDR "
                    "footage sRGB code values; HLG needs this option].")
@table_options("working_space",
               help="Colour space whose unit cube the histograms, the transport and the "
                    "colour map live in, e.g. acescct [default: sRGB-encoded Rec.709]; the "
                    "LUT ffmpeg applies is baked in the input space. Config: $OCIO, else "
                    "OpenColorIO's built-in ocio://default.")
@table_options("overwrite", help="Replace existing output files (never CLIP).")
@table_options("as_json")
@table_options("report_dir", help="Also write a contact sheet per shot (sampled frames before "
                                  "and after, what the grade did, palettes) and report.json "
                                  "into this folder.")
@click.pass_context
def video(ctx, clip, output, per_shot, sample_every, cut_threshold, blend_frames, codec, crf,
          lut, lut_size, look_path, overwrite, as_json, report_dir, **kwargs):
    """Grade CLIP with the look of a preset or of style photos, one grade per clip or shot.

    Frames sampled every --sample-every seconds are pooled into one palette
    (as `batch --consistent` pools photos), the grade is made once (the look,
    or with --mode palette the fitted blend of the style palettes) and
    the grade's colour map is applied to every frame by ffmpeg as a 3-D LUT
    (lut3d, tetrahedral): one grade for the whole clip, no flicker. Audio and
    other streams are copied; frame rate, pixel format and colour tags are
    kept. The output is written atomically and CLIP is never replaced.

    Colour management: --working-space (e.g. acescct) fits the grade in
    another space; the LUT is baked in the clip's own encoding (--input-space,
    else its tags: HDR PQ footage is Rec.2100-PQ, SDR footage sRGB code values).
    """
    from wbcgrade.color.options import flat_defaults

    defaults = flat_defaults()  # a LUT has no regrain
    kwargs.update(regrain=False, regrain_radius=defaults["regrain_radius"],
                  regrain_eps=defaults["regrain_eps"])
    options, source = take_grading_options(kwargs, photo=clip)  # checked before numpy loads
    from tqdm import tqdm

    from wbcgrade.cli._progress import bar_callbacks
    from wbcgrade.video.command import grade_clip
    from wbcgrade.video.workflow import VideoProgress, VideoSettings

    look = take_look(ctx, look_path, kwargs, options)
    settings = VideoSettings(per_shot=per_shot, sample_every=sample_every,
                             cut_threshold=cut_threshold, blend=blend_frames, codec=codec,
                             crf=crf, lut_size=lut_size)
    with tqdm(desc="styles", disable=None, leave=False) as bar:
        current = {"pass": None}

        def on_frames(name, done, total):  # one bar over frames, per ffmpeg pass
            if current["pass"] != name:
                current["pass"] = name
                bar.reset(total=total)
                bar.set_description(name)
            bar.total = max(total, done)
            bar.update(done - bar.n)

        callbacks = bar_callbacks(bar)
        stage = callbacks.pop("stage")

        def on_stage(name):
            if name not in ("scan", "encode"):
                stage(name)

        progress = VideoProgress(warn=_warn, setting_names=flag_of, frames=on_frames,
                                 stage=on_stage, **callbacks)
        result = grade_clip(clip, output, source, options, settings=settings, lut=lut,
                            overwrite=overwrite, report_dir=report_dir, progress=progress,
                            look=look)
    _print_result(result, as_json)
    if result.report is not None and not as_json:
        click.echo(f"report: {result.report}")
