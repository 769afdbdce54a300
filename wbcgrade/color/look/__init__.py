"""The default grade's looks, in one package.

A look is the global colour map a set of graded photos share, apart from
their content; the default grade (``map.builder`` "look") applies the style set's
look, moved towards the photo's own scene where a style photo shows it.

Submodules:

- :mod:`~wbcgrade.color.look.family`: the map family (:class:`LookMap`: each
  channel plus smooth curves of R, G, B and luma), its fit
  (:func:`fit_look_map`), pushing a histogram through it, relaxed
  correspondences;
- :mod:`~wbcgrade.color.look.statistics`: palette statistics (quantiles,
  bands by lightness) and the look read from them;
- :mod:`~wbcgrade.color.look.set_extraction`: the look a style set shares
  (by statistics or by transport against the natural palettes, cached on
  disk), its reliability from two halves of the set, the strength it is
  applied at (:func:`set_look_base`), as a LUT (:func:`set_look_map`), and
  the natural palettes with their statistics;
- :mod:`~wbcgrade.color.look.scene`: matching a photo to style photos of the
  same scene (features, homography, colour pairs, a disk cache);
- :mod:`~wbcgrade.color.look.scene_fit`: the look of one photo against its
  scene: the palette test (:func:`photo_look`) and the fit of matched pixels
  (:func:`fit_scene_look`, :func:`find_scene_look`, :func:`fit_pairs_look`);
- :mod:`~wbcgrade.color.look.learn`: the look of before/after pairs (and of edits
  without their originals).

The "look" map builder the grade path calls (``look_map``) is
:mod:`wbcgrade.color.grade.look_builder`, and the looks written as grades (``wbcgrade look
extract``, ``wbcgrade look learn``, a grade given the originals) are
:mod:`wbcgrade.color.grade.look_files`: the grade package imports this one, never the
other way round.

A saved grade is
:mod:`wbcgrade.color.grade.saved_grade`. This package imports only what it needs
to fit looks; the builder and the two workflows are imported from their
submodules.
"""

from wbcgrade.color.look.family import (
    LookMap,
    fit_look_map,
    look_coordinates,
    push_histogram,
    relaxed_correspondences,
)
from wbcgrade.color.look.scene_fit import (
    PairFit,
    PhotoLook,
    SceneLook,
    find_scene_look,
    fit_correction,
    fit_pair,
    fit_pairs_look,
    fit_scene_look,
    photo_look,
)
from wbcgrade.color.look.set_extraction import (
    LookResult,
    colour_photos,
    extract_look,
    load_naturals,
    look_reliability,
    natural_palettes,
    set_look,
    set_look_base,
    set_look_halves,
    set_look_map,
)

__all__ = ["LookMap", "fit_look_map", "push_histogram", "relaxed_correspondences",
           "LookResult", "extract_look", "look_coordinates", "PairFit", "fit_pair",
           "PhotoLook", "photo_look", "SceneLook", "fit_scene_look", "find_scene_look",
           "fit_correction", "fit_pairs_look",
           "set_look_base", "set_look_halves", "look_reliability",
           "set_look", "set_look_map", "natural_palettes", "load_naturals", "colour_photos"]
