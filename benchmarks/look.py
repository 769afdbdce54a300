"""Look benchmark: does a grade reproduce a known look? (ground truth, CIEDE2000)

Run ``python benchmarks/look.py`` (``--quick`` for a short run, ``--help``).
A look L (``benchmarks/_looks.py``: two ACES LMTs shipped in colour-clf-io and
applied with OpenColorIO, and looks defined there; ``--looks held-out`` runs
the looks no default was chosen on instead) is applied to some photos:
that is the style set. Other photos are graded towards it; the ground truth
of each is L(photo). Two protocols:

- ``shot`` (shot matching): each scene is cut into two overlapping framings,
  the left and the right 62 % of its width; the style set is the looked
  LEFT framings of N scenes, the RIGHT framings of the same N scenes are
  graded (truth: the looked right framing);
- ``cross`` (cross-content): the style set is N looked photos, N other
  photos are graded.

Each look gets its own partition of the photos (a fixed shuffled order,
rotated by 4 places a look, so that across the looks every photo is graded);
a look's partition does not depend on which looks or methods are run. A
graded photo is never in a set a method learns from: methods get the style
images and ``context.natural``, the names of the photos that are neither
graded in the case nor the source of a style photo (ungraded palettes a
method may learn from; ``context.load(name)`` reads one).

Scores (all images 8-bit: photos, looks and outputs are quantised):

- dE: mean CIEDE2000 over pixels between output and truth (sRGB -> XYZ ->
  CIE Lab, D65; colour-science); dE0: the same for the ungraded photo;
- recovered = 1 - dE / dE0 per photo: 1 = the look reproduced, 0 = no better
  than doing nothing, < 0 = worse than doing nothing; the table gives the
  mean over photos and the worst photo;
- grad r and noise, as in ``benchmarks/quality.py`` (input vs output):
  Sobel-gradient correlation of luma, mean (worst); high-pass luma noise in
  the input's flattest 30 %, output over input, geometric mean (worst). The
  ``(truth)`` row gives the look's own values (a contrasty look raises noise);
- same scene on top (shot matching, methods that report weights): how often
  the largest weight is on the graded photo's own scene.

Methods: ``METHODS`` maps a name to ``method(photo, styles, context) ->
image``; a method may put ``{"weights": {style name: weight}}`` into
``context.info``. All calls into wbcgrade go through :func:`wbcgrade_grade`.
``--method-file FILE.py`` adds the methods of that file's own ``METHODS``
dict (it may ``from look import Context, wbcgrade_grade``).

Writes in ``--out``: ``results.json`` (settings, the looks and where they
come from, every number of every photo), ``sheet_<protocol>.png`` (a row per
graded photo: photo, truth, each method; labels name the look, the photo,
the method and its recovered score; column order also in ``.txt``) and
``crops_<protocol>.png`` (2x nearest-neighbour crops of the photo's
flattest well-exposed area and, where one is found, of skin or sky).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.modules.setdefault("look", sys.modules[__name__])  # method files: ``from look import ...``

from _looks import (  # noqa: E402
    FILM_HELD_OUT_LOOKS,
    FILM_LOOKS,
    FILM_TUNED_LOOKS,
    HELD_OUT_LOOKS,
    LOOKS,
    MONOCHROME_LOOKS,
    PHOTOGRAPHER_LOOKS,
    TUNED_LOOKS,
)
from quality import (  # noqa: E402
    gradient_correlation,
    luma,
    nearest_style,
    noise_ratio,
    peer_idt_regrain,
    peer_mkl,
    sample_pixels,
    smooth_crop,
    sobel_magnitude,
    thumbnail,
    to_8bit,
    write_png,
)

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_PHOTOS = ROOT.parent / "shared" / "data" / "photos"
EXCLUDED = {"seeding_full"}  # the full-size original of seeding.jpg
SHUFFLE_SEED = 19
ROTATION = 4  # places the shuffled order turns from one look to the next
FRAMING = 0.62  # share of the width in each framing (shot matching)
PROTOCOLS = {"shot": "shot matching", "cross": "cross-content"}
#: Photos with people's faces (reported apart: skin is where a grade is judged first).
FACES = {"astronaut", "grace_hopper"}


# --------------------------------------------------------------------------- photos


def read_photo(path: Path, size: int) -> np.ndarray:
    """(H, W, 3) float64 sRGB in [0, 1], long side at most ``size`` (never enlarged), 8-bit."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    spec = buf.spec()
    if buf.has_error or spec.nchannels < 3:
        raise SystemExit(f"cannot read {path}: {buf.geterror()}")
    scale = size / max(spec.width, spec.height)
    if scale < 1:
        roi = oiio.ROI(0, max(1, round(spec.width * scale)), 0,
                       max(1, round(spec.height * scale)), 0, 1, 0, 3)
        buf = oiio.ImageBufAlgo.resize(buf, roi=roi)
    return to_8bit(buf.get_pixels(oiio.FLOAT)[..., :3].astype(np.float64))


