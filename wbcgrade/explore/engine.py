"""The explore page's one door into the colour library.

Everything ``wbcgrade explore`` asks of :mod:`wbcgrade.color` goes through
this module (the server, the job worker and the command import nothing
else of it), so that following a change of the colour library's options or
grade path means changing this file only. It offers:

- :func:`load_session`: the photo and its styles, read once, as ``apply``
  reads them (colour spaces, histograms on the fit, preview and transfer
  grids), a preview-size copy and a thumbnail per style;
- :meth:`Session.fit`: the weights ``apply`` would fit (never worse than the
  best single style);
- :meth:`Session.fast_map`: a colour map in well under a second for the
  live preview (palette, plan and smooth map on small grids, see below);
- :class:`ExactGrader` (run in the job worker, :mod:`wbcgrade.explore.jobs`):
  the colour map exactly as ``apply --weights W --no-regrain`` computes it,
  and the fit's loss at any weights (the landscape);
- :meth:`Session.look_grade` / :meth:`Session.look_at`: the grade ``apply``
  gives (its default look grade, by ``apply``'s own grade path, with its
  ``outcome``: where it comes from, its strength) at any strength;
  :func:`describe_outcome` puts the outcome in the page's words;
- :meth:`Session.save`: the graded photo at full size through ``apply``'s
  own output path, under a new name in a given folder;
- :meth:`Session.export` / :meth:`Session.export_grade` (``.cube`` or CLF,
  any size) and :meth:`Session.command_line` / :meth:`Session.look_command`
  (the ``apply`` command that reproduces it);
- :func:`shipped_presets`: the names of the presets the package ships.

The live preview. ``apply`` computes the palette on 64^3, the plan on 32^3 ->
64^3 -> 128^3 and a 33^3 smooth map (about 3 s on two cores): too slow for a
drag. The preview computes the same steps with the same kernel in colour
units (sigma = 1/31 of the cube) on 20^3 grids and a 9^3 smooth map (the
plan to a looser tolerance, the smooth map's system factored once per
photo), then adds the difference between the exact and
the fast map at the nearest weights whose exact map is known (a control
variate): at those weights the preview *is* the exact map, and nearby it
follows the fast map's change. The fast map is solved from scratch each
time, so that the difference is measured against the same map (a plan
warm-started from the previous move lags towards it). Before that answer
arrives, the page extrapolates from the last exact map with the fast map's
slopes there (:meth:`ExactGrader.slopes`). ``benchmarks/explore.py``
measures the times and the distances to the exact map.
"""

from __future__ import annotations

import os
import shlex
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from wbcgrade._publish import publish_bytes, write_png
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import (
    Grade,
    PhotoHistograms,
    finish_map,
    grade_encoded,
    grade_histograms,
    grade_outcome,
    strengthened,
)
from wbcgrade.color.grade.saved_grade import look_dict
from wbcgrade.color.histogram import HistogramCache, image_histogram
from wbcgrade.color.io.images import read_image
from wbcgrade.color.look.scene import matching_hook
from wbcgrade.color.mapping.lut import LUT_FORMATS, check_clf_support, write_grade_lut
from wbcgrade.color.mapping.remap import resample_lattice
from wbcgrade.color.options import GradeOptions, as_options
from wbcgrade.color.outcome import map_change
from wbcgrade.color.palette.fit import FitSummary, fit_problem, fit_weights, loss_at
from wbcgrade.color.palette.smooth_map import SmoothMapFitter
from wbcgrade.color.palette.transfer import transport_map
from wbcgrade.color.presets import StyleSet, StyleSource, list_presets, load_styles, styles_in_space
from wbcgrade.color.weights import parse_weights
from wbcgrade.errors import InputError
from wbcgrade.explore.settings import MAX_STRENGTH, Settings, format_number, weights_text
from wbcgrade.photos.report import style_pictures
from wbcgrade.photos.sheet import thumbnail
from wbcgrade.photos.workflow import default_output_path, grade_file, plan_photo

