"""Start-up: how soon each command answers (``--help``, a mistake, the README's first grade).

``python benchmarks/startup.py`` runs each row in fresh interpreters (as the ``wbcgrade``
script does) and prints, per row, the median wall time to the first byte of output
and to the exit, the same beyond Python's own start (``python -c pass``), and the
numeric modules the command imported (numpy, numba, scipy, OpenImageIO, colour,
OpenColorIO, cv2, the core). Targets (issue 45): ``--help`` and a mistake import
none of them; a mistake answered within 0.4 s beyond Python's start.

Options: ``--runs N`` (default 5; medians), ``--only TEXT`` (rows whose label or command contains
TEXT), ``--no-grade`` (skip the README's first grade, which fills the caches on its
first run and is timed on the following ones).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Top-level modules counted as numerics (``--help`` and mistakes should import none).
HEAVY = ("numpy", "numba", "scipy", "OpenImageIO", "colour", "PyOpenColorIO", "cv2",
         "wbcgrade.core")

# Runs the CLI as the console script does, then writes the numeric modules it loaded.
_RUN = f"""
import os, sys
sys.argv[0] = 'wbcgrade'
try:
    from wbcgrade.cli import main
    main()
finally:
    heavy = sorted(h for h in {HEAVY!r} if h in sys.modules)
    with open(os.environ['WBCGRADE_STARTUP_MODULES'], 'w') as f:
        f.write(' '.join(heavy))
"""

#: (label, arguments after ``wbcgrade``, expected exit: 0, or non-zero for a mistake).
ROWS = [
    ("--help", "--help", 0),
    ("--version", "--version", 0),
    *[(f"{c} --help", f"{c} --help", 0)
      for c in ("apply", "batch", "video", "report", "explore", "look extract",
                "look learn", "preset build", "preset list", "brdf fit", "shape complete")],
    ("mistake: apply missing photo", "apply {tmp}/missing.jpg --preset warm", 1),
    ("mistake: apply unknown preset", "apply samples/chelsea.jpg --preset nosuch "
                                      "-o {tmp}/x.jpg", 1),
    ("mistake: apply bad option", "apply samples/chelsea.jpg --bins 0", 2),
    ("mistake: batch missing folder", "batch {tmp}/nofolder -o {tmp}/out --preset warm", 1),
    ("mistake: video missing clip", "video {tmp}/missing.mp4 --preset warm", 1),
    ("mistake: report missing photo", "report {tmp}/missing.jpg --preset warm", 1),
    ("mistake: look learn missing", "look learn {tmp}/nobefore {tmp}/noafter "
                                    "-o {tmp}/look.json", 1),
    ("mistake: look extract missing", "look extract {tmp}/nofolder -o {tmp}/look.cube", 1),
    ("mistake: preset build missing", "preset build {tmp}/nofolder -o {tmp}/p.npz", 1),
]
GRADE = ("README first grade (cached)",
         "apply samples/chelsea.jpg --preset warm -o {tmp}/chelsea.jpg --overwrite", 0)


def timed(argv: list[str], env: dict[str, str], expect: int) -> tuple[float, float, str]:
    """(seconds to the first output byte, seconds to the exit, heavy modules) of one run."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)
    first = proc.stdout.read(1)
    first_at = time.perf_counter() - start
    rest = proc.stdout.read()
    proc.wait()
    total = time.perf_counter() - start
    if (proc.returncode == 0) != (expect == 0):
        raise SystemExit(f"{' '.join(argv)}: exit {proc.returncode}, expected "
                         f"{expect}:\n{(first + rest).decode(errors='replace')}")
    return (first_at if first else total), total, Path(env["WBCGRADE_STARTUP_MODULES"]).read_text()


def median_row(argv, env, expect, runs):
    times = [timed(argv, env, expect) for _ in range(runs)]
    return (statistics.median(t[0] for t in times), statistics.median(t[1] for t in times),
            times[-1][2])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", default="")
    parser.add_argument("--no-grade", action="store_true")
    parser.add_argument("--json", action="store_true", help="also print the rows as JSON")
    ns = parser.parse_args()
    rows = [r for r in ROWS + ([] if ns.no_grade else [GRADE])
            if ns.only in r[0] or ns.only in r[1]]
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "WBCGRADE_STARTUP_MODULES": f"{tmp}/modules.txt",
               "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT),
                                                           os.environ.get("PYTHONPATH")]))}
        bare = statistics.median(timed([sys.executable, "-c", _RUN.split("try:")[0]
                                        + "open(os.environ['WBCGRADE_STARTUP_MODULES'], 'w')"],
                                       env, 0)[1] for _ in range(ns.runs))
        print(f"Python's own start: {bare:.3f} s (median of {ns.runs}); "
              "'beyond' columns subtract it")
        head = (f"{'row':<34} {'first out s':>11} {'exit s':>7} {'beyond':>7}  "
                "numeric modules imported")
        print(head)
        print("-" * len(head))
        records = []
        for label, args, expect in rows:
            argv = [sys.executable, "-c", _RUN, *shlex.split(args.format(tmp=tmp))]
            if label == GRADE[0]:
                timed(argv, env, expect)  # fills the histogram and compiled-kernel caches
            first, total, heavy = median_row(argv, env, expect, ns.runs)
            print(f"{label:<34} {first:11.3f} {total:7.3f} {total - bare:7.3f}  "
                  f"{heavy or '-'}", flush=True)
            records.append({"row": label, "command": f"wbcgrade {args}", "first_output_s": first,
                            "exit_s": total, "beyond_python_s": total - bare,
                            "numeric_modules": heavy.split()})
        if ns.json:
            print(json.dumps({"python_start_s": bare, "rows": records}, indent=2))


if __name__ == "__main__":
    main()
