"""``wbcgrade look learn``: a photographer's before/after pairs become a reusable look.

Originals and the versions the photographer edited hold what no style folder
gives: every pixel of a pair is a colour before the look and the same
colour after it. The steps:

1. **Pairing** (:func:`pair_files`): two photos, or two folders whose photos
   pair by file stem (``IMG_1.CR2`` with ``IMG_1.jpg``; case does not count,
   and an export's ``-edit``/``_copy``/``-final`` ending is dropped). A stem
   on one side only is reported and left out.
2. **Reading** (:func:`read_pair`): both photos through the project's reader
   (raw originals demosaiced), each from its own colour space into the
   originals' working space (:func:`learn_space`: ACEScct when an original is
   raw, else sRGB-encoded Rec.709), shrunk to :data:`LEARN_SIZE` pixels a side.
3. **Registration** (:func:`register_pair`): an edit may be resized,
   cropped, rotated by 90 degrees, of another format or bit depth. First the
   cheap case: an after whose shape is the original's (after one of the
   four rotations) is resized onto it and checked patch by patch (phase
   correlation, which tone and colour changes do not disturb); otherwise
   keypoints and a homography as for a style photo of the photo's own scene
   (:func:`wbcgrade.color.look.scene.match_scene`). A pair of different scenes
   matches neither and is reported.
4. **Fit** (:func:`learn_look`): colour pairs of each overlap
   (:func:`wbcgrade.color.look.scene.colour_pairs`, edges down-weighted), every
   pair weighing the same, fitted as a scene look is
   (:func:`wbcgrade.color.look.scene_fit.fit_pairs_look`: tone curves and colour
   mixing, Cauchy-robust refits so that local edits such as a healed spot
   or a masked sky weigh little), then a lattice correction finer and less
   smoothed than a scene look's (:data:`CORRECTION_NODES`: a dozen photos
   hold more than one scene's pairs). When every after is black and white
   the look's output is made grey; when every after is toned (sepia,
   selenium: one tint per lightness) or black and white, the output is its
   luma plus the afters' mean tint at that luma
   (:func:`wbcgrade.color.mapping.remap.to_monochrome`), so that no colour of a
   photo survives the look.
5. **Report**: the mean CIEDE2000 between each after and the look applied
   to its original, fitted and held out (the pairs split into
   :data:`LEARN_FOLDS` folds, each fold's pairs predicted by a look fitted
   without them), and a warning for a pair that disagrees with the others.

:func:`wbcgrade.color.grade.look_files.learn_look_file` writes the look as a
``.cube``/``.clf`` LUT or a saved grade (``.json``) that
:func:`wbcgrade.color.grade.saved_grade.load_look` reads, as every command's saved look
does; :func:`wbcgrade.color.grade.look_files.learned_grade` gives it as a grade.
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypedDict

import numpy as np

from wbcgrade.color._colour import colour
from wbcgrade.color.colorspace import (
    SYCC_LUMA,
    ColorEncoding,
    convert,
    default_working_space,
    resolve_space,
)
from wbcgrade.color.histogram import grid_points, image_histogram, soft_histogram
from wbcgrade.color.io.cache import default_cache_dir
from wbcgrade.color.io.images import image_extensions, read_image
from wbcgrade.color.io.raw import RAW_SUFFIXES, RAW_WORKING_SPACE, is_raw
from wbcgrade.color.look.edits import FAMILIES, choose_family, extrapolating_family
from wbcgrade.color.look.family import fit_look_map
from wbcgrade.color.look.prior import content_noise, posterior_statistics_look
from wbcgrade.color.look.scene import (
    SceneImage,
    SceneMatch,
    colour_pairs,
    match_scene,
    scene_image,
    shrink_colors,
)
from wbcgrade.color.look.scene_fit import fit_correction, fit_pairs_look, interpolate_lattice
from wbcgrade.color.look.set_extraction import (
    MAP_BINS,
    natural_palettes,
    natural_statistics,
    space_scale,
)
from wbcgrade.color.look.statistics import (
    PaletteStatistics,
    look_differences,
    palette_statistics,
    tinted_statistics,
)
from wbcgrade.color.mapping.remap import TONE_LUMA, to_monochrome
from wbcgrade.color.presets import styles_in_space
from wbcgrade.core import fast_cpu
from wbcgrade.errors import InputError, worded_error, worded_text

__all__ = ["PairFiles", "FileMatch", "match_files", "CorrectedLook", "unpaired_correction",
           "SupportedLook", "supported_look", "TRUSTED_COVERAGE", "evidence_trust",
           "PairImages", "Registration", "LearnedLook", "PairReport",
           "LearnResult", "pair_files", "learn_space", "read_pair", "register_pair",
           "pair_colours", "learn_look", "LEARN_SIZE", "LEARN_FOLDS",
           "PAIRS_PER_PHOTO", "PAIRS_IN_ALL", "MONO_CHROMA", "TONED_SPREAD", "KEYPOINT_SIZE",
           "CORRECTION_NODES", "CORRECTION_SMOOTHNESS", "SKILLED_TRUST", "teaching_original",
           "OriginalToAdd", "ADVICE_GAIN"]

#: Long side (pixels) the photos are registered and sampled at (the scene match's size).
LEARN_SIZE = 768
#: Colour pairs drawn from each photo pair: at least ``PAIRS_PER_PHOTO``, and
#: ``PAIRS_IN_ALL`` shared among the pairs when they are few. Twelve pairs hold enough
#: colours at 4 000 or 20 000 a pair (``benchmarks/learn.py``, 16 film looks: +0.81 either
#: way, within 0.003); one pair does not: 5 000 of a 768-pixel photo's 300 000 miss the
#: colours just beside those drawn, and the look there is a guess (four looks learned from
#: each of four broad originals at 768 pixels, ``benchmarks/one_original.py``: mean
#: recovered +0.766 with 5 000, +0.806 with 80 000, +0.810 with 150 000, +0.804 with every
#: pixel; learning a 16-megapixel shoot took about 6, 8 and 9.5 s: docs/benchmarks.md).
PAIRS_PER_PHOTO = 5000
#: Colour pairs the pairs share when they are few (above).
PAIRS_IN_ALL = 80_000
#: The lattice correction of the learned look (what tone curves and colour mixing cannot
#: hold; :func:`wbcgrade.color.look.scene_fit.fit_correction`): nodes a side and smoothness. A scene
#: look's (9 nodes, 1e-3: pairs of one scene) smooths a film look's fine structure away:
#: a near-black photo's colours all lie in its first cell (0 to 0.125), one trilinear
#: blend, and the Hubble deep field under Ektar 100 recovered +0.34 (weighting the
#: pairs towards the dark end did not help: +0.33). Measured on ``benchmarks/learn.py``'s
#: eight tuned looks (the fit alone on the 12 pairs' colours; mean recovered, worst
#: photo): 9 nodes 1e-3 +0.825 / +0.545; 9 nodes 1e-4 +0.865 / +0.622; 17 nodes 1e-4,
#: 3e-5, 1e-5, 3e-6, 1e-6: +0.876, +0.895, +0.907, +0.913, +0.916 (worst +0.638 to
#: +0.689); 13 or 25 nodes at 1e-5 +0.904; a ridge of 1e-5 (pulling the correction to
#: none where pairs are few) +0.882. From 4 pairs, on four of them, 3e-6 too is best
#: (+0.84 against +0.71 with a scene look's).
CORRECTION_NODES = 17
CORRECTION_SMOOTHNESS = 3e-6
#: Each pair's colours are weighed against how common they are in it (weight / density **
#: FLATTEN_COLOURS, the density a 17^3 soft histogram blurred by ``_FLATTEN_BLUR`` nodes): a
#: portrait's few mid greys then count as its skin does, and the fit learns them rather
#: than taking them from the navy and skin beside them. ``benchmarks/one_original.py``
#: (eight looks, each of eight photos as the one original): held out +0.445 -> +0.510,
#: tuned +0.518 -> +0.575; ``learn.py --no-variant --size 512``, twelve pairs: +0.917 /
#: +0.903 -> +0.931 / +0.927 (docs/benchmarks.md). The pairs' support and coverage (how
#: far a look of few pairs is trusted) still count pixels: weighed alike too, the Hubble
#: field's and a sea's few colours earned trust (tuned +0.650, but 12 % of cases with a
#: photo worse than nothing, against none).
FLATTEN_COLOURS = 1.0
_FLATTEN_BLUR = 0.7
#: Folds of the held-out check (leave-one-out below this many pairs).
LEARN_FOLDS = 4
#: Below this many pairs the look is pulled, where the pairs' colours say little, towards
#: the photographer's edit that best explains them (:func:`~wbcgrade.color.look.edits.fit_edit`)
#: rather than towards no look: one photo's colours leave most of the cube to
#: extrapolation, and an edit extrapolates as edits do (the one-original figures in
#: docs/benchmarks.md).
EDIT_PRIOR_PAIRS = 4
#: An after whose 99th percentile of chroma (largest minus smallest channel, working
#: space) is below this is black and white (8-bit JPEG greys: 0 to 2/255).
MONO_CHROMA = 0.02
#: An after whose colours lie within this of a tint per lightness (:func:`_tint_spread`)
#: is toned (sepia, selenium), when its original's do not (twice this: an original with
#: so little colour, a night sky, says nothing of whether the look keeps colour).
#: Measured on ``benchmarks/learn.py``'s photos at 512 px: a sepia 0.007-0.009 (0.011-0.013
#: as a JPEG); the sixteen film looks' afters 0.056 to 0.41, but for the near-black
#: Hubble field (0.006-0.042; its original 0.026, the other originals 0.15-0.30).
TONED_SPREAD = 0.02
_TONE_BANDS = 32
_TONE_FLAT = 0.05
#: Long side (pixels) keypoints are found on when the cheap registration fails (crops);
#: the homography is then scaled to :data:`LEARN_SIZE`. Pairs of one scene under a look
#: agree on 60 or more keypoints at this size in ``benchmarks/learn.py``.
KEYPOINT_SIZE = 512
#: Export endings dropped from an after's stem before pairing (``IMG_1-Edit.tif``).
_EDIT_ENDING = re.compile(r"[-_ ](edit|edited|copy|final|export)(-?\d+)?$", re.IGNORECASE)
#: Cheap registration: aspect ratios that agree within this share are tried as one framing;
#: patches (of a 4x4 grid) whose phase correlation finds a shift within ``_PATCH_SHIFT``
#: pixels (at ``_CHECK_SIZE``), with a peak above ``_PATCH_RESPONSE``, agree; at least
#: ``_PATCH_AGREE`` of the textured ones must.
_ASPECT_TOLERANCE = 0.02
_CHECK_SIZE = 256
_PATCH_SHIFT = 1.0
_PATCH_AGREE = 0.8
#: Least phase-correlation peak of an agreeing patch. Measured on ``benchmarks/learn.py``'s
#: photos under a film look: patches of a pair laid right peak at 0.9-1.0; of a pair
#: turned the wrong way or cropped, at most 3 of 13-16 patches peak above 0.3 near no shift.
_PATCH_RESPONSE = 0.3
#: Held-out CIEDE2000 of a pair above both this multiple of the pairs' median and the
#: median plus ``_DISAGREE_MARGIN``: the pair disagrees with the others.
_DISAGREE_FACTOR = 2.0
_DISAGREE_MARGIN = 2.0
#: A pixel its own pair's global map misses by more than this (working-space units) was
#: edited locally (:func:`_edited_share`); a pair with more than ``_LOCAL_SHARE`` of them
#: is reported as locally edited (measured on 12 pairs of a film look with no edit, resized,
#: cropped and turned: at most 4.4 % of the flat pixels).
_LOCAL_DISTANCE = 0.06
_LOCAL_SHARE = 0.08
_FLAT = 0.7


# --------------------------------------------------------------------------- pairing


@dataclass(frozen=True)
class PairFiles:
    """A photo and its edited version: ``name`` (the stem), ``before``, ``after``."""
    name: str
    before: Path
    after: Path


def _image_files(folder: Path) -> list[Path]:

    exts = image_extensions() | RAW_SUFFIXES
    return sorted(p for p in folder.iterdir()
                  if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in exts)


def _pair_key(path: Path, edited: bool) -> str:
    stem = path.stem
    if edited:
        stem = _EDIT_ENDING.sub("", stem)
    return stem.casefold()


#: Which of several files sharing a stem is taken: raw first, then lossless, then the rest.
def _preference(path: Path) -> tuple[int, str]:

    suffix = path.suffix.lower()
    rank = 0 if is_raw(path) else 1 if suffix in (".tif", ".tiff", ".exr", ".png", ".dng") \
        else 3 if suffix in (".jpg", ".jpeg") else 2
    return rank, path.name


def pair_files(before: str | os.PathLike, after: str | os.PathLike
               ) -> tuple[list[PairFiles], list[tuple[str, str]]]:
    """The before/after pairs two photos or two folders give, and what could not be paired
    (:func:`match_files`, an edited photo without its original counted as a problem)."""
    matched = match_files(before, after)
    alone = [(path.stem, f"no original in {before} (nothing named {path.stem}.*)")
             for path in matched.edits_alone]
    return matched.pairs, sorted(matched.problems + alone)


@dataclass(frozen=True)
class FileMatch:
    """What two photos or two folders of originals and edits give.

    Attributes
    ----------
    pairs : the before/after pairs, in the order of their names.
    edits_alone : edited photos whose original is not there (evidence of the look too).
    problems : (name, reason) of originals without an edit and of stems several files share.
    """
    pairs: list[PairFiles]
    edits_alone: list[Path]
    problems: list[tuple[str, str]]


def match_files(before: str | os.PathLike, after: str | os.PathLike) -> FileMatch:
    """The before/after pairs two photos or two folders give, the edited photos without
    an original, and what could not be used.

    Parameters
    ----------
    before, after : two photo files (one pair, named by the original's stem),
        or two folders whose photos pair by stem (case-insensitive; an
        after's ``-edit``, ``_copy``, ``-final``... ending is dropped).

    Returns
    -------
    A :class:`FileMatch`: the pairs; the edits with no original; (name, reason) of
    each original with no edit, and of stems several files share (the raw, else the
    lossless file is used).

    Raises
    ------
    InputError
        A path is missing, or one is a file and the other a folder.
    """
    before, after = Path(before), Path(after)
    for path, side in ((before, "BEFORE"), (after, "AFTER")):
        if not path.exists():
            raise InputError(f"{path}: no such file or folder ({side})")
    if before.is_file() and after.is_file():
        return FileMatch([PairFiles(before.stem, before, after)], [], [])
    if not (before.is_dir() and after.is_dir()):
        raise InputError("BEFORE and AFTER must be two photos or two folders "
                         f"({before} is a {'folder' if before.is_dir() else 'file'}, "
                         f"{after} a {'folder' if after.is_dir() else 'file'})")
    if before.resolve() == after.resolve():
        raise InputError(f"{before}: BEFORE and AFTER are the same folder")
    problems: list[tuple[str, str]] = []
    sides = []
    for folder, edited, side in ((before, False, "originals"), (after, True, "edits")):
        found: dict[str, list[Path]] = {}
        for path in _image_files(folder):
            found.setdefault(_pair_key(path, edited), []).append(path)
        chosen = {}
        for key, paths in found.items():
            paths = sorted(paths, key=_preference)
            chosen[key] = paths[0]
            if len(paths) > 1:
                problems.append((paths[0].stem, f"{len(paths)} {side} share the name "
                                 f"({', '.join(p.name for p in paths)}); "
                                 f"{paths[0].name} is used"))
        sides.append(chosen)
    originals, edits = sides
    pairs = [PairFiles(originals[key].stem, originals[key], edits[key])
             for key in sorted(originals) if key in edits]
    for key in sorted(set(originals) - set(edits)):
        problems.append((originals[key].stem, f"no edited version in {after} "
                         f"(nothing named {originals[key].stem}.*)"))
    alone = [edits[key] for key in sorted(set(edits) - set(originals))]
    return FileMatch(pairs, alone, problems)


# --------------------------------------------------------------------------- reading


def learn_space(pairs: Sequence[PairFiles], working_space: str | None = None) -> str:
    """The working space the look is learned in: ``working_space``, else ACEScct when an
    original is a raw file (the space a raw photo is graded in), else sRGB-encoded Rec.709."""
    if working_space:
        return resolve_space(working_space, "spaces.working")
    if any(is_raw(p.before) for p in pairs):
        return resolve_space(RAW_WORKING_SPACE)
    return default_working_space()


@dataclass(frozen=True)
class PairImages:
    """A pair read into the working space.

    Attributes
    ----------
    name : the pair's name.
    before, after : (h, w, 3) float32 working-space colours in [0, 1], long side
        at most :data:`LEARN_SIZE` (each keeps its own shape).
    monochrome : whether the after is black and white (:data:`MONO_CHROMA`).
    toned : whether the after is toned, not black and white (:data:`TONED_SPREAD`);
        None when the original holds too little colour to tell.
    """
    name: str
    before: np.ndarray
    after: np.ndarray
    monochrome: bool
    toned: bool | None = False


def _read_small(path: Path, working: str) -> np.ndarray:
    """A photo in ``working``, shrunk first (a 24 MP raw is not converted whole)."""
    image = read_image(path)
    encoding = ColorEncoding.for_image(image, None, working)
    small = shrink_colors(image.rgb(), LEARN_SIZE)
    encoded, _ = encoding.encode(small, image.is_float)
    return np.ascontiguousarray(encoded, dtype=np.float32)


def read_pair(pair: PairFiles, working: str) -> PairImages:
    """Read both photos of a pair into the working space ``working`` (a config name).

    Raises InputError (naming the file) when either is unreadable.
    """
    before = _read_small(pair.before, working)
    after = _read_small(pair.after, working)
    chroma = after.max(axis=-1) - after.min(axis=-1)
    monochrome = bool(np.percentile(chroma, 99) < MONO_CHROMA)
    toned: bool | None = False
    if not monochrome and _tint_spread(after) < TONED_SPREAD:
        toned = True if _tint_spread(before) >= 2.0 * TONED_SPREAD else None
    return PairImages(pair.name, before, after, monochrome, toned)


def _tint_spread(image: np.ndarray) -> float:
    """99th percentile over the flat pixels of how far a colour's chroma (the colour minus
    its luma, largest channel) lies from the mean chroma of its lightness band: 0 for a
    photo whose every colour is its luma plus a tint of that luma (toned, or black and
    white). Flat: the luma of the 3x3 pixels about it spans under :data:`_TONE_FLAT` (a
    JPEG's chroma is one per 2x2 block, its luma one per pixel: on an edge a pixel holds
    another lightness's tint); all pixels when under a tenth are flat. (h, w, 3) image."""
    import cv2

    image = np.asarray(image, dtype=np.float32)
    luma = image @ TONE_LUMA.astype(np.float32)
    kernel = np.ones((3, 3), np.uint8)
    flat = (cv2.dilate(luma, kernel) - cv2.erode(luma, kernel)) < _TONE_FLAT
    if flat.mean() < 0.1:
        flat[...] = True
    colours = image[flat].astype(np.float64)
    band, _, tints = _band_tints(colours, np.ones(len(colours)))
    chroma = colours - (colours @ TONE_LUMA)[:, None]
    return float(np.percentile(np.abs(chroma - tints[band]).max(axis=1), 99))


def _band_tints(colours: np.ndarray, weights: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mean tint (colour minus its luma) of (N, 3) colours in each of
    :data:`_TONE_BANDS` bands of luma, ``weights`` (N,) weighing them.

    Returns (each colour's band (N,), each band's mean luma (B,), each band's mean tint
    (B, 3)); a band with no weight has luma NaN and tint 0."""
    luma = colours @ TONE_LUMA
    band = np.clip((luma * _TONE_BANDS).astype(np.intp), 0, _TONE_BANDS - 1)
    mass = np.bincount(band, weights, minlength=_TONE_BANDS)
    held = mass > 0
    safe = np.where(held, mass, 1.0)
    centres = np.where(held, np.bincount(band, weights * luma, minlength=_TONE_BANDS) / safe,
                       np.nan)
    tints = np.stack([np.bincount(band, weights * (colours[:, c] - luma),
                                  minlength=_TONE_BANDS) / safe for c in range(3)], axis=1)
    return band, centres, tints


# --------------------------------------------------------------------------- registration


@dataclass(frozen=True)
class Registration:
    """Where the after lies on the original.

    Attributes
    ----------
    homography : (3, 3) from the after's pixels to the original's (both at
        their :class:`PairImages` size).
    how : "same framing" or "resized" (either perhaps ", turned 90/180/270 degrees"),
        or "keypoints (N agree)".
    coverage : share of the original the after covers.
    """
    homography: np.ndarray
    how: str
    coverage: float


def _luma(colors: np.ndarray) -> np.ndarray:

    return np.asarray(colors, np.float32) @ np.float32(SYCC_LUMA)


def _rotation_homography(shape_after: tuple[int, int], turns: int,
                         shape_before: tuple[int, int]) -> np.ndarray:
    """The map from the after's pixels to the original's when the after, turned
    ``turns`` times by 90 degrees (as ``np.rot90``), is the original resized."""
    import cv2

    h, w = shape_after
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rx, ry = np.rot90(xs, turns), np.rot90(ys, turns)  # after's coords at each turned pixel
    th, tw = rx.shape
    hb, wb = shape_before
    corners = [(0, 0), (0, tw - 1), (th - 1, tw - 1), (th - 1, 0)]
    src = np.float32([(rx[i, j], ry[i, j]) for i, j in corners])
    dst = np.float32([((j + 0.5) * wb / tw - 0.5, (i + 0.5) * hb / th - 0.5)
                      for i, j in corners])
    return cv2.getPerspectiveTransform(src, dst)


def _warp(after: np.ndarray, homography: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    import cv2

    return cv2.warpPerspective(np.ascontiguousarray(after), homography, (shape[1], shape[0]),
                               flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_REPLICATE)


def _aligned(before: np.ndarray, warped: np.ndarray) -> bool:
    """Whether ``warped`` lies on ``before`` pixel for pixel: on a 4x4 grid of patches
    (at :data:`_CHECK_SIZE`), phase correlation finds no shift on most textured ones."""
    import cv2

    a = shrink_colors(np.repeat(_luma(before)[..., None], 3, axis=2), _CHECK_SIZE)[..., 0]
    b = shrink_colors(np.repeat(_luma(warped)[..., None], 3, axis=2), _CHECK_SIZE)[..., 0]
    h, w = a.shape
    ph, pw = h // 4, w // 4
    if ph < 16 or pw < 16:
        return False
    window = cv2.createHanningWindow((pw, ph), cv2.CV_32F)
    textured = agree = 0
    for i in range(4):
        for j in range(4):
            pa = np.ascontiguousarray(a[i * ph:(i + 1) * ph, j * pw:(j + 1) * pw])
            pb = np.ascontiguousarray(b[i * ph:(i + 1) * ph, j * pw:(j + 1) * pw])
            if pa.std() < 0.01 or pb.std() < 0.01:
                continue  # flat (sky, a wall): says nothing about the framing
            textured += 1
            # the means off: the window's own envelope would peak at no shift
            (dx, dy), response = cv2.phaseCorrelate(pa - pa.mean(), pb - pb.mean(), window)
            agree += bool(np.hypot(dx, dy) <= _PATCH_SHIFT and response > _PATCH_RESPONSE)
    return textured >= 4 and agree >= _PATCH_AGREE * textured


def register_pair(images: PairImages) -> Registration | None:
    """Lay the after over the original; None when they show different scenes.

    The cheap case first (the after is the original resized, perhaps turned
    by a multiple of 90 degrees: checked by :func:`_aligned`), then keypoints
    and a homography (:func:`wbcgrade.color.look.scene.match_scene`: crops,
    resized crops, turns).
    """
    before, after = images.before, images.after
    aspect = before.shape[1] / before.shape[0]
    for turns in range(4):
        th, tw = (after.shape[:2] if turns % 2 == 0 else after.shape[1::-1])
        if abs(tw / th / aspect - 1.0) > _ASPECT_TOLERANCE:
            continue
        homography = _rotation_homography(after.shape[:2], turns, before.shape[:2])
        if _aligned(before, _warp(after, homography, before.shape[:2])):
            how = ("same framing" if after.shape[:2] == (before.shape[:2] if turns % 2 == 0
                                                         else before.shape[1::-1])
                   else "resized")
            how += "" if turns == 0 else f", turned {90 * turns} degrees"
            return Registration(homography, how, 1.0)
    small_before, small_after = scene_image(before, KEYPOINT_SIZE), scene_image(after,
                                                                                KEYPOINT_SIZE)
    match = match_scene(small_before, small_after)
    if match is None:
        return None
    homography = (np.linalg.inv(_pixel_scale(before, small_before.colors)) @ match.homography
                  @ _pixel_scale(after, small_after.colors))
    return Registration(homography, f"keypoints ({match.inliers} agree)", match.coverage)


def _pixel_scale(image: np.ndarray, small: np.ndarray) -> np.ndarray:
    """(3, 3) from ``image``'s pixels to those of ``small``, a resized copy (pixel centres
    to pixel centres)."""
    fx, fy = small.shape[1] / image.shape[1], small.shape[0] / image.shape[0]
    return np.array([[fx, 0.0, 0.5 * fx - 0.5], [0.0, fy, 0.5 * fy - 0.5], [0.0, 0.0, 1.0]])


def pair_colours(images: PairImages, registration: Registration,
                 max_pairs: int = PAIRS_PER_PHOTO, seed: int = 0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Colour pairs of a registered pair: (originals (N, 3), afters (N, 3), weights (N,)),
    drawn from the overlap by :func:`wbcgrade.color.look.scene.colour_pairs`.

    A smaller after (resized) is not resampled: its pixels are area averages of the
    looked photo, and a bilinear blend of them mixes colours the look moved apart; the
    original, shrunk to the after's sharpness, is resampled onto them instead (Ektar 100
    learned from resized and cropped afters, ``benchmarks/learn.py``: +0.780 the other
    way, +0.798 so, against +0.841 from the afters as they were)."""
    before, homography = images.before, registration.homography
    h = homography / homography[2, 2]
    magnified = float(np.sqrt(abs(np.linalg.det(h[:2, :2]))))
    empty = (np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32))
    if magnified > 1.05:  # a smaller after: the original shrunk to its sharpness,
        size = max(16, round(max(before.shape[:2]) / magnified))
        small = shrink_colors(before, size)  # resampled onto the after's own pixels
        homography = np.linalg.inv(_pixel_scale(before, small) @ homography)
        after, original, weights = colour_pairs(
            SceneImage(images.after, *empty), SceneImage(small, *empty),
            SceneMatch(homography, 0, registration.coverage), max_pairs, seed)
        return original, after, weights
    return colour_pairs(SceneImage(before, *empty), SceneImage(images.after, *empty),
                        SceneMatch(homography, 0, registration.coverage), max_pairs, seed)


# --------------------------------------------------------------------------- the look


@dataclass(frozen=True)
class LearnedLook:
    """The look the pairs share: a scene look (:class:`wbcgrade.color.look.SceneLook`),
    made grey when every after was black and white, toned when every after was toned.

    Attributes
    ----------
    look : the fitted map (tone curves and colour mixing, then the lattice correction).
    monochrome : the output is grey (the mean of the fitted channels).
    toning : (lumas (m,), tints (m, 3)) of a toned look: the output is the fitted
        output's luma plus the afters' mean tint at that luma
        (:func:`wbcgrade.color.mapping.remap.to_monochrome`); None otherwise.
    """
    look: object
    monochrome: bool = False
    toning: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def toned(self) -> bool:
        """Whether the output is toned (a tint per lightness, no other colour)."""
        return self.toning is not None

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """Map colours: (..., 3) in [0, 1] -> (..., 3) float64 in [0, 1]."""
        out = self.look(rgb)
        if self.monochrome:
            out = np.repeat(out.mean(axis=-1, keepdims=True), 3, axis=-1)
        elif self.toning is not None:
            out = to_monochrome(out, self.toning).astype(np.float64)
        return out

    def lattice(self, size: int = 33) -> np.ndarray:
        """The map sampled as a (size, size, size, 3) float32 lattice LUT (R slowest)."""
        return self(grid_points(size)).reshape(size, size, size, 3).astype(np.float32)


def _flattened(part: tuple[np.ndarray, np.ndarray, np.ndarray]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A pair's colour pairs (sources (N, 3), targets, weights (N,)) with each weight divided
    by how common its source colour is in the pair (:data:`FLATTEN_COLOURS`): every colour
    the photo shows counts about the same, however many pixels show it."""
    sources, targets, weights = part
    density = _density(sources, weights, _FLATTEN_BLUR, "reflect")
    common = interpolate_lattice(density[..., None], sources)[:, 0]
    return sources, targets, weights / np.maximum(common, 1e-6) ** FLATTEN_COLOURS


def _every_pixel(part: tuple[np.ndarray, np.ndarray, np.ndarray]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A pair's colour pairs with every pixel weighing the same: what the original shows.
    Edges weigh less in the fit (a fraction of a pixel of misalignment mixes two colours
    there), not in which colours the pair shows: a starfield's stars and a portrait's
    eyes and tie are all edge, and their colours are counted as shown all the same (the
    Hubble field's pixels cover 0.57 of natural photos' colours, its edge-weighted ones
    0.34)."""
    sources, targets, _ = part
    return sources, targets, np.ones(len(sources))


def _pooled(parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parts' (sources, targets, weights) in one, each part weighing the same."""
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
            np.concatenate([p[2] / max(float(p[2].sum()), 1e-12) for p in parts]))


def _edit_prior(parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
                family: str | None = None):
    """The :class:`LookMap` of the edit that best explains the parts' pairs
    (:data:`EDIT_PRIOR_PAIRS`), or None for as many pairs or more. ``family``: the edit's
    family (:data:`~wbcgrade.color.look.edits.FAMILIES`; None: the one that extrapolates
    best within the pairs, :func:`~wbcgrade.color.look.edits.extrapolating_family`)."""
    if not parts or len(parts) >= EDIT_PRIOR_PAIRS:
        return None
    pooled = _pooled(parts)
    edit = FAMILIES[family or extrapolating_family(*pooled)](*pooled)
    points = grid_points(17)
    return fit_look_map(points, edit(points), np.ones(len(points)), None, 1e-4, 1e-6)


def _fit(parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], monochrome: bool,
         robust: Sequence[np.ndarray] | None = None, rounds: int = 3, toned: bool = False,
         prior=None) -> tuple[LearnedLook, list[np.ndarray], float]:
    """Fit the parts' pairs, each part weighing the same; ``monochrome``: the output
    made grey, ``toned``: made its luma plus the afters' mean tint at that luma (the
    afters' tints, robustly weighted, in bands of their luma: more faithful than the
    grey axis of a map fitted to colourful originals); ``prior``: the map where the pairs
    say little (default no look; :func:`_edit_prior`).

    Returns (the look, each part's robust weights, the pooled median distance)."""
    sources, targets, weights = _pooled(parts)
    start = None if robust is None else np.concatenate(list(robust))
    look, final = fit_pairs_look(sources, targets, weights, prior, rounds=rounds,
                                 robust=start, correct=False)
    with fast_cpu():
        correction = fit_correction(look.look(sources), targets, final, CORRECTION_NODES,
                                    CORRECTION_SMOOTHNESS)
    look = replace(look, correction=correction)
    split = np.cumsum([len(p[0]) for p in parts])[:-1]
    toning = None
    if toned and not monochrome:
        _, lumas, tints = _band_tints(targets, final)
        held = np.isfinite(lumas)
        toning = (lumas[held], tints[held])
    return LearnedLook(look, monochrome, toning), np.split(final, split), look.residual


def _delta_e(colors: np.ndarray, truth: np.ndarray, encoding) -> np.ndarray:
    """(N,) CIEDE2000 between two lists of working-space colours (shown as sRGB, D65)."""
    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]

    def lab(rgb: np.ndarray) -> np.ndarray:
        shown = encoding.to_display(rgb, working=True).astype(np.float64)
        return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(shown, illuminant=d65), d65)

    return np.asarray(colour.delta_E(lab(colors), lab(truth), method="CIE 2000"))


