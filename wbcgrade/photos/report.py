"""The palette weight report: report.json, weights.csv, PNG sheets and index.html.

Folder layout (REPORT_DIR)::

    report.json          styles, options, and one entry per photo (see FileResult.as_dict)
    weights.csv          one row per photo, one column per style (plus loss columns)
    sheets/<photo>.png   one sheet per graded photo (see wbcgrade.photos.sheet)
    photos/<photo>.json  the entry of each photo, reused when a rerun skips the photo
    index.html           self-contained page: the weight table and every sheet
                         (inline CSS, sheets referenced by relative paths)

All files are written atomically. They are planned before any work
(:func:`plan_report`, through :func:`wbcgrade._publish.plan_outputs`): a
report never replaces a file it did not write unless ``overwrite``.
"""

from __future__ import annotations

import csv
import html
import io
import json
import os
import re
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wbcgrade._publish import atomic_path, plan_outputs, publish_bytes
from wbcgrade.color.colorspace import ColorEncoding, config_info, convert, default_working_space
from wbcgrade.color.histogram import image_histogram
from wbcgrade.color.io.images import read_image
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.outcome import GradeSource, change_words
from wbcgrade.color.palette.fit import NONZERO_THRESHOLD
from wbcgrade.color.presets import StyleSet
from wbcgrade.errors import InputError
from wbcgrade.photos.results import BatchResult, FileResult
from wbcgrade.photos.sheet import (
    Palette,
    SheetContent,
    StyleTile,
    fit_size,
    histogram_palette,
    picture_box,
    thumbnail,
    write_sheet,
)

if TYPE_CHECKING:  # (a report of a batch's results loads no grade)
    from wbcgrade.photos.graded import GradeReport, PhotoGrade

__all__ = ["style_pictures", "report_paths", "own_report", "plan_report", "report_overwrite",
           "write_report", "report_entries", "report_from_grade", "sheet_content",
           "sheet_from_files", "sheet_picture", "sheet_path", "palette_record", "look_chart",
           "chart_record"]

#: The files of a report folder besides the per-photo ones.
INDEX_FILES = ("report.json", "weights.csv", "index.html")


def _write_text(path: Path, text: str, overwrite: bool) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path, overwrite=overwrite) as tmp, \
            open(tmp, "w", encoding="utf-8", errors="surrogateescape", newline="") as handle:
        handle.write(text)  # a non-UTF-8 file name keeps its own bytes (links still work)


def sheet_path(relative: str) -> Path:
    """A photo's sheet, relative to the report folder."""
    return Path("sheets") / f"{relative}.png"


def report_paths(report_dir: str | os.PathLike, relatives: list[str]) -> list[Path]:
    """Every file a report of these photos (paths relative to the graded folder) writes."""
    report_dir = Path(report_dir)
    return ([report_dir / name for name in INDEX_FILES]
            + [_record_path(report_dir, rel) for rel in relatives]
            + [report_dir / sheet_path(rel) for rel in relatives])


def own_report(report_dir: str | os.PathLike | None) -> bool:
    """Whether ``report_dir`` holds a report wbcgrade wrote (its ``report.json`` says so):
    a batch run again with the same ``--report`` folder updates it, as it resumes its
    photos, instead of refusing its files."""
    if report_dir is None:
        return False
    try:
        document = json.loads((Path(report_dir) / "report.json").read_text("utf-8"))
    except (OSError, ValueError, RecursionError):  # (nested too deep)
        return False
    return isinstance(document, dict) and document.get("format") == "wbcgrade-report"


def plan_report(report_dir: str | os.PathLike, relatives: list[str], inputs=(),
                overwrite: bool = False) -> list[Path]:
    """Check before any work that a report of these photos may be written into
    ``report_dir`` (:func:`wbcgrade._publish.plan_outputs`; every file stays in the
    folder, none is an input, none exists unless ``overwrite``)."""
    report_dir = Path(report_dir)
    if report_dir.exists() and not report_dir.is_dir():
        raise InputError(f"{report_dir}: the report folder is a file")
    paths = plan_outputs(report_paths(report_dir, relatives), inputs,
                         report_overwrite(report_dir, overwrite), root=report_dir,
                         make_folders=True)
    report_dir.mkdir(parents=True, exist_ok=True)
    publish_bytes(report_dir / UNFINISHED_FILE, b"a report is being written here\n",
                  sync=False)  # removed when index.html is written (write_report)
    return paths


