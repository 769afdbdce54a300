"""Tests of the BRDF domain: sampling, MERL I/O, analytic database, fit, render, CLI.

Small samplings (N = 32..48 directions, a spread subset of incoming rows) keep
the whole file fast. The known-weight recovery and the 10% robustness claim
use the default loss (the debiased Sinkhorn divergence); the paper's plain
entropic Wasserstein loss is checked for its gradient and shown to be biased.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from wbcgrade.brdf import analytic, io, merl, render, sampled, sampling
from wbcgrade.brdf.fit import DEFAULT_LOSS, brdf_histograms, fit_brdf
from wbcgrade.core import Loss, barycenter, barycenter_gradient, get_loss
from wbcgrade.core.losses import EntropicTransportLoss
from wbcgrade.core.masked import masked_loss
from wbcgrade.errors import InputError

N = 40
FIT_ROWS = 8
FAST = {"n_iter": 30, "max_iter": 30}


@pytest.fixture(scope="module")
def setup():
    directions = sampling.hemisphere_directions(N)
    geometry = sampling.hemisphere_geometry(N)
    materials = analytic.default_materials(5)
    database = np.stack([analytic.sample_material(m, directions) for m in materials])
    subset = sampling.spread_subset(directions, FIT_ROWS)
    return directions, geometry, database, subset


# -- sampling ---------------------------------------------------------------------------------


def test_hemisphere_directions_are_equal_area_unit_vectors():
    d = sampling.hemisphere_directions(288)
    assert d.shape == (288, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert (d[:, 2] > 0).all()
    # Equal area: z is uniform on (0, 1) (bands of equal height hold equal counts).
    counts, _ = np.histogram(d[:, 2], bins=8, range=(0, 1))
    assert counts.min() == counts.max() == 36
    assert len(np.unique(np.round(d, 12), axis=0)) == 288


def test_geodesic_cost_and_default_gamma():
    d = sampling.hemisphere_directions(64)
    cost = sampling.geodesic_cost(d)
    assert cost.shape == (64, 64)
    np.testing.assert_allclose(cost, cost.T)
    assert np.all(np.diag(cost) == 0) and cost.min() >= 0 and cost.max() <= np.pi**2
    i, j = 3, 40
    np.testing.assert_allclose(np.sqrt(cost[i, j]), np.arccos(np.clip(d[i] @ d[j], -1, 1)),
                               atol=1e-7)
    assert sampling.default_gamma(288) == pytest.approx(2 * (1.5 * np.sqrt(2 * np.pi / 288)) ** 2)
    geometry = sampling.hemisphere_geometry(64)
    assert geometry.shape == (64,) and geometry.gamma == pytest.approx(sampling.default_gamma(64))
    subset = sampling.spread_subset(d, 10)
    assert len(np.unique(subset)) == 10
    spread = sampling.geodesic_distance(d[subset], d[subset]) + 10 * np.eye(10)
    assert spread.min() > 0.5 * sampling.sample_spacing(10)


# -- analytic models ----------------------------------------------------------------------------


def test_analytic_materials_are_finite_reciprocal_and_deterministic():
    d = sampling.hemisphere_directions(40)
    for material in analytic.default_materials(14) + analytic.held_out_materials():
        values = analytic.sample_material(material, d)
        assert values.shape == (40, 40, 3)
        assert np.isfinite(values).all() and (values >= 0).all()
        np.testing.assert_allclose(values, values.transpose(1, 0, 2), rtol=1e-10)  # reciprocity
    assert [m.name for m in analytic.default_materials(14)] == \
        [m.name for m in analytic.default_materials(14)]
    lambert = analytic.material_by_name("white-lambert")
    np.testing.assert_allclose(analytic.sample_material(lambert, d), 0.8 / np.pi, rtol=0.06)
    with pytest.raises(InputError, match="material 'unobtainium' is unknown; known: "):
        analytic.material_by_name("unobtainium")


# -- MERL format --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory):
    material = analytic.material_by_name("copper-ggx-0.35")
    table = merl.tabulate_merl(material.evaluate)
    path = merl.write_merl(tmp_path_factory.mktemp("merl") / "copper.binary", table)
    return path, table, material


def test_merl_round_trip(merl_file):
    path, table, material = merl_file
    assert path.stat().st_size == merl.MERL_FILE_BYTES == 12 + 8 * 3 * 90 * 90 * 180
    header = np.fromfile(path, dtype="<i4", count=3)
    assert tuple(header) == (90, 90, 180)
    raw = np.fromfile(path, dtype="<f8", offset=12)
    np.testing.assert_allclose(raw[0] / 1500.0, table[0, 0, 0, 0], rtol=1e-14)  # red scale
    back = merl.read_merl(path)
    np.testing.assert_allclose(back, table, rtol=1e-14)
    # Resampling onto the hemisphere agrees with the analytic model up to the binning.
    d = sampling.hemisphere_directions(N)
    values = merl.resample_merl(back, d)
    exact = analytic.sample_material(material, d)
    relative = np.abs(values - exact) / (exact + 1e-2)
    assert np.median(relative) < 0.03


def test_half_diff_angles_invert():
    d = sampling.hemisphere_directions(24)
    wi = np.broadcast_to(d[:, None], (24, 24, 3))
    wo = np.broadcast_to(d[None], (24, 24, 3))
    angles = merl.half_diff_angles(wi, wo)
    back_in, back_out = merl.directions_from_half_diff(*angles)
    np.testing.assert_allclose(back_in, wi, atol=1e-6)
    np.testing.assert_allclose(back_out, wo, atol=1e-6)


def test_bad_merl_files_get_clear_errors(tmp_path, merl_file):
    path, _, _ = merl_file
    data = path.read_bytes()
    truncated = tmp_path / "truncated.binary"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="wrong size"):
        merl.read_merl(truncated)
    header = tmp_path / "header.binary"
    header.write_bytes(np.asarray([90, 90, 360], "<i4").tobytes() + data[12:])
    with pytest.raises(InputError, match="header"):
        merl.read_merl(header)
    tiny = tmp_path / "tiny.binary"
    tiny.write_bytes(b"abc")
    with pytest.raises(InputError, match="not a MERL"):
        merl.read_merl(tiny)
    raw = np.frombuffer(data, dtype=np.uint8).copy()
    raw[12 + 8 * 1000: 12 + 8 * 1001] = np.frombuffer(np.float64(np.nan).tobytes(), np.uint8)
    nan = tmp_path / "nan.binary"
    nan.write_bytes(raw.tobytes())
    with pytest.raises(InputError, match="NaN"):
        merl.read_merl(nan)
    with pytest.raises(InputError, match=r"shape \(3, 90, 90, 180\), got \(3, 90, 90, 90\)"):
        merl.write_merl(tmp_path / "bad.binary", np.zeros((3, 90, 90, 90)))


def test_sampled_files_and_mismatched_samplings(tmp_path, setup):
    directions, _, database, _ = setup
    path = io.write_sampled(tmp_path / "a.npz", database[0], directions, name="a")
    np.testing.assert_array_equal(io.load_brdf(path, directions), database[0])
    other = sampling.hemisphere_directions(32)
    io.write_sampled(tmp_path / "b.npz", analytic.sample_material(
        analytic.default_materials(1)[0], other), other)
    with pytest.raises(InputError, match="mismatched samplings"):
        io.load_database(tmp_path, directions)
    with pytest.raises(InputError, match="unknown BRDF format"):
        io.load_brdf(tmp_path / "x.txt", directions)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no BRDF files"):
        io.database_files(tmp_path / "empty")
    bad = tmp_path / "c.npz"
    values = database[0].copy()
    values[0, 0, 0] = np.nan
    np.savez(bad, values=values, directions=directions, format=io.SAMPLED_FORMAT)
    with pytest.raises(InputError, match="NaN"):
        io.read_sampled(bad)


def test_interpolation_is_exact_on_samples_and_constants(setup):
    directions, _, database, _ = setup
    values = sampled.interpolate(database[1], directions, directions[[3, 7]], directions[[5, 9]])
    np.testing.assert_allclose(values, database[1][[3, 7], [5, 9]], rtol=0.05)
    constant = np.full((N, N, 3), 0.25)
    rng = np.random.default_rng(0)
    queries = rng.normal(size=(2, 100, 3))
    queries /= np.linalg.norm(queries, axis=-1, keepdims=True)
    np.testing.assert_allclose(sampled.interpolate(constant, directions, *queries), 0.25)


# -- the fit ------------------------------------------------------------------------------------


def _finite_difference_check(histograms, target, geometry, loss, n_iter=30):
    """Compare directional derivatives of E(w) with the reverse-mode gradient."""
    weights = np.array([0.3, 0.1, 0.25, 0.15, 0.2])
    value, grad, _ = barycenter_gradient(histograms, weights, geometry, target, loss=loss,
                                         n_iter=n_iter)
    for i, j in [(0, 1), (2, 4), (3, 0)]:
        step = np.zeros(5)
        step[i], step[j] = 1e-5, -1e-5
        plus = barycenter_gradient(histograms, weights + step, geometry, target, loss=loss,
                                   n_iter=n_iter)[0]
        minus = barycenter_gradient(histograms, weights - step, geometry, target, loss=loss,
                                    n_iter=n_iter)[0]
        numeric = (plus - minus) / 2e-5
        assert numeric == pytest.approx(grad[i] - grad[j], rel=1e-4, abs=1e-7 * abs(value))


@pytest.mark.parametrize("loss", [DEFAULT_LOSS, "wasserstein", "quadratic"])
def test_gradient_check_on_hemisphere(setup, loss):
    """Reverse-mode gradient vs finite differences; losses looked up by name use
    their default inner Sinkhorn tolerance (each evaluation a fresh, cold loss)."""
    directions, geometry, database, subset = setup
    histograms, _ = brdf_histograms(database[:, subset[:6]])
    target, _ = brdf_histograms(analytic.sample_material(
        analytic.held_out_materials()[0], directions)[subset[:6]])
    _finite_difference_check(histograms, target, geometry, loss)


@pytest.mark.parametrize("loss", [DEFAULT_LOSS, "quadratic"])
def test_masked_loss_gradient(setup, loss):
    directions, geometry, database, subset = setup
    histograms, _ = brdf_histograms(database[:, subset[:4]])
    target, _ = brdf_histograms(analytic.sample_material(
        analytic.held_out_materials()[1], directions)[subset[:4]])
    mask = np.broadcast_to(sampled.decimation_mask(N, N, 0.3, seed=3)[subset[:4]][:, None, :],
                           target.shape)
    kept = np.where(mask, target, 0.0)
    kept /= kept.sum(axis=-1, keepdims=True)
    _finite_difference_check(histograms, kept, geometry, masked_loss(loss, mask))


@pytest.mark.parametrize("keep", [0.2, 0.8])  # per-row kernels / the full kernel with zeros
def test_masked_loss_is_the_loss_on_the_kept_entries(setup, keep):
    """The masked loss equals the transport problem on the full sampling."""
    directions, geometry, database, subset = setup
    histograms, _ = brdf_histograms(database[:, subset[:5]])
    P = barycenter(histograms, [0.1, 0.4, 0.2, 0.2, 0.1], geometry, n_iter=30)
    target, _ = brdf_histograms(database[3, subset[:5]])
    mask = np.broadcast_to(sampled.decimation_mask(N, N, keep, seed=1)[subset[:5]][:, None, :],
                           target.shape)
    kept = np.where(mask, target, 0.0)
    kept /= kept.sum(axis=-1, keepdims=True)
    P_kept = np.where(mask, P, 0.0)
    P_kept /= P_kept.sum(axis=-1, keepdims=True)
    for name in ("sinkhorn_divergence", "wasserstein"):
        full_loss = Loss(name, EntropicTransportLoss(name != "wasserstein", tol=1e-12))
        value, grad = full_loss.value_and_grad(P_kept, kept, geometry)
        compact_value, compact_grad = masked_loss(full_loss, mask).value_and_grad(P, kept,
                                                                                  geometry)
        assert compact_value == pytest.approx(value, rel=1e-9)
        # The masked gradient is the full one pushed through the restriction.
        mass = np.where(mask, P, 0.0).sum(axis=-1, keepdims=True)
        expected = np.where(mask, (grad - (grad * P_kept).sum(-1, keepdims=True)) / mass, 0.0)
        np.testing.assert_allclose(compact_grad, expected, atol=1e-8 * np.abs(expected).max())


def test_sinkhorn_divergence_is_zero_at_the_target_and_debiased(setup):
    directions, geometry, database, subset = setup
    q, _ = brdf_histograms(database[2, subset[:6]])
    loss = get_loss(DEFAULT_LOSS)
    value, grad = loss.value_and_grad(q, q, geometry)
    histograms, _ = brdf_histograms(database[:, subset[:6]])
    for weights in ([0.2, 0.2, 0.2, 0.2, 0.2], [0.7, 0.0, 0.1, 0.1, 0.1]):
        P = barycenter(histograms, weights, geometry, n_iter=30)
        away, grad_away = loss.value_and_grad(P, q, geometry)
        assert away > 0.01
        # Zero and stationary at P = q (up to the inner Sinkhorn tolerance).
        assert abs(value) < 1e-9 * away and np.abs(grad).max() < 1e-4 * np.abs(grad_away).max()
    # The plain entropic loss is not smallest at P = q: a blurred q beats q itself.
    wasserstein = get_loss("wasserstein")
    at_target = wasserstein.value_and_grad(q, q, geometry)[0]
    blurred = 0.7 * q + 0.3 * geometry.apply(q)
    blurred /= blurred.sum(axis=-1, keepdims=True)
    assert wasserstein.value_and_grad(blurred, q, geometry)[0] < at_target - 0.1
    assert loss.value_and_grad(blurred, q, geometry)[0] > 0.01


def test_losses_keep_warm_starts_within_one_fit_only(setup):
    directions, geometry, database, subset = setup
    histograms, _ = brdf_histograms(database[:, subset[:6]])
    q, _ = brdf_histograms(database[4, subset[:6]])
    P1 = barycenter(histograms, [0.2, 0.2, 0.2, 0.2, 0.2], geometry, n_iter=30)
    P2 = barycenter(histograms, [0.22, 0.18, 0.2, 0.2, 0.2], geometry, n_iter=30)
    warm = get_loss(DEFAULT_LOSS)
    assert get_loss(DEFAULT_LOSS).value_and_grad is not warm.value_and_grad  # one per look-up
    warm.value_and_grad(P1, q, geometry)
    before = warm.value_and_grad.inner_iterations
    warm_value, warm_grad = warm.value_and_grad(P2, q, geometry)
    cold = get_loss(DEFAULT_LOSS)
    cold_value, cold_grad = cold.value_and_grad(P2, q, geometry)
    assert warm.value_and_grad.inner_iterations - before < cold.value_and_grad.inner_iterations
    assert warm_value == pytest.approx(cold_value, rel=1e-8)
    np.testing.assert_allclose(warm_grad, cold_grad, atol=1e-4 * np.abs(cold_grad).max())


@pytest.mark.slow
def test_known_weights_are_recovered(setup):
    """The default loss recovers the weights of a target that is a barycenter of the
    database, from all measurements and from 10% of them."""
    directions, geometry, database, subset = setup
    histograms, sums = brdf_histograms(database)
    truth = np.array([0.5, 0.0, 0.3, 0.0, 0.2])
    P = barycenter(histograms, truth, geometry, n_iter=FAST["n_iter"])
    target = np.moveaxis(P * np.tensordot(truth, sums, axes=1)[..., None], -1, -2)
    result = fit_brdf(target, database, geometry, fit_incoming=subset, **FAST)
    np.testing.assert_allclose(result.weights, truth, atol=0.03)
    assert sampled.psnr(target, result.values) > 45
    mask = sampled.decimation_mask(N, N, 0.1, seed=0)
    sparse = fit_brdf(target, database, geometry, mask=mask, fit_incoming=subset, **FAST)
    np.testing.assert_allclose(sparse.weights, truth, atol=0.03)
    assert sparse.kept_fraction == pytest.approx(0.1, abs=1e-3)


@pytest.mark.slow
def test_decimated_fit_psnr_within_2db_of_full_fit(setup):
    """The paper's robustness claim with the default loss, on a material outside the database."""
    directions, geometry, database, subset = setup
    reference = analytic.sample_material(analytic.material_by_name("bronze-ggx-0.25"), directions)
    full = fit_brdf(reference, database, geometry, fit_incoming=subset, **FAST)
    mask = sampled.decimation_mask(N, N, 0.1, seed=0)
    sparse = fit_brdf(reference, database, geometry, mask=mask, fit_incoming=subset, **FAST)
    psnr_full = sampled.psnr(reference, full.values)
    psnr_sparse = sampled.psnr(reference, sparse.values)
    assert psnr_full > 20
    assert psnr_sparse > psnr_full - 2.0