__all__ = ["Session", "FitResult", "ExactGrader", "LoadedPhoto", "load_photo", "load_session",
           "describe_outcome", "shipped_presets", "blend_looks", "grade_file_of", "serve_jobs",
           "MAX_STRENGTH",
           "PREVIEW_BINS", "PREVIEW_MAP_SIZE", "PREVIEW_SIDE", "EXPORT_SIZES", "EXPORT_FORMATS"]

#: Bins per axis of the preview's palette, plan and photo histogram (the kernel
#: stays 1/31 of the cube: 0.6 bins here). On 20^3 a move costs a fifth of 32^3's
#: CPU time (the palette's 60 barycenter iterations dominate: they scale with
#: bins^4 and the number of styles), and the corrected preview is as close to the
#: exact map (measured at L1 distances 0.05-0.4 on two photos and both presets:
#: mean differences within 0.1/255 of 32^3's, most of them smaller;
#: ``benchmarks/explore.py``).
PREVIEW_BINS = 20
#: Nodes per axis of the preview's smooth map (upsampled to the exact map's lattice).
PREVIEW_MAP_SIZE = 9
#: The preview plan's Sinkhorn tolerance (L1 marginal error; ``apply``: 3e-3). Its
#: map is within 0.1-0.3/255 on average (p99 < 1/255) of a converged plan's, in
#: half the iterations (measured on two sample photos).
PREVIEW_SINKHORN_TOL = 1e-2
#: Weight step of the slopes the page extrapolates from (:meth:`ExactGrader.slopes`).
SLOPE_STEP = 0.05
#: Long side of the preview picture the browser grades, in pixels.
PREVIEW_SIDE = 1024
#: LUT sizes and formats the page exports.
EXPORT_SIZES = (33, 65)
EXPORT_FORMATS = ("cube", "clf")
#: Side of a style's thumbnail, in pixels.
THUMBNAIL_SIDE = 96


def _base_options():
    """``apply --mode palette --no-regrain``'s settings: the palette transfer (the grade
    the weights steer, whose fast map the preview follows) and what a LUT can hold."""
    return GradeOptions(regrain=False, mode="palette")


def _options(base, settings: Settings, **changes):
    """The grade options of ``settings`` (its map: the strength is applied afterwards),
    with other settings ``changes`` by their flat names."""
    return as_options(base, relaxation=settings.relaxation,
                      preserve_luminance=settings.keep_lightness, **changes)


def _look_options():
    """``apply --no-regrain``'s settings (the default "look" grade): what the page opens on,
    the grade of ``apply`` with the same styles, and what a LUT can hold."""
    return GradeOptions(regrain=False)


def _apply_weights(settings: Settings) -> tuple[float, ...]:
    """The weights ``apply --weights TEXT`` grades with: the text read as it reads it."""
    return tuple(parse_weights(weights_text(settings.weights)))


@dataclass
class FitResult:
    """The fitted weights and how they compare (fit grid, the fit's loss).

    Attributes
    ----------
    weights : (S,) fitted weights.
    loss : the fit's loss at ``weights``.
    vertex_losses : (S,) the loss of each style alone.
    start : "uniform", "vertex-refit" or "vertex" (see ``color.grading.FitSummary``).
    converged : whether L-BFGS stopped at its tolerance.
    evaluations : loss evaluations spent.
    time_s : wall time of the fit.
    """

    weights: tuple[float, ...]
    loss: float
    vertex_losses: tuple[float, ...]
    start: str
    converged: bool
    evaluations: int
    time_s: float

    def as_json(self, names: list[str]) -> dict:
        best = int(np.argmin(self.vertex_losses))
        return {"weights": list(self.weights), "loss": self.loss,
                "vertex_losses": list(self.vertex_losses), "start": self.start,
                "converged": self.converged, "evaluations": self.evaluations,
                "time_s": round(self.time_s, 3), "best_single": names[best],
                "best_single_loss": self.vertex_losses[best]}


