"""The grade's look: a smooth colour map, relaxed transport, regrain, lightness kept."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wbcgrade.color.colorspace import SYCC_LUMA, ColorEncoding
from wbcgrade.color.histogram import image_histogram
from wbcgrade.color.io.images import read_image
from wbcgrade.color.mapping import regrain as regrain_module
from wbcgrade.color.mapping.regrain import regrain
from wbcgrade.color.mapping.remap import (
    apply_color_map,
    identity_map,
    keep_lightness,
    monotone_lightness,
)
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.palette.smooth_map import fit_smooth_map
from wbcgrade.color.palette.transfer import color_transfer_map
from wbcgrade.color.presets import StyleSet

from .conftest import SAMPLES, grade_of, small_copy

LUMA_WEIGHTS = np.array(SYCC_LUMA)


@pytest.fixture(scope="module")
def scene(style_dir, tmp_path_factory):
    photo = small_copy(SAMPLES / "chelsea.jpg", tmp_path_factory.mktemp("p") / "chelsea.jpg")
    return read_image(photo).rgb(), style_dir


def _split_map(n: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """A raw map that sends reds below 0.5 to dark blue and above to light yellow, and a
    photo density spread over a wide blob across the split (a sky crossing it)."""
    x = identity_map(n, np.float64)
    raw = x.copy()
    low = raw[..., 0] < 0.5
    raw[low] = (0.1, 0.1, 0.6)
    raw[~low] = (0.9, 0.9, 0.3)
    density = np.exp(-np.sum((x - 0.5) ** 2, axis=-1) / (2 * 0.2 ** 2))
    return raw, density


@pytest.mark.slow
def test_smooth_map_has_no_jumps_where_the_raw_map_splits_a_colour():
    raw, density = _split_map()
    smooth = fit_smooth_map(raw, density, size=33)
    along_red = smooth[:, 16, 16]
    # the raw map jumps by 0.8 between two neighbouring bins; the fitted map moves
    # by a small step per node (no split colour), and still spans most of the range
    assert np.abs(np.diff(raw[:, 16, 16, 0])).max() > 0.75
    assert np.abs(np.diff(along_red, axis=0)).max() < 0.16
    assert along_red[0, 0] < 0.25 and along_red[-1, 0] > 0.75


def test_smooth_map_keeps_a_smooth_raw_map():
    n = 24
    x = identity_map(n, np.float64)
    affine = x @ np.array([[0.8, 0.1, 0.0], [0.0, 0.8, 0.1], [0.1, 0.0, 0.8]]) + 0.05
    rng = np.random.default_rng(0)
    density = rng.random((n, n, n)) ** 4
    # no first-difference penalty: the curvature penalty leaves affine maps alone
    smooth = fit_smooth_map(affine, density, size=17, stiffness=0.0)
    on_grid = apply_color_map(x.reshape(-1, 3), smooth).reshape(affine.shape)
    assert np.abs(on_grid - affine).max() < 2e-3


@pytest.mark.slow
@pytest.mark.parametrize("size", [17, 8])
def test_smooth_map_solves_its_least_squares_problem(size):
    """Multigrid-preconditioned CG (17: lattices 5, 9, 17) and Jacobi CG (8: no
    coarser lattice) against a direct sparse solve of the same normal equations (plain
    Jacobi CG capped at 400 iterations was off by up to 1.2/255 at 33 nodes)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    from wbcgrade.color.palette import smooth_map

    raw, density = _split_map(20)
    raw = 0.3 + 0.4 * raw  # inside the cube: no clipping of the result
    smoothness, stiffness = 3e-3, 1e-4
    weights = (density / density.sum()).ravel()
    points = identity_map(20, np.float64).reshape(-1, 3)
    B = smooth_map.interpolation_matrix(points, size)
    ratio = (size - 1) / (smooth_map.REFERENCE_SIZE - 1)
    system = (B.T @ sp.diags(weights) @ B + sp.eye(size ** 3) * 1e-12
              + smooth_map._regulariser(size, smoothness * ratio, stiffness / ratio)).tocsc()
    rhs = B.T @ (weights[:, None] * (raw.reshape(-1, 3) - points))
    direct = np.stack([spsolve(system, rhs[:, c]) for c in range(3)], axis=1)
    expected = identity_map(size, np.float64) + direct.reshape(size, size, size, 3)
    fitted = fit_smooth_map(raw, density, size=size, smoothness=smoothness,
                            stiffness=stiffness)
    assert np.abs(fitted - expected).max() < 2e-5
    if size ** 3 > smooth_map._DIRECT_NODES:
        return
    # the factored fit (explore's preview: one photo, many raw maps, small lattices)
    # solves the same system, for any raw map of the photo
    fitter = smooth_map.SmoothMapFitter(density, size, smoothness, stiffness)
    assert np.abs(fitter.fit(raw) - expected).max() < 2e-5
    shifted = np.clip(raw + 0.05, 0, 1)
    assert np.abs(fitter.fit(shifted) - fit_smooth_map(
        shifted, density, size=size, smoothness=smoothness, stiffness=stiffness)).max() < 2e-5


