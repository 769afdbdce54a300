"""The first grade after a fresh install: the README's first command with every cache empty.

``python benchmarks/first_grade.py`` runs ``wbcgrade apply samples/chelsea.jpg --preset
warm`` in fresh interpreters: first with an empty compiled-kernel cache (numba's,
``NUMBA_CACHE_DIR``) and an empty wbcgrade cache (``WBCGRADE_CACHE_DIR``), as after
``pip install``; then again with the caches the first run filled. Prints a table of
wall times (target: the first run <= 5 s on the README's reference machine).

Options: ``--runs N`` (default 2: cold then warm), ``--command "ARGS"`` (the
arguments after ``wbcgrade``; default the README's first command).
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README_COMMAND = "apply samples/chelsea.jpg --preset warm -o {out}/chelsea.jpg --overwrite"
_RUN = "import sys; from wbcgrade.cli import main; sys.argv[0] = 'wbcgrade'; main()"


def timed_run(args: list[str], env: dict[str, str]) -> float:
    """Seconds one ``wbcgrade ARGS`` takes in a fresh interpreter (raises on failure)."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _RUN, *args], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"wbcgrade {' '.join(args)} failed:\n{done.stdout}{done.stderr}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--command", default=README_COMMAND)
    ns = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "NUMBA_CACHE_DIR": f"{tmp}/numba",
               "WBCGRADE_CACHE_DIR": f"{tmp}/wbcgrade",
               "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT),
                                                           os.environ.get("PYTHONPATH")]))}
        args = shlex.split(ns.command.format(out=tmp))
        print(f"wbcgrade {' '.join(args)}")
        print(f"{'run':<28} {'wall s':>7}")
        for run in range(ns.runs):
            label = "1 (empty caches: install)" if run == 0 else f"{run + 1} (caches filled)"
            print(f"{label:<28} {timed_run(args, env):7.2f}", flush=True)


if __name__ == "__main__":
    main()
