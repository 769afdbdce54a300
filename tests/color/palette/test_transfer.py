"""The grade itself: towards the barycenter, self-grading, colourfulness, options."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.color.conftest import SAMPLES, grade_of, small_copy, write_array
from wbcgrade.color._colour import colour
from wbcgrade.color.colorspace import ColorEncoding
from wbcgrade.color.grade.grading import Grade
from wbcgrade.color.histogram import grid_points, image_histogram
from wbcgrade.color.io.images import read_image, write_image
from wbcgrade.color.mapping.remap import identity_map
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.presets import StyleSet, load_style_folder
from wbcgrade.color.weights import parse_weights
from wbcgrade.errors import InputError
from wbcgrade.photos.workflow import graded_pixels


def _lab(rgb):
    return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(np.clip(rgb.reshape(-1, 3), 0, 1)))


def _chroma(rgb, weights=None):
    lab = _lab(rgb)
    return float(np.average(np.hypot(lab[:, 1], lab[:, 2]), weights=weights))


def sliced_wasserstein_lab(a, wa, b, wb, n_directions=64, seed=0):
    """Mean over random directions of the 1-D W1 distance of weighted Lab samples."""
    rng = np.random.default_rng(seed)
    lab_a, lab_b = _lab(a), _lab(b)
    levels = np.linspace(0.005, 0.995, 200)
    total = 0.0
    for _ in range(n_directions):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)

        def quantiles(lab, w, direction=direction):
            proj = lab @ direction
            order = np.argsort(proj)
            cdf = np.cumsum(w[order])
            return np.interp(levels, cdf / cdf[-1], proj[order])

        total += np.abs(quantiles(lab_a, wa) - quantiles(lab_b, wb)).mean()
    return total / n_directions


@pytest.fixture(scope="module")
def scene(style_dir, tmp_path_factory):
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path_factory.mktemp("p") / "chelsea.jpg")
    return read_image(photo).rgb(), style_dir


@pytest.mark.slow
def test_graded_photo_is_closer_to_the_barycenter(scene, fast_options):
    rgb, style_dir = scene
    styles = load_style_folder(style_dir, fast_options.transfer.bins)
    grade = grade_of(rgb, styles, fast_options)
    assert grade.weights.sum() == pytest.approx(1.0) and grade.loss is not None
    graded = grade.apply(rgb)
    points, mass = grid_points(fast_options.transfer.bins), grade.barycenter.ravel()
    pixels, ones = rgb.reshape(-1, 3), np.ones(rgb.shape[0] * rgb.shape[1])
    before = sliced_wasserstein_lab(pixels, ones, points, mass)
    after = sliced_wasserstein_lab(graded.reshape(-1, 3), ones, points, mass)
    assert after < 0.6 * before
    # strength 0 is the identity, strength 1/2 lies half-way (on the colour map itself;
    # the regrain step clips to [0, 1], which is not linear)
    grade = replace(grade, regrain=None)
    graded = grade.apply(rgb)
    np.testing.assert_allclose(replace(grade, strength=0.0).apply(rgb), rgb, atol=1e-6)
    np.testing.assert_allclose(replace(grade, strength=0.5).apply(rgb), 0.5 * (rgb + graded),
                               atol=1e-5)
    with pytest.raises(AttributeError, match="strength"):  # a grade is frozen
        grade.strength = 0.0


@pytest.mark.slow
def test_grading_against_its_own_palette_changes_little(scene):
    rgb, _ = scene
    opts = GradeOptions(mode="palette", bins=24, fit_bins=8, max_iter=10, n_iter=30)
    own = StyleSet(names=["self"], histograms=image_histogram(rgb, 24)[None])
    graded = grade_of(rgb, own, opts).apply(rgb)
    assert np.abs(graded - rgb).mean() < 1 / 255


@pytest.mark.slow
def test_default_transfer_kernel_keeps_colourfulness(scene):
    """A map built with the fit's wide kernel dulls the photo; the default does not."""
    rgb, style_dir = scene
    styles = load_style_folder(style_dir, 24)
    sharp = GradeOptions(mode="palette", bins=24, fit_bins=8, max_iter=10, n_iter=30)
    fit_sigma_in_bins = sharp.fit.width / (sharp.fit.bins - 1) * (sharp.transfer.bins - 1)
    blurred = GradeOptions(mode="palette", bins=24, fit_bins=8, max_iter=10, n_iter=30,
                           transfer_width=fit_sigma_in_bins)  # ~5 bins
    grade = grade_of(rgb, styles, sharp)
    chroma_sharp = _chroma(grade.apply(rgb))
    chroma_blurred = _chroma(grade_of(rgb, styles, blurred).apply(rgb))
    chroma_target = _chroma(grid_points(24), grade.barycenter.ravel())
    assert chroma_sharp >= 0.85 * chroma_target
    assert chroma_sharp > 1.2 * chroma_blurred


@pytest.mark.slow
def test_given_weights_skip_the_fit(scene, fast_options):
    rgb, style_dir = scene
    from wbcgrade.color.grade.grading import grade_encoded

    styles = load_style_folder(style_dir, fast_options.transfer.bins)
    given = GradeOptions(fast_options.fit, fast_options.transfer, weights=parse_weights("0,1,0,1"))
    grade, fit = grade_encoded(rgb, styles, given, ColorEncoding.of())
    assert fit.start == "given" and "evaluations" not in grade.info["fit"]
    assert grade.loss == pytest.approx(fit.loss) and fit.loss > 0  # the given weights' loss
    np.testing.assert_allclose(grade.weights, [0, 0.5, 0, 0.5])
    with pytest.raises(InputError, match="2 numbers for 4 styles"):
        grade_of(rgb, styles, GradeOptions(fast_options.fit, weights=[0.5, 0.5]))


