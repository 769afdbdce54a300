"""Fixtures for the explore tests: a small photo and a running studio (server + job worker)."""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

import pytest

from tests.color.conftest import SAMPLES, THREE_STYLES, small_copy
from wbcgrade.explore.app import start_studio

#: The preset the tests explore (three styles on 32^3: the cheapest exact maps).
PRESET = str(THREE_STYLES)
ROOT = Path(__file__).resolve().parents[2]
#: ``wbcgrade`` as a command, from this source tree (whatever else is installed).
WBCGRADE = [sys.executable, "-c", "import sys; from wbcgrade.cli import main; sys.exit(main())"]


def command_env() -> dict:
    """The environment of a ``WBCGRADE`` process: this source tree first on the path."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path}


@pytest.fixture(scope="session")
def photo(tmp_path_factory) -> Path:
    """A 160 x 106 PNG copy of a sample photo (lossless, so 8-bit outputs compare exactly)."""
    return small_copy(SAMPLES / "chelsea.jpg", tmp_path_factory.mktemp("explore") / "cat.png",
                      width=160)


@pytest.fixture(scope="session")
def save_dir(tmp_path_factory) -> Path:
    """The folder the studio's saved photos go to."""
    return tmp_path_factory.mktemp("saved")


@pytest.fixture(scope="session")
def server(photo, save_dir):
    """A studio on the photo with the preset, served from a thread; closed afterwards."""
    server = start_studio(str(photo), preset=PRESET, prefetch=False, save_dir=save_dir)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1},
                              daemon=True)
    thread.start()
    yield server
    server.shutdown()
    server.close()
    thread.join(5)