def framings(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The left and the right ``FRAMING`` of the width."""
    w = img.shape[1]
    cut = round(w * FRAMING)
    return img[:, :cut], img[:, w - cut:]


class Photos:
    """Downscaled 8-bit photos and their looked versions, cached in memory and in ``cache_dir``.

    Looked images are cached on disk keyed by the photo file (size, mtime),
    the size and a hash of ``_looks.py`` (editing a look invalidates them).
    """

    def __init__(self, folder: Path, size: int, cache_dir: Path | None):
        self.folder, self.size, self.cache_dir = folder, size, cache_dir
        self._mem: dict = {}
        looks_code = (Path(__file__).resolve().parent / "_looks.py").read_bytes()
        self._looks_hash = hashlib.sha1(looks_code).hexdigest()[:12]

    def names(self) -> list[str]:
        names = sorted(p.stem for p in self.folder.glob("*.jpg") if p.stem not in EXCLUDED)
        if not names:
            raise SystemExit(f"no photos in {self.folder}")
        return names

    def photo(self, name: str) -> np.ndarray:
        if name not in self._mem:
            self._mem[name] = read_photo(self.folder / f"{name}.jpg", self.size)
        return self._mem[name]

    def looked(self, look: str, name: str) -> np.ndarray:
        key = (look, name)
        if key in self._mem:
            return self._mem[key]
        stat = (self.folder / f"{name}.jpg").stat()
        tag = hashlib.sha1(f"{name}|{stat.st_size}|{stat.st_mtime_ns}|{self.size}|{look}|"
                           f"{self._looks_hash}".encode()).hexdigest()[:16]
        path = self.cache_dir / "looked" / f"{look}-{name}-{tag}.npy" if self.cache_dir else None
        if path is not None and path.is_file():
            img = np.load(path).astype(np.float64) / 255.0
        else:
            img = to_8bit(LOOKS[look].apply(self.photo(name)))
            if path is not None:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
                np.save(tmp, np.round(img * 255).astype(np.uint8))
                os.replace(tmp, path)
        self._mem[key] = img
        return img


# --------------------------------------------------------------------------- cases


@dataclass
class Case:
    """One look under one protocol: which photos make the style set, which are graded."""

    protocol: str
    look: str
    style_sources: list[str]
    graded: list[str]
    natural: list[str]
    batch: list[str] = field(default_factory=list)


def make_cases(names: list[str], looks: list[str], protocols: list[str], n: int,
               graded: int | None = None, n_styles: int | None = None) -> list[Case]:
    """Deterministic partitions: look k uses the shuffled order turned by k * ROTATION.

    cross: styles = the first ``n_styles`` (default n), graded = the next n;
    shot: the last n scenes are both (left framings styled, right framings
    graded). ``graded`` < n grades only the first few of a case's graded
    photos (the partition, and so the natural list, stays that of the full run).
    """
    n_styles = n if n_styles is None else n_styles
    need = n_styles + n if "cross" in protocols else 2 * n
    if len(names) < need:
        raise SystemExit(f"--styles {n_styles} --photos {n} needs {need} photos, "
                         f"{len(names)} found")
    order = [names[i] for i in np.random.default_rng(SHUFFLE_SEED).permutation(len(names))]
    all_looks = list(LOOKS)
    cases = []
    for look in looks:
        turn = (all_looks.index(look) * ROTATION) % len(order)
        ring = order[turn:] + order[:turn]
        for protocol in protocols:
            if protocol == "cross":
                styles, graded_all = ring[:n_styles], ring[n_styles:n_styles + n]
            else:
                styles = graded_all = ring[-n:]
            held = set(styles) | set(graded_all)
            cases.append(Case(protocol, look, list(styles), list(graded_all[:graded or n]),
                              [p for p in names if p not in held], list(graded_all)))
    return cases


# --------------------------------------------------------------------------- scores


def lab(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) sRGB in [0, 1] -> CIE Lab (D65)."""
    import colour

    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(rgb, illuminant=d65), d65)


def delta_e(lab_a: np.ndarray, lab_b: np.ndarray) -> float:
    """Mean CIEDE2000 between two Lab images."""
    import colour

    return float(np.mean(colour.delta_E(lab_a, lab_b, method="CIE 2000")))


# --------------------------------------------------------------------------- wbcgrade


def wbcgrade_grade(photo: np.ndarray, styles: list[np.ndarray], style_names: list[str],
                   memo: dict | None = None, **options) -> tuple[np.ndarray, dict[str, float]]:
    """Grade ``photo`` towards ``styles`` with wbcgrade; the benchmark's only call into it.

    ``options``: grade settings by their flat names
    (:data:`wbcgrade.color.options.FLAT_FIELDS`, e.g. ``relaxation=0.05``;
    or whole groups, ``map=MapOptions(...)``). The style set is built from
    the arrays (one histogram per style image on the transfer grid, as
    ``load_style_folder`` builds it from files), once per ``memo`` (the
    case's memo: the same styles for all its photos).

    Returns (graded (H, W, 3) float in [0, 1], {style name: weight}).
    """
    from wbcgrade.color.colorspace import default_working_space
    from wbcgrade.color.grade.grading import grade_array
    from wbcgrade.color.histogram import image_histogram
    from wbcgrade.color.options import GradeOptions
    from wbcgrade.color.presets import StyleSet

    opts = GradeOptions(**options)
    bins, max_pixels = opts.transfer.bins, opts.transfer.max_pixels
    memo = {} if memo is None else memo
    key = ("wbcgrade-styles", tuple(style_names), bins, max_pixels)
    if key not in memo:
        hists = np.stack([image_histogram(np.asarray(s, np.float32), bins, None, max_pixels)
                          for s in styles])
        memo[key] = StyleSet(names=list(style_names), histograms=hists, source="look benchmark",
                             meta={"working_space": default_working_space(),
                                   "images": [np.asarray(s, np.float32) for s in styles]})
    graded, grade = grade_array(np.asarray(photo, np.float32), memo[key], opts)
    return np.clip(graded, 0.0, 1.0), dict(zip(grade.names, map(float, grade.weights)))