class _FastGrader:
    """Colour maps on small grids for the live preview (module docstring).

    Holds what every move shares: the styles re-binned to the preview grid and
    the smooth map's factored system (:class:`wbcgrade.color.palette.smooth_map.SmoothMapFitter`:
    the photo's histogram and the lattice do not change while exploring).
    """

    def __init__(self, styles, photo_hist: np.ndarray, base, encoding) -> None:
        self.styles = styles
        self.photo_hist = photo_hist
        self.encoding = encoding
        # the same steps and kernel in colour units (sigma = 1/31 of the cube) as apply,
        # on the preview grids; the plan to a looser tolerance; transport_map gives the
        # raw projection (no smoothing), the factored fit smooths it
        sigma = base.transfer.width_bins / (base.transfer.bins - 1)  # in units of the cube
        self.base = as_options(base, bins=PREVIEW_BINS, palette_bins=PREVIEW_BINS,
                               transfer_width=sigma * (PREVIEW_BINS - 1),
                               map_size=PREVIEW_MAP_SIZE, sinkhorn_tol=PREVIEW_SINKHORN_TOL,
                               smoothness=0.0, stiffness=0.0)
        self.smooth = SmoothMapFitter(photo_hist, PREVIEW_MAP_SIZE, base.map.smoothness,
                                      base.map.stiffness)
        styles.at_bins(PREVIEW_BINS)  # re-binned once, not on every move

    def solve(self, settings: Settings, weights, tol: float | None = None) -> np.ndarray:
        """(9, 9, 9, 3) map at ``weights`` (S,) with ``settings``' other options: the
        palette, the plan (solved cold, so the same weights give the same map) to
        ``tol`` (default :data:`PREVIEW_SINKHORN_TOL`), the smooth map, the finish."""
        options = _options(self.base, settings,
                           **({} if tol is None else {"sinkhorn_tol": tol}))
        weights = np.asarray(weights, dtype=np.float64)
        raw = transport_map(self.photo_hist, self.styles, weights / weights.sum(),
                            options).color_map
        return finish_map(self.smooth.fit(raw), options, self.encoding)