def test_fit_keeps_the_measured_row_sums(setup):
    directions, geometry, database, subset = setup
    reference = analytic.sample_material(analytic.held_out_materials()[0], directions)
    result = fit_brdf(reference, database, geometry, fit_incoming=subset[:6], n_iter=30,
                      max_iter=5)
    assert result.values.shape == (N, N, 3)
    assert np.isclose(result.weights.sum(), 1.0)
    # Rescaling keeps the measurement's row sums.
    np.testing.assert_allclose(result.values.sum(axis=1), reference.sum(axis=1), rtol=1e-8)


def test_fit_rejects_bad_input(setup):
    directions, geometry, database, _ = setup
    with pytest.raises(InputError, match="shape"):
        fit_brdf(database[0, :10], database, geometry)
    bad = database[0].copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        fit_brdf(bad, database, geometry)
    with pytest.raises(InputError, match="fraction"):
        sampled.decimation_mask(N, N, 1.5)


# -- picture and command line ------------------------------------------------------------------


def test_render_sphere(setup, tmp_path):
    directions, _, database, _ = setup
    image = render.render_sphere(database[0], directions, size=48)
    assert image.shape == (48, 48, 3) and image.max() > 0 and image[0, 0].sum() == 0
    picture = render.comparison_image([image, image], [["reference"], ["fit", "PSNR 30 dB"]])
    path = render.write_png(tmp_path / "sphere.png", picture)
    import OpenImageIO as oiio

    back = oiio.ImageBuf(str(path))
    assert back.spec().width == 96 and back.spec().nchannels == 3


