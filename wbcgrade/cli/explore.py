"""``wbcgrade explore``: steer a photo's grade by hand in a live local page."""

from __future__ import annotations

import click


def _warn(message: str) -> None:
    click.echo(f"Warning: {message}", err=True)


@click.command("explore")
@click.argument("photo", type=click.Path(dir_okay=False, path_type=str))
@click.option("--style", "style_dir", type=click.Path(path_type=str), default=None,
              help="Folder of style photos (non-images are skipped).")
@click.option("--preset", default=None, metavar="NAME_OR_FILE",
              help="Shipped preset name (see `wbcgrade preset list`) or a preset .npz file.")
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="Port on 127.0.0.1 (0: any free port).")
@click.option("--no-browser", is_flag=True,
              help="Do not open a browser; print the address only.")
def explore(photo, style_dir, preset, port, no_browser):
    """Steer the grade of PHOTO by hand in a live page, then export it.

    Loads PHOTO and the styles, fits the weights as `apply` does, and serves
    a page on 127.0.0.1 (its address, with a random token, is printed): the
    photo before and after, the styles at the corners of a polygon (drag the
    point to mix them), strength, relaxation and keep-lightness controls,
    LUT export (.cube 33/65, CLF) and the `wbcgrade apply` command that
    grades the full-size photo as shown. Ctrl-C stops it. The photo and the
    styles are only read.
    """
    from tqdm import tqdm

    from wbcgrade.cli._progress import style_progress
    from wbcgrade.explore.app import open_browser, serve, start_studio

    with style_progress() as progress, \
            tqdm(desc="load", unit="eval", disable=None, leave=False) as bar:
        def on_fit(n_eval, weights, value):
            bar.update(1)
            bar.set_postfix(loss=f"{value:.4g}")

        server = start_studio(photo, style_dir, preset, port, warn=_warn, progress=progress,
                              fit_callback=on_fit, stage=bar.set_description)
    fit = server.studio.fit
    ranked = sorted(zip(server.studio.session.names, fit.weights), key=lambda item: -item[1])
    click.echo("fitted: " + ", ".join(f"{name} {weight:.3f}" for name, weight in ranked),
               err=True)
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
