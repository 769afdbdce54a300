"""Completion and projection through the core, on small grids."""

from __future__ import annotations

import numpy as np
import pytest

from tests.shape.helpers import ball, voxel_shapes
from wbcgrade.core import GridGeometry, barycenter, barycenter_gradient
from wbcgrade.errors import InputError
from wbcgrade.shape.complete import complete_shape, estimate_missing_fraction, iso_level
from wbcgrade.shape.database import VoxelShape, intersection_over_union
from wbcgrade.shape.memory import check_memory, estimate_memory
from wbcgrade.shape.projection import KL_REVERSE, default_width, make_target, project
from wbcgrade.shape.surface import completion_surface
from wbcgrade.shape.volume import density_from_volume


def _shape_densities(n: int) -> np.ndarray:
    balls = [
        ball(n, 0.25, (0.35, 0.5, 0.5)),
        ball(n, 0.3, (0.6, 0.45, 0.5)),
        ball(n, 0.2, (0.5, 0.6, 0.4)),
    ]
    return np.stack([density_from_volume(b) for b in balls])


@pytest.mark.parametrize("loss", ["kl", KL_REVERSE])
def test_kl_gradient_matches_finite_differences_on_a_3d_grid(loss):
    n = 7
    histograms = _shape_densities(n)
    geometry = GridGeometry.with_width((n, n, n), 1.0)
    target = make_target(density_from_volume(ball(n, 0.28, (0.45, 0.5, 0.5))), missing=0.2)
    weights = np.array([0.5, 0.3, 0.2])
    _, grad, _ = barycenter_gradient(histograms, weights, geometry, target, loss=loss, n_iter=20)
    step = 1e-5
    for i, j in [(0, 1), (1, 2), (0, 2)]:
        direction = np.zeros(3)
        direction[i], direction[j] = 1.0, -1.0
        plus = barycenter_gradient(
            histograms, weights + step * direction, geometry, target, loss=loss, n_iter=20
        )[0]
        minus = barycenter_gradient(
            histograms, weights - step * direction, geometry, target, loss=loss, n_iter=20
        )[0]
        numeric = (plus - minus) / (2 * step)
        assert grad @ direction == pytest.approx(numeric, rel=1e-4, abs=1e-9)


@pytest.mark.slow
def test_slab_cut_from_a_barycenter_is_completed():
    n, n_iter = 16, 60
    database = voxel_shapes(n)  # box, sphere, torus
    densities = np.stack([density_from_volume(s.occupancy) for s in database])
    true_weights = np.array([0.5, 0.0, 0.5])
    geometry = GridGeometry.with_width((n,) * 3, default_width(n))
    full_density = barycenter(densities, true_weights, geometry, n_iter=n_iter)
    n_inside = true_weights @ [s.occupancy.sum() for s in database]
    full = full_density > iso_level(full_density, n_inside)
    # Cut away the last 30% of the shape along x.
    xs = np.nonzero(full.any(axis=(1, 2)))[0]
    cut = xs[-1] + 1 - int(0.3 * (xs[-1] - xs[0] + 1))
    occupancy = full.astype(float)
    occupancy[cut:] = 0.0
    partial = VoxelShape("partial", occupancy, np.eye(4), 0.0)

    # The partial is in the database's frame already: no placement.
    completion = complete_shape(partial, database, n_iter=n_iter, max_iter=10, place=False)
    completed = completion.shape > 0.5
    iou_partial = intersection_over_union(occupancy > 0.5, full)
    iou_completed = intersection_over_union(completed, full)
    assert iou_completed > iou_partial + 0.05, (iou_partial, iou_completed)
    assert completion.projection.weights.sum() == pytest.approx(1.0)
    assert 0.0 < completion.projection.missing <= 0.9  # estimated from the volumes

    euclidean = complete_shape(partial, database, euclidean=True, max_iter=10, place=False)
    mixed = euclidean.shape > 0.5
    assert euclidean.projection.weights.min() >= 0
    assert euclidean.projection.weights.sum() == pytest.approx(1.0)
    assert iou_completed > intersection_over_union(mixed, full)

    surface = completion_surface(completion)
    assert surface.is_watertight and surface.volume > 0


