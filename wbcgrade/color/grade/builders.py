"""What a map builder gets and returns, and the "palette" builder.

A builder (:data:`wbcgrade.color.grade.grading.MAP_BUILDERS`) takes a :class:`MapRequest`
and returns a :class:`BuiltMap` (with where its map came from, a
:class:`~wbcgrade.color.outcome.GradeSource`, and a look's typed findings,
:class:`LookFound`); :func:`palette_map` is the "palette" one, the
"look" one is :func:`wbcgrade.color.grade.look_builder.look_map`. Apart from the grade
path (:mod:`wbcgrade.color.grade.grading`) so that a builder can live in its own package
without importing the path that calls it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.histogram import (
    deferred_field,
    deferred_shape,
    image_histogram,
    resample_histogram,
)
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.outcome import GradeSource, TransportCheck
from wbcgrade.color.palette.fit import FitSummary, fit_weights
from wbcgrade.color.palette.transfer import transport_map
from wbcgrade.color.presets import StyleSet

__all__ = ["FitCallback", "quiet", "PhotoHistograms", "MapRequest", "LookFound", "BuiltMap",
           "palette_map"]

FitCallback = Callable[[int, np.ndarray, float], None]


def quiet(name: str) -> None:
    """A stage callback that says nothing."""


@dataclass(frozen=True)
class PhotoHistograms:
    """A photo's (or a series') histograms: ``fit`` on the fit grid, ``transfer`` on the
    transfer grid, both of working-space colours; :meth:`at` gives other grids."""

    fit: np.ndarray
    #: a :class:`~wbcgrade.color.histogram.Deferred` is binned when first read (a look grade
    #: may never need the transfer grid)
    transfer: np.ndarray = deferred_field()
    pixels: tuple | None = field(default=None, repr=False, compare=False)

    def at(self, bins: int) -> np.ndarray:
        """The histogram on a ``bins``^3 grid: binned from the pixels when there are
        some (a photo), else re-binned from the transfer grid's (a pooled series)."""
        if deferred_shape(self, "transfer")[0] == bins:
            return self.transfer
        if self.fit.shape[0] == bins:
            return self.fit
        if self.pixels is not None:
            encoded, alpha, limit = self.pixels
            return image_histogram(encoded, bins, alpha, limit)
        return resample_histogram(self.transfer, bins)


@dataclass(frozen=True)
class MapRequest:
    """What a map builder gets.

    Attributes
    ----------
    photo : the photo's (or series') histograms.
    styles : the style set, in the working space.
    options : every setting of the grade.
    encoding : the colour encoding (working space) of the grade.
    callback : ``callback(n_evaluations, weights, loss)`` of a weight fit, or None.
    stage : ``stage(name)`` as each stage starts (progress).
    palette_grade : ``palette_grade(options, stage) -> (Grade, FitSummary)``, the whole
        grade path (:func:`wbcgrade.color.grade.grading.grade_histograms`) on the same photo,
        styles and encoding with other options (the "look" builder's palette grade of
        the photo's scene), or None.
    """

    photo: PhotoHistograms
    styles: StyleSet
    options: GradeOptions
    encoding: ColorEncoding
    callback: FitCallback | None = None
    stage: Callable[[str], None] = quiet
    palette_grade: Callable[..., tuple] | None = None


@dataclass(frozen=True)
class LookFound:
    """What a look builder found, for the grade's outcome (its JSON is ``info["look"]``).

    Attributes
    ----------
    set_strength : the share of the set's look applied (0: none).
    match : the style the look leans on (the scene's style photo, or the one the set's
        look was moved towards), or None.
    confidence : how sure the builder is of ``match`` (0-1).
    shrunk : a statistics look, shrunk by what content varies by (its size says how much
        of it the set shares).
    probability : how sure it is that the set shares a look (judged jointly), or None.
    own_photos : the user's own photos the look was measured against.
    own_photos_unused : own photos given for that but too few to use.
    """

    set_strength: float = 1.0
    match: str | None = None
    confidence: float = 0.0
    shrunk: bool = False
    probability: float | None = None
    own_photos: int = 0
    own_photos_unused: int = 0


class BuiltMap(NamedTuple):
    """What a map builder returns: the map before finishing, the palette it aimed at
    (or None), diagnostics (JSON-friendly), seconds per stage, the weights with how sure
    the builder is of them (a :class:`~wbcgrade.color.palette.fit.FitSummary`), where the
    map came from, for a look what it found, and how the transport's Sinkhorn solve ended
    (None: no transport)."""

    color_map: np.ndarray
    palette: np.ndarray | None
    info: dict
    timings: dict
    fit: FitSummary
    source: GradeSource
    look: LookFound | None = None
    transport: TransportCheck | None = None


def palette_map(request: MapRequest) -> BuiltMap:
    """The "palette" builder: the weights (never worse than one style alone), then the
    map onto their barycenter palette (:func:`wbcgrade.color.palette.transfer.transport_map`)."""
    options, styles = request.options, request.styles
    request.stage("fit")
    fit = fit_weights(request.photo.fit, styles.at_bins(options.fit.bins), options.fit,
                      request.callback)
    found = transport_map(request.photo.transfer, styles, fit.weights, options, request.stage)
    return BuiltMap(found.color_map, found.palette, found.info,
                    {"fit": fit.time_s, **found.timings}, fit, GradeSource.PALETTE,
                    transport=found.check)
