"""``wbcgrade shape``: complete meshes and project volumes onto a database (paper §5.3-5.4).

Parsing, progress and printing only; the work is ``wbcgrade.shape.workflow``
(imported inside the commands, so that ``wbcgrade --help`` stays fast).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from wbcgrade.limits import MAX_BARYCENTER_ITERATIONS
from wbcgrade.shape.defaults import DEFAULT_LOSS, LOSS_NAMES

_LOSS_CHOICE = click.Choice(LOSS_NAMES, case_sensitive=False)


class _FitProgress:
    """A tqdm bar on stderr, opened at the fit's first evaluation; ``close()`` at the end."""

    def __init__(self, enabled: bool, total: int, desc: str) -> None:
        self.enabled, self.total, self.desc, self.bar = enabled, total, desc, None

    def __call__(self, n_evaluations: int, weights, loss: float) -> None:
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total, desc=self.desc, unit="eval",
                            disable=not self.enabled, file=sys.stderr, leave=False)
        bar = self.bar
        if n_evaluations > bar.total:
            bar.total = n_evaluations
        bar.update(n_evaluations - bar.n)
        bar.set_postfix(loss=f"{loss:.4g}")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _print_result(result, as_json: bool) -> None:
    """The weights table and one summary line, or the JSON record."""
    if as_json:
        click.echo(json.dumps(result.as_dict(), indent=2))
        return
    projection = result.projection
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
        + (" (estimated)" if result.details.get("missing_estimated") else "")
    )
    if "placed_on" in result.details:
        click.echo(f"input placed on {result.details['placed_on']} "
                   f"(scale {result.details['placement_scale']:.3f} of its own frame)")
    for key, value in result.details.items():
        if key.endswith("_file"):
            click.echo(f"wrote {value}")


