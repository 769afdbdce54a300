"""``wbcgrade shape``: complete meshes and project volumes onto a database (paper §5.3-5.4)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from wbcgrade.errors import InputError

# The names of wbcgrade.shape.complete.LOSS_NAMES, repeated so `--help` needs no core import.
_LOSS_CHOICE = click.Choice(["kl_reverse", "kl", "quadratic", "l1", "wasserstein"],
                            case_sensitive=False)


def _progress(enabled: bool, total: int, desc: str):
    """A tqdm bar on stderr and a callback for the core's fit."""
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="eval", disable=not enabled, file=sys.stderr,
               leave=False)

    def callback(n_evaluations: int, weights, loss: float) -> None:
        if n_evaluations > bar.total:
            bar.total = n_evaluations
        bar.update(n_evaluations - bar.n)
        bar.set_postfix(loss=f"{loss:.4g}")

    return bar, callback


def _check_outputs(outputs: list[Path], inputs: list[Path]) -> None:
    """Never overwrite an input."""
    resolved = {p.resolve() for p in inputs}
    for out in outputs:
        if out.resolve() in resolved:
            raise InputError(f"{out}: output would overwrite an input")


def _print_weights(projection, as_json: bool, extra: dict) -> None:
    if as_json:
        record = {
            "method": projection.method,
            "loss": projection.loss_name,
            "missing": projection.missing,
            "weights": {n: float(w) for n, w in zip(projection.names, projection.weights,
                                                    strict=True)},
            "loss_value": projection.loss,
            "initial_loss": projection.initial_loss,
            "kernel_width_voxels": projection.width,
            "evaluations": projection.n_evaluations,
            "coarse_evaluations": projection.n_coarse_evaluations,
            "converged": projection.converged,
            "time_s": round(projection.time_s, 3),
            **extra,
        }
        click.echo(json.dumps(record, indent=2))
        return
    width = max(len(n) for n in projection.names)
    click.echo(f"{'shape':<{width}}  weight")
    for index in projection.order():
        click.echo(f"{projection.names[index]:<{width}}  {projection.weights[index]:.4f}")
    click.echo(
        f"{projection.method} projection, {projection.loss_name} loss "
        f"{projection.initial_loss:.4g} -> {projection.loss:.4g} in "
        f"{projection.n_evaluations} evaluations"
        + (f" ({projection.n_coarse_evaluations} on a half-size grid)"
           if projection.n_coarse_evaluations else "")
        + f", {projection.time_s:.1f} s, "
        f"missing fraction {projection.missing:.3f}"
    )
    for key, value in extra.items():
        if key.endswith("_file"):
            click.echo(f"wrote {value}")


_common_options = [
    click.option("--database", "-d", "database", multiple=True, required=True,
                 help="Database files or folders (repeat the option for several)."),
    click.option("--resolution", "-n", type=click.IntRange(min=8), default=64, show_default=True,
                 help="Voxels along the largest axis."),
    click.option("--missing", type=click.FloatRange(0.0, 0.95), default=None,
                 help="Fraction of the input's volume that is missing "
                 "(complete: estimated when not given; project: 0)."),
    click.option("--euclidean", is_flag=True,
                 help="Fit a linear mixture of the database instead (for comparison)."),
    click.option("--width", type=click.FloatRange(min=0.5), default=None,
                 help="Kernel standard deviation in voxels (default 1 at 64^3, scaled)."),
    click.option("--iterations", type=click.IntRange(min=1), default=60, show_default=True,
                 help="Barycenter iterations L."),
    click.option("--max-iter", type=click.IntRange(min=1), default=15, show_default=True,
                 help="Optimiser iterations at most."),
    click.option("--coarse/--no-coarse", default=True, show_default=True,
                 help="Fit on a half-size grid first (grids of 32 voxels or more)."),
    click.option("--png", "png_path", type=click.Path(dir_okay=False, path_type=Path),
                 default=None, help="Picture of the views (default: beside -o, .png)."),
    click.option("--top", type=click.IntRange(min=0), default=3, show_default=True,
                 help="Database shapes shown in the picture."),
    click.option("--json", "as_json", is_flag=True, help="Print the result as JSON."),
    click.option("--quiet", "-q", is_flag=True, help="No progress bar."),
]


def _with_common(function):
    for option in reversed(_common_options):
        function = option(function)
    return function


@click.group()
def shape() -> None:
    """Complete shapes and project volumes with Wasserstein barycenters."""


@shape.command()
@click.argument("partial", type=click.Path(dir_okay=False, path_type=Path))
@_with_common
@click.option("--loss", type=_LOSS_CHOICE, default="kl_reverse", show_default=True,
              help="kl_reverse = KL(input|barycenter); kl = the paper's KL(barycenter|input).")
@click.option("--align", is_flag=True,
              help="Align every mesh on its principal axes first, picking the axes' signs "
                   "that overlap the input most (for databases of unaligned meshes).")
