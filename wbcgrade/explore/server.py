"""The explore page's local web server (standard library ``http.server``).

Why the standard library: the page needs a dozen routes, JSON in and out,
a few binary answers and no templates, sessions or websockets; a framework
(Flask, Starlette) would add dependencies and its own development server
for nothing the safety rules below need. ``ThreadingHTTPServer`` answers
each request in its own thread, so a long export does not hold up the
preview.

Safety (a local server is reachable by every web page the user visits,
through the browser):

- bound to 127.0.0.1 only;
- every request's path starts with a random token (``secrets``, 192 bits)
  that only the printed address holds: ``/TOKEN/...``; others get 403;
- the ``Host`` header must be ``127.0.0.1:PORT`` or ``localhost:PORT``
  (a DNS-rebinding page sends its own host name): others get 403;
- POST bodies must be JSON (``Content-Type: application/json``, so a
  cross-site form cannot send one without a CORS preflight, which is never
  granted), at most 1 MB, and an ``Origin`` header, when sent, must be this
  server's;
- answers carry ``no-store``, ``nosniff``, ``no-referrer``, a content
  security policy allowing only this origin, and ``frame-ancestors 'none'``;
- the photo and the styles are only read; exports are written by the LUT
  writer into a private temporary folder and sent as downloads;
- bad requests (malformed weights, NaN, negative, wrong length, unknown keys)
  get 400 and a JSON ``{"error": "..."}`` the page shows; the server keeps
  serving.
"""

from __future__ import annotations

import base64
import hmac
import json
import secrets
import threading
import time
import traceback
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qsl, quote, urlsplit

import numpy as np

from wbcgrade.explore.engine import EXPORT_FORMATS, EXPORT_SIZES, clf_available, describe_outcome
from wbcgrade.explore.jobs import JobError, JobWorker, Superseded
from wbcgrade.explore.settings import (
    RequestError,
    Settings,
    blend_from_json,
    settings_from_json,
    strength_from_json,
    weights_from_json,
    weights_text,
)

__all__ = ["Studio", "ExploreServer", "make_server", "MAX_BODY", "MAX_LANDSCAPE_ROWS"]

#: Largest POST body accepted, in bytes.
MAX_BODY = 1 << 20
#: Most weight rows one landscape request may ask for.
MAX_LANDSCAPE_ROWS = 1024
#: Seconds a connection may stay silent while a request is read or its answer written
#: (a client that sends half a request and stops held a thread each for ever).
SOCKET_TIMEOUT_S = 30.0
#: Seconds a request waits for an exact map (an export at most; a view job is
#: usually replaced long before).
EXACT_TIMEOUT_S = 900.0

_STATIC = {"": ("index.html", "text/html; charset=utf-8"),
           "index.html": ("index.html", "text/html; charset=utf-8"),
           "app.js": ("app.js", "text/javascript; charset=utf-8"),
           "style.css": ("style.css", "text/css; charset=utf-8")}

_SECURITY_HEADERS = {
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "X-Frame-Options": "DENY",
    "Cross-Origin-Opener-Policy": "same-origin",
    "Cross-Origin-Resource-Policy": "same-origin",
    "Content-Security-Policy": ("default-src 'none'; script-src 'self'; style-src 'self'; "
                                "img-src 'self' blob: data:; connect-src 'self'; "
                                "frame-ancestors 'none'; base-uri 'none'; form-action 'none'"),
}


class Stale(Exception):
    """A preview request older than one already answered for the same page."""


