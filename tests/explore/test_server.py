"""The studio's server: the token and the Host header are required, bad requests get a
JSON error and leave it working, LUTs and exports are what the library computes, and
nothing is written beside the photo or the styles."""

from __future__ import annotations

import hashlib
import http.client
import json
import time

import numpy as np
import pytest

from tests.explore.conftest import PRESET
from wbcgrade.color.mapping.lut import color_map_to_lut, read_cube
from wbcgrade.color.presets import resolve_preset
from wbcgrade.explore.jobs import Superseded

LUT_BYTES = 33 ** 3 * 3 * 4


def request(server, method, path, body=None, host=None, headers=None, raw=None):
    """(status, headers, body bytes) of one request to the studio."""
    connection = http.client.HTTPConnection("127.0.0.1", server.port, timeout=600)
    sent = {"Host": host if host is not None else f"127.0.0.1:{server.port}"}
    data = raw
    if body is not None:
        data = json.dumps(body).encode()
        sent["Content-Type"] = "application/json"
    sent.update(headers or {})
    connection.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
    for name, value in sent.items():
        connection.putheader(name, value)
    if data is not None:
        connection.putheader("Content-Length", str(len(data)))
    connection.endheaders(data)
    response = connection.getresponse()
    payload = response.read()
    connection.close()
    return response.status, response.headers, payload


def api(server, name, body, **kwargs):
    return request(server, "POST", f"/{server.token}/api/{name}", body, **kwargs)


def error_of(payload: bytes) -> str:
    return json.loads(payload)["error"]


def test_the_page_and_its_parts_need_the_token(server):
    status, headers, body = request(server, "GET", f"/{server.token}/")
    assert status == 200 and b"wbcgrade explore" in body
    assert headers["Content-Type"].startswith("text/html")
    assert "frame-ancestors 'none'" in headers["Content-Security-Policy"]
    assert headers["Cache-Control"] == "no-store" and headers["Referrer-Policy"] == "no-referrer"
    for path in ("app.js", "style.css", "photo.png", "style/0.png", "api/state"):
        assert request(server, "GET", f"/{server.token}/{path}")[0] == 200, path
    wrong = server.token[:-1] + ("A" if server.token[-1] != "A" else "B")
    for path in ("/", "/index.html", "/app.js", "/api/state", f"/{wrong}/", f"/{wrong}/api/state",
                 "/favicon.ico", f"/x{server.token}/"):
        status, _, body = request(server, "GET", path)
        assert status == 403 and "token" in error_of(body), path
    status, _, body = request(server, "POST", "/api/preview", {"weights": [1, 0, 0]})
    assert status == 403
    status, headers, _ = request(server, "GET", f"/{server.token}")  # no slash: redirected
    assert status == 301 and headers["Location"] == f"/{server.token}/"


@pytest.mark.parametrize("host", ["evil.example:{port}", "evil.example", "127.0.0.1",
                                  "127.0.0.1:1", "localhost", "0.0.0.0:{port}",
                                  "[::1]:{port}", "127.0.0.1.nip.io:{port}", ""])
def test_foreign_host_headers_are_refused(server, host):
    status, _, body = request(server, "GET", f"/{server.token}/api/state",
                              host=host.format(port=server.port))
    assert status == 403 and "127.0.0.1 or localhost" in error_of(body)


def test_own_host_names_are_served(server):
    for host in (f"127.0.0.1:{server.port}", f"localhost:{server.port}"):
        status, _, body = request(server, "GET", f"/{server.token}/api/state", host=host)
        assert status == 200 and json.loads(body)["names"] == ["coffee", "flower", "sunset"]


def test_path_tricks_find_nothing(server):
    for path in (f"/{server.token}/../../etc/passwd", f"/{server.token}/static/../engine.py",
                 f"/{server.token}/style/9.png", f"/{server.token}/style/-1.png",
                 f"/{server.token}/%2e%2e/x"):
        status, _, body = request(server, "GET", path)
        assert status == 404 and b"root:" not in body, path