@click.option("--output", "-o", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Completed mesh (.obj, .ply, .stl, .off); default PARTIAL_completed.obj.")
@click.option("--volume", "volume_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Barycenter volume (.npy; default beside -o).")
@click.option("--smooth", type=click.IntRange(min=0), default=10, show_default=True,
              help="Taubin smoothing passes on the surface.")
def complete(partial, database, resolution, missing, euclidean, width, iterations, max_iter,
             coarse, png_path, top, as_json, quiet, loss, align, output, volume_path,
             smooth) -> None:
    """Infer the missing geometry of the mesh PARTIAL from a database of meshes.

    Writes the completed surface (-o), the barycenter volume (.npy) and a PNG
    with views of the input, the completion and the heaviest database shapes.
    """
    from tqdm import tqdm

    from wbcgrade.shape.complete import (
        check_database_size,
        check_memory,
        complete_shape,
        completion_sheet,
        completion_surface,
        expand_paths,
        load_shape,
    )
    from wbcgrade.shape.mesh import MESH_SUFFIXES, write_mesh
    from wbcgrade.shape.render import write_png
    from wbcgrade.shape.volume import write_volume

    if not partial.is_file():
        raise InputError(f"{partial}: no such mesh file")
    output = output or Path(f"{partial.stem}_completed.obj")
    if output.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(f"{output}: the output mesh must end in {', '.join(MESH_SUFFIXES)}")
    volume_path = volume_path or output.with_suffix(".npy")
    png_path = png_path or output.with_suffix(".png")
    paths = [p for p in expand_paths(database, "mesh") if p.resolve() != partial.resolve()]
    check_database_size(paths)
    _check_outputs([output, volume_path, png_path], [partial, *paths])
    check_memory((resolution,) * 3, len(paths), iterations)

    def warn(message: str) -> None:
        tqdm.write(f"Warning: {message}", file=sys.stderr)

    shapes = []
    for path in tqdm([partial, *paths], desc="voxelising", unit="mesh", disable=quiet,
                     file=sys.stderr, leave=False):
        reference = shapes[0] if shapes else None
        shapes.append(load_shape(path, resolution, align=align, reference=reference, warn=warn))
    bar, callback = _progress(not quiet, max_iter, "fitting")
    with bar:
        completion = complete_shape(
            shapes[0], shapes[1:], missing=missing, loss=loss, euclidean=euclidean,
            width=width, n_iter=iterations, max_iter=max_iter, callback=callback,
            coarse_to_fine=coarse,
        )
    surface = completion_surface(completion, smooth_iterations=smooth)
    write_mesh(surface, output)
    write_volume(volume_path, completion.projection.barycenter)
    write_png(png_path, completion_sheet(completion, top=top))
    _print_weights(
        completion.projection,
        as_json,
        {
            "input": str(partial),
            "resolution": resolution,
            "missing_estimated": missing is None,
            "watertight": bool(surface.is_watertight),
            "mesh_file": str(output),
            "volume_file": str(volume_path),
            "png_file": str(png_path),
        },
    )


@shape.command()
@click.argument("volume", type=click.Path(dir_okay=False, path_type=Path))
@_with_common
@click.option("--loss", type=_LOSS_CHOICE, default="kl_reverse", show_default=True,
              help="Loss between the barycenter and the input (the paper's MRIs: quadratic).")
@click.option("--output", "-o", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Fitted volume (.npy, .nii, .nii.gz); default VOLUME_projected.npy.")
def project(volume, database, resolution, missing, euclidean, width, iterations, max_iter,
            coarse, png_path, top, as_json, quiet, loss, output) -> None:
    """Project the volume VOLUME (.npy or NIfTI) onto a database of volumes.

    The fitted volume is written scaled to the input's total intensity, at the
    (possibly reduced) working resolution.
    """
    from wbcgrade.shape.complete import (
        check_database_size,
        check_memory,
        expand_paths,
        projection_sheet,
    )
    from wbcgrade.shape.complete import project as project_density
    from wbcgrade.shape.render import write_png
    from wbcgrade.shape.volume import (
        density_from_volume,
        read_volume,
        resample_volume,
        volume_suffix,
        write_volume,
    )

    if not volume.is_file():
        raise InputError(f"{volume}: no such volume file")
    output = output or Path(volume.name[: -len(volume_suffix(volume))] + "_projected.npy")
    if not volume_suffix(output):
        raise InputError(f"{output}: the output volume must end in .npy, .nii or .nii.gz")
    png_path = png_path or Path(str(output)[: -len(volume_suffix(output))] + ".png")
    paths = [p for p in expand_paths(database, "volume") if p.resolve() != volume.resolve()]
    check_database_size(paths)
    _check_outputs([output, png_path], [volume, *paths])

    original = read_volume(volume)
    shape_after = tuple(
        max(2, round(n * min(1.0, resolution / max(original.shape)))) for n in original.shape
    )
    check_memory(shape_after, len(paths), iterations)
    source = resample_volume(original, resolution)
    volumes = []
    for path in paths:
        data = read_volume(path)
        if data.shape != original.shape:
            raise InputError(
                f"{path}: shape {data.shape} differs from the input's {original.shape}"
            )
        volumes.append(resample_volume(data, resolution))
    bar, callback = _progress(not quiet, max_iter, "fitting")
    with bar:
        projection = project_density(
            density_from_volume(source),
            [density_from_volume(v) for v in volumes],
            names=[p.name for p in paths],
            missing=0.0 if missing is None else missing,
            loss=loss,
            euclidean=euclidean,
            width=width,
            n_iter=iterations,
            max_iter=max_iter,
            callback=callback,
            coarse_to_fine=coarse,
        )
    fitted = projection.barycenter / projection.barycenter.sum() * source.sum()
    write_volume(output, fitted)
    write_png(png_path, projection_sheet(source, projection, volumes, top=top))
    _print_weights(
        projection,
        as_json,
        {
            "input": str(volume),
            "shape": list(source.shape),
            "volume_file": str(output),
            "png_file": str(png_path),
        },
    )