@pytest.mark.parametrize("text", ["a,b", "", "-1,2", "0,0"])
def test_bad_weights(text):
    with pytest.raises(InputError, match="comma-separated numbers|non-negative finite numbers"):
        parse_weights(text)


def test_render_grey_and_alpha(tmp_path, rng):
    warm = identity_map(9) * np.array([1.0, 0.8, 0.6], np.float32)
    grade = Grade(names=("w",), weights=np.ones(1), color_map=warm)
    srgb = ColorEncoding.of()

    def render(image, grade):
        return graded_pixels(image, grade, srgb)

    grey_alpha = rng.random((5, 6, 2)).astype(np.float32)
    image = read_image(write_array(tmp_path / "ga.png", grey_alpha, "uint16"))
    pixels, alpha = render(image, grade)
    # grey stays grey (the luma of the graded colours), alpha untouched
    assert pixels.shape == (5, 6, 2) and alpha == 1
    np.testing.assert_array_equal(pixels[:, :, 1], image.pixels[:, :, 1])
    luma = 0.299 * 1.0 + 0.587 * 0.8 + 0.114 * 0.6
    np.testing.assert_allclose(pixels[:, :, 0], luma * image.pixels[:, :, 0], atol=1e-6)
    back = read_image(write_image(tmp_path / "out.png", pixels, image, alpha_channel=alpha))
    assert back.spec.nchannels == 2 and back.alpha_channel == 1
    assert back.spec.format == image.spec.format
    rgba = read_image(write_array(tmp_path / "c.png", rng.random((5, 6, 4)), "uint8"))
    pixels, alpha = render(rgba, grade)
    assert alpha == 3 and np.array_equal(pixels[:, :, 3], rgba.pixels[:, :, 3])


def test_coarse_to_fine_plan_matches_a_single_grid_solve(rng):
    from wbcgrade.color.histogram import soft_histogram
    from wbcgrade.color.palette.transfer import color_transfer_map

    photo = soft_histogram(rng.random((4000, 3)) * 0.6, 40)
    target = soft_histogram(0.4 + rng.random((4000, 3)) * 0.6, 40)
    width = 39 / 31 * 1.5
    multi, result = color_transfer_map(photo, target, width, tol=1e-4, coarsest=10)
    single, single_result = color_transfer_map(photo, target, width, tol=1e-4, coarsest=40)
    assert result.converged and single_result.converged
    # Same plan to the tolerance: the maps agree to well under one 8-bit level.
    assert np.abs(multi - single).max() < 0.5 / 255
    # Barycentric projection of a plan: the photo's colours, moved, have the
    # target's mean colour (exact for a converged plan; floor and clipping aside).
    points = np.linspace(0, 1, 40)
    target_mean = [np.tensordot(target.sum(axis=tuple(a for a in range(3) if a != c)), points, 1)
                   for c in range(3)]
    moved_mean = np.tensordot(photo, multi, axes=3)
    np.testing.assert_allclose(moved_mean, target_mean, atol=0.01)


def test_the_palette_rebins_only_the_styles_it_uses(rng):
    """A palette of one style re-binned all S style histograms to the palette grid."""
    from wbcgrade.color.palette.transfer import palette_barycenter

    hists = rng.random((4, 16, 16, 16)) ** 6
    hists /= hists.sum(axis=(1, 2, 3), keepdims=True)
    styles = StyleSet([f"s{i}" for i in range(4)], hists)
    opts = GradeOptions(mode="palette", bins=16, palette_bins=8, n_iter=5)
    for weights in (np.array([0.0, 1.0, 0.0, 0.0]), np.array([0.5, 0.0, 0.5, 0.0])):
        target, _ = palette_barycenter(styles, weights, opts)
        assert styles._resampled == {}  # the unused styles were never re-binned
        expected, _ = palette_barycenter(StyleSet(styles.names, hists).at_bins, weights, opts)
        assert np.array_equal(target, expected)
    assert np.array_equal(styles.at_bins(8, [2, 0]), styles.at_bins(8)[[2, 0]])


def test_the_palette_leaves_out_styles_of_negligible_weight(rng):
    """A style the fit left at ~1e-13 (softmax weights never reach 0) is not computed: the
    palette is that of the other styles, and changes by far less than a code."""
    from wbcgrade.color.palette.transfer import palette_barycenter

    hists = rng.random((3, 16, 16, 16)) ** 6
    hists /= hists.sum(axis=(1, 2, 3), keepdims=True)
    opts = GradeOptions(mode="palette", bins=16, palette_bins=8, n_iter=5)
    styles = StyleSet(["a", "b", "c"], hists)
    target, _ = palette_barycenter(styles, np.array([0.4, 0.6, 1e-13]), opts)
    expected, _ = palette_barycenter(StyleSet(styles.names, hists), np.array([0.4, 0.6, 0.0]),
                                     opts)
    assert np.array_equal(target, expected)
    kept, _ = palette_barycenter(StyleSet(styles.names, hists), np.array([0.4, 0.6, 1e-3]),
                                 opts)
    assert not np.array_equal(kept, expected)  # a small weight that counts is kept
