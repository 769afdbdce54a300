"""What a command hears while the library works: :class:`Progress` (a photo's grade) and
:class:`BatchProgress` (a batch's). Callbacks only, no numerics: a command imports it
before the grade's modules (``wbcgrade report`` on a batch's results never needs them)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from wbcgrade.photos.results import FileResult

__all__ = ["Progress", "BatchProgress"]


@dataclass(frozen=True)
class Progress:
    """What a command wants to hear while the library works (every callback optional).

    Attributes
    ----------
    fit : ``fit(n_evaluations, weights, loss)`` after each evaluation of a fit.
    stage : ``stage(name)`` as each stage starts ("read", "fit", "barycenter", ...).
    styles : ``styles(done, total, name)`` while style photos are read.
    warn : ``warn(message)`` for what the user should know (skipped files, ...).
    setting_names : how the command names the library's settings (setting -> its flag) in what
        the results say (a grade's outcome, a colour encoding's source, a failed photo's
        error); None: as the library does.
    """

    fit: Callable[[int, np.ndarray, float], None] | None = None
    stage: Callable[[str], None] | None = None
    styles: Callable[[int, int, str], None] | None = None
    warn: Callable[[str], None] | None = None
    setting_names: Mapping[str, str] | None = None

    def say(self, name: str) -> None:
        if self.stage is not None:
            self.stage(name)


@dataclass(frozen=True)
class BatchProgress(Progress):
    """:class:`Progress` with the batch's own callbacks.

    ``planned(n_photos)`` once the photos are known; ``result(FileResult)``
    as each photo finishes; ``read(done, total)`` while a series reads its
    photos' histograms; ``photo(relative)`` as a photo graded in this process starts.
    """

    planned: Callable[[int], None] | None = None
    result: Callable[[FileResult], None] | None = None
    read: Callable[[int, int], None] | None = None
    photo: Callable[[str], None] | None = None
