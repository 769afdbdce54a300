"""The pure-array entry point: the same pipeline as ``apply``, arrays in and out."""

from __future__ import annotations

import numpy as np
import pytest

from tests.color.conftest import SAMPLES, small_copy, write_array
from wbcgrade.color.grade.grading import grade_array
from wbcgrade.color.io.images import read_image
from wbcgrade.color.options import FitOptions, GradeOptions, MapOptions, TransferOptions
from wbcgrade.color.presets import load_style_folder
from wbcgrade.errors import InputError
from wbcgrade.photos.workflow import grade_photo


@pytest.fixture(scope="module")
def scene(style_dir, tmp_path_factory):
    folder = tmp_path_factory.mktemp("array")
    path = small_copy(SAMPLES / "chelsea.jpg", folder / "chelsea.jpg")
    pixels = np.round(read_image(path).rgb() * 255).astype(np.uint8)
    png = write_array(folder / "chelsea.png", pixels / 255.0, "uint8")
    opts = GradeOptions(mode="palette", bins=16, fit_bins=8, max_iter=10, n_iter=30)
    return pixels, png, load_style_folder(style_dir, opts.transfer.bins), opts


@pytest.mark.slow
def test_an_array_is_graded_as_apply_grades_its_file(scene):
    pixels, png, styles, opts = scene
    graded, grade = grade_array(pixels, styles, opts)
    from_file = grade_photo(png, styles, opts)
    assert graded.shape == pixels.shape and graded.dtype == np.float32
    # (the file's pixels come back from OpenImageIO's uint8 conversion, which may
    # differ from k / 255 in the last bit)
    np.testing.assert_allclose(grade.weights, from_file.grade.weights, atol=1e-5)
    np.testing.assert_allclose(graded, from_file.pixels, atol=1e-4)
    # The vertex check: never worse than the best single style.
    assert grade.loss <= min(from_file.fit.vertex_losses) + 1e-12
    assert grade.info["fit"]["start"] in ("uniform", "vertex-refit", "vertex")


@pytest.mark.slow
def test_grading_in_place_gives_the_same_pixels_and_keeps_the_input_when_asked(scene):
    """apply grades a photo's pixels where they are when nothing looks at the ungraded
    ones afterwards; the result is the same, and by default the input is kept."""
    _, png, styles, opts = scene
    kept = grade_photo(png, styles, opts)
    ungraded = read_image(png).pixels
    np.testing.assert_array_equal(kept.image.pixels, ungraded)  # the input untouched
    in_place = grade_photo(png, styles, opts, keep_input=False)
    np.testing.assert_array_equal(in_place.pixels, kept.pixels)
    assert np.shares_memory(in_place.pixels, in_place.image.pixels)  # no second array
    assert not np.array_equal(in_place.image.pixels, ungraded)


@pytest.mark.slow
def test_integer_and_float_arrays_give_the_same_grade(scene):
    pixels, _, styles, opts = scene
    as_int, _ = grade_array(pixels, styles, opts)
    as_float, _ = grade_array(pixels / 255.0, styles, opts)
    np.testing.assert_allclose(as_int, as_float, atol=1e-6)


@pytest.mark.parametrize("bad, message", [
    (np.zeros((4, 4)), "an \\(H, W, 3\\) image"),
    (np.zeros((4, 4, 4)), "an \\(H, W, 3\\) image"),
    (np.full((4, 4, 3), np.nan), "NaN or inf"),
])
def test_bad_arrays_are_refused(scene, bad, message):
    _, _, styles, opts = scene
    with pytest.raises(InputError, match=message):
        grade_array(bad, styles, opts)


@pytest.mark.slow
def test_grouped_options_and_the_former_flat_ones_are_the_same(scene):
    """grade_array(rgb, styles, options) takes the grouped options; the former flat
    settings still work, as GradeOptions(...) or as keywords."""
    pixels, _, styles, opts = scene
    grouped = GradeOptions(fit=FitOptions(bins=8, max_iter=10, n_iter=30),
                           transfer=TransferOptions(bins=16, relaxation=0.05),
                           map=MapOptions(builder="palette", size=9))
    flat = GradeOptions(mode="palette", bins=16, fit_bins=8, max_iter=10, n_iter=30,
                        relaxation=0.05,
                        map_size=9)
    assert grouped == flat
    a, grade = grade_array(pixels, styles, grouped)
    b, _ = grade_array(pixels, styles, opts, relaxation=0.05, map_size=9)
    np.testing.assert_array_equal(a, b)
    assert grade.color_map.shape == (9, 9, 9, 3)
    assert grade.info["sinkhorn"]["relaxation"] == 0.05
