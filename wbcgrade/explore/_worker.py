"""Entry point of the explore page's job worker process (see :mod:`wbcgrade.explore.jobs`).

Kept free of heavy imports: the process lowers its priority before numpy,
the core and their threads start, so that every thread it makes inherits the
lower priority and the live preview in the server process keeps the cores.
"""

from __future__ import annotations

import os
import signal

from wbcgrade.explore.engine import serve_jobs

#: How much lower the worker's priority is than the server's (Unix ``nice``).
NICENESS = 10


def main(fd: int) -> None:
    """Lower the priority, ignore Ctrl-C (the server stops the worker), serve jobs on ``fd``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        os.nice(NICENESS)
    except (AttributeError, OSError):  # pragma: no cover - not Unix
        pass
    from multiprocessing.connection import Connection


    serve_jobs(Connection(fd))


if __name__ == "__main__":
    import sys

    main(int(sys.argv[1]))