@pytest.mark.slow
def test_cli_synth_and_fit(tmp_path, cli):
    database = tmp_path / "db"
    result = cli("brdf", "synth", "-o", str(database), "--material",
                 "white-lambert", "--material", "brushed-steel-ward",
                 "--directions", "32")
    assert result.exit_code == 0, result.output
    assert [p.name for p in io.database_files(database)] == [
        "brushed-steel-ward.npz", "white-lambert.binary"]
    result = cli("brdf", "synth", "-o", str(tmp_path / "ref"), "--material",
                 "brushed-gold-ward", "--directions", "32")
    assert result.exit_code == 0, result.output
    measured = tmp_path / "ref" / "brushed-gold-ward.npz"
    out = tmp_path / "fit.binary"
    result = cli("brdf", "fit", str(measured), "--database", str(database),
        "--keep", "0.3", "--keep", "0.15",
        "--directions", "32", "--fit-directions", "6", "--loss", "quadratic",
        "--max-iter", "4", "--iterations", "20", "-o", str(out), "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.output[result.output.index("{"):])
    assert [f["label"] for f in report["fits"]] == ["full", "keep 30%", "keep 15%"]
    for entry in report["fits"]:
        assert sum(entry["weights"].values()) == pytest.approx(1.0)
        assert np.isfinite(entry["psnr_db"])
    assert out.exists() and out.with_suffix(".png").exists()
    import OpenImageIO as oiio

    assert oiio.ImageBuf(str(out.with_suffix(".png"))).spec().width == 4 * 192
    assert io.load_brdf(out, sampling.hemisphere_directions(32)).shape == (32, 32, 3)


def test_cli_prints_weights_and_psnr(tmp_path, cli):
    directions = sampling.hemisphere_directions(24)
    database = tmp_path / "db"
    database.mkdir()
    for material in analytic.default_materials(3):
        io.write_sampled(database / f"{material.name}.npz",
                         analytic.sample_material(material, directions), directions)
    measured = io.write_sampled(tmp_path / "bronze.npz", analytic.sample_material(
        analytic.material_by_name("bronze-ggx-0.25"), directions), directions)
    out = tmp_path / "fit.npz"
    result = cli("brdf", "fit", str(measured), "--database", str(database), "--keep", "0.5",
        "--directions", "24", "--fit-directions", "4", "--max-iter", "3", "--n-iter", "15",
        "-o", str(out), "--no-png")
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[lines.index(next(x for x in lines if x.startswith("material"))) + 1][0] == "-"
    assert any(x.startswith("PSNR vs measurement") and x.count("dB") == 2 for x in lines)
    weights = [float(x.split()[1]) for x in lines if x.split()[0] in
               {m.name for m in analytic.default_materials(3)}]
    assert len(weights) == 3 and sum(weights) == pytest.approx(1.0, abs=2e-3)
    assert weights == sorted(weights, reverse=True)
    assert lines[-1] == f"wrote {out}" and out.exists()


def _corrupt_inputs(tmp_path):
    """(measurement, database folder, expected message) for each kind of bad input."""
    directions = sampling.hemisphere_directions(8)
    good_db = tmp_path / "db"
    good_db.mkdir()
    io.write_sampled(good_db / "a.npz", np.ones((8, 8, 3)), directions)
    io.write_sampled(good_db / "b.npz", np.full((8, 8, 3), 2.0), directions)
    good = io.write_sampled(tmp_path / "good.npz", np.full((8, 8, 3), 1.5), directions)
    merl_like = np.asarray(merl.MERL_SHAPE, "<i4").tobytes() + b"\x00" * 800
    (tmp_path / "short.binary").write_bytes(merl_like)
    (tmp_path / "header.binary").write_bytes(
        np.asarray([90, 90, 90], "<i4").tobytes() + b"\x00" * (merl.MERL_FILE_BYTES - 12))
    values = np.ones((8, 8, 3))
    values[2, 3, 1] = np.nan
    np.savez(tmp_path / "nan.npz", values=values, directions=directions,
             format=io.SAMPLED_FORMAT)
    mixed_db = tmp_path / "mixed"
    mixed_db.mkdir()
    io.write_sampled(mixed_db / "a.npz", np.ones((8, 8, 3)), directions)
    io.write_sampled(mixed_db / "c.npz", np.ones((9, 9, 3)), sampling.hemisphere_directions(9))
    return [
        (tmp_path / "short.binary", good_db, "wrong size"),
        (tmp_path / "header.binary", good_db, "header"),
        (tmp_path / "nan.npz", good_db, "NaN"),
        (good, mixed_db, "mismatched samplings"),
    ]


def test_cli_errors_are_one_line(tmp_path, cli):
    """Bad files (size, header, NaN, mismatched samplings): one line, exit 1, no traceback."""
    for measured, database, message in _corrupt_inputs(tmp_path):
        result = cli("brdf", "fit", str(measured), "--database", str(database),
                     "--directions", "8", "--no-png",
                     "-o", str(tmp_path / "out.npz"))
        text = result.output.strip()
        assert result.exit_code == 1, (measured, text)
        assert text.startswith("Error:") and "\n" not in text, text
        assert message in text and "Traceback" not in text
        assert not isinstance(result.exception, AssertionError)
