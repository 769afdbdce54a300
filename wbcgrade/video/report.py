"""The report of a graded clip: a PNG contact sheet per shot and ``report.json``.

Folder layout (REPORT_DIR)::

    report.json        the clip, the encoding, the cuts, and per shot its frames,
                       sampled frames, what its grade did (``outcome``: source,
                       strength, change), for a palette grade its ranked weights
                       and loss against the best single style, and timings
                       (VideoResult.as_dict)
    shot-NN.png        per shot: up to six sampled frames before and after its
                       LUT (a grid each), what the grade did, the styles (with
                       their weights for a palette grade), palettes of the
                       frames, the barycenter and the graded frames (the photo
                       sheet's layout, wbcgrade.photos.sheet)

The "after" pictures are the sampled frames through the shot's LUT
(trilinear, in the library), which is what ffmpeg's ``lut3d`` gives to
within interpolation and rounding (tests/video checks the encoded frames
against it). Footage in another space than sRGB (a PQ clip, say) is shown
converted to sRGB, and the barycenter's palette from the working space
(the clip's :class:`~wbcgrade.color.colorspace.ColorEncoding`); ``report.json``
records the spaces and the OpenColorIO config (``color``). All files are
written atomically, and only into a folder whose files they do not replace
(:func:`plan_video_report`) unless asked.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

import numpy as np

from wbcgrade._names import safe_text
from wbcgrade._publish import atomic_path, plan_outputs
from wbcgrade.color.histogram import image_histogram
from wbcgrade.color.mapping.remap import apply_color_map
from wbcgrade.color.palette.fit import NONZERO_THRESHOLD
from wbcgrade.color.presets import StyleSet
from wbcgrade.photos.report import style_pictures
from wbcgrade.photos.sheet import SheetContent, StyleTile, histogram_palette, write_sheet
from wbcgrade.video.workflow import ShotGrade, VideoResult

__all__ = ["contact_grid", "write_video_report"]

#: Sampled frames shown per shot.
FRAMES_PER_SHEET = 6


def contact_grid(frames: list[np.ndarray], columns: int = 3, gap: int = 4) -> np.ndarray:
    """Frames (same size, float in [0, 1]) laid out in a grid, white gaps -> (H, W, 3)."""
    h, w = frames[0].shape[:2]
    columns = min(columns, len(frames))
    rows = -(-len(frames) // columns)
    grid = np.ones((rows * h + (rows - 1) * gap, columns * w + (columns - 1) * gap, 3),
                   dtype=np.float32)
    for k, frame in enumerate(frames):
        r, c = divmod(k, columns)
        grid[r * (h + gap):r * (h + gap) + h, c * (w + gap):c * (w + gap) + w] = frame
    return grid


def _shown(indices: list[int], count: int) -> list[int]:
    if len(indices) <= count:
        return list(indices)
    picks = np.linspace(0, len(indices) - 1, count).round().astype(int)
    return [indices[i] for i in picks]


def _sheet(result: VideoResult, number: int, shot: ShotGrade,
           pictures: dict[str, np.ndarray]) -> SheetContent:
    fps = result.info.fps
    shown = _shown(shot.samples, FRAMES_PER_SHEET)
    before = [result.samples.frames[n][..., :3].astype(np.float32) / 255 for n in shown]
    after = [apply_color_map(frame, shot.table) for frame in before]
    encoding = result.encoding
    before = [encoding.to_display(frame) for frame in before]  # pictures in sRGB
    after = [encoding.to_display(frame) for frame in after]
    weights, names = shot.grade.weights, shot.grade.names
    outcome = shot.grade.outcome
    if outcome is not None and outcome.palette is None:  # a look: what it did, no weights
        title = (f"{safe_text(result.input.name)}  shot {number} of {len(result.shots)}: "
                 f"frames {shot.first}-{shot.last}, {len(shot.samples)} sampled")
        subtitle = outcome.headline().removeprefix("grade: ")
        if outcome.unchanged:
            subtitle += f"  |  essentially unchanged: {outcome.reason}"
        palettes = [("frames", histogram_palette(image_histogram(np.concatenate(before), 16))),
                    ("graded", histogram_palette(image_histogram(np.concatenate(after), 16)))]
        tiles = [StyleTile(name, 0.0, pictures[name]) for name in names if name in pictures]
        return SheetContent(title=title, subtitle=subtitle, before=contact_grid(before),
                            after=contact_grid(after), styles=tiles, palettes=palettes,
                            styles_label=f"styles ({outcome.source.describe(len(names))}; "
                                         "a look has no weights)")
    order = np.argsort(-weights, kind="stable")
    tiles = [StyleTile(names[i], float(weights[i]), pictures[names[i]])
             for i in order if weights[i] >= NONZERO_THRESHOLD]
    palettes = [("frames", histogram_palette(image_histogram(np.concatenate(before), 16)))]
    if shot.grade.barycenter is not None:  # a palette grade's target (a look grade has none)
        target = histogram_palette(shot.grade.barycenter)  # in the working space
        target.colors = encoding.to_display(target.colors, working=True)
        palettes.append(("barycenter", target))
    palettes.append(("graded", histogram_palette(image_histogram(np.concatenate(after), 16))))
    best = shot.fit.best_vertex
    title = (f"{safe_text(result.input.name)}  shot {number} of {len(result.shots)}: frames "
             f"{shot.first}-{shot.last} ({shot.first / fps:.2f}-{(shot.last + 1) / fps:.2f} s), "
             f"{len(shot.samples)} sampled")
    subtitle = (f"loss {shot.fit.loss:.4g}  |  best single style {names[best]}: "
                f"{shot.fit.vertex_losses[best]:.4g}  |  {shot.fit.n_nonzero} of {len(names)} "
                f"weights >= {NONZERO_THRESHOLD:g}  |  frames shown: "
                + " ".join(str(n) for n in shown))
    return SheetContent(title=title, subtitle=subtitle, before=contact_grid(before),
                        after=contact_grid(after), styles=tiles, palettes=palettes,
                        more_styles=len(names) - len(tiles))


def plan_video_report(report_dir: str | os.PathLike, inputs=(),
                      overwrite: bool = False) -> None:
    """Check before any work that a video report may be written into ``report_dir``:
    ``report.json`` and any shot sheet already there are refused unless ``overwrite``
    (how many shots there will be is known only after the scan)."""
    report_dir = Path(report_dir)
    existing = sorted(report_dir.glob("shot-*.png")) if report_dir.is_dir() else []
    plan_outputs([report_dir / "report.json", *existing], inputs, overwrite, root=report_dir,
                 make_folders=True)


def write_video_report(report_dir: str | os.PathLike, result: VideoResult,
                       styles: StyleSet, overwrite: bool = False,
                       stack: contextlib.ExitStack | None = None) -> Path:
    """Write the sheets and ``report.json`` into ``report_dir`` -> the JSON's path
    (existing files replaced only with ``overwrite``).

    With ``stack``, every file is written to a temporary file entered on it
    (:func:`wbcgrade._publish.atomic_path`) and published only when the caller
    closes the stack without an exception: the report goes out with the clip or
    not at all. A report folder this call made is removed again on failure.
    """
    report_dir = Path(report_dir)
    with contextlib.ExitStack() as own:
        stack = stack if stack is not None else own
        if not report_dir.is_dir():
            report_dir.mkdir(parents=True)
            stack.push(lambda kind, *_: kind is not None and _remove_empty(report_dir))
        pictures = style_pictures(styles)
        document = result.as_dict()
        document["styles"] = {"source": styles.source, "names": list(styles.names)}
        for number, shot in enumerate(result.shots, start=1):
            name = f"shot-{number:02d}.png"
            tmp = stack.enter_context(atomic_path(report_dir / name, overwrite=overwrite))
            write_sheet(tmp, _sheet(result, number, shot, pictures), overwrite=True)
            document["shots"][number - 1]["sheet"] = name
        path = report_dir / "report.json"
        tmp = stack.enter_context(atomic_path(path, overwrite=overwrite))
        with open(tmp, "w", encoding="utf-8") as handle:
            json.dump(document, handle, indent=2, default=float)
    return path


def _remove_empty(folder: Path) -> None:
    with contextlib.suppress(OSError):
        folder.rmdir()
