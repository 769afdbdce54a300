"""Progress bars shared by the commands."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

from tqdm import tqdm


@contextlib.contextmanager
def style_progress() -> Iterator[Callable[[int, int, str], None]]:
    """A tqdm bar over style photos; yields ``progress(done, total, name)``."""
    with tqdm(desc="style photos", unit="photo", disable=None, leave=False) as bar:

        def progress(done: int, total: int, name: str) -> None:
            bar.total = total
            bar.n = done
            bar.set_postfix_str(name)
            bar.refresh()

        yield progress
