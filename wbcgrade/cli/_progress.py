"""Progress bars shared by the commands (tqdm), handed to the library as callbacks."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

from wbcgrade.cli.option_table import flag_text

if TYPE_CHECKING:
    from tqdm import tqdm


class _NoBar:
    """Stands in for a tqdm bar that would not be drawn: every method does nothing."""

    n = 0
    total = None

    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def __getattr__(self, name: str):
        return lambda *args, **kwargs: None


def progress_bar(**options):
    """``tqdm(disable=None, **options)``: a bar on stderr when it is a terminal; otherwise
    a stand-in that draws nothing, as tqdm's would not, without importing tqdm (whose
    import reads its package metadata: a few hundredths of a second of every start)."""
    isatty = getattr(sys.stderr, "isatty", None)
    if isatty is None or not isatty():
        return _NoBar()
    from tqdm import tqdm

    return tqdm(disable=None, **options)


@contextlib.contextmanager
def style_progress() -> Iterator[Callable[[int, int, str], None]]:
    """A tqdm bar over style photos; yields ``progress(done, total, name)``."""
    with progress_bar(desc="style photos", unit="photo", leave=False) as bar:

        def progress(done: int, total: int, name: str) -> None:
            bar.total = total
            bar.n = done
            bar.set_postfix_str(name)
            bar.refresh()

        yield progress


@contextlib.contextmanager
def learn_progress(desc: str) -> Iterator[tuple[Callable[[int, int, str], None],
                                                Callable[[str], None]]]:
    """A bar over the photos a look is learned from; yields ``(progress(done, total,
    name), warn(message))`` (a warning clears the bar and goes to stderr)."""
    import click

    with progress_bar(desc=desc, unit="photo", leave=False) as bar:

        def progress(done: int, total: int, name: str) -> None:
            bar.total = total
            bar.n = done
            bar.set_postfix_str(name, refresh=True)

        def warn(message: str) -> None:
            bar.clear()
            click.echo(f"Warning: {flag_text(message)}", err=True)

        yield progress, warn


#: What the bar says while each stage of a grade runs (stage names from the library).
STAGE_TEXT = {"read": "reading the photo", "fit": "fitting the weights",
              "histograms": "photo histograms", "look": "extracting the set's look",
              "barycenter": "barycenter palette", "transfer": "colour transport",
              "remap": "applying the grade", "write": "writing", "lut": "writing the LUT",
              "scan": "scanning frames", "encode": "encoding"}


def stage_text(name: str) -> str:
    """The words a bar shows for a stage ("scene fit" -> "scene: fitting the weights")."""
    if name.startswith("scene "):
        return "scene: " + stage_text(name[len("scene "):])
    return STAGE_TEXT.get(name, name)


def bar_callbacks(bar: tqdm, photos: bool = False) -> dict:
    """``styles``, ``fit`` and ``stage`` callbacks drawing on one bar: style photos
    read, then the fit's evaluations and what each stage does; with ``photos``
    also ``photo(name)``, which names the photo in the bar (a batch). A new photo
    (or its "read" stage) starts the bar afresh: nothing of the previous photo's
    (its loss) stays on it."""
    current = {"photo": ""}

    def describe(text: str) -> None:
        bar.set_description(f"{current['photo']}: {text}" if current["photo"] else text,
                            refresh=False)
        bar.refresh()

    def on_styles(done: int, total: int, name: str) -> None:
        bar.set_description("reading style photos")
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
            bar.set_postfix_str("", refresh=False)
        describe(stage_text(name))

    def on_photo(name: str) -> None:
        current["photo"] = name
        bar.reset(total=None)
        bar.set_postfix_str("", refresh=False)
        describe("starting")

    callbacks = {"styles": on_styles, "fit": on_fit, "stage": on_stage}
    if photos:
        callbacks["photo"] = on_photo
    return callbacks