def test_euclidean_projection_recovers_mixture_weights():
    histograms = _shape_densities(10)
    weights = np.array([0.2, 0.5, 0.3])
    mixture = np.tensordot(weights, histograms, axes=1)
    for loss in ("kl", "quadratic", "kl_reverse"):
        result = project(mixture, histograms, loss=loss, euclidean=True)
        np.testing.assert_allclose(result.weights, weights, atol=2e-3)
        assert result.method == "euclidean"


def test_missing_fraction_and_target():
    full = ball(12, 0.3)
    half = full.copy()
    half[6:] = 0
    assert estimate_missing_fraction(half, [full, full]) == pytest.approx(0.5, abs=0.1)
    assert estimate_missing_fraction(full, [half]) == 0.0
    target = make_target(np.ones((4, 4, 4)), missing=0.25)
    assert target.sum() == pytest.approx(0.75)
    with pytest.raises(InputError, match=r"missing fraction must be in \[0, 1\), got 1.0"):
        make_target(np.ones((4, 4, 4)), missing=1.0)


def test_memory_estimate_refuses_huge_grids():
    small = estimate_memory((32, 32, 32), 4)
    assert small < 200 * 2**20
    assert check_memory((32, 32, 32), 4, available=8 * 2**30) == small
    with pytest.raises(InputError, match="lower --resolution"):
        check_memory((512, 512, 512), 6, available=8 * 2**30)


def test_projection_refuses_mismatched_or_single_database():
    histograms = _shape_densities(8)
    with pytest.raises(InputError, match="at least 2"):
        project(histograms[0], histograms[:1])
    with pytest.raises(InputError, match="shape"):
        project(np.ones((6, 6, 6)), histograms)


def test_alignment_picks_the_axes_signs_that_match_the_reference(tmp_path):
    import trimesh

    from wbcgrade.shape.database import load_shape

    body = trimesh.creation.box(extents=(1.0, 0.4, 0.25))
    head = trimesh.creation.icosphere(subdivisions=2, radius=0.15)
    head.apply_translation((0.7, 0.15, 0.0))
    shape = trimesh.util.concatenate([body, head])
    shape.export(tmp_path / "reference.off")
    turned = shape.copy()
    turned.apply_transform(trimesh.transformations.random_rotation_matrix(seed=3))
    turned.apply_scale(3.0)
    turned.export(tmp_path / "turned.off")

    reference = load_shape(tmp_path / "reference.off", 20, align=True)
    aligned = load_shape(tmp_path / "turned.off", 20, align=True, reference=reference)
    unguided = load_shape(tmp_path / "turned.off", 20)
    iou = intersection_over_union(aligned.occupancy > 0.5, reference.occupancy > 0.5)
    assert iou > 0.85
    assert iou > intersection_over_union(unguided.occupancy > 0.5, reference.occupancy > 0.5)


@pytest.mark.slow
def test_coarse_to_fine_schedule_recovers_translation_weights():
    n = 32
    left = density_from_volume(ball(n, 0.15, (0.35, 0.5, 0.5)))
    right = density_from_volume(ball(n, 0.15, (0.65, 0.5, 0.5)))
    # The barycenter of two translated balls is the ball in between.
    target = density_from_volume(ball(n, 0.15, (0.35 + 0.7 * 0.3, 0.5, 0.5)))
    result = project(target, [left, right], n_iter=25, max_iter=4)
    assert result.n_coarse_evaluations > 0
    assert result.n_evaluations > result.n_coarse_evaluations
    assert result.weights[1] == pytest.approx(0.7, abs=0.08)
