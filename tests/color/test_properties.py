"""Property tests (Hypothesis) of the colour domain's small contracts: ``--weights``
parsing, the options' ranges, colour encoding round trips and LUT file round trips.
Few examples each (fast tier); every property holds for any input Hypothesis draws."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from wbcgrade.color.colorspace import ColorEncoding, convert, resolve_space
from wbcgrade.color.grade.saved_grade import load_look, look_dict, look_from_dict
from wbcgrade.color.mapping.lut import read_cube, write_cube
from wbcgrade.color.options import FitOptions, MapOptions, RegrainOptions
from wbcgrade.color.weights import parse_weights
from wbcgrade.errors import InputError, OptionError

FEW = settings(max_examples=25, deadline=None,
               suppress_health_check=[HealthCheck.function_scoped_fixture])

#: colour conversions go through OpenColorIO (a few milliseconds a call): fewer examples
CONVERSIONS = settings(max_examples=10, deadline=None)

finite = st.floats(min_value=0, max_value=1e300, allow_nan=False, allow_infinity=False)


# -- --weights ------------------------------------------------------------------------------

@FEW
@given(st.lists(finite, min_size=1, max_size=12).filter(lambda v: max(v) > 0))
def test_weights_are_the_given_proportions_summing_to_one(values):
    weights = parse_weights(",".join(repr(v) for v in values))
    assert len(weights) == len(values) and all(w >= 0 for w in weights)
    assert math.fsum(weights) == pytest.approx(1.0, abs=1e-12)
    largest = values.index(max(values))
    total = math.fsum(v / max(values) for v in values)  # (1 to 12: a second division)
    for value, weight in zip(values, weights):
        # what underflows is dropped (value / largest, then over the total, can reach 0)
        assert (weight == 0) == (value / max(values) / total == 0)
        assert weight / weights[largest] == pytest.approx(value / values[largest], rel=1e-9)


@FEW
@given(st.lists(finite, min_size=1, max_size=6),
       st.sampled_from(["-1", "nan", "inf", "-inf", "x", "1e999"]), st.data())
def test_a_negative_or_non_finite_weight_is_refused(values, bad, data):
    position = data.draw(st.integers(0, len(values)))
    words = [repr(v) for v in values]
    words.insert(position, bad)
    with pytest.raises(InputError, match="comma-separated numbers|non-negative finite"):
        parse_weights(",".join(words))


# -- option ranges --------------------------------------------------------------------------

RANGES = [  # (group, field, lowest, highest) of the integer options
    (FitOptions, "bins", 4, 256),
    (MapOptions, "size", 2, 129),
]


@FEW
@pytest.mark.parametrize("group, field, low, high", RANGES)
@given(value=st.integers(-10 ** 6, 10 ** 6))
def test_an_integer_option_is_accepted_exactly_inside_its_range(group, field, low, high, value):
    if low <= value <= high:
        assert getattr(group(**{field: value}), field) == value
    else:
        with pytest.raises(OptionError, match=f"between {low} and {high}") as caught:
            group(**{field: value})
        assert caught.value.option.endswith(field)


@FEW
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_regrain_eps_is_accepted_exactly_when_within_its_bounds(value):
    """Positive and finite, and between MIN_REGRAIN_EPS and MAX_REGRAIN_EPS (1e39 made an
    all-black photo; below 1e-12 float32 cannot hold it)."""
    from wbcgrade.limits import MAX_REGRAIN_EPS, MIN_REGRAIN_EPS

    if math.isfinite(value) and MIN_REGRAIN_EPS <= value <= MAX_REGRAIN_EPS:
        assert RegrainOptions(eps=value).eps == value
    else:
        with pytest.raises(OptionError, match="positive" if not value > 0 or math.isinf(value)
                           else "between"):
            RegrainOptions(eps=value)


@FEW
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_the_fit_floor_is_a_fraction_below_one(value):
    if math.isfinite(value) and 0 <= value < 1:
        assert FitOptions(floor=value).floor == value
    else:
        with pytest.raises(OptionError, match=r"\[0, 1\)"):
            FitOptions(floor=value)


# -- colour encoding round trips ------------------------------------------------------------

unit = arrays(np.float32, st.tuples(st.integers(1, 16), st.just(3)),
              elements=st.floats(0, 1, width=32))
scene = arrays(np.float32, st.tuples(st.integers(1, 16), st.just(3)),
               elements=st.floats(-0.5, 50, width=32))


@CONVERSIONS
@given(unit)
def test_srgb_encoding_and_decoding_are_inverse(rgb):
    srgb, linear = resolve_space("srgb"), resolve_space("linear-rec709")
    decoded = convert(rgb, srgb, linear)
    assert np.abs(convert(decoded, linear, srgb) - rgb).max() < 5e-5
    # the sRGB curve itself (IEC 61966-2-1), which the conversion must be
    expected = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    assert np.abs(decoded - expected).max() < 5e-5


@CONVERSIONS
@pytest.mark.parametrize("working", ["srgb", "acescct"])
@given(rgb=scene)
def test_a_scene_linear_photo_comes_back_from_its_working_space(working, rgb):
    """Into the working cube (values above its top scaled down, what leaves it carried
    aside) and back: the photo, values above 1 and below 0 included."""
    encoding = ColorEncoding.of(input_space=resolve_space("linear-rec709"),
                                working_space=resolve_space(working))
    encoded, state = encoding.encode(rgb, float_values=True)
    assert encoded.min() >= 0 and encoded.max() <= 1
    back = encoding.decode(encoded, state)
    # float32 conversions (primaries mixed by a matrix): an error relative to the pixel's
    # largest channel
    size = np.maximum(1.0, np.abs(rgb).max(axis=-1, keepdims=True))
    assert np.all(np.abs(back - rgb) <= 5e-5 * size)


# -- LUT file round trips -------------------------------------------------------------------

tables = st.integers(2, 9).flatmap(lambda n: arrays(
    np.float32, (n, n, n, 3), elements=st.floats(0, 1, width=32)))


@FEW
@given(tables)
def test_a_cube_written_reads_back_as_the_same_table(table):
    with tempfile.TemporaryDirectory() as folder:
        path = write_cube(Path(folder) / "look.cube", table)
        look = load_look(path)                                # wbcgrade's own reader
        assert look.color_map.shape == table.shape
        assert np.abs(look.color_map - table).max() <= 6e-7   # six decimals
        assert np.abs(read_cube(path).table - table).max() <= 6e-7   # colour-science's


@FEW
@given(tables)
def test_a_saved_grade_keeps_its_map_within_one_16_bit_code(table):
    assume(table.max() > table.min())
    with tempfile.TemporaryDirectory() as folder:
        grade = load_look(write_cube(Path(folder) / "look.cube", table))
    again = look_from_dict(look_dict(grade))
    span = float(grade.color_map.max() - grade.color_map.min())
    assert np.abs(again.color_map - grade.color_map).max() <= span / 65535 * 0.5 + 1e-7
