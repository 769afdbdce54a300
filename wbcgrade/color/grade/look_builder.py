"""The "look" map builder (``map.builder`` "look", the default grade): the set's look,
moved towards the photo's own scene by how sure it is that a style shows it.

:func:`look_map` is the builder the grade path calls
(:data:`wbcgrade.color.grade.grading.MAP_BUILDERS`); :func:`look_color_map` is the
set's look with the palette test of the photo's scene (:func:`photo_look`).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from wbcgrade.color.grade.builders import BuiltMap, LookFound, MapRequest, palette_map
from wbcgrade.color.histogram import resample_histogram
from wbcgrade.color.look.family import LookMap
from wbcgrade.color.look.scene import has_style_images
from wbcgrade.color.look.scene_fit import PhotoLook, find_scene_look, photo_look
from wbcgrade.color.look.set_extraction import MAP_BINS, load_naturals, set_look_base
from wbcgrade.color.mapping.remap import monochrome_map, resample_lattice
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.outcome import GradeSource
from wbcgrade.color.palette.fit import FitSummary

__all__ = ["look_map", "look_color_map", "look_found"]

#: The per-photo correction towards the photo's own scene (when a style shows
#: it): the palette grade with this loss and relaxation, which recover the scene's look
#: where the quadratic, balanced fit does not (docs/benchmarks.md).
SCENE_LOSS = "kl"
SCENE_RELAXATION = 0.01


def look_color_map(photo_hist: np.ndarray, styles, naturals=None,
                   set_strength: float | None = None
                   ) -> tuple[LookMap, PhotoLook, dict, LookFound, bool]:
    """The set's look and how sure it is that a style shows the photo's own scene.

    Parameters
    ----------
    photo_hist : (n, n, n) the photo's histogram (any grid; re-binned to 32^3).
    styles : StyleSet.
    naturals : StyleSet of ungraded palettes (default the shipped ones).

    Returns
    -------
    base : the set's look at ``set_strength`` (what a photo of another scene gets;
        None: its reliability on the photo's colours, :func:`set_look_base`).
    photo : the :class:`PhotoLook` (match, confidence, residuals).
    info : JSON-friendly diagnostics.
    found : what the grade's outcome needs of it (:class:`LookFound`).
    monochrome : every style photo is black and white (or toned).
    """
    base, extracted, set_strength = set_look_base(styles, naturals, set_strength, photo_hist)
    photo = photo_look(resample_histogram(photo_hist, MAP_BINS), styles.at_bins(MAP_BINS), base)
    info = {"look": {"set_amplitude": extracted.look.amplitude(),
                     "set_strength": set_strength,
                     "match": styles.names[photo.match],
                     "confidence": photo.confidence,
                     "overlap": photo.overlap,
                     "residuals": [float(r) for r in photo.residuals],
                     **extracted.info}}
    found = look_found(extracted, set_strength, styles.names[photo.match], photo.confidence)
    return base, photo, info, found, bool(extracted.info.get("monochrome"))


def look_found(extracted, set_strength: float, match: str | None,
               confidence: float) -> LookFound:
    """The typed findings of a set's look (``extracted``: its
    :class:`~wbcgrade.color.look.set_extraction.LookResult`) for the grade's outcome."""
    info = extracted.info
    probability = info.get("probability") if info.get("rule") == "posterior" else None
    return LookFound(float(set_strength), match, float(confidence or 0.0),
                     shrunk=info.get("method") == "statistics",
                     probability=None if probability is None else float(probability),
                     own_photos=int(info.get("own_photos") or 0),
                     own_photos_unused=int(info.get("own_photos_unused") or 0))


#: Nodes per axis (at least) of a preset's look converted into another working space
#: (:func:`wbcgrade.color.presets.look_in_space`): sRGB fills about half of ACEScct's
#: cube, so the lattice needs more nodes there (docs/benchmarks.md).
CONVERTED_LOOK_SIZE = 65


