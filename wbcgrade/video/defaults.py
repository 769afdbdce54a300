"""Default settings of ``wbcgrade video``, in one light module (no numpy, no ffmpeg).

:mod:`wbcgrade.video.workflow` and :mod:`wbcgrade.video.sampling` use these
and re-export them; the command line reads them here, so that ``--help``
imports neither the colour library nor numba.
"""

from __future__ import annotations

#: --codec NAME -> (ffmpeg encoder, containers it may go in).
CODECS = {
    "x264": ("libx264", (".mp4", ".m4v", ".mov", ".mkv")),
    "x265": ("libx265", (".mp4", ".m4v", ".mov", ".mkv")),
    "prores": ("prores_ks", (".mov", ".mkv")),
    "ffv1": ("ffv1", (".mkv", ".avi")),
}
#: Codecs that store alpha so that ffmpeg reads it back (libx265's yuva420p does not:
#: the HEVC decoder drops the alpha layer).
ALPHA_CODECS = ("prores", "ffv1")
#: The codec when --codec is not given.
DEFAULT_CODEC = "x264"
#: x264/x265 constant rate factor (18: visually lossless for x264).
DEFAULT_CRF = 18
#: Frames over which the grade changes at a cut (--per-shot).
DEFAULT_BLEND = 8
#: Seconds between sampled frames.
DEFAULT_SAMPLE_EVERY = 1.0
#: Colour distance between consecutive frames above which a cut is declared.
DEFAULT_CUT_THRESHOLD = 0.35
#: Shortest shot, seconds.
DEFAULT_MIN_SHOT = 0.5
