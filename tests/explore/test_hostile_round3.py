"""The third hostile round (issue 31), the explore server: every request gets an answer, a
stalled client does not hold a thread for ever, a non-UTF-8 photo exports, Ctrl-C is quiet.

- ``GET /TOKEN/style/².png`` raised in the server ('²' is a digit to ``isdigit``);
- a POST body of 100 000 nested ``[`` raised RecursionError, no answer;
- a POST body ``null`` never got an answer;
- half a request held its thread with no time limit;
- exports of a photo whose name is not UTF-8 were all 500;
- Ctrl-C printed ~20 ``nanobind: leaked ...`` lines after "Stopped.".
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import time

import pytest

from tests.color.conftest import SAMPLES, small_copy
from tests.explore.conftest import PRESET, ROOT, WBCGRADE, command_env
from wbcgrade.explore import server as server_module


def _raw(server, data: bytes, timeout: float = 20.0) -> bytes:
    """What the server answers to ``data`` sent as is, until it closes (b"": no answer)."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=timeout) as sock:
        sock.sendall(data)
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
        return answer


def _post(server, body: bytes) -> bytes:
    head = (f"POST /{server.token}/api/preview HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n"
            f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
            "Connection: close\r\n\r\n")
    return _raw(server, head.encode() + body)


def test_a_superscript_digit_in_a_style_address_is_a_404(server):
    for digit in (b"\xb2", "²".encode()):  # the request line is read as Latin-1: b"\xb2" is '²'
        answer = _raw(server, f"GET /{server.token}/style/".encode() + digit
                      + f".png HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n"
                        "Connection: close\r\n\r\n".encode())
        assert answer.startswith(b"HTTP/1.1 404"), answer
    answer = _raw(server, f"GET /{server.token}/style/0.png HTTP/1.1\r\n"
                          f"Host: 127.0.0.1:{server.port}\r\nConnection: close\r\n\r\n".encode())
    assert answer.startswith(b"HTTP/1.1 200"), answer  # still serving


def test_deeply_nested_and_null_bodies_get_a_400(server):
    for body, words in ((b"[" * 100_000, b"nested too deeply"),
                        (b"null", b"must be a JSON object"),
                        (b"[1, 2]", b"must be a JSON object")):
        answer = _post(server, body)
        assert answer.startswith(b"HTTP/1.1 400"), (body[:10], answer)
        assert words in answer, answer


def test_a_stalled_request_is_dropped_after_the_socket_time_limit(server, monkeypatch):
    assert 0 < server_module._Handler.timeout <= 60  # no limit before
    monkeypatch.setattr(server_module._Handler, "timeout", 0.5)
    head = (f"POST /{server.token}/api/preview HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n"
            f"Content-Type: application/json\r\nContent-Length: 100\r\n\r\n{{\"weig")
    started = time.monotonic()
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as sock:
        sock.sendall(head.encode())  # ... and nothing more
        assert sock.recv(4096) == b""  # the server hung up
    assert time.monotonic() - started < 10
    answer = _post(server, json.dumps({"weights": [1, 0, 0], "client": "x", "seq": 1}).encode())
    assert answer.startswith(b"HTTP/1.1 200"), answer


@pytest.mark.slow
def test_a_photo_named_in_bytes_exports_and_ctrl_c_is_quiet(tmp_path):
    name = os.fsdecode(b"chat\xe9.png")
    photo = tmp_path / name
    os.rename(small_copy(SAMPLES / "chelsea.jpg", tmp_path / "plain.png", width=48), photo)
    process = subprocess.Popen([*WBCGRADE, "explore", str(photo), "--preset", PRESET,
                                "--no-browser"], cwd=ROOT, env=command_env(),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        url = process.stdout.readline().decode().strip()
        assert url.startswith("http://127.0.0.1:"), process.stderr.read().decode()
        port, token = int(url.split(":")[2].split("/")[0]), url.rstrip("/").rsplit("/", 1)[1]
        body = json.dumps({"weights": [1, 0, 0], "format": "cube", "size": 33}).encode()
        with socket.create_connection(("127.0.0.1", port), timeout=600) as sock:
            sock.sendall((f"POST /{token}/api/export HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                          f"Content-Type: application/json\r\nContent-Length: {len(body)}"
                          "\r\nConnection: close\r\n\r\n").encode() + body)
            answer = b""
            while chunk := sock.recv(65536):
                answer += chunk
        assert answer.startswith(b"HTTP/1.1 200"), answer[:300]
        assert b"LUT_3D_SIZE 33" in answer
        process.send_signal(signal.SIGINT)
        started = time.monotonic()
        _, stderr = process.communicate(timeout=30)
        assert time.monotonic() - started < 5
    finally:
        process.kill()
    text = stderr.decode("utf-8", "replace")
    assert text.strip().splitlines()[-1] == "Stopped.", text
    assert "nanobind" not in text and "leaked" not in text and "Traceback" not in text, text