# --------------------------------------------------------------------------- methods


@dataclass
class Context:
    """What a method may know about the case besides the photo and the style images.

    style_names : names of the style images (scene names; in shot matching
        the left framing of that scene).
    natural : photos a method may learn from as ungraded palettes (neither
        graded in this case nor the source of a style image).
    batch : the photos graded in this case, all of them (``--graded`` grades the
        first few): what ``batch`` gets as one folder (ungraded, as they come).
    cache_dir : a folder for a method's own caches (shared across runs).
    memo : a dict shared by all photos and methods of the case (in memory).
    info : a method puts what it wants recorded here, e.g. ``"weights"``:
        {style name: weight} (gives "same scene on top").
    """

    protocol: str
    look: str
    photo_name: str
    style_names: list[str]
    natural: list[str]
    cache_dir: Path
    memo: dict
    info: dict = field(default_factory=dict)
    batch: list[str] = field(default_factory=list)
    _photos: Photos | None = field(default=None, repr=False)

    def load(self, name: str) -> np.ndarray:
        """A natural photo, ungraded, at the benchmark's size."""
        if name not in self.natural:
            raise ValueError(f"{name} is not a natural photo of this case")
        return self._photos.photo(name)

    def before(self, index: int) -> np.ndarray:
        """The ungraded original of style image ``index``: for the paired ceiling only (no
        user has it; a method graded on it is a bound, not a method)."""
        photo = self._photos.photo(self.style_names[index])
        return framings(photo)[0] if self.protocol == "shot" else photo


Method = Callable[[np.ndarray, list, Context], np.ndarray]


def nothing(photo: np.ndarray, styles: list[np.ndarray], context: Context) -> np.ndarray:
    return photo


#: A preset of natural palettes that replaces the shipped one (``--natural``): palettes of
#: photos other than the benchmark's, so nothing needs holding out.
NATURAL_FILE: str | None = None
#: How the scenes of shot matching are shot (``--framing``): "plain", "dark" (the whole
#: scene 2.5 stops under: 0.18 x its encoded values, then the look; both framings) or
#: "flipped" (the graded framing flipped left to right).
GRADED_FRAMING = "plain"


def natural_preset(context: Context) -> str:
    """A preset file of the shipped natural palettes this case may learn from
    (``--natural``'s file instead, when given).

    The shipped palettes (``wbcgrade/color/data/natural.npz``) come from photos
    other than the benchmark's; should one of the benchmark's photos be among
    them, it is left out (held out) unless the case allows it, so a look is
    never learnt from the case's graded photos or the sources of its style images.
    """
    from wbcgrade.color.look import natural_palettes
    from wbcgrade.color.presets import save_preset

    if NATURAL_FILE is not None:
        return NATURAL_FILE
    allowed = sorted(context.natural)
    key = ("natural", tuple(allowed))
    if key not in context.memo:
        shipped = natural_palettes()
        photos = context._photos
        benchmark = set(photos.names()) if photos is not None else set(shipped.names)
        held_out = (set(shipped.names) & benchmark) - set(allowed)
        digest = hashlib.sha1(",".join(allowed).encode()).hexdigest()[:16]
        path = Path(context.cache_dir) / f"natural-{digest}.npz"
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            save_preset(path, natural_palettes(exclude=held_out), overwrite=True)
        context.memo[key] = str(path)
    return context.memo[key]


def wbcgrade_method(**options) -> Method:
    """A method grading with wbcgrade with these grade settings (flat names or groups; look
    mode: held-out naturals)."""

    def method(photo: np.ndarray, styles: list[np.ndarray], context: Context) -> np.ndarray:
        from wbcgrade.color.options import GradeOptions

        look = GradeOptions(**options).map.builder == "look"  # (the default)
        extra = {"natural": natural_preset(context)} if look else {}
        out, weights = wbcgrade_grade(photo, styles, context.style_names, context.memo,
                                      **options, **extra)
        context.info["weights"] = weights
        return out

    return method


def batch_route(photo: np.ndarray, styles: list[np.ndarray], context: Context) -> np.ndarray:
    """``batch FOLDER --style DIR --natural FOLDER``: the default grade with the batch's
    own photos (the case's graded photos, ungraded, as one folder) as the evidence of what
    content looks like in this collection, beside the shipped palettes. Measured against
    the default (film looks, cross-content, 384 px, 3 graded of 8 a look): +0.30 (worst
    -0.01) against +0.26 (-0.00). Not the default: the batch's photos and the style photos
    of a case are of one suite here, and random ungraded style sets against random own
    sets got looks of up to 24-46/255 (the halves of a set share the own set, so its
    sampling error passes their check)."""
    photos = context._photos
    images = {name: (framings(photos.photo(name))[1] if context.protocol == "shot"
                     else photos.photo(name)) for name in context.batch}
    return _graded_with_own_photos(photo, styles, context, "batch", images)


