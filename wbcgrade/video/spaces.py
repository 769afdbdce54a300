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
  exactly as for photos (one :class:`~wbcgrade.color.colorspace.ColorEncoding`,
  :func:`clip_encoding`).
- The LUT is *baked in the input encoding*
  (:meth:`wbcgrade.color.grade.grading.Grade.lut` with the clip's encoding):
  lattice point x (input code values in [0, 1]) -> working space (outside
  its unit cube: clipped for the map, the rest carried past it as a
  residual) -> the grade's colour map -> back into the input space -> x';
  only x' is clipped to [0, 1], which the integer frames force anyway. When
  the input is the working space (sRGB footage graded in sRGB) the table is
  the map sampled on the lattice.
"""

from __future__ import annotations

import numpy as np

from wbcgrade.color.colorspace import ColorEncoding, config_line, config_path, resolve_space
from wbcgrade.color.options import SpaceOptions
from wbcgrade.errors import InputError, OptionError
from wbcgrade.video.ffmpeg import VideoInfo

__all__ = ["HDR_TRANSFERS", "tagged_space", "clip_encoding", "frame_to_working", "lut_comments"]

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
            return resolve_space(name, "spaces.input")
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
        raise InputError(
            f"{info.path}: tagged {HDR_TRANSFERS[transfer]} ({tags}), but OpenColorIO config "
            f"{config_path()} has no colour space for it; name one with {{spaces.input}} NAME "
            f"(or {{spaces.input}} srgb to grade the code values as sRGB)",
            fields=("spaces.input", "spaces.input"), path=info.path)
    return found, f"tags {tags}"


def clip_encoding(info: VideoInfo, spaces: SpaceOptions | None = None) -> ColorEncoding:
    """The :class:`~wbcgrade.color.colorspace.ColorEncoding` of a clip's grade.

    ``spaces.input`` None: what the tags say (:func:`tagged_space`), else
    sRGB code values; ``spaces.working`` None: sRGB-encoded Rec.709.
    Unknown names raise OptionError (one line, listing the valid names), as
    for photos.
    """
    spaces = spaces or SpaceOptions()
    if spaces.input:
        return ColorEncoding.of(spaces.input, spaces.working)
    found, source = tagged_space(info)
    return ColorEncoding.of(found, spaces.working, source=source)


def frame_to_working(frame: np.ndarray, encoding: ColorEncoding) -> np.ndarray:
    """An (h, w, 3) uint8 frame -> float32 colours in the working space's unit cube."""
    return encoding.encode(frame.astype(np.float32) / np.float32(255))[0]


def lut_comments(encoding: ColorEncoding) -> list[str]:
    """``--lut`` header lines: the spaces the LUT expects and produces, the working space
    the grade was fitted in, and the config (as ``apply --lut`` names its spaces)."""
    return [f"input space: {encoding.input} (the clip's code values; {encoding.source})",
            f"output space: {encoding.input}",
            f"working space: {encoding.working} (where the grade was fitted)",
            config_line()]