def look_map(request: MapRequest) -> BuiltMap:
    """The "look" builder: the set's look, corrected towards the photo's scene.

    The colour map is the look the style set shares
    (:func:`look_color_map`, content modelled by the
    natural palettes of ``map.natural``), moved towards the photo's palette
    grade (the "palette" builder with a KL fit and relaxed transport) by how
    sure it is that a style shows the photo's own scene. Fixed weights
    (``fit.weights``) give the palette grade.
    """
    options, styles, say = request.options, request.styles, request.stage
    if options.fit.weights is not None:
        return palette_map(request)
    if styles.look is not None:  # a preset made with a known look: that look
        n_styles = len(styles.names)
        fit = FitSummary(np.full(n_styles, 1.0 / n_styles), 0.0, np.zeros(n_styles), None,
                         {"look": "the preset's own"}, 0.0)
        size = options.map.size
        if styles.converted_from:  # converted from the preset's own space: finer,
            size = max(size, CONVERTED_LOOK_SIZE)  # as its gamut fills part of this cube
        return BuiltMap(resample_lattice(styles.look, size), None,
                        {"look": {"source": "preset"}}, {}, fit, GradeSource.PRESET_LOOK)
    timings: dict[str, float] = {}
    start = time.perf_counter()
    say("histograms")
    photo_hist = request.photo.at(MAP_BINS)
    timings["histograms"] = time.perf_counter() - start
    say("look")
    start = time.perf_counter()
    naturals = load_naturals(options.map.natural, styles.working_space)
    n_styles = len(styles.names)
    if request.photo.pixels is not None:
        base, extracted, strength = set_look_base(styles, naturals, None, photo_hist)
        timings["look"] = time.perf_counter() - start
        say("scene")
        start = time.perf_counter()
        no_scene: dict[str, str] = {}
        scene = find_scene_look(request.photo.pixels[0], styles, base, why=no_scene)
        timings["scene"] = time.perf_counter() - start
        if scene is not None and scene.confidence > 0:
            size = options.map.size
            base_map = base.lattice(size)
            color_map = base_map + scene.confidence * (scene.lattice(size) - base_map)
            total = sum(scene.matches.values())
            weights = np.full(n_styles, (1.0 - scene.confidence) / n_styles)
            for index, inliers in scene.matches.items():
                weights[index] += scene.confidence * inliers / total
            best = max(scene.matches, key=scene.matches.get)
            info = {"look": {"set_amplitude": extracted.look.amplitude(),
                             "set_strength": strength,
                             "match": styles.names[best], "confidence": scene.confidence,
                             "scene": {styles.names[i]: n for i, n in scene.matches.items()},
                             "scene_residual": scene.residual, "pairs": scene.pairs,
                             **extracted.info}}
            # per style: the pair residual where it shows the scene, the cube's diagonal elsewhere
            alone = np.full(n_styles, float(np.sqrt(3.0)))
            alone[list(scene.matches)] = scene.residual
            fit = FitSummary(weights, scene.residual, alone, None,
                             {"match": styles.names[best], "confidence": scene.confidence},
                             sum(timings.values()))
            return BuiltMap(_as_set_look(color_map, extracted), None, info, timings, fit,
                            GradeSource.OWN_SCENE,
                            look_found(extracted, strength, styles.names[best], scene.confidence))
        if has_style_images(styles):
            # the style photos were looked at and none shows this scene: the set's look
            # (a palette that merely resembles the photo's is no better sign of its scene)
            info = {"look": {"set_amplitude": extracted.look.amplitude(),
                             "set_strength": strength, "match": None,
                             "confidence": 0.0, **extracted.info,
                             "no_scene": no_scene}}
            fit = FitSummary(np.full(n_styles, 1.0 / n_styles), 0.0, np.zeros(n_styles),
                             None, {"match": None, "confidence": 0.0}, sum(timings.values()))
            return BuiltMap(_as_set_look(base.lattice(options.map.size), extracted), None, info,
                            timings, fit, GradeSource.SET_LOOK,
                            look_found(extracted, strength, None, 0.0))
        start = time.perf_counter()
    base, photo, info, found, monochrome = look_color_map(photo_hist, styles, naturals)
    timings["look"] = timings.get("look", 0.0) + time.perf_counter() - start
    confidence = photo.confidence
    weights = np.full(n_styles, 1.0 / n_styles)
    color_map = base.lattice(options.map.size)
    fit_info: dict = {"match": found.match, "confidence": confidence}
    transport = None  # the scene's palette grade's Sinkhorn solve, when there is one
    if confidence > 0:
        scene_options = GradeOptions(
            replace(options.fit, loss=SCENE_LOSS),
            replace(options.transfer,
                    relaxation=options.transfer.relaxation or SCENE_RELAXATION),
            replace(options.map, builder="palette"), options.regrain, options.spaces)
        if request.palette_grade is None:
            raise ValueError("the look builder needs MapRequest.palette_grade (the grade "
                             "path gives it)")
        scene, summary = request.palette_grade(scene_options,
                                               lambda name: say(f"palette {name}"))
        for name, seconds in scene.timings.items():
            timings[f"palette {name}"] = seconds
        base_map = base.lattice(scene.color_map.shape[0])
        color_map = (base_map + confidence * (scene.color_map - base_map)).astype(np.float32)
        weights = confidence * np.asarray(summary.weights) + (1.0 - confidence) * weights
        fit_info["scene_fit"] = {**summary.info, "weights": [float(w) for w in summary.weights],
                                 "loss": summary.loss}
        info.update({k: v for k, v in scene.info.items() if k != "fit"})
        transport = scene.transport
    fit = FitSummary(weights, float(photo.residuals[photo.match]), photo.residuals, None,
                     fit_info, sum(timings.values()))
    if monochrome:
        color_map = monochrome_map(color_map)
    return BuiltMap(color_map, None, info, timings, fit, GradeSource.SET_LOOK, found,
                    transport)


def _as_set_look(color_map: np.ndarray, extracted) -> np.ndarray:
    """The map as the set's look has it: exactly black and white (or toned) when every
    style photo is (a scene read off such a style is too), float32."""
    if extracted.info.get("monochrome"):
        return monochrome_map(color_map)
    return np.asarray(color_map, dtype=np.float32)
