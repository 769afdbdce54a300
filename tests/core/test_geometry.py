import numpy as np
import pytest

from wbcgrade.core import DenseGeometry, GridGeometry


@pytest.mark.parametrize("shape", [(11,), (6, 7), (4, 5, 6)])
def test_grid_kernel_matches_dense_kernel(shape, rng):
    geom = GridGeometry(shape, gamma=0.05)
    K = np.exp(-geom.cost_matrix() / geom.gamma)
    x = rng.random((3, *shape))
    expected = (x.reshape(3, -1) @ K.T).reshape(x.shape)
    np.testing.assert_allclose(geom.apply(x), expected, rtol=1e-12, atol=1e-15)


def test_grid_points_are_linspace_in_c_order():
    geom = GridGeometry((3, 2), gamma=0.1)
    np.testing.assert_allclose(
        geom.points, [[0, 0], [0, 1], [0.5, 0], [0.5, 1], [1, 0], [1, 1]]
    )


@pytest.mark.parametrize("shape", [(9,), (5, 6), (4, 3, 5)])
def test_log_apply_is_exact_including_zeros(shape, rng):
    geom = GridGeometry(shape, gamma=0.02)
    x = rng.random((2, *shape))
    x[x < 0.3] = 0.0
    K = np.exp(-geom.cost_matrix() / geom.gamma)
    expected = np.log((x.reshape(2, -1) @ K.T).reshape(x.shape))
    with np.errstate(divide="ignore"):
        got = geom.log_apply(np.log(x))
    np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_log_apply_survives_ranges_that_underflow_in_linear_domain():
    geom = GridGeometry(200, gamma=1e-4)  # exp(-1/gamma) underflows across the domain
    f = np.full(200, -np.inf)
    f[0] = 0.0
    out = geom.log_apply(f)
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out, -(geom.axes[0] ** 2) / geom.gamma, rtol=1e-12)


def test_denormal_kernel_entries_are_zeroed():
    for dtype in (np.float32, np.float64):
        geom = GridGeometry(128, gamma=2 * (1.5 / 127) ** 2, dtype=dtype)
        k = geom.kernels[0]
        assert k.dtype == dtype
        nonzero = k[k != 0]
        assert nonzero.min() >= np.finfo(dtype).tiny
        assert np.count_nonzero(k) < k.size  # far entries were truncated


def test_with_width_sets_gamma():
    geom = GridGeometry.with_width((33, 33), 2.0)
    assert geom.gamma == pytest.approx(2 * (2.0 / 32) ** 2)
    assert geom.width == pytest.approx(2.0)


