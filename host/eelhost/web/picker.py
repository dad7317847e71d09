"""Click points in a frame on a local web page (``eelbot calibrate --click``).

:func:`pick_points` serves the frame at its natural size (one screen pixel per image pixel, so a
click is as precise as the eye) with numbered dots where it was clicked, an Undo and a Done button;
Done posts the points and the function returns them in image pixels (OpenCV's convention: pixel
(column c, row r) has its centre at (c, r)).
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable

import cv2
import numpy as np
from numpy.typing import NDArray

from eelhost.errors import UserError
from eelhost.web.server import LocalServer

__all__ = ["PickError", "pick_points"]


class PickError(UserError, ValueError):
    """Points that were not given (the page was left, too few clicks)."""


def pick_points(
    frame: NDArray[np.uint8],
    count: int,
    port: int = 0,
    announce: Callable[[str], None] = lambda _url: None,
    prompt: str = "click the tank's corners in order: origin, along +x, opposite, along +y",
    timeout_s: float | None = None,
) -> list[tuple[float, float]]:
    """Serve ``frame`` and wait until ``count`` points are clicked and Done is pressed.

    Parameters
    ----------
    frame : ndarray
        The image (grey or BGR).
    count : int
        How many points.
    port : int
        Port on 127.0.0.1 (0: any).
    announce : callable
        Told the page's address once it is served.
    prompt : str
        The instruction shown above the image.
    timeout_s : float, optional
        Give up after this long (None: wait).

    Returns
    -------
    list of (float, float)
        The points, in image pixels, in the order clicked.

    Raises
    ------
    PickError
        When the time runs out first.
    """
    ok, png = cv2.imencode(".png", frame)
    done = threading.Event()
    picked: list[tuple[float, float]] = []

    def receive(body: bytes) -> tuple[str, bytes]:
        try:
            points = [(float(u), float(v)) for u, v in json.loads(body)]
        except (ValueError, TypeError):
            return "application/json", b'{"ok": false, "error": "expected [[u, v], ...]"}'
        if len(points) != count:
            return "application/json", json.dumps(
                {"ok": False, "error": f"need {count} points, got {len(points)}"}).encode()
        picked[:] = points
        done.set()
        return "application/json", b'{"ok": true}'

    page = PAGE.replace("__COUNT__", str(count)).replace("__PROMPT__", prompt)
    server = LocalServer({"/": lambda: ("text/html; charset=utf-8", page.encode()),
                          "/frame.png": lambda: ("image/png", png.tobytes())},
                         {"/points": receive}, port=port)
    try:
        announce(server.url)
        if not done.wait(timeout_s):
            raise PickError(f"no {count} points were clicked within {timeout_s:g} s")
    finally:
        server.close()
    return list(picked)


PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>eelbot: click points</title>
<style>
 body { margin: 0; font: 14px sans-serif; background: #222; color: #eee; }
 #bar { padding: 6px 10px; position: sticky; top: 0; background: #222; }
 #wrap { position: relative; display: inline-block; }
 #frame { display: block; cursor: crosshair; }
 .dot { position: absolute; width: 9px; height: 9px; margin: -5px 0 0 -5px; border-radius: 50%;
        background: #ff00c8; border: 1px solid #fff; pointer-events: none; }
 .label { position: absolute; color: #ff00c8; font: bold 16px sans-serif; pointer-events: none; }
</style></head>
<body>
<div id="bar">__PROMPT__ (<span id="n">0</span>/__COUNT__)
 <button id="undo">Undo</button> <button id="done" disabled>Done</button> <span id="msg"></span></div>
<div id="wrap"><img id="frame" src="/frame.png" alt="frame"></div>
<script>
const want = __COUNT__, points = [];
const img = document.getElementById("frame"), wrap = document.getElementById("wrap");
function draw() {
  wrap.querySelectorAll(".dot,.label").forEach((e) => e.remove());
  points.forEach((p, i) => {
    const x = (p[0] + 0.5) * img.clientWidth / img.naturalWidth;
    const y = (p[1] + 0.5) * img.clientHeight / img.naturalHeight;
    const d = document.createElement("div"); d.className = "dot";
    d.style.left = x + "px"; d.style.top = y + "px"; wrap.appendChild(d);
    const l = document.createElement("div"); l.className = "label"; l.textContent = i + 1;
    l.style.left = (x + 6) + "px"; l.style.top = (y + 2) + "px"; wrap.appendChild(l);
  });
  document.getElementById("n").textContent = points.length;
  document.getElementById("done").disabled = points.length !== want;
}
img.addEventListener("click", (e) => {
  if (points.length >= want) return;
  // pixel centres at integers: the left edge of pixel 0 is -0.5
  points.push([e.offsetX * img.naturalWidth / img.clientWidth - 0.5,
               e.offsetY * img.naturalHeight / img.clientHeight - 0.5]);
  draw();
});
document.getElementById("undo").onclick = () => { points.pop(); draw(); };
document.getElementById("done").onclick = async () => {
  const r = await (await fetch("/points", {method: "POST", body: JSON.stringify(points)})).json();
  document.getElementById("msg").textContent = r.ok ? "sent: you can close this page" : r.error;
};
</script>
</body></html>
"""
