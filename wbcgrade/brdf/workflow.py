"""BRDF workflows: files in, fits and files out (what ``wbcgrade brdf`` runs).

- :func:`write_database`: write analytic materials as a database folder.
- :func:`fit_outputs`: the output paths of a fit, checked before any work.
- :func:`fit_measurement`: read a measured BRDF and a database, fit it
  (from all measurements and/or decimated ones), write the fitted BRDF and a
  comparison picture; returns a :class:`MeasurementFit`.

The command line only parses options, calls these, shows progress and prints
the result. Data flow and names: ``docs/architecture.md``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbcgrade._publish import check_output_path, remove_stale_beside
from wbcgrade.brdf import analytic, io, merl, render, sampled, sampling
from wbcgrade.brdf.defaults import (
    DEFAULT_DIRECTIONS,
    DEFAULT_FIT_DIRECTIONS,
    DEFAULT_LOSS,
    DEFAULT_MAX_ITER,
    DEFAULT_N_ITER,
    DEFAULT_TOL,
    DEFAULT_WIDTH,
)
from wbcgrade.brdf.fit import fit_brdf
from wbcgrade.errors import NumericalError, OptionError

__all__ = ["FitRun", "MeasurementFit", "write_database", "default_fit_output", "fit_outputs",
           "fit_measurement", "comparison_picture", "ranked"]

#: ``progress(label, n_evaluations, weights, loss)`` after each evaluation of a fit.
FitProgress = Callable[[str, int, np.ndarray, float], None]


def write_database(folder: str | os.PathLike, materials: Sequence[str] = (), count: int = 6,
                   directions: int = DEFAULT_DIRECTIONS,
                   progress: Callable[[int, int, str], None] | None = None) -> list[Path]:
    """Write analytic BRDFs into ``folder`` (created if needed).

    Parameters
    ----------
    folder : path-like
    materials : sequence of str
        Material names (``analytic.all_material_names()``), written as
        ``<name>.<ext>``; when empty, the first ``count`` of the built-in
        catalogue, written as ``NN-<name>.<ext>``.
    count : int
    directions : int
        Hemisphere directions N of the ``.npz`` files (anisotropic materials).
    progress : callable, optional
        ``progress(done, total, name)`` after each file.

    Returns
    -------
    paths : list of Path
        Isotropic materials as MERL ``.binary``, anisotropic ones as sampled
        ``.npz`` (N, N, 3): the MERL format cannot hold anisotropy.
    """
    chosen = ([analytic.material_by_name(n) for n in materials] if materials
              else analytic.default_materials(count))
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    dirs = sampling.hemisphere_directions(directions)
    written = []
    for index, material in enumerate(chosen):
        stem = material.name if materials else f"{index + 1:02d}-{material.name}"
        if material.isotropic:
            path = merl.write_merl(out / f"{stem}.binary", merl.tabulate_merl(material.evaluate))
        else:
            path = io.write_sampled(out / f"{stem}.npz", analytic.sample_material(material, dirs),
                                    dirs, name=material.name)
        written.append(path)
        if progress is not None:
            progress(index + 1, len(chosen), material.name)
    return written


def default_fit_output(measured: str | os.PathLike, keep: float | None) -> Path:
    """``./<measured stem>[-keepK]-fit.binary`` in the current folder."""
    tag = "" if keep is None else f"-keep{keep * 100:g}"
    return Path.cwd() / f"{Path(measured).stem}{tag}-fit.binary"


def fit_outputs(measured: str | os.PathLike, database: str | os.PathLike,
                keeps: Sequence[float] = (), output: str | os.PathLike | None = None,
                png: str | os.PathLike | None = None,
                no_png: bool = False) -> tuple[Path, Path | None]:
    """The fitted BRDF's and the picture's paths, checked before any work.

    Defaults: :func:`default_fit_output` for the BRDF, its ``.png`` sibling
    for the picture (None with ``no_png``). Raises OptionError when an output
    is an input (the measurement or a database file) or the BRDF's suffix is
    not ``.binary``/``.merl``/``.npz``; InputError when an output's folder is
    missing or not writable or an output exists and is not a regular file.
    Existing regular files are replaced.
    """
    measured = Path(measured)
    out = Path(output) if output else default_fit_output(measured, keeps[0] if keeps else None)
    png_path = None if no_png else (Path(png) if png else out.with_suffix(".png"))
    inputs = {measured.resolve(), *(p.resolve() for p in io.database_files(database))}
    for target, name in ((out, "output"), (png_path, "png")):
        if target is not None and target.resolve() in inputs:
            raise OptionError(f"{target}: an input; choose another {{{name}}}", name, path=target)
    if out.suffix.lower() not in io.BRDF_SUFFIXES:
        raise OptionError(f"{out}: {{output}} needs a .binary or .npz suffix", "output", path=out)
    for target in (out, png_path):
        if target is not None:
            check_output_path(target, overwrite=True)
    return out, png_path


def ranked(names: Sequence[str], weights: np.ndarray) -> list[tuple[str, float]]:
    """(name, weight) pairs, largest weight first (ties keep the database order)."""
    order = np.argsort(-np.asarray(weights), kind="stable")
    return [(names[i], float(weights[i])) for i in order]


@dataclass(frozen=True)
class FitRun:
    """One fit of a measurement: ``label`` ("full" or "keep K%"), the fit, its PSNR in dB
    against the full measurement (inf for an exact fit)."""

    label: str
    fit: object  # wbcgrade.brdf.fit.BRDFFit (not imported here: keeps this module light)
    psnr: float


@dataclass(frozen=True)
class MeasurementFit:
    """What :func:`fit_measurement` did.

    Attributes
    ----------
    measured : Path
    names : list of str, length S
        Database materials (file stems), in the order of every fit's weights.
    directions, fit_directions : int
        Hemisphere sampling size N; incoming directions whose rows fitted the weights.
    gamma : float
        Entropic regularisation of the hemisphere geometry.
    loss : str
    runs : list of FitRun
        In order: "full" (unless ``--keep`` without ``compare``), then one per keep.
    output : Path
        The fitted BRDF written (the first keep's fit when keeps were given).
    png : Path or None
    """

    measured: Path
    names: list[str]
    directions: int
    fit_directions: int
    gamma: float
    loss: str
    runs: list[FitRun]
    output: Path
    png: Path | None

    def as_dict(self) -> dict:
        """The result as JSON-ready values (non-finite numbers as None: JSON has no NaN)."""
        return {
            "measured": str(self.measured),
            "database": list(self.names),
            "directions": self.directions,
            "fit_directions": self.fit_directions,
            "gamma": _json_number(self.gamma),
            "loss": self.loss,
            "fits": [{
                "label": run.label,
                "kept_fraction": run.fit.kept_fraction,
                "weights": dict(zip(self.names, (float(w) for w in run.fit.weights),
                                    strict=True)),
                "psnr_db": _json_number(run.psnr),  # null: an exact fit (infinite PSNR)
                "loss": _json_number(run.fit.loss),
                "initial_loss": _json_number(run.fit.initial_loss),
                "n_evaluations": run.fit.n_evaluations,
                "converged": run.fit.converged,
                "time_s": round(run.fit.time_s, 3),
            } for run in self.runs],
            "output": str(self.output),
            "png": None if self.png is None else str(self.png),
        }


def _json_number(value: float) -> float | None:
    """``value`` as a float for JSON, None where it is not finite."""
    value = float(value)
    return value if np.isfinite(value) else None


def fit_measurement(
    measured: str | os.PathLike,
    database: str | os.PathLike,
    *,
    keeps: Sequence[float] = (),
    seed: int = 0,
    output: str | os.PathLike | None = None,
    png: str | os.PathLike | None = None,
    no_png: bool = False,
    compare: bool = True,
    loss: str = DEFAULT_LOSS,
    directions: int = DEFAULT_DIRECTIONS,
    fit_directions: int = DEFAULT_FIT_DIRECTIONS,
    width: float = DEFAULT_WIDTH,
    n_iter: int = DEFAULT_N_ITER,
    max_iter: int = DEFAULT_MAX_ITER,
    tol: float = DEFAULT_TOL,
    progress: FitProgress | None = None,
) -> MeasurementFit:
    """Fit the BRDF file ``measured`` with weights on the BRDF files of ``database``.

    Parameters
    ----------
    measured : path-like
        ``.binary``/``.merl`` (resampled onto the hemisphere) or ``.npz``
        sampled on ``directions`` directions.
    database : path-like
        Folder of BRDF files; ``measured`` is left out when it lies in it.
    keeps : sequence of float in (0, 1]
        Fit also (or only, without ``compare``) from these random fractions of
        the (incoming, outgoing) measurements (``sampled.decimation_mask``
        with ``seed``): a simulated sparse acquisition.
    output, png, no_png : see :func:`fit_outputs` (checked before any work).
    compare : bool
        With ``keeps``, also fit the full measurement (first run).
    loss : one of ``defaults.BRDF_LOSSES``
    directions : int
        Hemisphere sampling size N (the histograms have N bins).
    fit_directions : int
        Well-spread incoming directions whose rows fit the weights; 0 or N: all.
    width : float
        Kernel width in sample spacings (sets gamma; ``sampling.default_gamma``).
    n_iter, max_iter, tol : barycenter iterations L, L-BFGS iterations at most,
        L-BFGS stopping gain (see ``fit.fit_brdf``).
    progress : callable, optional
        ``progress(label, n_evaluations, weights, loss)`` after each evaluation.

    Returns
    -------
    MeasurementFit
        The fitted BRDF (N, N, 3) is written to ``output`` and the picture
        (spheres: reference, then each fit, with PSNR and top weights) to ``png``.

    Raises
    ------
    OptionError, InputError
        Bad outputs (before any work), unreadable or mismatched BRDF files.
    NumericalError
        A fit whose PSNR is not defined (NaN).
    """
    measured = Path(measured)
    out, png_path = fit_outputs(measured, database, keeps, output, png, no_png)
    dirs = sampling.hemisphere_directions(directions)
    geometry = sampling.hemisphere_geometry(directions,
                                            sampling.default_gamma(directions, width))
    reference = io.load_brdf(measured, dirs)
    names, base = io.load_database(database, dirs, exclude=measured)
    subset = None if fit_directions in (0, directions) else sampling.spread_subset(
        dirs, fit_directions)

    plans: list[tuple[str, np.ndarray | None]] = [
        (f"keep {fraction * 100:g}%", sampled.decimation_mask(directions, directions, fraction,
                                                               seed))
        for fraction in keeps]
    if not keeps or compare:
        plans.insert(0, ("full", None))
    runs = []
    for label, mask in plans:
        callback = None
        if progress is not None:
            def callback(n, weights, value, label=label):
                progress(label, n, weights, value)

        result = fit_brdf(reference, base, geometry, mask=mask, loss=loss, n_iter=n_iter,
                          max_iter=max_iter, tol=tol, fit_incoming=subset, callback=callback)
        psnr = sampled.psnr(reference, result.values)
        if np.isnan(psnr):
            raise NumericalError(f"the {label} fit of {measured} has no defined PSNR")
        runs.append(FitRun(label, result, psnr))

    final = runs[1] if keeps and compare else runs[0]
    remove_stale_beside(out, png_path)  # what killed runs left
    io.save_brdf(out, final.fit.values, dirs, name=f"{measured.stem} {final.label} fit")
    if png_path is not None:
        render.write_png(png_path, comparison_picture(reference, dirs, measured.stem, names,
                                                      runs))
    return MeasurementFit(
        measured=measured, names=names, directions=directions,
        fit_directions=directions if subset is None else len(subset),
        gamma=float(geometry.gamma), loss=loss, runs=runs, output=out, png=png_path)


def comparison_picture(reference: np.ndarray, directions: np.ndarray, name: str,
                       names: Sequence[str], runs: Sequence[FitRun]) -> np.ndarray:
    """Spheres rendered with the reference and each fit, captioned.

    Parameters
    ----------
    reference : ndarray, shape (N, N, 3)
    directions : ndarray, shape (N, 3)
    name : str
        The reference's name (first caption).
    names : sequence of str, length S
    runs : sequence of FitRun

    Returns
    -------
    image : ndarray, shape (H, (1 + len(runs)) * W, 3), uint8
    """
    renderings = [render.render_sphere(reference, directions)]
    captions = [["reference", name[:30], "(all measurements)"]]
    for run in runs:
        renderings.append(render.render_sphere(run.fit.values, directions))
        shown = [(n, w) for n, w in ranked(names, run.fit.weights)[:3] if w >= 0.005]
        captions.append([f"fit, {run.label}", f"PSNR {run.psnr:.1f} dB",
                         *(f"{w * 100:.0f}%  {n}"[:31] for n, w in shown)])
    return render.comparison_image(renderings, captions, caption_lines=5)
