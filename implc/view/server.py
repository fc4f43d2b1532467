"""``implc view``'s local HTTP server: the viewer page and its chunks, to this machine only.

It binds 127.0.0.1, answers only requests with exactly one Host header naming that address (or localhost)
with its port (against DNS rebinding) and an origin-form target (``/TOKEN/...``, not
``http://host/...``), and only under a random token that starts every path, as Jupyter's does
(``http://127.0.0.1:PORT/TOKEN/``). A connection that sends nothing for :data:`READ_TIMEOUT` seconds is
closed, and so is one whose request (read and answered) takes more than :data:`REQUEST_SECONDS` in all (a
client sending a byte every few seconds holds no thread for ever), at most :data:`MAX_CONNECTIONS` are served
at once (others wait in the listen queue), and a client that hangs up early is forgotten without a traceback.
Its routes are the page's files, ``meta.json``, ``chunks/<level>-<i>-<j>-<k>.bin`` and
``sections/<axis>-<index>-<level>.bin`` (for a mesh, ``mesh.bin`` instead), all served from memory: no file
system path is ever read, anything else is 404 (a path with ``..`` or ``.`` segments, encoded or not,
included), a missing or wrong token 403, a foreign Host 403.

A live server (``implc view --watch``) is given new models while it serves (:meth:`ViewServer.replace`),
each a new *generation*, and a status line (:meth:`ViewServer.report`: building, or the last error). Its
page asks ``live.json?after=N``, answered as soon as the status has changed since revision N (or after
:data:`LIVE_WAIT` seconds), and names the generation it draws in each chunk request (``?generation=G``): a
request for an older one is answered 409, so a page never mixes two models.
"""

from __future__ import annotations

import contextlib
import re
import secrets
import socket
import sys
import threading
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs, unquote, urlsplit

from .json_text import json_bytes
from .lod_chunks import LodChunks
from .mesh_payload import MeshPayload
from .page import ASSET_TYPES, asset

DEFAULT_PORT = 8765
PORT_TRIES = 20
READ_TIMEOUT = 10.0
"""Seconds a connection may stay silent before it is closed (a slow client holds no thread for ever)."""
REQUEST_SECONDS = 60.0
"""Seconds one request may take in all, from its first byte to the last of the answer."""
MAX_CONNECTIONS = 32
"""Connections served at once; more wait until one ends."""
LISTEN_QUEUE = 128
"""Connections the kernel queues before they are accepted (socketserver's default is 5): a burst beyond
that, as a page fetching its chunks or many clients at once make, had each connection past the queue
wait for TCP's retransmission of its SYN, a second or more."""
CHUNK_PATH = re.compile(r"chunks/(\d{1,2})-(\d{1,7})-(\d{1,7})-(\d{1,7})\.bin")
SECTION_PATH = re.compile(r"sections/(\d)-(\d{1,7})-(\d{1,2})\.bin")
LIVE_WAIT = 25.0
"""Seconds a ``live.json`` request waits for news before it is answered with the status unchanged."""


@dataclass(frozen=True)
class _Model:
    """One generation of what is shown, swapped whole (a request reads one generation throughout)."""

    chunks: LodChunks | MeshPayload
    meta: bytes
    mesh: bytes | None
    generation: int


