"""Contact sheets of a completion and of a projection (PNG views, :mod:`wbcgrade.shape.render`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.ndimage as ndi
import trimesh

from wbcgrade.shape.complete import Completion
from wbcgrade.shape.mesh import voxelize_together
from wbcgrade.shape.projection import Projection
from wbcgrade.shape.render import Panel, contact_sheet

INPUT_COLOR = (0.95, 0.7, 0.35)
"""Colour of the input (and of the input's part of a completion) in pictures."""

ADDED_COLOR = (0.35, 0.6, 1.0)
"""Colour of the part a completion adds, in pictures."""

SHEET_RESOLUTION = 96
"""Voxels along the longest side of the output-frame views of :func:`completion_sheet`."""


def completion_sheet(
    completion: Completion,
    top: int = 3,
    tile: int = 160,
    surface: trimesh.Trimesh | None = None,
) -> np.ndarray:
    """Contact sheet: input, completion (added part in blue), the ``top`` heaviest database shapes.

    With the written ``surface`` and the input's mesh (``load_shape(...,
    keep_mesh=True)``), the input and the completion are drawn in the input's
    own frame (both voxelised on one grid over their joint bounding box;
    voxels more than one voxel away from the input count as added);
    otherwise in the unit frame. Database shapes are drawn in the unit frame.

    Returns
    -------
    (H, W, 3) float32 RGB image in [0, 1].
    """
    projection = completion.projection
    title = "Euclidean" if projection.method == "euclidean" else "completion"
    source = completion.partial.mesh
    if surface is not None and source is not None:
        (observed, completed), _ = voxelize_together([source, surface], SHEET_RESOLUTION)
        near_input = ndi.binary_dilation(observed > 0.5, iterations=1)
        added = ~near_input
    else:
        observed, completed = completion.partial.occupancy, completion.shape
        added = completion.added
    panels = [
        Panel(observed, f"input {completion.partial.name}", 0.5, INPUT_COLOR),
        Panel(completed, f"{title} (blue: new)", 0.5, INPUT_COLOR, highlight=added,
              highlight_color=ADDED_COLOR),
    ]
    for index in projection.order()[: max(0, top)]:
        shape = completion.database[index]
        panels.append(Panel(shape.occupancy, f"{shape.name} {projection.weights[index]:.2f}", 0.5))
    return contact_sheet(panels, tile=tile)


def projection_sheet(
    volume: np.ndarray,
    projection: Projection,
    database: Sequence[np.ndarray],
    top: int = 3,
    tile: int = 160,
) -> np.ndarray:
    """Maximum-intensity projections of the input, the fit and the heaviest database volumes."""
    title = "Euclidean" if projection.method == "euclidean" else "projection"
    panels = [Panel(volume, "input"), Panel(projection.barycenter, title)]
    for index in projection.order()[: max(0, top)]:
        panels.append(
            Panel(database[index], f"{projection.names[index]} {projection.weights[index]:.2f}")
        )
    return contact_sheet(panels, tile=tile)
