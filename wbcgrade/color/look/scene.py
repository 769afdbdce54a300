"""Finding the photo's own scene among the style photos, and the colour pairs it gives.

When a style photo shows the same scene as the photo being graded (another
framing of the shot, the next frame of a burst, the hero shot of a
sequence), the look needs no guessing: the two images can be laid over each
other, and every pixel of the overlap is a pair (colour before the look,
colour after it). :class:`~wbcgrade.color.look.LookMap` fitted to such pairs
recovers the look far better than any comparison of palettes, which cannot
tell content from look.

The steps, on images of at most :data:`MATCH_SIZE` pixels a side:

1. SIFT keypoints on the lightness of both images, each smoothed a little,
   stretched between its 1st and 99th percentiles and equalised tile by tile
   (a dark, a flat or a lifted-black frame keeps its keypoints; gradient
   orientations survive a change of tone and colour);
2. descriptor matches kept by the ratio test, then a homography fitted with
   RANSAC; a match counts when enough keypoints agree (:data:`MIN_INLIERS`;
   photos of other scenes give a handful by chance) and the homography is a
   plausible change of framing (no mirror image, scale within a factor 4);
3. the same with the photo mirrored (a framing flipped left to right): per
   style, the framing more keypoints agree on;
4. the style image warped onto the photo's frame; pixels of the overlap
   (away from its border, down-weighted on edges where a small misalignment
   mixes colours) give the pairs.

Feature detection uses OpenCV; the matches are OpenCV's brute-force ones, computed
with one BLAS product (:func:`nearest_two`).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbcgrade.color.colorspace import (
    SYCC_LUMA,
    ColorEncoding,
    default_working_space,
    resolve_space,
)
from wbcgrade.color.io.cache import cache_folder, entry_path, file_key, read_entry, write_entry
from wbcgrade.color.io.images import read_image
from wbcgrade.color.io.raw import is_raw
from wbcgrade.errors import InputError

__all__ = ["SceneImage", "SceneMatch", "scene_image", "match_scene", "mirrored", "unmirror",
           "colour_pairs", "style_scene_images", "keep_style_scenes", "has_style_images",
           "prepare_photo_scene", "forget_photo_scene", "photo_scene_entry",
           "shrink_colors",
           "keep_for_matching", "matching_hook",
           "MATCH_SIZE", "MIN_INLIERS", "SURE_INLIERS"]

#: Long side (pixels) of the images keypoints are found on and pairs are read from.
MATCH_SIZE = 768
#: Keypoints agreeing with one homography for a style to count as the photo's scene,
#: and the count from which the match is sure: far above what two different scenes agree
#: on, far below what two framings of one scene do (docs/benchmarks.md).
MIN_INLIERS = 12
SURE_INLIERS = 24
#: Overlap (share of the photo's pixels) below which a match gives too few pairs.
MIN_COVERAGE = 0.05
#: Most keypoints per image, and the least contrast of one (OpenCV's SIFT
#: ``contrastThreshold``; half its default: hazy, low-contrast scenes keep keypoints).
MAX_FEATURES = 4000
CONTRAST = 0.02
#: Keypoints of the mirrored photo (the check for a flipped framing, made on every photo,
#: so kept to a quarter of the photo's own).
MIRROR_FEATURES = 1000
#: Bumped when what is cached (size, features) changes.
SCENE_VERSION = 3
#: Share of the pixels left at each end when the lightness is stretched for keypoints.
STRETCH = 0.01
#: Gaussian smoothing (pixels at the matching size) of the lightness before it is
#: stretched, and the clip limit and tiles (per side) of its local equalisation
#: (:func:`_stretched_lightness8`): dark and under-exposed framings keep keypoints that
#: agree, and other scenes still never match (docs/benchmarks.md).
SMOOTH = 0.8
LOCAL_CONTRAST = 2.0
LOCAL_TILES = 8


def _cv2():
    try:
        import cv2
    except ImportError as exc:  # pragma: no cover - a dependency
        raise ImportError("finding the photo's scene needs OpenCV "
                          "(pip install opencv-python-headless)") from exc
    return cv2


@dataclass(frozen=True)
class SceneImage:
    """A photo prepared for matching.

    Attributes
    ----------
    colors : (h, w, 3) float32 working-space colours, long side at most
        :data:`MATCH_SIZE`.
    points : (N, 2) float32 keypoint positions (x, y) in ``colors``' pixels.
    descriptors : (N, 128) float32 SIFT descriptors.
    """

    colors: np.ndarray
    points: np.ndarray
    descriptors: np.ndarray


@dataclass(frozen=True)
class SceneMatch:
    """A style photo found to show the photo's scene.

    Attributes
    ----------
    homography : (3, 3) from the style image's pixels to the photo's (both
        at their :class:`SceneImage` size).
    inliers : keypoints that agree with it.
    coverage : share of the photo's pixels the style image covers.
    """

    homography: np.ndarray
    inliers: int
    coverage: float

    @property
    def sureness(self) -> float:
        """0 at :data:`MIN_INLIERS` agreeing keypoints, 1 from :data:`SURE_INLIERS` on."""
        return float(np.clip((self.inliers - MIN_INLIERS) / (SURE_INLIERS - MIN_INLIERS),
                             0.0, 1.0))


def _lightness8(colors: np.ndarray) -> np.ndarray:
    luma = np.asarray(colors, dtype=np.float32) @ np.float32(SYCC_LUMA)
    return np.clip(np.rint(luma * 255.0), 0, 255).astype(np.uint8)


def _stretched_lightness8(colors: np.ndarray) -> np.ndarray:
    """(h, w) uint8: the lightness keypoints are found on. Smoothed by :data:`SMOOTH` pixels
    (an 8-bit dark frame holds a few dozen grey levels: their steps make keypoints that
    match nothing), stretched from its :data:`STRETCH` quantiles to 16 bits, then
    equalised tile by tile (OpenCV's CLAHE, :data:`LOCAL_CONTRAST`), so a dark, a flat or
    a lifted-black frame has the local contrast a keypoint needs."""
    cv2 = _cv2()
    luma = np.asarray(colors, dtype=np.float32) @ np.float32(SYCC_LUMA)
    if SMOOTH > 0:
        luma = cv2.GaussianBlur(luma, (0, 0), SMOOTH)
    low, high = np.quantile(luma[::2, ::2], [STRETCH, 1.0 - STRETCH])
    scale = 65535.0 / max(float(high - low), 1.0 / 255.0)
    wide = np.clip(np.rint((luma - low) * scale), 0, 65535).astype(np.uint16)
    if LOCAL_CONTRAST > 0:
        wide = cv2.createCLAHE(clipLimit=LOCAL_CONTRAST,
                               tileGridSize=(LOCAL_TILES, LOCAL_TILES)).apply(wide)
    return (wide >> 8).astype(np.uint8)


def shrink_colors(colors: np.ndarray, size: int) -> np.ndarray:
    """(H, W, C) colours with their long side at most ``size`` (OpenCV's area average;
    float32; the colours themselves when already that small)."""
    cv2 = _cv2()
    h, w = colors.shape[:2]
    scale = size / max(h, w)
    colors = np.ascontiguousarray(colors[..., :3], dtype=np.float32)
    if scale >= 1.0:
        return colors
    shape = (max(1, round(w * scale)), max(1, round(h * scale)))
    return cv2.resize(colors, shape, interpolation=cv2.INTER_AREA)


def scene_image(colors: np.ndarray, size: int = MATCH_SIZE,
                features: int = MAX_FEATURES) -> SceneImage:
    """Shrink (H, W, 3) working-space colours in [0, 1] and find their keypoints (at most
    ``features``): what :func:`prepare_photo_scene` started for this very array, when it
    did."""
    if size == MATCH_SIZE and features == MAX_FEATURES:
        ahead = _taken_ahead(colors)
        if ahead is not None:
            return ahead
    return _scene_image(colors, size, features)


#: Photos' scene images being prepared on another thread (:func:`prepare_photo_scene`), by
#: the id of the colours they are prepared from (the array kept beside: the same array,
#: not a later one at its address), and the mirrors found with them, by the photo's id.
_AHEAD: dict[int, tuple[np.ndarray, Future]] = {}
_MIRRORS: dict[int, tuple[SceneImage, SceneImage]] = {}
_AHEAD_LOCK = threading.Lock()


def prepare_photo_scene(colors: np.ndarray, entry: Path | None = None) -> None:
    """Start preparing a photo for matching on another thread: :func:`scene_image` of
    ``colors`` (its default size and keypoints) and its :func:`mirrored` copy, so that the
    decoder's next steps (the photo's histograms, the set's look: one core) and the
    keypoints (OpenCV, no interpreter lock) run side by side. ``entry``: where they are
    kept in the cache (:func:`photo_scene_entry`; a photo graded again, at another
    strength or with other styles, finds them there); None: not kept. The grade's own
    calls for this array take them (or what preparing them raised);
    :func:`forget_photo_scene` drops them if it never asks."""
    future: Future = Future()

    def prepare() -> None:
        try:
            found = _read_photo_scene(entry, colors)
            if found is None:
                photo = _scene_image(colors)
                found = (photo, _mirrored(photo))
                _write_photo_scene(entry, *found)
            future.set_result(found)
        except BaseException as exc:  # noqa: BLE001 - raised where the grade asks for it
            future.set_exception(exc)

    with _AHEAD_LOCK:
        _AHEAD[id(colors)] = (colors, future)
    threading.Thread(target=prepare, name="wbcgrade-scene").start()  # (no daemon: ReadAhead)


def photo_scene_entry(path: str | os.PathLike, input_space: str | None,
                      working_space: str) -> Path | None:
    """Where the photo at ``path``, read in ``input_space`` (None: what the file says) and
    encoded into ``working_space``, keeps its keypoints and its mirror's in the command's
    cache (``scenes/``; None when caching is off or the file is gone): keyed by the file as
    it is now and every matching setting, its colours kept as float32 (the photo's own
    pairs are read from them: exactly what preparing them again gives)."""
    folder = cache_folder()
    if folder is None:
        return None
    try:
        key = (f"photo|{file_key(path)}|{input_space or 'file'}|{working_space}|"
               f"{MATCH_SIZE}|{MAX_FEATURES}|{MIRROR_FEATURES}|{CONTRAST}|{SMOOTH}|"
               f"{STRETCH}|{LOCAL_CONTRAST}|{LOCAL_TILES}|{SCENE_VERSION}")
    except OSError:
        return None
    return entry_path(folder, "scenes", key)


def _read_photo_scene(entry: Path | None, colors: np.ndarray
                      ) -> tuple[SceneImage, SceneImage] | None:
    data = read_entry(entry)
    if data is None:
        return None
    try:
        small = np.ascontiguousarray(data["colors"], dtype=np.float32)
        h, w = colors.shape[:2]
        scale = MATCH_SIZE / max(h, w)
        expected = (h, w) if scale >= 1.0 else (max(1, round(h * scale)),
                                                 max(1, round(w * scale)))
        if small.shape != (*expected, 3):  # (another photo at that key: computed again)
            return None
        photo = SceneImage(small, data["points"].astype(np.float32),
                           data["descriptors"].astype(np.float32))
        mirror = SceneImage(np.ascontiguousarray(small[:, ::-1]),
                            data["mirror_points"].astype(np.float32),
                            data["mirror_descriptors"].astype(np.float32))
    except Exception:  # noqa: BLE001 - any damage is a miss: computed again, rewritten
        return None
    return photo, mirror


def _write_photo_scene(entry: Path | None, photo: SceneImage, mirror: SceneImage) -> None:
    """Best effort: a cache that cannot be written is skipped."""
    write_entry(entry, colors=photo.colors, points=photo.points,
                descriptors=photo.descriptors, mirror_points=mirror.points,
                mirror_descriptors=mirror.descriptors)


def forget_photo_scene(colors: np.ndarray) -> None:
    """Drop what :func:`prepare_photo_scene` prepared for ``colors`` and the grade did not
    take (nothing of a graded photo is kept: a batch grades many)."""
    with _AHEAD_LOCK:
        entry = _AHEAD.get(id(colors))
        if entry is not None and entry[0] is colors:
            del _AHEAD[id(colors)]
        _MIRRORS.clear()


def _taken_ahead(colors: np.ndarray) -> SceneImage | None:
    with _AHEAD_LOCK:
        entry = _AHEAD.get(id(colors))
        if entry is None or entry[0] is not colors:
            return None
        del _AHEAD[id(colors)]
    photo, mirror = entry[1].result()
    with _AHEAD_LOCK:
        _MIRRORS.clear()  # (one photo at a time: the one asked for now)
        _MIRRORS[id(photo)] = (photo, mirror)
    return photo


def _scene_image(colors: np.ndarray, size: int = MATCH_SIZE,
                 features: int = MAX_FEATURES) -> SceneImage:
    cv2 = _cv2()
    small = shrink_colors(colors, size)
    sift = cv2.SIFT_create(nfeatures=features, contrastThreshold=CONTRAST)
    keypoints, descriptors = sift.detectAndCompute(_stretched_lightness8(small), None)
    if descriptors is None or not keypoints:
        return SceneImage(small, np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32))
    points = np.float32([k.pt for k in keypoints])
    return SceneImage(small, points, np.asarray(descriptors, dtype=np.float32))


#: Rows of the query descriptors whose distances to every train descriptor are held at once.
_DISTANCE_ROWS = 1024
#: Whole numbers below this have distinct float32 square roots (consecutive roots differ
#: by more than a float32 step there).
_DISTINCT_ROOTS = 2 ** 21


def _nearest_two_roots(query: np.ndarray, train: np.ndarray, train_sq: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_two` of a few whole-number query rows through the float32 distances
    themselves (OpenCV's order where two distances' roots round to one float32)."""
    sq = query @ train.T
    sq *= -2.0
    sq += train_sq[None, :]
    sq += np.einsum("ij,ij->i", query, query)[:, None]
    d = np.sqrt(np.maximum(sq, 0.0, out=sq), out=sq)
    here = np.arange(len(query))
    first = np.argmin(d, axis=1)
    nearest_d = d[here, first]
    d[here, first] = np.inf
    second = np.argmin(d, axis=1)
    return (np.stack([nearest_d, d[here, second]], axis=1),
            np.stack([first, second], axis=1).astype(np.int32))


def nearest_two(query: np.ndarray, train: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each query descriptor's two nearest train descriptors (L2): ((N, 2) float32 distances,
    (N, 2) indices), exactly OpenCV's brute-force ``knnMatch(k=2)`` (``cv2.batchDistance``).

    ``train`` needs two rows or more. SIFT descriptors hold whole numbers in 0..255: then
    every squared distance, computed with one BLAS product (``|q|^2 + |t|^2 - 2 q.t``), is
    an exact float32 whole number below 2^24 whatever the order of the sums, as in OpenCV's
    loop; its float32 square root is OpenCV's distance, and ties go to the lower index
    as OpenCV's insertion does. Other descriptors go to OpenCV itself.
    """
    query = np.ascontiguousarray(query, dtype=np.float32)
    train = np.ascontiguousarray(train, dtype=np.float32)
    whole = all(len(x) and x.min() >= 0 and x.max() <= 255 and np.array_equal(x, np.rint(x))
                for x in (query, train))
    if not whole or query.shape[1] > 128 or len(train) < 2:
        cv2 = _cv2()
        distance, nearest = cv2.batchDistance(query, train, cv2.CV_32F,
                                              normType=cv2.NORM_L2, K=2)
        return distance, nearest
    # one product per block gives |t|^2 - 2 q.t (the squared distance less |q|^2, a
    # constant of the row): every partial sum is a whole number of magnitude under 2^24
    # (|t|^2 <= 128 * 255^2, 2 q.t <= 2 |q| |t|), exact in any order of the sums
    train_sq = np.einsum("ij,ij->i", train, train)
    train_aug = np.empty((train.shape[1] + 1, len(train)), np.float32)
    train_aug[:-1] = train.T
    train_aug[-1] = train_sq
    query_aug = np.empty((len(query), query.shape[1] + 1), np.float32)
    np.multiply(query, np.float32(-2.0), out=query_aug[:, :-1])
    query_aug[:, -1] = 1.0
    query_sq = np.einsum("ij,ij->i", query, query)
    distance = np.empty((len(query), 2), np.float32)
    nearest = np.empty((len(query), 2), np.int32)
    rows = np.arange(min(len(query), _DISTANCE_ROWS))
    for lo in range(0, len(query), _DISTANCE_ROWS):
        hi = min(lo + _DISTANCE_ROWS, len(query))
        partial = query_aug[lo:hi] @ train_aug
        here = rows[: hi - lo]
        first = np.argmin(partial, axis=1)  # the lowest index among equal distances
        nearest_sq = partial[here, first] + query_sq[lo:hi]
        partial[here, first] = np.inf
        second = np.argmin(partial, axis=1)
        second_sq = partial[here, second] + query_sq[lo:hi]
        distance[lo:hi, 0] = np.sqrt(nearest_sq)
        distance[lo:hi, 1] = np.sqrt(second_sq)
        nearest[lo:hi, 0], nearest[lo:hi, 1] = first, second
        # the float32 square roots of whole numbers under 2^21 are all distinct, so the
        # order of squared distances is that of OpenCV's distances, ties included; rows
        # whose two nearest lie further go through the distances themselves
        far = np.flatnonzero(second_sq >= _DISTINCT_ROOTS)
        if len(far):
            distance[lo + far], nearest[lo + far] = _nearest_two_roots(
                query[lo + far], train, train_sq)
    return distance, nearest


def match_scene(photo: SceneImage, style: SceneImage, ratio: float = 0.75,
                why: list[str] | None = None) -> SceneMatch | None:
    """The framing that lays ``style`` over ``photo``, or None when it shows another scene
    (``why``, when given, gets the reason in words)."""
    cv2 = _cv2()

    def no(reason: str) -> None:
        if why is not None:
            why.append(reason)

    if len(photo.points) < MIN_INLIERS or len(style.points) < MIN_INLIERS:
        return no(f"too little texture: {min(len(photo.points), len(style.points))} "
                  f"keypoints, {MIN_INLIERS} needed")
    distance, nearest = nearest_two(photo.descriptors, style.descriptors)
    good = np.flatnonzero(distance[:, 0].astype(np.float64)
                          < ratio * distance[:, 1].astype(np.float64))
    if len(good) < MIN_INLIERS:
        return no(f"{len(good)} keypoints in common, {MIN_INLIERS} needed")
    src = style.points[nearest[good, 0]]
    dst = photo.points[good]
    homography, mask = cv2.findHomography(src, dst, cv2.RANSAC, 3.0)
    if homography is None or mask is None:
        return no(f"{len(good)} keypoints in common but no framing fits them")
    inliers = int(mask.sum())
    if inliers < MIN_INLIERS:
        return no(f"{inliers} keypoints agree on a framing, {MIN_INLIERS} needed")
    if not _plausible(homography):
        return no("the keypoints agree only on an implausible framing (mirrored, scaled by "
                  "over 4 or in strong perspective)")
    coverage = float(_overlap_mask(photo, style, homography, erode=0).mean())
    if coverage < MIN_COVERAGE:
        return no(f"the framings overlap on {coverage:.0%} of the photo, "
                  f"{MIN_COVERAGE:.0%} needed")
    return SceneMatch(homography, inliers, coverage)


def mirrored(photo: SceneImage) -> SceneImage:
    """The photo flipped left to right, with its own keypoints (the strongest
    :data:`MIRROR_FEATURES`: a flipped framing shares hundreds; for :func:`unmirror`);
    the one :func:`prepare_photo_scene` found beside ``photo``, when it did."""
    with _AHEAD_LOCK:
        entry = _MIRRORS.pop(id(photo), None)
    if entry is not None and entry[0] is photo:
        return entry[1]
    return _mirrored(photo)


def _mirrored(photo: SceneImage) -> SceneImage:
    return _scene_image(photo.colors[:, ::-1], size=max(photo.colors.shape[:2]),
                        features=MIRROR_FEATURES)


def unmirror(match: SceneMatch, width: int) -> SceneMatch:
    """A match on the :func:`mirrored` photo (``width`` pixels wide) as a match on the
    photo itself: its homography followed by the flip."""
    flip = np.array([[-1.0, 0.0, width - 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    return SceneMatch(flip @ match.homography, match.inliers, match.coverage)


def _plausible(homography: np.ndarray) -> bool:
    """A change of framing: no mirror image, scale within a factor 4, mild perspective."""
    h = homography / homography[2, 2] if homography[2, 2] != 0 else homography
    det = float(np.linalg.det(h[:2, :2]))
    return bool(np.isfinite(h).all() and 1 / 16 < det < 16
                and np.abs(h[2, :2]).max() < 2e-3)


def _overlap_mask(photo: SceneImage, style: SceneImage, homography: np.ndarray,
                  erode: int) -> np.ndarray:
    cv2 = _cv2()
    h, w = photo.colors.shape[:2]
    ones = np.ones(style.colors.shape[:2], np.uint8)
    mask = cv2.warpPerspective(ones, homography, (w, h), flags=cv2.INTER_NEAREST)
    if erode:
        mask = cv2.erode(mask, np.ones((2 * erode + 1,) * 2, np.uint8))
    return mask.astype(bool)


def colour_pairs(photo: SceneImage, style: SceneImage, match: SceneMatch,
                 max_pairs: int = 100_000, seed: int = 0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Colour pairs of the overlap: the photo's colour and the style's at the same place.

    Returns (sources (N, 3), targets (N, 3), weights (N,)); pixels on strong
    edges weigh less (a fraction of a pixel of misalignment mixes two colours
    there), and at most ``max_pairs`` pixels are drawn.
    """
    cv2 = _cv2()
    h, w = photo.colors.shape[:2]
    warped = cv2.warpPerspective(style.colors, match.homography, (w, h),
                                 flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    mask = _overlap_mask(photo, style, match.homography, erode=3)
    light = _lightness8(photo.colors).astype(np.float32) / 255.0
    edges = np.hypot(cv2.Sobel(light, cv2.CV_32F, 1, 0), cv2.Sobel(light, cv2.CV_32F, 0, 1))
    weights = 1.0 / (1.0 + 4.0 * edges)
    where = np.flatnonzero(mask.ravel())
    if len(where) > max_pairs:
        where = np.sort(np.random.default_rng(seed).choice(where, max_pairs, replace=False))
    return (photo.colors.reshape(-1, 3)[where].astype(np.float64),
            np.clip(warped.reshape(-1, 3)[where], 0.0, 1.0).astype(np.float64),
            weights.ravel()[where].astype(np.float64))


# ------------------------------------------------------------------------ style images


def _scene_key(path: Path, working_space: str) -> str | None:
    """What names a style photo prepared for matching: the file as it is now, the working
    space and the matching settings (None when the file is gone)."""
    try:
        return (f"{file_key(path)}|{working_space}|{MATCH_SIZE}|{MAX_FEATURES}|{CONTRAST}|"
                f"{SCENE_VERSION}")
    except OSError:
        return None


def _read_cached(path: Path | None) -> SceneImage | None:
    data = read_entry(path)
    try:
        return SceneImage(data["colors"].astype(np.float32),
                          data["points"].astype(np.float32),
                          data["descriptors"].astype(np.float32))
    except Exception:  # noqa: BLE001 - any damage is a miss: computed again, rewritten
        return None


def _write_cached(path: Path | None, image: SceneImage) -> None:
    """Best effort: a cache that cannot be written is skipped."""
    write_entry(path, colors=image.colors.astype(np.float16), points=image.points,
                descriptors=image.descriptors.astype(np.float16))


def _read_style(path: Path, working_space: str) -> SceneImage:
    """A style photo from its file, in the working space, prepared for matching."""

    image = read_image(path)
    encoding = ColorEncoding.for_image(image, None, working_space)
    encoded, _ = encoding.encode(image.rgb(), image.is_float)
    return scene_image(encoded)


#: Style images already prepared in this process, by :func:`_scene_key`: a batch grades
#: many photos towards them, and a folder's photos read for their histograms are prepared
#: from that one decode (:func:`keep_for_matching`). Threads read a folder: one lock.
_IN_MEMORY: dict[str, SceneImage] = {}
_IN_MEMORY_MAX = 64
_IN_MEMORY_LOCK = threading.Lock()


def _remembered(key: str | None) -> SceneImage | None:
    if key is None:
        return None
    with _IN_MEMORY_LOCK:
        return _IN_MEMORY.get(key)


def _remember(key: str, image: SceneImage) -> None:
    with _IN_MEMORY_LOCK:
        if key not in _IN_MEMORY and len(_IN_MEMORY) >= _IN_MEMORY_MAX:
            _IN_MEMORY.pop(next(iter(_IN_MEMORY)), None)
        _IN_MEMORY[key] = image


def _as_stored(image: SceneImage) -> SceneImage:
    """``image`` as its cache entry keeps it (colours and descriptors in float16), so a
    style prepared now and one read back from the cache later give the same grade."""
    return SceneImage(image.colors.astype(np.float16).astype(np.float32), image.points,
                      image.descriptors.astype(np.float16).astype(np.float32))


def _prepared(path: Path, working_space: str, key: str, where: Path | None,
              colors: np.ndarray | None = None) -> SceneImage | None:
    """The style photo at ``path`` prepared for matching in ``working_space`` (``key``:
    :func:`_scene_key`): from this process, the cache entry ``where``, else from ``colors``
    (its working-space colours) or its file (then written to ``where``); None when its file
    cannot be read any more."""
    found = _remembered(key) or _read_cached(where)
    if found is None:
        try:
            found = _as_stored(scene_image(colors) if colors is not None
                               else _read_style(path, working_space))
        except (InputError, OSError, ValueError):  # gone or changed since: no scene
            return None
        _write_cached(where, found)
    _remember(key, found)
    return found


def keep_for_matching(working_space: str, cache_dir: str | os.PathLike | None
                      ) -> Callable[[Path, np.ndarray], None]:
    """A ``load_styles(on_image=...)`` callback: each style photo read for its histogram
    ((H, W, 3) working-space colours) is prepared for matching from that same decode, kept
    in this process and in ``scenes/`` of ``cache_dir`` (None: nowhere on disk), so that
    :func:`style_scene_images` does not decode it again (a 16-megapixel JPEG: 0.3 s)."""
    folder = None if cache_dir is None else Path(cache_dir)

    def keep(path: Path, colors: np.ndarray) -> None:
        key = _scene_key(Path(path), working_space)
        if key is not None:  # (one prepared already, in memory or on disk, is kept as it is)
            _prepared(Path(path), working_space, key, entry_path(folder, "scenes", key),
                      colors)

    return keep


def matching_hook(source, options, photos: Sequence[str | os.PathLike] = ()
                  ) -> Callable[[Path, np.ndarray], None] | None:
    """:func:`keep_for_matching` for a command loading ``source`` (a StyleSource) to grade
    ``photos`` one by one, each towards the style photo showing its scene (``options``,
    GradeOptions: look mode, no fixed weights); else None (nothing to prepare): a preset,
    a palette grade, no folder of at most ``_IN_MEMORY_MAX`` photos, or photos all graded
    in another working space than the styles are read in (raw files, without
    ``spaces.working``: ACEScct)."""

    if (source.style_dir is None or options.map.builder != "look"
            or options.fit.weights is not None):
        return None
    try:
        if sum(1 for p in Path(source.style_dir).iterdir() if p.is_file()) > _IN_MEMORY_MAX:
            return None  # (kept in memory first-in first-out, a bigger folder would miss)
    except OSError:
        return None
    working = options.spaces.working
    if working is None and photos and all(is_raw(photo) for photo in photos):
        return None
    working = resolve_space(working) if working else default_working_space()
    cache = source.cache
    return keep_for_matching(working, cache.folder if cache is not None and cache.enabled
                             else None)


def has_style_images(styles) -> bool:
    """Whether a StyleSet names its photos' files or carries their images (a folder's
    does, a preset's does not): whether :func:`style_scene_images` has anything to match."""
    return bool(styles.images or styles.files)


def style_scene_images(styles, progress: Callable[[int, int], None] | None = None,
                       cache: bool = True) -> list[SceneImage | None]:
    """The style photos prepared for matching, one per style (None where there is none).

    A :class:`~wbcgrade.color.presets.StyleSet` loaded from a folder names its
    files (``styles.files``); one built from arrays may carry the images
    themselves (``styles.images``: (H, W, 3) working-space colours); a preset
    holds palettes only (all None). Images read from files are kept in ``scenes/``
    in the styles' cache folder (:func:`wbcgrade.color.io.cache.cache_folder`, beside
    the histograms), keyed by the file and the working space.
    """
    with _AHEAD_LOCK:  # (the style photos being prepared ahead: waited for, then found)
        ahead, _STYLES_AHEAD[:] = list(_STYLES_AHEAD), []
    for thread in ahead:
        thread.join()
    return _style_scene_images(styles, progress, cache)


def _style_scene_images(styles, progress: Callable[[int, int], None] | None = None,
                        cache: bool = True) -> list[SceneImage | None]:
    images: Sequence = styles.images
    files: Sequence = styles.files
    out: list[SceneImage | None] = []
    n = len(styles.names)
    for i in range(n):
        found = None
        if i < len(images) and images[i] is not None:
            found = scene_image(np.asarray(images[i], dtype=np.float32))
        elif i < len(files) and files[i]:
            path = Path(files[i])
            key = _scene_key(path, styles.working_space)
            if key is not None:
                found = _prepared(path, styles.working_space, key, entry_path(
                    cache_folder(styles) if cache else None, "scenes", key))
        out.append(found)
        if progress is not None:
            progress(i + 1, n)
    return out


def keep_style_scenes(styles) -> bool:
    """Start preparing the style photos of a StyleSet for matching on another thread
    (:func:`style_scene_images`, kept in this process: read from the cache, which holds
    no interpreter lock for most of its time, while the photo's histograms and the set's
    look are found; the grade's own call waits for it and finds them there), when it names
    their files (images given as arrays are not kept: nothing to gain) and no more than
    this process keeps; whether it started. Best effort: what it could not prepare, the
    grade prepares (and reports)."""
    if (not styles.files or any(image is not None for image in styles.images)
            or len(styles.names) > _IN_MEMORY_MAX):
        return False

    def keep() -> None:
        try:
            _style_scene_images(styles)
        except Exception:  # noqa: BLE001, S110 - the grade prepares (and reports) them again
            pass

    thread = threading.Thread(target=keep, name="wbcgrade-styles")
    with _AHEAD_LOCK:
        _STYLES_AHEAD.append(thread)
    thread.start()
    return True


#: The threads :func:`keep_style_scenes` started that no grade has waited for yet.
_STYLES_AHEAD: list[threading.Thread] = []
