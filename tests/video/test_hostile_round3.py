"""The third hostile round (issue 31), video: a SIGTERM right after the work folder is made
left it in the system's temporary folder (``test_hostile.py::
test_sigterm_and_sighup_clean_up_like_ctrl_c[15]`` failed now and then on that race)."""

from __future__ import annotations

import os
import signal
import tempfile

import pytest

from wbcgrade.errors import Terminated
from wbcgrade.video import workflow


def test_a_signal_just_after_the_work_folder_is_made_still_removes_it(tmp_path, monkeypatch):
    made = []
    real = os.mkdir

    def mkdir_then_signal(path, *args, **kwargs):
        real(path, *args, **kwargs)
        if os.path.basename(path).startswith(workflow.WORK_PREFIX):
            made.append(path)
            os.kill(os.getpid(), signal.SIGTERM)  # as `kill` would, at the worst moment

    def terminate(signum, frame):
        raise Terminated(signum)

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setattr(os, "mkdir", mkdir_then_signal)
    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        with pytest.raises(Terminated, match=str(int(signal.SIGTERM))):
            with workflow.work_folder():
                pytest.fail("the signal was not handled before the work began")
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert made and not os.path.exists(made[0])
    assert [p.name for p in tmp_path.iterdir()] == []