@pytest.mark.slow
def test_smooth_map_validates_its_input():
    from wbcgrade.color.palette.smooth_map import SmoothMapFitter

    raw, density = _split_map(8)
    with pytest.raises(ValueError, match=r"raw_map must be \(n, n, n, 3\) and density"):
        fit_smooth_map(raw, density[:4])
    with pytest.raises(ValueError, match="too large"):
        SmoothMapFitter(density, 33)
    with pytest.raises(ValueError, match=r"raw_map must be \(8, 8, 8, 3\)"):
        SmoothMapFitter(density, 9).fit(raw[:4, :4, :4])
    with pytest.raises(ValueError, match="not both 0"):
        fit_smooth_map(raw, density, smoothness=0, stiffness=0)
    with pytest.raises(ValueError, match="density is empty"):
        fit_smooth_map(raw, np.zeros_like(density))


def _blob(n, centre, width=0.05):
    x = identity_map(n, np.float64)
    return np.exp(-np.sum((x - np.asarray(centre)) ** 2, axis=-1) / (2 * width ** 2))


def test_relaxation_leaves_out_palette_colours_the_photo_does_not_hold():
    """Photo: greens. Palette: a green close to them and a yellow far away. Balanced
    transport drags half the photo to yellow; relaxed transport keeps it green."""
    n = 16
    photo = _blob(n, (0.2, 0.5, 0.2))
    photo /= photo.sum()
    palette = _blob(n, (0.25, 0.55, 0.25)) + _blob(n, (0.95, 0.9, 0.1))
    palette /= palette.sum()
    density = photo.reshape(-1)
    yellow = np.array([0.95, 0.9, 0.1])

    def mean_move_to_yellow(relaxation):
        cmap, _ = color_transfer_map(photo, palette, width=1.0, relaxation=relaxation)
        moved = cmap.reshape(-1, 3)
        return np.sum(density * (np.linalg.norm(moved - yellow, axis=1)))

    balanced, relaxed = mean_move_to_yellow(None), mean_move_to_yellow(0.01)
    start = np.sum(density * np.linalg.norm(identity_map(n).reshape(-1, 3) - yellow, axis=1))
    assert balanced < start - 0.25  # pulled a long way towards yellow
    assert relaxed > start - 0.1  # stays by its own greens
    assert relaxed > balanced + 0.2


def test_regrain_reproduces_an_affine_grade_and_does_not_amplify_grain():
    rng = np.random.default_rng(1)
    texture = rng.random((120, 160, 3)).astype(np.float32)
    affine = texture @ np.array([[0.8, 0.1, 0.0], [0.0, 0.7, 0.1], [0.1, 0.0, 0.8]],
                                np.float32) + 0.05
    # strong texture (variance >> eps): the map's own contrast is kept
    assert np.abs(regrain(texture, affine, eps=1e-4) - affine).max() < 2e-3
    # flat noisy sky stretched 5x by the map: the output keeps the input's grain
    sky = np.clip(0.5 + 0.01 * rng.normal(size=(120, 160, 3)), 0, 1).astype(np.float32)
    stretched = np.clip((sky - 0.5) * 5 + 0.3, 0, 1)
    out = regrain(sky, stretched, radius=0.05)  # 8 px windows (5 px at 1024 px by default)
    assert stretched.std() > 4 * sky.std()
    assert out.std() < 1.2 * sky.std()
    assert abs(out.mean() - stretched.mean()) < 2e-3  # the colour still lands


def test_regrain_has_no_halo_away_from_edges_and_solves_large_images_on_a_subsample(
        monkeypatch):
    image = np.zeros((90, 120, 3), np.float32)
    image[:, :60] = (0.2, 0.4, 0.8)
    image[:, 60:] = (0.3, 0.6, 0.2)
    graded = image.copy()
    graded[:, :60] = (0.9, 0.7, 0.5)
    graded[:, 60:] = (0.1, 0.2, 0.1)
    out = regrain(image, graded, radius=0.02)  # 2-3 px windows
    far = np.r_[0:50, 70:120]
    assert np.abs(out[:, far] - graded[:, far]).max() < 1 / 255
    # the subsampled solve (fast guided filter) agrees with the full one on smooth images
    y, x = np.mgrid[0:90, 0:120] / 120.0
    smooth = np.stack([x, y, 0.5 + 0.2 * x * y], axis=-1).astype(np.float32)
    mapped = np.clip(smooth ** 1.5 + 0.05, 0, 1)
    full = regrain(smooth, mapped)
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", 90 * 120 // 9)
    subsampled = regrain(smooth, mapped)
    assert np.abs(subsampled - full).mean() < 2 / 255


def test_keep_lightness_keeps_oklab_lightness():
    from wbcgrade.color._colour import colour

    cmap = np.clip(identity_map(9, np.float64)[..., ::-1] * 0.6 + 0.2, 0, 1)  # a hue swap
    kept = keep_lightness(cmap, ColorEncoding.of())

    def lightness(encoded):
        linear = colour.cctf_decoding(encoded, function="sRGB")
        return colour.XYZ_to_Oklab(colour.RGB_to_XYZ(linear, "sRGB"))[..., 0]

    inside = (kept > 0.01).all(axis=-1) & (kept < 0.99).all(axis=-1)
    assert inside.mean() > 0.5
    assert np.abs(lightness(kept) - lightness(identity_map(9, np.float64)))[inside].max() < 0.01
    assert np.abs(kept - identity_map(9)).max() > 0.1  # the colour still changed