@dataclass
class Session:
    """A photo and its styles, loaded once for exploring (nothing is ever written to them).

    Attributes
    ----------
    photo : the photo's path as given (the command line repeats it).
    style_dir, preset : where the styles came from, as given (one is None).
    names : S style names.
    styles : the style set in the photo's working space.
    encoding : the photo's colour encoding (``color.colorspace.ColorEncoding``).
    hists : {bins: (bins, bins, bins)} photo histograms on the fit, preview
        and transfer grids, as ``apply`` bins them.
    preview : (h, w, 3) uint8 preview picture (working-space colours: the
        values the LUT takes).
    thumbnails : one (h, w, 3) float32 display picture per style.
    setting_names : how the command names the library's settings (setting -> its flag) in
        what the page says of a grade (:func:`describe_outcome`); None: as the library does.
    """

    photo: str
    style_dir: str | None
    preset: str | None
    names: list[str]
    styles: object
    encoding: object
    hists: dict
    preview: np.ndarray
    thumbnails: list[np.ndarray]
    base: object
    lut_size: int
    loaded: LoadedPhoto | None = None
    setting_names: Mapping[str, str] | None = None

    def __post_init__(self) -> None:
        import threading

        self._fast_grader = None
        self._look = None
        self._look_lock = threading.Lock()

    @property
    def _fast(self) -> _FastGrader:
        """The preview's fast grader (made on the palette mode's first move)."""
        with self._look_lock:
            if self._fast_grader is None:
                self._fast_grader = _FastGrader(self.styles, self.hists[PREVIEW_BINS],
                                                self.base, self.encoding)
            return self._fast_grader

    @property
    def source_args(self) -> list[str]:
        """The command line's style source: ``--style DIR`` or ``--preset NAME_OR_FILE``."""
        if self.style_dir is not None:
            return ["--style", self.style_dir]
        return ["--preset", self.preset]

    def look_grade(self):
        """The grade ``apply --no-regrain`` gives this photo with these styles (a
        ``color.grading.Grade`` at ``--strength`` 1, its ``outcome`` saying what it is;
        computed once, by ``apply``'s own grade path ``color.grading.grade_encoded`` on
        the full-size photo)."""
        return self._look_and_fit()[0]

    def _look_and_fit(self):
        with self._look_lock:
            if self._look is None:
                if self.loaded is None:
                    raise ValueError("the session was loaded without its photo's pixels")
                grade, fit = grade_encoded(self.loaded.encoded, self.styles, _look_options(),
                                           self.encoding, self.loaded.alpha)
                if grade.outcome is not None:  # in the command's words
                    grade = replace(grade, outcome=grade.outcome.named(self.setting_names))
                self._look = grade, fit
            return self._look

    def look_at(self, strength: float):
        """The look grade at ``apply --strength`` (0 to :data:`MAX_STRENGTH`; above 1 the
        map's change scaled, as ``apply`` does), its outcome judged at that strength."""
        grade, fit = self._look_and_fit()
        if strength == 1.0:
            return grade
        color_map, blend = strengthened(grade.color_map, strength)
        grade = replace(grade, color_map=np.asarray(color_map, dtype=np.float32),
                        strength=blend)
        outcome = grade_outcome(grade, fit, self.hists[self.base.fit.bins], strength)
        return replace(grade, outcome=outcome.named(self.setting_names))

    def palette_grade(self, color_map: np.ndarray, settings: Settings):
        """The palette grade of ``settings`` whose exact map is ``color_map`` (a Grade,
        its outcome judged on this photo as ``apply --weights`` judges it)."""
        weights = np.asarray(settings.weights, dtype=np.float64)
        color_map, blend = strengthened(np.asarray(color_map, dtype=np.float32),
                                        settings.strength)
        grade = Grade(names=tuple(self.names), weights=weights / weights.sum(),
                      color_map=np.asarray(color_map, dtype=np.float32),
                      working=self.encoding.working, strength=blend)
        fit = FitSummary(grade.weights, 0.0, np.zeros(0), "given")
        outcome = grade_outcome(grade, fit, self.hists[self.base.fit.bins],
                                settings.strength)
        return replace(grade, outcome=outcome.named(self.setting_names))

    def look_command(self, strength: float) -> str:
        """The ``wbcgrade apply`` command that gives the look grade at ``strength``."""
        parts = ["wbcgrade", "apply", self.photo, *self.source_args, "--mode", "look",
                 "--no-regrain"]
        if strength != 1.0:
            parts += ["--strength", format_number(strength, 3)]
        return " ".join(shlex.quote(p) for p in parts)

    def save(self, grade, folder: str | os.PathLike, with_grade: bool = False) -> Path:
        """Grade the full-size photo with ``grade`` and write it into ``folder``; -> its path.

        ``apply``'s own path (``color.workflow.plan_photo`` and ``grade_file``, the grade
        given as a series' shared grade): the photo's format, bit depth and metadata, written
        atomically. The name is ``<stem>_explore_<n><ext>`` with the first ``n`` no file
        has: never the photo, never a file that exists (one appearing meanwhile is not
        replaced: the next ``n`` is taken). ``with_grade``: the grade itself is written
        beside it too, ``<stem>_explore_<n>.grade.json`` (what ``apply --look`` reads;
        :func:`grade_file_of` names it).
        """
        folder = Path(folder)
        suffix = default_output_path(self.photo).suffix
        stem = Path(self.photo).stem
        for number in range(1, 10000):
            target = folder / f"{stem}_explore_{number}{suffix}"
            saved = grade_file_of(target) if with_grade else None
            if os.path.lexists(target) or (saved is not None and os.path.lexists(saved)):
                continue
            try:
                plan = plan_photo(self.photo, target, overwrite=False, saved_grade=saved)
                grade_file(plan, self.styles, _look_options(), shared=grade, keep_input=False)
                if saved is not None:
                    _publish_grade(saved, grade)
            except InputError:
                if os.path.lexists(target) or (saved is not None and os.path.lexists(saved)):
                    continue  # taken meanwhile: the next number
                raise
            return target
        raise InputError(f"{folder}: no free name for {stem}_explore_N{suffix}")

    @property
    def n_styles(self) -> int:
        return len(self.names)

    def fit(self, callback: Callable[[int, np.ndarray, float], None] | None = None
            ) -> FitResult:
        """Fit the weights as ``apply`` does (never worse than one style alone)."""
        fit = self.base.fit
        summary = fit_weights(self.hists[fit.bins], self.styles.at_bins(fit.bins), fit,
                              callback)
        return FitResult(weights=tuple(float(w) for w in summary.weights),
                         loss=float(summary.loss),
                         vertex_losses=tuple(float(v) for v in summary.vertex_losses),
                         start=summary.start, converged=summary.converged,
                         evaluations=summary.evaluations,
                         time_s=summary.time_s)

    def fast_map(self, settings: Settings) -> np.ndarray:
        """The preview's colour map of ``settings`` (PREVIEW_MAP_SIZE^3, float32)."""
        return self._fast.solve(settings, _apply_weights(settings))

    def preview_lut(self, fast_map: np.ndarray, offset: np.ndarray | None) -> np.ndarray:
        """The LUT the browser applies: the fast map on the exact map's lattice plus
        ``offset`` (exact minus fast map at the nearest known weights), clipped."""
        lut = resample_lattice(fast_map, self.lut_size)
        if offset is not None:
            lut = np.clip(lut + offset, 0.0, 1.0)
        return np.ascontiguousarray(lut, dtype=np.float32)

    def grader_state(self) -> dict:
        """What the job worker needs to build an :class:`ExactGrader` (picklable)."""
        styles = self.styles
        clean = StyleSet(list(styles.names), styles.histograms, styles.source, styles.width,
                         styles.description, dict(styles.meta))
        return {"styles": clean, "hists": self.hists, "base": self.base,
                "encoding": self.encoding, "lut_size": self.lut_size}

    def command_line(self, settings: Settings) -> str:
        """The ``wbcgrade apply`` command that grades the full-size photo as shown."""
        parts = ["wbcgrade", "apply", self.photo, *self.source_args]
        parts += ["--mode", "palette", "--weights", weights_text(settings.weights),
                  "--no-regrain"]
        if settings.strength != 1.0:
            parts += ["--strength", format_number(settings.strength, 3)]
        if settings.relaxation is not None:
            parts += ["--relax", format(settings.relaxation, ".3g")]
        if settings.keep_lightness:
            parts += ["--preserve-luminance"]
        return " ".join(shlex.quote(p) for p in parts)

    def export(self, color_map: np.ndarray, settings: Settings, lut_format: str,
               size: int) -> tuple[str, bytes]:
        """The LUT file of the palette map ``color_map`` at ``settings`` -> (file name, bytes)."""
        ranked = ", ".join(f"{n} {w:.4f}" for n, w in sorted(
            zip(self.names, settings.weights), key=lambda item: -item[1]))
        return self.export_grade(self.palette_grade(color_map, settings), lut_format, size,
                                 f"palette weights {ranked}", self.command_line(settings))

    def export_grade(self, grade, lut_format: str, size: int, what: str,
                     command: str) -> tuple[str, bytes]:
        """The LUT file of ``grade`` (at its strength) -> (file name, bytes).

        Made by the colour library's LUT writer (the header names the spaces,
        ``what`` the grade is and the ``command`` that reproduces it) in a temporary
        folder; nothing is written beside the photo.
        """
        stem = Path(self.photo).stem
        name = f"{stem}_explore_{size}{LUT_FORMATS[lut_format]}"
        with tempfile.TemporaryDirectory(prefix="wbcgrade-explore-") as folder:
            path = Path(folder) / name
            write_grade_lut(path, grade, self.encoding.within_working(), size, lut_format,
                            title=f"wbcgrade {stem}",
                            comments=[f"wbcgrade explore grade of {Path(self.photo).name}: "
                                      f"{what}", f"reproduce: {command}"])
            return name, path.read_bytes()

    def png(self, pixels: np.ndarray) -> bytes:
        """An (h, w, 3) picture (uint8, or floats in [0, 1]) as PNG bytes."""
        with tempfile.TemporaryDirectory(prefix="wbcgrade-explore-") as folder:
            path = Path(folder) / "picture.png"
            write_png(path, pixels)
            return path.read_bytes()