@pytest.mark.parametrize("body, message", [
    ({"weights": [0.5, 0.5]}, "must hold 3 numbers"),
    ({"weights": [0.5, -0.2, 0.7]}, "must not be negative"),
    ({"weights": [0.5, "x", 0.5]}, "weight 2 must be a number"),
    ({"weights": [0, 0, 0]}, "must not all be zero"),
    ({"weights": [1, 0, 0], "strength": -1}, "strength"),
    ({"weights": [1, 0, 0], "volume": 11}, "unknown setting"),
])
def test_malformed_weights_get_a_json_error_and_the_server_keeps_working(server, body,
                                                                         message):
    status, headers, payload = api(server, "preview", body)
    assert status == 400 and headers["Content-Type"] == "application/json"
    assert message in error_of(payload)
    status, _, payload = api(server, "preview", {"weights": [0.2, 0.3, 0.5],
                                                  "client": "t", "seq": 10 ** 9})
    assert status == 200 and len(payload) == LUT_BYTES


def test_bodies_that_are_not_plain_json_are_refused(server):
    path = f"/{server.token}/api/preview"
    status, _, payload = request(server, "POST", path, raw=b'{"weights": [NaN, 1, 1]}',
                                 headers={"Content-Type": "application/json"})
    assert status == 400 and "NaN" in error_of(payload)
    status, _, payload = request(server, "POST", path, raw=b'{"weights": [1e309, 0, 0]}',
                                 headers={"Content-Type": "application/json"})
    assert status == 400 and "weight 1 must be a finite number" in error_of(payload)
    status, _, payload = request(server, "POST", path, raw=b"weights=1,0,0",
                                 headers={"Content-Type": "application/x-www-form-urlencoded"})
    assert status == 415
    status, _, payload = request(server, "POST", path, raw=b"{not json",
                                 headers={"Content-Type": "application/json"})
    assert status == 400 and "not valid JSON" in error_of(payload)
    status, _, payload = request(server, "POST", path, {"weights": [1, 0, 0]},
                                 headers={"Origin": "http://evil.example"})
    assert status == 403 and "another site" in error_of(payload)
    status, _, payload = request(server, "POST", path,  # refused before the body is read
                                 headers={"Content-Type": "application/json",
                                          "Content-Length": str(2 << 20)})
    assert status == 413
    status, _, payload = api(server, "landscape", {"rows": [[1, 0]]})
    assert status == 400 and "must hold 3 numbers" in error_of(payload)


def test_older_preview_requests_of_a_page_are_dropped(server):
    body = {"weights": [0.3, 0.3, 0.4], "client": "old", "seq": 5}
    assert api(server, "preview", body)[0] == 200
    status, _, payload = api(server, "preview", {**body, "seq": 4})
    assert status == 409 and json.loads(payload)["stale"] is True


@pytest.mark.slow
def test_exact_lut_and_exports_are_the_library_grade(server, tmp_path):
    studio = server.studio
    body = {"weights": [0.25, 0.25, 0.5], "strength": 0.8}
    status, headers, payload = api(server, "exact", body)
    assert status == 200 and len(payload) == LUT_BYTES
    meta = json.loads(headers["X-Explore-Meta"])
    assert meta["kind"] == "exact" and meta["weights_text"] == "0.25,0.25,0.5"
    assert "--weights 0.25,0.25,0.5 --no-regrain --strength 0.8" in meta["command"]
    exact = np.frombuffer(payload, "<f4").reshape(33, 33, 33, 3)
    # a preview at those weights now is that exact map
    status, headers, payload = api(server, "preview", {**body, "client": "x", "seq": 1})
    assert json.loads(headers["X-Explore-Meta"])["kind"] == "exact"
    assert np.array_equal(np.frombuffer(payload, "<f4").reshape(exact.shape), exact)
    for size in (33, 65):
        status, headers, payload = api(server, "export", {**body, "format": "cube",
                                                          "size": size})
        assert status == 200 and 'filename="cat_explore_' in headers["Content-Disposition"]
        path = tmp_path / f"grade{size}.cube"
        path.write_bytes(payload)
        table = read_cube(path).table
        np.testing.assert_allclose(table, color_map_to_lut(exact, size, 0.8), atol=1e-6)
        assert "reproduce: wbcgrade apply" in payload.decode()
    if "clf" in studio.formats:
        status, headers, payload = api(server, "export", {**body, "format": "clf", "size": 33})
        assert status == 200 and b"ProcessList" in payload
    status, _, payload = api(server, "export", {**body, "format": "3dl", "size": 33})
    assert status == 400 and "format must be one of" in error_of(payload)
    status, _, payload = api(server, "export", {**body, "format": "cube", "size": 17})
    assert status == 400 and "size must be one of" in error_of(payload)


