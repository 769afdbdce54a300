"""``wbcgrade shape``: complete meshes and project volumes onto a database (paper §5.3-5.4).

Parsing, progress and printing only; the work is ``wbcgrade.shape.workflow``
(imported inside the commands, so that ``wbcgrade --help`` stays fast).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from wbcgrade.cli.grading_options import table_options


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


_FILE_PATH = click.Path(dir_okay=False, path_type=Path)


def _with_common(function):
    """The options of ``shape complete`` and ``shape project`` both (the option table's)."""
    function = table_options("top", "as_json", "quiet")(function)
    function = table_options("png", type=_FILE_PATH,
                             help="Picture of the views (default: beside -o, .png).")(function)
    return table_options("shape_database", "resolution", "missing", "euclidean", "shape_width",
                         "shape_iterations", "shape_max_iter", "coarse")(function)


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
@table_options("shape_loss", "observed_only", "align")
@table_options("output", type=_FILE_PATH, decls=("--output", "-o"),
               help="Completed mesh (.obj, .ply, .stl, .off); default PARTIAL_completed.obj.")
@table_options("volume_path", "smooth", "shape_jobs")
def complete(partial, shape_database, resolution, missing, euclidean, shape_width,
             shape_iterations, shape_max_iter, coarse, png, top, as_json, quiet, shape_loss,
             observed_only, align, output, volume_path, smooth, shape_jobs) -> None:
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

    callback = _FitProgress(not quiet, shape_max_iter, "fitting")
    try:
        result = complete_mesh_file(
            partial, shape_database, output=output, volume_path=volume_path, png_path=png,
            resolution=resolution, missing=missing, loss=shape_loss, euclidean=euclidean,
            width=shape_width, n_iter=shape_iterations, max_iter=shape_max_iter,
            coarse_to_fine=coarse, align=align, observed_only=observed_only, smooth=smooth,
            top=top, warn=warn, on_mesh=on_mesh, callback=callback, jobs=shape_jobs)
    finally:
        for bar in bars:
            bar.close()
        callback.close()
    _print_result(result, as_json)


@shape.command()
@click.argument("volume", type=click.Path(dir_okay=False, path_type=Path))
@_with_common
@table_options("shape_loss", help="Loss between the barycenter and the input (the paper's "
                                  "MRIs: quadratic).")
@table_options("output", type=_FILE_PATH, decls=("--output", "-o"),
               help="Fitted volume (.npy, .nii, .nii.gz); default VOLUME_projected.npy.")
def project(volume, shape_database, resolution, missing, euclidean, shape_width,
            shape_iterations, shape_max_iter, coarse, png, top, as_json, quiet, shape_loss,
            output) -> None:
    """Project the volume VOLUME (.npy or NIfTI) onto a database of volumes.

    The fitted volume is written scaled to the input's total intensity, at the
    (possibly reduced) working resolution.
    """
    from wbcgrade.shape.workflow import project_volume_file

    callback = _FitProgress(not quiet, shape_max_iter, "fitting")
    try:
        result = project_volume_file(
            volume, shape_database, output=output, png_path=png, resolution=resolution,
            missing=missing, loss=shape_loss, euclidean=euclidean, width=shape_width,
            n_iter=shape_iterations, max_iter=shape_max_iter, coarse_to_fine=coarse, top=top,
            callback=callback)
    finally:
        callback.close()
    _print_result(result, as_json)
