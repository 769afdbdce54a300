"""The path of one photo through `wbcgrade apply`: the calls between modules, counted.

    python benchmarks/apply_path.py                 # a preset with --lut (samples/chelsea.jpg)
    python benchmarks/apply_path.py --style DIR     # any apply arguments after the photo's

Runs one `apply` in this process under a profiler and prints, for every pair of
wbcgrade modules where one calls the other at run time (imports left out), how
many calls went that way and the first caller -> callee, in the order they first
happened; then how often the planning checks ran (`lut_format_of`,
`resolve_space`, `check_image_output`, `check_lut_path`, `check_output_path`).
A call from a lower layer into a higher one (e.g. `color.workflow -> cli._progress`,
the progress callbacks) is a call back up.
"""

from __future__ import annotations

import collections
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHECKS = ("lut_format_of", "resolve_space", "check_image_output", "check_lut_path",
          "check_output_path")


def _module(frame) -> str:
    return frame.f_globals.get("__name__", "")


def _importing(frame) -> bool:
    while frame is not None:
        if frame.f_code.co_name == "<module>" and frame.f_back is not None:
            return True
        frame = frame.f_back
    return False


def trace(args: list[str]) -> tuple[dict, dict, collections.Counter]:
    """Run ``wbcgrade apply ARGS``; -> (calls per module pair, first call per pair, checks)."""
    from wbcgrade.cli import main

    edges: dict[tuple[str, str], int] = {}
    first: dict[tuple[str, str], str] = {}
    checks: collections.Counter = collections.Counter()

    def profile(frame, event, arg) -> None:
        if event != "call":
            return
        callee = _module(frame)
        if not callee.startswith("wbcgrade") or frame.f_code.co_name.startswith("__"):
            return
        if frame.f_code.co_name in CHECKS:
            checks[frame.f_code.co_name] += 1
        back = frame.f_back
        while back is not None and not _module(back).startswith("wbcgrade"):
            back = back.f_back
        if back is None or _module(back) == callee or _importing(frame):
            return
        key = (_module(back).removeprefix("wbcgrade."), callee.removeprefix("wbcgrade."))
        edges[key] = edges.get(key, 0) + 1
        first.setdefault(key, f"{back.f_code.co_name} -> {frame.f_code.co_name}")

    sys.setprofile(profile)
    try:
        main.main(["apply", *args], standalone_mode=False)
    finally:
        sys.setprofile(None)
    return edges, first, checks


def main() -> int:
    out = Path(tempfile.mkdtemp())
    extra = sys.argv[1:] or ["--preset", "warm", "--lut", str(out / "photo.cube")]
    edges, first, checks = trace([str(ROOT / "samples" / "chelsea.jpg"), "-o",
                                  str(out / "photo.jpg"), *extra])
    print("calls  caller module -> callee module  (first call)")
    for (caller, callee), count in edges.items():
        print(f"{count:5d}  {caller} -> {callee}  ({first[caller, callee]})")
    print("checks: " + ", ".join(f"{name} x{checks[name]}" for name in CHECKS))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
