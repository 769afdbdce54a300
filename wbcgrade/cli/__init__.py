"""Command-line interface: ``wbcgrade COMMAND``.

Each command group lives in its own module and is registered below. The CLI
holds no mathematics: it parses options, calls the library, shows progress and
turns library errors into one-line messages. Command modules import click
and light modules only; the library (numpy, the core, numba) is imported
inside the commands, so ``wbcgrade --help`` lists the commands in a fraction
of a second (tests/cli/test_main.py checks that it imports neither numba nor
wbcgrade.core). Layers and data flow: docs/architecture.md.
"""

from __future__ import annotations

import contextlib
import errno
import signal
import sys
import threading
import warnings

import click

from wbcgrade import __version__
from wbcgrade.errors import InputError, OptionError, Terminated, WbcgradeError, first_line


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Library warnings (e.g. a solve stopping above its tolerance) as one line each."""
    click.echo(f"Warning: {first_line(message, category.__name__)}", err=True)


#: Signals that end a command the way Ctrl-C does (clean-up included).
_ENDING_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP")
                        if hasattr(signal, name))


def _terminate(signum, frame) -> None:
    raise Terminated(signum)


@contextlib.contextmanager
def _signals_end_cleanly():
    """SIGTERM and SIGHUP raise :class:`~wbcgrade.errors.Terminated` in the main thread
    while a command runs (temporary files and work folders are removed, ffmpeg and
    worker processes stopped); the previous handlers come back afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.signal(signum, _terminate) for signum in _ENDING_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


#: Exit status of a bad option (click's own usage errors exit with it too).
USAGE_ERROR = 2

_DISK_FULL = {errno.ENOSPC: "disk full", errno.EDQUOT: "disk quota exceeded",
              errno.EFBIG: "file size limit"}


def _message(exc: BaseException) -> str:
    """One line for an error: an OSError as ``FILE: reason (disk full)``, not ``[Errno 28] ...``."""
    if isinstance(exc, OSError) and not isinstance(exc, WbcgradeError) and exc.strerror:
        text = exc.strerror
        if exc.errno in _DISK_FULL:
            text += f" ({_DISK_FULL[exc.errno]})"
        return f"{exc.filename}: {text}" if exc.filename else text
    return first_line(exc)


class _Group(click.Group):
    """A click group that turns library errors into one-line messages (warnings too)."""

    def invoke(self, ctx: click.Context):
        warnings.showwarning = _show_warning
        try:
            with _signals_end_cleanly():
                return super().invoke(ctx)
        except (click.exceptions.Exit, click.ClickException, click.Abort):
            raise
        except Terminated as exc:
            click.echo(f"Terminated ({signal.Signals(exc.signum).name}).", err=True)
            sys.exit(128 + exc.signum)
        except KeyboardInterrupt:
            click.echo("Interrupted.", err=True)
            sys.exit(130)
        except (WbcgradeError, ValueError, OSError, MemoryError) as exc:
            status = 1
            if isinstance(exc, OptionError):  # a library field -> the flag that sets it
                from wbcgrade.cli.option_table import flag_error

                exc, status = flag_error(exc), USAGE_ERROR
            elif getattr(exc, "fields", ()):  # an input error whose hint names a setting
                from wbcgrade.cli.option_table import flag_text

                exc = InputError(flag_text(exc))
            click.echo(f"Error: {_message(exc)}", err=True)
            sys.exit(status)
        finally:  # the command's --cache-dir/--no-cache end with it (in-process runs too)
            cache = sys.modules.get("wbcgrade.color.io.cache")
            if cache is not None:
                cache.set_command_cache()


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="wbcgrade")
def main() -> None:
    """Put a look on your photos and clips: a shipped preset's, the look a folder
    of graded photos shares, or the look of your own before/after edits.

    apply grades a photo, batch a folder, video a clip; look extract and look
    learn save a look as a LUT. --mode palette is the paper's colour transfer
    instead: the photo's palette moved onto the closest blend of the style
    palettes (Wasserstein barycentric coordinates; Bonneel, Peyré, Cuturi,
    SIGGRAPH 2016). The same core fits measured BRDFs and completes shapes.
    """


def _register() -> None:
    # One line per command module; keep imports here so `wbcgrade --help` lists them.
    from wbcgrade.cli.apply import apply
    from wbcgrade.cli.batch import batch
    from wbcgrade.cli.brdf import brdf
    from wbcgrade.cli.explore import explore
    from wbcgrade.cli.look import look
    from wbcgrade.cli.preset import preset
    from wbcgrade.cli.report import report
    from wbcgrade.cli.shape import shape
    from wbcgrade.cli.video import video

    main.add_command(apply)
    main.add_command(batch)
    main.add_command(brdf)
    main.add_command(explore)
    main.add_command(look)
    main.add_command(preset)
    main.add_command(report)
    main.add_command(shape)
    main.add_command(video)


_register()
