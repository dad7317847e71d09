"""The local web pages answer only their own page: forged requests are refused (docs/cli.md,
"Security"), and nothing they carry reaches a route."""

from __future__ import annotations

import http.client
import json
from urllib.parse import urlsplit

import numpy as np
import pytest

from eelhost.web import picker
from eelhost.web.server import TOKEN_HEADER, LocalServer


@pytest.fixture
def server():
    posted: list[bytes] = []

    def receive(body: bytes):
        posted.append(body)
        return "application/json", b'{"ok": true}'

    srv = LocalServer({"/": lambda: ("text/html; charset=utf-8", b"<html><head></head>page</html>"),
                       "/state.json": lambda: ("application/json", b"{}")},
                      {"/points": receive})
    srv.posted = posted
    yield srv
    srv.close()


def send(srv, method, path, headers=None, body=b"", host=None):
    conn = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=10)
    conn.putrequest(method, path, skip_host=True)
    conn.putheader("Host", host or f"127.0.0.1:{srv.port}")
    for k, v in (headers or {}).items():
        conn.putheader(k, v)
    conn.putheader("Content-Length", str(len(body)))
    conn.endheaders(body)
    resp = conn.getresponse()
    out = resp.status, resp.read(), dict(resp.getheaders())
    conn.close()
    return out


def test_the_page_opens_from_the_printed_address_and_holds_the_token(server):
    path = urlsplit(server.url)
    status, body, headers = send(server, "GET", f"{path.path}?{path.query}")
    assert status == 200 and server.token.encode() in body
    cookie = headers["Set-Cookie"]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    # the page's later requests carry the cookie
    status, _, _ = send(server, "GET", "/state.json", {"Cookie": cookie.split(";")[0]})
    assert status == 200


@pytest.mark.parametrize("forged", [
    {"host": "evil.example:80"},  # DNS rebinding: another name resolving to 127.0.0.1
    {"host": "127.0.0.1:1"},
    {"headers": {"Origin": "http://evil.example"}},
    {"headers": {"Origin": "null"}},
    {"headers": {"Sec-Fetch-Site": "cross-site"}},
    {"token": False},  # without the token
    {"token": "not-the-token"},
], ids=["host-rebinding", "host-other-port", "origin-other-site", "origin-null",
        "sec-fetch-cross-site", "token-missing", "token-wrong"])
def test_a_forged_get_is_refused_and_serves_nothing(server, forged):
    token = forged.get("token", server.token)
    path = "/state.json" + (f"?token={token}" if token else "")
    status, body, _ = send(server, "GET", path, forged.get("headers"), host=forged.get("host"))
    assert status == 403 and body.startswith(b"refused")


@pytest.mark.parametrize("forged", [
    {"headers": {"Origin": "http://evil.example", "Content-Type": "text/plain"}},
    {"host": "evil.example:8080"},
    {"headers": {"Sec-Fetch-Site": "same-site"}},
    {"token": None},  # the classic cross-site form post: no header
    {"token": "wrong"},
    {"token": None, "cookie": True},  # a cookie alone does not drive the page
    {"token": None, "query": True},  # nor the token in the address
], ids=["origin-other-site", "host-rebinding", "sec-fetch-same-site", "token-missing",
        "token-wrong", "cookie-only", "query-only"])
def test_a_forged_post_is_refused_and_reaches_no_route(server, forged):
    headers = dict(forged.get("headers", {}))
    token = forged.get("token", server.token)
    if token:
        headers[TOKEN_HEADER] = token
    if forged.get("cookie"):
        headers["Cookie"] = f"eelbot_{server.port}={server.token}"
    path = f"/points?token={server.token}" if forged.get("query") else "/points"
    status, _, _ = send(server, "POST", path, headers, b"[[1, 2]]", host=forged.get("host"))
    assert status == 403
    assert server.posted == []


def test_the_pages_own_post_with_the_token_is_taken(server):
    headers = {TOKEN_HEADER: server.token, "Origin": f"http://127.0.0.1:{server.port}",
               "Sec-Fetch-Site": "same-origin"}
    status, body, _ = send(server, "POST", "/points", headers, b"[[1, 2]]")
    assert status == 200 and json.loads(body)["ok"]
    assert server.posted == [b"[[1, 2]]"]


def test_a_cross_origin_post_cannot_set_the_corners_of_calibrate_click():
    """The attack of issue 31: a text/plain POST from another site set the four corners."""
    import threading

    seen: dict = {}
    ready = threading.Event()

    def announce(url):
        seen["url"] = url
        ready.set()

    def attack():
        ready.wait(10)
        port = urlsplit(seen["url"]).port
        srv = type("S", (), {"port": port})
        seen["status"] = send(srv, "POST", "/points",
                              {"Origin": "http://evil.example", "Content-Type": "text/plain"},
                              b"[[1,1],[2,2],[3,3],[4,4]]")[0]

    thread = threading.Thread(target=attack)
    thread.start()
    with pytest.raises(picker.PickError, match="no 4 points were clicked"):
        picker.pick_points(np.zeros((10, 10), np.uint8), 4, announce=announce, timeout_s=1.0)
    thread.join(10)
    assert seen["status"] == 403
