"""A small HTTP server on 127.0.0.1 in a background thread: fixed routes, no files served.

Each GET route is a function returning ``(content_type, body)``; each POST route takes the request
body and returns the same. Only the loopback address is bound, so nothing outside the machine
reaches it; and since a web page elsewhere can still make the user's browser send requests to
the loopback address, every request is checked (docs/cli.md, "Security"):

- ``Host`` must be this server's own address (``127.0.0.1:PORT`` or ``localhost:PORT``): a DNS
  rebinding page, whose own name resolves to 127.0.0.1, sends its own name and is refused;
- ``Origin``, when the browser sends one, must be this server's own origin, and
  ``Sec-Fetch-Site``, when sent, must say the request comes from the page itself or from the
  address bar;
- every GET carries the session's token (a random 256-bit value made when the server starts): in
  the address eelbot prints (``?token=``), or in the cookie the page sets from it;
- every POST carries the token in the ``X-Eelbot-Token`` header, which only the page's own script
  knows (and which another site could not send without a CORS preflight this server never grants).

The token reaches the page without the page's own code doing anything: every HTML page served
gets a ``<meta name="eelbot-token">`` and a small script that adds the header to the page's own
``fetch`` calls. A refused request gets 403 and a line in the log; no route runs.
"""

from __future__ import annotations

import hmac
import logging
import secrets
import threading
from collections.abc import Callable
from email.message import Message
from http.cookies import SimpleCookie
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs, urlsplit

from eelhost.errors import UserError

log = logging.getLogger(__name__)

__all__ = ["TOKEN_HEADER", "GetRoute", "LocalServer", "PostRoute", "WebServerError"]

GetRoute = Callable[[], tuple[str, bytes]]
PostRoute = Callable[[bytes], tuple[str, bytes]]
HOST = "127.0.0.1"
TOKEN_HEADER = "X-Eelbot-Token"
MAX_POST_BYTES = 1 << 20  # the pages post a few points or a command

# Added after <head> of every HTML page: the token, and the page's own fetch calls carrying it.
_TOKEN_SCRIPT = """<meta name="eelbot-token" content="{token}">
<script>(() => {{
  const token = "{token}", plain = window.fetch.bind(window);
  window.fetch = (resource, init = {{}}) => {{
    const url = new URL(resource instanceof Request ? resource.url : resource, location.href);
    if (url.origin !== location.origin) return plain(resource, init);
    const headers = new Headers(init.headers || {{}});
    headers.set("{header}", token);
    return plain(resource, {{...init, headers}});
  }};
}})();</script>
"""


class WebServerError(UserError, OSError):
    """The page's port cannot be opened (in use, not allowed)."""


