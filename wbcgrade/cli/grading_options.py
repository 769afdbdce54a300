"""Click options shared by the commands that grade photos (``batch``, ``report``).

Same names, defaults and help as ``wbcgrade apply``; ``apply`` could use
:func:`grading_options` too.
"""

from __future__ import annotations

import click

from wbcgrade.color.histogram import HistogramCache
from wbcgrade.color.imageio import DEFAULT_MAX_IMAGE_PIXELS, set_max_image_pixels
from wbcgrade.color.transfer import LOSSES, GradeOptions
from wbcgrade.color.weights import parse_weights

_DEFAULTS = GradeOptions()

_OPTIONS = [
    click.option("--style", "style_dir", type=click.Path(path_type=str), default=None,
                 help="Folder of style photos (non-images are skipped)."),
    click.option("--preset", default=None, metavar="NAME_OR_FILE",
                 help="Shipped preset name (see `wbcgrade preset list`) or a preset .npz file."),
    click.option("--bins", type=int, default=_DEFAULTS.bins, show_default=True,
                 help="Bins per axis of the colour map (transfer grid)."),
    click.option("--fit-bins", type=int, default=_DEFAULTS.fit_bins, show_default=True,
                 help="Bins per axis of the grid the weights are fitted on."),
    click.option("--loss", type=click.Choice(LOSSES), default=_DEFAULTS.loss, show_default=True,
                 help="Fit loss between the barycenter and the photo's histogram."),
    click.option("--width", type=float, default=_DEFAULTS.width, show_default=True,
                 help="Fit kernel width in bins of the fit grid."),
    click.option("--gamma", type=float, default=None,
                 help="Fit entropic regularisation gamma (overrides --width)."),
    click.option("--transfer-width", type=float, default=None,
                 help="Kernel width in bins of the transfer grid [default: max(1, (bins-1)/31)]."),
    click.option("--iterations", "n_iter", type=int, default=_DEFAULTS.n_iter,
                 show_default=True, help="Barycenter iterations."),
    click.option("--max-iter", type=int, default=_DEFAULTS.max_iter, show_default=True,
                 help="L-BFGS iterations of the fit at most."),
    click.option("--weights", "weights_text", default=None, metavar="A,B,C",
                 help="Use these style weights and skip the fit."),
    click.option("--strength", type=float, default=1.0, show_default=True,
                 help="Blend: x -> (1-t) x + t T(x)."),
    click.option("--no-cache", is_flag=True, help="Do not read or write cached style histograms."),
    click.option("--cache-dir", type=click.Path(file_okay=False, path_type=str), default=None,
                 help="Style histogram cache [default: $WBCGRADE_CACHE_DIR or "
                      "~/.cache/wbcgrade]."),
]


def _set_max_image_pixels(ctx: click.Context, param: click.Parameter, value: int | None):
    set_max_image_pixels(value)  # None: back to $WBCGRADE_MAX_IMAGE_PIXELS or the default
    return value


#: ``--max-image-pixels N``: raise (or lower) the decompression-bomb limit of this run.
max_image_pixels_option = click.option(
    "--max-image-pixels", type=click.IntRange(min=1), default=None, expose_value=False,
    callback=_set_max_image_pixels, metavar="N",
    help=f"Refuse images with more pixels than this, read from the header before "
         f"decoding [default: $WBCGRADE_MAX_IMAGE_PIXELS or {DEFAULT_MAX_IMAGE_PIXELS:_}].")
_OPTIONS.append(max_image_pixels_option)

GRADING_KEYS = ("style_dir", "preset", "bins", "fit_bins", "loss", "width", "gamma",
                "transfer_width", "n_iter", "max_iter", "weights_text", "strength", "no_cache",
                "cache_dir")


def grading_options(function):
    """Decorator adding the grading options of ``apply`` to a click command."""
    for option in reversed(_OPTIONS):
        function = option(function)
    return function


def take_grading_options(kwargs: dict) -> tuple[GradeOptions, dict]:
    """Pop the grading options from a command's kwargs -> (GradeOptions, style arguments).

    The style arguments are ``style_dir``, ``preset`` and ``cache`` (a HistogramCache).
    """
    values = {key: kwargs.pop(key) for key in GRADING_KEYS}
    text = values["weights_text"]
    opts = GradeOptions(bins=values["bins"], fit_bins=values["fit_bins"], loss=values["loss"],
                        width=values["width"], gamma=values["gamma"],
                        transfer_width=values["transfer_width"], n_iter=values["n_iter"],
                        max_iter=values["max_iter"], strength=values["strength"],
                        weights=parse_weights(text) if text else None)
    opts.validate()
    cache = HistogramCache(values["cache_dir"], enabled=not values["no_cache"])
    return opts, {"style_dir": values["style_dir"], "preset": values["preset"], "cache": cache}
