"""Progress bars shared by the commands, and loading styles under one."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

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


def load_styles_with_bar(opts: Any, style_args: dict, warn: Callable[[str], None]) -> Any:
    """The style set named by a command's options, with a bar over style photos.

    ``opts`` is the command's GradeOptions (bins, working space), ``style_args``
    what :func:`wbcgrade.cli.grading_options.take_grading_options` returned.
    """
    from wbcgrade.color.pipeline import load_styles

    with style_progress() as progress:
        return load_styles(style_args["style_dir"], style_args["preset"], opts.bins,
                           cache=style_args["cache"], warn=warn, progress=progress,
                           working_space=opts.working_space)
