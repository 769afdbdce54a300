"""Which LUT each frame gets: one per shot, blended over a few frames at each cut.

A LUT applied with tetrahedral (or trilinear) interpolation is linear in its
table entries for a fixed input colour, so blending two LUT tables,
``(1 - s) T_a + s T_b``, gives every pixel exactly the blend of the two
graded colours. At a cut between shot a and shot b the ``blend`` frames
centred on the cut get ``s = (j + 1/2) / blend`` for j = 0 .. blend-1 (the
change of grade is spread evenly, no frame takes more than ``1/blend`` of
it); the window is shortened to at most half of each neighbouring shot.

The schedule is a list of :class:`Segment` (a frame range and the table it
gets); the encoding pass turns each into one ``lut3d`` filter enabled on
exactly that range (``enable='between(n,first,last)'``), so every frame goes
through one LUT and the others pass it on untouched.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Segment", "lut_schedule", "frame_tables"]


@dataclass
class Segment:
    """Frames ``first..last`` (inclusive) get ``table`` ((m, m, m, 3), values in [0, 1]).

    ``shots`` and ``mix`` say how the table was made: ``(k,)`` and ``1.0`` for
    shot k's own LUT, ``(a, b)`` and ``s`` for ``(1 - s) T_a + s T_b``.
    """

    first: int
    last: int
    table: np.ndarray
    shots: tuple[int, ...]
    mix: float = 1.0


def lut_schedule(shots: list[tuple[int, int]], tables: list[np.ndarray],
                 blend: int) -> list[Segment]:
    """Segments covering every frame of ``shots`` ((first, last) per shot), in order.

    Parameters
    ----------
    shots : (first, last) frame indices, consecutive.
    tables : one LUT table per shot.
    blend : frames over which the grade changes at each cut (0 or 1: a hard switch).
    """
    if len(shots) != len(tables):
        raise ValueError("one table per shot")
    lengths = [last - first + 1 for first, last in shots]
    before = [0] * len(shots)  # blended frames at the end of shot k (before cut k+1)
    after = [0] * len(shots)   # blended frames at the start of shot k
    if blend > 1:
        for k in range(1, len(shots)):
            before[k - 1] = min(blend // 2, lengths[k - 1] // 2)
            after[k] = min(blend - blend // 2, lengths[k] // 2)
    segments: list[Segment] = []
    for k, (first, last) in enumerate(shots):
        if k > 0:  # the transition from shot k-1 into shot k
            cut = first
            start, stop = cut - before[k - 1], cut + after[k]
            m = stop - start
            for j, n in enumerate(range(start, stop)):
                s = (j + 0.5) / m
                table = ((1.0 - s) * tables[k - 1] + s * tables[k]).astype(np.float32)
                segments.append(Segment(n, n, table, (k - 1, k), round(s, 6)))
        core_first, core_last = first + after[k], last - before[k]
        if core_last >= core_first:
            segments.append(Segment(core_first, core_last, tables[k], (k,)))
    return segments


def frame_tables(segments: list[Segment], n_frames: int) -> list[np.ndarray]:
    """The table of every frame (for tests and reports)."""
    out: list[np.ndarray | None] = [None] * n_frames
    for seg in segments:
        for n in range(seg.first, min(seg.last, n_frames - 1) + 1):
            out[n] = seg.table
    if any(t is None for t in out):
        raise ValueError("the segments leave frames out")
    return out  # type: ignore[return-value]
