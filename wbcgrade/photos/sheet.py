"""A PNG sheet per graded photo: what went in, what came out, and why.

Layout (top to bottom): a title line (photo, loss against the best single
style, number of non-zero weights, time); the input and the graded output
side by side; thumbnails of the contributing styles, each with its weight as
a bar; palette swatches of the input, the barycenter and the output.

Composed with numpy, Pillow and OpenImageIO (no plotting library): pictures are
resized with Pillow's Lanczos filter, text is drawn by Pillow with the fonts
OpenImageIO's package ships (Droid, what its ``render_text`` draws with); an
OpenImageIO without fonts gives sheets without labels (logged once), the report's
HTML table still has every number; the PNG is encoded by OpenImageIO. Palettes are
the main colours of a histogram: its highest peaks (greedy, at least ``min_distance`` apart),
refined by a few weighted k-means steps over the histogram's bins; each
swatch is as wide as the share of mass nearest to it.
"""

from __future__ import annotations

import functools
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
from PIL import Image as PILImage
from PIL import ImageDraw, ImageFont

from wbcgrade._names import safe_text
from wbcgrade._publish import encode_png, publish_bytes
from wbcgrade.color.histogram import grid_points, resample_histogram

__all__ = ["Palette", "histogram_palette", "thumbnail", "picture_box", "fit_size", "StyleTile",
           "SheetContent", "compose_sheet", "write_sheet"]

_BACKGROUND = (0.96, 0.96, 0.95)
_INK = (0.12, 0.12, 0.12)
_BAR = (0.20, 0.45, 0.75)
_PAD = 12
#: Draw labels with OpenImageIO's fonts (tests turn this off: the sheet without labels).
USE_FONTS = True
log = logging.getLogger(__name__)


@dataclass
class Palette:
    """Main colours of a histogram: colors (k, 3) encoded RGB, shares (k,) summing to 1."""

    colors: np.ndarray
    shares: np.ndarray


def histogram_palette(hist: np.ndarray, k: int = 8, bins: int = 16,
                      min_distance: float = 0.15, steps: int = 5) -> Palette:
    """Main colours of an (n, n, n) colour histogram.

    Parameters
    ----------
    hist : (n, n, n) non-negative histogram over the encoded RGB cube.
    k : at most this many colours.
    bins : grid the histogram is re-binned to first (keeps this cheap).
    min_distance : initial peaks are at least this far apart (RGB, [0, 1] units).
    steps : weighted k-means refinement steps.

    Returns
    -------
    Palette sorted by decreasing share.
    """
    hist = resample_histogram(np.asarray(hist, dtype=np.float64), bins)
    mass = hist.ravel() / hist.sum()
    points = grid_points(bins)
    live = np.flatnonzero(mass > 1e-6 * mass.max())
    points, mass = points[live], mass[live]
    centres: list[np.ndarray] = []
    for index in np.argsort(-mass, kind="stable"):
        if len(centres) == k:
            break
        if all(np.linalg.norm(points[index] - c) >= min_distance for c in centres):
            centres.append(points[index])
    centres_arr = np.array(centres)
    for _ in range(steps):
        nearest = np.argmin(((points[:, None, :] - centres_arr[None]) ** 2).sum(-1), axis=1)
        for j in range(len(centres_arr)):
            mine = nearest == j
            if mass[mine].sum() > 0:
                centres_arr[j] = (points[mine] * mass[mine, None]).sum(0) / mass[mine].sum()
    nearest = np.argmin(((points[:, None, :] - centres_arr[None]) ** 2).sum(-1), axis=1)
    shares = np.bincount(nearest, weights=mass, minlength=len(centres_arr))
    order = np.argsort(-shares, kind="stable")
    shares = shares[order]
    return Palette(np.clip(centres_arr[order], 0, 1), shares / shares.sum())


#: The height of the before and after pictures on a sheet (their width: half the sheet's).
PICTURE_HEIGHT = 300


def picture_box(width: int = 960) -> tuple[int, int]:
    """(height, width) the before and after pictures of a sheet ``width`` wide fit in."""
    return PICTURE_HEIGHT, (width - 3 * _PAD) // 2


