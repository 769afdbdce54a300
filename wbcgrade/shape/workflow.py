"""Shape workflows: files in, fits and files out (what ``wbcgrade shape`` runs).

- :func:`complete_mesh_file`: voxelise a partial mesh and a database of
  meshes (optionally aligned on their principal axes; the database in
  ``jobs`` worker processes through :class:`wbcgrade._executor.Executor`),
  place the partial on the database, fit, and write the completed surface
  (the input united with the added part, in the input's own coordinates),
  the fitted density and a picture.
- :func:`project_volume_file`: read a volume and a database of volumes,
  shrink them to the working resolution, fit, and write the fitted volume
  rescaled to the input's total intensity, and a picture.

The command line only parses options, calls these, shows progress and
prints the result. Data flow and names: ``docs/architecture.md``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from wbcgrade._executor import Executor
from wbcgrade._publish import remove_stale_beside
from wbcgrade.errors import InputError, OptionError
from wbcgrade.shape.complete import complete_shape
from wbcgrade.shape.database import VoxelShape, check_database_size, expand_paths, load_shape
from wbcgrade.shape.defaults import (
    DEFAULT_LOSS,
    DEFAULT_MAX_ITER,
    DEFAULT_N_ITER,
    DEFAULT_RESOLUTION,
)
from wbcgrade.shape.memory import check_memory
from wbcgrade.shape.mesh import MESH_SUFFIXES, write_mesh
from wbcgrade.shape.projection import Projection, project
from wbcgrade.shape.render import write_png
from wbcgrade.shape.sheets import completion_sheet, projection_sheet
from wbcgrade.shape.surface import completion_surface
from wbcgrade.shape.volume import (
    density_from_volume,
    read_volume,
    resample_volume,
    volume_suffix,
    write_volume,
)

log = logging.getLogger(__name__)

__all__ = ["ShapeResult", "complete_mesh_file", "project_volume_file", "check_not_inputs"]

#: ``callback(n_evaluations, weights, loss)`` after each evaluation of the fit.
FitCallback = Callable[[int, np.ndarray, float], None]


@dataclass(frozen=True)
class ShapeResult:
    """What a shape workflow did.

    projection : Projection
        The fit: weights (S,), barycenter volume, losses, evaluations.
    details : dict
        Input, working shape or resolution, and the files written
        (keys ending in ``_file``), in the order the command prints them.
    """

    projection: Projection
    details: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """The fit and the details as JSON-ready values."""
        p = self.projection
        return {
            "method": p.method,
            "loss": p.loss_name,
            "missing": p.missing,
            "weights": {n: float(w) for n, w in zip(p.names, p.weights, strict=True)},
            "loss_value": p.loss,
            "initial_loss": p.initial_loss,
            "kernel_width_voxels": p.width,
            "evaluations": p.n_evaluations,
            "coarse_evaluations": p.n_coarse_evaluations,
            "converged": p.converged,
            "time_s": round(p.time_s, 3),
            **self.details,
        }


def check_not_inputs(outputs: Sequence[Path], inputs: Sequence[Path]) -> None:
    """Raise InputError when an output would overwrite an input."""
    resolved = {Path(p).resolve() for p in inputs}
    for out in outputs:
        if Path(out).resolve() in resolved:
            raise InputError(f"{out}: output would overwrite an input")


@dataclass(frozen=True)
class _Voxelising:
    """What every database mesh's voxelisation needs (sent once to each worker)."""

    resolution: int
    align: bool
    reference: VoxelShape | None


def _voxelise(path: Path, settings: _Voxelising) -> tuple[VoxelShape, list[str]]:
    """One database mesh, voxelised; -> the shape and its repair messages."""
    messages: list[str] = []
    shape = load_shape(path, settings.resolution, align=settings.align,
                       reference=settings.reference, warn=messages.append, keep_mesh=True)
    return shape, messages


