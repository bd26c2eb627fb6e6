"""One .rrd file served over plain HTTP on 127.0.0.1, for the web viewer's `?url=http://...`.

The web viewer fetches the file once and holds it; the server then sleeps in accept() (a wake-up
every half second to see whether it should stop). Rerun's own `--serve-web FILE.rrd` streams the
file over gRPC instead, and its server polls the finished stream without pause: one core at ~100%
for as long as it serves (rerun-sdk 0.41.0).

Only the file's own path is served, and only to the web viewer's page: the CORS header names the
viewer's origin, so another page in the same browser cannot read the recording.
"""

from __future__ import annotations

import os
import shutil
import threading
import urllib.parse
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from twin.record.rerun.process import LOOPBACK, ViewerError

POLL_S = 0.5  # how often the idle server looks whether it should stop (socketserver's default)
CHUNK_BYTES = 1 << 20


class RrdServer(ThreadingHTTPServer):
    """Serves `rrd` at `url_path` to `origins`; `url` is the address the viewer fetches."""

    daemon_threads = True  # a transfer in flight does not hold up the stop

    def __init__(self, rrd: Path, port: int, origins: frozenset[str]):
        self.rrd = rrd
        self.url_path = "/" + urllib.parse.quote(rrd.name)
        self.origins = origins
        super().__init__((LOOPBACK, port), _Handler)

    @property
    def url(self) -> str:
        return f"http://{LOOPBACK}:{self.server_address[1]}{self.url_path}"

    def handle_error(self, request, client_address) -> None:
        """A browser that closes the connection mid-file (a reload, a closed tab) is no error to
        print."""


class _Handler(BaseHTTPRequestHandler):
    server: RrdServer

    def do_GET(self) -> None:
        self._answer(body=True)

    def do_HEAD(self) -> None:
        self._answer(body=False)

    def do_OPTIONS(self) -> None:
        self.send_response(HTTPStatus.NO_CONTENT)
        self._cors()
        self.send_header("Access-Control-Allow-Methods", "GET, HEAD")
        self.send_header("Content-Length", "0")
        self.end_headers()

    def _answer(self, *, body: bool) -> None:
        if urllib.parse.urlsplit(self.path).path != self.server.url_path:
            self.send_error(HTTPStatus.NOT_FOUND)
            return
        with open(self.server.rrd, "rb") as f:
            self.send_response(HTTPStatus.OK)
            self._cors()
            self.send_header("Content-Type", "application/octet-stream")
            self.send_header("Content-Length", str(os.fstat(f.fileno()).st_size))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            if body:
                shutil.copyfileobj(f, self.wfile, CHUNK_BYTES)

    def _cors(self) -> None:
        origin = self.headers.get("Origin")
        if origin in self.server.origins:
            self.send_header("Access-Control-Allow-Origin", origin)
            self.send_header("Vary", "Origin")

    def log_message(self, format, *args) -> None:
        """No line per request in the user's terminal."""


def serve_rrd(
    rrd: str | os.PathLike, port: int, viewer_port: int, *, option: str = "--grpc-port"
) -> RrdServer:
    """Serve `rrd` on 127.0.0.1:port (0: a free one) from a thread of this process, to the web
    viewer served on viewer_port; stop it with `stop_rrd`. ViewerError naming `option` if the port
    is taken."""
    origins = frozenset(f"http://{host}:{viewer_port}" for host in (LOOPBACK, "localhost"))
    try:
        server = RrdServer(Path(rrd), port, origins)
    except OSError as err:
        raise ViewerError(
            f"{option} {port}: {LOOPBACK}:{port} is already in use ({err.strerror}); "
            f"expected a free port, or 0 for any free one"
        ) from err
    threading.Thread(
        target=server.serve_forever, args=(POLL_S,), name="twin-rrd-http", daemon=True
    ).start()
    return server


def stop_rrd(server: RrdServer) -> None:
    """Stop serving and free the port."""
    server.shutdown()
    server.server_close()
