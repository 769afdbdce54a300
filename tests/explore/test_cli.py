"""`wbcgrade explore` on the command line: errors are one line, the address is printed,
Ctrl-C stops the server and its worker."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import time
import urllib.request
import uuid
from pathlib import Path

import pytest

from tests.conftest import run_cli as run
from tests.explore.conftest import PRESET, WBCGRADE, command_env


def test_explore_is_a_command_with_its_options():
    assert "explore" in run("--help").output
    result = run("explore", "--help")
    assert result.exit_code == 0
    for option in ("--style", "--preset", "--port", "--no-browser"):
        assert option in result.output


def test_bad_inputs_are_one_line_errors(tmp_path, photo):
    # a missing input (photo, styles, preset) exits 1; a bad option value 2 (a usage error)
    for args, message, status in (
            ((tmp_path / "missing.jpg", "--preset", PRESET), "no such file", 1),
            ((photo,), "give exactly one of --style DIR or --preset", 2),
            ((photo, "--preset", PRESET, "--style", tmp_path), "give exactly one of", 2),
            ((photo, "--preset", "nosuch"), "unknown preset 'nosuch'", 1),
            ((photo, "--style", tmp_path / "nope"), "style folder does not exist", 1),
            ((photo, "--preset", PRESET, "--save-dir", tmp_path / "nope"),
             "the save folder does not exist (--save-dir)", 2)):
        result = run("explore", *args, "--no-browser")
        assert result.exit_code == status, (args, result.output)
        assert result.stderr.strip().splitlines()[-1].startswith("Error: "), result.stderr
        assert message in result.stderr and "Traceback" not in result.stderr


def test_a_busy_port_is_reported_before_any_work(photo):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = run("explore", photo, "--preset", PRESET, "--port", port, "--no-browser")
    assert result.exit_code == 1
    assert f"cannot listen on 127.0.0.1:{port}" in result.stderr and "--port" in result.stderr


#: In the environment of the explore processes a test starts (their job workers inherit it),
#: so that the test counts its own workers only: another test may run beside it
#: (pytest-xdist) with workers of its own.
TAG = "WBCGRADE_TEST_TAG"


def _workers(tag: str) -> set[int]:
    """The explore job workers running with ``tag`` in their environment."""
    mine = f"{TAG}={tag}".encode()
    found = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if b"wbcgrade.explore._worker" in (entry / "cmdline").read_bytes() \
                        and mine in (entry / "environ").read_bytes().split(b"\0"):
                    found.add(int(entry.name))
            except OSError:
                continue
    return found


@pytest.mark.slow
def test_it_prints_the_address_serves_and_stops_cleanly_on_ctrl_c(photo):
    tag = uuid.uuid4().hex
    before = _workers(tag)
    process = subprocess.Popen(
        [*WBCGRADE, "explore", str(photo), "--preset", PRESET, "--no-browser"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**command_env(), "DISPLAY": "", TAG: tag})
    try:
        url = process.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:") and url.endswith("/"), url
        with urllib.request.urlopen(url + "api/state", timeout=60) as answer:
            state = json.load(answer)
        assert state["names"] == ["coffee", "flower", "sunset"]
        assert state["look"]["command"].startswith("wbcgrade apply ")
        with urllib.request.urlopen(url + "api/state?palette=1", timeout=120) as answer:
            assert len(json.load(answer)["fit"]["weights"]) == 3  # the palette mode
        deadline = time.monotonic() + 60
        while not (_workers(tag) - before) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert _workers(tag) - before, "the job worker did not start"
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, err
    assert "Open the address above" in err and "Stopped." in err and "Traceback" not in err
    assert "grade: " in err and "saves into: " in err
    deadline = time.monotonic() + 10
    while (_workers(tag) - before) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not (_workers(tag) - before), "the job worker outlived the server"


def _ignore_ctrl_c() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.mark.slow
def test_ctrl_c_stops_the_server_started_by_a_process_that_ignores_it(photo):
    # (a process inherits an ignored SIGINT: a test runner's worker, a script's background job)
    process = subprocess.Popen(
        [*WBCGRADE, "explore", str(photo), "--preset", PRESET, "--no-browser"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**command_env(), "DISPLAY": ""}, preexec_fn=_ignore_ctrl_c)
    try:
        url = process.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), url
        with urllib.request.urlopen(url + "api/state", timeout=60) as answer:
            assert json.load(answer)["names"]  # serving
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0 and "Stopped." in err, err


@pytest.mark.slow
def test_a_worker_still_starting_is_stopped_with_the_server(server, monkeypatch):
    """Closed while its worker process still imports, the job queue kills it (else it
    outlived the server until its imports were done)."""
    from wbcgrade.explore.jobs import JobWorker

    tag = uuid.uuid4().hex
    monkeypatch.setenv(TAG, tag)
    before = _workers(tag)
    worker = JobWorker(server.studio.session.grader_state()).start()
    deadline = time.monotonic() + 30
    while not (_workers(tag) - before) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert _workers(tag) - before, "the job worker did not start"
    worker.close()
    deadline = time.monotonic() + 0.5  # killed, not left to finish its imports (~1-2 s)
    while (_workers(tag) - before) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert not (_workers(tag) - before), "the starting worker outlived close()"
