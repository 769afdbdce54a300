"""Grade quality of ``wbcgrade`` beside two established colour-transfer methods.

Run ``python benchmarks/quality.py`` (``--help`` for options). It grades
photos the shipped presets were not built from towards two style sets (warm,
cool) with wbcgrade's defaults and, in the same run, the same photos with
color-matcher's ``mkl`` (Pitié's linear Monge-Kantorovich map) and IDT +
regrain (Pitié et al. 2007, ``python-color-transfer``) towards the single
style photo nearest to the input. The peers are benchmark-only extras:
``pip install color-matcher`` and ``pip install --no-deps python-color-transfer``
(its metadata pins numpy < 2 and the non-headless OpenCV; it runs on what
wbcgrade installs).

It prints one table (means over photos x style sets) and writes, in ``--out``:

- ``sheet.png``: rows = photo x set, columns = input, wbcgrade, peers;
- ``crops.png``: 2x crops (nearest neighbour) of each input's smoothest
  well-exposed area (sky, fog, skin, bokeh) for every method;
- ``metrics.json``: every metric of every grade.

Metrics (8-bit outputs, sRGB-encoded values in [0, 1]):

- style: min over the set's style photos of the sliced 2-Wasserstein distance
  between 20,000 output pixels and 20,000 style pixels (200 random
  directions, fixed seed);
- grad r: Pearson r of the Sobel gradient magnitude of luma
  (0.299 R + 0.587 G + 0.114 B), input vs output;
- noise: standard deviation of high-pass luma (luma minus its Gaussian blur,
  sigma = 1.5 px) inside the input's flattest 30 % of pixels (lowest Sobel
  magnitude), output over input; averaged as a geometric mean;
- reversals: among horizontally or vertically adjacent 8x8 block pairs whose
  mean-luma step in the input is at least 1/255, the share whose step
  changes sign in the output;
- lut: mean absolute difference (x 255) between the input graded by the
  ``.cube`` that ``--lut`` writes (applied with colour-science, trilinear)
  and the input through the grade's colour map; and between that and the
  output (which also went through the regrain step).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
#: The full photo set (the figures of docs/benchmarks.md): ``--photo-dir``, else
#: $WBCGRADE_PHOTOS, else this folder beside the clone when it is there.
DEFAULT_PHOTOS = ROOT.parent / "shared" / "data" / "photos"
#: A clone's own photos (``samples/``), used when the full set is not found.
SAMPLE_PHOTOS = ROOT / "samples"

STYLE_SETS = {
    "warm": ["coffee", "flower", "sunset", "fig", "wine", "chelsea"],
    "cool": ["bridge", "dragonfly", "kleiber", "rocket", "infinite_sea", "grace_hopper"],
}
#: Photos in neither set: skies, fog, foliage, wood, saturated paint, a dark forest.
DEFAULT_PHOTOS_GRADED = ["picosdeeuropa", "life", "china", "friends", "brushes", "aitzgorri"]
#: The same benchmark on a clone's samples/ (smaller sets; figures not those of docs/benchmarks.md).
SAMPLE_SETS = {"warm": ["coffee", "flower", "sunset"], "cool": ["bridge", "astronaut"]}
SAMPLE_PHOTOS_GRADED = ["aitzgorri", "chelsea", "seeding"]


def photo_source(photo_dir: Path | None) -> tuple[Path, dict, list[str]]:
    """(folder, style sets, photos to grade): the full set where it is found (``photo_dir``,
    $WBCGRADE_PHOTOS, or beside the clone), else the clone's samples/ with smaller sets."""
    import os

    def holds(folder, sets: dict, graded: list[str]) -> bool:
        names = [n for group in sets.values() for n in group] + graded
        return bool(folder) and all(Path(folder, f"{n}.jpg").is_file() for n in names)

    for folder in (photo_dir, os.environ.get("WBCGRADE_PHOTOS"), DEFAULT_PHOTOS):
        if holds(folder, STYLE_SETS, DEFAULT_PHOTOS_GRADED):
            return Path(folder), STYLE_SETS, DEFAULT_PHOTOS_GRADED
    if photo_dir is not None:
        if holds(photo_dir, SAMPLE_SETS, SAMPLE_PHOTOS_GRADED):
            return Path(photo_dir), SAMPLE_SETS, SAMPLE_PHOTOS_GRADED
        raise SystemExit(f"--photo-dir {photo_dir}: the benchmark's photos are not all there")
    print(f"photo set not found ({DEFAULT_PHOTOS}; set --photo-dir or $WBCGRADE_PHOTOS): "
          f"using the clone's {SAMPLE_PHOTOS} (smaller sets, not the figures of "
          "docs/benchmarks.md)",
          file=sys.stderr)
    return SAMPLE_PHOTOS, SAMPLE_SETS, SAMPLE_PHOTOS_GRADED


