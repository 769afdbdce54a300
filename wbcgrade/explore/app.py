"""Start, serve and stop an explore studio (what ``wbcgrade explore`` runs)."""

from __future__ import annotations

import os
import sys
import threading
import webbrowser
from collections.abc import Callable
from typing import TYPE_CHECKING

from wbcgrade.explore.server import ExploreServer, Studio, make_server

if TYPE_CHECKING:
    import numpy as np

__all__ = ["start_studio", "open_browser", "serve"]


def start_studio(photo: str, style_dir: str | None = None, preset: str | None = None,
                 port: int = 0, *, warn: Callable[[str], None] | None = None,
                 progress: Callable[[int, int, str], None] | None = None,
                 fit_callback: Callable[[int, np.ndarray, float], None] | None = None,
                 stage: Callable[[str], None] | None = None,
                 token: str | None = None) -> ExploreServer:
    """Bind the server, load the photo and styles, fit the weights; -> the server.

    The port is taken first (a busy port is reported before any work). The
    exact map of the fitted weights is queued at once, so the page's first
    picture turns exact within seconds. Nothing is written to the photo or
    the styles.
    """
    from wbcgrade.explore.engine import load_session
    from wbcgrade.explore.jobs import JobWorker

    say = stage or (lambda name: None)
    if (style_dir is None) == (preset is None):
        from wbcgrade.errors import InputError

        raise InputError("give exactly one of --style DIR or --preset NAME_OR_FILE")
    server = make_server(port, token)
    worker = None
    try:
        say("load")
        session = load_session(photo, style_dir, preset, warn=warn, progress=progress)
        worker = JobWorker(session.grader_state()).start()
        say("fit")
        fit = session.fit(fit_callback)
        studio = Studio(session, fit, worker)
        threading.Thread(target=_prefetch, args=(worker, studio.fitted), daemon=True,
                         name="explore-prefetch").start()
        server.studio = studio
    except BaseException:
        server.server_close()
        if worker is not None:
            worker.close()
        raise
    return server


def _prefetch(worker, settings) -> None:
    """Compute the exact map of the fitted weights (the page asks for it first)."""
    from wbcgrade.explore.jobs import JobError, Superseded

    try:
        worker.reference(settings, "view")
    except (JobError, Superseded, TimeoutError):
        pass  # the page asks again


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
    """Serve until Ctrl-C (or SIGTERM); then close the socket and stop the worker."""
    import signal

    def stop(signum, frame):
        raise KeyboardInterrupt

    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, stop)
    try:
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
