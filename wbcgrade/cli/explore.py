"""``wbcgrade explore``: steer a photo's grade by hand in a live local page."""

from __future__ import annotations

import click


def _warn(message: str) -> None:
    click.echo(f"Warning: {message}", err=True)


@click.command("explore")
@click.argument("photo", type=click.Path(dir_okay=False, path_type=str))
@click.option("--style", "style_dir", type=click.Path(path_type=str), default=None,
              help="Folder of style photos (non-images are skipped).")
@click.option("--preset", "presets", multiple=True, metavar="NAME_OR_FILE",
              help="Shipped preset name (see `wbcgrade preset list`) or a preset .npz file; "
                   "repeat it to offer more in the page's preset picker (the page opens on "
                   "the first; every shipped preset is offered too).")
@click.option("--save-dir", type=click.Path(file_okay=False, path_type=str), default=None,
              help="Folder the page's \"Save the graded photo\" writes into (new files "
                   "<stem>_explore_<n>.<ext>, never replacing one) [default: the photo's "
                   "folder].")
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="Port on 127.0.0.1 (0: any free port).")
@click.option("--no-browser", is_flag=True,
              help="Do not open a browser; print the address only.")
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
                              save_dir=save_dir)
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
