"""The live view's Stop button stops a real ``eelbot run``: the robot is sent Stop, the take closed.

A run of the virtual robot in real time with its live view; the button's request (a POST to
``/stop`` with the session token, what the page's script sends) ends it within a second or two,
as Ctrl-C would: reason ``interrupted``, Stop acknowledged, the record complete.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import urllib.request
from urllib.parse import parse_qs, urlsplit

import pytest

from eelhost.web.server import TOKEN_HEADER


@pytest.mark.slow
def test_the_stop_button_stops_the_robot_and_closes_the_take(tmp_path):
    stem = tmp_path / "take"
    proc = subprocess.Popen(
        [sys.executable, "-m", "eelhost", "--progress", "none", "run", "--link",
         "sim://?speed=1", "--camera", "synthetic:clean", "--waypoints", "1.4,0", "--gait",
         "0.87,3.9", "--duration", "60", "--view-port", "0", "--out", str(stem)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("live view: http://127.0.0.1:"), line + proc.stderr.read()
        url = line.split(": ", 1)[1].strip()
        token = parse_qs(urlsplit(url).query)["token"][0]
        time.sleep(2.0)  # the robot swims
        stop = urllib.request.Request(url.split("?")[0] + "stop", data=b"", method="POST",
                                      headers={TOKEN_HEADER: token})
        answer = json.loads(urllib.request.urlopen(stop, timeout=10).read())
        assert answer["stopping"] is True
        # no wall-time bound beyond the hang guard: on a loaded machine the exit took 17 s;
        # the robot's own clock at the stop (t_end_s below) shows the stop came at once
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, err  # a stop on purpose
    assert out.startswith("interrupted") or "\ninterrupted" in out, out
    assert "Stop ack" in out
    meta = json.loads(stem.with_suffix(".json").read_text())
    recording = meta["source"]["recording"]
    assert recording["complete"] is True and recording["reason"] == "interrupted"
    assert "live view" in recording["detail"] and recording["t_end_s"] < 30
