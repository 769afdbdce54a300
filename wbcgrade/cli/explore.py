"""``wbcgrade explore``: steer a photo's grade by hand in a live local page."""

from __future__ import annotations

import click

from wbcgrade.cli.grading_options import table_options
from wbcgrade.cli.option_table import flag_of, flag_text


def _warn(message: str) -> None:
    click.echo(f"Warning: {flag_text(message)}", err=True)


@click.command("explore")
@click.argument("photo", type=click.Path(path_type=str))  # the library checks it (exit 1)
@table_options("style_dir", "presets", "save_dir", "port", "no_browser", "max_image_pixels")
def explore(photo, style_dir, presets, port, save_dir, no_browser):
    """Steer the grade of PHOTO by hand in a live page, then export it.

    Loads PHOTO and the styles, grades it as `apply` does, and serves a page
    on 127.0.0.1 (its address, with a random token, is printed). It opens on
    the grade `apply` gives (the preset's look, the style photo of the same
    scene, or the look the styles share) and says which; the page changes
    its strength, picks another preset, or switches to the palette mode
    (the styles at the corners of a polygon: drag the point to mix them).
    It saves the graded photo at full size into --save-dir, exports the LUT
    (.cube 33/65, CLF) and gives the `wbcgrade apply` command that grades
    the full-size photo as shown, with undo/redo. Ctrl-C stops it. The
    photo and the styles are only read.
    """
    from tqdm import tqdm

    from wbcgrade.cli._progress import style_progress
    from wbcgrade.explore.app import open_browser, serve, start_studio

    with style_progress() as progress, \
            tqdm(desc="load", disable=None, leave=False) as bar:
        server = start_studio(photo, style_dir, list(presets) or None, port, warn=_warn,
                              progress=progress, stage=bar.set_description,
                              save_dir=save_dir, setting_names=flag_of)
    studio = server.studio
    _, look = studio.look(0, 1.0)
    click.echo(f"grade: {look['grade']['words']} (as `wbcgrade apply` gives it)", err=True)
    click.echo(f"saves into: {studio.save_dir}", err=True)
    click.echo(server.url)
    if no_browser or not open_browser(server.url):
        click.echo("Open the address above in a browser; Ctrl-C stops the server.", err=True)
    else:
        click.echo("Opened in your browser; Ctrl-C stops the server.", err=True)
    serve(server)
    click.echo("Stopped.", err=True)
    _release(server)


def _release(server) -> None:
    """Free the studio (the photo, the styles, OpenImageIO's colour objects) while the
    bindings still exist: at exit they were reported as ~20 ``nanobind: leaked ...``
    lines after "Stopped." (issue 31)."""
    import gc

    from wbcgrade._executor import release_cached_objects

    server.studio = None
    gc.collect()
    release_cached_objects()
