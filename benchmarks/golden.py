"""Digests of the default outputs, to check that a refactor changes no picture.

    python benchmarks/golden.py OUT_DIR            # render, print one digest per output
    python benchmarks/golden.py OUT_DIR --compare BEFORE_DIR

Renders a fixed set of commands on the shipped samples (a preset look, a style
folder's look, palette mode, a LUT, a saved grade, a batch, `look extract`) into
OUT_DIR with empty caches, then prints the SHA-256 of every picture and LUT.
With --compare, lists the files whose bytes differ from BEFORE_DIR's (exit 1).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"
PICTURES = {".jpg", ".png", ".tif", ".exr", ".cube", ".clf"}


def _commands(out: Path, styles: Path) -> list[list[str]]:
    s = str(SAMPLES)
    return [
        ["apply", f"{s}/chelsea.jpg", "--preset", "warm", "-o", f"{out}/preset.jpg",
         "--lut", f"{out}/preset.cube", "--save-grade", f"{out}/preset_grade.json"],
        ["apply", f"{s}/coffee.jpg", "--preset", "teal-orange", "--strength", "0.6",
         "-o", f"{out}/strength.png", "--bit-depth", "16"],
        ["apply", f"{s}/flower.jpg", "--style", str(styles), "-o", f"{out}/style.jpg",
         "--save-grade", f"{out}/style_grade.json"],
        ["apply", f"{s}/bridge.jpg", "--style", str(styles), "--mode", "palette",
         "--bins", "16", "-o", f"{out}/palette.jpg"],
        ["apply", f"{s}/sunset.jpg", "--look", f"{out}/preset_grade.json",
         "-o", f"{out}/saved.jpg"],
        ["apply", f"{s}/seeding.jpg", "--preset", "kodak-2383", "--preserve-luminance",
         "-o", f"{out}/luminance.jpg"],
        ["batch", str(styles), "--preset", "faded", "-o", f"{out}/batch"],
        ["look", "extract", str(styles), "-o", f"{out}/extract.cube"],
    ]


def render(out: Path) -> dict[str, str]:
    """Run the commands into `out` with fresh caches; return {relative path: sha256}."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        styles = Path(tmp) / "styles"
        styles.mkdir()
        for name in ("aitzgorri.jpg", "astronaut.jpg", "sunset.jpg", "coffee.jpg"):
            shutil.copy(SAMPLES / name, styles / name)
        env = dict(os.environ, WBCGRADE_CACHE_DIR=str(Path(tmp) / "cache"),
                   PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        for args in _commands(out, styles):
            run = subprocess.run([sys.executable, "-m", "wbcgrade", *args], env=env,
                                 capture_output=True, text=True)
            if run.returncode != 0:
                print(f"FAILED ({run.returncode}): wbcgrade {' '.join(args)}\n{run.stderr}",
                      file=sys.stderr)
    digests = {}
    for path in sorted(out.rglob("*")):
        if path.is_file() and path.suffix.lower() in PICTURES:
            digests[str(path.relative_to(out))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return digests


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--compare", type=Path, help="a folder rendered before the change")
    args = parser.parse_args()
    digests = render(args.out)
    for name, digest in digests.items():
        print(f"{digest[:16]}  {name}")
    if args.compare is None:
        return 0
    before = {str(p.relative_to(args.compare)): hashlib.sha256(p.read_bytes()).hexdigest()
              for p in args.compare.rglob("*") if p.is_file()}
    before = {n: d for n, d in before.items() if Path(n).suffix.lower() in PICTURES}
    changed = sorted(n for n in set(digests) | set(before) if digests.get(n) != before.get(n))
    listed = ": " + ", ".join(changed) if changed else ""
    print(f"{len(digests)} outputs, {len(changed)} differ{listed}")
    return 1 if changed else 0


if __name__ == "__main__":
    raise SystemExit(main())
