"""The fused remap of large photos (colour map and block means in one pass, no full-size
graded image) gives the numbers of the two steps, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

import wbcgrade.color.mapping.regrain as regrain_module
from wbcgrade.color.mapping.regrain import regrain, regrain_map
from wbcgrade.color.mapping.remap import apply_color_map, block_means_mapped, identity_map


def _image_and_map(rng, h=61, w=47, size=9):
    rgb = rng.random((h, w, 3)).astype(np.float32) * 1.2 - 0.1  # some values out of range
    table = np.clip(identity_map(size) ** 1.7 + 0.05 * rng.standard_normal((size,) * 3 + (3,)),
                    0.0, 1.0).astype(np.float32)
    return rgb, table


@pytest.mark.slow
@pytest.mark.parametrize("step", [1, 2, 3, 5])
@pytest.mark.parametrize("strength", [1.0, 0.6])
def test_block_means_of_the_mapped_image(rng, step, strength):
    rgb, table = _image_and_map(rng)
    expected = regrain_module._downsample(apply_color_map(rgb, table, strength), step)
    kernel = block_means_mapped(rgb, table, strength, step)
    np.testing.assert_allclose(kernel, expected, rtol=0, atol=1e-6)
    mapped, source = block_means_mapped(rgb, table, strength, step, with_source=True)
    assert np.array_equal(mapped, kernel)
    np.testing.assert_allclose(source, regrain_module._downsample(rgb, step), rtol=0,
                               atol=1e-6)
    # OpenColorIO's LUT and OpenCV's area means: the kernel's numbers to float32 rounding
    library_mapped, library_source = regrain_module._block_means(rgb, table, strength, step)
    np.testing.assert_allclose(library_mapped, kernel, rtol=0, atol=1e-6)
    np.testing.assert_allclose(library_source, source, rtol=0, atol=1e-6)


def test_the_library_block_means_are_the_kernels_on_a_large_image(rng):
    """A large photo's map and block means (OpenColorIO's LUT processor and OpenCV's area
    resize, in bands on every core; colours out of the cube clipped as the kernel clips
    them): the compiled kernel's numbers to float32 rounding, its shape (partial edge
    blocks dropped) and no full-size array of it returned."""
    pytest.importorskip("PyOpenColorIO")
    rgb, table = _image_and_map(rng, h=301, w=203, size=17)
    for step, strength in [(4, 1.0), (3, 0.7), (7, 0.0)]:
        mapped, source = regrain_module._block_means(rgb, table, strength, step)
        kernel = block_means_mapped(rgb, table, strength, step, with_source=True)
        assert mapped.shape == source.shape == (301 // step, 203 // step, 3)
        np.testing.assert_allclose(mapped, kernel[0], rtol=0, atol=1e-6)
        np.testing.assert_allclose(source, kernel[1], rtol=0, atol=1e-6)


@pytest.mark.parametrize("library", [True, False])  # the map's block means by OpenColorIO
@pytest.mark.parametrize("max_pixels", [10 ** 6, 700])  # solved at full size / subsampled
def test_regrain_map_is_regrain_of_the_mapped_image(rng, monkeypatch, max_pixels, library):
    """Bit for bit where solved at full size; to float32 rounding on a subsampled copy
    (the block means of the mapped colours by the compiled kernel, or by OpenColorIO's
    LUT and OpenCV's area means, against OpenCV's area means of the mapped image)."""
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", max_pixels)
    if not library:
        monkeypatch.setattr(regrain_module, "lut_processor", lambda *args: None)
    rgb, table = _image_and_map(rng)
    rgb = np.clip(rgb, 0.0, 1.0)
    subsampled = regrain_module._step(*rgb.shape[:2]) > 1
    assert subsampled == (max_pixels < rgb.size)
    expected = regrain(rgb, apply_color_map(rgb, table, 0.8), 0.05, 0.01)
    if subsampled:
        np.testing.assert_allclose(regrain_map(rgb, table, 0.8, 0.05, 0.01), expected,
                                   rtol=0, atol=1e-5)
    else:
        assert np.array_equal(regrain_map(rgb, table, 0.8, 0.05, 0.01), expected)


@pytest.mark.parametrize("shape, coarse, step", [((23, 31), (6, 8), 4.0), ((9, 7), (3, 2), 3.0),
                                                 ((5, 6), (1, 2), 4.0), ((75, 40), (9, 5), 8.0),
                                                 ((70, 13), (1, 1), 9.0)])
def test_regrain_applies_bilinearly_interpolated_coefficients(rng, shape, coarse, step):
    source = rng.random((*shape, 3)).astype(np.float32)
    A = (rng.random((*coarse, 3, 3)).astype(np.float32) - 0.5) * 0.5
    b = (rng.random((*coarse, 3)).astype(np.float32) - 0.5) * 0.2

    def weights(n_out, n_in):  # (n_out, n_in) bilinear weights, pixel centres, edges clamped
        pos = np.clip((np.arange(n_out) + 0.5) / step - 0.5, 0.0, n_in - 1.0)
        lo = np.minimum(pos.astype(int), max(n_in - 2, 0))
        frac = pos - lo
        m = np.zeros((n_out, n_in))
        m[np.arange(n_out), lo] += 1 - frac
        m[np.arange(n_out), np.minimum(lo + 1, n_in - 1)] += frac
        return m

    wy, wx = weights(shape[0], coarse[0]), weights(shape[1], coarse[1])
    A_full = np.einsum("yi,xj,ijac->yxac", wy, wx, A)
    b_full = np.einsum("yi,xj,ijc->yxc", wy, wx, b)
    expected = np.clip(source + np.einsum("yxac,yxa->yxc", A_full, source) + b_full, 0, 1)
    out = np.empty_like(source)
    coefficients = np.concatenate([A.reshape(*coarse, 9), b], axis=-1)
    regrain_module._apply_upsampled(source, coefficients, step, out)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-6)
    # a large photo's route (OpenCV's resize of the coefficients band by band, numpy's
    # affine maps): the same numbers, rows and columns past the last node included
    library = np.full_like(source, np.nan)
    regrain_module._apply_upsampled_cv2(source, coefficients, int(step), library)
    np.testing.assert_allclose(library, expected, rtol=0, atol=1e-6)
    regrain_module._apply_upsampled_cv2(source, coefficients, int(step), source)  # in place
    np.testing.assert_allclose(source, expected, rtol=0, atol=1e-6)


@pytest.mark.parametrize("shape, radius", [((37, 53, 5), 3), ((7, 5, 2), 9), ((1, 6, 3), 2),
                                           ((6, 1, 1), 4), ((70, 40, 12), 1)])
def test_box_means_are_scipys_uniform_filter(rng, shape, radius):
    """OpenCV's box filter (wider than the image too: mirrored again and again; up to 12
    channels in one call, more in turn) gives scipy.ndimage's reflect-mode uniform filter
    on every channel, to float32 rounding."""
    from scipy import ndimage

    x = rng.random(shape).astype(np.float32) * 2 - 0.5
    expected = np.stack([ndimage.uniform_filter(x[..., k], size=2 * radius + 1, mode="reflect")
                         for k in range(shape[2])], axis=-1)
    np.testing.assert_allclose(regrain_module._box_cv2(x, radius), expected, rtol=0, atol=1e-6)
    wide = np.concatenate([x] * 5, axis=-1)  # over 12 channels
    np.testing.assert_allclose(regrain_module._box_cv2(wide, radius),
                               np.concatenate([expected] * 5, axis=-1), rtol=0, atol=1e-6)


@pytest.mark.slow
def test_window_models_solve_the_regularised_local_fit(rng):
    """Each window's A, b are the ridge regression of the change on the guide over the
    window (the covariances of every pixel in it, numpy's solver), at an inner pixel."""
    guide = rng.random((15, 17, 3)).astype(np.float32)
    change = (0.3 * guide[..., ::-1] ** 2 - 0.1
              + 0.02 * rng.standard_normal(guide.shape)).astype(np.float32)
    radius, eps, y, x = 2, 0.01, 7, 9
    models = regrain_module._window_models_numpy(guide, change, radius, eps, None,
                                                 regrain_module._uniform_filter_cv2)
    window = np.s_[y - radius:y + radius + 1, x - radius:x + radius + 1]
    g = guide[window].reshape(-1, 3).astype(np.float64)
    d = change[window].reshape(-1, 3).astype(np.float64)
    g_centred, d_centred = g - g.mean(0), d - d.mean(0)
    A = np.linalg.solve(g_centred.T @ g_centred / len(g) + eps * np.eye(3),
                        g_centred.T @ d_centred / len(g))
    b = d.mean(0) - A.T @ g.mean(0)
    np.testing.assert_allclose(models[y, x, :9].reshape(3, 3), A, rtol=0, atol=2e-5)
    np.testing.assert_allclose(models[y, x, 9:], b, rtol=0, atol=2e-5)


@pytest.mark.parametrize("max_pixels", [10 ** 6, 700])  # solved at full size / subsampled
def test_regrain_writes_into_out_even_over_its_input(rng, monkeypatch, max_pixels):
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", max_pixels)
    rgb, table = _image_and_map(rng)
    rgb = np.clip(rgb, 0.0, 1.0)
    expected = regrain_map(rgb, table, 0.8, 0.05, 0.01)
    out = np.full_like(rgb, np.nan)
    assert regrain_map(rgb, table, 0.8, 0.05, 0.01, out=out) is out
    assert np.array_equal(out, expected)
    in_place = rgb.copy()
    assert regrain_map(in_place, table, 0.8, 0.05, 0.01, out=in_place) is in_place
    assert np.array_equal(in_place, expected)
    graded = apply_color_map(rgb, table, 0.8)
    source = rgb.copy()
    assert regrain(source, graded, 0.05, 0.01, out=source) is source
    if max_pixels < rgb.size:  # block means of the mapped colours: to float32 rounding
        np.testing.assert_allclose(source, expected, rtol=0, atol=1e-5)
    else:
        assert np.array_equal(source, expected)
    with pytest.raises(ValueError, match="out must be"):
        regrain_map(rgb, table, 0.8, 0.05, 0.01, out=np.empty(rgb.shape, np.float64))


@pytest.mark.parametrize("max_pixels", [10 ** 6, 700])  # solved at full size / subsampled
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_map_that_moves_nothing_is_not_regrained(rng, monkeypatch, max_pixels, dtype):
    """The identity map (a look the styles do not share), or any map at strength 0: the
    regrain is the colours themselves clipped to the cube (no change, so every window's
    A and b are 0), returned without solving anything; what the solve gives to its float
    rounding. A map one node off is regrained."""
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", max_pixels)
    rgb, table = _image_and_map(rng)
    identity = identity_map(9, dtype)
    solved = regrain_map(rgb, identity, 1.0, 0.05, 0.01, follow=0.5)
    assert regrain_module.moves_nothing(identity)
    assert regrain_module.moves_nothing(table, 0.0)

    def no_solve(*args, **kwargs):
        raise AssertionError("solved a regrain that moves nothing")

    monkeypatch.setattr(regrain_module, "_regrain_upsampled", no_solve)
    monkeypatch.setattr(regrain_module, "regrain", no_solve)
    for color_map, strength in [(identity, 1.0), (identity, 0.4), (table, 0.0)]:
        out = np.full(rgb.shape, np.nan, np.float32)
        assert regrain_map(rgb, color_map, strength, 0.05, 0.01, out=out) is out
        assert np.array_equal(out, np.clip(rgb, 0.0, 1.0).astype(np.float32))
    np.testing.assert_allclose(out, solved, rtol=0, atol=1e-6)
    moved = identity.copy()
    moved[4, 4, 4, 0] += dtype(1e-3)
    assert not regrain_module.moves_nothing(moved)
    assert not regrain_module.moves_nothing(table, 1e-3)
    with pytest.raises(AssertionError, match="moves nothing"):
        regrain_map(rgb, moved, 1.0, 0.05, 0.01)


@pytest.mark.parametrize("shape, radius, rows", [((50, 23, 3), 3, 8), ((50, 23, 3), 9, 4),
                                                 ((9, 31, 3), 2, 64), ((3, 4, 3), 5, 2)])
@pytest.mark.parametrize("precise", [True, False])
@pytest.mark.parametrize("with_prior", [False, True])
def test_window_models_by_bands_are_those_of_whole_planes(rng, monkeypatch, shape, radius,
                                                         rows, precise, with_prior):
    """A large grid's window models are made band by band of rows (each band's moments
    filtered with the radius of rows beyond it, the bands of each thread in turn): the
    numbers of whole planes of moments filtered by OpenCV and solved, bit for bit, with
    bands shorter than the radius and a grid shorter than one band."""
    monkeypatch.setattr(regrain_module, "_MOMENT_ROWS", rows)
    guide = rng.random(shape).astype(np.float32)
    change = (0.3 * guide[..., ::-1] ** 2 - 0.1
              + 0.02 * rng.standard_normal(shape)).astype(np.float32)
    prior = (0.2 * rng.standard_normal((*shape[:2], 9))).astype(np.float32) \
        if with_prior else None
    banded = regrain_module._window_models_numpy(guide, change, radius, 0.04, prior,
                                                 regrain_module._uniform_filter_cv2, precise)

    def whole_planes(plane, size, out):  # (not the banded filter: one call per plane)
        regrain_module._uniform_filter_cv2(plane, size, out)

    planes = regrain_module._window_models_numpy(guide, change, radius, 0.04, prior,
                                                 whole_planes, precise)
    assert np.array_equal(banded, planes)


@pytest.mark.parametrize("shape, radius", [((37, 53, 3), 3), ((7, 5, 3), 9), ((1, 6, 3), 2)])
def test_small_grids_solved_with_numpy_match_opencvs_filter(rng, shape, radius):
    """Below ``_NUMPY_SOLVE_PIXELS`` the window models and box means are filtered with
    numpy and scipy (the numbers small photos always had), above with OpenCV's box
    filter: the same models to float32 rounding."""
    guide = rng.random(shape).astype(np.float32)
    change = (0.3 * guide[..., ::-1] ** 2 - 0.1).astype(np.float32)
    fast = regrain_module._window_models_numpy(guide, change, radius, 0.01, None,
                                               regrain_module._uniform_filter_cv2)
    plain = regrain_module._window_models_numpy(guide, change, radius, 0.01)
    np.testing.assert_allclose(plain, fast, rtol=0, atol=5e-5)
    np.testing.assert_allclose(regrain_module._box_numpy(fast, radius),
                               regrain_module._box_cv2(fast, radius), rtol=0, atol=1e-5)


@pytest.mark.parametrize("shape", [(37, 53), (1, 9), (9, 1), (1, 1), (64, 300)])
def test_a_photo_solved_at_full_size_is_applied_by_numpy_as_the_kernel_does(rng, shape):
    """A photo solved at full size (up to 1.5 megapixels) takes each pixel's own ``A, b``
    with numpy (``_apply_same_grid``: nothing to load): the kernel's float32 numbers bit
    for bit, zeros and signed zeros among the coefficients, 0 and 1 among the colours."""
    from wbcgrade.core import in_bands

    source = rng.random((*shape, 3), dtype=np.float32)
    source[rng.random(shape) < 0.1] = 0.0
    source[rng.random(shape) < 0.1] = 1.0
    coefficients = (rng.standard_normal((*shape, 12)) * 0.5).astype(np.float32)
    coefficients[rng.random((*shape, 12)) < 0.05] = 0.0
    coefficients[rng.random((*shape, 12)) < 0.05] = -0.0
    width = shape[1]
    fx = np.minimum(np.maximum(np.arange(width) + 0.5 - 0.5, 0.0), width - 1.0)
    left = np.minimum(fx.astype(np.int64), width - 2) if width > 1 \
        else np.zeros(width, np.int64)
    right = np.minimum(left + 1, width - 1)
    weight = (fx - left).astype(np.float32)
    kernel = np.empty_like(source)
    in_bands(regrain_module._apply_rows, shape[0], source, coefficients, 1.0, left, right,
             weight, kernel)
    twin = np.empty_like(source)
    regrain_module._apply_same_grid(source, coefficients, twin)
    assert np.array_equal(twin.view(np.uint32), kernel.view(np.uint32))
    regrain_module._apply_same_grid(source, coefficients, source)  # in place
    assert np.array_equal(source.view(np.uint32), kernel.view(np.uint32))


_WITHOUT_NUMBA = """
import sys
import numpy as np
import wbcgrade.core._cpu as cpu
from wbcgrade.color.mapping.regrain import regrain_map
from wbcgrade.color.io._quantise import to_uint8

cpu.fast_cpu = lambda *args, **kwargs: None  # (its own helper: not what this test is about)
rng = np.random.default_rng(0)
rgb = rng.random((700, 1000, 3), dtype=np.float32)
table = (np.stack(np.meshgrid(*[np.linspace(0, 1, 9)] * 3, indexing="ij"), -1) ** 1.5)
graded = regrain_map(rgb, table.astype(np.float32), 0.8)
to_uint8(graded)
assert "numba" not in sys.modules, "numba loaded"
"""


@pytest.mark.slow
def test_a_photo_solved_at_full_size_is_graded_without_numba():
    """A 0.7-megapixel photo's regrain (solved at full size: OpenCV's box filter, the numpy
    solve and the numpy twins of the map and the apply) and its 8-bit conversion load no
    compiled kernel: numba's start (~0.7 s) is not paid by a saved grade of that size."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _WITHOUT_NUMBA], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr[-3000:]


# numpy twins: a small photo's first grade runs numpy instead of loading numba's compiler
# (wbcgrade.core.numpy_first); both give the same float32 numbers, bit for bit.

def _kernel_trilinear(colors, table, strength):
    from wbcgrade.color.mapping.remap import _trilinear
    from wbcgrade.core import in_bands

    out = np.empty_like(colors)
    in_bands(_trilinear, colors.shape[0], colors, table, np.float32(strength), out)
    return out


@pytest.mark.parametrize("size", [2, 9, 33])
@pytest.mark.parametrize("strength", [1.0, 0.37, 0.0])
def test_trilinear_numpy_twin_is_the_kernel_bit_for_bit(rng, size, strength):
    from wbcgrade.color.mapping.remap import _trilinear_numpy

    colors = (rng.random((20000, 3)) * 1.4 - 0.2).astype(np.float32)  # > 1 chunk, out of range
    colors[:64] = np.round(colors[:64] * 4) / 4  # nodes, 0 and 1 exactly
    colors[64] = -0.0
    table = (rng.random((size,) * 3 + (3,)) * 1.2 - 0.1).astype(np.float32)
    twin = _trilinear_numpy(colors, table, strength)
    assert twin.dtype == np.float32
    assert np.array_equal(twin.view(np.uint32), _kernel_trilinear(colors, table, strength)
                          .view(np.uint32))


@pytest.mark.parametrize("shape, coarse, step", [((40, 57), (40, 57), 1.0),
                                                 ((97, 130), (33, 44), 3.0),
                                                 ((50, 80), (2, 3), 27.0),
                                                 ((16, 16), (1, 1), 16.0)])
def test_upsampled_apply_numpy_twin_is_the_kernel_bit_for_bit(rng, shape, coarse, step):
    from wbcgrade.core import in_bands

    source = rng.random((*shape, 3)).astype(np.float32)
    source[0, 0] = 0.0
    coefficients = (rng.standard_normal((*coarse, 12)) * 0.3).astype(np.float32)
    lw = coarse[1]
    fx = np.minimum(np.maximum((np.arange(shape[1]) + 0.5) / step - 0.5, 0.0), lw - 1.0)
    left = np.minimum(fx.astype(np.int64), lw - 2) if lw > 1 else np.zeros(shape[1], np.int64)
    right = np.minimum(left + 1, lw - 1)
    weight = (fx - left).astype(np.float32)
    kernel = np.empty_like(source)
    in_bands(regrain_module._apply_rows, shape[0], source, coefficients, step, left, right,
             weight, kernel)
    twin = np.empty_like(source)
    regrain_module._apply_rows_numpy(source, coefficients, step, left, right, weight, twin)
    assert np.array_equal(twin.view(np.uint32), kernel.view(np.uint32))
    regrain_module._apply_rows_numpy(source, coefficients, step, left, right, weight, source)
    assert np.array_equal(source.view(np.uint32), kernel.view(np.uint32))  # in place


def test_numpy_first_only_for_small_work_before_the_kernel_ran(monkeypatch):
    import wbcgrade.core._jit as jit
    from wbcgrade.core import compiled, numpy_first

    @compiled()
    def kernel(x):  # pragma: no cover - compiled
        return x + 1

    other = compiled()(lambda x: x - 1)
    third = compiled()(lambda x: x * 2)
    monkeypatch.setattr(jit, "_prefer_compiled", False)  # as in a fresh process
    monkeypatch.setattr(jit, "_made", False)  # (no kernel has run yet)
    assert numpy_first(kernel, 10, 100) and not numpy_first(kernel, 1000, 100)
    # a batch of small work: the twin takes up to 4 x the limit, then the kernel is loaded
    assert [numpy_first(kernel, 100, 100) for _ in range(5)] == [True] * 3 + [False] * 2
    assert numpy_first(other, 10, 100)  # each kernel its own budget
    monkeypatch.setattr(jit, "_prefer_compiled", True)  # a batch: kernels from the start
    assert not numpy_first(other, 10, 100)
    monkeypatch.setattr(jit, "_prefer_compiled", False)
    kernel(1)
    assert not numpy_first(kernel, 10, 100)  # loaded: the kernel is the faster one now
    monkeypatch.setattr(jit, "_made", True)  # a kernel ran: numba's compiler is loaded
    assert not numpy_first(third, 10, 100)  # so a third one's first call costs its cache


@pytest.mark.parametrize("shape", [(30, 45), (1, 1), (1, 7), (5, 3), (64, 9)])
@pytest.mark.parametrize("radius", [1, 2, 7, 40])
def test_uniform_filter_numpy_twin_is_scipys_bit_for_bit(rng, shape, radius):
    """A small photo's regrain filters with numpy while scipy.ndimage is not loaded (its
    import costs more than the filter): the numbers of scipy's reflect-mode filter."""
    from scipy import ndimage

    plane = (rng.random(shape) * rng.choice([1e-3, 1.0, 100.0])).astype(np.float32)
    expected = np.empty_like(plane)
    ndimage.uniform_filter(plane, size=2 * radius + 1, mode="reflect", output=expected)
    twin = regrain_module._uniform_filter_numpy(plane, 2 * radius + 1)
    assert twin.dtype == np.float32
    assert np.array_equal(twin.view(np.uint32), expected.view(np.uint32))