@pytest.mark.slow
def test_slopes_come_with_the_exact_map_they_start_from(server):
    fitted = server.studio.fitted.as_json()
    status, headers, payload = api(server, "slopes", fitted)
    assert status == 200 and len(payload) == 4 * LUT_BYTES  # the exact map and 3 slopes
    meta = json.loads(headers["X-Explore-Meta"])
    assert meta["styles"] == 3 and meta["weights"] == fitted["weights"]
    stack = np.frombuffer(payload, "<f4").reshape(4, 33, 33, 33, 3)
    assert np.array_equal(stack[0], server.studio.worker.reference(server.studio.fitted).exact)
    assert np.abs(stack[1:]).max() > 0.01  # moving towards a style changes the map


def test_landscape_gives_the_fit_loss_at_each_mix(server):
    status, _, payload = api(server, "landscape",
                             {"rows": [[1, 0, 0], [0, 1, 0], [0, 0, 1], list(
                                 server.studio.fit.weights)]})
    assert status == 200
    data = json.loads(payload)
    vertex = server.studio.fit.vertex_losses
    np.testing.assert_allclose(data["losses"][:3], vertex, rtol=1e-6)
    assert data["fit_loss"] == pytest.approx(data["losses"][3], rel=1e-5)  # rounded weights
    assert data["fit_loss"] <= min(vertex) + 1e-12  # never worse than one style alone


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns


@pytest.mark.slow
def test_photo_and_styles_are_never_written(server, photo):
    preset = resolve_preset(PRESET)
    before = {p: _digest(p) for p in (photo, preset)}
    listing = sorted(p.name for p in photo.parent.iterdir())
    assert api(server, "export", {**server.studio.fitted.as_json(), "format": "cube",
                                  "size": 33})[0] == 200
    assert {p: _digest(p) for p in (photo, preset)} == before
    assert sorted(p.name for p in photo.parent.iterdir()) == listing


@pytest.mark.slow
def test_a_newer_job_replaces_one_still_waiting(server):
    """Coalescing: while one job runs, a newer job of its kind replaces the one waiting."""
    import threading

    worker = server.studio.worker
    worker.losses([(1.0, 0.0, 0.0)], 600)  # started: the next job runs at once
    outcomes = {}
    slow = [tuple(np.random.default_rng(0).dirichlet(np.ones(3))) for _ in range(120)]

    def ask(name, rows):
        try:
            outcomes[name] = len(worker.losses(rows, 600))
        except Superseded:
            outcomes[name] = "superseded"

    threads = [threading.Thread(target=ask, args=job) for job in
               (("first", slow), ("second", [(0.2, 0.6, 0.2)]), ("third", [(0.2, 0.2, 0.6)]))]
    for thread in threads:
        thread.start()
        time.sleep(0.2)
    for thread in threads:
        thread.join(600)
    assert outcomes == {"first": 120, "second": "superseded", "third": 1}


def test_huge_numbers_and_float_sizes_are_bad_requests(server):
    """``strength`` 10**400 (OverflowError) and ``"size": 33.0`` answered 500: they are the
    request's fault (400), with one line saying what is wrong."""
    body = {"weights": [0.25, 0.25, 0.5]}
    for name, extra, words in (("look", {"strength": 10 ** 400}, "finite number"),
                               ("exact", {"strength": 10 ** 400}, "finite number"),
                               ("export", {"format": "cube", "size": 33.0}, "size must be"),
                               ("export", {"format": "cube", "size": True}, "size must be")):
        status, _, payload = api(server, name, {**({} if name == "look" else body), **extra})
        assert status == 400 and words in error_of(payload), (name, extra, payload)
