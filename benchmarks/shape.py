"""Shape completion benchmark: meshes cut by a plane, completed, measured against the whole.

Run ``python benchmarks/shape.py`` (options: ``--help``). For every mesh of
the database and every cut, the mesh is cut by a plane across one axis
(``wbcgrade.shape.evaluate.cut_mesh``: the end ``fraction`` of its extent
along that axis removed, the cut capped), written as a PLY, completed by
``wbcgrade.shape.workflow.complete_mesh_file`` against the whole database (the
uncut mesh included, the partial file itself not) and measured with
``wbcgrade.shape.evaluate.restoration`` in the mesh's own frame (one 64^3 grid
over the joint bounding box):

- ``cut %``: the cut part's share of the mesh's voxels;
- ``restored %``: the cut part's voxels inside the completion;
- ``IoU partial`` / ``IoU completed``: IoU with the whole mesh of the input
  and of the written completion;
- ``top``: the heaviest database shape and its weight; ``s``: wall time.

Cuts (``--cuts``) are ``AXIS:FRACTION:END`` with AXIS ``long`` (the mesh's
longest extent), ``mid`` (its second) or ``short``, and END ``top``
(larger coordinates) or ``bottom``. The database is the meshes shipped in
``samples/shapes`` and ``samples/shapes/more`` (CC0, see their
ATTRIBUTION.md), ``*_partial`` files left out.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from wbcgrade.shape.evaluate import cut_mesh, restoration  # noqa: E402
from wbcgrade.shape.mesh import MESH_SUFFIXES, read_mesh  # noqa: E402
from wbcgrade.shape.workflow import complete_mesh_file  # noqa: E402

DEFAULT_CUTS = ("long:0.25:top", "long:0.3:bottom", "mid:0.3:bottom")
FOLDERS = (ROOT / "samples" / "shapes", ROOT / "samples" / "shapes" / "more")


def database_meshes(folders=FOLDERS) -> list[Path]:
    """The shipped whole meshes, by name."""
    paths = [p for folder in folders for p in sorted(folder.iterdir())
             if p.suffix.lower() in MESH_SUFFIXES and not p.stem.endswith("_partial")]
    return sorted(paths, key=lambda p: p.stem)


def parse_cut(text: str) -> tuple[str, float, bool]:
    """``long:0.25:top`` -> ("long", 0.25, True)."""
    which, fraction, end = text.split(":")
    if which not in ("long", "mid", "short") or end not in ("top", "bottom"):
        raise argparse.ArgumentTypeError(f"bad cut {text!r}: AXIS long|mid|short, END top|bottom")
    return which, float(fraction), end == "top"


def run_case(path: Path, database: list[Path], cut: tuple[str, float, bool], args,
             folder: Path) -> dict:
    """Cut, complete and measure one mesh; -> a table row."""
    whole = read_mesh(path, repair=True)
    which, fraction, top = cut
    axis = int(np.argsort(-whole.extents)[("long", "mid", "short").index(which)])
    partial = cut_mesh(whole, axis, fraction, from_top=top)
    partial_path = folder / f"{path.stem}_cut.ply"
    partial.export(partial_path)
    start = time.perf_counter()
    result = complete_mesh_file(
        partial_path, database, output=folder / f"{path.stem}_completed.ply",
        resolution=args.resolution, n_iter=args.iterations, max_iter=args.max_iter,
        warn=lambda message: None,
    )
    seconds = time.perf_counter() - start
    import trimesh

    measured = restoration(whole, partial, trimesh.load(folder / f"{path.stem}_completed.ply"))
    projection = result.projection
    best = int(projection.order()[0])
    return {
        "mesh": path.stem, "cut": f"{which}:{fraction:g}:{'top' if top else 'bottom'}",
        "cut %": 100 * measured.cut_fraction, "restored %": 100 * measured.restored,
        "IoU partial": measured.iou_partial, "IoU completed": measured.iou_completed,
        "top": f"{projection.names[best]} {projection.weights[best]:.2f}", "s": seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", "-n", type=int, default=40)
    parser.add_argument("--iterations", type=int, default=40, help="barycenter iterations L")
    parser.add_argument("--max-iter", type=int, default=8, help="optimiser iterations")
    parser.add_argument("--cuts", nargs="+", type=parse_cut,
                        default=[parse_cut(c) for c in DEFAULT_CUTS])
    parser.add_argument("--meshes", nargs="+", default=None,
                        help="names of the database meshes to cut (default: all)")
    parser.add_argument("--out", type=Path, default=None,
                        help="folder for the partial and completed meshes (default: temporary)")
    args = parser.parse_args()

    database = database_meshes()
    chosen = [p for p in database if args.meshes is None or p.stem in args.meshes]
    columns = ("mesh", "cut", "cut %", "restored %", "IoU partial", "IoU completed", "top", "s")
    print(f"database: {len(database)} meshes, fit at {args.resolution}^3, "
          f"L = {args.iterations}, {args.max_iter} optimiser iterations")
    print("  ".join(f"{c:>14}" for c in columns))
    rows = []
    with tempfile.TemporaryDirectory() as temporary:
        folder = args.out or Path(temporary)
        folder.mkdir(parents=True, exist_ok=True)
        for path in chosen:
            for cut in args.cuts:
                row = run_case(path, database, cut, args, folder)
                rows.append(row)
                print("  ".join(
                    f"{row[c]:>14.3f}" if c.startswith("IoU") else
                    f"{row[c]:>14.1f}" if isinstance(row[c], float) else f"{row[c]:>14}"
                    for c in columns), flush=True)
    restored = np.array([r["restored %"] for r in rows])
    better = np.array([r["IoU completed"] > r["IoU partial"] for r in rows])
    print(f"{len(rows)} cuts: restored >= 60% in {np.count_nonzero(restored >= 60)}, "
          f"median {np.median(restored):.1f}%; IoU above the partial's in "
          f"{np.count_nonzero(better)}")


if __name__ == "__main__":
    main()