class ViewServer:
    """Serves one voxelization's (or one mesh's) viewer; ``url`` carries the token. ``port=None`` takes the first free
    port from :data:`DEFAULT_PORT` on, ``0`` any free port; a given port that is taken raises OSError."""

    def __init__(self, chunks: LodChunks | MeshPayload, *, port: int | None = None, budget: int = 1_000_000,
                 request_seconds: float = REQUEST_SECONDS, live: bool = False):
        self.token = secrets.token_urlsafe(24)
        self.request_seconds, self.budget, self.live = request_seconds, budget, live
        self._news = threading.Condition()
        self._revision, self._building, self._closed = 0, False, False
        self._error: str | None = None
        self._model = self._made(chunks, 0)
        self.assets = {name: asset(name) for name in ASSET_TYPES}
        handler = type("Handler", (_Handler,), {"owner": self})
        candidates = [port] if port is not None else [DEFAULT_PORT + i for i in range(PORT_TRIES)] + [0]
        for i, candidate in enumerate(candidates):
            try:
                self.httpd = _Server(("127.0.0.1", candidate), handler)
                break
            except OSError:
                if i == len(candidates) - 1:
                    raise
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self.hosts = {f"127.0.0.1:{self.port}", f"localhost:{self.port}"}
        self._thread: threading.Thread | None = None

    def _made(self, chunks: LodChunks | MeshPayload, generation: int) -> _Model:
        meta = chunks.meta(self.budget)
        if self.live:
            meta.update(live=True, generation=generation)
        body = chunks.body() if isinstance(chunks, MeshPayload) else None
        return _Model(chunks, json_bytes(meta), body, generation)

    @property
    def chunks(self) -> LodChunks | MeshPayload:
        return self._model.chunks

    @property
    def meta(self) -> bytes:
        return self._model.meta

    @property
    def generation(self) -> int:
        return self._model.generation

    def replace(self, chunks: LodChunks | MeshPayload):
        """Show ``chunks`` from now on (a new generation); clears the error and the building status."""
        model = self._made(chunks, self._model.generation + 1)  # the payload made before the swap
        with self._news:
            self._model, self._error, self._building = model, None, False
            self._revision += 1
            self._news.notify_all()

    def report(self, *, error: str | None = None, building: bool = False):
        """The status the page shows: building a new model, or the error that stopped the last one (the
        model shown stays)."""
        with self._news:
            self._error, self._building = error, building
            self._revision += 1
            self._news.notify_all()

    def live_state(self, after: int, wait: float = LIVE_WAIT) -> bytes:
        """The status as JSON once it is newer than revision ``after`` (or ``wait`` seconds have passed)."""
        with self._news:
            self._news.wait_for(lambda: self._revision > after or self._closed, timeout=wait)
            return json_bytes({"revision": self._revision, "generation": self._model.generation,
                               "error": self._error, "building": self._building})

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/{self.token}/"

    def serve_forever(self):
        """Serve until :meth:`close` (from another thread) or Ctrl-C in this one."""
        self.httpd.serve_forever(poll_interval=0.1)

    def start(self) -> ViewServer:
        """Serve from a daemon thread (notebooks, tests)."""
        self._thread = threading.Thread(target=self.serve_forever, name="implc-view-server", daemon=True)
        self._thread.start()
        return self

    def close(self):
        with self._news:  # a page's waiting live.json is answered now
            self._closed = True
            self._news.notify_all()
        if self._thread is not None:
            self.httpd.shutdown()
            self._thread.join()
            self._thread = None
        self.httpd.server_close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def resource(self, rest: str, query: dict | None = None) -> tuple[bytes, str] | HTTPStatus | None:
        """The body and content type of a route below the token, None (404), or CONFLICT for a request that
        names an older generation than the one shown."""
        query = query or {}
        if rest in ("", "index.html"):
            return self.assets["index.html"], ASSET_TYPES["index.html"]
        if rest in ASSET_TYPES:
            return self.assets[rest], ASSET_TYPES[rest]
        if rest == "live.json" and self.live:
            after = query.get("after", ["-1"])[-1]
            return self.live_state(int(after) if re.fullmatch(r"-?\d{1,12}", after) else -1), "application/json"
        model = self._model
        if "generation" in query and query["generation"][-1] != str(model.generation):
            return HTTPStatus.CONFLICT
        if rest == "meta.json":
            return model.meta, "application/json"
        if isinstance(model.chunks, MeshPayload):
            return (model.mesh, "application/octet-stream") if rest == "mesh.bin" and model.mesh is not None else None
        for pattern, make in ((CHUNK_PATH, model.chunks.chunk), (SECTION_PATH, model.chunks.section)):
            match = pattern.fullmatch(rest)
            if match:
                body = make(*map(int, match.groups()))
                return (body, "application/octet-stream") if body is not None else None
        return None


