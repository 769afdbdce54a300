"""Colour spaces of footage: which space a clip's code values are in, and its LUT in them.

ffmpeg's ``lut3d`` sees the clip's code values (full-range RGB decoded with
its own matrix and range), so the LUT it applies must take and give those
values, whatever space the grade was fitted in:

- The *input space* (``--input-space``, else the clip's tags,
  :func:`tagged_space`): PQ (``smpte2084``) with BT.2020 primaries is the
  config's Rec.2100-PQ display space (``ocio://default``: display-referred,
  its reference CIE XYZ-D65 with 1.0 = 100 cd/m²; OpenColorIO reaches
  scene-referred spaces such as ACEScg/ACEScct through the config's default
  view transform, "Un-tone-mapped", so 100 cd/m² becomes ACEScg 1.0 and
  10,000 cd/m² becomes 100, inside ACEScct's cube: no tone mapping, a
  change of primaries and encoding); PQ with P3-D65 primaries
  (``smpte432``) its ST2084-P3-D65 space. HLG (``arib-std-b67``) or PQ
  with other primaries, when the config has no space for them, is an
  error asking for ``--input-space``. Everything else (BT.709, BT.601,
  untagged, other SDR tags) is graded on its code values as sRGB, as before
  colour management.
- The *working space* (``--working-space``; default sRGB-encoded Rec.709) is
  where the sampled frames' histograms, the styles and the colour map live,
  exactly as for photos (:func:`wbcgrade.color.colorspace.to_working`).
- The LUT is *baked in the input encoding* (:func:`bake_lut`): lattice point
  x (input code values in [0, 1]) -> working space (outside its unit cube:
  clipped for the map, the rest carried past it as a residual) -> the
  grade's colour map -> back into the input space -> x'; only x' is clipped
  to [0, 1], which the integer frames force anyway.

The default pair (sRGB in sRGB) runs the code of before colour management
(``Spaces.legacy``): the same samples, the same LUT, byte for byte.
"""

from __future__ import annotations

import numpy as np

from wbcgrade.color.colorspace import (
    Spaces,
    config_info,
    convert,
    default_working_space,
    from_working,
    resolve_space,
    spaces_for,
    to_display,
    to_working,
)
from wbcgrade.color.imageio import encode_for_grading
from wbcgrade.color.lut import DEFAULT_LUT_SIZE, color_map_to_lut
from wbcgrade.color.remap import apply_color_map, identity_map
from wbcgrade.errors import InputError, OptionError
from wbcgrade.video.ffmpeg import VideoInfo

__all__ = ["HDR_TRANSFERS", "tagged_space", "plan_clip_spaces", "frame_to_working",
           "bake_lut", "lut_comments", "frames_for_display", "palette_for_display"]

#: ffmpeg's transfer tags of HDR footage -> what they are called in messages.
HDR_TRANSFERS = {"smpte2084": "PQ", "arib-std-b67": "HLG"}

#: (transfer, primaries) tags -> candidate config names (first found wins; None: any
#: primaries). Names of OpenColorIO's ACES configs (2.2-2.6) and their aliases.
_TAGGED: dict[tuple[str, str | None], tuple[str, ...]] = {
    ("smpte2084", "bt2020"): ("Rec.2100-PQ - Display", "rec2100_pq_display"),
    ("smpte2084", "smpte432"): ("ST2084-P3-D65 - Display", "st2084_p3d65_display"),
    ("arib-std-b67", None): ("Rec.2100-HLG - Display", "rec2100_hlg_display",
                             "Rec.2100-HLG 1000 nits - Display"),
}


def _first_known(candidates: tuple[str, ...]) -> str | None:
    for name in candidates:
        try:
            return resolve_space(name, "--input-space")
        except OptionError:
            continue
    return None