class Studio:
    """What the page works on: the session, its fit, the job worker, the preview state.

    Parameters
    ----------
    session : :class:`wbcgrade.explore.engine.Session`.
    fit : its :class:`~wbcgrade.explore.engine.FitResult`.
    worker : a started :class:`~wbcgrade.explore.jobs.JobWorker`.
    """

    def __init__(self, session, fit=None, worker: JobWorker | None = None) -> None:
        self.session = session
        self._fit = fit
        self._worker = worker
        self._fitted = None
        self._lazy_lock = threading.Lock()
        self.formats = [f for f in EXPORT_FORMATS if f != "clf" or clf_available()]
        self.sizes = list(EXPORT_SIZES)
        self._preview_lock = threading.Lock()
        self._latest: dict[str, int] = {}
        self._latest_lock = threading.Lock()
        self.photo_png = session.png(session.preview)
        self.thumbnails_png = [session.png(t) for t in session.thumbnails]

    # the palette fit and the job worker: made when the palette mode first needs them
    @property
    def fit(self):
        """The palette weights ``apply --mode palette`` fits (fitted on first use)."""
        with self._lazy_lock:
            if self._fit is None:
                self._fit = self.session.fit()
            return self._fit

    @property
    def fitted(self) -> Settings:
        """The fitted weights as page settings."""
        if self._fitted is None:
            self._fitted = settings_from_json({"weights": list(self.fit.weights)},
                                              self.session.n_styles)
        return self._fitted

    @property
    def worker(self) -> JobWorker:
        """The job worker of this style source (started on first use)."""
        with self._lazy_lock:
            if self._worker is None:
                self._worker = JobWorker(self.session.grader_state()).start()
            return self._worker

    def close(self) -> None:
        """Stop the job worker, when one was started."""
        with self._lazy_lock:
            worker, self._worker = self._worker, None
        if worker is not None:
            worker.close()

    # the look grade (what ``apply`` gives): its map, words, command, export and save
    def look(self, strength: float):
        """The look grade ``apply`` gives -> (its 33^3 map at ``--strength`` 1, meta: what
        it is at the page's ``strength`` and the ``apply`` command). The page applies the
        strength itself (above 1 on the map's lattice, as ``apply`` does)."""
        started = time.perf_counter()
        grade = self.session.look_at(strength)
        lut = np.ascontiguousarray(self.session.look_grade().color_map, dtype=np.float32)
        return lut, {"kind": "exact", "mode": "look",
                     "ms": round(1000 * (time.perf_counter() - started), 1),
                     "strength": strength,
                     "grade": describe_outcome(grade.outcome, self.session.setting_names),
                     "command": self.session.look_command(strength)}

    def grade_of(self, mode: str, settings: Settings | None, strength: float):
        """(the Grade the page shows in ``mode``, what it is in words, its ``apply`` command)."""
        session = self.session
        if mode == "look":
            grade = session.look_at(strength)
            command = session.look_command(strength)
        else:
            color_map, _ = self.exact(settings, "export")
            grade = session.palette_grade(color_map, settings)
            command = session.command_line(settings)
            ranked = ", ".join(f"{n} {w:.4f}" for n, w in grade.ranked())
            words = describe_outcome(grade.outcome, session.setting_names)["words"]
            return grade, f"{words}; weights {ranked}", \
                command
        return grade, describe_outcome(grade.outcome, session.setting_names)["words"], command

    def export_mode(self, mode: str, settings: Settings | None, strength: float,
                    lut_format: str, size: int) -> tuple[str, bytes]:
        """The LUT file of exactly what the page shows in ``mode``."""
        if lut_format not in self.formats:
            raise RequestError(f"format must be one of {', '.join(self.formats)}")
        if isinstance(size, bool) or not isinstance(size, int) or size not in self.sizes:
            raise RequestError(f"size must be one of {', '.join(map(str, self.sizes))}")
        grade, words, command = self.grade_of(mode, settings, strength)
        return self.session.export_grade(grade, lut_format, size, words, command)

    def state(self) -> dict:
        """The page's start-up data."""
        session = self.session
        prefix = session.command_line(self.fitted).split(" --weights ")[0]
        height, width = session.preview.shape[:2]
        return {"photo": session.photo, "names": session.names,
                "styles": session.style_dir if session.style_dir is not None
                else f"preset {session.preset}",
                "fit": self.fit.as_json(session.names),
                "fitted": self.fitted.as_json(),
                "fitted_text": weights_text(self.fitted.weights),
                "command_prefix": prefix, "lut_size": session.lut_size,
                "preview": {"width": width, "height": height},
                "formats": self.formats, "sizes": self.sizes}

    def _meta(self, settings: Settings, kind: str, started: float, **extra) -> dict:
        return {"kind": kind, "ms": round(1000 * (time.perf_counter() - started), 1),
                "weights": list(settings.weights), "weights_text": weights_text(settings.weights),
                "relaxation": settings.relaxation, "keep_lightness": settings.keep_lightness,
                "command": self.session.command_line(settings), **extra}

    def preview(self, settings: Settings, client: str, seq: int):
        """The LUT to show now for ``settings`` -> (33^3 x 3 float32, meta).

        The exact map when it is known; else the fast map corrected by the
        nearest known exact map of the same family. Raises Stale when a newer
        request of the same page arrived meanwhile (it is answered instead).
        """
        with self._latest_lock:
            self._latest[client] = max(self._latest.get(client, seq), seq)
        with self._preview_lock:
            with self._latest_lock:
                if seq < self._latest[client]:
                    raise Stale
            started = time.perf_counter()
            known = [r for r in self.worker.references(settings.family)
                     if r.settings.weights == settings.weights]
            if known:
                return known[0].exact, self._meta(settings, "exact", started)
            nearest, distance = None, None
            for reference in self.worker.references(settings.family):
                gap = sum(abs(a - b) for a, b in zip(reference.settings.weights,
                                                     settings.weights))
                if distance is None or gap < distance:
                    nearest, distance = reference, gap
            lut = self.session.preview_lut(self.session.fast_map(settings),
                                           None if nearest is None else nearest.offset)
            if distance is not None:
                distance = round(distance, 4)
            return lut, self._meta(settings, "preview", started, reference_distance=distance)

    def exact(self, settings: Settings, group: str = "view"):
        """The exact map of ``settings`` (waits; Superseded when a newer view replaced it)."""
        started = time.perf_counter()
        reference = self.worker.reference(settings, group, EXACT_TIMEOUT_S)
        return reference.exact, self._meta(settings, "exact", started,
                                           compute_s=round(reference.seconds, 3))

    def export(self, settings: Settings, lut_format: str, size: int) -> tuple[str, bytes]:
        """The LUT file of exactly what the page shows at ``settings``."""
        if lut_format not in self.formats:
            raise RequestError(f"format must be one of {', '.join(self.formats)}")
        if isinstance(size, bool) or not isinstance(size, int) or size not in self.sizes:
            raise RequestError(f"size must be one of {', '.join(map(str, self.sizes))}")
        color_map, _ = self.exact(settings, "export")
        return self.session.export(color_map, settings, lut_format, size)

    def slopes(self, settings: Settings):
        """The exact map at ``settings`` and the fast map's slopes there ->
        ((S + 1) x 33^3 x 3 float32, meta): what the page extrapolates moves from."""
        started = time.perf_counter()
        reference = self.worker.reference(settings, "view", EXACT_TIMEOUT_S)
        slopes = self.worker.slopes(settings, EXACT_TIMEOUT_S)
        return np.concatenate([reference.exact[None], slopes]), self._meta(
            settings, "slopes", started, styles=len(slopes))

    def landscape(self, rows: list[tuple[float, ...]]) -> dict:
        """The fit's loss at each row of weights, and at the fitted weights."""
        losses = self.worker.losses([self.fit.weights, *rows], EXACT_TIMEOUT_S)
        return {"fit_loss": losses[0], "losses": losses[1:]}


