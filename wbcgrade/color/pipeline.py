"""Grade a photo file end to end: read, fit, remap, write the photo and a LUT.

This is the library behind ``wbcgrade apply``; it knows files and colours but
no command line (progress and messages go through callbacks).
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wbcgrade._publish import remove_stale_beside
from wbcgrade.color.grading import FitSummary, grade_photo
from wbcgrade.color.histogram import HistogramCache
from wbcgrade.color.imageio import check_image_output, check_output_path, stage_image
from wbcgrade.color.lut import check_lut_path, write_cube, write_grade_lut
from wbcgrade.color.presets import (
    StyleSet,
    load_preset,
    load_style_folder,
    resolve_preset,
    styles_in_space,
)
from wbcgrade.color.render import render
from wbcgrade.color.transfer import Grade, GradeOptions
from wbcgrade.errors import InputError

__all__ = ["GradeReport", "default_output_path", "check_outputs", "load_styles", "render",
           "grade_file"]


@dataclass
class GradeReport:
    """What ``grade_file`` did, for printing or JSON."""

    photo: Path
    output: Path
    lut: Path | None
    grade: Grade
    styles_source: str
    timings: dict[str, float] = field(default_factory=dict)
    fit: FitSummary | None = None
    color: dict = field(default_factory=dict)

    @property
    def fit_start(self) -> str:
        """How the weights were found: "uniform", "vertex-refit", "vertex" or "given"."""
        if self.fit is not None:
            return self.fit.start
        return "given" if self.grade.loss is None else "uniform"

    def as_dict(self) -> dict:
        """JSON-friendly summary."""
        return {
            "photo": str(self.photo),
            "output": str(self.output),
            "lut": None if self.lut is None else str(self.lut),
            "styles": self.styles_source,
            "weights": [{"style": name, "weight": round(w, 6)} for name, w in self.grade.ranked()],
            "loss": self.grade.loss,
            "fitted": self.fit_start != "given",
            "fit_start": self.fit_start,
            "regrain": self.grade.regrain is not None,
            "timings_s": {k: round(v, 3) for k, v in self.timings.items()},
            **{k: v for k, v in self.grade.info.items()},
            "color": self.color,
        }


def default_output_path(photo: str | os.PathLike) -> Path:
    """``<stem>_graded<ext>`` beside the photo."""
    photo = Path(photo)
    return photo.with_name(f"{photo.stem}_graded{photo.suffix}")


def check_outputs(photo: str | os.PathLike, output: str | os.PathLike | None,
                  lut: str | os.PathLike | None, lut_size: int = 33,
                  overwrite: bool = False, lut_format: str = "cube") -> tuple[Path, Path | None]:
    """Check the photo exists and the outputs may be written; -> (output, lut) paths.

    Checked before any work: the output's file type can be written, its
    folder exists and is writable, it is not the photo, not an existing file
    (unless ``overwrite``) and not a device or other non-regular file; the
    same for the LUT, which must end in ``.cube`` (``.clf`` for ``lut_format``
    "clf") and differ from the output.
    """
    photo = Path(photo)
    if not photo.exists():
        raise InputError(f"{photo}: no such file")
    output = Path(output) if output is not None else default_output_path(photo)
    check_output_path(output, [photo], overwrite)
    check_image_output(output)
    if lut is not None:
        lut = check_lut_path(lut, lut_format)
        if lut.absolute() == output.absolute():
            raise InputError(f"{lut}: the LUT and the graded photo must be different files")
        check_output_path(lut, [photo, output], overwrite)
        if not 2 <= lut_size <= 256:
            raise InputError("--lut-size must be between 2 and 256")
    return output, lut


def load_styles(style_dir: str | os.PathLike | None, preset: str | None, bins: int,
                cache: HistogramCache | None = None,
                warn: Callable[[str], None] | None = None,
                progress: Callable[[int, int, str], None] | None = None,
                working_space: str | None = None) -> StyleSet:
    """Styles from a folder (histograms at ``bins``, cached) or a preset NAME/FILE.

    The histograms are those of ``working_space`` (None: sRGB-encoded
    Rec.709): style photos are converted from their own spaces before
    binning; a preset built in another working space is converted
    (:func:`wbcgrade.color.presets.styles_in_space`).
    """
    if (style_dir is None) == (preset is None):
        raise InputError("give exactly one of --style DIR or --preset NAME_OR_FILE")
    if preset is not None:
        styles = load_preset(resolve_preset(preset))
        if working_space is None and "working_space" not in styles.meta:
            return styles  # the default: sRGB-encoded Rec.709 on both sides
        from wbcgrade.color.colorspace import default_working_space

        return styles_in_space(styles, working_space or default_working_space())
    return load_style_folder(style_dir, bins, cache=cache, warn=warn, progress=progress,
                             working_space=working_space)


def grade_file(photo: str | os.PathLike, styles: StyleSet, opts: GradeOptions,
               output: str | os.PathLike | None = None, lut: str | os.PathLike | None = None,
               lut_size: int = 33, overwrite: bool = False,
               fit_callback: Callable[[int, np.ndarray, float], None] | None = None,
               stage: Callable[[str], None] | None = None,
               timings: dict[str, float] | None = None,
               lut_format: str = "cube") -> GradeReport:
    """Grade ``photo`` towards ``styles`` and write the result (and a LUT).

    The output paths are checked before any computation; files are written
    atomically and the input is never replaced. The photo and the LUT are
    published together: when the LUT cannot be written, the graded photo is
    not published either. Temporary files a killed earlier run left in the
    output folders are removed. ``timings`` may hold stages timed by the
    caller (e.g. loading styles); they are kept in the report.

    Colour spaces: ``opts.input_space`` (None: what the file says) and
    ``opts.working_space`` (None: sRGB-encoded Rec.709); the styles are
    converted into the working space when they are in another, the output
    is written in the input space, the LUT (``lut_format`` "cube" or "clf")
    names the spaces it expects and produces.
    """
    photo = Path(photo)
    opts.validate(len(styles.names))
    output, lut = check_outputs(photo, output, lut, lut_size, overwrite, lut_format)
    remove_stale_beside(output, lut)
    timings = dict(timings or {})
    say = stage or (lambda name: None)

    # Read, fit (never worse than the best single style), colour map and remap.
    graded = grade_photo(photo, styles, opts, callback=fit_callback, stage=say)
    image, pixels, alpha_channel, grade = (
        graded.image, graded.pixels, graded.alpha_channel, graded.grade
    )
    timings.update(graded.timings)

    say("write")
    start = time.perf_counter()
    lut_existed = lut is not None and lut.exists()
    lut_written = False
    try:
        with stage_image(output, pixels, image, overwrite=overwrite,
                         alpha_channel=alpha_channel):
            timings["write"] = time.perf_counter() - start
            if lut is not None:  # written while the photo waits, published just before it
                say("lut")
                start = time.perf_counter()
                ranked = ", ".join(f"{n} {w:.3f}" for n, w in grade.ranked())
                write_grade_lut(lut, grade.color_map, graded.spaces, lut_size, grade.strength,
                                lut_format, title=f"wbcgrade {photo.stem}",
                                comments=[f"wbcgrade grade of {photo.name}: {ranked}"],
                                overwrite=overwrite, cube_writer=write_cube)
                lut_written = True
                timings["lut"] = time.perf_counter() - start
    except BaseException:
        if lut_written and not lut_existed:  # the photo failed to publish: take the LUT back
            with contextlib.suppress(OSError):
                lut.unlink()
        raise
    timings["total"] = sum(v for k, v in timings.items() if k != "total")
    color = {**graded.spaces.as_dict(), "styles_space": styles.working_space}
    return GradeReport(photo=photo, output=output, lut=lut, grade=grade,
                       styles_source=styles.source, timings=timings, fit=graded.fit,
                       color=color)
