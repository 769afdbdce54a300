"""What the page sends is checked before any work: weights, strength, relaxation, keys."""

from __future__ import annotations

import math

import pytest

from wbcgrade.explore.settings import RequestError, settings_from_json, weights_text


def test_weights_are_normalised_and_rounded_as_the_command_line_writes_them():
    settings = settings_from_json({"weights": [1, 1, 1]}, 3)
    assert settings.weights == (0.3333, 0.3333, 0.3333)
    assert weights_text(settings.weights) == "0.3333,0.3333,0.3333"
    settings = settings_from_json({"weights": [2e300, 6e300, 0]}, 3)  # huge but finite
    assert settings.weights == (0.25, 0.75, 0.0)
    assert weights_text(settings.weights) == "0.25,0.75,0"
    assert settings_from_json({"weights": [0.2, 0.8], "strength": 0.12345}, 2).strength == 0.123


@pytest.mark.parametrize("body, message", [
    ({"weights": "0.5,0.5"}, "must be a list of 2 numbers"),
    ({"weights": [0.5]}, "must hold 2 numbers (one per style), got 1"),
    ({"weights": [0.5, 0.3, 0.2]}, "must hold 2 numbers"),
    ({"weights": [0.5, "a"]}, "weight 2 must be a number"),
    ({"weights": [0.5, True]}, "weight 2 must be a number"),
    ({"weights": [0.5, None]}, "weight 2 must be a number"),
    ({"weights": [math.nan, 0.5]}, "weight 1 must be a finite number"),
    ({"weights": [math.inf, 0.5]}, "weight 1 must be a finite number"),
    ({"weights": [-0.1, 1.1]}, "must not be negative"),
    ({"weights": [0, 0]}, "must not all be zero"),
    ({"weights": [1e-9, 0]}, None),  # tiny but positive: all on the first style
    ({}, "weights are missing"),
    ([0.5, 0.5], "must be a JSON object"),
    ({"weights": [0.5, 0.5], "strength": 2.5}, "strength must be between 0 and 2"),
    ({"weights": [0.5, 0.5], "strength": "x"}, "strength must be a number"),
    ({"weights": [0.5, 0.5], "relaxation": 0}, "relaxation must be between"),
    ({"weights": [0.5, 0.5], "relaxation": math.nan}, "relaxation must be a finite number"),
    ({"weights": [0.5, 0.5], "keep_lightness": "yes"}, "keep_lightness must be true or false"),
    ({"weights": [0.5, 0.5], "wieghts": [1, 0]}, "unknown setting 'wieghts'"),
])
def test_bad_settings_are_refused_with_a_sentence(body, message):
    if message is None:
        assert settings_from_json(body, 2).weights == (1.0, 0.0)
        return
    with pytest.raises(RequestError, match=None) as caught:
        settings_from_json(body, 2)
    assert message in str(caught.value)


def test_relaxation_is_rounded_like_the_command_line():
    assert settings_from_json({"weights": [1, 0], "relaxation": 0.123456}, 2).relaxation == 0.123
    assert settings_from_json({"weights": [1, 0], "relaxation": None}, 2).relaxation is None
