"""Placing a partial shape on whole ones, the debiased barycenter and the extension mask."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from tests.shape.helpers import ball
from wbcgrade.core import GridGeometry, barycenter, debiased_barycenter
from wbcgrade.shape.complete import extension_occupancy, iso_level
from wbcgrade.shape.database import intersection_over_union, load_shape
from wbcgrade.shape.evaluate import cut_mesh
from wbcgrade.shape.mesh import normalization_transform, read_mesh, voxelize
from wbcgrade.shape.register import place_partial, soft_field
from wbcgrade.shape.volume import density_from_volume

SAMPLES = Path(__file__).resolve().parents[2] / "samples" / "shapes"
N = 32


def _in_frame(mesh: trimesh.Trimesh, transform: np.ndarray) -> np.ndarray:
    moved = mesh.copy()
    moved.apply_transform(transform)
    return voxelize(moved, N)


def _largest_error(mesh: trimesh.Trimesh, first: np.ndarray, second: np.ndarray) -> float:
    """Largest distance (voxels of the N grid) between a mesh's vertices under two transforms."""
    a = trimesh.transform_points(mesh.vertices, first)
    b = trimesh.transform_points(mesh.vertices, second)
    return float(np.abs(a - b).max() * (N - 1))


@pytest.mark.slow
@pytest.mark.parametrize(("name", "axis", "fraction", "from_top"), [
    ("cow.off", 0, 0.3, True),
    ("elephant.off", 1, 0.3, True),
    ("triceratops.off", 0, 0.3, False),
])
def test_a_cut_mesh_is_placed_where_it_was_on_its_whole(name, axis, fraction, from_top):
    names = ["bull.ply", "cow.off", "elephant.off", "triceratops.off"]
    wholes = [read_mesh(SAMPLES / n) for n in names]
    frames = [normalization_transform(w) for w in wholes]
    references = [_in_frame(w, t) for w, t in zip(wholes, frames, strict=True)]
    index = names.index(name)
    partial = cut_mesh(wholes[index], axis, fraction, from_top)
    own = normalization_transform(partial)  # larger and off-centre: what a partial gets alone
    assert _largest_error(partial, own, frames[index]) > 3.0
    placement = place_partial(_in_frame(partial, own), references)
    assert placement.reference == index
    assert _largest_error(partial, placement.transform @ own, frames[index]) < 1.5
    assert 0.6 < placement.explained <= 1.05


@pytest.mark.slow
def test_placement_with_rotation_turns_a_partial_back():
    whole = read_mesh(SAMPLES / "cow.off")
    frame = normalization_transform(whole)
    partial = cut_mesh(whole, 0, 0.25, True)
    turn = trimesh.transformations.rotation_matrix(np.radians(12.0), [0, 0, 1], [0.5, 0.5, 0.5])
    own = turn @ frame  # the partial arrives turned in its own frame
    truth = _in_frame(partial, frame)
    straight = place_partial(_in_frame(partial, own), [_in_frame(whole, frame)], rotate=True)
    unturned = place_partial(_in_frame(partial, own), [_in_frame(whole, frame)])
    placed = _in_frame(partial, straight.transform @ own)
    shifted = _in_frame(partial, unturned.transform @ own)
    assert intersection_over_union(placed > 0.5, truth > 0.5) > 0.85
    assert intersection_over_union(placed > 0.5, truth > 0.5) > intersection_over_union(
        shifted > 0.5, truth > 0.5) + 0.05


def test_soft_field_rewards_inside_and_charges_deep_spills_more():
    field = soft_field(ball(24, 0.3), band=1.0)
    centre, rim_out, far_out = field[12, 12, 12], field[12, 12, 21], field[12, 12, 23]
    assert centre == pytest.approx(0.5)
    assert far_out < rim_out < 0 < centre
    assert field.min() == pytest.approx(-2.0)


def test_debiased_barycenter_of_one_shape_is_that_shape_not_its_blur():
    n = 24
    x = np.linspace(0, 1, n)
    bar = np.zeros((n, n, n))
    bar[4:20, 11:13, 11:13] = 1.0  # a rod two voxels thick
    bar = np.maximum(bar, ball(n, 0.2))
    densities = np.stack([density_from_volume(bar), density_from_volume(ball(n, 0.25))])
    geometry = GridGeometry.with_width((n,) * 3, 1.0)
    weights = np.array([1.0, 0.0])
    sharp = debiased_barycenter(densities, weights, geometry)
    blurred = barycenter(densities, weights, geometry)
    inside = bar.sum()
    iou_sharp = intersection_over_union(sharp > iso_level(sharp, inside), bar > 0.5)
    iou_blurred = intersection_over_union(blurred > iso_level(blurred, inside), bar > 0.5)
    assert iou_sharp > 0.97 and iou_sharp > iou_blurred + 0.05
    assert sharp.sum() == pytest.approx(1.0, abs=1e-3)
    # Two translated balls, half each: the ball half way.
    left, right = ball(n, 0.15, (0.3, 0.5, 0.5)), ball(n, 0.15, (0.7, 0.5, 0.5))
    pair = np.stack([density_from_volume(left), density_from_volume(right)])
    middle = debiased_barycenter(pair, np.array([0.5, 0.5]), geometry)
    centre_x = float((middle.sum(axis=(1, 2)) * x).sum() / middle.sum())
    assert centre_x == pytest.approx(0.5, abs=0.01)
    mask = middle > iso_level(middle, left.sum())
    assert intersection_over_union(mask, ball(n, 0.15) > 0.5) > 0.8


def test_extension_drops_a_thin_shell_and_keeps_a_protrusion_joined():
    n = 32
    observed = ball(n, 0.25)
    slightly_wider = ball(n, 0.25 + 1.0 / (n - 1))
    assert not extension_occupancy(slightly_wider, observed).any()
    x = np.linspace(0, 1, n)
    leg = ((np.abs(x - 0.5)[:, None, None] < 0.06) & (np.abs(x - 0.5)[None, None, :] < 0.06)
           & (x[None, :, None] < 0.5)).astype(float)
    fitted = np.maximum(slightly_wider, leg)
    extension = extension_occupancy(fitted, observed)
    assert extension[16, 1, 16] == 1.0  # the far end of the leg
    shape = np.maximum(observed, extension) > 0.5
    from scipy import ndimage

    assert ndimage.label(shape)[1] == 1  # joined to the body
    assert not extension[28, 16, 16] and not extension[16, 16, 28]  # the shell elsewhere: gone
    assert np.array_equal(extension_occupancy(fitted, observed, shell=0), fitted)


def test_load_shape_keeps_the_mesh_only_when_asked():
    assert load_shape(SAMPLES / "cow.off", 12).mesh is None
    assert len(load_shape(SAMPLES / "cow.off", 12, keep_mesh=True).mesh.faces) > 0
