"""``wbcgrade preset``: build and list style presets."""

from __future__ import annotations

import json
import os

import click

from wbcgrade.cli.grading_options import LazyOptionsCommand, check_photo, table_options, table_rows
from wbcgrade.cli.option_table import flag_text


@click.group("preset")
def preset() -> None:
    """Build and list style presets (databases of style palettes)."""


@preset.command("build", cls=LazyOptionsCommand)
@click.argument("folder", type=click.Path(path_type=str))
@table_options("output", required=True, help="Preset file to write (.npz).")
@table_options("preset_bins")
@table_rows("preset_width")
@table_options("description")
@table_options("overwrite", help="Replace an existing preset file.")
@table_options("no_cache", help="Do not use the style histogram cache.")
@table_options("working_space", help="Colour space of the histograms (OpenColorIO name or "
                                     "alias, e.g. acescct), recorded in the preset [default: "
                                     "sRGB-encoded Rec.709].")
@table_options("compact")
@table_options("max_image_pixels")
def build(folder, output, preset_bins, preset_width, description, overwrite, no_cache,
          working_space, compact):
    """Build a preset from the photos in FOLDER (non-images are skipped).

    Each photo is converted from its own colour space (ICC profile, EXR
    metadata) into the working space before its histogram.
    """
    from wbcgrade.errors import InputError, OptionError

    bins = preset_bins
    if not 4 <= bins <= 256:
        raise OptionError("{bins} must be between 4 and 256", "bins")
    if not output.lower().endswith(".npz"):
        raise OptionError(f"{output}: {{output}} file name must end in .npz", "output", path=output)
    if os.path.exists(output) and not overwrite:
        raise InputError(f"{output}: file exists (use --overwrite to replace it)")
    check_photo(folder, "style folder does not exist")  # answered before numpy loads
    from wbcgrade.cli._progress import style_progress
    from wbcgrade.color.histogram import HistogramCache
    from wbcgrade.color.presets import check_preset_width, load_style_folder, save_preset

    width = check_preset_width(preset_width)
    if working_space:
        from wbcgrade.color.colorspace import resolve_space

        working_space = resolve_space(working_space, "spaces.working")
    with style_progress() as progress:
        styles = load_style_folder(
            folder, bins, cache=HistogramCache(enabled=not no_cache),
            warn=lambda m: click.echo(f"Warning: {flag_text(m)}", err=True), progress=progress,
            working_space=working_space)
    path = save_preset(output, styles, width=width, description=description, overwrite=overwrite,
                       compact=compact)
    click.echo(f"wrote {path}: {len(styles.names)} styles ({', '.join(styles.names)}), "
               f"{bins}^3 bins in {styles.working_space}, {path.stat().st_size / 1024:.0f} KiB")


@preset.command("list")
@table_options("as_json", help="Print as JSON.")
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