class ExploreServer(ThreadingHTTPServer):
    """The HTTP server of one studio: 127.0.0.1 only, one token.

    Bound when made (so that a busy port is reported before any work); it
    answers 503 until ``studio`` is set.
    """

    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, port: int = 0, token: str | None = None,
                 studio: Studio | None = None) -> None:
        self.studio = studio
        self.token = token or secrets.token_urlsafe(24)
        super().__init__(("127.0.0.1", port), _Handler)
        self.port = self.server_address[1]
        self.hosts = {f"127.0.0.1:{self.port}", f"localhost:{self.port}"}
        self.origins = {f"http://{host}" for host in self.hosts}

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/{self.token}/"

    def close(self) -> None:
        """Close the socket and stop the studio's job worker."""
        self.server_close()
        if self.studio is not None:
            self.studio.close()


def make_server(port: int = 0, token: str | None = None) -> ExploreServer:
    """An :class:`ExploreServer` bound to 127.0.0.1:``port`` (0: any free port).

    Raises OSError with a sentence when the port is taken or not allowed.
    """
    try:
        return ExploreServer(port, token)
    except OSError as exc:
        raise OSError(f"cannot listen on 127.0.0.1:{port} ({exc.strerror or exc}); choose "
                      "another --port, or 0 for any free port") from None


