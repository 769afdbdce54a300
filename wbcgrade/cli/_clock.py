"""When the running command started, start-up included (the ``total`` a command prints).

A ``wbcgrade`` command spends part of its wall time before its first line of
code: starting Python, importing click, numpy and the core. The total it
prints counts from the process start (``/proc/self/stat`` on Linux) when the
command line interface was imported at the start of the process, as the
``wbcgrade`` script and ``python -m wbcgrade`` do; a command run from a
longer-lived process (a test's CliRunner, a notebook) counts from its call.
Light: the standard library only.
"""

from __future__ import annotations

import os
import time

__all__ = ["command_started"]

#: Seconds between the process start and the import of the CLI beyond which the
#: process is not a ``wbcgrade`` run (its earlier life is not the command's start-up).
_SCRIPT_START = 5.0


def _process_age() -> float | None:
    """Seconds since this process started (Linux /proc), or None where unknown."""
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()  # the name may hold spaces
        with open("/proc/uptime", encoding="ascii") as f:
            uptime = float(f.read().split()[0])
        started = int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22: start, clock ticks
    except (OSError, ValueError, IndexError):
        return None
    return max(0.0, uptime - started)


_IMPORTED = time.perf_counter()
_AGE = _process_age()
#: perf_counter() at the process start, when the CLI was imported at its start; else None.
_PROCESS_START = _IMPORTED - _AGE if _AGE is not None and _AGE < _SCRIPT_START else None
_first_call = True


def command_started() -> float:
    """``time.perf_counter()`` at the start of the running command: the process start for
    the first command of a ``wbcgrade`` process (start-up included), else now."""
    global _first_call
    first, _first_call = _first_call, False
    if first and _PROCESS_START is not None:
        return _PROCESS_START
    return time.perf_counter()
