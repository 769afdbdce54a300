"""``compiled``: numba's ``njit`` with an on-disk cache that can never fail a run.

numba's own ``cache=True`` raises when the cache cannot be written: a full
disk, a file-size limit (``ulimit -f``), a read-only or vanished cache folder.
A grade must not fail because a compiled function could not be *saved*, so
every compiled function of the package goes through this decorator: the cache
is used when it works, and a failed load or save only costs a compilation.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numba

__all__ = ["compiled"]

log = logging.getLogger(__name__)

try:  # numba's cache class; the decorator still works (uncached) without it
    from numba.core.caching import FunctionCache as _FunctionCache
except ImportError:  # pragma: no cover - other numba layouts
    _FunctionCache = None


if _FunctionCache is not None:

    class _BestEffortCache(_FunctionCache):
        """numba's function cache whose I/O errors are logged, not raised."""

        def load_overload(self, sig, target_context):
            try:
                return super().load_overload(sig, target_context)
            except (OSError, EOFError) as exc:
                log.debug("numba cache not read for %s: %s", self._name, exc)
                return None

        def save_overload(self, sig, data) -> None:
            try:
                super().save_overload(sig, data)
            except OSError as exc:
                log.debug("numba cache not written for %s: %s", self._name, exc)


def compiled(**options: Any) -> Callable[[Callable], Callable]:
    """Like ``numba.njit(cache=True, **options)``, but cache I/O errors never raise."""
    options.pop("cache", None)

    def decorate(function: Callable) -> Callable:
        dispatcher = numba.njit(**options)(function)
        if _FunctionCache is not None:
            try:
                dispatcher._cache = _BestEffortCache(dispatcher.py_func)
            except (RuntimeError, OSError) as exc:  # no usable cache folder at all
                log.debug("numba cache off for %s: %s", function.__qualname__, exc)
        return dispatcher

    return decorate
