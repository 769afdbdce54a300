"""``wbcgrade preset``: build and list style presets."""

from __future__ import annotations

import json
import os

import click

from wbcgrade.cli.grading_options import LazyOptionsCommand, lazy_options
from wbcgrade.errors import InputError


def _width_option() -> list:
    """``--width`` (default: the preset library's), for :func:`lazy_options`."""
    from wbcgrade.color.presets import DEFAULT_PRESET_WIDTH

    return [click.option("--width", type=float, default=DEFAULT_PRESET_WIDTH, show_default=True,
                         help="Kernel width (bins) recorded with the preset.")]


@click.group("preset")
def preset() -> None:
    """Build and list style presets (databases of style palettes)."""


@preset.command("build", cls=LazyOptionsCommand)
@click.argument("folder", type=click.Path(path_type=str))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=str),
              help="Preset file to write (.npz).")
@click.option("--bins", type=int, default=32, show_default=True,
              help="Bins per axis of the stored histograms (apply re-bins them as needed).")
@lazy_options(_width_option)
@click.option("--description", default="", help="One line shown by `preset list`.")
@click.option("--overwrite", is_flag=True, help="Replace an existing preset file.")
@click.option("--no-cache", is_flag=True, help="Do not use the style histogram cache.")
@click.option("--working-space", default=None, metavar="NAME",
              help="Colour space of the histograms (OpenColorIO name or alias, e.g. acescct), "
                   "recorded in the preset [default: sRGB-encoded Rec.709].")
@click.option("--compact", is_flag=True,
              help="Store 16-bit bins (about half the file; for hundreds of photos).")
def build(folder, output, bins, width, description, overwrite, no_cache, working_space, compact):
    """Build a preset from the photos in FOLDER (non-images are skipped).

    Each photo is converted from its own colour space (ICC profile, EXR
    metadata) into the working space before its histogram.
    """
    from wbcgrade.cli._progress import style_progress
    from wbcgrade.color.histogram import HistogramCache
    from wbcgrade.color.presets import check_preset_width, load_style_folder, save_preset

    if not 4 <= bins <= 256:
        raise InputError("--bins must be between 4 and 256")
    width = check_preset_width(width)
    if not output.lower().endswith(".npz"):
        raise InputError(f"{output}: preset file name must end in .npz")
    if os.path.exists(output) and not overwrite:
        raise InputError(f"{output}: file exists (use --overwrite to replace it)")
    if working_space:
        from wbcgrade.color.colorspace import resolve_space

        working_space = resolve_space(working_space, "spaces.working")
    with style_progress() as progress:
        styles = load_style_folder(
            folder, bins, cache=HistogramCache(enabled=not no_cache),
            warn=lambda m: click.echo(f"Warning: {m}", err=True), progress=progress,
            working_space=working_space)
    path = save_preset(output, styles, width=width, description=description, overwrite=overwrite,
                       compact=compact)
    click.echo(f"wrote {path}: {len(styles.names)} styles ({', '.join(styles.names)}), "
               f"{bins}^3 bins in {styles.working_space}, {path.stat().st_size / 1024:.0f} KiB")


@preset.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
def list_(as_json):
    """List the presets shipped with wbcgrade."""
    from wbcgrade.color.presets import list_presets, load_preset

    rows = []
    for name, path in list_presets():
        styles = load_preset(path)
        rows.append({"name": name, "styles": styles.names, "bins": styles.bins,
                     "description": styles.description, "path": str(path)})
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    if not rows:
        click.echo("no presets installed")
        return
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        click.echo(f"{r['name']:<{width}}  {r['bins']}^3  {', '.join(r['styles'])}"
                   + (f"  - {r['description']}" if r["description"] else ""))
