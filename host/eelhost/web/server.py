"""A small HTTP server on 127.0.0.1 in a background thread: fixed routes, no files served.

Each GET route is a function returning ``(content_type, body)``; each POST route takes the request
body and returns the same. Only the loopback address is bound, so nothing outside the machine
reaches it.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from eelhost.errors import UserError

log = logging.getLogger(__name__)

__all__ = ["GetRoute", "LocalServer", "PostRoute", "WebServerError"]

GetRoute = Callable[[], tuple[str, bytes]]
PostRoute = Callable[[bytes], tuple[str, bytes]]
HOST = "127.0.0.1"


class WebServerError(UserError, OSError):
    """The page's port cannot be opened (in use, not allowed)."""


class LocalServer:
    """Serve ``get`` and ``post`` routes on ``http://127.0.0.1:port/`` until :meth:`close`.

    Parameters
    ----------
    get : dict of path to callable
        ``"/"`` and the like, each returning (content type, body).
    post : dict of path to callable, optional
        Each taking the body and returning (content type, body).
    port : int
        0 picks a free port.
    """

    def __init__(self, get: dict[str, GetRoute], post: dict[str, PostRoute] | None = None,
                 port: int = 0) -> None:
        routes_get, routes_post = dict(get), dict(post or {})

        class Handler(BaseHTTPRequestHandler):
            def _reply(self, route: Callable[[], tuple[str, bytes]] | None) -> None:
                if route is None:
                    self.send_error(404)
                    return
                content_type, body = route()
                self.send_response(200)
                self.send_header("Content-Type", content_type)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.write(body)

            def do_GET(self) -> None:  # noqa: N802 (the name http.server calls)
                self._reply(routes_get.get(self.path.split("?", 1)[0]))

            def do_POST(self) -> None:  # noqa: N802
                route = routes_post.get(self.path.split("?", 1)[0])
                length = int(self.headers.get("Content-Length") or 0)
                body = self.rfile.read(length)
                self._reply(None if route is None else lambda: route(body))

            def log_message(self, format: str, *args: object) -> None:  # noqa: A002
                log.debug("%s " + format, self.address_string(), *args)

        try:
            self._httpd = ThreadingHTTPServer((HOST, port), Handler)
        except OSError as err:
            raise WebServerError(f"cannot serve on {HOST}:{port}: {err.strerror}") from None
        self._httpd.daemon_threads = True
        self._thread = threading.Thread(target=self._httpd.serve_forever, name="eelbot-web",
                                        daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """The page's address."""
        return f"http://{HOST}:{self._httpd.server_address[1]}/"

    def close(self) -> None:
        """Stop serving and free the port."""
        self._httpd.shutdown()
        self._httpd.server_close()
        self._thread.join(timeout=5)