# --------------------------------------------------------------------------- metrics


def luma(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., 0] * 0.299 + rgb[..., 1] * 0.587 + rgb[..., 2] * 0.114


def sobel_magnitude(y: np.ndarray) -> np.ndarray:
    return np.hypot(ndimage.sobel(y, axis=0), ndimage.sobel(y, axis=1))


def sliced_wasserstein(a: np.ndarray, b: np.ndarray, n_dirs: int = 200, seed: int = 0) -> float:
    """SW2 between two (n, 3) samples of equal size."""
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(n_dirs, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    pa = np.sort(a @ dirs.T, axis=0)
    pb = np.sort(b @ dirs.T, axis=0)
    return float(np.sqrt(np.mean((pa - pb) ** 2)))


def sample_pixels(rgb: np.ndarray, n: int = 20_000, seed: int = 0) -> np.ndarray:
    flat = rgb.reshape(-1, 3)
    rng = np.random.default_rng(seed)
    return flat[rng.choice(len(flat), size=n, replace=len(flat) < n)]


def style_distance(out: np.ndarray, styles: list[np.ndarray]) -> float:
    sample = sample_pixels(out)
    return min(sliced_wasserstein(sample, sample_pixels(s, seed=1)) for s in styles)


def gradient_correlation(inp: np.ndarray, out: np.ndarray) -> float:
    a, b = sobel_magnitude(luma(inp)).ravel(), sobel_magnitude(luma(out)).ravel()
    return float(np.corrcoef(a, b)[0, 1])


def noise_ratio(inp: np.ndarray, out: np.ndarray) -> float:
    y_in, y_out = luma(inp), luma(out)
    flat = sobel_magnitude(y_in) <= np.quantile(sobel_magnitude(y_in), 0.30)
    hp_in = (y_in - ndimage.gaussian_filter(y_in, 1.5))[flat]
    hp_out = (y_out - ndimage.gaussian_filter(y_out, 1.5))[flat]
    return float(hp_out.std() / max(hp_in.std(), 1e-12))


def block_reversals(inp: np.ndarray, out: np.ndarray) -> float:
    def means(y):
        h, w = (y.shape[0] // 8) * 8, (y.shape[1] // 8) * 8
        return y[:h, :w].reshape(h // 8, 8, w // 8, 8).mean(axis=(1, 3))

    m_in, m_out = means(luma(inp)), means(luma(out))
    flips, count = 0, 0
    for axis in (0, 1):
        d_in, d_out = np.diff(m_in, axis=axis), np.diff(m_out, axis=axis)
        big = np.abs(d_in) >= 1.0 / 255.0
        flips += int(np.sum(np.sign(d_in[big]) != np.sign(d_out[big])))
        count += int(big.sum())
    return flips / max(count, 1)


def metrics(inp: np.ndarray, out: np.ndarray, styles: list[np.ndarray]) -> dict:
    return {"style": style_distance(out, styles), "grad_r": gradient_correlation(inp, out),
            "noise": noise_ratio(inp, out), "reversals": block_reversals(inp, out)}


# --------------------------------------------------------------------------- images


def read_rgb(path: Path) -> np.ndarray:
    from wbcgrade.color.io.images import read_image

    return np.clip(read_image(path).rgb(), 0.0, 1.0).astype(np.float64)


def to_8bit(x: np.ndarray) -> np.ndarray:
    return np.round(np.clip(x, 0.0, 1.0) * 255.0) / 255.0


def nearest_style(inp: np.ndarray, styles: list[np.ndarray]) -> int:
    sample = sample_pixels(inp)
    return int(np.argmin([sliced_wasserstein(sample, sample_pixels(s, seed=1)) for s in styles]))


def peer_mkl(inp: np.ndarray, ref: np.ndarray) -> np.ndarray:
    from color_matcher import ColorMatcher

    return ColorMatcher().transfer(src=inp, ref=ref, method="mkl")


def peer_idt_regrain(inp: np.ndarray, ref: np.ndarray) -> np.ndarray:
    from python_color_transfer.color_transfer import ColorTransfer

    bgr_in = np.ascontiguousarray((inp[..., ::-1] * 255).round().astype(np.uint8))
    bgr_ref = np.ascontiguousarray((ref[..., ::-1] * 255).round().astype(np.uint8))
    out = ColorTransfer().pdf_transfer(img_arr_in=bgr_in, img_arr_ref=bgr_ref, regrain=True)
    return np.asarray(out, dtype=np.float64)[..., ::-1] / 255.0


def smooth_crop(inp: np.ndarray, size: int = 96) -> tuple[int, int]:
    """Top-left corner of the input's smoothest well-exposed size x size window."""
    y = luma(inp)
    grad = ndimage.uniform_filter(sobel_magnitude(y), size)
    mean = ndimage.uniform_filter(y, size)
    grad[(mean < 0.12) | (mean > 0.92)] = np.inf
    half = size // 2
    grad[:half], grad[-half:], grad[:, :half], grad[:, -half:] = np.inf, np.inf, np.inf, np.inf
    if not np.isfinite(grad).any():
        return (inp.shape[0] - size) // 2, (inp.shape[1] - size) // 2
    r, c = np.unravel_index(np.argmin(grad), grad.shape)
    return int(r - half), int(c - half)


def thumbnail(img: np.ndarray, size: int) -> np.ndarray:
    import OpenImageIO as oiio

    h, w = img.shape[:2]
    scale = size / max(h, w)
    buf = oiio.ImageBuf(np.ascontiguousarray(img, dtype=np.float32))
    small = oiio.ImageBufAlgo.resize(
        buf, roi=oiio.ROI(0, max(1, round(w * scale)), 0, max(1, round(h * scale)), 0, 1, 0, 3))
    tile = np.ones((size, size, 3), np.float32)
    pix = small.get_pixels(oiio.FLOAT)
    tile[: pix.shape[0], : pix.shape[1]] = pix[..., :3]
    return tile


def write_png(path: Path, img: np.ndarray) -> None:
    import OpenImageIO as oiio

    img = np.ascontiguousarray(np.clip(img, 0, 1), dtype=np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), img)
    if not buf.write(str(path)):
        raise SystemExit(f"cannot write {path}: {buf.geterror()}")


def grid_sheet(rows: list[list[np.ndarray]], gap: int = 4) -> np.ndarray:
    h, w = rows[0][0].shape[:2]
    ncol = max(len(r) for r in rows)
    sheet = np.ones((len(rows) * (h + gap), ncol * (w + gap), 3), np.float32)
    for i, row in enumerate(rows):
        for j, tile in enumerate(row):
            sheet[i * (h + gap): i * (h + gap) + h, j * (w + gap): j * (w + gap) + w] = tile
    return sheet


# --------------------------------------------------------------------------- grading


def load_set(photos: Path, names: list[str], bins: int):
    from wbcgrade.color.histogram import HistogramCache
    from wbcgrade.color.presets import load_style_folder

    folder = Path(tempfile.mkdtemp(prefix="wbc-quality-"))
    for name in names:
        (folder / f"{name}.jpg").symlink_to(photos / f"{name}.jpg")
    return load_style_folder(folder, bins, cache=HistogramCache())


def grade_wbcgrade(path: Path, styles, opts, lut_dir: Path):
    """(graded 8-bit pixels, LUT-applied and map-applied 8-bit pixels, grade) for one photo."""
    from wbcgrade.color._colour import colour
    from wbcgrade.color.mapping.lut import color_map_to_lut, write_cube
    from wbcgrade.color.mapping.remap import apply_color_map
    from wbcgrade.photos.workflow import grade_photo

    graded = grade_photo(path, styles, opts)
    out = to_8bit(graded.pixels[..., :3])
    cube = lut_dir / f"{path.stem}.cube"
    grade = graded.grade
    write_cube(cube, color_map_to_lut(grade.color_map, 33, grade.strength), overwrite=True)
    lut = colour.read_LUT(str(cube))
    inp = read_rgb(path)
    by_lut = to_8bit(lut.apply(inp, interpolator=colour.algebra.table_interpolation_trilinear))
    by_map = to_8bit(apply_color_map(inp, grade.color_map, grade.strength))
    return out, by_lut, by_map, graded


def parse_options(pairs: list[str]):
    from wbcgrade.color.options import FLAT_FIELDS, GradeOptions

    types = {**FLAT_FIELDS, "floor": None}
    values = {}
    for pair in pairs:
        key, _, text = pair.partition("=")
        key = key.strip().replace("-", "_")
        if key not in types:
            raise SystemExit(f"--set {pair}: unknown option {key!r}")
        if text.lower() in ("none", ""):
            values[key] = None
        elif text.lower() in ("true", "false"):
            values[key] = text.lower() == "true"
        else:
            try:
                values[key] = int(text)
            except ValueError:
                try:
                    values[key] = float(text)
                except ValueError:
                    values[key] = text
    values.setdefault("mode", "palette")  # the palette transfer, as this benchmark always measured
    return GradeOptions(**values)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--photo-dir", type=Path, default=None,
                        help=f"the photos [default: $WBCGRADE_PHOTOS, else {DEFAULT_PHOTOS} "
                             f"when it is there, else the clone's samples/]")
    parser.add_argument("--photos", default=None, help="photos to grade (comma-separated)")
    parser.add_argument("--sets", default=None, help="style sets (comma-separated)")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "quality")
    parser.add_argument("--no-peers", action="store_true", help="wbcgrade only")
    parser.add_argument("--set", dest="options", action="append", default=[],
                        metavar="KEY=VALUE",
                        help="a grade option by its flat name, e.g. relaxation=0.05 (repeatable); "
                             "mode=palette unless set (this benchmark measures the palette "
                             "transfer: distance to the style palettes)")
    args = parser.parse_args(argv)

    opts = parse_options(args.options)
    args.out.mkdir(parents=True, exist_ok=True)
    lut_dir = Path(tempfile.mkdtemp(prefix="wbc-quality-lut-"))
    args.photo_dir, style_sets, graded_photos = photo_source(args.photo_dir)
    photos = [p for p in (args.photos or ",".join(graded_photos)).split(",") if p]
    sets = [s for s in (args.sets or ",".join(style_sets)).split(",") if s]
    methods = ["wbcgrade"] + ([] if args.no_peers else ["mkl", "idt+regrain"])
    results: dict = {m: [] for m in ["input"] + methods}
    lut_diffs: list[float] = []
    regrain_diffs: list[float] = []
    sheet_rows, crop_rows = [], []
    seconds = []
    for set_name in sets:
        names = style_sets[set_name]
        style_pixels = [read_rgb(args.photo_dir / f"{n}.jpg") for n in names]
        styles = load_set(args.photo_dir, names, opts.transfer.bins)
        for photo in photos:
            path = args.photo_dir / f"{photo}.jpg"
            inp = to_8bit(read_rgb(path))
            outs = {"input": inp}
            start = time.perf_counter()
            outs["wbcgrade"], by_lut, by_map, graded = grade_wbcgrade(path, styles, opts,
                                                                      lut_dir)
            seconds.append(time.perf_counter() - start)
            lut_diffs.append(float(np.abs(by_map - by_lut).mean() * 255))
            regrain_diffs.append(float(np.abs(outs["wbcgrade"] - by_lut).mean() * 255))
            if not args.no_peers:
                ref = style_pixels[nearest_style(inp, style_pixels)]
                outs["mkl"] = to_8bit(peer_mkl(inp, ref))
                outs["idt+regrain"] = to_8bit(peer_idt_regrain(inp, ref))
            for method, out in outs.items():
                row = metrics(inp, out, style_pixels)
                row.update(photo=photo, set=set_name)
                if method == "wbcgrade":
                    row["weights"] = {n: round(float(w), 3) for n, w in graded.grade.ranked()}
                    row["lut_diff"] = lut_diffs[-1]
                results[method].append(row)
                print(f"{set_name:5s} {photo:14s} {method:12s} style {row['style']:.3f} "
                      f"grad r {row['grad_r']:.3f} noise {row['noise']:.2f} "
                      f"rev {100 * row['reversals']:.2f}%", file=sys.stderr)
            sheet_rows.append([thumbnail(outs[m], 256) for m in ["input"] + methods])
            r, c = smooth_crop(inp)
            crop_rows.append([np.kron(outs[m][r: r + 96, c: c + 96],
                                      np.ones((2, 2, 1))).astype(np.float32)
                              for m in ["input"] + methods])
    write_png(args.out / "sheet.png", grid_sheet(sheet_rows))
    write_png(args.out / "crops.png", grid_sheet(crop_rows))
    (args.out / "metrics.json").write_text(json.dumps(results, indent=1))

    print(f"{len(photos)} photos x {len(sets)} style sets ({', '.join(sets)}); "
          f"columns of the sheets: {', '.join(['input'] + methods)}")
    print(f"{'method':14s} {'style':>7s} {'(% in)':>7s} {'grad r':>7s} {'worst':>7s} "
          f"{'noise':>7s} {'worst':>7s} {'revers.':>8s}")
    base = np.mean([r["style"] for r in results["input"]])
    for method, rows in results.items():
        style = np.mean([r["style"] for r in rows])
        grad = [r["grad_r"] for r in rows]
        noise = [r["noise"] for r in rows]
        print(f"{method:14s} {style:7.3f} {100 * style / base:6.0f}% {np.mean(grad):7.3f} "
              f"{np.min(grad):7.3f} {np.exp(np.mean(np.log(noise))):6.2f}x "
              f"{np.max(noise):6.2f}x {100 * np.mean([r['reversals'] for r in rows]):7.2f}%")
    print(f"wbcgrade: 33^3 .cube (colour-science) vs the colour map: mean "
          f"{np.mean(lut_diffs):.3f}/255 (worst photo {np.max(lut_diffs):.3f}/255); "
          f"vs the output (regrain included): mean {np.mean(regrain_diffs):.2f}/255 "
          f"(worst {np.max(regrain_diffs):.2f}/255); median {np.median(seconds):.1f} s a photo")
    print(f"wrote {args.out / 'sheet.png'}, {args.out / 'crops.png'}, "
          f"{args.out / 'metrics.json'}")


if __name__ == "__main__":
    main()