def grade_file_of(photo: Path) -> Path:
    """The grade file saved beside a saved photo: ``<its stem>.grade.json``."""
    return photo.with_name(f"{photo.stem}.grade.json")


def _publish_grade(path: Path, grade) -> None:
    """Write ``grade`` as the JSON ``apply --look`` reads, atomically, never replacing."""
    import json


    publish_bytes(path, json.dumps(look_dict(grade), indent=1).encode("utf-8"),
                  overwrite=False)


def blend_looks(first, second, amount: float, strength: float, names: tuple[str, str],
                photo_hist: np.ndarray | None = None) -> tuple:
    """Two look grades blended on their lattice, ``(1 - amount) A + amount B``, at
    ``--strength`` ``strength`` (above 1 the blend's change scaled, as ``apply`` does).

    ``first`` and ``second``: Grades in the same working space (their maps at blend 1).
    Returns (the Grade: names and weights the two looks and their shares, no regrain;
    the map at blend 1 the page applies; the photo's mean change in /255, None without
    ``photo_hist``).
    """
    if first.working != second.working or first.color_map.shape != second.color_map.shape:
        raise ValueError("the looks to blend live in different spaces or lattices")
    mixed = ((1.0 - amount) * np.asarray(first.color_map, dtype=np.float64)
             + amount * np.asarray(second.color_map, dtype=np.float64)).astype(np.float32)
    color_map, blend = strengthened(mixed, strength)
    grade = Grade(names=tuple(names), weights=np.array([1.0 - amount, amount]),
                  color_map=np.asarray(color_map, dtype=np.float32), working=first.working,
                  strength=blend)
    change = (None if photo_hist is None
              else map_change(grade.color_map, grade.strength, grade.working, photo_hist))
    return grade, mixed, change


