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
from wbcgrade.color.lut import color_map_to_lut, write_cube
from wbcgrade.color.presets import StyleSet, load_preset, load_style_folder, resolve_preset
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
        }


def default_output_path(photo: str | os.PathLike) -> Path:
    """``<stem>_graded<ext>`` beside the photo."""
    photo = Path(photo)
    return photo.with_name(f"{photo.stem}_graded{photo.suffix}")


def check_outputs(photo: str | os.PathLike, output: str | os.PathLike | None,
                  lut: str | os.PathLike | None, lut_size: int = 33,
                  overwrite: bool = False) -> tuple[Path, Path | None]:
    """Check the photo exists and the outputs may be written; -> (output, lut) paths.

    Checked before any work: the output's file type can be written, its
    folder exists and is writable, it is not the photo, not an existing file
    (unless ``overwrite``) and not a device or other non-regular file; the
    same for the LUT, which must end in ``.cube`` and differ from the output.
    """
    photo = Path(photo)
    if not photo.exists():
        raise InputError(f"{photo}: no such file")
    output = Path(output) if output is not None else default_output_path(photo)
    check_output_path(output, [photo], overwrite)
    check_image_output(output)
    if lut is not None:
        lut = Path(lut)
        if lut.suffix.lower() != ".cube":
            raise InputError(f"{lut}: LUT file name must end in .cube")
        if lut.absolute() == output.absolute():
            raise InputError(f"{lut}: the LUT and the graded photo must be different files")
        check_output_path(lut, [photo, output], overwrite)
        if not 2 <= lut_size <= 256:
            raise InputError("--lut-size must be between 2 and 256")
    return output, lut


def load_styles(style_dir: str | os.PathLike | None, preset: str | None, bins: int,
                cache: HistogramCache | None = None,
                warn: Callable[[str], None] | None = None,
                progress: Callable[[int, int, str], None] | None = None) -> StyleSet:
    """Styles from a folder (histograms at ``bins``, cached) or a preset NAME/FILE."""
    if (style_dir is None) == (preset is None):
        raise InputError("give exactly one of --style DIR or --preset NAME_OR_FILE")
    if preset is not None:
        return load_preset(resolve_preset(preset))
    return load_style_folder(style_dir, bins, cache=cache, warn=warn, progress=progress)


def grade_file(photo: str | os.PathLike, styles: StyleSet, opts: GradeOptions,
               output: str | os.PathLike | None = None, lut: str | os.PathLike | None = None,
               lut_size: int = 33, overwrite: bool = False,
               fit_callback: Callable[[int, np.ndarray, float], None] | None = None,
               stage: Callable[[str], None] | None = None,
               timings: dict[str, float] | None = None) -> GradeReport:
    """Grade ``photo`` towards ``styles`` and write the result (and a LUT).

    The output paths are checked before any computation; files are written
    atomically and the input is never replaced. The photo and the LUT are
    published together: when the LUT cannot be written, the graded photo is
    not published either. Temporary files a killed earlier run left in the
    output folders are removed. ``timings`` may hold stages timed by the
    caller (e.g. loading styles); they are kept in the report.
    """
    photo = Path(photo)
    opts.validate(len(styles.names))
    output, lut = check_outputs(photo, output, lut, lut_size, overwrite)
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
                table = color_map_to_lut(grade.color_map, lut_size, grade.strength)
                ranked = ", ".join(f"{n} {w:.3f}" for n, w in grade.ranked())
                write_cube(lut, table, title=f"wbcgrade {photo.stem}",
                           comments=[f"wbcgrade grade of {photo.name}: {ranked}",
                                     "input: encoded RGB in [0, 1] (sRGB-encoded for float "
                                     "images)"],
                           overwrite=overwrite)
                lut_written = True
                timings["lut"] = time.perf_counter() - start
    except BaseException:
        if lut_written and not lut_existed:  # the photo failed to publish: take the LUT back
            with contextlib.suppress(OSError):
                lut.unlink()
        raise
    timings["total"] = sum(v for k, v in timings.items() if k != "total")
    return GradeReport(photo=photo, output=output, lut=lut, grade=grade,
                       styles_source=styles.source, timings=timings, fit=graded.fit)
