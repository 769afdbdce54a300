"""``fit.weights`` written as text ("A,B,C"): user-given barycentric weights."""

from __future__ import annotations

import math

from wbcgrade.errors import OptionError

__all__ = ["parse_weights"]


def parse_weights(text: str) -> list[float]:
    """'a,b,c' -> weights normalised to sum 1 (OptionError naming ``fit.weights`` when
    malformed).

    Normalised by the largest value first, so that huge but finite values
    (``1e308,1e308``) give equal weights rather than an infinite sum.
    """
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise OptionError(f"{{fit.weights}} {text!r}: expected comma-separated numbers",
                          "fit.weights") from None
    if not values or any(not math.isfinite(v) or v < 0 for v in values) or max(values) <= 0:
        raise OptionError(f"{{fit.weights}} {text!r}: need non-negative finite numbers, not all "
                          "zero", "fit.weights")
    largest = max(values)
    scaled = [v / largest for v in values]
    total = math.fsum(scaled)
    return [v / total for v in scaled]
