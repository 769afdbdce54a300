"""One photo file graded end to end: plan the outputs, read, grade, write (``apply``, ``batch``).

This is the library behind ``wbcgrade apply`` (:func:`apply_photo`, the one
call the command makes) and behind every photo of ``wbcgrade batch``
(:func:`grade_file`); it knows files and colours but no command line
(progress and messages go through the callbacks of :class:`Progress`). The
data flow (docs/architecture.md):

1. the outputs are planned and checked once, before any work
   (:func:`plan_photo`, through :func:`wbcgrade._publish.plan_outputs`);
2. the photo is read (:func:`wbcgrade.color.io.images.read_image`) and
   encoded into the working space (:class:`~wbcgrade.color.colorspace.ColorEncoding`);
3. the grade path fits and builds the grade
   (:func:`wbcgrade.color.grade.grading.grade_encoded`), or a series' shared
   grade is used as it is;
4. the pixels go through the grade and back into the photo's space
   (:func:`grade_photo`);
5. the photo and the LUT are published together (:func:`grade_file`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from wbcgrade._publish import make_folders_for, plan_outputs
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import Grade, grade_encoded, outcome_on_photo, style_grids
from wbcgrade.color.grade.saved_grade import save_grade, saved_name
from wbcgrade.color.histogram import image_histogram
from wbcgrade.color.io.images import (
    Image,
    WriteOptions,
    check_image_output,
    check_write_options,
    header_pixels,
    stage_image,
)
from wbcgrade.color.io.raw import output_name
from wbcgrade.color.look.scene import (
    forget_photo_scene,
    has_style_images,
    keep_style_scenes,
    matching_hook,
    prepare_photo_scene,
)
from wbcgrade.color.mapping.lut import (
    DEFAULT_LUT_SIZE,
    check_clf_support,
    check_lut_path,
    check_lut_size,
    lut_format_of,
    write_checked_lut,
)
from wbcgrade.color.mapping.regrain import kernels_needed, load_kernels, solved_subsampled
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.presets import (
    StyleSet,
    StyleSource,
    load_styles,
    one_style_warning,
    source_files,
)
from wbcgrade.errors import InputError, OptionError
from wbcgrade.limits import check_input_file
from wbcgrade.photos.graded import GradeReport, PhotoGrade
from wbcgrade.photos.output import grey_of, output_pixels
from wbcgrade.photos.progress import Progress  # (defined there: no numerics)
from wbcgrade.photos.read_ahead import ReadAhead, read_encoded
from wbcgrade.photos.report import plan_report, report_from_grade

__all__ = ["Progress", "PhotoPlan", "PhotoGrade", "GradeReport", "default_output_path",
           "plan_photo", "graded_pixels", "grade_photo", "grade_file", "apply_photo"]


@dataclass(frozen=True)
class PhotoPlan:
    """A photo and its outputs, checked before any work (:func:`plan_photo`).

    ``output`` None: graded in memory only (``wbcgrade report``); ``lut`` None: no LUT.
    Paths are resolved (links followed). ``lut_format`` and ``output_format`` (the image
    format's name, :func:`~wbcgrade.color.io.images.check_image_output`) are what the
    checks found: the writers use them as they are.
    """

    photo: Path
    output: Path | None
    lut: Path | None = None
    lut_size: int = DEFAULT_LUT_SIZE
    lut_format: str = "cube"
    overwrite: bool = False
    encode: WriteOptions = WriteOptions()
    saved_grade: Path | None = None
    output_format: str | None = None


def default_output_path(photo: str | os.PathLike) -> Path:
    """``<stem>_graded<ext>`` beside the photo (a raw photo's: ``<stem>_graded.tif``)."""
    photo = Path(photo)
    return photo.with_name(f"{photo.stem}_graded{output_name(photo).suffix}")


def plan_photo(photo: str | os.PathLike, output: str | os.PathLike | None = None,
               *, lut: str | os.PathLike | None = None, lut_size: int = DEFAULT_LUT_SIZE,
               lut_format: str | None = None, overwrite: bool = False,
               write: bool = True, encode: WriteOptions | None = None,
               saved_grade: str | os.PathLike | None = None,
               reads: Iterable[str | os.PathLike] = ()) -> PhotoPlan:
    """Check that the photo exists and its outputs may be written; -> the plan.

    Checked before any work: the output's file type can be written, and
    every output (the graded photo, default ``<stem>_graded<ext>`` beside it,
    and the LUT, whose format ``lut_format`` names, else its ending: ``.cube``
    or ``.clf``) passes :func:`wbcgrade._publish.plan_outputs`: not the photo, not
    an existing file unless ``overwrite``, not a device, not two outputs in
    one file, a writable folder (a missing one is created when the outputs are written,
    never over a file). ``write`` False: nothing
    is written (no output). ``saved_grade``: where the grade itself goes (a JSON
    file that ``--look`` reads), planned with the others. ``reads``: the other files
    the grade reads (style photos, presets, a saved look:
    :func:`~wbcgrade.color.presets.source_files`), inputs too: never replaced.
    """
    photo = Path(photo)
    if not photo.exists():
        raise InputError(f"{photo}: no such file")
    if photo.is_dir():
        raise InputError(f"{photo}: is a folder, not a photo")
    check_input_file(photo, "photo")  # a FIFO or device: refused before any output is planned
    if not write:
        output = None
    else:
        output = Path(output) if output is not None else default_output_path(photo)
    encode = encode or WriteOptions()
    output_format = None
    if output is not None:
        output_format = check_image_output(output)
        check_write_options(output, encode)
    check_lut_size(lut_size)
    if lut is not None:
        lut_format = lut_format_of(lut, lut_format)
        lut = check_lut_path(lut, lut_format)
        if lut_format == "clf":
            check_clf_support()
    output, lut, saved_grade = plan_outputs([output, lut, saved_grade], [photo, *reads],
                                            overwrite, make_folders=True)
    return PhotoPlan(photo, output, lut, lut_size, lut_format or "cube", overwrite, encode,
                     saved_grade, output_format)


def graded_pixels(image: Image, grade: Grade, encoding: ColorEncoding,
                  encoded: tuple | None = None,
                  in_place: bool = False) -> tuple[np.ndarray, int]:
    """Graded pixels of a whole image at full resolution.

    Colour channels go through the encoding, the grade and back; alpha and
    any extra channels pass through untouched. A grey photo stays grey: the
    luma of its graded colours (:func:`wbcgrade.photos.output.grey_of`).
    ``encoded`` may pass the ``(encoded, state)`` of ``encoding.encode`` the
    caller already has (not modified unless ``in_place``). ``in_place``: the
    encoded colours may be graded where they are, saving a full-size array;
    they may be the image's own pixels (``encoding.encode`` returns them when
    the photo is graded in its own space), which then hold the graded colours.

    Returns
    -------
    pixels : (H, W, C') float32 in the image's value convention.
    alpha_channel : index of alpha in ``pixels`` or -1.
    """
    pixels, state = encoded if encoded is not None else encoding.encode(image.rgb(),
                                                                         image.is_float)
    writable = (in_place and pixels.dtype == np.float32 and pixels.flags.c_contiguous
                and pixels.flags.writeable)
    graded = encoding.decode(grade.apply(pixels, out=pixels if writable else None), state)
    chans = image.color_channels
    if chans == [0, 1, 2] and image.pixels.shape[2] == 3:
        return graded, image.alpha_channel
    if len(chans) == 3:
        out = image.pixels.copy()
        out[:, :, chans] = graded
        return out, image.alpha_channel
    out = image.pixels.copy()
    out[:, :, chans[0]] = grey_of(graded, image.is_float)
    return out, image.alpha_channel


log = logging.getLogger(__name__)

#: The thread :func:`load_kernels_beside` started in this process (one per process).
_LOADER: list[threading.Thread] = []
_LOADER_LOCK = threading.Lock()


def _load_kernels(pixels: int) -> None:
    try:
        load_kernels(pixels)
    except Exception as exc:  # noqa: BLE001 - the grade itself loads (and reports) them
        log.debug("compiled kernels not loaded ahead: %s", exc)


def load_kernels_beside(photo: str | os.PathLike) -> threading.Thread | None:
    """Start loading, in a thread, the compiled kernels the regrain runs on ``photo`` when
    it is large enough for them (over 1.5 megapixels, from its header;
    :func:`wbcgrade.color.mapping.regrain.load_kernels`), once per process: importing
    numba and loading its first kernel (~0.7 s of Python) then runs while the photo is
    decoded and its scene matched, which hold no interpreter lock for most of their time.
    The thread, or None (nothing to load, or started before)."""
    if _LOADER or not kernels_needed():  # (OpenColorIO maps a large photo's colours)
        return None
    pixels = header_pixels(photo)
    if not solved_subsampled(pixels):
        return None
    with _LOADER_LOCK:
        if _LOADER:
            return None
        thread = threading.Thread(target=_load_kernels, args=(pixels,),
                                  name="wbcgrade-kernels")
        _LOADER.append(thread)
    thread.start()
    return thread


def grade_photo(photo: str | os.PathLike, styles: StyleSet | None, options: GradeOptions,
                *, shared: Grade | None = None, progress: Progress | None = None,
                keep_input: bool = True, read_ahead: ReadAhead | None = None) -> PhotoGrade:
    """Read and grade one photo (nothing is written).

    With ``shared`` (a series grade or a saved one, in the same working space), its colour
    map is applied as it is (``styles`` may be None); otherwise the photo gets its own grade
    (:func:`wbcgrade.color.grade.grading.grade_encoded`). ``keep_input`` False:
    nothing will look at the ungraded pixels afterwards (no report sheet), so
    a photo graded in its own space is graded in place (the returned
    ``image.pixels`` then hold graded colours). ``read_ahead``: the photo being decoded
    already (:class:`~wbcgrade.photos.read_ahead.ReadAhead`), waited for instead of read
    when it is this photo in these colour spaces.
    """
    progress = progress or Progress()
    timings: dict[str, float] = {}
    progress.say("read")
    start = time.perf_counter()
    regrained = (shared.regrain if shared is not None else options.regrain.settings) is not None
    if regrained:
        load_kernels_beside(photo)
    spaces = options.spaces
    scene_started = False
    if read_ahead is not None and read_ahead.serves(photo, spaces.input, spaces.working):
        image, encoding, encoded = read_ahead.result()
        scene_started = read_ahead.scene_started
    else:
        if read_ahead is not None:  # (another photo, or other spaces)
            read_ahead.discard()
        image, encoding, encoded = read_encoded(photo, spaces.input, spaces.working)
    encoding = encoding.named(progress.setting_names)
    timings["read"] = time.perf_counter() - start
    try:
        return _graded_photo(image, encoding, encoded, styles, options, shared, progress,
                             keep_input, timings, scene_started)
    finally:
        if scene_started or (shared is None and _matches_scenes(styles, options)):
            forget_photo_scene(encoded[0])  # (nothing of a graded photo is kept)


def _graded_photo(image: Image, encoding: ColorEncoding, encoded: tuple,
                  styles: StyleSet | None, options: GradeOptions, shared: Grade | None,
                  progress: Progress, keep_input: bool, timings: dict[str, float],
                  scene_started: bool) -> PhotoGrade:
    """:func:`grade_photo` of a photo read and encoded (``scene_started``: its keypoints
    are being found already)."""
    fit = None
    if shared is not None:  # what the shared (series or saved) grade does to this photo
        hist = image_histogram(encoded[0], 16, image.alpha(), options.transfer.max_pixels)
        grade = replace(shared, outcome=outcome_on_photo(shared, hist))
    else:
        start = time.perf_counter()
        if not scene_started and _matches_scenes(styles, options):
            prepare_photo_scene(encoded[0])  # keypoints found beside histograms and look
        grade, fit = grade_encoded(encoded[0], styles, options, encoding, image.alpha(),
                                   progress.fit, progress.stage)
        timings.update(grade.timings)
        # what the grade's own stages leave out: the histograms, the look, the outcome
        timings["grade"] = max(0.0, time.perf_counter() - start
                               - sum(v for k, v in grade.timings.items() if k != "total"))
    if grade.outcome is not None and progress.setting_names is not None:  # the command's words
        grade = replace(grade, outcome=grade.outcome.named(progress.setting_names))
    progress.say("remap")
    start = time.perf_counter()
    owned = not np.shares_memory(encoded[0], image.pixels)  # converted: a copy of ours
    pixels, alpha_channel = graded_pixels(image, grade, encoding, encoded,
                                          in_place=owned or not keep_input)
    timings["remap"] = time.perf_counter() - start
    return PhotoGrade(image, pixels, alpha_channel, grade, fit, encoding, timings)


def grade_file(plan: PhotoPlan, styles: StyleSet | None, options: GradeOptions,
               *, shared: Grade | None = None, progress: Progress | None = None,
               timings: dict[str, float] | None = None,
               keep_input: bool = True, read_ahead: ReadAhead | None = None) -> GradeReport:
    """Grade a planned photo and write its outputs (:func:`plan_photo` checked them).

    The photo and the LUT are published together: when the LUT cannot be
    written, the graded photo is not published either. Files are written
    atomically, the input is never replaced, and an existing file only with
    ``plan.overwrite``. ``timings`` may hold stages timed by the caller (e.g.
    loading styles); they are kept in the report. ``keep_input`` False: the
    report's ``graded.image`` may hold graded pixels (:func:`grade_photo`). Colour spaces:
    ``options.spaces`` (the input: what the file says unless given; the
    working space: sRGB-encoded Rec.709 unless given); the output is written
    in the input space, the LUT names the spaces it expects and produces.
    """
    progress = progress or Progress()
    timings = dict(timings or {})
    graded = grade_photo(plan.photo, styles, options, shared=shared, progress=progress,
                         keep_input=keep_input, read_ahead=read_ahead)
    grade = graded.grade
    timings.update(graded.timings)
    if plan.output is not None:
        progress.say("write")
        start = time.perf_counter()
        make_folders_for(plan.output, plan.lut, plan.saved_grade)
        lut_existed = plan.lut is not None and plan.lut.exists()
        lut_written = False
        try:
            pixels = output_pixels(graded.pixels, graded.alpha_channel, graded.image,
                                   graded.encoding, plan.output, plan.encode)
            with stage_image(plan.output, pixels, graded.image, plan.overwrite,
                             graded.alpha_channel, plan.encode,
                             format_name=plan.output_format):
                timings["write"] = time.perf_counter() - start
                if plan.lut is not None:  # written while the photo waits, published before it
                    progress.say("lut")
                    start = time.perf_counter()
                    ranked = ", ".join(f"{n} {w:.3f}" for n, w in grade.ranked())
                    write_checked_lut(plan.lut, plan.lut_format, grade,
                                      graded.encoding.within_working(), plan.lut_size,
                                      title=f"wbcgrade {plan.photo.stem}",
                                      comments=[f"wbcgrade grade of {plan.photo.name}: "
                                                f"{ranked}"],
                                      overwrite=plan.overwrite)
                    lut_written = True
                    timings["lut"] = time.perf_counter() - start
        except BaseException:
            if lut_written and not lut_existed:  # the photo failed to publish: take it back
                with contextlib.suppress(OSError):
                    plan.lut.unlink()
            raise
    timings["total"] = sum(v for k, v in timings.items() if k != "total")
    return GradeReport(plan.photo, plan.output, plan.lut, grade,
                       styles.source if styles is not None else saved_name(shared), graded,
                       timings, graded.fit)


def apply_photo(photo: str | os.PathLike, source: StyleSource | Grade, options: GradeOptions,
                *, output: str | os.PathLike | None = None, lut: str | os.PathLike | None = None,
                lut_size: int = DEFAULT_LUT_SIZE, lut_format: str | None = None,
                overwrite: bool = False, report_dir: str | os.PathLike | None = None,
                progress: Progress | None = None,
                encode: WriteOptions | None = None,
                save_grade: str | os.PathLike | None = None,
                read_ahead: ReadAhead | None = None) -> GradeReport:
    """``wbcgrade apply``: grade ``photo`` and write it, the LUT and the report.

    Every output (the graded photo, the LUT, the report's files) is planned
    and checked before any work (:func:`plan_photo`). ``source`` is where
    the grade comes from:

    - a :class:`~wbcgrade.color.presets.StyleSource`: the styles are loaded
      and the photo gets its own grade (:func:`grade_file`); with
      ``report_dir`` the palette weight report is written too;
    - a :class:`~wbcgrade.color.grade.grading.Grade` (a saved grade,
      :func:`wbcgrade.color.grade.saved_grade.load_look`): applied as it is, in its
      own working space, nothing fitted (``fit_start`` "saved"); a report
      needs styles, so ``report_dir`` is an OptionError.

    ``encode``: JPEG/WebP quality and bit depth of the graded photo.
    ``save_grade``: also write the grade itself, as JSON (what ``--look`` reads).
    ``read_ahead``: the photo being read already (the command line starts it as soon as
    its options are checked, :meth:`~wbcgrade.photos.read_ahead.ReadAhead.for_grade`);
    else a grade towards styles starts it before they load.
    """
    progress = progress or Progress()
    saved = isinstance(source, Grade)
    if saved and report_dir is not None:
        raise OptionError("{report_dir} needs styles to compare with; a saved {look} has none",
                          "report_dir", also=("look",))
    reads = source_files(None if saved else source, options.map.natural,
                         source if saved else None)
    plan = plan_photo(photo, output, lut=lut, lut_size=lut_size, lut_format=lut_format,
                      overwrite=overwrite, encode=encode, saved_grade=save_grade, reads=reads)
    if report_dir is not None:
        plan_report(report_dir, [plan.photo.name], [plan.photo, *reads], overwrite)
    if read_ahead is not None:  # the outputs are planned: the grade goes ahead
        read_ahead.proceed()
    if saved:
        spaces = options.spaces
        if spaces.working != source.working:
            options = replace(options, spaces=replace(spaces, working=source.working))
        report = grade_file(plan, None, options, shared=source, progress=progress,
                            keep_input=False)
        _save_grade(plan, report.grade)
        return report
    start = time.perf_counter()
    if read_ahead is None:  # decoded on another core while the styles load
        read_ahead = ReadAhead.for_grade(plan.photo, source, options)
        read_ahead.proceed()
    styles = load_styles(source, options.transfer.bins, options.spaces.working, progress.warn,
                         progress.styles, matching_hook(source, options, [plan.photo]),
                         resampled=style_grids(options))
    _warn_one_style(source, styles, options, progress.warn)
    _prepare_scenes(styles, options)
    report = grade_file(plan, styles, options, progress=progress,
                        timings={"styles": time.perf_counter() - start},
                        keep_input=report_dir is not None, read_ahead=read_ahead)
    _save_grade(plan, report.grade)
    if report_dir is not None:
        report.report = report_from_grade(report_dir, report, styles, options, overwrite)
    return report


def _matches_scenes(styles: StyleSet | None, options: GradeOptions) -> bool:
    """Whether the grade looks for the photo's scene among the style photos: a look grade
    (no fixed weights) of styles that have photos (a folder's, not a preset's look)."""
    return (styles is not None and options.map.builder == "look"
            and options.fit.weights is None and styles.look is None
            and has_style_images(styles))


def _prepare_scenes(styles: StyleSet, options: GradeOptions) -> None:
    """The style photos prepared for scene matching now, while the photo is still being
    decoded (:func:`wbcgrade.color.look.scene.keep_style_scenes`: read from the cache into
    this process; the look grade finds them there), when the grade will match scenes
    (:func:`_matches_scenes`). Best effort: the grade prepares (and reports) whatever
    this could not."""
    if not _matches_scenes(styles, options):
        return
    try:
        keep_style_scenes(styles)
    except Exception as exc:  # noqa: BLE001 - the grade itself prepares them again
        log.debug("style photos not prepared ahead: %s", exc)


def _warn_one_style(source: StyleSource, styles: StyleSet, options: GradeOptions,
                    warn) -> None:
    message = one_style_warning(source, styles, options.map.builder)
    if message is not None and warn is not None:
        warn(message)


def _save_grade(plan: PhotoPlan, grade: Grade) -> None:
    """Write the grade itself where the plan says (``--save-grade``), atomically."""
    if plan.saved_grade is not None:
        save_grade(plan.saved_grade, grade, overwrite=plan.overwrite)