def _static(name: str) -> bytes:
    return resources.files("wbcgrade.explore").joinpath("static", name).read_bytes()


class _Handler(BaseHTTPRequestHandler):
    server: ExploreServer
    timeout = SOCKET_TIMEOUT_S  # the socket's, set by StreamRequestHandler.setup
    protocol_version = "HTTP/1.1"
    server_version = "wbcgrade-explore"
    sys_version = ""

    def log_message(self, format, *args) -> None:  # noqa: A002 - the base class's name
        pass  # quiet: the terminal shows the address and errors only

    def handle(self) -> None:
        try:
            super().handle()
        except (BrokenPipeError, ConnectionResetError, TimeoutError):
            pass  # the page went away (closed, reloaded) or stalled before its answer

    # -- answers -------------------------------------------------------------------
    def _send(self, status: int, body: bytes, content_type: str,
              headers: dict[str, str] | None = None) -> None:
        self.send_response(status)
        for name, value in {**_SECURITY_HEADERS, **(headers or {})}.items():
            self.send_header(name, value)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, data: dict) -> None:
        self._send(status, json.dumps(data).encode("utf-8"), "application/json")

    def _error(self, status: int, message: str, **extra) -> None:
        # A refused request's body may be unread: do not read the next request from it.
        self.close_connection = True
        self._send(status, json.dumps({"error": message, **extra}).encode("utf-8"),
                   "application/json", {"Connection": "close"})

    def _lut(self, lut, meta: dict) -> None:
        """LUTs (one (n, n, n, 3) or a stack of them) as little-endian float32, C order."""
        body = lut.astype("<f4", copy=False).tobytes()
        self._send(200, body, "application/octet-stream",
                   {"X-Explore-Meta": json.dumps({**meta, "size": int(lut.shape[-2])})})

    def _download(self, name: str, body: bytes) -> None:
        """A file the browser saves (a LUT), its name in the headers."""
        plain = "".join(c if c.isascii() and c.isprintable() and c not in '"\\'
                        else "_" for c in name)
        raw = name.encode("utf-8", "surrogateescape")  # a non-UTF-8 photo's name
        self._send(200, body, "application/octet-stream",
                   {"Content-Disposition": f"attachment; filename=\"{plain}\"; "
                                           f"filename*=UTF-8''{quote(raw)}",
                    "X-Explore-File": base64.b64encode(raw).decode("ascii")})

    # -- checks ------------------------------------------------------------------------
    def _route(self) -> str | None:
        """The path after the token, or None after refusing the request."""
        host = self.headers.get("Host", "")
        if host not in self.server.hosts:
            self._error(403, "refused: this server answers only to 127.0.0.1 or localhost "
                             "on its own port")
            return None
        path = urlsplit(self.path).path
        parts = path.split("/", 2)
        token = parts[1] if len(parts) > 1 else ""
        if not hmac.compare_digest(token.encode(), self.server.token.encode()):
            self._error(403, "refused: the address lacks the token; open the address "
                             "`wbcgrade explore` printed")
            return None
        if self.server.studio is None:
            self._error(503, "still loading the photo and the styles")
            return None
        if len(parts) == 2:  # /TOKEN -> /TOKEN/ so that relative addresses work
            self._send(301, b"", "text/plain", {"Location": f"/{self.server.token}/"})
            return None
        return parts[2]

    def _body(self) -> dict | None:
        origin = self.headers.get("Origin")
        if origin is not None and origin not in self.server.origins:
            self._error(403, "refused: a request from another site")
            return None
        if self.headers.get("Content-Type", "").split(";")[0].strip() != "application/json":
            self._error(415, "the request body must be JSON (Content-Type: application/json)")
            return None
        try:
            length = int(self.headers.get("Content-Length", ""))
        except ValueError:
            self._error(411, "the request needs a Content-Length")
            return None
        if not 0 <= length <= MAX_BODY:
            self._error(413, f"the request body is larger than {MAX_BODY} bytes")
            self.close_connection = True
            return None
        raw = self.rfile.read(length)
        try:
            data = json.loads(raw.decode("utf-8"), parse_constant=_refuse_constant)
        except (UnicodeDecodeError, ValueError) as exc:
            self._error(400, f"the request body is not valid JSON ({exc})"[:300])
            return None
        except RecursionError:  # thousands of nested brackets
            self._error(400, "the request body is nested too deeply")
            return None
        if not isinstance(data, dict):  # ``null`` went unanswered
            self._error(400, "the request body must be a JSON object")
            return None
        return data

    # -- methods -------------------------------------------------------------------------
    def do_HEAD(self) -> None:  # noqa: N802 - http.server's naming
        self.do_GET()

    def do_GET(self) -> None:  # noqa: N802
        route = self._route()
        if route is None:
            return
        studio = self.server.studio
        if route in _STATIC:
            name, content_type = _STATIC[route]
            self._send(200, _static(name), content_type)
        elif route == "photo.png":
            self._send(200, studio.photo_png, "image/png")
        elif route.startswith("style/") and route.endswith(".png") \
                and route[6:-4].isascii() and route[6:-4].isdigit():  # '²' is a digit too
            try:
                thumbnails = _source_of(studio, self._query()).thumbnails_png
            except RequestError as exc:
                self._error(400, str(exc))
                return
            if int(route[6:-4]) < len(thumbnails):
                self._send(200, thumbnails[int(route[6:-4])], "image/png")
            else:
                self._error(404, f"no such page: /{route}"[:200])
        elif route == "api/state":
            query = self._query()
            try:
                index = _source_index(query)
                data = (studio.state(index, query.get("palette") == "1")
                        if hasattr(studio, "choices") else studio.state())
            except RequestError as exc:
                self._error(400, str(exc))
                return
            except Exception as exc:  # a style source that cannot be read: one line
                text = str(exc).strip().splitlines()
                self._error(500, text[0] if text else type(exc).__name__)
                return
            self._json(200, data)
        else:
            self._error(404, f"no such page: /{route}"[:200])

    def _query(self) -> dict[str, str]:
        """The address's query (``?source=1&palette=1``): its last value of each name."""
        return dict(parse_qsl(urlsplit(self.path).query))

    def do_POST(self) -> None:  # noqa: N802
        route = self._route()
        if route is None:
            return
        data = self._body()
        if data is None:
            return
        explorer = self.server.studio
        try:
            studio, mode, index = _take_source(explorer, data)
            n_styles = studio.session.n_styles
            if route == "api/look" or (route in ("api/save", "api/export") and mode == "look"):
                strength = strength_from_json(data)
                blend = blend_from_json(data.get("blend"))
                if blend is not None:
                    if not hasattr(explorer, "choices"):
                        raise RequestError("there is no other look to blend with")
                    explorer.source(blend[0])  # RequestError when there is no such entry
                if route == "api/look":
                    self._lut(*(explorer.look(index, strength, blend) if blend is not None
                                else studio.look(strength)))
                elif route == "api/save":
                    self._json(200, explorer.save(index, "look", None, strength, blend))
                else:
                    fmt, size = data.get("format", "cube"), data.get("size", studio.sizes[0])
                    self._download(*(explorer.export_look(index, strength, blend, fmt, size)
                                     if blend is not None else
                                     studio.export_mode("look", None, strength, fmt, size)))
                return
            if route == "api/landscape":
                rows = data.get("rows") if isinstance(data, dict) else None
                if not isinstance(rows, list) or not 0 < len(rows) <= MAX_LANDSCAPE_ROWS:
                    raise RequestError(f"rows must be a list of 1 to {MAX_LANDSCAPE_ROWS} "
                                       "weight lists")
                self._json(200, studio.landscape([weights_from_json(r, n_styles)
                                                  for r in rows]))
                return
            settings = settings_from_json(data, n_styles)
            if route == "api/preview":
                client = data.get("client", "")
                seq = data.get("seq", 0)
                if not isinstance(client, str) or len(client) > 64 \
                        or isinstance(seq, bool) or not isinstance(seq, int):
                    raise RequestError("client must be a short string and seq an integer")
                self._lut(*studio.preview(settings, client, seq))
            elif route == "api/exact":
                self._lut(*studio.exact(settings))
            elif route == "api/slopes":
                self._lut(*studio.slopes(settings))
            elif route == "api/export":
                self._download(*studio.export_mode("palette", settings, settings.strength,
                                                   data.get("format", "cube"),
                                                   data.get("size", studio.sizes[0])))
            elif route == "api/save":
                self._json(200, explorer.save(index, "palette", settings, settings.strength))
            else:
                self._error(404, f"no such action: /{route}"[:200])
        except RequestError as exc:
            self._error(400, str(exc))
        except (Stale, Superseded):
            self._error(409, "superseded by a newer request", stale=True)
        except (JobError, TimeoutError) as exc:
            self._error(503, f"the grade could not be computed: {exc}")
        except (BrokenPipeError, ConnectionResetError):
            raise  # the page went away: nothing to answer
        except Exception as exc:  # the page shows one line; the server keeps serving
            traceback.print_exc()
            text = str(exc).strip().splitlines()
            self._error(500, text[0] if text else type(exc).__name__)