@dataclass
class PairReport:
    """How one pair went.

    Attributes
    ----------
    name : the pair's name (the original's stem).
    before, after : the files.
    registered : how the after was laid on the original (:attr:`Registration.how`),
        or None.
    problem : why the pair was not used (unreadable file, another scene), or None.
    coverage : share of the original the after covers.
    monochrome : the after is black and white.
    toned : the after is toned (a tint per lightness, not black and white); None:
        the original holds too little colour to tell.
    delta_e : mean CIEDE2000 of the after against the look applied to the
        original (the look fitted on all pairs).
    held_out : the same with the look fitted without this pair's fold, or None.
    edited_share : share of the pair's pixels the robust fit left out (local edits).
    warning : why the pair disagrees with the others, or None.
    """
    name: str
    before: str
    after: str
    registered: str | None = None
    problem: str | None = None
    coverage: float | None = None
    monochrome: bool = False
    toned: bool | None = False
    delta_e: float | None = None
    held_out: float | None = None
    edited_share: float | None = None
    warning: str | None = None

    def as_dict(self) -> dict:
        """JSON-friendly."""
        out = dict(self.__dict__)
        for key in ("coverage", "delta_e", "held_out", "edited_share"):
            if out[key] is not None:
                out[key] = round(float(out[key]), 4)
        return out


