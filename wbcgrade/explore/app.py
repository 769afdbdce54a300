"""Start, serve and stop an explore studio (what ``wbcgrade explore`` runs)."""

from __future__ import annotations

import os
import sys
import threading
import webbrowser
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from wbcgrade.errors import OptionError
from wbcgrade.explore.engine import load_session
from wbcgrade.explore.server import ExploreServer, Studio, make_server
from wbcgrade.explore.studio import Explorer, style_choices

__all__ = ["start_studio", "open_browser", "serve"]


def start_studio(photo: str, style_dir: str | None = None,
                 preset: str | Sequence[str] | None = None,
                 port: int = 0, *, warn: Callable[[str], None] | None = None,
                 progress: Callable[[int, int, str], None] | None = None,
                 stage: Callable[[str], None] | None = None,
                 token: str | None = None,
                 save_dir: str | os.PathLike | None = None,
                 prefetch: bool = True,
                 setting_names: Mapping[str, str] | None = None) -> ExploreServer:
    """Bind the server, load the photo and styles, compute the grade ``apply`` gives;
    -> the server (its ``studio``: an :class:`~wbcgrade.explore.studio.Explorer`).

    The port is taken first (a busy port is reported before any work). The
    page opens on ``style_dir``, else on the first of ``preset`` (one name or
    file, or several: the others join the page's preset picker, with every
    shipped preset). The palette fit runs when the page first asks for the
    palette mode. Saved photos go into ``save_dir`` (default: the photo's
    folder), which must be a folder that exists; nothing else is written.
    ``prefetch``: the other sources are loaded in the background at once.
    ``setting_names``: how the command names the library's settings (setting -> its flag)
    in what the page says of a grade.
    """
    say = stage or (lambda name: None)
    presets = [preset] if isinstance(preset, str) else list(preset or [])
    if (style_dir is None) == (not presets):
        raise OptionError("give exactly one of {style_dir} DIR or {preset} NAME_OR_FILE",
                          "style_dir", also=("preset",))
    folder = Path(save_dir) if save_dir is not None else Path(photo).resolve().parent
    if not folder.is_dir():
        raise OptionError(f"{folder}: the save folder does not exist ({{save_dir}})", "save_dir",
                          path=folder)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OptionError(f"{folder}: the save folder is not writable ({{save_dir}})",
                          "save_dir", path=folder)
    server = make_server(port, token)
    studio = None
    try:
        say("load")
        choices = style_choices(style_dir, presets)
        session = load_session(photo, choices[0].style_dir, choices[0].preset, warn=warn,
                               progress=progress, setting_names=setting_names)
        studio = Studio(session)
        say("look")
        session.look_grade()
        server.studio = Explorer(studio, choices, folder.resolve())
        if prefetch:
            server.studio.prefetch()
    except BaseException:
        server.server_close()
        if studio is not None:
            studio.close()
        raise
    return server


def open_browser(url: str) -> bool:
    """Open ``url`` in the user's browser where there is one; -> whether it was tried.

    On a Unix machine without a display (a server over ssh) nothing is
    opened: Python's fallback would start a text browser in this terminal.
    """
    unix = sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd"))
    if unix and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return False
    try:
        browser = webbrowser.get()
    except webbrowser.Error:
        return False
    threading.Thread(target=browser.open, args=(url, 2), daemon=True,
                     name="explore-browser").start()
    return True


def serve(server: ExploreServer) -> None:
    """Serve until Ctrl-C (or SIGTERM); then close the socket and stop the worker.

    Both signals are handled here, whatever the process inherited: a process started by
    one that ignores SIGINT (a test runner's worker, a script's background job) inherits
    the ignoring, and Ctrl-C would never stop the server."""
    import signal

    def stop(signum, frame):
        raise KeyboardInterrupt

    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = {signum: signal.signal(signum, stop)
                    for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