def fit_size(height: int, width: int, max_h: int, max_w: int) -> tuple[int, int]:
    """(height, width) of a picture ``height`` x ``width`` scaled to fit ``max_h`` x ``max_w``."""
    scale = min(max_h / height, max_w / width)
    return max(1, round(height * scale)), max(1, round(width * scale))


#: A picture this many times larger than its thumbnail (in both directions) is first
#: averaged down by whole blocks to about that size: OpenImageIO's filtered resize widens
#: its filter with the ratio (a 16-megapixel photo to a 96 x 128 tile: 1.8 s; blocks first:
#: 0.1 s), and the blocks' average is the area filter the last step still smooths.
PRESHRINK = 4


def _block_mean(pixels: np.ndarray, factor: int) -> np.ndarray:
    """(H, W, C) -> (H // factor, W // factor, C): the mean of each whole factor x factor
    block (the last partial rows and columns dropped)."""
    height, width = (pixels.shape[0] // factor) * factor, (pixels.shape[1] // factor) * factor
    channels = pixels.shape[2]
    rows = pixels[:height, :width].reshape(height // factor, factor, width, channels)
    rows = rows.sum(axis=1, dtype=np.float32)  # (one axis at a time: 6x faster than both)
    blocks = rows.reshape(height // factor, width // factor, factor, channels).sum(axis=2)
    return blocks / np.float32(factor * factor)


def thumbnail(rgb: np.ndarray, max_h: int, max_w: int) -> np.ndarray:
    """(H, W, 3) float display pixels -> resized copy fitting in max_h x max_w (filtered)."""
    height, width = rgb.shape[:2]
    out_h, out_w = fit_size(height, width, max_h, max_w)
    pixels = rgb[:, :, :3]
    if (out_h, out_w) == (height, width):  # already that size (as Pillow's resize: a copy)
        return np.array(pixels, dtype=np.float32)
    factor = min(height // (PRESHRINK * out_h), width // (PRESHRINK * out_w))
    if factor >= 2:
        pixels = _block_mean(np.asarray(pixels, dtype=np.float32), factor)
    # Pillow's Lanczos on each float channel: OpenImageIO's filtered resize within 1e-5 on
    # average, 8x faster (docs/benchmarks.md)
    return np.stack([np.asarray(PILImage.fromarray(np.ascontiguousarray(pixels[:, :, c],
                                                                        dtype=np.float32))
                                .resize((out_w, out_h), PILImage.Resampling.LANCZOS))
                     for c in range(3)], axis=2)


def _swatches(palette: Palette, height: int, width: int) -> np.ndarray:
    strip = np.empty((height, width, 3), dtype=np.float32)
    edges = np.round(np.concatenate([[0], np.cumsum(palette.shares)]) * width).astype(int)
    edges[-1] = width
    for j, colour in enumerate(palette.colors):
        strip[:, edges[j]:edges[j + 1]] = colour
    return strip


@dataclass
class StyleTile:
    """One contributing style: name, weight and a (h, w, 3) display picture."""

    name: str
    weight: float
    picture: np.ndarray


@dataclass
class SheetContent:
    """Everything a sheet shows (pictures are display-encoded (H, W, 3) floats in [0, 1])."""

    title: str
    subtitle: str
    before: np.ndarray
    after: np.ndarray
    styles: list[StyleTile]
    palettes: list[tuple[str, Palette]]
    more_styles: int = 0
    #: a look grade has no weights: the styles are shown without bars, under this label
    styles_label: str | None = None
    #: a look grade: a colour chart before and after the look ((h, w, 3) each), shown
    #: instead of weights
    chart: tuple[np.ndarray, np.ndarray] | None = None


def _to_8bit(values) -> np.ndarray:
    """Display values in [0, 1] (clipped) -> uint8 (rounded), as the PNG holds them."""
    values = np.clip(np.asarray(values, dtype=np.float32), 0.0, 1.0) * np.float32(255)
    return np.rint(values, out=values).astype(np.uint8)


class _Canvas:
    """The sheet in 8 bits, as it is written (a quarter of a float canvas's memory)."""

    def __init__(self, height: int, width: int):
        self.pixels = np.empty((height, width, 3), dtype=np.uint8)
        self.pixels[:] = _to_8bit(_BACKGROUND)
        self.texts: list[tuple[int, int, str, int, tuple]] = []

    def paste(self, picture: np.ndarray, top: int, left: int) -> None:
        h, w = picture.shape[:2]
        self.pixels[top:top + h, left:left + w] = _to_8bit(picture[:, :, :3])

    def fill(self, top: int, left: int, height: int, width: int, colour) -> None:
        self.pixels[top:top + height, left:left + width] = _to_8bit(colour)

    def text(self, x: int, baseline: int, text: str, size: int = 14, colour=_INK) -> None:
        self.texts.append((x, baseline, safe_text(text), size, colour))  # non-UTF-8 names

    def render(self) -> np.ndarray:
        """The sheet's pixels with its labels drawn in (the canvas's own array)."""
        pixels = self.pixels
        if not USE_FONTS:
            return pixels
        fonts = [_font(size) for _, _, _, size, _ in self.texts]
        if None in fonts:
            _no_fonts("no font file in OpenImageIO's font_file_list")
            return pixels
        height, width = pixels.shape[:2]
        for (x, y, text, _, colour), font in zip(self.texts, fonts):
            # the label's coverage (its bounding box only), laid over the canvas in its colour
            left, top, right, bottom = font.getbbox(text, anchor="ls")
            x0, y0, x1, y1 = x + left, y + top, x + right, y + bottom
            rows, columns = slice(max(0, y0), min(height, y1)), slice(max(0, x0), min(width, x1))
            if x1 <= x0 or y1 <= y0 or rows.stop <= rows.start or columns.stop <= columns.start:
                continue
            mask = PILImage.new("L", (x1 - x0, y1 - y0), 0)
            ImageDraw.Draw(mask).text((x - x0, y - y0), text, font=font, fill=255, anchor="ls")
            alpha = np.asarray(mask, dtype=np.float32)[rows.start - y0:rows.stop - y0,
                                                       columns.start - x0:columns.stop - x0]
            region = pixels[rows, columns].astype(np.float32)
            region += (alpha[:, :, None] / np.float32(255)) * (
                np.asarray(colour, np.float32) * np.float32(255) - region)
            pixels[rows, columns] = np.rint(region)
        return pixels


@functools.lru_cache(maxsize=8)
def _font(size: int):
    """OpenImageIO's own sans font (DroidSans, what its ``render_text`` draws with by
    default; else the first font file it lists) at ``size`` pixels, for Pillow (which draws
    a label 5x faster); None when OpenImageIO lists no font file Pillow can read."""
    files = [f for f in oiio.get_string_attribute("font_file_list").split(";")
             if f.lower().endswith((".ttf", ".otf", ".ttc"))]
    for path in sorted(files, key=lambda f: Path(f).name != "DroidSans.ttf"):
        try:
            return ImageFont.truetype(path, size)
        except OSError:
            continue
    return None


@functools.lru_cache(maxsize=1)
def _no_fonts(error: str) -> None:
    log.warning("OpenImageIO found no font: report sheets have no labels (%s)",
                error.strip() or "no font")


def compose_sheet(content: SheetContent, width: int = 960) -> np.ndarray:
    """Lay out a sheet -> (H, width, 3) float32 display pixels in [0, 1] (in steps of 1/255:
    the sheet is composed in 8 bits, as it is written)."""
    return _compose(content, width).astype(np.float32) / np.float32(255)


def _compose(content: SheetContent, width: int) -> np.ndarray:
    """:func:`compose_sheet`'s sheet as uint8 display pixels (H, width, 3)."""
    pad = _PAD
    pic_h, half = picture_box(width)
    before = thumbnail(content.before, pic_h, half)
    after = thumbnail(content.after, pic_h, half)
    row_h = max(before.shape[0], after.shape[0])
    tile_w, tile_h = 104, 78
    per_row = max(1, (width - pad) // (tile_w + pad))
    tiles = content.styles
    tile_rows = max(1, -(-len(tiles) // per_row)) if tiles or content.chart is None else 0
    tile_block = tile_h + 40
    swatch_h = 30
    cell = 24
    chart_h = 0 if content.chart is None else content.chart[0].shape[0] * cell + 22 + 24
    height = (pad + 44 + row_h + 24 + (22 if tile_rows else 0) + tile_rows * tile_block
              + chart_h + len(content.palettes) * (swatch_h + 22) + pad)
    canvas = _Canvas(height, width)
    canvas.text(pad, pad + 16, content.title, 18)
    canvas.text(pad, pad + 38, content.subtitle, 13)
    top = pad + 48
    canvas.paste(before, top, pad)
    canvas.paste(after, top, 2 * pad + half)
    canvas.text(pad, top + row_h + 16, "input", 13)
    canvas.text(2 * pad + half, top + row_h + 16, "graded", 13)
    top += row_h + 24
    if content.chart is not None:  # the look itself: what it does to a colour chart
        canvas.text(pad, top + 14, "the look on a colour chart: before | after (rows: "
                    "lightness, columns: hue, the last one grey)", 13)
        top += 22
        left = pad
        for chart in content.chart:
            big = np.repeat(np.repeat(np.asarray(chart, np.float32), cell, axis=0), cell,
                            axis=1)
            canvas.paste(big, top, left)
            left += big.shape[1] + 2 * pad
        top += content.chart[0].shape[0] * cell + 24
    label = content.styles_label or "styles (weight bars)"
    if content.more_styles:
        label += f", {content.more_styles} more below the threshold"
    if tile_rows:
        canvas.text(pad, top + 14, label, 13)
        top += 22
    for number, tile in enumerate(tiles):
        row, col = divmod(number, per_row)
        y, x = top + row * tile_block, pad + col * (tile_w + pad)
        pic = thumbnail(tile.picture, tile_h, tile_w)
        canvas.paste(pic, y + (tile_h - pic.shape[0]) // 2, x + (tile_w - pic.shape[1]) // 2)
        name = tile.name if len(tile.name) <= 11 else tile.name[:10] + "~"
        if content.styles_label is not None:  # no weights to show
            canvas.text(x, y + tile_h + 26, name, 11)
            continue
        canvas.fill(y + tile_h + 3, x, 8, tile_w, (0.85, 0.85, 0.85))
        canvas.fill(y + tile_h + 3, x, 8, max(1, round(tile_w * min(tile.weight, 1.0))), _BAR)
        canvas.text(x, y + tile_h + 26, f"{name} {tile.weight:.2f}", 11)
    top += tile_rows * tile_block
    label_w = 92
    for name, palette in content.palettes:
        canvas.text(pad, top + 20, name, 13)
        canvas.paste(_swatches(palette, swatch_h, width - 2 * pad - label_w), top,
                     pad + label_w)
        top += swatch_h + 22
    return canvas.render()


def write_sheet(path: str | os.PathLike, content: SheetContent, width: int = 960,
                overwrite: bool = False) -> Path:
    """Compose a sheet and write it as an 8-bit sRGB PNG (atomically; an existing file
    is replaced only with ``overwrite``)."""
    path = Path(path)
    pixels = _compose(content, width)
    path.parent.mkdir(parents=True, exist_ok=True)
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, oiio.UINT8)
    spec.attribute("oiio:ColorSpace", "sRGB")
    spec.attribute("png:compressionLevel", 1)  # zlib's fastest: 2x faster, 4 % larger
    spec.attribute("png:filter", 0x40)  # libpng's average filter alone: 2x faster, 2 % larger
    # encoded in memory and checked, then published by Python: a full disk or a file
    # size limit is an OSError, never a truncated sheet
    publish_bytes(path, encode_png(path, np.ascontiguousarray(pixels), spec),
                  overwrite=overwrite)
    return path
