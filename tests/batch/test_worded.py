"""A batch's records say what the command line says: settings named as its flags."""

from __future__ import annotations

import numpy as np

from wbcgrade.batch import task as batch_task
from wbcgrade.batch.plan import BatchTask
from wbcgrade.batch.task import BatchContext, run_task
from wbcgrade.cli.option_table import flag_of
from wbcgrade.color.options import GradeOptions
from wbcgrade.color.presets import StyleSet
from wbcgrade.errors import OptionError


def test_a_failed_photos_record_names_the_flag_the_command_was_given(tmp_path, monkeypatch):
    """A photo's error names a setting (``{map.strength}``): the record says ``--strength``
    when the command gave its flags, the setting's name when a library caller gave none."""
    def refuse(*args, **kwargs):
        raise OptionError("{map.strength} 3 cannot grade this photo", "map.strength")

    monkeypatch.setattr(batch_task, "grade_file", refuse)
    photo = tmp_path / "a.jpg"
    photo.write_bytes(b"")
    styles = StyleSet(["s"], np.ones((1, 2, 2, 2)) / 8)
    task = BatchTask(photo, tmp_path / "out" / "a.jpg", "a.jpg")
    for names, said in ((dict(flag_of), "--strength 3 cannot"), (None, "map.strength 3 cannot")):
        context = BatchContext(styles, GradeOptions(), write_outputs=False, setting_names=names)
        result = run_task(task, context)
        assert result.status == "failed" and result.error.startswith(said), result.error