def complete_mesh_file(
    partial: str | os.PathLike,
    database: Sequence[str | os.PathLike],
    *,
    output: str | os.PathLike | None = None,
    volume_path: str | os.PathLike | None = None,
    png_path: str | os.PathLike | None = None,
    resolution: int = DEFAULT_RESOLUTION,
    missing: float | None = None,
    loss: str = DEFAULT_LOSS,
    euclidean: bool = False,
    width: float | None = None,
    n_iter: int = DEFAULT_N_ITER,
    max_iter: int = DEFAULT_MAX_ITER,
    coarse_to_fine: bool = True,
    align: bool = False,
    observed_only: bool = True,
    smooth: int = 10,
    top: int = 3,
    warn: Callable[[str], None] | None = None,
    on_mesh: Callable[[int, int, Path], None] | None = None,
    callback: FitCallback | None = None,
    jobs: int = 1,
) -> ShapeResult:
    """Infer the missing geometry of the mesh ``partial`` from a database of meshes.

    See :func:`wbcgrade.shape.complete.complete_shape` (placing, fitting,
    drawing) and :func:`~wbcgrade.shape.surface.completion_surface` (the
    written mesh: the input itself, united with what the database adds,
    in the input's coordinates).

    Parameters
    ----------
    partial : path-like
        The partial mesh (``.obj``, ``.ply``, ``.stl``, ``.off``).
    database : sequence of path-like
        Mesh files or folders of them; ``partial`` is left out.
    output : path-like, optional
        Completed mesh (a mesh suffix); default ``./<stem>_completed.obj``.
    volume_path, png_path : path-like, optional
        Fitted density (.npy: the debiased barycenter on the fit's grid, in
        the database's unit frame) and picture (input and completion in the
        input's frame, the added part in blue; the heaviest database
        shapes); default beside ``output``.
    resolution : int
        Voxels along each axis of the unit frame: volumes (n, n, n).
    missing : float, optional
        Fraction of the shape's volume missing from the input; estimated when None.
    loss, euclidean, width, n_iter, max_iter, coarse_to_fine :
        See :func:`wbcgrade.shape.projection.project` (``width`` in voxels).
    observed_only : bool
        Compare the input's voxels only (``--all-voxels`` turns it off).
    align : bool
        Rotate every mesh onto its principal axes, signs chosen to overlap the
        input most, and fit a rotation when placing the input.
    smooth : int
        Taubin smoothing passes on the surface.
    top : int
        Database shapes shown in the picture.
    warn : callable, optional
        One-line messages about repaired meshes.
    on_mesh : callable, optional
        ``on_mesh(done, total, path)`` once the checks passed (``done`` 0,
        the first mesh's path) and after each mesh is voxelised.
    callback : callable, optional
        ``callback(n_evaluations, weights, loss)`` after each evaluation.
    jobs : int
        Worker processes voxelising the database (1: in this process). The
        voxelisations, hence the result, are the same for any ``jobs``.

    Returns
    -------
    ShapeResult
        ``details``: input, resolution, missing_estimated, placed_on (the
        database shape the input was placed on), placement_scale (of the
        input's own normalisation), placements (1 or 2), watertight,
        mesh_file, volume_file, png_file.

    Raises
    ------
    InputError
        Missing or bad files, a database of fewer than two shapes, an output
        that is an input, a grid too large for the memory.
    """
    partial = Path(partial)
    if not partial.is_file():
        raise InputError(f"{partial}: no such mesh file")
    output = Path(output) if output else Path(f"{partial.stem}_completed.obj")
    if output.suffix.lower() not in MESH_SUFFIXES:
        raise OptionError(f"{output}: the {{output}} mesh must end in {', '.join(MESH_SUFFIXES)}",
                          "output", path=str(output))
    volume_path = Path(volume_path) if volume_path else output.with_suffix(".npy")
    png_path = Path(png_path) if png_path else output.with_suffix(".png")
    paths = [p for p in expand_paths(database, "mesh") if p.resolve() != partial.resolve()]
    check_database_size(paths)
    check_not_inputs([output, volume_path, png_path], [partial, *paths])
    check_memory((resolution,) * 3, len(paths), n_iter)

    if on_mesh is not None:
        on_mesh(0, len(paths) + 1, partial)
    reference = load_shape(partial, resolution, align=align, warn=warn, keep_mesh=True)
    if on_mesh is not None:
        on_mesh(1, len(paths) + 1, partial)
    loaded: dict[Path, VoxelShape] = {}
    settings = _Voxelising(resolution, align, replace(reference, mesh=None) if align else None)
    with Executor(settings, jobs=min(jobs, len(paths))) as executor:
        for path, (shape, messages) in executor.map_unordered(_voxelise, paths):
            loaded[path] = shape
            for message in messages:
                (warn or log.warning)(message)
            if on_mesh is not None:
                on_mesh(len(loaded) + 1, len(paths) + 1, path)
    shapes = [reference, *(loaded[path] for path in paths)]
    completion = complete_shape(
        shapes[0], shapes[1:], missing=missing, loss=loss, euclidean=euclidean, width=width,
        n_iter=n_iter, max_iter=max_iter, callback=callback, coarse_to_fine=coarse_to_fine,
        rotate=align, observed_only=observed_only,
    )
    surface = completion_surface(completion, smooth_iterations=smooth, n_iter=n_iter)
    remove_stale_beside(output, volume_path, png_path)  # what killed runs left
    write_mesh(surface, output)
    write_volume(volume_path, completion.fitted)
    write_png(png_path, completion_sheet(completion, top=top, surface=surface))
    return ShapeResult(completion.projection, {
        "input": str(partial),
        "resolution": resolution,
        "missing_estimated": missing is None,
        "placed_on": completion.database[completion.placement.reference].name,
        "placement_scale": round(completion.placement.scale, 4),
        "placements": completion.n_placements,
        "watertight": bool(surface.is_watertight),
        "mesh_file": str(output),
        "volume_file": str(volume_path),
        "png_file": str(png_path),
    })