class OriginalToAdd(TypedDict):
    """The edited photo whose original would teach the look most (:func:`teaching_original`):
    its name (the stem its original pairs by), and the share of natural photos' colours
    the pairs cover ``now`` and would cover ``with_it``."""
    name: str
    now: float
    with_it: float


@dataclass
class LearnResult:
    """The learned look and how well it explains the pairs.

    Attributes
    ----------
    look : the :class:`LearnedLook` (None when no pair was usable).
    pairs : a :class:`PairReport` per pair, used or not.
    problems : (name, reason) of files that could not be paired.
    working_space : the working space of the look (config name).
    folds : folds of the held-out check (0: one pair, none).
    seconds : time taken.
    coverage : how much of each region of colour the pairs show (:func:`colour_coverage`).
    far_trust : with few pairs and edited photos without originals, how far the look is
        followed away from the pairs' colours (0 not at all, 1 fully): ``by_pairs`` as
        the pairs say (their coverage and how well the look carried their own held-out
        colours: :func:`supported_look`), ``by_edits`` as the edited photos then say
        (:func:`evidence_trust`); empty otherwise.
    original_to_add : with few pairs, the edited photo without an original whose original
        would show the look most of what the pairs do not (:func:`teaching_original`);
        None when no such photo would add much.
    """
    look: LearnedLook | None
    pairs: list[PairReport]
    problems: list[tuple[str, str]]
    working_space: str
    folds: int = 0
    seconds: float = 0.0
    output: Path | None = None
    edits_alone: list[str] = field(default_factory=list)
    coverage: dict[str, float] = field(default_factory=dict)
    far_trust: dict[str, float] = field(default_factory=dict)
    original_to_add: OriginalToAdd | None = None

    @property
    def used(self) -> list[PairReport]:
        return [p for p in self.pairs if p.problem is None]

    def describe(self) -> str:
        """In words: what the look was learned from."""
        n, alone = len(self.used), len(self.edits_alone)
        return (f"the look learned from {n} before/after pair{'s' * (n != 1)}"
                + (f" and {alone} edited photo{'s' * (alone != 1)} without an original"
                   if alone else ""))

    def coverage_words(self) -> str | None:
        """In words: how much of each region of colour the pairs show, and what becomes of
        the rest (None when nothing was learned)."""
        if not self.coverage:
            return None
        sure = ", ".join(f"{name} {100 * share:.0f} %" for name, share in self.coverage.items())
        rest = ("corrected by the edits without an original" if self.edits_alone
                else "extrapolated")
        return f"how much of each kind of colour the pairs show (the rest is {rest}): {sure}"

    def reach_words(self) -> str | None:
        """In words: how far the look is followed away from the pairs' colours, and what
        said so (None unless the edited photos were asked: :attr:`far_trust`)."""
        if not self.far_trust:
            return None
        by_pairs, by_edits = self.far_trust["by_pairs"], self.far_trust["by_edits"]
        said = ("as the pairs themselves say" if by_edits <= by_pairs
                else f"{100 * by_pairs:.0f} % by the pairs alone; the edited photos "
                     "without an original show the look reaching further")
        return (f"away from the pairs' colours the look is followed {100 * by_edits:.0f} % "
                f"of the way ({said})")

    def original_to_add_words(self) -> str | None:
        """In words: the original worth adding to learn more of the look (None: none)."""
        add = self.original_to_add
        if not add:
            return None
        return (f"the original of {add['name']} would teach the look more: with it the "
                f"pairs would show about {100 * add['with_it']:.0f} % of the colours photos "
                f"hold (judged from its edit), against {100 * add['now']:.0f} % now; add it "
                "to the originals")

    def original_to_add_dict(self) -> dict | None:
        """:attr:`original_to_add`, rounded for JSON (None: none)."""
        add = self.original_to_add
        return None if not add else {"name": add["name"], "now": round(add["now"], 3),
                                     "with_it": round(add["with_it"], 3)}

    def _mean(self, key: str) -> float | None:
        values = [getattr(p, key) for p in self.used if getattr(p, key) is not None]
        return float(np.mean(values)) if values else None

    @property
    def delta_e(self) -> float | None:
        """Mean over the used pairs of their CIEDE2000 (fitted)."""
        return self._mean("delta_e")

    @property
    def held_out(self) -> float | None:
        """Mean over the used pairs of their held-out CIEDE2000 (None: fewer than two pairs)."""
        return self._mean("held_out")

    def as_dict(self) -> dict:
        """JSON-friendly summary (what the command prints as JSON)."""
        return {"output": None if self.output is None else str(self.output),
                "working_space": self.working_space,
                "pairs_used": len(self.used), "pairs_given": len(self.pairs),
                "monochrome": bool(self.look is not None and self.look.monochrome),
                "toned": bool(self.look is not None and self.look.toned),
                "delta_e": None if self.delta_e is None else round(self.delta_e, 4),
                "held_out_delta_e": None if self.held_out is None else round(self.held_out, 4),
                "held_out_folds": self.folds,
                "seconds": round(self.seconds, 3),
                "pairs": [p.as_dict() for p in self.pairs],
                "unpaired": [{"name": n, "problem": why} for n, why in self.problems],
                "edits_without_original": list(self.edits_alone),
                "pairs_cover": {k: round(v, 3) for k, v in self.coverage.items()},
                "far_trust": {k: round(v, 3) for k, v in self.far_trust.items()},
                "original_to_add": self.original_to_add_dict(),
                "warnings": [f"{p.name}: {p.warning}" for p in self.pairs if p.warning]}