class _Server(ThreadingHTTPServer):
    """One thread per connection, at most :data:`MAX_CONNECTIONS` at once; a client's hang-up is not an
    error worth a traceback. The listen queue holds :data:`LISTEN_QUEUE` connections not yet accepted."""

    request_queue_size = LISTEN_QUEUE

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._slots = threading.BoundedSemaphore(MAX_CONNECTIONS)

    def process_request(self, request, client_address):
        self._slots.acquire()
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._slots.release()
            raise

    def process_request_thread(self, request, client_address):
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._slots.release()

    def handle_error(self, request, client_address):
        exc = sys.exc_info()[1]
        if isinstance(exc, (ConnectionError, TimeoutError, OSError)):
            return  # the client went away (or was too slow): nothing to report
        super().handle_error(request, client_address)


class _Handler(BaseHTTPRequestHandler):
    owner: ViewServer
    server_version = "implc-view"
    sys_version = ""
    protocol_version = "HTTP/1.1"
    timeout = READ_TIMEOUT  # the socket's timeout: a silent client's connection is closed

    def log_message(self, format, *args):  # noqa: A002 - the base class's name
        pass

    def handle_one_request(self):
        """One request, cut off (its connection shut) once it has taken :attr:`ViewServer.request_seconds`."""
        deadline = threading.Timer(self.owner.request_seconds, self._cut_off)
        deadline.daemon = True
        deadline.start()
        try:
            super().handle_one_request()
        finally:
            deadline.cancel()

    def _cut_off(self):
        self.close_connection = True
        with contextlib.suppress(OSError):
            self.connection.shutdown(socket.SHUT_RDWR)

    def _send(self, status: HTTPStatus, body: bytes, content_type: str = "text/plain; charset=utf-8"):
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Referrer-Policy", "no-referrer")
        self.send_header("Cache-Control", "no-store")
        self.send_header("Content-Security-Policy", "default-src 'self'; img-src 'self' data:; frame-ancestors 'none'")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def do_GET(self):
        owner = self.owner
        hosts = self.headers.get_all("Host") or []
        if len(hosts) != 1 or hosts[0] not in owner.hosts:
            return self._send(HTTPStatus.FORBIDDEN, b"this server answers only to 127.0.0.1\n")
        if not self.path.startswith("/") or self.path.startswith("//"):  # absolute, authority or scheme-relative
            return self._send(HTTPStatus.BAD_REQUEST, b"origin-form request targets only\n")
        target = urlsplit(self.path)
        path = unquote(target.path)
        segments = path.split("/")
        if any(s in (".", "..") for s in segments) or "\\" in path or "\x00" in path:
            return self._send(HTTPStatus.NOT_FOUND, b"not found\n")
        if len(segments) < 2 or not secrets.compare_digest(segments[1].encode(), owner.token.encode()):
            return self._send(HTTPStatus.FORBIDDEN, b"open the URL that 'implc view' printed: it carries a token\n")
        if len(segments) == 2:  # /TOKEN: the page is at /TOKEN/
            self.send_response(HTTPStatus.MOVED_PERMANENTLY)
            self.send_header("Location", f"/{owner.token}/")
            self.send_header("Content-Length", "0")
            self.end_headers()
            return None
        try:
            query = parse_qs(target.query, max_num_fields=8)
        except ValueError:
            return self._send(HTTPStatus.BAD_REQUEST, b"too many query fields\n")
        found = owner.resource("/".join(segments[2:]), query)
        if found is None:
            return self._send(HTTPStatus.NOT_FOUND, b"not found\n")
        if found is HTTPStatus.CONFLICT:
            return self._send(found, b"the model changed: this request names an older generation\n")
        return self._send(HTTPStatus.OK, *found)

    do_HEAD = do_GET
