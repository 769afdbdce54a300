"""The explore page says what a grade did in the command line's words (its flags)."""

from __future__ import annotations

import numpy as np

from wbcgrade.cli.option_table import flag_of
from wbcgrade.color.grade.grading import Grade, grade_outcome
from wbcgrade.color.mapping.remap import identity_map
from wbcgrade.color.outcome import GradeSource
from wbcgrade.explore.engine import describe_outcome


def test_the_page_names_flags_where_the_library_names_settings():
    moved = identity_map(9)
    moved[..., 0] = np.minimum(moved[..., 0] + 0.3, 1.0)
    grade = Grade(("warm",), np.ones(1), moved, source=GradeSource.PRESET_LOOK)
    outcome = grade_outcome(grade, None, None, blend=0.01)  # almost none of it: advice
    assert outcome.unchanged and "map.strength" in outcome.reason
    page = describe_outcome(outcome, flag_of)
    assert "--strength 0.01 applies almost none" in page["words"]
    assert page["reason"].startswith("--strength 0.01") and "--strength" in page["advice"]
    assert "map.strength" in describe_outcome(outcome)["words"]  # a caller with no flags