def _folds(n: int) -> list[np.ndarray]:
    k = min(n, LEARN_FOLDS)
    return [np.arange(i, n, k) for i in range(k)] if n >= 2 else []


def learn_look(pairs: Sequence[PairFiles], working_space: str | None = None,
               problems: Sequence[tuple[str, str]] = (),
               warn: Callable[[str], None] | None = None,
               progress: Callable[[int, int, str], None] | None = None,
               edits_alone: Sequence[Path] = ()) -> LearnResult:
    """Learn the look before/after pairs share.

    Parameters
    ----------
    pairs : the pairs (:func:`pair_files`).
    working_space : where the look is fitted and applied (None: :func:`learn_space`).
    problems : what pairing could not pair (carried into the result).
    warn : called with one line for each pair that cannot be used or disagrees.
    progress : ``progress(done, total, name)`` as pairs are read.
    edits_alone : edited photos without their original: evidence of how the look moves
        the colours the pairs do not show (:func:`unpaired_correction`).

    Returns
    -------
    :class:`LearnResult`; its ``look`` is None when no pair was usable.
    """
    import time

    start = time.perf_counter()
    warn = warn or (lambda message: None)
    working = learn_space(pairs, working_space)
    encoding = ColorEncoding.of(working, working)
    reports, parts, read = [], [], []
    total = len(pairs) + len(edits_alone)
    drawn = max(PAIRS_PER_PHOTO, PAIRS_IN_ALL // max(len(pairs), 1))
    for number, pair in enumerate(pairs):
        if progress:
            progress(number, total, pair.name)
        report = PairReport(pair.name, str(pair.before), str(pair.after))
        reports.append(report)
        try:
            images = read_pair(pair, working)
        except (InputError, OSError) as exc:
            report.problem = worded_error(exc, "unreadable: ")
        else:
            registration = register_pair(images)
            if registration is None:
                report.problem = ("the edited photo shows another scene (no framing of it "
                                  "lies on the original)")
            else:
                report.registered = registration.how
                report.coverage = registration.coverage
                report.monochrome = images.monochrome
                report.toned = images.toned
                parts.append((report, pair_colours(images, registration, drawn)))
                read.append(images)
        if report.problem:
            warn(worded_text(report.problem, f"{pair.name}: ", "; left out"))
    alone: list[tuple[str, np.ndarray]] = []
    for number, path in enumerate(edits_alone):
        if progress:
            progress(len(pairs) + number, total, path.stem)
        try:
            alone.append((path.stem, _read_small(Path(path), working)))
        except (InputError, OSError) as exc:
            warn(worded_error(exc, f"{path.stem}: unreadable: ", "; left out"))
    if progress:
        progress(total, total, "")
    result = LearnResult(None, reports, list(problems), working,
                         edits_alone=[name for name, _ in alone])
    if not parts:
        result.seconds = time.perf_counter() - start
        return result
    used = [report for report, _ in parts]
    colours = [pair for _, pair in parts]
    alone_mono = [bool(np.percentile(image.max(axis=-1) - image.min(axis=-1), 99)
                       < MONO_CHROMA) for _, image in alone]
    monochrome = all(r.monochrome for r in used) and all(alone_mono)
    toned = (not monochrome and any(r.toned for r in used)
             and all(r.monochrome or r.toned is not False for r in used))
    plain = monochrome or toned  # (an edit's colours are not what such a look keeps)
    fitted = [_flattened(c) for c in colours]
    shown_parts = [_every_pixel(c) for c in colours]
    shown = _pooled(shown_parts)[::2]  # (sources, weights): the colours the pairs show
    choice = (None if plain or len(colours) >= EDIT_PRIOR_PAIRS
              else choose_family(*_pooled(fitted)))
    family = None if choice is None else choice.name
    skill = None if choice is None else choice.skill
    look, robust, _ = _fit(fitted, monochrome, toned=toned,
                           prior=None if plain else _edit_prior(fitted, family))
    if not plain:
        look = _trusted_near(look, shown_parts, working, skill)
    if alone and not plain:
        edits = [i.after for i in read] + [image for _, image in alone]
        inner = look.look
        if isinstance(inner, SupportedLook):
            chosen = evidence_trust(inner, edits, working)
            result.far_trust = {"by_pairs": inner.trust, "by_edits": chosen.trust}
            inner = chosen
        corrected = unpaired_correction(inner, edits, [i.before for i in read], *shown,
                                        working)
        look = replace(look, look=corrected)
    for report, (sources, targets, weights) in zip(used, colours):
        report.delta_e = float(np.mean(_delta_e(look(sources), targets, encoding)))
        report.edited_share = _edited_share(sources, targets, weights)
    folds = _folds(len(colours))
    for held in folds:
        rest = [i for i in range(len(colours)) if i not in set(held.tolist())]
        kept = [fitted[i] for i in rest]
        fold_look, _, _ = _fit(kept, monochrome, [robust[i] for i in rest], rounds=1,
                               toned=toned,
                               prior=None if plain else _edit_prior(kept, family))
        if not plain:  # (the family and its skill as all the pairs chose them)
            fold_look = _trusted_near(fold_look, [shown_parts[i] for i in rest], working,
                                      skill)
        for i in held:
            sources, targets, _ = colours[i]
            used[i].held_out = float(np.mean(_delta_e(fold_look(sources), targets, encoding)))
    result.look, result.folds = look, len(folds)
    result.coverage = colour_coverage(*shown, working)
    if alone and not plain and len(colours) < EDIT_PRIOR_PAIRS:
        result.original_to_add = teaching_original(*shown, alone, working)
    _flag_disagreements(used, warn)
    _warn_mixed(used, monochrome, toned, warn)
    result.seconds = time.perf_counter() - start
    return result


def _warn_mixed(used: list[PairReport], monochrome: bool, toned: bool,
                warn: Callable[[str], None]) -> None:
    """Warn when some afters are black and white or toned and the others are not."""
    if monochrome:
        return
    if toned:
        odd, what, rest, learned = ([r.name for r in used if r.monochrome], "black and white",
                                    "toned", "the toning learned lies between theirs")
    else:
        odd = [r.name for r in used if r.monochrome or r.toned]
        what, rest, learned = ("black and white or toned", "in colour",
                               "the look learned is a colour one")
    if odd:
        warn(f"{len(odd)} of the {len(used)} edited photos are {what} "
             f"({', '.join(odd[:4])}{', ...' if len(odd) > 4 else ''}), the others "
             f"{rest}: two looks? {learned}")


def _edited_share(sources: np.ndarray, targets: np.ndarray, weights: np.ndarray) -> float:
    """Share of a pair's flat pixels that no global map of that pair alone explains: what
    a local edit (a healed spot, a masked sky) changed. The pair's own look (robust, no
    correction) misses them by more than :data:`_LOCAL_DISTANCE` and four times its
    median distance. Pixels on edges and texture (``weights`` below :data:`_FLAT`, as
    :func:`wbcgrade.color.look.scene.colour_pairs` gives them) are not counted: a look applied
    before or after resizing differs there."""
    own, _ = fit_pairs_look(sources, targets, weights, rounds=2, correct=False)
    distance = np.linalg.norm(own(sources) - targets, axis=1)
    flat = weights >= _FLAT
    if not flat.any():
        return 0.0
    far = distance > max(_LOCAL_DISTANCE, 4.0 * float(np.median(distance)))
    return float(np.mean(far[flat]))


def _flag_disagreements(used: list[PairReport], warn: Callable[[str], None]) -> None:
    """Warn of pairs with local edits (many pixels no global map of the pair explains)
    and, among three or more, of pairs whose held-out error stands out (another look)."""
    held = [r.held_out for r in used if r.held_out is not None]
    typical = float(np.median(held)) if len(held) >= 3 else None
    for report in used:
        error = report.held_out
        stands_out = (typical is not None and error is not None
                      and error > max(_DISAGREE_FACTOR * typical, typical + _DISAGREE_MARGIN))
        if report.edited_share is not None and report.edited_share > _LOCAL_SHARE:
            report.warning = (f"local edits: about {100 * report.edited_share:.0f}% of the "
                              "photo differs from the look the pairs share (those pixels "
                              "weigh little in the fit)")
        elif stands_out:
            report.warning = (f"disagrees with the other pairs (held-out CIEDE2000 "
                              f"{error:.1f} against {typical:.1f} typical): another look?")
        if report.warning:
            warn(f"{report.name}: {report.warning}")


# --------------------------------------------------------------------------- the file


#: Colours whose density in the pairs' edited colours (a 17^3 soft histogram, blurred by a
#: node) reaches this multiple of the uniform density are pinned by the pairs: the edited
#: photos without originals correct the look only where the pairs show little
#: (:func:`unpaired_correction`).
PAIR_SUPPORT = 0.5
#: Prior probability that the edits without originals show nothing beyond the pairs' look
#: (a correction is less likely than a look: the pairs already show most of it). Measured
#: again once a look of few pairs was trusted only near their colours (the tuned looks of
#: ``benchmarks/one_original.py``: mean, mean of the worst photos, cases with a photo worse
#: than nothing): 0.5 +0.519 / +0.289 / 16 %; 0.8 +0.518 / +0.290 / 12 %; 0.95 +0.516 /
#: +0.288 / 9 %: the edits' correction is a small part of what one original gives.
NO_CORRECTION = 0.8
#: Grid of the support.
_SUPPORT_SIZE = 17
#: With fewer pairs than :data:`EDIT_PRIOR_PAIRS`, how far the look is trusted away from
#: the pairs' colours follows how much of what natural photos hold the pairs cover (the
#: natural palettes' mass under their :func:`_support`): at or below the first share the
#: look moves only the colours the pairs show (and fades to no change away from them),
#: at or above the second it is trusted everywhere, in between partly
#: (:class:`SupportedLook`). A pair of one hue (a purple sea: 0.28 of natural colours)
#: fits curves that turn greys and blacks brown; a portrait or a still life (0.82 to
#: 0.87) teaches a look that carries. Chosen on the tuned looks of
#: ``benchmarks/one_original.py`` (each of eight photos as the one original; the held-out
#: looks checked after; docs/benchmarks.md). The shares are of every pixel of the
#: originals (:func:`_every_pixel`); they were chosen 0.03 lower on edge-weighted
#: colours, which show 0.005 to 0.07 less of most photos (the benchmark's sea 0.25
#: against 0.28, its bridge 0.43 against 0.46; the samples' bridge 0.43 against 0.48)
#: and far less of the few whose colours are small things (the Hubble field's stars
#: 0.34 against 0.57, Grace Hopper 0.69 against 0.82). Both shares moved with the
#: typical photo (+0.03; this and :data:`NEAR_COVERAGE`), the tuned looks went from
#: +0.661 to +0.684 (mean of the worst photos +0.487 -> +0.506, still none worse than
#: nothing; left where they were: +0.695, +0.498, but 6 % of cases with one, from the
#: sea); the held-out looks, run once after, from +0.585 to +0.616 (+0.352 -> +0.384).
TRUSTED_COVERAGE = (0.43, 0.73)
#: Just beside the pairs' colours (a node or two of the support's grid away), where their
#: own support gives the look only part of the way, the look is followed this many times
#: further (the support times the gain, at most 1) once the pairs cover the second share
#: of natural colours, not at all below the first (:func:`supported_look`). The look
#: learned there is 2 to 8 times nearer the truth than the faded one (RGB error on the
#: photos of ``benchmarks/one_original.py``, support 0.1 to 0.9), except beside a purple
#: sea's colours (0.28 of natural colours, the lowest of the 21 photos; a pale bridge
#: 0.46): its darkest blues sit beside black, where its look lifts and greens. Chosen on
#: the tuned looks of ``one_original.py``: mean +0.575 -> +0.597, mean of the worst
#: photos +0.393 -> +0.413, no photo worse than nothing (a gain of 3 for every pair:
#: +0.601, but 9 % of cases with one, all from the sea; 10: +0.617, 12 %); held out run
#: once after: +0.510 -> +0.533, +0.292 -> +0.305, unchanged 12 % (then on edge-weighted
#: colours, the shares 0.03 lower: :data:`TRUSTED_COVERAGE`).
NEAR_GAIN = 3.0
NEAR_COVERAGE = (0.28, 0.38)
#: How far the pairs' look is trusted away from their colours also follows how well its
#: family carried the pairs' edit to their own held-out colours (the skill of
#: :func:`~wbcgrade.color.look.edits.choose_family`: 1 minus its error over no change's):
#: from no trust at the first skill to full trust at the second, once the pairs cover
#: the second share of :data:`NEAR_COVERAGE` (a pair of one hue carries its held-out
#: blocks of blues easily: they lie beside the others, and its look still turns greys).
#: A film stock learned from the Hubble field or a bridge is carried that well (Velvia
#: 0.74 to 0.94), a subtle stock less (Portra from the espresso, the flower or the Hubble
#: field 0.14 to 0.46). Chosen on the tuned looks of ``benchmarks/one_original.py``
#: (384 px): mean +0.653 -> +0.661, mean of the worst photos +0.480 -> +0.487, still none
#: worse than nothing (without the coverage's condition (0.6, 0.9) gave +0.665, +0.485, 3 %
#: of cases with one, and (0.7, 0.9) the sea's greys moved); held out once after: +0.584
#: -> +0.585, +0.349 -> +0.352.
SKILLED_TRUST = (0.7, 0.9)
#: With fewer pairs than :data:`EDIT_PRIOR_PAIRS` and edited photos without originals, how
#: far the pairs' look is followed away from their colours (the trust) is what the edited
#: photos make most probable (:func:`evidence_trust`): the trusts whose likelihood is
#: measured, the spread of the prior about the pairs' trust, and the natural palettes
#: each is pushed through (a seeded draw: their medians need no more; all 316 cost 1.1 s a
#: trust). Chosen on the tuned looks of ``benchmarks/one_original.py``: mean +0.597 ->
#: +0.621, mean of the worst photos +0.413 -> +0.449, no photo worse than nothing (the
#: likeliest trust alone: 6 % of cases with one, from the sea); held out once after:
#: +0.533 -> +0.546. The prior's spread 0.3 -> 0.5 (the cap to the near gain's ramp
#: does what the tighter prior did): tuned +0.621 -> +0.628, worst photos +0.449 ->
#: +0.458, still none worse than nothing; held out +0.546 -> +0.558, +0.322 -> +0.335
#: (docs/benchmarks.md).
FAR_TRUSTS = (0.0, 0.25, 0.5, 0.75, 1.0)
FAR_TRUST_PRIOR = 0.5
EVIDENCE_PALETTES = 80


@dataclass(frozen=True)
class CorrectedLook:
    """A look fitted on pairs, after a correction of the content colours the pairs do not
    show (read from edited photos without originals).

    ``y + (1 - support(y)) * (residual(y) - y)`` with ``y = look(x)``: ``residual`` the
    edits' look beyond the pairs' (a :class:`~wbcgrade.color.look.statistics.StatisticsLook`:
    tone, saturation and tint by lightness, applied as it is: a smooth map fitted to it on
    the cube carried its pull on saturated blues into blacks, 0.02 of blue), ``support`` in
    [0, 1] how well the pairs' edited colours cover ``y``.
    """
    look: object
    residual: object
    support: np.ndarray

    def __call__(self, rgb: np.ndarray) -> np.ndarray:

        rgb = np.asarray(rgb, dtype=np.float64)
        mapped = np.asarray(self.look(rgb.reshape(-1, 3)), dtype=np.float64)
        free = 1.0 - interpolate_lattice(self.support[..., None], mapped)[:, 0]
        out = np.clip(mapped + free[:, None] * (self.residual(mapped) - mapped), 0.0, 1.0)
        return out.reshape(rgb.shape)


def _density(sources: np.ndarray, weights: np.ndarray, blur: float, mode: str) -> np.ndarray:
    """(m, m, m) how dense colours ``sources`` (N, 3) with ``weights`` lie at each node of
    the support's grid (1: as dense as if spread evenly), blurred by ``blur`` nodes
    (``mode``: scipy's edge rule)."""
    from scipy.ndimage import gaussian_filter

    density = soft_histogram(sources, _SUPPORT_SIZE, weights)
    return gaussian_filter(density, blur, mode=mode) * density.size


def _support(sources: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(m, m, m) how well colours ``sources`` (N, 3) with ``weights`` cover each node, in
    [0, 1]."""
    return _support_of(_support_density(sources, weights))


def _support_density(sources: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(m, m, m) the density :func:`_support` is read from (linear in the colours' mass:
    the density of two sets pooled is their mean, weighed by each set's total weight)."""
    return _density(sources, weights, 1.0, "constant")


def _support_of(density: np.ndarray) -> np.ndarray:
    """:func:`_support` from its density (:func:`_support_density`)."""
    return np.clip(density / PAIR_SUPPORT, 0.0, 1.0)


#: Regions of colour the learned look reports its sureness for (:func:`colour_coverage`):
#: name -> test on sRGB-encoded colours (N, 3) -> (N,) bool.
COLOUR_REGIONS = {
    "shadows": lambda c: c @ np.array([0.2126, 0.7152, 0.0722]) < 0.2,
    "highlights": lambda c: c @ np.array([0.2126, 0.7152, 0.0722]) > 0.8,
    "greys": lambda c: np.ptp(c, axis=1) < 0.06,
    "skin": lambda c: (c[:, 0] > c[:, 1]) & (c[:, 1] > c[:, 2]) & (np.ptp(c, axis=1) > 0.06)
    & (c[:, 0] - c[:, 2] < 0.45) & (c[:, 0] > 0.35),
    "skies and water": lambda c: (c[:, 2] > c[:, 0] + 0.06) & (c[:, 2] >= c[:, 1]),
    "foliage": lambda c: (c[:, 1] > c[:, 0] + 0.03) & (c[:, 1] > c[:, 2] + 0.03),
    "reds": lambda c: (c[:, 0] > c[:, 1] + 0.25) & (c[:, 0] > c[:, 2] + 0.25),
}


@dataclass(frozen=True)
class SupportedLook:
    """A look fitted on few pairs, trusted where their colours are.

    ``x + (trust + (1 - trust) * support(x)) * (look(x) - x)``: ``support`` (m, m, m) in
    [0, 1], how well the pairs' original colours cover ``x`` (:func:`_support`, reaching
    further by :data:`NEAR_GAIN` when they cover enough); ``trust`` in [0, 1], how far
    the look is followed away from them; ``reach``, the most the edited photos may raise
    the trust to (:func:`evidence_trust`).
    """
    look: object
    support: np.ndarray
    trust: float
    reach: float = 1.0

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """Map colours: (..., 3) in [0, 1] -> (..., 3) float64 in [0, 1]."""
        rgb = np.asarray(rgb, dtype=np.float64)
        flat = rgb.reshape(-1, 3)
        mapped = np.asarray(self.look(flat), dtype=np.float64)
        near = interpolate_lattice(self.support[..., None], flat)[:, 0]
        follow = self.trust + (1.0 - self.trust) * np.clip(near, 0.0, 1.0)
        return np.clip(flat + follow[:, None] * (mapped - flat), 0.0, 1.0).reshape(rgb.shape)


@functools.lru_cache(maxsize=4)
def _natural_density(working: str) -> np.ndarray:
    """(m, m, m) the natural palettes' mean histogram on the support's grid, in ``working``
    (read-only; converted once per working space: the look, each fold and the coverage)."""
    natural = styles_in_space(natural_palettes(), working).at_bins(_SUPPORT_SIZE)
    density = natural.mean(axis=0)
    density.setflags(write=False)
    return density


def _covered(support: np.ndarray, working: str) -> float:
    """The share of natural photos' colours a support (m, m, m) in [0, 1] covers."""
    density = _natural_density(working).ravel()
    return float(density @ support.ravel() / max(float(density.sum()), 1e-300))


def supported_look(look, sources: np.ndarray, weights: np.ndarray, working: str,
                   skill: float | None = None) -> SupportedLook:
    """``look`` (fitted on pairs whose original colours are ``sources`` (N, 3) with
    ``weights``) trusted as far as those colours cover natural photos'
    (:data:`TRUSTED_COVERAGE`), and just beside them further than their own support
    (:data:`NEAR_GAIN`, :data:`NEAR_COVERAGE`; the edited photos may raise the trust as
    far as the latter's share of the way to 1: ``reach``). ``skill``: how well the look's
    family carried the pairs' edit to their own held-out colours
    (:class:`~wbcgrade.color.look.edits.FamilyChoice`); a high one raises the trust of
    pairs that cover enough (:data:`SKILLED_TRUST`)."""
    support = _support(sources, weights)
    covered = _covered(support, working)
    low, high = TRUSTED_COVERAGE
    near_low, near_high = NEAR_COVERAGE
    near = float(np.clip((covered - near_low) / (near_high - near_low), 0.0, 1.0))
    trust = float(np.clip((covered - low) / (high - low), 0.0, 1.0))
    reach = max(trust, near)
    if skill is not None and near >= 1.0:  # (held-out blocks of one hue lie side by side)
        low, high = SKILLED_TRUST
        trust = max(trust, float(np.clip((skill - low) / (high - low), 0.0, 1.0)))  # (reach 1)
    return SupportedLook(look, np.clip(support * (1.0 + (NEAR_GAIN - 1.0) * near), 0.0, 1.0),
                         trust, reach)


def _trusted_near(look: LearnedLook, parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
                  working: str, skill: float | None = None) -> LearnedLook:
    """``look`` fitted on ``parts`` (pairs' colours), trusted near their colours
    (:func:`supported_look`, ``skill`` its family's) when they are fewer than
    :data:`EDIT_PRIOR_PAIRS`."""
    if len(parts) >= EDIT_PRIOR_PAIRS:
        return look
    sources, _, weights = _pooled(parts)
    return replace(look, look=supported_look(look.look, sources, weights, working, skill))


def colour_coverage(sources: np.ndarray, weights: np.ndarray, working: str) -> dict[str, float]:
    """How sure the pairs make the look, region by region of colour: the share of what
    natural photos hold of each region (:data:`COLOUR_REGIONS`) that the pairs' original
    colours ``sources`` (N, 3, working space) cover (:func:`_support`), in [0, 1]."""
    support = _support(sources, weights).ravel()
    density = _natural_density(working).ravel()
    nodes = grid_points(_SUPPORT_SIZE)
    srgb = default_working_space()
    shown = nodes if working == srgb else np.clip(convert(nodes, working, srgb), 0.0, 1.0)
    out = {}
    for name, test in COLOUR_REGIONS.items():
        mass = density * test(shown)
        total = float(mass.sum())
        out[name] = float(mass @ np.minimum(support, 1.0) / total) if total > 0 else 0.0
    return out


#: With fewer pairs than :data:`EDIT_PRIOR_PAIRS`, an edited photo without its original is
#: named as the one worth pairing when its colours would widen the share of natural
#: photos' colours the pairs cover by at least this much (:func:`teaching_original`): one
#: original of a purple sea covers 0.28 of them and teaches a look +0.09 to +0.37 of the
#: way on other photos; one of a portrait or a still life covers 0.82 to 0.87 and teaches
#: +0.78 to +0.94 (``benchmarks/one_original.py``, tuned looks). Set at 0.15 when the
#: pairs' share was of edge-weighted colours; lowered with the typical photo's share once
#: every pixel counted (:data:`TRUSTED_COVERAGE`; a candidate's was counted so already).
ADVICE_GAIN = 0.12
#: Pixels of each edited photo looked at (evenly strided) by :func:`teaching_original`.
_ADVICE_PIXELS = 20_000


def teaching_original(sources: np.ndarray, weights: np.ndarray,
                      edits: Sequence[tuple[str, np.ndarray]], working: str
                      ) -> OriginalToAdd | None:
    """Of edited photos without an original, the one whose original would teach the look
    most: pooled with the pairs' original colours ``sources`` (N, 3) with ``weights``
    (each pair weighing the same, as the look is fitted), it would cover most of natural
    photos' colours (:func:`_support`). Its edited colours stand for its original's: a
    subtle look moves them little in this measure, a strong one more (beside a bridge,
    a bleach-bypassed espresso promises 0.85, its original covers 0.73), so the share is
    approximate.

    Parameters
    ----------
    sources, weights : the pairs' original colours (N, 3), each pair's weights summing
        to 1 (as :func:`_pooled` gives them).
    edits : (name, (h, w, 3) working-space colours) of each edited photo.

    Returns the photo (:class:`OriginalToAdd`), or None when none would widen the share
    by :data:`ADVICE_GAIN`.
    """
    sources = np.asarray(sources, dtype=np.float64).reshape(-1, 3)
    weights = np.asarray(weights, dtype=np.float64).ravel()
    pairs, total = _support_density(sources, weights), float(weights.sum())
    now = _covered(_support_of(pairs), working)
    best: OriginalToAdd | None = None
    for name, image in edits:
        colours = np.asarray(image, dtype=np.float64).reshape(-1, 3)
        colours = colours[::max(1, len(colours) // _ADVICE_PIXELS)]
        if not len(colours):
            continue
        theirs = _support_density(colours, np.ones(len(colours)))  # (its weight: 1)
        with_it = _covered(_support_of((total * pairs + theirs) / (total + 1.0)), working)
        if best is None or with_it > best["with_it"]:
            best = {"name": name, "now": now, "with_it": with_it}
    return best if best is not None and best["with_it"] >= now + ADVICE_GAIN else None


def unpaired_correction(look, edits: Sequence[np.ndarray], originals: Sequence[np.ndarray],
                        sources: np.ndarray, weights: np.ndarray, working: str):
    """The look corrected by what the edited photos say of the colours the pairs lack.

    Every edited photo (with an original or not) is ``look(content)`` for content of
    natural photos. The natural palettes pushed through the pairs' look are what the
    edited photos would be if the pairs had shown the whole look; what the edited
    photos show beyond that is the set look of the edits against the pushed palettes
    (:func:`~wbcgrade.color.look.prior.posterior_statistics_look`: judged jointly against
    what content does), applied after the pairs' look only where the pairs' edited
    colours show little (:func:`_support`).

    Parameters
    ----------
    look : the pairs' look (a callable on (N, 3) colours).
    edits : every edited photo, (h, w, 3) working-space colours.
    originals : the pairs' originals (unused beyond ``sources``).
    sources, weights : the pairs' original colours (N, 3) and their weights.
    working : the working space.

    Returns a :class:`CorrectedLook`, or ``look`` itself when nothing is left to correct.
    """
    bins = MAP_BINS
    naturals = styles_in_space(natural_palettes(), working)
    pushed_stats = _pushed_statistics(look, naturals.at_bins(bins))
    hists = np.stack([image_histogram(np.asarray(e, np.float64), bins) for e in edits])
    scale = space_scale(working)
    model = posterior_statistics_look(tinted_statistics(hists, pushed_stats, space_scale=scale),
                                      pushed_stats, scale,
                                      noise_from=natural_statistics(naturals),
                                      cache=default_cache_dir(), no_look=NO_CORRECTION)
    if model.info.get("share", 0.0) <= 0.0:
        return look
    return CorrectedLook(look, model, _support(look(sources), weights))


def _pushed_statistics(look, hists: np.ndarray) -> PaletteStatistics:
    """The statistics of histograms ``hists`` (K, n, n, n) pushed through ``look``: the
    look is evaluated once on the grid's nodes the histograms hold (they share the grid),
    not once a histogram."""
    bins = hists.shape[1]
    flats = hists.reshape(len(hists), -1)
    held = np.flatnonzero((flats > 0).any(axis=0))
    mapped = np.zeros((flats.shape[1], 3))
    mapped[held] = look(grid_points(bins)[held])
    pushed = []
    for flat in flats:
        keep = np.flatnonzero(flat > 0)
        pushed.append(soft_histogram(mapped[keep], bins, flat[keep]))
    return palette_statistics(np.stack(pushed))


def evidence_trust(look: SupportedLook, edits: Sequence[np.ndarray], working: str
                   ) -> SupportedLook:
    """``look`` (a look of few pairs, trusted near their colours) followed as far away from
    them as the edited photos ``edits`` ((h, w, 3) working-space colours, with and without
    originals) say.

    Every edited photo is the look applied to some natural photo. For each trust of
    :data:`FAR_TRUSTS`, natural palettes pushed through the look so trusted give the
    statistics the edits would have (tone, saturation and tint by lightness); how far the
    edits' own statistics lie from them, against what content alone varies by
    (:func:`~wbcgrade.color.look.prior.content_noise` for a median of that many photos),
    is the trust's likelihood. The trust chosen is the most probable under a prior about
    the pairs' trust (``look.trust``: their coverage's, raised by their skill;
    :data:`FAR_TRUST_PRIOR`), from that trust up to ``look.reach`` (held back, on the
    tuned looks, it cost the portraits and still lifes that are trusted fully): where the
    statistics cannot tell, the pairs' trust stands.
    """
    from scipy.stats import multivariate_normal

    if look.reach <= look.trust or len(edits) == 0:
        return look
    naturals = styles_in_space(natural_palettes(), working)
    pick = np.random.default_rng(0).permutation(len(naturals.names))[:EVIDENCE_PALETTES]
    hists = naturals.at_bins(MAP_BINS)[np.sort(pick)]
    own = np.stack([image_histogram(np.asarray(e, np.float64), MAP_BINS) for e in edits])
    scale = space_scale(working)
    noise, _ = content_noise(natural_statistics(naturals), len(edits),
                             cache=default_cache_dir())
    tried = sorted({look.trust, look.reach,
                    *(t for t in FAR_TRUSTS if look.trust < t < look.reach)})
    likelihood = []
    for trust in tried:
        pushed = _pushed_statistics(replace(look, trust=trust), hists)
        styles = tinted_statistics(own, pushed, space_scale=scale)
        likelihood.append(multivariate_normal.logpdf(look_differences(styles, pushed).vector(),
                                                     cov=noise, allow_singular=True))
    trusts = np.linspace(look.trust, look.reach, 41)
    log_post = (np.interp(trusts, tried, likelihood)
                - 0.5 * ((trusts - look.trust) / FAR_TRUST_PRIOR) ** 2)
    return replace(look, trust=float(trusts[np.argmax(log_post)]))