def shipped_presets() -> list[str]:
    """The names of the presets shipped with the package, sorted."""
    return [name for name, _ in list_presets()]


def clf_available() -> bool:
    """Whether CLF LUTs can be written (the ``opencolorio`` package is installed)."""
    try:
        check_clf_support()
    except InputError:
        return False
    return True


@dataclass
class LoadedPhoto:
    """The photo as ``apply`` reads it, shared by the sessions of every style source.

    Attributes
    ----------
    encoding : its colour encoding (``color.colorspace.ColorEncoding``).
    encoded : (H, W, 3) float32 working-space colours, full size.
    alpha : (H, W) coverage or None.
    hists : {bins: (bins, bins, bins)} histograms on the fit, preview and transfer grids.
    preview : (h, w, 3) uint8 preview picture (working-space colours).
    """

    encoding: object
    encoded: np.ndarray
    alpha: np.ndarray | None
    hists: dict
    preview: np.ndarray


def load_photo(photo: str, preview_side: int = PREVIEW_SIDE) -> LoadedPhoto:
    """Read the photo as ``apply`` does (colour spaces, histograms); nothing is written."""
    if not Path(photo).is_file():
        raise InputError(f"{photo}: " + ("is a folder, not a photo" if Path(photo).is_dir()
                                         else "not a regular file" if Path(photo).exists()
                                         else "no such file"))
    base = _base_options()
    image = read_image(photo)
    encoding = ColorEncoding.for_image(image, base.spaces.input, base.spaces.working)
    encoded, _ = encoding.encode(image.rgb(), image.is_float)
    encoded = np.ascontiguousarray(encoded, dtype=np.float32)
    alpha = image.alpha()
    limit = base.transfer.max_pixels
    hists = {bins: image_histogram(encoded, bins, alpha, limit)
             for bins in (base.fit.bins, PREVIEW_BINS, base.transfer.bins)}
    height, width = encoded.shape[:2]
    side = min(preview_side, max(height, width))
    small = thumbnail(np.clip(encoded, 0.0, 1.0), side, side)
    preview = np.clip(np.round(small * 255.0), 0, 255).astype(np.uint8)
    return LoadedPhoto(encoding, encoded, alpha, hists, preview)