def tagged_space(info: VideoInfo) -> tuple[str | None, str]:
    """The config space a clip's colour tags name -> (space or None, where it came from).

    None means the default: the code values graded as sRGB (SDR tags or
    none). HDR tags (:data:`HDR_TRANSFERS`) the config has no space for raise
    InputError asking for ``--input-space``.
    """
    transfer, primaries = info.transfer, info.primaries
    tags = "/".join(t or "unknown" for t in (transfer, primaries))
    if transfer not in HDR_TRANSFERS:
        return None, ("untagged: sRGB code values" if transfer is None
                      else f"tags {tags} (SDR): sRGB code values")
    candidates = _TAGGED.get((transfer, primaries)) or _TAGGED.get((transfer, None))
    found = _first_known(candidates) if candidates else None
    if found is None:
        from wbcgrade.color.colorspace import config_path

        raise InputError(
            f"{info.path}: tagged {HDR_TRANSFERS[transfer]} ({tags}), but OpenColorIO config "
            f"{config_path()} has no colour space for it; name one with --input-space NAME "
            f"(or --input-space srgb to grade the code values as sRGB)")
    return found, f"tags {tags}"


def plan_clip_spaces(info: VideoInfo, input_space: str | None = None,
                     working_space: str | None = None) -> Spaces:
    """The :class:`~wbcgrade.color.colorspace.Spaces` of a clip's grade.

    ``input_space`` None: what the tags say (:func:`tagged_space`);
    ``working_space`` None: sRGB-encoded Rec.709. Unknown names raise
    OptionError (one line, listing the valid names), as for photos.
    """
    if input_space:
        return spaces_for(input_space, working_space)
    found, source = tagged_space(info)
    spaces = spaces_for(found, working_space)
    return Spaces(spaces.input, spaces.working, spaces.linear, spaces.peak, spaces.legacy,
                  source, spaces.config)


def frame_to_working(frame: np.ndarray, spaces: Spaces | None) -> np.ndarray:
    """An (h, w, 3) uint8 frame -> float32 colours in the working space's unit cube.

    ``spaces`` None or the default pair: sRGB-encoded, as before colour management.
    """
    rgb = frame.astype(np.float32) / np.float32(255)
    if spaces is None or spaces.legacy:
        return encode_for_grading(rgb, False)[0]
    return to_working(rgb, spaces, False)[0]


def bake_lut(color_map: np.ndarray, spaces: Spaces | None, size: int = DEFAULT_LUT_SIZE,
             strength: float = 1.0) -> np.ndarray:
    """The grade as a (size, size, size, 3) LUT indexed [r, g, b] in the input encoding.

    Lattice point x -> working space -> ``color_map`` (blended with the
    identity by ``strength``) -> input space -> x', clipped to [0, 1]. The
    LUT holds ``x + (back(graded) - back(working))``, which is that value up
    to OpenColorIO's float32 round trip, so an identity grade gives exactly
    the identity (PQ's steep toe otherwise turns the round trip's 1e-7 into
    up to 0.015 at saturated colours next to near-black channels). The
    default pair (``spaces`` None or legacy) samples the map directly
    (:func:`wbcgrade.color.lut.color_map_to_lut`), as before.
    """
    if spaces is None or spaces.legacy:
        return color_map_to_lut(color_map, size, strength)
    if not 2 <= size <= 256:
        raise InputError("LUT size must be between 2 and 256")
    nodes = identity_map(size)
    working, state = to_working(nodes, spaces, False)
    graded = apply_color_map(working, color_map, strength)
    moved = from_working(graded, state) - from_working(working, state)
    return np.clip(nodes + moved, 0.0, 1.0)


def lut_comments(spaces: Spaces) -> list[str]:
    """``--lut`` header lines: the spaces the LUT expects and produces, the working space
    the grade was fitted in, and the config (as ``apply --lut`` names its spaces)."""
    info = config_info()
    return [f"input space: {spaces.input} (the clip's code values; {spaces.source})",
            f"output space: {spaces.input}",
            f"working space: {spaces.working} (where the grade was fitted)",
            f"OpenColorIO config: {info['ocio_config']} (OpenColorIO {info['ocio_version']})"]


def frames_for_display(frames: list[np.ndarray], spaces: Spaces | None) -> list[np.ndarray]:
    """Float frames of the input encoding -> sRGB pictures for a contact sheet.

    The default pair's frames are shown as they are (sRGB code values).
    """
    if spaces is None or spaces.input == default_working_space():
        return frames
    return [to_display(frame, spaces) for frame in frames]


def palette_for_display(colors: np.ndarray, spaces: Spaces | None) -> np.ndarray:
    """Working-space palette colours -> sRGB-encoded Rec.709 in [0, 1]."""
    if spaces is None or spaces.working == default_working_space():
        return colors
    return np.clip(convert(colors, spaces.working, default_working_space()), 0.0, 1.0)
