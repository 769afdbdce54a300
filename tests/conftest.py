"""Shared test fixtures."""

import os
import tempfile

import numpy as np
import pytest


@pytest.fixture(scope="session", autouse=True)
def _system_temporary_folder_in_basetemp(tmp_path_factory):
    """Every temporary file of the session (``tempfile``, and ``$TMPDIR`` for the commands
    the tests start) goes under pytest's own folder, removed when every test passed
    (``tmp_path_retention_policy = "failed"``): a run of the suite leaves nothing in the
    system's temporary folder (issue 31: it left about 590 MB there)."""
    folder = tmp_path_factory.mktemp("system-tmp")
    before_env, before = os.environ.get("TMPDIR"), tempfile.tempdir
    os.environ["TMPDIR"], tempfile.tempdir = str(folder), str(folder)
    yield folder
    tempfile.tempdir = before
    if before_env is None:
        os.environ.pop("TMPDIR", None)
    else:
        os.environ["TMPDIR"] = before_env


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