def _graded_with_own_photos(photo: np.ndarray, styles: list[np.ndarray], context: Context,
                            kind: str, images: dict[str, np.ndarray]) -> np.ndarray:
    """The default grade with ``images`` ({file stem: image}) as the user's own ungraded
    photos (``--natural FOLDER``): written once as PNG files into a folder of the cache,
    named by ``kind``, the protocol, the photo size and the stems."""
    key = (f"{kind}-folder",)
    if key not in context.memo:
        from PIL import Image

        digest = hashlib.sha1(",".join([context.protocol, str(context._photos.size),
                                        *images]).encode())
        folder = Path(context.cache_dir) / f"{kind}-{digest.hexdigest()[:16]}"
        if not folder.is_dir():
            staging = Path(f"{folder}.{os.getpid()}")
            staging.mkdir(parents=True, exist_ok=True)
            for name, img in images.items():
                Image.fromarray(np.rint(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(
                    staging / f"{name}.png")
            os.replace(staging, folder)
        context.memo[key] = str(folder)
    out, weights = wbcgrade_grade(photo, styles, context.style_names, context.memo,
                                  natural=context.memo[key])
    context.info["weights"] = weights
    return out


def known_content(photo: np.ndarray, styles: list[np.ndarray], context: Context) -> np.ndarray:
    """A bound, not a method: the default grade given the style photos' own UNGRADED
    originals as the user's own photos (``--natural FOLDER``), which no user has: the best
    any content model can tell it (the same photos before the look: no collection bias,
    no sampling difference). What it still misses, a better content model cannot add."""
    images = {f"{i:02d}-{name}": context.before(i)
              for i, name in enumerate(context.style_names)}
    return _graded_with_own_photos(photo, styles, context, "originals", images)


def extract_route(photo: np.ndarray, styles: list[np.ndarray], context: Context) -> np.ndarray:
    """The fit-once route: ``look extract`` (the set's look as a LUT, once per set), then
    ``apply --look`` (that LUT applied in full, with the default regrain)."""
    from wbcgrade.color.grade.grading import grade_array
    from wbcgrade.color.look import set_look_map
    from wbcgrade.color.presets import StyleSet, load_preset

    key = ("extracted-look",)
    if key not in context.memo:
        from wbcgrade.color.colorspace import default_working_space
        from wbcgrade.color.histogram import image_histogram

        hists = np.stack([image_histogram(np.asarray(s, np.float32), 64, None, 1 << 20)
                          for s in styles])
        style_set = StyleSet(names=list(context.style_names), histograms=hists,
                             source="look benchmark",
                             meta={"working_space": default_working_space(),
                                   "images": [np.asarray(s, np.float32) for s in styles]})
        lattice, _ = set_look_map(style_set, load_preset(natural_preset(context)))
        context.memo[key] = StyleSet(names=["look"], histograms=hists[:1], source="look",
                                     meta={"working_space": default_working_space(),
                                           "look": lattice})
    graded, _ = grade_array(np.asarray(photo, np.float32), context.memo[key])
    return np.clip(graded, 0.0, 1.0)


def _cubic_features(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) -> (N, 20): the monomials of R, G, B up to degree 3."""
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    one = np.ones_like(r)
    cols = [one, r, g, b, r * r, g * g, b * b, r * g, r * b, g * b,
            r ** 3, g ** 3, b ** 3, r * r * g, r * r * b, g * g * r, g * g * b, b * b * r,
            b * b * g, r * g * b]
    return np.stack(cols, axis=1)


def paired_ceiling(photo: np.ndarray, styles: list[np.ndarray], context: Context) -> np.ndarray:
    """A ceiling, not a method: a cubic polynomial of R, G, B fitted (least squares) on the
    style images and their UNGRADED originals, which no user has, applied to the photo."""
    key = ("paired-ceiling",)
    if key not in context.memo:
        before = np.concatenate([sample_pixels(context.before(i), 40_000, seed=i)
                                 for i in range(len(styles))])
        after = np.concatenate([sample_pixels(s, 40_000, seed=i)
                                for i, s in enumerate(styles)])
        features = _cubic_features(before.reshape(-1, 3))
        context.memo[key] = np.linalg.lstsq(features, after.reshape(-1, 3), rcond=None)[0]
    flat = photo.reshape(-1, 3)
    return np.clip(_cubic_features(flat) @ context.memo[key], 0.0, 1.0).reshape(photo.shape)


def nearest_reference(photo: np.ndarray, styles: list[np.ndarray], context: Context):
    """The style image nearest to the photo (sliced Wasserstein; quality.py), as one-hot weights."""
    key = ("nearest", context.photo_name)
    if key not in context.memo:  # shared by the peers towards the nearest style
        context.memo[key] = nearest_style(photo, styles)
    best = context.memo[key]
    context.info["weights"] = {n: float(i == best) for i, n in enumerate(context.style_names)}
    return styles[best]


def pooled_reference(styles: list[np.ndarray], context: Context, per_style: int = 50_000):
    """All style images' pixels, the same number from each, as one (n, 1, 3) image."""
    key = ("pooled", per_style)
    if key not in context.memo:
        pixels = [sample_pixels(s, per_style, seed=i) for i, s in enumerate(styles)]
        context.memo[key] = np.concatenate(pixels)[:, None, :]
    return context.memo[key]


def mkl_nearest(photo, styles, context):
    return peer_mkl(photo, nearest_reference(photo, styles, context))


def mkl_pooled(photo, styles, context):
    return peer_mkl(photo, pooled_reference(styles, context))


def idt_nearest(photo, styles, context):
    return peer_idt_regrain(photo, nearest_reference(photo, styles, context))


def idt_pooled(photo, styles, context):
    return peer_idt_regrain(photo, pooled_reference(styles, context))


METHODS: dict[str, Method] = {
    "nothing": nothing,
    "wbcgrade": wbcgrade_method(),  # the defaults: the look grade
    "wbcgrade-extract": extract_route,
    "wbcgrade-batch": batch_route,
    "ceiling": paired_ceiling,
    "known-content": known_content,
    "wbcgrade-palette": wbcgrade_method(mode="palette"),
    "wbcgrade-relax0.1": wbcgrade_method(mode="palette", relaxation=0.1),
    "wbcgrade-kl-relax0.01": wbcgrade_method(mode="palette", loss="kl", relaxation=0.01),
    "mkl-nearest": mkl_nearest,
    "mkl-pooled": mkl_pooled,
    "idt-nearest": idt_nearest,
    "idt-pooled": idt_pooled,
}


def load_method_file(path: Path) -> None:
    """Add the ``METHODS`` of a Python file to ours (same names replace ours)."""
    spec = importlib.util.spec_from_file_location(f"look_methods_{path.stem}", path)
    if spec is None or spec.loader is None:
        raise SystemExit(f"--method-file {path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    extra = getattr(module, "METHODS", None)
    if not isinstance(extra, dict):
        raise SystemExit(f"--method-file {path}: defines no METHODS dict")
    METHODS.update(extra)


# --------------------------------------------------------------------------- one case


def label(tile: np.ndarray, lines: list[str]) -> np.ndarray:
    """The tile with a white strip of small text above it (no text if no font is found)."""
    import OpenImageIO as oiio

    strip = 13 * len(lines) + 3
    out = np.ones((tile.shape[0] + strip, tile.shape[1], 3), np.float32)
    out[strip:] = tile
    buf = oiio.ImageBuf(np.ascontiguousarray(out))
    for i, text in enumerate(lines):
        oiio.ImageBufAlgo.render_text(buf, 2, 12 + 13 * i, text, 11, "", (0.0, 0.0, 0.0))
    return buf.get_pixels(oiio.FLOAT)[..., :3]


def feature_crop(img: np.ndarray, size: int) -> tuple[str, int, int] | None:
    """(kind, row, col) of the smoothest size x size window mostly of skin-like, else
    sky-like colours (CIE Lab hue and chroma ranges); None if neither is found."""
    lab_img = lab(img)
    lightness = lab_img[..., 0]
    chroma = np.hypot(lab_img[..., 1], lab_img[..., 2])
    hue = np.degrees(np.arctan2(lab_img[..., 2], lab_img[..., 1])) % 360
    masks = {"skin-like": (lightness > 35) & (lightness < 90) & (chroma > 10) & (chroma < 40)
             & (hue > 20) & (hue < 75),
             "sky-like": (lightness > 45) & (lightness < 97) & (chroma > 8)
             & (hue > 200) & (hue < 290)}
    half = size // 2
    if min(img.shape[:2]) <= size + 1:
        return None
    inner = (slice(half, img.shape[0] - half), slice(half, img.shape[1] - half))
    texture = ndimage.uniform_filter(sobel_magnitude(luma(img)), size)[inner]
    for kind, mask in masks.items():
        share = ndimage.uniform_filter(mask.astype(np.float64), size)[inner]
        if share.max() >= 0.6:
            rr, cc = np.unravel_index(np.argmin(np.where(share >= 0.6, texture, np.inf)),
                                      share.shape)
            return kind, int(rr), int(cc)
    return None


#: JPEG quality the style photos are written with before anything reads them
#: (``--style-jpeg``; 0: as arrays, the benchmark's default).
STYLE_JPEG = 0


def jpeg_round_trip(img: np.ndarray, quality: int) -> np.ndarray:
    """(H, W, 3) float in [0, 1] -> the same after a JPEG file at ``quality`` (PIL's
    default 4:2:0 chroma subsampling, as most cameras and exports write)."""
    import io

    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.rint(np.clip(img, 0, 1) * 255).astype(np.uint8)).save(
        buffer, "JPEG", quality=quality)
    buffer.seek(0)
    return np.asarray(Image.open(buffer).convert("RGB"), dtype=np.float64) / 255.0


def run_case(case: Case, method_names: list[str], photos: Photos, tile: int) -> dict:
    """Grade the case's photos with every method; numbers, sheet rows and crop rows."""
    memo: dict = {}
    if case.protocol == "shot" and GRADED_FRAMING == "dark":  # a dark scene: both framings
        styles = [framings(to_8bit(LOOKS[case.look].apply(to_8bit(0.18 * photos.photo(s)))))[0]
                  for s in case.style_sources]
    elif case.protocol == "shot":
        styles = [framings(photos.looked(case.look, s))[0] for s in case.style_sources]
    else:
        styles = [photos.looked(case.look, s) for s in case.style_sources]
    if STYLE_JPEG:  # style photos as users have them: JPEG files
        styles = [jpeg_round_trip(s, STYLE_JPEG) for s in styles]
    rows, sheet, crops = {}, [], []
    for name in case.graded:
        if case.protocol == "shot":
            photo = framings(photos.photo(name))[1]
            truth = framings(photos.looked(case.look, name))[1]
            if GRADED_FRAMING == "dark":  # the scene 2.5 stops under (x 0.18 encoded values)
                photo = to_8bit(0.18 * photo)
                truth = to_8bit(LOOKS[case.look].apply(photo))
            elif GRADED_FRAMING == "flipped":
                photo, truth = photo[:, ::-1].copy(), truth[:, ::-1].copy()
        else:
            photo, truth = photos.photo(name), photos.looked(case.look, name)
        truth_lab, photo_lab = lab(truth), lab(photo)
        de0 = delta_e(photo_lab, truth_lab)
        row = {"dE0": de0, "truth": {"grad_r": gradient_correlation(photo, truth),
                                     "noise": noise_ratio(photo, truth)}, "methods": {}}
        outs = {}
        for method in method_names:
            context = Context(case.protocol, case.look, name, list(case.style_sources),
                              list(case.natural), photos.cache_dir, memo, batch=list(case.batch),
                              _photos=photos)
            start = time.perf_counter()
            out = METHODS[method](photo.copy(), [s.copy() for s in styles], context)
            seconds = time.perf_counter() - start
            out = to_8bit(np.asarray(out, dtype=np.float64)[..., :3])
            if out.shape != photo.shape:
                raise SystemExit(f"{method} returned {out.shape} for a {photo.shape} photo")
            out_lab = photo_lab if np.array_equal(out, photo) else lab(out)
            de = delta_e(out_lab, truth_lab)
            result = {"dE": de, "recovered": 1.0 - de / de0,
                      "chroma": float(np.mean(np.hypot(out_lab[..., 1], out_lab[..., 2]))),
                      "grad_r": gradient_correlation(photo, out),
                      "noise": noise_ratio(photo, out), "seconds": seconds}
            weights = context.info.get("weights")
            if weights:
                result["weights"] = {k: round(v, 4) for k, v in weights.items()}
                top = max(weights, key=weights.get)
                result["top"] = top
                if case.protocol == "shot":
                    result["same_scene_on_top"] = top == name
            extra = {k: v for k, v in context.info.items() if k != "weights"}
            if extra:
                result["info"] = extra
            row["methods"][method] = result
            outs[method] = out
        rows[name] = row
        sheet.append(sheet_row(case, name, photo, truth, outs, row, tile))
        crops.extend(crop_rows(photo, truth, outs, photos.size))
    return {"case": case.__dict__, "photos": rows, "sheet": sheet, "crops": crops}


def small(img: np.ndarray, tile: int) -> np.ndarray:
    """The image resized to ``tile`` px on its long side (quality.thumbnail without padding)."""
    h, w = img.shape[:2]
    scale = tile / max(h, w)
    return thumbnail(img, tile)[: max(1, round(h * scale)), : max(1, round(w * scale))]


def assemble(rows: list[list[np.ndarray]], gap: int = 4) -> np.ndarray:
    """Tiles of any size on a white sheet: columns as wide as their widest tile, rows as tall
    as their tallest."""
    ncol = max(len(r) for r in rows)
    widths = [max(r[j].shape[1] for r in rows if j < len(r)) for j in range(ncol)]
    heights = [max(t.shape[0] for t in r) for r in rows]
    sheet = np.ones((sum(heights) + gap * len(rows), sum(widths) + gap * ncol, 3), np.float32)
    top = 0
    for row, height in zip(rows, heights):
        left = 0
        for tile, width in zip(row, widths):
            sheet[top: top + tile.shape[0], left: left + tile.shape[1]] = tile
            left += width + gap
        top += height + gap
    return sheet


def sheet_row(case: Case, name: str, photo, truth, outs: dict, row: dict, tile: int) -> list:
    where = f"{name} (right)" if case.protocol == "shot" else name
    tiles = [label(small(photo, tile), [case.look, f"{where} dE0 {row['dE0']:.1f}"]),
             label(small(truth, tile), ["truth", ""])]
    for method, out in outs.items():
        r = row["methods"][method]
        tiles.append(label(small(out, tile), [method, f"rec {r['recovered']:+.2f}"]))
    return tiles


def crop_rows(photo, truth, outs: dict, size: int) -> list:
    """2x crops: the flattest well-exposed window, and skin or sky where found."""
    side = max(32, size // 8)
    if min(photo.shape[:2]) <= side:
        return []
    r0, c0 = smooth_crop(photo, side)
    windows = [("flat", r0, c0)]
    feature = feature_crop(photo, side)
    if feature and max(abs(feature[1] - r0), abs(feature[2] - c0)) > side // 2:
        windows.append(feature)  # unless it is the flat window again
    rows = []
    for kind, r, c in windows:
        images = {"photo": photo, "truth": truth, **outs}
        rows.append([label(np.kron(img[r:r + side, c:c + side], np.ones((2, 2, 1)))
                           .astype(np.float32), [f"{kind}: {key}"[:2 * side // 6]])
                     for key, img in images.items()])
    return rows


# --------------------------------------------------------------------------- report


def summarise(cases: list[dict], methods: list[str], protocol: str) -> dict:
    """Per method: mean dE, mean and worst recovered, grad r, noise, same scene, seconds."""
    summary = {}
    for method in ["(truth)"] + methods:
        per = [(row, row["methods"].get(method)) for c in cases for row in c["photos"].values()]
        if method == "(truth)":
            per = [(row, {"dE": 0.0, "recovered": 1.0, **row["truth"]}) for row, _ in per]
        per = [p for p in per if p[1] is not None]
        rec = [r["recovered"] for _, r in per]
        faces = [r["recovered"] for c in cases for name, row in c["photos"].items()
                 if name in FACES and (r := row["methods"].get(method, {} if method != "(truth)"
                                                               else {"recovered": 1.0}))]
        mono = [r["chroma"] for c in cases if c["case"]["look"] in MONOCHROME_LOOKS
                for row in c["photos"].values()
                if (r := row["methods"].get(method)) and "chroma" in r]
        same = [r["same_scene_on_top"] for _, r in per if "same_scene_on_top" in r]
        secs = [r["seconds"] for _, r in per if "seconds" in r]
        summary[method] = {
            "photos": len(per), "dE": float(np.mean([r["dE"] for _, r in per])),
            "dE0": float(np.mean([row["dE0"] for row, _ in per])),
            "recovered_mean": float(np.mean(rec)), "recovered_worst": float(np.min(rec)),
            "grad_r_mean": float(np.mean([r["grad_r"] for _, r in per])),
            "grad_r_worst": float(np.min([r["grad_r"] for _, r in per])),
            "noise_geomean": float(np.exp(np.mean(np.log([r["noise"] for _, r in per])))),
            "noise_worst": float(np.max([r["noise"] for _, r in per])),
            "same_scene_on_top": [int(sum(same)), len(same)] if same else None,
            "faces_mean": float(np.mean(faces)) if faces else None,
            "faces_worst": float(np.min(faces)) if faces else None,
            "monochrome_chroma_max": float(np.max(mono)) if mono else None,
            "seconds_median": float(np.median(secs)) if secs else None,
            "by_look": {c["case"]["look"]: float(np.mean(
                [row["methods"][method]["recovered"] if method != "(truth)" else 1.0
                 for row in c["photos"].values()])) for c in cases},
        }
    return summary


def print_table(protocol: str, summary: dict, looks: list[str]) -> None:
    any_row = next(iter(summary.values()))
    print(f"\n{PROTOCOLS[protocol]}: {any_row['photos']} graded photos, mean dE0 "
          f"(ungraded vs truth) {any_row['dE0']:.2f}")
    head = (f"| {'method':24s} | {'dE2000':>6s} | {'recovered':>9s} | {'worst':>6s} | "
            f"{'grad r (worst)':>14s} | {'noise (worst)':>13s} | {'same scene on top':>17s} "
            f"| {'s/photo':>7s} | {'faces (worst)':>13s} | {'b&w chroma':>10s} |")
    print(head)
    print("|" + "|".join("-" * (len(part)) for part in head.split("|")[1:-1]) + "|")
    for method, s in summary.items():
        same = f"{s['same_scene_on_top'][0]} of {s['same_scene_on_top'][1]}" \
            if s["same_scene_on_top"] else "-"
        secs = f"{s['seconds_median']:.2f}" if s["seconds_median"] is not None else "-"
        faces = (f"{s['faces_mean']:+.2f} ({s['faces_worst']:+.2f})"
                 if s["faces_mean"] is not None else "-")
        mono = (f"{s['monochrome_chroma_max']:.1f}" if s["monochrome_chroma_max"] is not None
                else "-")
        print(f"| {method:24s} | {s['dE']:6.2f} | {s['recovered_mean']:+9.2f} | "
              f"{s['recovered_worst']:+6.2f} | {s['grad_r_mean']:6.3f} ({s['grad_r_worst']:5.3f})"
              f" | {s['noise_geomean']:5.2f} ({s['noise_worst']:5.2f}) | {same:>17s} | "
              f"{secs:>7s} | {faces:>13s} | {mono:>10s} |")
    print(f"recovered by look ({PROTOCOLS[protocol]}):")
    print(f"| {'method':24s} | " + " | ".join(f"{lk:>13s}" for lk in looks) + " |")
    for method, s in summary.items():
        if method != "(truth)":
            print(f"| {method:24s} | " + " | ".join(f"{s['by_look'][lk]:+13.2f}"
                                                   for lk in looks) + " |")


def write_sheets(out: Path, protocol: str, cases: list[dict], methods: list[str]) -> list[Path]:
    columns = ["photo", "truth", *methods]
    written = []
    for kind in ("sheet", "crops"):
        rows = [r for c in cases for r in c[kind]]
        if not rows:
            continue
        path = out / f"{kind}_{protocol}.png"
        write_png(path, assemble(rows))
        text = [f"{PROTOCOLS[protocol]}: columns = {', '.join(columns)}"]
        if kind == "sheet":
            text += [f"row {i}: {c['case']['look']} / {name}" for i, (c, name) in enumerate(
                (c, name) for c in cases for name in c["photos"])]
        else:
            text.append("rows: per graded photo, the flattest well-exposed window, then skin "
                        "or sky where found (2x nearest neighbour)")
        path.with_suffix(".txt").write_text("\n".join(text) + "\n")
        written.append(path)
    return written


# --------------------------------------------------------------------------- main


def _worker_init(threads: int) -> None:
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(threads)
    except ImportError:
        pass
    try:
        import numba

        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    except ImportError:
        pass


def _run_one(args: tuple) -> dict:
    case, methods, folder, size, cache_dir, tile = args
    return run_case(case, methods, Photos(folder, size, cache_dir), tile)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog="tuned looks: " + ", ".join(TUNED_LOOKS)
                                     + "; held-out looks: " + ", ".join(HELD_OUT_LOOKS))
    parser.add_argument("--protocol", choices=["shot", "cross", "both"], default="both")
    parser.add_argument("--looks", help="comma-separated; 'held-out': the looks no default "
                        "was chosen on, 'film': the 16 real film looks ('film-tuned', "
                        "'film-held-out': those settings were / were not chosen on), 'all': "
                        "every look (default: the six tuned looks; --quick: 3 of them)")
    parser.add_argument("--methods", help="comma-separated (default: all registered)")
    parser.add_argument("--method-file", type=Path, action="append", default=[],
                        help="a Python file with its own METHODS dict (repeatable)")
    parser.add_argument("--photos", type=int, default=6, help="photos per set (default 6)")
    parser.add_argument("--styles", type=int, help="style photos per cross-content set "
                        "(default --photos; --looks film: 12)")
    parser.add_argument("--natural", type=Path, help="a preset (.npz) of natural palettes of "
                        "photos other than the benchmark's, for wbcgrade's content model")
    parser.add_argument("--framing", choices=["plain", "dark", "flipped"], default="plain",
                        help="shot matching: the scenes as they are, 2.5 stops darker (both "
                        "framings), or the graded framing flipped left to right")
    parser.add_argument("--style-jpeg", type=int, default=0, metavar="Q",
                        help="write the style photos as JPEG at quality Q (1-95) before "
                        "any method reads them, as a user's style folder holds them "
                        "(default: as arrays)")
    parser.add_argument("--graded", type=int,
                        help="grade only the first K photos of each case (--quick: 3)")
    parser.add_argument("--size", type=int, help="long side in px (default 768; --quick: 384)")
    parser.add_argument("--quick", action="store_true",
                        help="size 384, looks kodak2383,teal-orange,faded-film, 3 graded a case")
    parser.add_argument("--jobs", type=int, default=1, help="cases run in parallel")
    parser.add_argument("--photo-dir", type=Path, default=DEFAULT_PHOTOS)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "look")
    parser.add_argument("--cache-dir", type=Path,
                        default=ROOT / "benchmarks" / "out" / "look-cache")
    parser.add_argument("--tile", type=int, default=192, help="sheet tile size in px")
    args = parser.parse_args(argv)

    for path in args.method_file:
        load_method_file(path)
    size = args.size or (384 if args.quick else 768)
    graded = args.graded or (3 if args.quick else None)
    groups = {"held-out": HELD_OUT_LOOKS, "all": list(LOOKS), "tuned": TUNED_LOOKS,
              "film": FILM_LOOKS, "film-tuned": FILM_TUNED_LOOKS,
              "film-held-out": FILM_HELD_OUT_LOOKS, "photographer": PHOTOGRAPHER_LOOKS}
    if args.looks:
        looks = [lk for part in args.looks.split(",") if part
                 for lk in groups.get(part, [part])]
    else:
        looks = ["kodak2383", "teal-orange", "faded-film"] if args.quick else TUNED_LOOKS
    methods = [m for m in args.methods.split(",") if m] if args.methods else list(METHODS)
    for name, known, what in ((looks, LOOKS, "look"), (methods, METHODS, "method")):
        unknown = [x for x in name if x not in known]
        if unknown:
            raise SystemExit(f"unknown {what} {unknown[0]!r}; known: {', '.join(known)}")
    protocols = ["shot", "cross"] if args.protocol == "both" else [args.protocol]
    if not 1 <= args.photos <= 10 or (graded is not None and graded < 1):
        raise SystemExit("--photos must be in 1..10 and --graded at least 1")
    film = any(lk in FILM_LOOKS for lk in looks)
    n_styles = args.styles or (12 if film and args.photos <= 8 else args.photos)
    global NATURAL_FILE, GRADED_FRAMING, STYLE_JPEG
    if not 0 <= args.style_jpeg <= 95:
        raise SystemExit("--style-jpeg must be in 1..95 (0: no JPEG)")
    STYLE_JPEG = args.style_jpeg
    if args.natural is not None:
        NATURAL_FILE = str(args.natural.resolve())
    GRADED_FRAMING = args.framing

    photos = Photos(args.photo_dir, size, args.cache_dir)
    cases = make_cases(photos.names(), looks, protocols, args.photos, graded, n_styles)
    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    from tqdm import tqdm

    jobs = [(case, methods, args.photo_dir, size, args.cache_dir, args.tile) for case in cases]
    done: list[dict] = []
    with tqdm(total=len(cases), desc="cases", unit="case", file=sys.stderr) as bar:
        if args.jobs > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            threads = max(1, (os.cpu_count() or 1) // args.jobs)
            with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("fork"),
                                     initializer=_worker_init, initargs=(threads,)) as pool:
                for result in pool.map(_run_one, jobs):
                    done.append(result)
                    bar.update()
        else:
            for job in jobs:
                done.append(_run_one(job))
                bar.update()
    total = time.perf_counter() - start

    results = {"settings": {"size": size, "photos_per_set": args.photos, "graded": graded,
                            "styles_per_set": n_styles, "natural": NATURAL_FILE,
                            "framing": FRAMING, "graded_framing": GRADED_FRAMING,
                            "style_jpeg": STYLE_JPEG,
                            "shuffle_seed": SHUFFLE_SEED,
                            "rotation": ROTATION, "photo_dir": str(args.photo_dir),
                            "methods": methods, "looks": looks, "jobs": args.jobs,
                            "seconds_total": total},
               "looks": {lk: {"description": LOOKS[lk].description,
                              "source": LOOKS[lk].source()} for lk in looks},
               "protocols": {}}
    written = []
    for protocol in protocols:
        these = [c for c in done if c["case"]["protocol"] == protocol]
        summary = summarise(these, methods, protocol)
        results["protocols"][protocol] = {
            "summary": summary,
            "cases": [{**c["case"], "photos": c["photos"]} for c in these]}
        print_table(protocol, summary, looks)
        written += write_sheets(args.out, protocol, these, methods)
    (args.out / "results.json").write_text(json.dumps(results, indent=1))
    print(f"\n{len(cases)} cases, size {size}, {total:.0f} s in all; wrote "
          f"{args.out / 'results.json'}, " + ", ".join(str(p) for p in written))


if __name__ == "__main__":
    main()