_common_options = [
    click.option("--database", "-d", "database", multiple=True, required=True,
                 help="Database files or folders (repeat the option for several)."),
    click.option("--resolution", "-n", type=click.IntRange(min=8), default=64, show_default=True,
                 help="Voxels along the largest axis."),
    click.option("--missing", type=click.FloatRange(0.0, 0.95), default=None,
                 help="Fraction of the input's volume that is missing "
                 "(complete: estimated where the input is placed when not given; project: 0)."),
    click.option("--euclidean", is_flag=True,
                 help="Fit a linear mixture of the database instead (for comparison)."),
    click.option("--width", type=click.FloatRange(min=0.5), default=None,
                 help="Kernel standard deviation in voxels (default 1 at 64^3, scaled)."),
    click.option("--iterations", type=click.IntRange(1, MAX_BARYCENTER_ITERATIONS), default=60,
                 show_default=True,
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


#: What ``wbcgrade shape`` needs beyond the base install (the ``shape`` extra).
SHAPE_EXTRA = ("trimesh", "skimage")


def _check_shape_extra() -> None:
    """One line, not a traceback, when the ``shape`` extra is not installed."""
    import importlib.util

    missing = [name for name in SHAPE_EXTRA if importlib.util.find_spec(name) is None]
    if missing:
        names = ", ".join("scikit-image" if name == "skimage" else name for name in missing)
        raise click.ClickException(f"wbcgrade shape needs {names}: "
                                   "pip install 'wbcgrade[shape]'")


@click.group()
def shape() -> None:
    """Complete shapes and project volumes with Wasserstein barycenters.

    Needs the ``shape`` extra: pip install 'wbcgrade[shape]' (trimesh, scikit-image).
    """
    _check_shape_extra()


@shape.command()
@click.argument("partial", type=click.Path(dir_okay=False, path_type=Path))
@_with_common
@click.option("--loss", type=_LOSS_CHOICE, default=DEFAULT_LOSS, show_default=True,
              help="kl_reverse = KL(input|barycenter); kl = the paper's KL(barycenter|input).")
@click.option("--observed-only/--all-voxels", default=True, show_default=True,
              help="Compare the input's voxels only, leaving the barycenter free where the "
                   "input is missing (kl_reverse, kl, quadratic, l1), or every voxel.")
@click.option("--align", is_flag=True,
              help="Align every mesh on its principal axes first, picking the axes' signs "
                   "that overlap the input most, and fit a rotation when placing the input "
                   "(for databases of unaligned meshes).")
@click.option("--output", "-o", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Completed mesh (.obj, .ply, .stl, .off); default PARTIAL_completed.obj.")
@click.option("--volume", "volume_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Fitted density (.npy; default beside -o).")
@click.option("--smooth", type=click.IntRange(min=0), default=10, show_default=True,
              help="Taubin smoothing passes on the surface.")
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=1, show_default=True,
              help="Worker processes voxelising the database meshes.")
def complete(partial, database, resolution, missing, euclidean, width, iterations, max_iter,
             coarse, png_path, top, as_json, quiet, loss, observed_only, align, output,
             volume_path, smooth, jobs) -> None:
    """Infer the missing geometry of the mesh PARTIAL from a database of meshes.

    PARTIAL is placed where it overlaps a database shape best (scale and
    shift; rotation too with --align), the weights are fitted there, and the
    completed surface (-o) is PARTIAL itself united with what the fitted
    shape adds, in PARTIAL's own coordinates. Also writes the fitted density
    (.npy) and a PNG: input and completion (added part in blue) and the
    heaviest database shapes.
    """
    from tqdm import tqdm

    from wbcgrade.shape.workflow import complete_mesh_file

    def warn(message: str) -> None:
        tqdm.write(f"Warning: {message}", file=sys.stderr)

    bars = []

    def on_mesh(done: int, total: int, path: Path) -> None:
        if not bars:
            bars.append(tqdm(total=total, desc="voxelising", unit="mesh", disable=quiet,
                             file=sys.stderr, leave=False))
        bars[0].update(done - bars[0].n)
        if done == total:
            bars[0].close()

    callback = _FitProgress(not quiet, max_iter, "fitting")
    try:
        result = complete_mesh_file(
            partial, database, output=output, volume_path=volume_path, png_path=png_path,
            resolution=resolution, missing=missing, loss=loss, euclidean=euclidean,
            width=width, n_iter=iterations, max_iter=max_iter, coarse_to_fine=coarse,
            align=align, observed_only=observed_only, smooth=smooth, top=top, warn=warn,
            on_mesh=on_mesh,
            callback=callback, jobs=jobs)
    finally:
        for bar in bars:
            bar.close()
        callback.close()
    _print_result(result, as_json)


@shape.command()
@click.argument("volume", type=click.Path(dir_okay=False, path_type=Path))
@_with_common
@click.option("--loss", type=_LOSS_CHOICE, default=DEFAULT_LOSS, show_default=True,
              help="Loss between the barycenter and the input (the paper's MRIs: quadratic).")
@click.option("--output", "-o", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Fitted volume (.npy, .nii, .nii.gz); default VOLUME_projected.npy.")
def project(volume, database, resolution, missing, euclidean, width, iterations, max_iter,
            coarse, png_path, top, as_json, quiet, loss, output) -> None:
    """Project the volume VOLUME (.npy or NIfTI) onto a database of volumes.

    The fitted volume is written scaled to the input's total intensity, at the
    (possibly reduced) working resolution.
    """
    from wbcgrade.shape.workflow import project_volume_file

    callback = _FitProgress(not quiet, max_iter, "fitting")
    try:
        result = project_volume_file(
            volume, database, output=output, png_path=png_path, resolution=resolution,
            missing=missing, loss=loss, euclidean=euclidean, width=width, n_iter=iterations,
            max_iter=max_iter, coarse_to_fine=coarse, top=top, callback=callback)
    finally:
        callback.close()
    _print_result(result, as_json)