_LOADED_AHEAD = """
import sys
import numpy as np
import wbcgrade.color.mapping.regrain as regrain
import wbcgrade.color.mapping.remap as remap

regrain.has_lut_library = lambda: False  # (as without the opencolorio package)
regrain.lut_processor = lambda *args: None
assert not regrain.load_kernels(1_000_000) and "numba" not in sys.modules
assert regrain.load_kernels(16_000_000)
loaded = list(remap._block_means_mapped.signatures)
assert len(loaded) == 1, loaded
regrain._MAX_SOLVE_PIXELS, regrain._NUMPY_SOLVE_PIXELS = 700, 1  # the compiled solve
rng = np.random.default_rng(0)
rgb = rng.random((61, 47, 3), dtype=np.float32)
table = (np.stack(np.meshgrid(*[np.linspace(0, 1, 9)] * 3, indexing="ij"), -1) ** 1.5)
regrain.regrain_map(rgb, table.astype(np.float32), 0.8, 0.05, 0.01)
assert list(remap._block_means_mapped.signatures) == loaded
"""


@pytest.mark.slow
def test_kernels_loaded_ahead_are_the_ones_a_large_photo_runs():
    """Without OpenColorIO, ``load_kernels`` (what ``apply`` starts in a thread before
    decoding a large photo) loads the one kernel of the subsampled regrain (its map's
    block means) with the argument types the grade then calls it with: the grade adds no
    signature (no second compilation); a photo solved at full size loads nothing (numba
    not even imported)."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _LOADED_AHEAD], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr[-3000:]


_LARGE_WITHOUT_NUMBA = """
import sys
import numpy as np
import wbcgrade.color.mapping.regrain as regrain
from wbcgrade.color.io._quantise import to_uint8

