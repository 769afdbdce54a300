"""The colour encoding of a grade: pixels into the working space's unit cube and back.

A :class:`ColorEncoding` names the space of the pixels (``input``) and the
space whose unit cube the histograms, the transport and the colour map live
in (``working``); every conversion goes through one engine,
OpenColorIO (:func:`wbcgrade.color.colorspace.convert`). The default pair
(an sRGB photo graded in sRGB-encoded Rec.709, or a Linear Rec.709 EXR
graded there) is one instance like any other.

A photo goes there and back as follows (:meth:`ColorEncoding.encode`,
:meth:`ColorEncoding.decode`):

1. float pixels (EXR, float TIFF) are converted into the working space's
   *linear partner* (Linear Rec.709 for sRGB, ACEScg for ACEScct/ACEScc,
   Linear P3-D65 for sRGB-encoded P3, ...); a pixel whose largest channel m
   exceeds the partner's *peak* (the linear value the working space encodes
   as 1: 1.0 for sRGB, ~222.9 for ACEScct) is divided by m / peak and
   multiplied back after grading: highlights keep their intensity, only
   their colour is graded. Integer pixels are converted directly;
2. what is still outside [0, 1] in the working space (out-of-gamut colours,
   negative values) is carried as a residual: the grade sees the clipped
   colour and the residual is added back to its result, so an identity
   grade returns every pixel unchanged;
3. after grading the same steps run backwards, into the *input* space: the
   written file keeps its space, its ICC profile and its metadata.

The encoding also says what lightness means in the working space, for the
map's finishing steps: :meth:`~ColorEncoding.to_oklab` (Oklab through the
working space's own decoding and primaries, D65) and
:attr:`~ColorEncoding.luma_weights` (the working encoding's luma).

>>> import numpy as np
>>> from wbcgrade.color.encoding import ColorEncoding
>>> srgb = ColorEncoding.of()                     # sRGB pixels in sRGB-encoded Rec.709
>>> encoded, state = srgb.encode(np.array([[[0.2, 0.5, 0.9]]], np.float32))
>>> np.allclose(srgb.decode(encoded, state), [[[0.2, 0.5, 0.9]]])
True
>>> cct = ColorEncoding.of("acescg", "acescct")   # linear ACEScg pixels, graded in ACEScct
>>> hot = np.array([[[4.0, 2.0, 1.0]]], np.float32)
>>> encoded, state = cct.encode(hot, float_values=True)
>>> bool(np.all((encoded > 0) & (encoded < 1)))     # 4.0 is inside ACEScct's cube
True
>>> np.allclose(cct.decode(encoded, state), hot, rtol=1e-4)
True
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from wbcgrade.color.colorspace import (
    canonical,
    config_info,
    config_path,
    convert,
    default_working_space,
    detect_input_space,
    is_logarithmic,
    linear_partner,
    peak,
    resolve_space,
)
from wbcgrade.errors import InputError

__all__ = ["ColorEncoding", "WorkingState", "SYCC_LUMA"]

#: Luma of sRGB-encoded values: sYCC's (IEC 61966-2-1), BT.601's weights, as
#: 8-bit JPEG files store their Y'CbCr.
SYCC_LUMA = (0.299, 0.587, 0.114)


@dataclass
class WorkingState:
    """What :meth:`ColorEncoding.decode` needs to undo one :meth:`ColorEncoding.encode`.

    ``scale`` (H, W, 1): the exposure factor (>= 1) of float pixels above the
    peak, or None; ``residual`` (H, W, 3): the working-space colours outside
    [0, 1], or None.
    """

    scale: np.ndarray | None = None
    residual: np.ndarray | None = None


@dataclass(frozen=True)
class ColorEncoding:
    """Pixels of one colour space (``input``) graded in another's unit cube (``working``).

    Attributes
    ----------
    input : config name of the pixels' space.
    working : config name of the working space.
    linear : the working space's linear partner (where the exposure rule divides).
    peak : the largest grey value of ``linear`` that ``working`` encodes at or below 1.
    source : where ``input`` came from ("--input-space", "ICC profile ...", "default").
    config : the OpenColorIO config.
    """

    input: str
    working: str
    linear: str
    peak: float
    source: str = "given"
    config: str = ""

    # ------------------------------------------------------------------ making one

    @classmethod
    def of(cls, input_space: str | None = None, working_space: str | None = None,
           float_values: bool = False, source: str | None = None) -> ColorEncoding:
        """The encoding of named spaces (names, aliases or roles; OptionError if unknown).

        ``input_space`` None: sRGB, or Linear Rec.709 with ``float_values``;
        ``working_space`` None: sRGB-encoded Rec.709.
        """
        if input_space:
            space, where = resolve_space(input_space, "--input-space"), "--input-space"
        elif float_values:
            space, where = canonical("linear-rec709") or default_working_space(), "default"
        else:
            space, where = default_working_space(), "default"
        return cls._make(space, source or where, working_space)

    @classmethod
    def for_image(cls, image, input_space: str | None = None,
                  working_space: str | None = None) -> ColorEncoding:
        """The encoding of a decoded photo (``input_space`` None: what the file says)."""
        if input_space:
            return cls.of(input_space, working_space)
        space, where = detect_input_space(image)
        return cls._make(space, where, working_space)

    @classmethod
    def _make(cls, input_space: str, source: str, working_space: str | None) -> ColorEncoding:
        working = (resolve_space(working_space, "--working-space") if working_space
                   else default_working_space())
        linear = linear_partner(working)
        return cls(input_space, working, linear, peak(linear, working), source, config_path())

    def within_working(self) -> ColorEncoding:
        """The encoding whose pixels are already working-space colours (a LUT's own domain)."""
        return ColorEncoding(self.working, self.working, self.linear, self.peak,
                             "working space", self.config)

    # -------------------------------------------------------------- there and back

    def encode(self, rgb: np.ndarray,
               float_values: bool = False) -> tuple[np.ndarray, WorkingState]:
        """Pixel values of the input space -> colours in the working space's unit cube.

        Parameters
        ----------
        rgb : (..., 3) float pixel values (integer files scaled to [0, 1]).
        float_values : the pixels are scene-linear floats (the exposure rule
            applies above the peak).

        Returns
        -------
        encoded : (..., 3) float32 in [0, 1]
        state : for :meth:`decode`.
        """
        rgb = np.asarray(rgb, dtype=np.float32)
        scale = None
        if float_values:
            linear = convert(rgb, self.input, self.linear)
            top = linear.max(axis=-1, keepdims=True) / np.float32(self.peak)
            if np.any(top > 1.0):
                scale = np.maximum(top, 1.0).astype(np.float32)
                linear /= scale
            working = convert(linear, self.linear, self.working)
        else:
            working = convert(rgb, self.input, self.working)
        encoded = np.clip(working, 0.0, 1.0)
        residual = working - encoded
        if not np.any(residual):
            residual = None
        return encoded.astype(np.float32, copy=False), WorkingState(scale, residual)

    def decode(self, graded: np.ndarray, state: WorkingState) -> np.ndarray:
        """Inverse of :meth:`encode`: graded working colours -> input-space pixel values.

        Float outputs keep values above 1 (the exposure factor is multiplied
        back in the linear partner); integer outputs are clipped by the writer.
        """
        working = np.asarray(graded, dtype=np.float32)
        if state.residual is not None:
            working = working + state.residual
        if state.scale is None:
            return convert(working, self.working, self.input)
        linear = convert(working, self.working, self.linear) * state.scale
        return convert(linear, self.linear, self.input)

    def to_display(self, rgb: np.ndarray, working: bool = False) -> np.ndarray:
        """Colours for a picture on screen: sRGB-encoded Rec.709, clipped to [0, 1].

        ``rgb`` (..., 3) in the input space, or with ``working`` in the
        working space (e.g. a palette of the grade's histograms).
        """
        source = self.working if working else self.input
        return np.clip(convert(rgb, source, default_working_space()), 0.0, 1.0)

    # --------------------------------------------------- lightness in working terms

    @property
    def logarithmic(self) -> bool:
        """Whether the working space is a logarithmic encoding (ACEScct, ACEScc)."""
        return is_logarithmic(self.working)

    @property
    def luma_weights(self) -> np.ndarray:
        """(3,) weights of the working encoding's luma ``Y' = w . rgb``.

        sRGB-encoded Rec.709: sYCC's (BT.601, :data:`SYCC_LUMA`); any other
        working space: the luminance of its own primaries (the Y row of its
        linear partner's RGB -> XYZ matrix), applied to its encoded values.
        """
        return np.array(_luma_weights(self.working, self.linear, self.config))

    def to_oklab(self, colors: np.ndarray) -> np.ndarray:
        """Working-space colours (..., 3) -> Oklab (L, a, b), float64.

        Decoded into the linear partner, then to CIE XYZ (D65) through Linear
        Rec.709 (OpenColorIO's chromatic adaptation for other white points).
        """
        from wbcgrade.color._colour import colour

        linear = convert(np.clip(colors, 0.0, 1.0), self.working, self.linear)
        xyz = np.asarray(linear, dtype=np.float64) @ _to_xyz(self.linear, self.config).T
        return colour.XYZ_to_Oklab(xyz)

    def from_oklab(self, lab: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_oklab`, clipped to the working space's unit cube (float32)."""
        from wbcgrade.color._colour import colour

        xyz = colour.Oklab_to_XYZ(np.asarray(lab, dtype=np.float64))
        linear = xyz @ np.linalg.inv(_to_xyz(self.linear, self.config)).T
        working = convert(linear, self.linear, self.working)
        return np.clip(working, 0.0, 1.0).astype(np.float32)

    def as_dict(self) -> dict:
        """JSON-friendly description (config, OpenColorIO version, spaces)."""
        return {**config_info(), "input_space": self.input, "input_space_from": self.source,
                "working_space": self.working, "linear_space": self.linear,
                "peak": round(self.peak, 4)}


@functools.lru_cache(maxsize=16)
def _to_xyz(linear: str, config: str) -> np.ndarray:
    """(3, 3) matrix: colours of the linear space ``linear`` -> CIE XYZ (D65)."""
    from wbcgrade.color._colour import colour

    rec709 = canonical("linear-rec709")
    if rec709 is None:
        raise InputError(f"OpenColorIO config {config} has no Linear Rec.709 space: lightness "
                         "cannot be computed in the working space's terms")
    to_rec709 = convert(np.eye(3), linear, rec709).astype(np.float64).T  # columns: primaries
    return colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ @ to_rec709


@functools.lru_cache(maxsize=16)
def _luma_weights(working: str, linear: str, config: str) -> tuple[float, float, float]:
    if working == default_working_space():
        return SYCC_LUMA
    if canonical("linear-rec709") is None:
        return SYCC_LUMA  # no way to read the primaries: the sRGB convention
    row = _to_xyz(linear, config)[1]
    return tuple(float(v) for v in row / row.sum())
