"""Batch grading, series grades, scale-out and the palette weight report (tiny images)."""

from __future__ import annotations

import csv
import json
import re
import shutil
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.conftest import run_cli
from wbcgrade.batch import BatchContext, plan_batch, run_batch
from wbcgrade.color.options import FitOptions, GradeOptions
from wbcgrade.color.palette.fit import fit_weights
from wbcgrade.color.presets import load_preset, load_style_folder

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
FAST = ["--mode", "palette", "--bins", "8", "--fit-bins", "6", "--max-iter", "3",
        "--iterations", "10", "--no-cache"]
GOOD = ["chelsea.jpg", "astronaut.png", "sub/bridge.jpg"]


def small_copy(src: Path, dst: Path, width: int = 64) -> Path:
    buf = oiio.ImageBuf(str(src))
    spec = buf.spec()
    height = max(1, round(spec.height * width / spec.width))
    small = oiio.ImageBufAlgo.resample(buf, roi=oiio.ROI(0, width, 0, height, 0, 1, 0, 3))
    dst.parent.mkdir(parents=True, exist_ok=True)
    assert small.write(str(dst)), small.geterror()
    return dst


@pytest.fixture(scope="module")
def folders(tmp_path_factory) -> tuple[Path, Path]:
    """(photos, styles): three good photos (one in a sub-folder, one PNG), a truncated
    JPEG and a text file; three style photos."""
    root = tmp_path_factory.mktemp("batch")
    photos, styles = root / "photos", root / "styles"
    for name in ("aitzgorri", "coffee", "flower"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.jpg", 48)
    small_copy(SAMPLES / "chelsea.jpg", photos / "chelsea.jpg")
    small_copy(SAMPLES / "astronaut.jpg", photos / "astronaut.png")
    small_copy(SAMPLES / "bridge.jpg", photos / "sub" / "bridge.jpg")
    (photos / "broken.jpg").write_bytes((photos / "chelsea.jpg").read_bytes()[:300])
    (photos / "notes.txt").write_text("not a photo")
    return photos, styles


def _batch(photos: Path, styles: Path, out: Path, *extra: str):
    return run_cli("batch", str(photos), "-o", str(out), "--style", str(styles),
                   "-r", *FAST, *extra)


def _pixels(path: Path) -> np.ndarray:
    buf = oiio.ImageBuf(str(path))
    assert not buf.has_error, buf.geterror()
    return buf.get_pixels(oiio.FLOAT)


@pytest.fixture(scope="module")
def local_run(folders, tmp_path_factory) -> Path:
    """One per-photo batch run in this process; its output folder."""
    photos, styles = folders
    out = tmp_path_factory.mktemp("local") / "out"
    result = _batch(photos, styles, out)
    assert result.exit_code == 1, result.output
    return out


@pytest.mark.slow
def test_batch_grades_good_files_and_reports_bad_ones(folders, local_run):
    photos, styles = folders
    for name in GOOD:
        graded, source = local_run / name, photos / name
        assert graded.is_file()
        spec_in, spec_out = oiio.ImageInput.open(str(source)), oiio.ImageInput.open(str(graded))
        assert spec_out.format_name() == spec_in.format_name()
        assert spec_out.spec().format == spec_in.spec().format
        assert (spec_out.spec().width, spec_out.spec().height) == (spec_in.spec().width,
                                                                   spec_in.spec().height)
        spec_in.close()
        spec_out.close()
        assert not np.array_equal(_pixels(graded), _pixels(source))
    assert not (local_run / "broken.jpg").exists()
    assert not (local_run / "notes.txt").exists()
    hidden = [p.name for p in local_run.rglob(".*")]
    # the run's settings, its per-photo results and the folder's lock file; no temporary
    # file left
    assert sorted(hidden) == [".wbcgrade-batch.json", ".wbcgrade-results", ".wbcgrade.lock"]

    # A rerun reports the bad file again and skips the finished ones.
    out = local_run.parent / "rerun"
    shutil.copytree(local_run, out)
    before = {name: (out / name).stat().st_mtime_ns for name in GOOD}
    result = _batch(photos, styles, out)
    assert result.exit_code == 1
    assert "graded 0, skipped 3, failed 1" in result.output
    assert "broken.jpg" in result.output and "notes.txt" in result.output
    assert before == {name: (out / name).stat().st_mtime_ns for name in GOOD}
    assert "other settings" not in result.output
    result = _batch(photos, styles, out, "--strength", "0.5")
    assert "graded 0, skipped 3" in result.output and "other settings (strength)" in result.output
    # A file this run did not write (of another size: not a finished output) is not
    # replaced: that photo fails, the file is kept (tests/io/test_output_plan.py).
    small_copy(SAMPLES / "coffee.jpg", out / "chelsea.jpg", 20)
    foreign = (out / "chelsea.jpg").read_bytes()
    result = _batch(photos, styles, out)
    assert "graded 0, skipped 2, failed 2" in result.output
    assert "chelsea.jpg: file exists (use --overwrite" in result.output
    assert (out / "chelsea.jpg").read_bytes() == foreign
    # The library says overwrite= as the command says --overwrite; force= still works, warned.
    plan = plan_batch(photos, out, recursive=True)
    assert len(plan.done) == 2 and [t.relative for t, _ in plan.refused] == ["chelsea.jpg"]
    assert not plan_batch(photos, out, recursive=True, overwrite=True).done
    with pytest.warns(DeprecationWarning, match="overwrite="):
        assert not plan_batch(photos, out, recursive=True, force=True).done


@pytest.mark.slow
def test_good_folder_exits_zero(folders, tmp_path):
    photos, styles = folders
    clean = tmp_path / "clean"
    clean.mkdir()
    shutil.copy(photos / "chelsea.jpg", clean / "chelsea.jpg")
    result = _batch(clean, styles, tmp_path / "out", "--weights", "1,1,1")
    assert result.exit_code == 0, result.output
    assert "graded 1, skipped 0, failed 0" in result.output
    result = _batch(clean, styles, clean)
    assert result.exit_code == 1 and "must differ" in result.output


def _write_png(path: Path, pixels: np.ndarray) -> None:
    buf = oiio.ImageBuf(np.ascontiguousarray(pixels, dtype=np.float32))
    buf.set_write_format(oiio.UINT8)
    assert buf.write(str(path)), buf.geterror()


@pytest.mark.slow
def test_consistent_gives_every_photo_the_same_grade(folders, tmp_path):
    photos, styles = folders
    # b.png holds a.png's pixels on its left half: one colour map for the series grades
    # them identically; a per-photo grade would not (b's palette differs). (Without
    # the regrain step, which looks at each pixel's neighbours.)
    series = tmp_path / "series"
    series.mkdir()
    right = _pixels(photos / "sub" / "bridge.jpg")
    left = _pixels(photos / "chelsea.jpg")[: right.shape[0]]
    _write_png(series / "a.png", left)
    _write_png(series / "b.png", np.concatenate([left, right], axis=1))
    shutil.copy(photos / "astronaut.png", series / "c.png")
    report = tmp_path / "report"
    lut = tmp_path / "series.cube"
    result = _batch(series, styles, tmp_path / "out", "--consistent", "--report", str(report),
                    "--lut", str(lut), "--lut-size", "9", "--no-regrain")
    assert result.exit_code == 0, result.output
    from wbcgrade.color.mapping.lut import read_cube

    assert read_cube(lut).size == 9
    entries = json.loads((report / "report.json").read_text())["photos"]
    assert [e["status"] for e in entries] == ["graded"] * 3
    weights = [{w["style"]: w["weight"] for w in e["weights"]} for e in entries]
    assert all(w == weights[0] for w in weights)
    graded_a = _pixels(tmp_path / "out" / "a.png")
    graded_b = _pixels(tmp_path / "out" / "b.png")
    np.testing.assert_array_equal(graded_b[:, : left.shape[1]], graded_a)
    assert not np.array_equal(graded_a, left)


@pytest.mark.slow
def test_the_series_lut_is_baked_for_the_photos_input_space(folders, tmp_path):
    """``--consistent --lut`` with ``--input-space``: the LUT takes the photos' own code
    values (it was baked for sRGB whatever the input space was), so applying it to a
    photo gives the batch's graded photo."""
    from wbcgrade.color.mapping.lut import read_cube
    from wbcgrade.color.mapping.remap import apply_color_map

    photos, styles = folders
    series = tmp_path / "series"
    series.mkdir()
    _write_png(series / "cat.png", _pixels(photos / "chelsea.jpg"))  # lossless outputs
    shutil.copy(photos / "astronaut.png", series / "astronaut.png")
    lut = tmp_path / "series.cube"
    result = _batch(series, styles, tmp_path / "out", "--consistent", "--lut", str(lut),
                    "--lut-size", "33", "--no-regrain", "--input-space", "display-p3")
    assert result.exit_code == 0, result.output
    header = [line for line in lut.read_text().splitlines() if line.startswith("#")]
    assert any("input space: sRGB Encoded P3-D65" in line for line in header), header
    table = read_cube(lut).table
    for name in ("cat.png", "astronaut.png"):
        source, graded = _pixels(series / name), _pixels(tmp_path / "out" / name)
        error = np.abs(apply_color_map(source, table) - graded) * 255
        assert np.abs(graded - source).mean() * 255 > 2  # it did grade
        assert error.max() <= 3 and error.mean() < 0.6, (name, error.max(), error.mean())


@pytest.mark.slow
def test_dask_and_process_pool_match_a_local_run(folders, local_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    photos, styles = folders
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        result = _batch(photos, styles, tmp_path / "dask", "--scheduler",
                        cluster.scheduler_address)
    assert result.exit_code == 1, result.output
    assert "graded 3, skipped 0, failed 1" in result.output
    for name in GOOD:
        np.testing.assert_array_equal(_pixels(tmp_path / "dask" / name),
                                      _pixels(local_run / name))
    # Two local processes, library level (two photos keep it short).
    style_set = load_style_folder(styles, 8)
    plan = plan_batch(photos, tmp_path / "pool")
    context = BatchContext(style_set, GradeOptions(mode="palette", bins=8, fit_bins=6,
                                                   max_iter=3, n_iter=10))
    outcome = run_batch(plan, context, jobs=2)
    assert outcome.count("graded") == 2 and outcome.count("failed") == 1
    for name in ("chelsea.jpg", "astronaut.png"):
        np.testing.assert_array_equal(_pixels(tmp_path / "pool" / name),
                                      _pixels(local_run / name))


@pytest.mark.slow
def test_scheduler_errors_are_one_line(folders, tmp_path, monkeypatch):
    import sys

    import wbcgrade._executor as executor

    photos, styles = folders
    pytest.importorskip("distributed")
    monkeypatch.setattr(executor, "DASK_CONNECT_TIMEOUT", "1s")
    result = _batch(photos, styles, tmp_path / "out", "--scheduler", "tcp://127.0.0.1:9")
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1].startswith("Error: cannot reach")
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # as if not installed
    result = _batch(photos, styles, tmp_path / "out", "--scheduler", "tcp://127.0.0.1:9")
    assert result.exit_code == 2  # a setting whose extra is missing: a bad option
    assert result.output.strip().splitlines()[-1] == (
        "Error: --scheduler needs Dask: pip install 'wbcgrade[dask]' (dask[distributed])")


@pytest.mark.slow
def test_report_files_are_valid(folders, tmp_path, cli):
    photos, styles = folders
    out = tmp_path / "report"
    result = cli("report", str(photos), "-o", str(out), "--style",
                 str(styles), "-r", *FAST)
    assert result.exit_code == 1, result.output  # the broken photo
    document = json.loads((out / "report.json").read_text())
    entries = document["photos"]
    assert sorted(e["photo"] for e in entries) == sorted(GOOD + ["broken.jpg"])
    for entry in entries:
        if entry["status"] != "graded":
            assert "error" in entry
            continue
        weights = [w["weight"] for w in entry["weights"]]
        assert weights == sorted(weights, reverse=True)
        assert abs(sum(weights) - 1) < 1e-4
        assert entry["loss"] <= entry["best_single_style"]["loss"] * (1 + 1e-9)
        assert entry["nonzero_weights"] == sum(w >= document["nonzero_threshold"]
                                               for w in weights)
        sheet = oiio.ImageInput.open(str(out / entry["sheet"]))
        assert sheet is not None and sheet.spec().width == 960
        sheet.close()
    with open(out / "weights.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["photo"] for r in rows] == [e["photo"] for e in entries]
    assert set(document["style_names"]) <= set(rows[0])
    page = (out / "index.html").read_text()
    links = re.findall(r'(?:src|href)="([^"#][^"]*)"', page)
    assert len(links) == 3
    assert all((out / link).is_file() for link in links)
    assert not list(photos.rglob("*_graded*"))  # report writes no graded photos


@pytest.mark.slow
def test_report_one_photo_with_preset(folders, tmp_path, cli):
    photos, _ = folders
    out = tmp_path / "one"
    result = cli("report", str(photos / "chelsea.jpg"), "-o", str(out),
                 "--preset", "warm", *FAST)
    assert result.exit_code == 0, result.output
    rows = list(csv.reader(open(out / "weights.csv", newline="")))
    assert len(rows) == 2 and rows[1][0] == "chelsea.jpg"


def test_fit_is_never_worse_than_the_best_single_style():
    rng = np.random.default_rng(0)
    styles = rng.random((3, 6, 6, 6)) ** 8
    styles /= styles.sum(axis=(1, 2, 3), keepdims=True)
    photo = styles[1] * 0.97 + styles[0] * 0.03
    fit = fit_weights(photo, styles, FitOptions(bins=6, max_iter=1, n_iter=10))
    assert fit.loss <= fit.vertex_losses.min() * (1 + 1e-12)
    assert fit.weights.argmax() == 1


@pytest.mark.slow
def test_interrupt_leaves_no_partial_file(folders, tmp_path, monkeypatch):
    import contextlib

    import wbcgrade.photos.workflow as workflow

    photos, styles = folders
    out = tmp_path / "out"
    plan = plan_batch(photos, out, recursive=True)
    real_stage = workflow.stage_image
    calls = []

    @contextlib.contextmanager
    def write_then_interrupt(path, *args, **kwargs):
        calls.append(path)
        if len(calls) == 2:  # as if killed while writing: a temporary file is left
            (Path(path).parent / f".{Path(path).stem}.x1y2z3{Path(path).suffix}").write_text("")
            raise KeyboardInterrupt
        with real_stage(path, *args, **kwargs) as written:
            yield written

    monkeypatch.setattr(workflow, "stage_image", write_then_interrupt)
    context = BatchContext(load_style_folder(styles, 8),
                           GradeOptions(mode="palette", bins=8, fit_bins=6, max_iter=3, n_iter=10))
    with pytest.raises(KeyboardInterrupt, match="^$"):  # the one write_then_interrupt raised
        run_batch(plan, context)
    written = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert written == [Path(calls[0]).relative_to(out).as_posix()]
    _pixels(calls[0])  # complete and readable


@pytest.mark.slow
def test_report_hook_for_apply(folders, tmp_path):
    from wbcgrade.photos.report import report_from_grade
    from wbcgrade.photos.workflow import grade_file, plan_photo

    photos, styles = folders
    opts = GradeOptions(mode="palette", bins=8, fit_bins=6, max_iter=3, n_iter=10)
    style_set = load_style_folder(styles, 8)
    graded = grade_file(plan_photo(photos / "chelsea.jpg", tmp_path / "c.jpg"), style_set, opts)
    path = report_from_grade(tmp_path / "report", graded, style_set, opts)
    entry = json.loads(path.read_text())["photos"][0]
    assert entry["photo"] == "chelsea.jpg" and len(entry["weights"]) == 3
    assert (tmp_path / "report" / entry["sheet"]).is_file()
    # The report says what the fit did (it once called every fit "uniform") and reuses
    # its single-style losses instead of evaluating them again.
    assert entry["fit_start"] == graded.fit.start == graded.as_dict()["fit_start"]
    assert list(entry["single_style_losses"].values()) == pytest.approx(
        list(graded.fit.vertex_losses))
    assert entry["loss"] == pytest.approx(graded.fit.loss)


@pytest.mark.slow
@pytest.mark.parametrize("start", ["vertex-refit", "vertex", "given"])
def test_the_apply_report_labels_every_kind_of_fit(folders, tmp_path, monkeypatch, start):
    """Vertex refits and given weights were labelled "uniform", and every vertex loss was
    evaluated a second time for the report."""
    from dataclasses import replace

    import wbcgrade.color.grade.builders as builders
    import wbcgrade.color.palette.fit as fit_module
    from wbcgrade.photos.report import report_from_grade
    from wbcgrade.photos.workflow import grade_file, plan_photo

    photos, styles = folders
    opts = GradeOptions(mode="palette", bins=8, fit_bins=6, max_iter=3, n_iter=10,
                        weights=[1.0, 1.0, 0.0] if start == "given" else None)
    style_set = load_style_folder(styles, 8)
    fit = builders.fit_weights

    def labelled(*args, **kwargs):
        summary = fit(*args, **kwargs)
        if start != "given":
            summary = replace(summary, start=start, info={**summary.info, "start": start})
        return summary

    monkeypatch.setattr(builders, "fit_weights", labelled)
    graded = grade_file(plan_photo(photos / "chelsea.jpg", tmp_path / "c.jpg"), style_set, opts)
    calls = []
    monkeypatch.setattr(fit_module, "vertex_losses", lambda *a: calls.append(a))
    path = report_from_grade(tmp_path / "report", graded, style_set, opts)
    entry = json.loads(path.read_text())["photos"][0]
    assert entry["fit_start"] == start and calls == []
    assert graded.as_dict()["fitted"] is (start != "given")


def test_palette_and_sheet_without_fonts(tmp_path, monkeypatch):
    import wbcgrade.photos.sheet as sheet
    from wbcgrade.color.histogram import soft_histogram

    colours = np.array([[0.9, 0.1, 0.1]] * 3 + [[0.1, 0.2, 0.8]])
    palette = sheet.histogram_palette(soft_histogram(colours, 16), k=4)
    assert palette.shares[:2] == pytest.approx([0.75, 0.25], abs=0.02)
    np.testing.assert_allclose(palette.colors[0], [0.9, 0.1, 0.1], atol=0.04)
    picture = np.full((12, 16, 3), 0.5, dtype=np.float32)
    content = sheet.SheetContent("title", "loss 0.1", picture, picture,
                                 [sheet.StyleTile("a", 1.0, picture)], [("input", palette)])
    labelled = sheet.compose_sheet(content, width=400)  # OpenImageIO's own fonts
    assert np.any(np.all(np.abs(labelled - 0.12) < 0.02, axis=2))  # ink
    monkeypatch.setattr(sheet, "USE_FONTS", False)  # as without fonts: a sheet, no labels
    pixels = sheet.compose_sheet(content, width=400)
    assert pixels.shape == labelled.shape and pixels.shape[1] == 400
    assert not np.any(np.all(np.abs(pixels - 0.12) < 0.02, axis=2))
    # the pictures are there (a sheet is composed in 8 bits, as it is written: 0.5 is 128)
    assert np.any(np.all(np.abs(pixels - 128 / 255) < 1e-6, axis=2))


@pytest.mark.slow
def test_apply_report_option_writes_a_report(folders, tmp_path, cli):
    photos, styles = folders
    result = cli(
        "apply", str(photos / "chelsea.jpg"), "--style", str(styles), "-o", str(tmp_path / "c.jpg"),
        "--mode", "palette", "--bins", "8", "--fit-bins", "6", "--max-iter", "3",
        "--iterations", "10", "--no-cache", "--report", str(tmp_path / "report"))
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert [p["photo"] for p in report["photos"]] == ["chelsea.jpg"]
    assert (tmp_path / "report" / "index.html").is_file()


#: The batch folder's own photos (six or more: the look's content model).
OWN_NAMES = ["aitzgorri", "astronaut", "bridge", "chelsea", "coffee", "flower", "seeding"]


@pytest.fixture(scope="module")
def own_photos(tmp_path_factory) -> tuple[Path, Path]:
    """(a folder of seven photos, a broken one and a stem twice; a folder of six warm style
    photos)."""
    root = tmp_path_factory.mktemp("own")
    photos = root / "mine"
    for name in OWN_NAMES:
        small_copy(SAMPLES / f"{name}.jpg", photos / f"{name}.jpg", 40)
    (photos / "broken.jpg").write_bytes((photos / "chelsea.jpg").read_bytes()[:300])
    _write_png(photos / "coffee.png", _pixels(photos / "coffee.jpg"))  # a stem twice
    warm = root / "warm"
    for name in ("sunset", "coffee", "flower", "seeding", "aitzgorri", "bridge"):
        img = _pixels(small_copy(SAMPLES / f"{name}.jpg", warm / f"{name}.png", 40))
        _write_png(warm / f"{name}.png", np.clip(img[..., :3] * [1.1, 0.95, 0.7], 0, 1))
    return photos, warm


@pytest.fixture(scope="module")
def own_batch(own_photos, tmp_path_factory) -> tuple[Path, object]:
    """(the output folder, the result) of a batch of ``own_photos`` with the warm styles."""
    photos, warm = own_photos
    out = tmp_path_factory.mktemp("own_out") / "own"
    return out, run_cli("batch", str(photos), "-o", str(out), "--style", str(warm),
                        "--no-cache")


def test_a_batch_measures_the_look_against_its_own_photos(own_batch):
    """Six or more photos directly in the batch's folder are the look's content model
    beside the shipped palettes: said on the summary, recorded in the settings; their
    palettes are read once and kept in the output folder; a broken photo among them is
    skipped there as in the grade, two photos of one stem are both read."""
    out, own = own_batch
    assert own.exit_code == 1, own.output  # the broken photo fails; the others are graded
    assert "graded 8, skipped 0, failed 1" in own.output
    assert "measured against 8 photos of the folder" in own.output
    settings = json.loads((out / ".wbcgrade-batch.json").read_text())
    kept = out / ".wbcgrade-own-photos.npz"  # their palettes, read once
    assert settings["options"]["natural"] == str(kept.resolve())
    assert len(load_preset(kept).names) == 8


@pytest.mark.slow
def test_the_own_photos_change_the_grade_from_the_shipped_palettes(own_photos, own_batch,
                                                                    tmp_path):
    """The look is judged against them: how sure it is that the styles share a look differs
    from the shipped palettes' alone (``--natural shipped``), and so does the grade wherever
    one is applied."""
    photos, warm = own_photos
    out, _ = own_batch
    shipped = run_cli("batch", str(photos), "-o", str(tmp_path / "shipped"), "--style",
                      str(warm), "--natural", "shipped", "--no-cache")
    assert "graded 8" in shipped.output and "content:" not in shipped.output

    def outcome(folder: Path, name: str) -> dict:
        return json.loads((folder / ".wbcgrade-results" / f"{name}.jpg.json").read_text())[
            "outcome"]

    judged = 0
    for name in OWN_NAMES:
        own, alone = outcome(out, name), outcome(tmp_path / "shipped", name)
        assert own["source"] == alone["source"]
        if own["source"] != "set-look":  # a style photo of its scene: that style's look
            continue
        judged += 1
        assert own["look_probability"] != alone["look_probability"]  # (rounded to 0.001)
        assert "your 8 own photos" in own["advice"] and "own photos" not in alone["advice"]
        differ = np.abs(_pixels(out / f"{name}.jpg") - _pixels(tmp_path / "shipped"
                                                               / f"{name}.jpg")).max()
        assert (differ > 0) == (own["strength"] != alone["strength"])
    assert judged >= 3


def test_five_own_photos_are_too_few(own_photos, tmp_path):
    photos, warm = own_photos
    few = tmp_path / "few"
    few.mkdir()
    for name in OWN_NAMES[:5]:
        shutil.copy(photos / f"{name}.jpg", few / f"{name}.jpg")
    result = run_cli("batch", str(few), "-o", str(tmp_path / "few_out"), "--style", str(warm),
                     "--no-cache")
    assert result.exit_code == 0 and "content:" not in result.output


def test_a_presets_look_reads_no_content_of_the_batch(own_photos, tmp_path):
    """A preset's look is baked in: no content model is read."""
    photos, _ = own_photos
    preset = run_cli("batch", str(photos), "-o", str(tmp_path / "preset"), "--preset", "warm",
                     "--no-cache")
    assert "graded 8" in preset.output and "content:" not in preset.output


@pytest.mark.slow
def test_a_folder_graded_towards_its_own_look_is_not_its_own_content(own_photos, tmp_path):
    """A folder graded towards its own look: its photos are the styles, not its content."""
    _, warm = own_photos
    itself = run_cli("batch", str(warm), "-o", str(tmp_path / "itself"), "--style", str(warm),
                     "--no-cache")
    assert itself.exit_code == 0 and "content:" not in itself.output