def load_session(photo: str, style_dir: str | None = None, preset: str | None = None,
                 preview_side: int = PREVIEW_SIDE,
                 warn: Callable[[str], None] | None = None,
                 progress: Callable[[int, int, str], None] | None = None,
                 loaded: LoadedPhoto | None = None,
                 setting_names: Mapping[str, str] | None = None) -> Session:
    """Read the photo (unless ``loaded`` holds it) and the styles as ``apply`` does;
    nothing is written.

    ``style_dir`` photos' histograms come from (and go to) the histogram
    cache, as with ``apply``. Raises InputError on a missing or unreadable
    photo or style source (one line). ``setting_names``: :attr:`Session.setting_names`.
    """
    if loaded is None:
        loaded = load_photo(photo, preview_side)
    base = _base_options()
    source = StyleSource(style_dir, preset, HistogramCache())
    styles = load_styles(source, base.transfer.bins, base.spaces.working, warn, progress,
                         matching_hook(source, _look_options(), [photo]))  # (what it opens on)
    styles = styles_in_space(styles, loaded.encoding.working)
    pictures = style_pictures(styles, THUMBNAIL_SIDE)
    return Session(photo=str(photo), style_dir=None if style_dir is None else str(style_dir),
                   preset=preset, names=list(styles.names), styles=styles,
                   encoding=loaded.encoding, hists=loaded.hists, preview=loaded.preview,
                   thumbnails=[pictures[name] for name in styles.names], base=base,
                   lut_size=base.map.size, loaded=loaded, setting_names=setting_names)


def describe_outcome(outcome, setting_names: Mapping[str, str] | None = None) -> dict:
    """What a grade did (``color.outcome.GradeOutcome``), for the page (JSON-friendly).

    The outcome's own fields (``source``: "preset-look", "own-scene", "set-look",
    "palette"; ``strength``: the look's own strength times ``blend``, the
    ``--strength``; ``look_strength``; the photo's mean change, ...) and ``words``: its
    lines (``outcome.lines()``) without their "grade: " lead, naming settings as
    ``setting_names`` says (the command line: its flags).
    """
    outcome = outcome.named(setting_names)
    lines = outcome.lines()
    head = lines[0].removeprefix("grade: ")
    return {**outcome.as_dict(), "words": " ".join([head, *lines[1:]])}