class LocalServer:
    """Serve ``get`` and ``post`` routes on ``http://127.0.0.1:port/`` until :meth:`close`.

    Only requests from the user's own page pass (see the module docstring); :attr:`url` holds
    the session's token.

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
        self.token = secrets.token_urlsafe(32)
        server = self

        class Handler(BaseHTTPRequestHandler):
            def _refuse(self, why: str) -> None:
                log.warning("web page: refused %s %s: %s", self.command,
                            self.path.split("?", 1)[0], why)
                body = f"refused: {why}\n".encode()
                self.send_response(403)
                self.send_header("Content-Type", "text/plain; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def _reply(self, route: Callable[[], tuple[str, bytes]] | None,
                       cookie: str | None = None) -> None:
                if route is None:
                    self.send_error(404)
                    return
                content_type, body = route()
                if content_type.startswith("text/html"):
                    body = server._with_token(body)
                self.send_response(200)
                self.send_header("Content-Type", content_type)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.send_header("X-Frame-Options", "DENY")  # no framing by another page
                self.send_header("Referrer-Policy", "no-referrer")  # the token stays here
                if cookie:
                    self.send_header("Set-Cookie", cookie)
                self.end_headers()
                self.wfile.write(body)

            def do_GET(self) -> None:  # noqa: N802 (the name http.server calls)
                why = server._refusal(self.headers, "GET")
                query = parse_qs(urlsplit(self.path).query).get("token", [])
                by_query = bool(query) and server._is_token(query[0])
                if why is None and not (by_query or server._is_token(self._cookie())
                                        or server._is_token(self.headers.get(TOKEN_HEADER))):
                    why = "no session token (open the address eelbot printed)"
                if why is not None:
                    self._refuse(why)
                    return
                cookie = (f"{server._cookie_name}={server.token}; Path=/; HttpOnly; "
                          "SameSite=Strict") if by_query else None
                self._reply(routes_get.get(self.path.split("?", 1)[0]), cookie)

            def do_POST(self) -> None:  # noqa: N802
                why = server._refusal(self.headers, "POST")
                if why is None and not server._is_token(self.headers.get(TOKEN_HEADER)):
                    why = f"no {TOKEN_HEADER} header with the session token"
                length = int(self.headers.get("Content-Length") or 0)
                if why is None and not 0 <= length <= MAX_POST_BYTES:
                    why = f"a body of {length} bytes"
                if why is not None:
                    self._refuse(why)
                    return
                route = routes_post.get(self.path.split("?", 1)[0])
                body = self.rfile.read(length)
                self._reply(None if route is None else lambda: route(body))

            def _cookie(self) -> str | None:
                jar = SimpleCookie()
                try:
                    jar.load(self.headers.get("Cookie") or "")
                except Exception:  # noqa: BLE001 (a malformed cookie is simply no token)
                    return None
                morsel = jar.get(server._cookie_name)
                return None if morsel is None else morsel.value

            def log_message(self, format: str, *args: object) -> None:  # noqa: A002
                log.debug("%s " + format, self.address_string(), *args)

        try:
            self._httpd = ThreadingHTTPServer((HOST, port), Handler)
        except OSError as err:
            raise WebServerError(f"cannot serve on {HOST}:{port}: {err.strerror}") from None
        self.port = int(self._httpd.server_address[1])
        self._hosts = {f"{HOST}:{self.port}", f"localhost:{self.port}"}
        self._origins = {f"http://{h}" for h in self._hosts}
        self._cookie_name = f"eelbot_{self.port}"  # cookies are shared by every port of a host
        self._httpd.daemon_threads = True
        self._thread = threading.Thread(target=self._httpd.serve_forever, name="eelbot-web",
                                        daemon=True)
        self._thread.start()

    def _is_token(self, value: str | None) -> bool:
        return value is not None and hmac.compare_digest(value.encode(), self.token.encode())

    def _refusal(self, headers: Message, method: str) -> str | None:
        """Why a request's headers show it is not from this server's own page (None: they do)."""
        host = headers.get("Host")
        if host not in self._hosts:
            return f"Host {host!r} is not this server's (DNS rebinding?)"
        origin = headers.get("Origin")
        if origin is not None and origin not in self._origins:
            return f"Origin {origin!r} is another site's"
        site = headers.get("Sec-Fetch-Site")
        allowed = ("same-origin",) if method == "POST" else ("same-origin", "none")
        if site is not None and site not in allowed:
            return f"Sec-Fetch-Site {site!r}: sent by another site"
        return None

    def _with_token(self, page: bytes) -> bytes:
        script = _TOKEN_SCRIPT.format(token=self.token, header=TOKEN_HEADER).encode()
        head = page.find(b"<head>")
        if head < 0:
            return script + page
        return page[: head + 6] + script + page[head + 6:]

    @property
    def url(self) -> str:
        """The page's address, with the session's token."""
        return f"http://{HOST}:{self.port}/?token={self.token}"

    def close(self) -> None:
        """Stop serving and free the port."""
        self._httpd.shutdown()
        self._httpd.server_close()
        self._thread.join(timeout=5)
