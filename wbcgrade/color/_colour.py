"""colour-science, imported on first use (one to two seconds) with its optional-dependency
warnings silenced: :func:`colour_science`."""

from __future__ import annotations

import functools
import warnings

__all__ = ["colour_science"]


@functools.cache
def colour_science():
    """The ``colour`` module (colour-science), imported once."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    return colour


def __getattr__(name: str):
    """``from wbcgrade.color._colour import colour``: the module, imported then."""
    if name == "colour":
        return colour_science()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