class ExactGrader:
    """The exact colour maps and the fit's losses (built in the job worker).

    Parameters
    ----------
    state : :meth:`Session.grader_state`.
    """

    def __init__(self, state: dict) -> None:
        self.styles = state["styles"]
        self.hists = state["hists"]
        self.base = state["base"]
        self.encoding = state["encoding"]
        self.lut_size = state["lut_size"]
        self._fast = _FastGrader(self.styles, self.hists[PREVIEW_BINS], self.base,
                                 self.encoding)
        self._loss_problem = None

    def color_map(self, settings: Settings) -> np.ndarray:
        """The colour map ``apply --weights W --no-regrain`` grades with (33^3, float32).

        ``apply``'s own grade path (``color.grading.grade_histograms``) on the
        photo's histograms, with the weights read from the command line's text.
        """
        options = _options(self.base, settings, weights=_apply_weights(settings))
        photo = PhotoHistograms(self.hists[options.fit.bins],
                                self.hists[options.transfer.bins])
        grade, _ = grade_histograms(photo, self.styles, options, self.encoding)
        return np.ascontiguousarray(grade.color_map, dtype=np.float32)

    def reference(self, settings: Settings) -> dict:
        """The exact map of ``settings`` and its offset from the fast map there."""
        exact = self.color_map(settings)
        fast = self._fast.solve(settings, _apply_weights(settings))
        return {"exact": exact,
                "offset": (exact - resample_lattice(fast, self.lut_size)).astype(np.float32)}

    def slopes(self, settings: Settings, step: float = SLOPE_STEP) -> np.ndarray:
        """How the fast map changes towards each style, at ``settings``' weights w.

        Returns (S, n, n, n, 3) float32 (n: the LUT size): slope s is
        ``(F((1 - h) w + h e_s) - F(w)) / h`` with F the fast map (its plan at
        ``apply``'s tolerance, every one from the plan at w) and h = ``step``.
        A move dw (summing to 0) changes the map by about ``sum_s dw_s slope_s``
        (dw = sum_s dw_s (e_s - w)): the page's instant preview.
        """
        weights = np.asarray(_apply_weights(settings))
        weights = weights / weights.sum()
        tol = self.base.transfer.tol
        centre = resample_lattice(self._fast.solve(settings, weights, tol), self.lut_size)
        out = np.empty((len(weights), *centre.shape), dtype=np.float32)
        for s in range(len(weights)):
            towards = (1.0 - step) * weights + step * np.eye(len(weights))[s]
            moved = self._fast.solve(settings, towards, tol)
            out[s] = (resample_lattice(moved, self.lut_size) - centre) / step
        return out

    def losses(self, rows: list[tuple[float, ...]]) -> list[float]:
        """The fit's loss (fit grid, as ``apply`` fits) at each row of weights."""
        fit = self.base.fit
        if self._loss_problem is None:
            self._loss_problem = fit_problem(self.hists[fit.bins], self.styles.at_bins(fit.bins),
                                          fit)
        target, hists, geometry = self._loss_problem
        out = []
        for row in rows:
            weights = np.asarray(row, dtype=np.float64)
            out.append(loss_at(target, hists, geometry, weights / weights.sum(), fit))
        return out


def serve_jobs(connection) -> None:
    """The job worker's loop: build an :class:`ExactGrader`, answer jobs until EOF.

    Messages: ``(kind, payload)`` with kind "reference" or "slopes" (payload:
    Settings) or "losses" (payload: rows of weights); answers ``("ok",
    result, seconds)`` or ``("error", one line, seconds)``.
    """
    try:
        grader = ExactGrader(connection.recv())
        connection.send(("ready", os.getpid(), 0.0))
    except (EOFError, OSError):  # the server stopped while this worker was starting
        return
    while True:
        try:
            kind, payload = connection.recv()
        except (EOFError, OSError):
            return
        start = time.perf_counter()
        try:
            if kind == "reference":
                answer = ("ok", grader.reference(payload))
            elif kind == "slopes":
                answer = ("ok", grader.slopes(payload))
            elif kind == "losses":
                answer = ("ok", grader.losses(payload))
            else:
                answer = ("error", f"unknown job {kind!r}")
        except Exception as exc:  # reported to the page as one line, the worker lives on
            text = str(exc).strip().splitlines()
            answer = ("error", text[0] if text else type(exc).__name__)
        try:
            connection.send((*answer, time.perf_counter() - start))
        except (EOFError, OSError):
            return