#: Kept in a report folder while its report is written: a report that was stopped is
#: finished by the next run without ``--overwrite`` (its own files are replaced).
UNFINISHED_FILE = ".wbcgrade-report-unfinished"


def report_overwrite(report_dir: str | os.PathLike, overwrite: bool = False) -> bool:
    """Whether the files of a report into ``report_dir`` may replace existing ones:
    ``overwrite``, or the folder holds a report that was stopped before it was written in
    full (:data:`UNFINISHED_FILE`)."""
    return bool(overwrite) or (Path(report_dir) / UNFINISHED_FILE).is_file()


def style_pictures(styles: StyleSet, size: int = 96) -> dict[str, np.ndarray]:
    """A small display picture per style: the photo itself for a style folder,
    else (presets hold histograms only) a block of the style's palette swatches.

    Returns {name: (h, w, 3) float32 in [0, 1]}.
    """
    working = styles.working_space
    palette_spaces = (None if working == default_working_space()
                      else ColorEncoding.of(None, working))
    folder = Path(styles.source) if styles.source else None
    pictures = {}
    files = {}
    if folder is not None and folder.is_dir():
        files = {p.stem: p for p in sorted(folder.iterdir()) if p.is_file()}
    for name, hist in zip(styles.names, styles.histograms):
        picture = None
        if name in files:
            try:  # as it looks (a JPEG decoded small)
                picture = sheet_picture(files[name], size, size * 4 // 3)
            except (ValueError, OSError):
                picture = None
        if picture is None:
            palette = histogram_palette(hist, k=6)
            if palette_spaces is not None:  # the styles' histograms are in another space
                palette.colors = palette_spaces.to_display(palette.colors, working=True)
            picture = np.zeros((size, size * 4 // 3, 3), dtype=np.float32)
            edges = np.round(np.concatenate([[0], np.cumsum(palette.shares)]) * size).astype(int)
            for j, colour in enumerate(palette.colors):
                picture[edges[j]:edges[j + 1]] = colour
        pictures[name] = picture
    return pictures


def palette_record(grade, encoding: ColorEncoding) -> dict | None:
    """The main colours of the palette a grade aimed at (its barycenter), display-encoded,
    as JSON (``{"colors": [[r, g, b], ...], "shares": [...]}``); None when the grade
    has no barycenter (a look)."""
    if grade.barycenter is None:
        return None
    palette = histogram_palette(grade.barycenter)  # in the working space
    colors = encoding.to_display(palette.colors, working=True)
    return {"colors": np.round(np.asarray(colors, np.float64), 4).tolist(),
            "shares": np.round(np.asarray(palette.shares, np.float64), 4).tolist()}


def look_chart() -> np.ndarray:
    """A colour chart, (6, 13, 3) sRGB display colours: five rows of twelve hues at five
    lightnesses (then a grey of each lightness), and a row of thirteen greys from black to
    white. What a look does to it shows the look itself (tone, tint, saturation)."""
    import colorsys

    rows = []
    for value in (0.25, 0.4, 0.55, 0.7, 0.85):
        row = [colorsys.hsv_to_rgb(h / 12, 0.55, value) for h in range(12)]
        rows.append([*row, (value * 0.85,) * 3])
    rows.append([(g / 12,) * 3 for g in range(13)])
    return np.asarray(rows, dtype=np.float32)


def chart_record(grade, encoding: ColorEncoding) -> dict | None:
    """The :func:`look_chart` through a look grade's colour map, as the photo's space
    shows it on screen (``{"after": [[[r, g, b], ...], ...]}``, display sRGB); None for a
    palette grade (its sheet shows weights)."""
    outcome = getattr(grade, "outcome", None)
    if outcome is None or outcome.palette is not None:
        return None
    chart = look_chart()
    values = chart.reshape(-1, 3)
    if encoding.input != default_working_space():
        values = convert(values, default_working_space(), encoding.input)
    encoded, state = encoding.encode(values)
    graded = encoding.decode(grade.apply(np.ascontiguousarray(encoded, np.float32)), state)
    after = encoding.to_display(graded).reshape(chart.shape)
    return {"after": np.round(np.asarray(after, np.float64), 4).tolist()}


def _chart(record: dict | None) -> tuple[np.ndarray, np.ndarray] | None:
    if not record or "after" not in record:
        return None
    after = np.asarray(record["after"], np.float32)
    chart = look_chart()
    return (chart, after) if after.shape == chart.shape else None


def _palette(record: dict | None):
    if not record:
        return None
    return Palette(np.asarray(record["colors"], np.float64), np.asarray(record["shares"]))


def sheet_content(result: FileResult, graded: PhotoGrade,
                  style_pictures: dict[str, np.ndarray] | None = None):
    """The SheetContent of a graded photo (pictures, style tiles, palettes, losses)."""
    image, encoding = graded.image, graded.encoding
    color = [c for c in range(graded.pixels.shape[2]) if c != graded.alpha_channel][:3]
    # pictures and palettes shown in sRGB, whatever the photo's space
    before = encoding.to_display(image.rgb())
    after = encoding.to_display(np.repeat(graded.pixels[:, :, color], 3 // len(color), axis=2))
    if result.chart is None:
        result.chart = chart_record(graded.grade, encoding)
    return _content(result, before, after, _palette(palette_record(graded.grade, encoding)),
                    style_pictures)


def sheet_from_files(result: FileResult, style_pictures: dict[str, np.ndarray] | None = None):
    """The SheetContent of a photo a batch graded, from its files (``result.source``, the
    photo; ``result.output``, the graded copy) and its record (weights, losses, the
    palette aimed at): nothing is graded. Raises InputError when a file is unreadable."""
    pictures = [sheet_picture(path, *picture_box()) for path in (result.source, result.output)]
    return _content(result, *pictures, _palette(result.palette), style_pictures)


#: The size a JPEG is decoded at for a sheet, at least (its pictures are at most 300 x 462):
#: the decoder's DCT scaling to this, then one filtered resize.
_SHEET_READ = 480


def sheet_picture(path: str | os.PathLike, max_h: int, max_w: int) -> np.ndarray:
    """A photo as a sheet shows it: display sRGB, fitting in ``max_h`` x ``max_w``.

    A JPEG without an ICC profile (sRGB) is decoded at a fraction of its size (the
    decoder's DCT scaling: a tenth of the time, and no full-size arrays) and resized in 8
    bits (the sheet is 8-bit); any other file is read as ``apply`` reads it and made small
    before its colours are converted. Raises OSError or ValueError (InputError) when the
    file cannot be read."""
    from PIL import ExifTags, ImageOps
    from PIL import Image as PILImage


    try:
        with PILImage.open(path) as image:
            if image.format == "JPEG" and image.mode in ("RGB", "L") \
                    and not image.info.get("icc_profile"):
                image.draft("RGB", (_SHEET_READ, _SHEET_READ))
                turned = image.getexif().get(ExifTags.Base.Orientation, 1) != 1
                upright = ImageOps.exif_transpose(image) if turned else image  # (else a copy)
                if upright.mode != "RGB":
                    upright = upright.convert("RGB")
                height, width = fit_size(upright.height, upright.width, max_h, max_w)
                small = upright.resize((width, height), PILImage.Resampling.LANCZOS)
                return np.asarray(small, dtype=np.float32) / np.float32(255)
    except (OSError, ValueError, SyntaxError):  # not for Pillow: read as apply reads it
        pass
    image = read_image(path)
    small = thumbnail(image.rgb(), max_h, max_w)
    return np.asarray(ColorEncoding.for_image(image).to_display(small), np.float32)


#: The pixels of a sheet's picture its palette is read from, at most.
_PALETTE_PIXELS = 16384


def _content(result: FileResult, before: np.ndarray, after: np.ndarray, target,
             style_pictures: dict[str, np.ndarray] | None):
    small_before = thumbnail(before, *picture_box())  # as the sheet shows them
    small_after = thumbnail(after, *picture_box())
    pictures = {} if style_pictures is None else style_pictures  # (made on first use)
    bins = 16
    # the main colours of the pictures as shown (every third pixel or so, about 16000: the
    # same eight colours, at a third of the cost of every other one)
    shown = [histogram_palette(image_histogram(small, bins, max_pixels=_PALETTE_PIXELS))
             for small in (small_before, small_after)]
    outcome = result.grade_outcome
    if outcome is not None and outcome.palette is None:  # a look: what it did, no weights
        # the style photos a look was read from (a preset's own look: not its photos)
        tiles = ([] if outcome.source in (GradeSource.PRESET_LOOK, GradeSource.SAVED) else
                 [StyleTile(name, 0.0, pictures.get(name, np.full((8, 8, 3), 0.5, np.float32)))
                  for name in result.names])
        subtitle = outcome.headline().removeprefix("grade: ")
        if outcome.unchanged:
            subtitle += f"  |  essentially unchanged: {outcome.reason}"
        return SheetContent(title=result.relative, subtitle=subtitle, before=small_before,
                            after=small_after, styles=tiles,
                            palettes=[("input", shown[0]), ("output", shown[1])],
                            styles_label="the style photos the look was read from",
                            chart=_chart(result.chart))
    order = sorted(range(len(result.weights)), key=lambda i: -result.weights[i])
    tiles = [StyleTile(result.names[i], result.weights[i],
                       pictures.get(result.names[i], np.full((8, 8, 3), 0.5, np.float32)))
             for i in order if result.weights[i] >= NONZERO_THRESHOLD]
    palettes = [("input", shown[0]), *([("barycenter", target)] if target is not None else []),
                ("output", shown[1])]
    best = int(np.argmin(result.vertex_losses))
    subtitle = (f"loss {result.loss:.4g}  |  best single style {result.names[best]}: "
                f"{result.vertex_losses[best]:.4g}  |  {result.n_nonzero} of {len(result.names)} "
                f"weights >= {NONZERO_THRESHOLD:g}  |  {result.timings.get('total', 0):.1f} s")
    return SheetContent(title=result.relative, subtitle=subtitle, before=small_before,
                        after=small_after, styles=tiles, palettes=palettes,
                        more_styles=len(result.weights) - len(tiles))


def _record_path(report_dir: Path, relative: str) -> Path:
    return report_dir / "photos" / f"{relative}.json"


def report_entries(report_dir: str | os.PathLike, result: BatchResult) -> list[dict]:
    """One entry per photo; skipped photos reuse the entry a previous run saved."""
    report_dir = Path(report_dir)
    entries = []
    for item in result.results:
        entry = item.as_dict()
        if item.status == "skipped":
            try:
                previous = json.loads(_record_path(report_dir, item.relative).read_text("utf-8"))
                if isinstance(previous, dict) and ("weights" in previous
                                                   or "outcome" in previous):
                    entry = {**previous, "status": "skipped"}
            except (OSError, ValueError, RecursionError):  # (nested too deep)
                pass
        entries.append(entry)
    return entries


def _weights_row(entry: dict, names: list[str]) -> list:
    """A photo's row: its weights and loss for a palette grade (empty cells for a look
    grade, which has none), then what the grade did (source, strength, change)."""
    weights = {w["style"]: w["weight"] for w in entry.get("weights", [])}
    best = entry.get("best_single_style") or {}
    outcome = entry.get("outcome") or {}
    return ([entry["photo"], entry["status"]] + [weights.get(n, "") for n in names]
            + [entry.get("loss", ""), best.get("style", ""), best.get("loss", ""),
               entry.get("nonzero_weights", ""), outcome.get("source", ""),
               outcome.get("strength", ""), outcome.get("mean_change_255", ""),
               {True: "yes", False: "no"}.get(outcome.get("unchanged"), "")])


_FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value):
    """A text cell made safe from spreadsheet formula injection (OWASP "CSV Injection").

    Text starting with ``=``, ``+``, ``-``, ``@``, tab or carriage return gets a
    leading single quote, so spreadsheets show it as text instead of running
    it; the csv module quotes the cell when needed and doubles inner quotes.
    Numbers are left as they are (a negative loss stays a number).
    """
    if isinstance(value, str) and value.startswith(_FORMULA_STARTS):
        return "'" + value
    return value


def _csv_text(entries: list[dict], names: list[str]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    rows = [["photo", "status", *names, "loss", "best_single_style", "best_single_loss",
             "nonzero_weights", "source", "strength", "mean_change_255", "unchanged"]]
    rows += [_weights_row(entry, names) for entry in entries]
    for row in rows:
        writer.writerow([csv_cell(cell) for cell in row])
    return out.getvalue()


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px;color:#222;
background:#fafaf8}
h1{font-size:20px;margin:0 0 4px}p.meta{color:#666;margin:0 0 16px;font-size:13px}
table{border-collapse:collapse;font-size:12px;margin-bottom:24px}
th,td{border:1px solid #ddd;padding:3px 6px;text-align:right}
th{background:#eee;position:sticky;top:0}td.name{text-align:left}
td.failed{color:#b00;text-align:left}
figure{margin:0 0 28px}figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:13px;color:#444;margin-bottom:4px}
"""


#: Characters a name may hold that would reorder or hide the text around it in a page
#: (bidirectional controls: U+202E shows "gpj.exe" as "exe.jpg") or are not text at all.
_UNSAFE_TEXT = re.compile("[\u0000-\u001f\u007f-\u009f\u061c\u200e\u200f\u2028\u2029"
                          "\u202a-\u202e\u2066-\u2069\ufeff]")


def _esc(value: object) -> str:
    """``value`` as HTML text: escaped, and its bidirectional and control characters
    written visibly as ``\\uXXXX`` (an entity would still act on the page)."""
    return _UNSAFE_TEXT.sub(lambda m: f"\\u{ord(m.group()):04x}", html.escape(str(value)))


def _url(path: str) -> str:
    """A relative file name as a link: percent-encoded (its own bytes when not UTF-8), so
    no character of it acts on the page."""
    from urllib.parse import quote

    return quote(path, safe="/", errors="surrogateescape")


def _look_index_html(entries: list[dict], meta: dict) -> str:
    """The page of a report whose grades are all looks: per photo where the look came
    from, its strength and how much the colours moved; then each photo's sheet (before and
    after, the look on a colour chart)."""
    esc = _esc
    rows = []
    for entry in entries:
        photo = esc(entry["photo"])
        if entry.get("sheet"):
            photo = f'<a href="#{esc(entry["photo"])}">{photo}</a>'
        outcome = entry.get("outcome")
        if not outcome:
            rows.append(f'<tr><td class="name">{photo}</td><td class="failed" colspan="4">'
                        f'{esc(entry["status"])}: {esc(entry.get("error", ""))}</td></tr>')
            continue
        note = ""
        if outcome.get("unchanged") or outcome.get("faint"):
            note = esc(str(outcome.get("reason") or ""))
        change = change_words(float(outcome.get("mean_change_255", 0)))
        rows.append(f'<tr><td class="name">{photo}</td>'
                    f'<td class="name">{esc(str(outcome.get("source_text", "")))}</td>'
                    f'<td>{float(outcome.get("strength", 0)):.2f}</td>'
                    f'<td class="name">{esc(change)}</td><td class="name">{note}</td></tr>')
    figures, summary = _figures_and_summary(entries, meta)
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
            f"<title>wbcgrade look report</title><style>{_CSS}</style></head><body>"
            f"<h1>wbcgrade look report</h1><p class=\"meta\">{summary}. Strength: how much of "
            "the look was applied (1: all of it); change: how far each photo's colours moved, "
            "in percent of the tonal range. Each sheet shows the photo before and after, and "
            "the look on a colour chart.</p>"
            "<table><thead><tr><th>photo</th><th>where the look came from</th>"
            "<th>strength</th><th>change</th><th>note</th></tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table>{figures}</body></html>\n")


def _figures_and_summary(entries: list[dict], meta: dict) -> tuple[str, str]:
    """The index page's figures (a sheet per photo) and its one-line summary of ``meta``."""
    esc = _esc
    figures = "".join(
        f'<figure id="{esc(e["photo"])}"><figcaption>{esc(e["photo"])}</figcaption>'
        f'<img src="{_url(e["sheet"])}" alt="sheet of {esc(e["photo"])}" loading="lazy">'
        f"</figure>" for e in entries if e.get("sheet"))
    return figures, esc(", ".join(f"{k}: {v}" for k, v in meta.items() if k != "options"))


def _index_html(entries: list[dict], names: list[str], meta: dict) -> str:
    if not any("weights" in entry for entry in entries) and any(
            entry.get("outcome") for entry in entries):  # looks only: no weights to show
        return _look_index_html(entries, meta)
    esc = _esc
    rows = []
    for entry in entries:
        weights = {w["style"]: w["weight"] for w in entry.get("weights", [])}
        photo = esc(entry["photo"])
        if entry.get("sheet"):
            photo = f'<a href="#{esc(entry["photo"])}">{photo}</a>'
        outcome = entry.get("outcome")
        if "weights" not in entry and outcome:  # a look grade: what it did, no weights
            said = (f'{esc(str(outcome.get("source_text", "")))}, strength '
                    f'{float(outcome.get("strength", 0)):.2f}, mean change '
                    f'{float(outcome.get("mean_change_255", 0)):.1f}/255')
            if outcome.get("unchanged"):
                said += f'; essentially unchanged: {esc(str(outcome.get("reason", "")))}'
            rows.append(f'<tr><td class="name">{photo}</td>'
                        f'<td class="name" colspan="{len(names) + 2}">{said}</td></tr>')
            continue
        if "weights" not in entry:
            rows.append(f'<tr><td class="name">{photo}</td>'
                        f'<td class="failed" colspan="{len(names) + 2}">'
                        f'{esc(entry["status"])}: {esc(entry.get("error", ""))}</td></tr>')
            continue
        cells = []
        for name in names:
            w = float(weights.get(name, 0.0))
            shade = f"rgba(51,115,191,{min(1.0, w):.2f})"
            colour = "#fff" if w > 0.5 else "#222"
            cells.append(f'<td style="background:{shade};color:{colour}">{w:.3f}</td>')
        best = entry.get("best_single_style") or {}
        rows.append(f'<tr><td class="name">{photo}</td>{"".join(cells)}'
                    f'<td>{entry.get("loss", 0):.4g}</td>'
                    f'<td>{esc(str(best.get("style", "")))} {best.get("loss", 0):.4g}</td></tr>')
    head = "".join(f"<th>{esc(n)}</th>" for n in names)
    figures, summary = _figures_and_summary(entries, meta)
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
            f"<title>wbcgrade report</title><style>{_CSS}</style></head><body>"
            f"<h1>wbcgrade palette weight report</h1><p class=\"meta\">{summary}. Weights "
            f"&ge; {NONZERO_THRESHOLD:g} count as non-zero; loss = fit loss of the barycenter, "
            f"compared with the best single style.</p>"
            f'<table><thead><tr><th>photo</th>{head}<th>loss</th><th>best single style</th>'
            f"</tr></thead><tbody>{''.join(rows)}</tbody></table>{figures}</body></html>\n")


def write_report(report_dir: str | os.PathLike, result: BatchResult, styles: StyleSet,
                 options: GradeOptions | dict, mode: str = "per-photo",
                 overwrite: bool = False, color: dict | None = None) -> Path:
    """Write report.json, weights.csv, index.html (and per-photo records) into ``report_dir``.

    ``options``: the grade's options, or their flat names as a batch recorded them.
    ``color``: the OpenColorIO config and working space the photos were graded with (a
    batch's records say), else those in use now.
    Sheets are written by the tasks themselves (``BatchContext.sheet_dir``).
    Existing files are replaced only with ``overwrite`` (:func:`plan_report`
    checked them before any work). Returns the path of report.json.
    """
    report_dir = Path(report_dir)
    report_dir.mkdir(parents=True, exist_ok=True)
    overwrite = report_overwrite(report_dir, overwrite)
    entries = report_entries(report_dir, result)
    records = [(_record_path(report_dir, item.relative), json.dumps(entry, indent=1))
               for item, entry in zip(result.results, entries) if item.status == "graded"]
    # several at once: each waits on the disk (its flush), not on the interpreter
    with ThreadPoolExecutor(max_workers=max(1, min(4, len(records)))) as pool:
        list(pool.map(lambda record: _write_text(*record, overwrite), records))
    names = list(styles.names)
    meta = {"styles": styles.source, "mode": mode, "photos": len(entries),
            "graded": result.count("graded"), "skipped": result.count("skipped"),
            "failed": result.count("failed"), "time_s": round(result.time_s, 2)}
    flat = options.flat() if isinstance(options, GradeOptions) else dict(options)
    if color is None:
        color = {**config_info(), "working_space": default_working_space()}
    color = {**{k: v for k, v in color.items() if k != "working_space"},
             "input_space": flat.get("input_space") or "what each file says",
             "working_space": flat.get("working_space") or color["working_space"]}
    document = {"format": "wbcgrade-report", "version": 1, **meta, "color": color,
                "style_names": names, "nonzero_threshold": NONZERO_THRESHOLD,
                "options": flat, "ignored": result.ignored, "photos": entries}
    if result.series is not None:
        document["series_weights"] = dict(zip(names, map(float, result.series.weights)))
        document["series_loss"] = float(result.series.loss)
    path = report_dir / "report.json"
    _write_text(path, json.dumps(document, indent=2, default=float), overwrite)
    _write_text(report_dir / "weights.csv", _csv_text(entries, names), overwrite)
    _write_text(report_dir / "index.html", _index_html(entries, names, meta), overwrite)
    (report_dir / UNFINISHED_FILE).unlink(missing_ok=True)  # the report is whole
    return path


def report_from_grade(report_dir: str | os.PathLike, graded: GradeReport, styles: StyleSet,
                      options: GradeOptions, overwrite: bool = False) -> Path:
    """The report of one photo graded by ``wbcgrade apply`` (``apply --report``).

    ``graded`` is what :func:`wbcgrade.photos.workflow.grade_file` returned:
    its fit summary gives the loss, the single-style losses and how the
    weights were found, its pixels the sheet. Returns the path of report.json.
    """
    report_dir = Path(report_dir)
    fit = graded.fit
    result = FileResult(graded.photo.name, str(graded.photo),
                        None if graded.output is None else str(graded.output), "graded",
                        names=list(styles.names),
                        weights=[float(w) for w in graded.grade.weights],
                        loss=float(fit.loss), vertex_losses=[float(v) for v in fit.vertex_losses],
                        start=graded.fit_start, timings=dict(graded.timings),
                        color=graded.color,
                        own_style=graded.grade.own_style,
                        outcome=None if graded.outcome is None else graded.outcome.as_dict())
    sheet = sheet_path(result.relative)
    write_sheet(report_dir / sheet, sheet_content(result, graded.graded, style_pictures(styles)),
                overwrite=overwrite)
    result.sheet = sheet.as_posix()
    batch = BatchResult([result], [], graded.timings.get("total", 0.0))
    return write_report(report_dir, batch, styles, options, "apply", overwrite)