@pytest.mark.slow
def test_default_grade_is_a_lattice_lut_with_regrain(scene):
    rgb, style_dir = scene
    from wbcgrade.color.presets import load_style_folder

    opts = GradeOptions(mode="palette", bins=16, fit_bins=8, max_iter=10, n_iter=30)
    styles = load_style_folder(style_dir, 16)
    grade = grade_of(rgb, styles, opts)
    assert grade.color_map.shape == (33, 33, 33, 3) and grade.regrain is not None
    assert grade.info["map"]["size"] == 33 and grade.info["sinkhorn"]["relaxation"] is None
    plain = GradeOptions(mode="palette", bins=16, fit_bins=8, max_iter=10, n_iter=30, smoothness=0,
                         stiffness=0, regrain=False)
    raw = grade_of(rgb, styles, plain)
    assert raw.color_map.shape == (16, 16, 16, 3) and raw.regrain is None
    lum = grade_of(rgb, StyleSet(styles.names, styles.histograms),
                   GradeOptions(mode="palette", bins=16, fit_bins=8, max_iter=10, n_iter=30,
                                preserve_luminance=True))
    assert lum.info["map"]["preserve_luminance"] is True
    before, after = rgb.reshape(-1, 3), lum.apply(rgb.reshape(-1, 3))
    luma = np.array([0.2126, 0.7152, 0.0722])
    assert np.abs((after - before) @ luma).mean() < np.abs((grade.apply(before) - before)
                                                          @ luma).mean()


@pytest.mark.parametrize("field,value", [("relaxation", -1.0), ("relaxation", float("nan")),
                                         ("map_size", 1), ("smoothness", -1.0),
                                         ("regrain_eps", 0.0), ("regrain_radius", -0.1)])
def test_look_options_are_validated(field, value):
    from wbcgrade.color.options import FLAT_FIELDS
    from wbcgrade.errors import OptionError

    with pytest.raises(OptionError, match="must") as caught:
        GradeOptions(**{field: value})
    assert caught.value.option == ".".join(FLAT_FIELDS[field])  # the field, e.g. map.size
    assert str(caught.value).startswith(caught.value.option)


@pytest.mark.slow
def test_histogram_of_regrained_output_still_lands_near_the_palette(scene):
    """Regrain keeps grain, not the input's palette: the graded palette moves as much."""
    rgb, style_dir = scene
    from wbcgrade.color.presets import load_style_folder

    styles = load_style_folder(style_dir, 16)
    opts = GradeOptions(mode="palette", bins=16, fit_bins=8, max_iter=10, n_iter=30)
    grade = grade_of(rgb, styles, opts)
    with_regrain = grade.apply(rgb)
    without = replace(grade, regrain=None).apply(rgb)
    h_in, h_with, h_without = (image_histogram(x, 8) for x in (rgb, with_regrain, without))
    assert np.abs(h_with - h_without).sum() < 0.5 * np.abs(h_in - h_without).sum()


def test_monotone_lightness_removes_reversals_and_keeps_monotone_maps():
    x = identity_map(17, np.float64)
    # a map whose output luma falls when red rises past 0.5 (a lightness reversal)
    bent = 0.2 + 0.6 * x
    bent[..., 1] = 0.2 + 0.6 * np.abs(x[..., 0] - 0.5) * 2 * 0.5 + 0.3 * x[..., 1]
    luma_before = bent @ LUMA_WEIGHTS
    assert np.diff(luma_before, axis=0).min() < -0.01
    fixed = monotone_lightness(bent)
    luma = fixed.astype(np.float64) @ LUMA_WEIGHTS
    for axis in range(3):
        assert np.diff(luma, axis=axis).min() > -1e-6
    # only the lightness moved: channel differences (hue, chroma) are kept
    np.testing.assert_allclose(np.diff(fixed, axis=-1), np.diff(bent, axis=-1), atol=1e-6)
    # a map that is already monotone is left alone
    affine = 0.1 + 0.8 * x
    np.testing.assert_allclose(monotone_lightness(affine), affine, atol=1e-6)


def test_monotone_lightness_holds_at_the_cube_faces():
    """Where the shift along grey would leave the cube, the clipped part goes to the
    channels with room: no reversal is left (a plain clip left up to 0.07 on these)."""
    for seed in range(3):
        table = np.random.default_rng(seed).uniform(0.0, 1.0, (9, 9, 9, 3))
        fixed = monotone_lightness(table)
        assert fixed.min() >= 0.0 and fixed.max() <= 1.0
        luma = fixed.astype(np.float64) @ LUMA_WEIGHTS
        for axis in range(3):
            assert np.diff(luma, axis=axis).min() > -1e-6, (seed, axis)
