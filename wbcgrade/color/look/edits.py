"""A generator of photographers' edits: the kinds of look presets are made of.

The prior over looks (:mod:`wbcgrade.color.look.prior`) is learned from this
generator, never from any benchmark's or shipped film's look: a random edit is
a chain of the controls every raw editor has (exposure, a contrast curve,
lifted blacks and lowered whites (a fade), saturation, white balance,
split toning of shadows and highlights, a channel mix, per-channel film-like
gammas), each switched on at random with a random amount, at a random
overall size from a trace to a heavy look.

Arrays in, arrays out: colours are (N, 3) encoded RGB in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbcgrade.color.colorspace import REC709_LUMA

__all__ = ["Edit", "random_edit"]

_LUMA = np.array(REC709_LUMA)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class Edit:
    """One photographer's edit; all zero (saturation 1, mix the identity) changes nothing.

    Attributes
    ----------
    exposure : stops (applied as a gain on linear light, approximated by gamma 2.2).
    contrast : S-curve amount on luma (negative: flatter).
    black, white : fade: output black level lifted to ``black``, white lowered by ``white``.
    saturation : chroma scale about Rec.709 luma.
    balance : (3,) RGB gains - 1 (white balance: warm, cool, green, magenta).
    shadow_tint, highlight_tint : (3,) chroma added where the photo is dark / bright.
    mix : (3, 3) channel mix (rows sum to 1).
    gamma : (3,) per-channel power (film-like crossover), 1 = none.
    """

    exposure: float = 0.0
    contrast: float = 0.0
    black: float = 0.0
    white: float = 0.0
    saturation: float = 1.0
    balance: tuple = (0.0, 0.0, 0.0)
    shadow_tint: tuple = (0.0, 0.0, 0.0)
    highlight_tint: tuple = (0.0, 0.0, 0.0)
    mix: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    gamma: tuple = (1.0, 1.0, 1.0)

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """(..., 3) colours in [0, 1] -> (..., 3) float64 in [0, 1]."""
        rgb = np.asarray(rgb, dtype=np.float64)
        x = rgb.reshape(-1, 3)
        x = np.clip(x @ np.asarray(self.mix, dtype=np.float64).T, 0.0, 1.0)
        x = np.clip(x * (1.0 + np.asarray(self.balance)), 0.0, 1.0)
        if self.exposure:
            x = np.clip(x * 2.0 ** (self.exposure / 2.2), 0.0, 1.0)
        x = x ** np.asarray(self.gamma)
        luma = x @ _LUMA
        chroma = x - luma[:, None]
        curved = luma + self.contrast * (_smoothstep(luma) - luma)
        curved = np.clip(curved, 0.0, 1.0)
        toned = (chroma * self.saturation
                 + (1.0 - curved[:, None]) ** 2 * np.asarray(self.shadow_tint)
                 + curved[:, None] ** 2 * np.asarray(self.highlight_tint))
        out = curved[:, None] + toned
        out = self.black + (1.0 - self.black - self.white) * out
        return np.clip(out, 0.0, 1.0).reshape(rgb.shape)


def _chroma(rng: np.random.Generator, size: float) -> np.ndarray:
    """A random chroma vector (zero luma) of rms ``size``."""
    v = rng.normal(0.0, size, 3)
    return v - (v @ _LUMA)


def random_edit(rng: np.random.Generator, size: float | None = None) -> Edit:
    """A random edit (each control on with its own chance) at ``size`` (default
    log-uniform from 0.15, a trace, to 1.5, a heavy look)."""
    if size is None:
        size = float(np.exp(rng.uniform(np.log(0.15), np.log(1.5))))

    def on(chance: float) -> bool:
        return bool(rng.random() < chance)

    exposure = rng.normal(0.0, 0.4) * size if on(0.4) else 0.0
    contrast = rng.normal(0.1, 0.5) * size if on(0.6) else 0.0
    black = abs(rng.normal(0.0, 0.06)) * size if on(0.35) else 0.0
    white = abs(rng.normal(0.0, 0.06)) * size if on(0.25) else 0.0
    saturation = float(np.exp(rng.normal(0.0, 0.45) * size)) if on(0.6) else 1.0
    balance = tuple(_chroma(rng, 0.06 * size)) if on(0.5) else (0.0, 0.0, 0.0)
    shadow = tuple(_chroma(rng, 0.08 * size)) if on(0.35) else (0.0, 0.0, 0.0)
    highlight = tuple(_chroma(rng, 0.08 * size)) if on(0.35) else (0.0, 0.0, 0.0)
    mix = np.eye(3)
    if on(0.2):
        mix = mix + rng.normal(0.0, 0.08 * size, (3, 3)) * (1.0 - np.eye(3))
        mix = mix / mix.sum(axis=1, keepdims=True)
    gamma = (tuple(np.exp(rng.normal(0.0, 0.12 * size, 3))) if on(0.25)
             else (1.0, 1.0, 1.0))
    return Edit(float(exposure), float(np.clip(contrast, -0.9, 1.5)), float(min(black, 0.3)),
                float(min(white, 0.3)), float(np.clip(saturation, 0.0, 3.0)), balance, shadow,
                highlight, tuple(map(tuple, mix)), gamma)