def project_volume_file(
    volume: str | os.PathLike,
    database: Sequence[str | os.PathLike],
    *,
    output: str | os.PathLike | None = None,
    png_path: str | os.PathLike | None = None,
    resolution: int = DEFAULT_RESOLUTION,
    missing: float | None = None,
    loss: str = DEFAULT_LOSS,
    euclidean: bool = False,
    width: float | None = None,
    n_iter: int = DEFAULT_N_ITER,
    max_iter: int = DEFAULT_MAX_ITER,
    coarse_to_fine: bool = True,
    top: int = 3,
    callback: FitCallback | None = None,
) -> ShapeResult:
    """Project the volume file ``volume`` (.npy or NIfTI) onto a database of volumes.

    Parameters
    ----------
    volume : path-like
        Non-negative volume (X, Y, Z); database volumes must have its shape.
    database : sequence of path-like
        Volume files or folders of them; ``volume`` is left out.
    output : path-like, optional
        Fitted volume (.npy, .nii, .nii.gz); default ``./<stem>_projected.npy``.
    png_path : path-like, optional
        Picture; default beside ``output``.
    resolution : int
        Voxels along the largest axis: every volume is shrunk to it (aspect
        kept; smaller volumes are used as they are).
    missing : float, optional
        Fraction of the input's mass missing (default 0).
    loss, euclidean, width, n_iter, max_iter, coarse_to_fine, top, callback :
        As in :func:`complete_mesh_file`.

    Returns
    -------
    ShapeResult
        The fitted volume is written at the working shape, scaled to the
        (shrunk) input's total intensity. ``details``: input, shape,
        volume_file, png_file.
    """
    volume = Path(volume)
    if not volume.is_file():
        raise InputError(f"{volume}: no such volume file")
    output = (Path(output) if output
              else Path(volume.name[: -len(volume_suffix(volume))] + "_projected.npy"))
    if not volume_suffix(output):
        raise OptionError(f"{output}: the {{output}} volume must end in .npy, .nii or .nii.gz",
                          "output", path=str(output))
    png_path = (Path(png_path) if png_path
                else Path(str(output)[: -len(volume_suffix(output))] + ".png"))
    paths = [p for p in expand_paths(database, "volume") if p.resolve() != volume.resolve()]
    check_database_size(paths)
    check_not_inputs([output, png_path], [volume, *paths])

    original = read_volume(volume)
    shape_after = tuple(
        max(2, round(n * min(1.0, resolution / max(original.shape)))) for n in original.shape
    )
    check_memory(shape_after, len(paths), n_iter)
    source = resample_volume(original, resolution)
    volumes = []
    for path in paths:
        data = read_volume(path)
        if data.shape != original.shape:
            raise InputError(
                f"{path}: shape {data.shape} differs from the input's {original.shape}"
            )
        volumes.append(resample_volume(data, resolution))
    projection = project(
        density_from_volume(source),
        [density_from_volume(v) for v in volumes],
        names=[p.name for p in paths],
        missing=0.0 if missing is None else missing,
        loss=loss,
        euclidean=euclidean,
        width=width,
        n_iter=n_iter,
        max_iter=max_iter,
        callback=callback,
        coarse_to_fine=coarse_to_fine,
    )
    fitted = projection.barycenter / projection.barycenter.sum() * source.sum()
    remove_stale_beside(output, png_path)  # what killed runs left
    write_volume(output, fitted)
    write_png(png_path, projection_sheet(source, projection, volumes, top=top))
    return ShapeResult(projection, {
        "input": str(volume),
        "shape": list(source.shape),
        "volume_file": str(output),
        "png_file": str(png_path),
    })
