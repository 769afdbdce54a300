"""Grade a clip end to end: probe, sample, fit one grade per clip (or shot), one ffmpeg pass.

1. check every output first (:func:`plan_video`, through
   :func:`wbcgrade._publish.plan_outputs`), then
   :func:`~wbcgrade.video.ffmpeg.probe` the input (playlists and truncated
   files refused) and check the encoding with a trial pass of a few frames
   (:func:`check_encoding`: ffmpeg's own reason, lost size, streams or alpha
   refused, lost bit depth or field order said), all before the fit.
2. :func:`~wbcgrade.video.sampling.scan`: one small decoding pass keeps a
   frame every ``sample_every`` seconds (and finds the cuts with ``per_shot``).
3. Per shot (the whole clip by default), the sampled frames' palettes are
   pooled as ``batch --consistent`` pools photos (every frame counts once;
   :class:`~wbcgrade.color.histogram.PaletteSum`) and take the one grade
   path of photos: :func:`~wbcgrade.color.grade.grading.grade_histograms`
   (vertex-checked fit, palette, smooth colour map). The grade is its LUT:
   there is no regrain (a LUT sees one pixel at a time; ffmpeg applies it).
4. The LUTs are written as ``.cube`` files and scheduled over the frames
   (:mod:`wbcgrade.video.shots`: blended over ``blend`` frames at each cut);
   one ffmpeg pass decodes, converts to RGB with the clip's matrix and range,
   applies them with ``lut3d`` (tetrahedral), converts back to the input's
   pixel format and colour tags, and encodes, copying every other stream
   (audio, subtitles, data) as it is, into a temporary file beside the
   output; alpha is carried through (``lut3d`` on planar RGBA), interlaced
   frames keep their field order. The clip and its LUTs are published
   together (and with the report, :func:`wbcgrade.video.command.grade_clip`)
   only when everything was written and ffmpeg wrote every frame.

Colour spaces (:mod:`wbcgrade.video.spaces`): the sampled frames are
converted from the clip's input space (``opts.input_space``, else its tags)
into the working space (``opts.working_space``) before their histograms are
taken, the styles are converted into the working space, and each shot's LUT
is baked in the input encoding (what ``lut3d`` sees:
:meth:`wbcgrade.color.grade.grading.Grade.lut`). The ``video`` command's
workflow (outputs planned, styles loaded, the clip graded, the report
written) is :func:`wbcgrade.video.command.grade_clip`.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import secrets
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from wbcgrade._publish import atomic_path, is_unlocked, make_folders_for, plan_outputs
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import (
    Grade,
    PhotoHistograms,
    grade_histograms,
    grade_outcome,
    photo_histograms,
)
from wbcgrade.color.histogram import PaletteSum
from wbcgrade.color.mapping.lut import DEFAULT_LUT_SIZE, check_lut_size, write_cube
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.outcome import fit_start_word
from wbcgrade.color.palette.fit import FitSummary
from wbcgrade.color.presets import StyleSet, styles_in_space
from wbcgrade.errors import InputError, OptionError, WbcgradeError
from wbcgrade.photos.workflow import Progress
from wbcgrade.video.defaults import (
    ALPHA_CODECS,
    CODECS,
    DEFAULT_BLEND,
    DEFAULT_CODEC,
    DEFAULT_CRF,
    DEFAULT_CUT_THRESHOLD,
    DEFAULT_MIN_SHOT,
    DEFAULT_SAMPLE_EVERY,
)
from wbcgrade.video.ffmpeg import (
    FfmpegError,
    VideoInfo,
    encoder_pixel_formats,
    file_arg,
    from_rgb_filter,
    input_args,
    pixel_format,
    probe,
    run_pass,
    to_rgb_filter,
)
from wbcgrade.video.sampling import Samples, scan
from wbcgrade.video.shots import Segment, lut_schedule
from wbcgrade.video.spaces import clip_encoding, frame_to_working, lut_comments

__all__ = ["CODECS", "ALPHA_CODECS", "DEFAULT_CRF", "DEFAULT_BLEND", "VideoSettings",
           "VideoProgress", "ShotGrade", "VideoResult", "default_output", "plan_video",
           "shot_lut_paths", "shot_grade", "grade_video", "grade_planned", "encode_args",
           "check_encoding", "work_folder", "remove_stale_work_folders", "WORK_PREFIX"]



@dataclass(frozen=True)
class VideoSettings:
    """How a clip is sampled, cut and encoded (the grade's own settings are GradeOptions)."""

    per_shot: bool = False
    sample_every: float = DEFAULT_SAMPLE_EVERY
    cut_threshold: float = DEFAULT_CUT_THRESHOLD
    min_shot: float = DEFAULT_MIN_SHOT
    blend: int = DEFAULT_BLEND
    codec: str = DEFAULT_CODEC
    crf: int = DEFAULT_CRF
    lut_size: int = DEFAULT_LUT_SIZE

    def __post_init__(self) -> None:
        """Validated once, when made (OptionError naming the field)."""
        if self.codec not in CODECS:
            raise OptionError(f"{{codec}} must be one of {', '.join(CODECS)}", "codec")
        if not 0 <= self.crf <= 51:
            raise OptionError("{crf} must be between 0 and 51", "crf")
        check_lut_size(self.lut_size)
        if self.blend < 0:
            raise OptionError("{blend} must be 0 or more", "blend")
        if not (np.isfinite(self.sample_every) and self.sample_every > 0):
            raise OptionError("{sample_every} must be a positive number of seconds",
                              "sample_every")
        if not 0 < self.cut_threshold < 1:
            raise OptionError("{cut_threshold} must be between 0 and 1", "cut_threshold")


@dataclass
class ShotGrade:
    """One shot: its frames, the frames sampled from it and its grade."""

    first: int
    last: int
    samples: list[int]
    grade: Grade
    fit: FitSummary | None  # None: a saved grade (nothing fitted)
    table: np.ndarray

    def as_dict(self, fps: float) -> dict:
        """The shot, what its grade did (``outcome``) and, for a palette grade only, its
        weights and losses (a look grade has none that mean anything)."""
        outcome = self.grade.outcome
        entry = {"first_frame": self.first, "last_frame": self.last,
                 "start_s": round(self.first / fps, 4), "end_s": round((self.last + 1) / fps, 4),
                 "sampled_frames": self.samples,
                 "outcome": None if outcome is None else outcome.as_dict(),
                 "fit_start": fit_start_word(self.grade.source,
                                             None if self.fit is None else self.fit.start),
                 "timings_s": {k: round(v, 3) for k, v in self.grade.timings.items()}}
        if outcome is None or outcome.palette is not None:
            entry.update({
                "weights": [{"style": n, "weight": round(w, 6)} for n, w in self.grade.ranked()],
                "loss": self.fit.loss,
                "single_style_losses": dict(zip(self.grade.names,
                                                (float(v) for v in self.fit.vertex_losses))),
                "fit": self.grade.info.get("fit", {})})
        return entry


@dataclass
class VideoResult:
    """What :func:`grade_video` did (JSON-friendly via :meth:`as_dict`)."""

    input: Path
    output: Path
    luts: list[Path]
    info: VideoInfo
    settings: VideoSettings
    shots: list[ShotGrade]
    segments: list[Segment]
    samples: Samples
    timings: dict[str, float] = field(default_factory=dict)
    encoder: str = ""
    pix_fmt: str = ""
    encoding: ColorEncoding | None = None
    styles_space: str = ""
    report: Path | None = None

    def as_dict(self) -> dict:
        info = self.info
        return {
            "input": str(self.input), "output": str(self.output),
            "luts": [str(p) for p in self.luts],
            "video": {"width": info.width, "height": info.height, "fps": info.fps,
                      "frames": info.frames, "duration_s": info.duration,
                      "pix_fmt": info.pix_fmt, "codec": info.codec, "streams": info.streams,
                      "matrix": None if info.is_rgb else info.matrix, "range": info.range,
                      "tags": info.tags()},
            "encoding": {"encoder": self.encoder, "pix_fmt": self.pix_fmt,
                         "crf": self.settings.crf if self.settings.codec in ("x264", "x265")
                         else None},
            "settings": {k: v for k, v in vars(self.settings).items()},
            "cuts": list(self.samples.cuts),
            "shots": [shot.as_dict(info.fps) for shot in self.shots],
            "blends": [{"frame": s.first, "shots": list(s.shots), "mix": s.mix}
                       for s in self.segments if len(s.shots) == 2],
            "timings_s": {k: round(v, 3) for k, v in self.timings.items()},
            **({} if self.encoding is None else
               {"color": {**self.encoding.as_dict(), "styles_space": self.styles_space}}),
        }


def default_output(source: str | os.PathLike, codec: str = "x264") -> Path:
    """``<stem>_graded<ext>`` beside the clip, in a container the codec goes in."""
    path = Path(source)
    containers = CODECS[codec][1]
    suffix = path.suffix.lower() if path.suffix.lower() in containers else containers[0]
    return path.with_name(f"{path.stem}_graded{suffix}")


def plan_video(source: str | os.PathLike, output: str | os.PathLike | None,
               lut: str | os.PathLike | None, settings: VideoSettings,
               overwrite: bool = False,
               reads: Iterable[str | os.PathLike] = ()) -> tuple[Path, Path, Path | None]:
    """Check, before any work, that the outputs may be written -> (source, output, lut).

    The output (default :func:`default_output`) must be a container that
    holds the codec; the LUT a ``.cube``; both then pass
    :func:`wbcgrade._publish.plan_outputs` (never the input, never an
    existing file unless ``overwrite``, a regular file in a writable folder, made
    when missing, two different files). Resolved paths are returned. ``reads``: the other files
    the grade reads (styles, presets, a saved look), never replaced either.
    """
    source = Path(source)
    if not source.exists():
        raise InputError(f"{source}: no such file")
    output = Path(output) if output is not None else default_output(source, settings.codec)
    encoder, containers = CODECS[settings.codec]
    if output.suffix.lower() not in containers:
        raise OptionError(f"{output}: {{codec}} {settings.codec} needs one of "
                          f"{', '.join(containers)} as the output's extension", "codec",
                          path=output)
    if lut is not None and Path(lut).suffix.lower() != ".cube":
        raise OptionError(f"{lut}: {{lut}} file name must end in .cube", "lut", path=lut)
    output, lut = plan_outputs([output, lut], [source, *reads], overwrite, make_folders=True)
    return source, output, lut


def shot_lut_paths(lut: str | os.PathLike, n_shots: int) -> list[Path]:
    """Where ``--lut`` goes: the file itself for one grade, else ``<stem>_shotNN.cube`` per
    shot (NN from 01, in order)."""
    lut = Path(lut)
    if n_shots == 1:
        return [lut]
    return [lut.with_name(f"{lut.stem}_shot{k:02d}{lut.suffix}") for k in range(1, n_shots + 1)]


def shot_grade(frames: list[np.ndarray], styles: StyleSet, options: GradeOptions,
               encoding: ColorEncoding,
               callback: Callable[[int, np.ndarray, float], None] | None = None,
               stage: Callable[[str], None] | None = None) -> tuple[Grade, FitSummary]:
    """One grade for a list of (h, w, 3) uint8 frames: their pooled palette, one fit.

    Every frame counts once (as every photo of ``batch --consistent``). The
    frames are in ``encoding.input`` and graded in ``encoding.working`` (the
    styles must be there already), through the photos' grade path.
    """
    pool_fit, pool = PaletteSum(), PaletteSum()
    for frame in frames:  # (h, w, 4) with alpha: transparent pixels do not count
        alpha = frame[..., 3].astype(np.float32) / 255 if frame.shape[-1] == 4 else None
        hists = photo_histograms(frame_to_working(frame[..., :3], encoding), options, alpha)
        pool_fit.add(hists.fit)
        pool.add(hists.transfer)
    return grade_histograms(PhotoHistograms(pool_fit.result(), pool.result()), styles, options,
                            encoding, callback, stage)


def _family(pix_fmt: str) -> str:
    """"rgb", or the chroma layout of a Y'CbCr format (``yuv420``, ``yuv444``...), alpha or not."""
    if pix_fmt.startswith(("gbr", "bgr", "rgb", "argb", "abgr", "0rgb", "0bgr")):
        return "rgb"
    return pix_fmt.replace("yuva", "yuv").replace("yuvj", "yuv")[:6]


def _output_pix_fmt(info: VideoInfo, encoder: str) -> str:
    """The input's pixel format when the encoder takes it; else the nearest it takes: with
    alpha when the input has alpha, the same RGB or chroma layout where there is one, and
    the shallowest depth at least the input's (else the deepest)."""
    supported = list(encoder_pixel_formats(encoder))
    if not supported or info.pix_fmt in supported:
        return info.pix_fmt
    alpha = [f for f in supported if pixel_format(f)[2]]
    pool = alpha if info.alpha else ([f for f in supported if f not in alpha] or supported)
    family = "rgb" if info.is_rgb else _family(info.pix_fmt)
    pool = [f for f in pool if _family(f) == family] or pool
    deep = [f for f in pool if pixel_format(f)[1] >= info.bits]
    if deep:
        return min(deep, key=lambda f: pixel_format(f)[1])
    return max(pool, key=lambda f: pixel_format(f)[1])


def encode_args(info: VideoInfo, settings: VideoSettings, output: Path, chain: str,
                folder: Path, frames: int | None = None) -> tuple[list[str], str, str]:
    """ffmpeg arguments of the grading pass -> (args, encoder, output pixel format).

    ``chain`` is the filter chain (``lut3d`` filters) between the conversion to
    RGB and back; the whole graph is written to ``folder/graph.txt`` (read
    with ``-/filter_complex``: a clip with many shots makes a long graph) and
    ffmpeg must run in ``folder``. The output file is given as is (the caller
    passes a temporary path with the output's extension). ``frames``: encode
    only the first ``frames`` frames (the trial pass, :func:`check_encoding`).
    Alpha is carried through untouched (``lut3d`` grades RGB and copies the
    alpha plane); interlaced footage keeps its field order.
    """
    encoder, _ = CODECS[settings.codec]
    pix_fmt = _output_pix_fmt(info, encoder)
    # 8-bit planar RGB for 8-bit footage: ffmpeg 9.0's swscale round-trips yuv420p
    # through it within 2/255 (mean ~0.05/255), the same conversion decode_frames uses
    # for the samples; its 16-bit and float paths are twice as fast but shift the mean
    # by 1-1.5/255 against it (measured on a 480x270 clip, identity LUT).
    rgb = ("gbrap" if info.alpha else "gbrp") + ("16le" if info.high_depth else "")
    graph = (f"[0:v:0]{to_rgb_filter(info, rgb)},{chain},"
             f"{from_rgb_filter(info, pix_fmt)}[graded]")
    (folder / "graph.txt").write_text(graph, encoding="utf-8")
    args = [*input_args(info.path), "-/filter_complex", "graph.txt",
            "-map", "[graded]", "-map", "0", "-map", "-0:v:0",
            "-c", "copy", "-c:v:0", encoder]
    if settings.codec in ("x264", "x265"):
        args += ["-crf", str(settings.crf), "-preset", "medium"]
        if settings.codec == "x265":
            args += ["-x265-params", "log-level=error"]
            if output.suffix.lower() in (".mp4", ".m4v", ".mov"):
                args += ["-tag:v:0", "hvc1"]
    elif settings.codec == "prores":
        args += ["-profile:v:0", "3" if "444" not in pix_fmt else "4"]
    elif settings.codec == "ffv1":
        args += ["-level", "3"]
    if info.interlaced:
        if settings.codec in ("x264", "prores"):
            args += ["-flags:v:0", "+ildct+ilme" if settings.codec == "x264" else "+ildct"]
        args += ["-field_order:v:0", info.field_order]
    if output.suffix.lower() in (".mp4", ".m4v", ".mov"):
        args += ["-movflags", "+faststart"]
    if frames is not None:
        args += ["-frames:v:0", str(frames)]
    args += ["-fps_mode", "passthrough", "-map_metadata", "0", "-loglevel", "error", "-y",
             file_arg(output)]
    return args, encoder, pix_fmt


#: Frames the trial pass encodes before the fit.
TRIAL_FRAMES = 3


def check_encoding(info: VideoInfo, settings: VideoSettings, output: Path, folder: Path,
                   warn: Callable[[str], None] | None = None) -> tuple[str, str]:
    """Check, before the fit, that the clip can be written as asked -> (encoder, pix_fmt).

    Alpha the codec cannot store is refused (InputError naming codecs that
    can). Then a trial pass encodes the first :data:`TRIAL_FRAMES` frames
    with every stream into ``folder`` (same container, codec, pixel format,
    streams): ffmpeg's own reason when it fails ("codec not currently
    supported in container", an odd size...), and a refusal when the trial
    file lost frame size, streams or alpha. Losing bit depth (12-bit footage
    into a 10-bit encoder) or interlacing is said through ``warn``.
    """
    encoder = CODECS[settings.codec][0]
    where = f"{info.path}: " if info.path else ""
    if info.alpha and settings.codec not in ALPHA_CODECS:
        raise InputError(f"{where}the frames have an alpha channel ({info.pix_fmt}), which "
                         f"--codec {settings.codec} cannot store; use --codec prores (.mov) "
                         "or ffv1 (.mkv) to keep it")
    trial = folder / f"trial{output.suffix}"
    with _writing_in(folder):
        args, encoder, pix_fmt = encode_args(info, settings, trial, "null", folder,
                                             TRIAL_FRAMES)
    try:
        run_pass(args, cwd=str(folder))
    except FfmpegError as exc:
        reason = str(exc).removeprefix("ffmpeg failed: ")
        if "No space left" in reason:
            raise InputError(f"{folder}: cannot write the temporary files ({reason}); set "
                             "TMPDIR to a folder with space") from None
        raise InputError(f"{output}: ffmpeg cannot write this clip with --codec "
                         f"{settings.codec} into {output.suffix}: {reason}") from None
    written = probe(trial)
    if (written.width, written.height) != (info.width, info.height):
        raise InputError(f"{output}: {encoder} ({pix_fmt}) would store the {info.width}x"
                         f"{info.height} frames as {written.width}x{written.height}; use "
                         "--codec ffv1 (.mkv) or prores (.mov)")
    if written.streams != info.streams:
        raise InputError(f"{output}: {output.suffix} would keep the streams "
                         f"{', '.join(written.streams)} of {', '.join(info.streams)}; "
                         "choose another container")
    if info.alpha and not written.alpha:
        raise InputError(f"{output}: the alpha channel would be lost ({pix_fmt}); use "
                         "--codec prores (.mov) or ffv1 (.mkv)")
    say = warn or (lambda message: None)
    out_bits, in_bits = pixel_format(pix_fmt)[1], info.bits
    prores = info.codec == "prores" and settings.codec == "prores"  # 4444 decodes as 12-bit
    if out_bits < in_bits and not prores:
        deeper = [n for n, (enc, _) in CODECS.items()
                  if max((pixel_format(f)[1] for f in encoder_pixel_formats(enc)),
                         default=0) >= in_bits]
        say(f"{info.path.name}: {in_bits}-bit footage written {out_bits}-bit ({encoder} "
            f"takes {pix_fmt} at most)" + (f"; --codec {' or '.join(deeper)} keeps "
                                           f"{in_bits} bits" if deeper else ""))
    if info.interlaced and written.field_order is None:
        say(f"{info.path.name}: interlaced footage ({info.field_order}) written without its "
            f"field order by {encoder}; --codec x264, prores or ffv1 keeps it")
    return encoder, pix_fmt


def _lut_chain(segments: list[Segment], names: list[str]) -> str:
    """The lut3d filters of a schedule, each reading its table's file ``names[i]``."""
    filters = []
    for seg, name in zip(segments, names):
        text = f"lut3d=file={name}:interp=tetrahedral"
        if len(segments) > 1:
            text += f":enable='between(n,{seg.first},{seg.last})'"
        filters.append(text)
    return ",".join(filters)


@dataclass(frozen=True)
class VideoProgress(Progress):
    """:class:`~wbcgrade.photos.workflow.Progress` with ``frames(pass_name, done, total)``
    during the decoding ("scan") and encoding ("encode") passes."""

    frames: Callable[[str, int, int], None] | None = None


def grade_video(source: str | os.PathLike, output: str | os.PathLike, styles: StyleSet,
                options: GradeOptions, *, settings: VideoSettings | None = None,
                lut: str | os.PathLike | None = None, overwrite: bool = False,
                progress: VideoProgress | None = None,
                timings: dict[str, float] | None = None) -> VideoResult:
    """Grade a clip and write it (and the LUT of its grade).

    Parameters
    ----------
    source, output : input clip and graded clip (never the same file).
    styles, options : as for photos; ``options.regrain`` is not used (a LUT has none).
    settings : sampling, cuts and encoding (:class:`VideoSettings`).
    options.spaces : colour spaces (None: the clip's tags, else sRGB code values;
        sRGB-encoded Rec.709), :func:`wbcgrade.video.spaces.clip_encoding`.
        The styles are converted into the working space when they are elsewhere.
    lut : also write the clip's LUT here (with several shots, one file per shot:
        :func:`shot_lut_paths`).
    progress : fit, stage and frame progress.

    The outputs are checked first (:func:`plan_video`), the encoding before
    the fit (:func:`check_encoding`). Every output is written to a temporary
    file beside it and all are renamed onto their names only when everything
    was written (:func:`grade_planned`); on any failure, Ctrl-C or SIGTERM
    ffmpeg is killed and the temporary files removed.
    """
    settings = settings or VideoSettings()
    source, output, lut = plan_video(source, output, lut, settings, overwrite)
    with contextlib.ExitStack() as stack:
        return grade_planned(source, output, lut=lut, styles=styles, options=options,
                             settings=settings, overwrite=overwrite,
                             progress=progress or VideoProgress(), timings=timings, stack=stack)


#: Prefix of the work folders in the system's temporary folder (``$TMPDIR``).
WORK_PREFIX = "wbcgrade-video-"
#: The lock file a live run holds in its work folder.
WORK_LOCK = ".lock"
#: A work folder without a lock file is removed when older than this (seconds).
UNLOCKED_WORK_AGE_S = 3600.0


def remove_stale_work_folders(base: str | os.PathLike | None = None) -> list[Path]:
    """Remove the work folders of killed runs (their lock is free) -> the removed folders."""
    base = Path(base or tempfile.gettempdir())
    removed = []
    try:
        entries = [e for e in os.scandir(base) if e.name.startswith(WORK_PREFIX)]
    except OSError:
        return removed
    for entry in entries:
        try:
            if not entry.is_dir(follow_symlinks=False) or entry.stat().st_uid != os.getuid():
                continue
            lock = Path(entry.path) / WORK_LOCK
            stale = (is_unlocked(lock) if lock.exists() else
                     time.time() - entry.stat().st_mtime > UNLOCKED_WORK_AGE_S)
        except OSError:
            continue
        if stale:
            shutil.rmtree(entry.path, ignore_errors=True)
            removed.append(Path(entry.path))
    return removed


@contextlib.contextmanager
def work_folder() -> Iterator[Path]:
    """A private folder in ``$TMPDIR`` for the LUTs, graph and trial file of one run.

    Locked while the run lives; removed when it ends (an exception, Ctrl-C and
    SIGTERM/SIGHUP included: the CLI turns those into exceptions). A folder a
    SIGKILL left behind is removed by the next run (:func:`remove_stale_work_folders`).
    Failures to write here (a full ``$TMPDIR``) are InputErrors naming the folder.
    """
    base = Path(tempfile.gettempdir())
    remove_stale_work_folders(base)
    folder = lock = None
    try:
        for _ in range(100):
            # the name is known before the folder exists: a signal at any moment after
            # (SIGTERM right after mkdtemp left it behind) finds it in ``folder``
            folder = base / f"{WORK_PREFIX}{secrets.token_hex(6)}"
            try:
                os.mkdir(folder, 0o700)
                break
            except FileExistsError:
                continue
            except OSError as exc:
                folder = None
                raise InputError(f"{base}: cannot create a temporary folder here "
                                 f"({exc.strerror}); set TMPDIR to a folder with space") \
                    from None
        lock = os.open(folder / WORK_LOCK, os.O_RDWR | os.O_CREAT, 0o600)
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        yield folder
    finally:
        if lock is not None:
            os.close(lock)
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)


