"""Sampling a clip for the fit, and finding its cuts, in one decoding pass.

:func:`scan` decodes every frame once, small (at most ``max_side`` pixels
on the long side, area-averaged, converted to RGB with the clip's own matrix
and range), keeps one frame every ``sample_every`` seconds and, with
``cuts=True``, the first frame of every shot, and measures how much each
frame's colours differ from the previous one's: half the L1 distance between
their coarse (8 x 8 x 8) RGB histograms, in [0, 1] (0: the same colours,
1: no colour in common). A slow pan or zoom moves few colours from one bin to
another (on the shipped clip at most ~0.1); a hard cut between two scenes
replaces most of them (~0.5 and more). A cut is declared where the distance
exceeds ``cut_threshold`` and at least ``min_shot`` seconds have passed
since the previous one (a flash or a fast whip pan does not split a clip
into a dozen shots).

Histogram differences rather than ffmpeg's ``scdet``: the frames are
decoded here anyway (for the samples), the cut is located to the exact frame
index the encoding pass's ``lut3d`` filters count (``n``), and a colour
grade cares about colour changes, not about motion.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wbcgrade.errors import InputError, OptionError
from wbcgrade.video.defaults import DEFAULT_CUT_THRESHOLD, DEFAULT_MIN_SHOT, DEFAULT_SAMPLE_EVERY
from wbcgrade.video.ffmpeg import VideoInfo, decode_frames

__all__ = ["Samples", "scan", "analysis_size", "DEFAULT_SAMPLE_EVERY", "DEFAULT_CUT_THRESHOLD",
           "DEFAULT_MIN_SHOT", "DEFAULT_MAX_SIDE"]

#: Long side of the decoded samples, pixels.
DEFAULT_MAX_SIDE = 256


@dataclass
class Samples:
    """What :func:`scan` found.

    Attributes
    ----------
    frames : {frame index: (h, w, 3) uint8 RGB} the sampled frames ((h, w, 4) RGBA for a
        clip with alpha: transparent pixels do not count in the palettes).
    cuts : frame indices where a new shot starts (0 not included).
    distances : (n_frames,) colour distance of each frame to the previous (0 for the first).
    n_frames : frames decoded.
    """

    frames: dict[int, np.ndarray] = field(default_factory=dict)
    cuts: list[int] = field(default_factory=list)
    distances: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_frames: int = 0

    def shots(self) -> list[tuple[int, int]]:
        """(first, last) frame index of every shot, in order."""
        starts = [0, *self.cuts]
        ends = [c - 1 for c in self.cuts] + [self.n_frames - 1]
        return list(zip(starts, ends))


def analysis_size(info: VideoInfo, max_side: int = DEFAULT_MAX_SIDE) -> tuple[int, int]:
    """(width, height) of the decoded samples: the frame shrunk to ``max_side`` at most."""
    scale = min(1.0, max_side / max(info.width, info.height))
    return max(1, round(info.width * scale)), max(1, round(info.height * scale))


def _coarse_histogram(frame: np.ndarray) -> np.ndarray:
    q = (frame >> 5).astype(np.int32)
    index = (q[..., 0] * 64 + q[..., 1] * 8 + q[..., 2]).ravel()
    return np.bincount(index, minlength=512) / index.size


def scan(path: str | os.PathLike, info: VideoInfo, sample_every: float = DEFAULT_SAMPLE_EVERY,
         cuts: bool = False, cut_threshold: float = DEFAULT_CUT_THRESHOLD,
         min_shot: float = DEFAULT_MIN_SHOT, max_side: int = DEFAULT_MAX_SIDE,
         progress: Callable[[int], None] | None = None) -> Samples:
    """Decode a clip once, small: sampled frames, colour distances and (optionally) cuts.

    Parameters
    ----------
    sample_every : seconds between sampled frames (the first frame is always one).
    cuts : detect cuts; the first frame of every shot is then sampled too.
    cut_threshold : colour distance (0..1) above which a frame starts a new shot.
    min_shot : seconds a shot lasts at least.
    progress : called with the number of frames decoded so far.
    """
    if not (np.isfinite(sample_every) and sample_every > 0):
        raise OptionError("{sample_every} must be a positive number of seconds", "sample_every")
    if not 0 < cut_threshold < 1:
        raise OptionError("{cut_threshold} must be between 0 and 1", "cut_threshold")
    step = max(1, round(sample_every * info.fps))
    shortest = max(1, round(min_shot * info.fps))
    width, height = analysis_size(info, max_side)
    out = Samples()
    distances = []
    previous = None
    for n, frame in enumerate(decode_frames(path, info, width, height, alpha=info.alpha)):
        hist = _coarse_histogram(frame)
        distance = 0.0 if previous is None else 0.5 * float(np.abs(hist - previous).sum())
        previous = hist
        distances.append(distance)
        last_start = out.cuts[-1] if out.cuts else 0
        if cuts and n > 0 and distance > cut_threshold and n - last_start >= shortest:
            out.cuts.append(n)
            out.frames[n] = frame.copy()
        elif n % step == 0:
            out.frames[n] = frame.copy()
        if progress is not None:
            progress(n + 1)
    out.n_frames = len(distances)
    out.distances = np.asarray(distances)
    if out.n_frames == 0:
        raise InputError(f"{info.path}: no frame could be decoded")
    if out.cuts and out.n_frames - out.cuts[-1] < shortest:  # a last shot too short to keep
        out.cuts.pop()
    return out