def test_dense_geometry_matches_grid(rng):
    grid = GridGeometry((5, 4), gamma=0.07)
    dense = DenseGeometry(grid.cost_matrix(), gamma=0.07, points=grid.points)
    x = rng.random((2, 20))
    np.testing.assert_allclose(dense.apply(x), grid.apply(x.reshape(2, 5, 4)).reshape(2, 20))
    np.testing.assert_allclose(
        dense.log_apply(np.log(x)), grid.log_apply(np.log(x.reshape(2, 5, 4))).reshape(2, 20)
    )


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: GridGeometry((8, 8), gamma=0.0), "gamma"),
        (lambda: GridGeometry((8, 8), gamma=-1.0), "gamma"),
        (lambda: GridGeometry((8, 8), gamma=float("nan")), "gamma"),
        (lambda: GridGeometry((8, 1), gamma=0.1), "at least 2"),
        (lambda: DenseGeometry(np.ones((3, 4)), gamma=0.1), "square"),
        (lambda: DenseGeometry([[0, 1], [2, 0]], gamma=0.1), "symmetric"),
        (lambda: DenseGeometry([[0, -1], [-1, 0]], gamma=0.1), "non-negative"),
        (lambda: DenseGeometry([[0, np.nan], [np.nan, 0]], gamma=0.1), "NaN"),
    ],
)
def test_bad_geometry_raises_value_error(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_apply_rejects_wrong_shape():
    geom = GridGeometry((4, 4), gamma=0.1)
    with pytest.raises(ValueError, match="shape"):
        geom.apply(np.ones((4, 5)))


def test_refine_grid_is_exact_on_multilinear_functions_and_keeps_leading_axes():
    from wbcgrade.core import refine_grid

    def f(n):
        x = np.linspace(0, 1, n)
        return 1 + 2 * x[:, None, None] - x[None, :, None] + 3 * x[None, None, :] * x[:, None, None]

    coarse = np.stack([f(5), 2 * f(5)])
    fine = refine_grid(coarse, (9, 9, 9))
    assert fine.shape == (2, 9, 9, 9)
    assert np.abs(fine - np.stack([f(9), 2 * f(9)])).max() < 1e-12
    with_inf = coarse.copy()
    with_inf[0, 0, 0, 0] = -np.inf
    assert np.all(np.isfinite(refine_grid(with_inf, (9, 9, 9))))
    with pytest.raises(ValueError, match=r"cannot refine an array of shape \(1, 4\) to \(8, 8\)"):
        refine_grid(np.zeros((1, 4)), (8, 8))


def test_one_large_histogram_is_split_over_threads_with_the_same_result(rng):
    geom = GridGeometry((70, 50, 40), 0.01)  # >= 2**17 bins: the split path
    x = rng.random((70, 50, 40))
    reference = np.empty((1, 70, 50, 40))
    geom.apply_into(x[None], reference)
    np.testing.assert_allclose(geom.apply(x), reference[0], rtol=1e-12)
    np.testing.assert_allclose(geom.apply(x[None]), reference, rtol=1e-12)


def _steep_log_values(shape, rng, count=3):
    """Log-values with ranges of thousands of nats along every axis, and zeros (-inf)."""
    axes = np.meshgrid(*[np.arange(k, dtype=float) for k in shape], indexing="ij")
    ramp = 150.0 * axes[0] - 30.0 * (axes[-1] - 5) ** 2
    f = np.stack([ramp, -ramp] + [rng.normal(0, 400, shape) for _ in range(count - 2)])
    f += rng.normal(0, 20, f.shape)
    f[rng.random(f.shape) < 0.3] = -np.inf
    return f


@pytest.mark.parametrize("shape, width", [((40,), 0.3), ((200,), 0.4), ((14, 13, 12), 0.5)])
def test_shifted_log_apply_matches_the_per_entry_log_sum_exp(shape, width, rng):
    geom = GridGeometry.with_width(shape, width)
    f = _steep_log_values(shape, rng)
    got = geom.log_apply(f)
    expected = geom._log_apply_direct(f)
    assert np.array_equal(np.isfinite(got), np.isfinite(expected))
    finite = np.isfinite(expected)
    scale = np.maximum(1.0, np.abs(expected[finite]))
    assert np.all(np.abs(got[finite] - expected[finite]) <= 1e-13 * scale)
    if geom.ndim == 1:
        assert geom.last_log_repairs > 0  # the per-block second pass ran


def test_every_pass_of_the_shifted_product_is_exact(rng):
    """A line with one huge value at one end: pass 2 (per block) and pass 3 (per entry) run."""
    import wbcgrade.core.geometry.logsum as geometry_module

    geom = GridGeometry.with_width(64, 0.5)
    f = np.full((2, 64), -np.inf)
    f[0, 0], f[0, 40:] = 5000.0, 0.0
    f[1] = rng.normal(0, 300, 64)
    calls = {"entries": 0}
    repair = geometry_module._repair_entries

    def counting(*args):
        calls["entries"] += int(args[4].sum())
        return repair(*args)

    geometry_module._repair_entries = counting
    try:
        got = geom.log_apply(f)
    finally:
        geometry_module._repair_entries = repair
    expected = geom._log_apply_direct(f)
    np.testing.assert_allclose(got, expected, rtol=1e-13)
    assert geom.last_log_repairs > 0 and calls["entries"] > 0


def test_signed_log_apply_matches_both_parts(rng):
    shape = (14, 13, 12)
    geom = GridGeometry.with_width(shape, 0.5)
    f = _steep_log_values(shape, rng)
    signs = rng.choice([-1.0, 1.0], f.shape)
    signs[f == -np.inf] = 0.0
    log_abs, sign = geom.signed_log_apply(f, signs)
    pos = geom._log_apply_direct(np.where(signs > 0, f, -np.inf))
    neg = geom._log_apply_direct(np.where(signs < 0, f, -np.inf))
    top = np.maximum(pos, neg)
    live = np.isfinite(top)
    with np.errstate(invalid="ignore"):
        got = sign * np.exp(log_abs - top)
        expected = np.exp(pos - top) - np.exp(neg - top)
    assert np.abs(got[live] - expected[live]).max() <= 1e-12
    assert np.all(sign[~live] == 0)


@pytest.mark.parametrize("shape, width", [((200,), 0.4), ((9, 10), 0.5), ((14, 13, 12), 0.5)])
def test_log_apply_in_place_equals_out_of_place(shape, width, rng):
    """Written over its input (as the log-domain barycenter does), signed or not."""
    geom = GridGeometry.with_width(shape, width)
    f = _steep_log_values(shape, rng)
    signs = rng.choice([-1.0, 1.0], f.shape)
    signs[f == -np.inf] = 0.0
    expected = geom.log_apply(f)
    if geom.ndim == 1:  # one axis: the passes that re-read the input ran
        assert geom.last_log_repairs > 0
    expected_abs, expected_signs = geom.signed_log_apply(f, signs)

    x = f.copy()
    got = geom.log_apply_into(x, x)
    assert got is x
    np.testing.assert_array_equal(got, expected)
    x, s = f.copy(), signs.copy()
    got_abs, got_signs = geom.signed_log_apply(x, s, out=x, out_signs=s)
    assert got_abs is x and got_signs is s
    np.testing.assert_array_equal(got_abs, expected_abs)
    np.testing.assert_array_equal(got_signs, expected_signs)
    with pytest.raises(ValueError, match="out must be"):
        geom.log_apply_into(f, np.empty(f.shape, np.float32))


def test_default_capabilities_of_a_dense_geometry_agree_with_the_grid(rng):
    """The base class's defaults (signed product from two parts, one histogram at a
    time, into an array) give a grid's exact answers on the same kernel."""
    grid = GridGeometry.with_width((7, 6), 0.8)
    dense = DenseGeometry(grid.cost_matrix(), grid.gamma)
    assert not dense.log_per_histogram and dense.log_apply_rate is None
    assert dense.separable_factors() is None and not dense.is_grid
    with pytest.raises(TypeError, match="not a regular grid"):
        dense.with_grid((4,), 0.1)
    f = _steep_log_values(grid.shape, rng)
    signs = rng.choice([-1.0, 1.0], f.shape)
    signs[f == -np.inf] = 0.0
    flat, flat_signs = f.reshape(len(f), -1), signs.reshape(len(f), -1)
    got_abs, got_signs = dense.signed_log_apply(flat, flat_signs)
    ref_abs, ref_signs = grid.signed_log_apply(f, signs)
    live = np.isfinite(ref_abs.reshape(flat.shape))
    np.testing.assert_allclose(got_abs[live], ref_abs.reshape(flat.shape)[live], rtol=1e-10)
    np.testing.assert_array_equal(got_signs[live], ref_signs.reshape(flat.shape)[live])
    out = np.empty(dense.shape)
    assert dense.log_apply_one(flat[0], out) == 0
    np.testing.assert_allclose(out, grid.log_apply(f[0]).ravel(), rtol=1e-12)
    assert grid.with_grid((4, 5), 0.1).shape == (4, 5)
    kernels = grid.separable_factors()
    assert [k.shape for k, _ in kernels] == [(7, 7), (6, 6)]


@pytest.mark.parametrize("shape", [(200,), (14, 13, 12)])
def test_a_product_needed_on_a_subset_is_exact_there_and_repairs_less(shape, rng):
    geom = GridGeometry.with_width(shape, 0.3)
    all_repairs = some_repairs = 0
    for f in _steep_log_values(shape, rng):
        needed = rng.random(shape) < 0.2
        full, part = np.empty(shape), np.empty(shape)
        all_repairs += geom.log_apply_one(f, full)
        some_repairs += geom.log_apply_one(f, part, needed=needed)
        np.testing.assert_allclose(part[needed], full[needed], rtol=1e-14)  # to rounding
    assert all_repairs > 0 and some_repairs < all_repairs


@pytest.mark.parametrize("shape,dtype", [((24, 20, 16), np.float64), ((64, 48), np.float32),
                                         ((8, 7, 6, 5), np.float64)])
def test_grid_products_reuse_one_scratch_array_and_give_the_same_numbers(shape, dtype, rng):
    """``apply_into`` alternates between ``out`` and a scratch array the thread keeps: after
    the first product it allocates no intermediate (it made one per axis), and its numbers
    are those of the products with fresh intermediates, ``out`` overlapping the input too."""
    import tracemalloc

    geom = GridGeometry(shape, 0.05, dtype)
    block = rng.random((3, *shape)).astype(dtype)
    expected = np.empty_like(block)
    geom._apply_into_allocating(block, expected)
    out = np.empty_like(block)
    geom.apply_into(block, out)
    assert np.array_equal(out, expected)
    tracemalloc.start()
    try:
        geom.apply_into(block[:2], out[:2])  # a smaller block: the same scratch
        geom.apply_into(block, out)
        allocated = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert allocated < block.nbytes / 3  # no intermediate (one histogram's worth at most)
    assert np.array_equal(out, expected)
    same = block.copy()
    geom.apply_into(same, same)  # out is the input: fresh intermediates, the same numbers
    assert np.array_equal(same, expected)
