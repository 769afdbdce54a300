"""colour-science, imported once with its optional-dependency warnings silenced."""

from __future__ import annotations

import warnings

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour  # noqa: F401

__all__ = ["colour"]
