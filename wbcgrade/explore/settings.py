"""What the explore page controls, checked as it arrives from the browser.

A :class:`Settings` is one look: the style weights, the strength, the
relaxation and whether lightness is kept. :func:`settings_from_json` turns a
request body into one or raises :class:`RequestError` with a sentence the
page shows (malformed weights, NaN, negative, wrong length, ...). No numpy,
no colour library: the server checks requests before any work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Settings", "RequestError", "settings_from_json", "strength_from_json",
           "blend_from_json",
           "weights_from_json",
           "weights_text", "format_number", "WEIGHT_DECIMALS", "MAX_STRENGTH", "MAX_RELAXATION",
           "MIN_RELAXATION"]

#: Weights are rounded to this many decimals: the command line the page gives
#: (``--weights``) names exactly the weights that were graded.
WEIGHT_DECIMALS = 4
#: Strength is a percentage on the page: rounded to 0.001.
STRENGTH_DECIMALS = 3
#: The largest strength the page offers (``apply --strength`` takes up to 4; above 1 the
#: map's change is scaled, x -> x + t (T(x) - x) on its lattice, clipped to the cube).
MAX_STRENGTH = 2.0
#: The relaxation slider's range (``apply --relax RHO``), rounded to 3 significant digits.
MIN_RELAXATION = 0.01
MAX_RELAXATION = 100.0


#: Keys a request may hold: the settings and what the routes add (seq, client, format, size).
_KEYS = {"weights", "strength", "relaxation", "keep_lightness", "seq", "client", "format",
         "size"}


class RequestError(ValueError):
    """A request the server refuses, with a message for the page (HTTP 400)."""


@dataclass(frozen=True)
class Settings:
    """One look: what the page shows and exports.

    Attributes
    ----------
    weights : (S,) style weights: non-negative, normalised to sum 1, then
        rounded to :data:`WEIGHT_DECIMALS` decimals: exactly the numbers of the
        ``--weights`` text (:func:`weights_text`), which ``apply`` normalises
        again (so the sum may be 1 +- a few 1e-4).
    strength : t in [0, :data:`MAX_STRENGTH`]: x -> (1 - t) x + t T(x) (``--strength``;
        above 1 on the map's lattice, clipped to the cube).
    relaxation : rho > 0 of ``--relax``, or None (balanced transport).
    keep_lightness : ``--preserve-luminance``.
    """

    weights: tuple[float, ...]
    strength: float = 1.0
    relaxation: float | None = None
    keep_lightness: bool = False

    @property
    def map_key(self) -> tuple:
        """What the colour map depends on (the strength is applied afterwards)."""
        return (self.weights, self.relaxation, self.keep_lightness)

    @property
    def family(self) -> tuple:
        """The map's settings other than the weights (maps of one family are comparable)."""
        return (self.relaxation, self.keep_lightness)

    def as_json(self) -> dict:
        return {"weights": list(self.weights), "strength": self.strength,
                "relaxation": self.relaxation, "keep_lightness": self.keep_lightness}


def format_number(value: float, decimals: int) -> str:
    """``value`` with at most ``decimals`` decimals, no trailing zeros ("0.25", "1", "0")."""
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def weights_text(weights) -> str:
    """``--weights`` text: each weight with at most :data:`WEIGHT_DECIMALS` decimals."""
    return ",".join(format_number(float(w), WEIGHT_DECIMALS) for w in weights)


def _number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RequestError(f"{what} must be a number, got {value!r}"[:200])
    try:
        number = float(value)
    except OverflowError:  # an integer of 400 digits
        number = math.inf
    if not math.isfinite(number):
        raise RequestError(f"{what} must be a finite number, got {value!r}")
    return number


def weights_from_json(value, n_styles: int) -> tuple[float, ...]:
    """A list of ``n_styles`` non-negative finite numbers, not all zero -> weights
    normalised to sum 1 and rounded as :data:`Settings.weights` (RequestError otherwise)."""
    if not isinstance(value, list):
        raise RequestError(f"weights must be a list of {n_styles} numbers")
    if len(value) != n_styles:
        raise RequestError(f"weights must hold {n_styles} numbers (one per style), "
                           f"got {len(value)}")
    numbers = [_number(v, f"weight {i + 1}") for i, v in enumerate(value)]
    if any(v < 0 for v in numbers):
        raise RequestError("weights must not be negative")
    largest = max(numbers)
    if not largest > 0:
        raise RequestError("weights must not all be zero")
    scaled = [v / largest for v in numbers]  # huge finite values give a finite sum
    total = math.fsum(scaled)
    rounded = tuple(float(text) for text in weights_text(v / total for v in scaled).split(","))
    if not max(rounded) > 0:
        raise RequestError("weights must not all be zero")
    return rounded


def strength_from_json(data) -> float:
    """The ``strength`` of a look request (default 1): a number in [0, 2], rounded as
    :data:`Settings.strength`. Other keys but ``format`` and ``size`` are refused."""
    if not isinstance(data, dict):
        raise RequestError("the request body must be a JSON object")
    unknown = sorted(set(data) - {"strength", "blend", "format", "size", "seq", "client"})
    if unknown:
        raise RequestError(f"unknown setting {unknown[0]!r} for the look"[:200])
    strength = _number(data.get("strength", 1.0), "strength")
    if not 0.0 <= strength <= MAX_STRENGTH:
        raise RequestError(f"strength must be between 0 and {MAX_STRENGTH:g}")
    return round(strength, STRENGTH_DECIMALS)


def blend_from_json(value) -> tuple[int, float] | None:
    """A look request's ``blend`` (null, or ``{"source": N, "amount": A}``: the share A in
    [0, 1] of picker entry N's look) -> None or (N, A rounded to 3 decimals)."""
    if value is None:
        return None
    if not isinstance(value, dict) or set(value) != {"source", "amount"}:
        raise RequestError('blend must be null or {"source": N, "amount": A}')
    source = value["source"]
    if isinstance(source, bool) or not isinstance(source, int) or source < 0:
        raise RequestError("the blend's source must be a picker entry's number")
    amount = _number(value["amount"], "the blend's amount")
    if not 0.0 <= amount <= 1.0:
        raise RequestError("the blend's amount must be between 0 and 1")
    return source, round(amount, STRENGTH_DECIMALS)


def settings_from_json(data, n_styles: int) -> Settings:
    """Check a request's settings (a JSON object) -> :class:`Settings` (not yet rounded).

    Keys: ``weights`` (required), ``strength`` (default 1), ``relaxation``
    (null or a number in [0.01, 100]), ``keep_lightness`` (default false).
    Unknown keys are refused, so a typo is not silently ignored.
    """
    if not isinstance(data, dict):
        raise RequestError("the request body must be a JSON object")
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise RequestError(f"unknown setting {unknown[0]!r}"[:200])
    if "weights" not in data:
        raise RequestError("weights are missing")
    weights = weights_from_json(data["weights"], n_styles)
    strength = _number(data.get("strength", 1.0), "strength")
    if not 0.0 <= strength <= MAX_STRENGTH:
        raise RequestError(f"strength must be between 0 and {MAX_STRENGTH:g}")
    relaxation = data.get("relaxation")
    if relaxation is not None:
        relaxation = _number(relaxation, "relaxation")
        if not MIN_RELAXATION <= relaxation <= MAX_RELAXATION:
            raise RequestError(f"relaxation must be between {MIN_RELAXATION:g} and "
                               f"{MAX_RELAXATION:g} (or null: balanced)")
    keep = data.get("keep_lightness", False)
    if not isinstance(keep, bool):
        raise RequestError("keep_lightness must be true or false")
    return Settings(weights=weights, strength=round(strength, STRENGTH_DECIMALS),
                    relaxation=None if relaxation is None else float(f"{relaxation:.3g}"),
                    keep_lightness=keep)