@contextlib.contextmanager
def _writing_in(folder: Path) -> Iterator[None]:
    """A failure to write into the work folder (a full ``$TMPDIR``) as an InputError naming it."""
    try:
        yield
    except OSError as exc:
        if isinstance(exc, WbcgradeError) or exc.errno is None:
            raise
        raise InputError(f"{folder}: cannot write the temporary files ({exc.strerror}); set "
                         "TMPDIR to a folder with space") from None


def grade_planned(source: Path, output: Path, *, lut: Path | None, styles: StyleSet | None,
                   options: GradeOptions, settings: VideoSettings, overwrite: bool,
                   progress: VideoProgress, timings: dict[str, float] | None,
                   stack: contextlib.ExitStack, look: Grade | None = None) -> VideoResult:
    """:func:`grade_video` once :func:`plan_video` checked the outputs (the outputs as
    it returned them); ``look``: a saved grade used for every shot (no fit, no ``styles``).

    The graded clip and its LUTs are written to temporary files entered on
    ``stack`` (:func:`wbcgrade._publish.atomic_path`): they are published when
    the caller closes the stack without an exception (after writing whatever
    else belongs to the run, e.g. the report), and all removed otherwise.
    """
    timings = dict(timings or {})
    start = time.perf_counter()
    info = probe(source)
    encoding = clip_encoding(info, options.spaces).named(progress.setting_names)
    if look is None:
        styles = styles_in_space(styles, encoding.working)
        options.check_styles(len(styles.names))
    frames = progress.frames
    folder = stack.enter_context(work_folder())
    check_encoding(info, settings, output, folder, progress.warn)

    progress.say("scan")
    t0 = time.perf_counter()
    samples = scan(source, info, settings.sample_every, cuts=settings.per_shot,
                   cut_threshold=settings.cut_threshold, min_shot=settings.min_shot,
                   progress=None if frames is None else
                   (lambda n: frames("scan", n, info.frames)))
    timings["scan"] = time.perf_counter() - t0
    if samples.n_frames != info.frames:  # the decoded frames are the clip (an edit list
        # trims the packets counted by the probe: a cut made with -c copy)
        info = replace(info, frames=samples.n_frames, duration=samples.n_frames / info.fps)

    shots = []
    t0 = time.perf_counter()
    for first, last in samples.shots():
        indices = [n for n in sorted(samples.frames) if first <= n <= last]
        if look is not None:
            grade, fit = look, None
            grade = replace(grade, outcome=grade_outcome(grade, None, None))
        else:
            grade, fit = shot_grade([samples.frames[n] for n in indices], styles, options,
                                    encoding, progress.fit, progress.stage)
        if grade.outcome is not None:  # in the command's words
            grade = replace(grade, outcome=grade.outcome.named(progress.setting_names))
        table = grade.lut(settings.lut_size, encoding)
        shots.append(ShotGrade(first, last, indices, grade, fit, table.astype(np.float32)))
    timings["grade"] = time.perf_counter() - t0
    segments = lut_schedule(samples.shots(), [s.table for s in shots], settings.blend)
    luts = [] if lut is None else shot_lut_paths(lut, len(shots))
    luts = luts[:1] + plan_outputs(luts[1:], [source, output], overwrite)  # the first: planned

    progress.say("encode")
    t0 = time.perf_counter()
    names = [f"lut{number:05d}.cube" for number in range(len(segments))]
    make_folders_for(output, *luts)  # planned: a missing folder of -o or --lut is made
    tmp = stack.enter_context(atomic_path(output, overwrite=overwrite))
    with _writing_in(folder):
        for name, seg in zip(names, segments):
            write_cube(folder / name, seg.table)
        args, encoder, pix_fmt = encode_args(info, settings, Path(tmp), _lut_chain(
            segments, names), folder)
    try:
        done = run_pass(args, None if frames is None else
                        (lambda n: frames("encode", n, info.frames)), cwd=str(folder))
    except FfmpegError as exc:
        raise FfmpegError(f"{output}: {exc}") from None
    if done != info.frames:
        raise FfmpegError(f"{output}: ffmpeg wrote {done} of the clip's {info.frames} frames; "
                          "nothing is published")
    timings["encode"] = time.perf_counter() - t0
    for path, shot in zip(luts, shots):
        ranked = ", ".join(f"{n} {w:.3f}" for n, w in shot.grade.ranked())
        written = stack.enter_context(atomic_path(path, overwrite=overwrite))
        write_cube(written, shot.table, title=f"wbcgrade video {Path(source).name}",
                   comments=[f"wbcgrade grade of {Path(source).name}, frames {shot.first}-"
                             f"{shot.last}: {ranked}",
                             "input: full-range RGB decoded with the clip's own matrix",
                             *lut_comments(encoding)],
                   overwrite=True)
    timings["total"] = time.perf_counter() - start
    return VideoResult(Path(source), output, luts, info, settings, shots, segments, samples,
                       timings, encoder, pix_fmt, encoding,
                       encoding.working if look is not None else styles.working_space)
