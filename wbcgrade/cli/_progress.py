"""Progress bars shared by the commands (tqdm), handed to the library as callbacks."""

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


def bar_callbacks(bar: tqdm) -> dict:
    """``styles``, ``fit`` and ``stage`` callbacks drawing on one bar: style photos read,
    then the fit's evaluations and each stage's name."""
    def on_styles(done: int, total: int, name: str) -> None:
        bar.set_description("style photos")
        bar.total = total
        bar.n = done
        bar.set_postfix_str(name)
        bar.refresh()

    def on_fit(n_eval, weights, value) -> None:
        bar.update(1)
        bar.set_postfix(loss=f"{value:.4g}")

    def on_stage(name: str) -> None:
        if name in ("read", "fit"):
            bar.reset(total=None)
        bar.set_description(name)

    return {"styles": on_styles, "fit": on_fit, "stage": on_stage}
