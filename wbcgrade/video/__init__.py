"""Grading footage: one grade per clip (or per shot) applied by ffmpeg as a 3-D LUT.

Layers (each imports only those above it):

- :mod:`wbcgrade.video.ffmpeg`: the ``imageio-ffmpeg`` binary; probing, decoding
  to RGB with the clip's own matrix and range, running a pass with progress.
- :mod:`wbcgrade.video.sampling`: one small decoding pass: sampled frames and cuts.
- :mod:`wbcgrade.video.shots`: which LUT (or blend of two) each frame gets.
- :mod:`wbcgrade.video.spaces`: the clip's colour encoding (``--input-space`` or
  its tags).
- :mod:`wbcgrade.video.workflow`: :func:`grade_video`, probe to published file.
- :mod:`wbcgrade.video.report`: contact sheets and ``report.json``.
- :mod:`wbcgrade.video.command`: :func:`grade_clip`, the ``video`` command.
- :mod:`wbcgrade.video.defaults`: default settings (light: read by ``--help``).

The grading itself is the colour library's one grade path
(``color.grading.grade_histograms``; ``Grade.lut`` bakes it in the clip's
encoding; ``color.lut.write_cube`` writes every LUT); nothing here touches
pixels of the full-size frames.
"""

from __future__ import annotations

import importlib

__all__ = ["VideoResult", "VideoSettings", "grade_video", "grade_clip"]

#: public name -> the module that defines it (imported on first use, so that the
#: command line can read :mod:`wbcgrade.video.defaults` without the colour library)
_HOMES = {"VideoResult": "workflow", "VideoSettings": "workflow", "grade_video": "workflow",
          "grade_clip": "command"}


def __getattr__(name: str):
    if name in _HOMES:
        return getattr(importlib.import_module(f"wbcgrade.video.{_HOMES[name]}"), name)
    raise AttributeError(f"module 'wbcgrade.video' has no attribute {name!r}")