assert not regrain.kernels_needed() and not regrain.load_kernels(16_000_000)
regrain._MAX_SOLVE_PIXELS, regrain._NUMPY_APPLY_PIXELS = 20_000, 0  # solved subsampled
rng = np.random.default_rng(0)
rgb = rng.random((300, 400, 3), dtype=np.float32)
table = (np.stack(np.meshgrid(*[np.linspace(0, 1, 9)] * 3, indexing="ij"), -1) ** 1.5)
assert regrain._step(300, 400) > 1
for follow in (0.0, 1.0):
    to_uint8(regrain.regrain_map(rgb, table.astype(np.float32), 0.8, follow=follow))
assert "numba" not in sys.modules, "numba loaded"
"""


@pytest.mark.slow
def test_a_photo_solved_on_a_subsampled_copy_is_graded_without_numba():
    """With OpenColorIO, a large photo's regrain (the map's block means by OpenColorIO and
    OpenCV, the coefficients' upsampling by OpenCV) and its 8-bit conversion load no
    compiled kernel, and nothing is loaded ahead: numba's start (~0.6 s of CPU) is not
    paid by a 16-megapixel grade."""
    pytest.importorskip("PyOpenColorIO")
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _LARGE_WITHOUT_NUMBA], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr[-3000:]


def test_apply_starts_one_kernel_loader_and_only_for_a_large_photo(monkeypatch, tmp_path):
    """``grade_photo``'s loader (where a large photo needs a kernel: no OpenColorIO):
    nothing for a photo solved at full size (its header says 1.4 megapixels), one thread
    for a larger one, handed the header's pixel count, and none again in the same
    process; none at all where OpenColorIO maps the colours (its header not even read)."""
    import wbcgrade.photos.workflow as workflow

    sizes = {"small.jpg": 1_400_000, "large.jpg": 16_000_000, "next.jpg": 24_000_000}
    loaded = []
    monkeypatch.setattr(workflow, "_LOADER", [])
    monkeypatch.setattr(workflow, "kernels_needed", lambda: True)  # (without OpenColorIO)
    monkeypatch.setattr(workflow, "header_pixels", lambda path: sizes[path.name])
    monkeypatch.setattr(workflow, "load_kernels", loaded.append)
    assert workflow.load_kernels_beside(tmp_path / "small.jpg") is None
    thread = workflow.load_kernels_beside(tmp_path / "large.jpg")
    assert thread is not None
    thread.join(timeout=30)
    assert loaded == [16_000_000]
    assert workflow.load_kernels_beside(tmp_path / "next.jpg") is None
    assert loaded == [16_000_000]
    monkeypatch.setattr(workflow, "_LOADER", [])
    monkeypatch.setattr(workflow, "kernels_needed", lambda: False)
    monkeypatch.setattr(workflow, "header_pixels", lambda path: 1 / 0)
    assert workflow.load_kernels_beside(tmp_path / "large.jpg") is None


def test_a_subsampled_solve_in_float32_is_the_float64_one_to_its_rounding(rng, monkeypatch):
    """A photo solved on a subsampled copy solves its window models in float32 (the
    precision of the window means they are made of): within 1e-6 of the float64 solve
    at the default eps; a small eps (nearly singular covariances) keeps float64."""
    guide = rng.random((40, 50, 3)).astype(np.float32)
    change = (0.3 * guide[..., ::-1] ** 2 - 0.1
              + 0.02 * rng.standard_normal(guide.shape)).astype(np.float32)
    solved = []
    real = regrain_module._solve_band
    monkeypatch.setattr(regrain_module, "_solve_band",
                        lambda m, *args: (solved.append(m.dtype.type), real(m, *args))[1])
    precise = regrain_module._coefficients(guide, change, 3, 0.04)
    fast = regrain_module._coefficients(guide, change, 3, 0.04, precise=False)
    assert set(solved) == {np.float64, np.float32}
    np.testing.assert_allclose(fast, precise, rtol=0, atol=1e-6)
    solved.clear()
    regrain_module._coefficients(guide, change, 3, 1e-5, precise=False)
    assert set(solved) == {np.float64}
    solved.clear()  # the subsampled regrain asks for float32, a full-size one does not
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", 700)
    rgb, table = _image_and_map(rng)
    regrain_map(np.clip(rgb, 0, 1), table, 0.8)
    assert set(solved) == {np.float32}
    monkeypatch.setattr(regrain_module, "_MAX_SOLVE_PIXELS", 10 ** 6)
    solved.clear()
    regrain_map(np.clip(rgb, 0, 1), table, 0.8)
    assert set(solved) == {np.float64}


def test_a_subsampled_solve_reads_its_prior_through_opencolorio(rng, monkeypatch):
    """The grain prior of a subsampled solve (a preset's or a matched scene's look) is read
    at each window's mean colour by OpenColorIO's LUT processor: the trilinear lookup of
    ``apply_color_map`` to float32 rounding (the prior's values are not colours: below 0
    and above 1 too); a full-size solve reads it as before."""
    pytest.importorskip("PyOpenColorIO")
    colors = rng.random((37, 41, 3)).astype(np.float32)
    table = (rng.standard_normal((9, 9, 9, 3)) * 0.4).astype(np.float32)
    expected = apply_color_map(colors, table)
    np.testing.assert_allclose(regrain_module._read_prior(colors, table, False), expected,
                               rtol=0, atol=1e-6)
    looked = []
    monkeypatch.setattr(regrain_module, "lut_processor",
                        lambda *args: looked.append(args) or None)
    assert np.array_equal(regrain_module._read_prior(colors, table, True), expected)
    assert not looked  # (precise: apply_color_map itself)


@pytest.mark.parametrize("shape, radius", [((300, 50, 12), 3), ((97, 31, 5), 1),
                                           ((400, 20, 3), 7), ((30, 40, 12), 7)])
def test_box_means_in_bands_of_rows_are_one_calls_bit_for_bit(rng, shape, radius,
                                                               monkeypatch):
    """OpenCV's box filter on two bands of rows (each with the radius of rows beyond it)
    gives the numbers of one call over the whole image, bit for bit."""
    import cv2

    x = (rng.random(shape) * 2 - 0.5).astype(np.float32)
    whole = np.empty_like(x)
    cv2.boxFilter(x, -1, (2 * radius + 1,) * 2, dst=whole, normalize=True,
                  borderType=cv2.BORDER_REFLECT)
    monkeypatch.setattr(regrain_module, "num_threads", lambda: 2)
    calls = []
    real = regrain_module._uniform_filter_cv2
    monkeypatch.setattr(regrain_module, "_uniform_filter_cv2",
                        lambda plane, *args: (calls.append(plane.shape[0]), real(plane, *args)))
    assert np.array_equal(regrain_module._box_cv2(x, radius).view(np.uint32),
                          whole.view(np.uint32))
    tall = shape[0] >= 16 * (2 * radius + 1)
    assert len(calls) == (2 if tall else 1)  # in two bands on two cores where it is tall