#: What a request's ``mode`` may be: the look grade (``apply``'s default) or a palette mix.
MODES = ("look", "palette")


def _source_index(query: dict[str, str]) -> int:
    """The ``source`` of an address's query (default 0) -> an index (RequestError)."""
    text = query.get("source", "0")
    if not (text.isascii() and text.isdigit()) or len(text) > 4:
        raise RequestError("source must be a small whole number")
    return int(text)


def _source_of(explorer, query: dict[str, str]):
    """The Studio a GET names with ``?source=N`` (the only one when there are no choices)."""
    if not hasattr(explorer, "choices"):
        return explorer
    return explorer.source(_source_index(query))


def _take_source(explorer, data) -> tuple:
    """Take ``source`` (default 0) and ``mode`` (default "palette", the routes of the
    weights) out of a request body -> (Studio, mode, index); RequestError when bad."""
    if not isinstance(data, dict):
        raise RequestError("the request body must be a JSON object")
    index = data.pop("source", 0)
    mode = data.pop("mode", "palette")
    if mode not in MODES:
        raise RequestError(f"mode must be one of {', '.join(MODES)}")
    if not hasattr(explorer, "choices"):
        if index != 0:
            raise RequestError("source must be 0")
        return explorer, mode, 0
    return explorer.source(index), mode, index


def _refuse_constant(name: str):
    """JSON's NaN and Infinity extensions are refused: weights must be finite numbers."""
    raise ValueError(f"{name} is not a number JSON allows")
