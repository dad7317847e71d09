"""``eelbot run`` over ``sim://``: what a take records, overwriting, signals, the camera first."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from importlib import resources

import numpy as np
import pytest

from eelhost.cli import main
from eelhost.data.experiments import read_experiment
from eelhost.field.recorder import read_commands_csv
from eelhost.link.base import Link
from eelhost.vision.calibration import load_calibration

FAST = ["--link", "sim://?speed=0", "--camera", "synthetic:clean", "--gait", "0.87,3.9",
        "--no-view"]


def test_a_take_records_everything_a_dataset_needs(tmp_path, capsys):
    stem = tmp_path / "take1"
    assert main(["run", *FAST, "--waypoints", "1.4,0.02", "--duration", "3", "--note",
                 "water 21 C", "--out", str(stem)]) == 0
    exp = read_experiment(stem)
    assert exp.motion == "straight"  # one waypoint ahead of the start heading
    assert exp.scenario.duration_s == pytest.approx(3.0)  # how long it ran, not a default
    assert exp.camera["fps"] == pytest.approx(30.0) and exp.camera["fps_nominal"] == 30.0
    assert exp.camera["pixel_m"] == pytest.approx(0.0038, rel=0.01)
    run = exp.source["run"]
    # a waypoint run has no planner to give a feed-forward its current: the paper's pursuit
    assert exp.source["guidance"]["law"] == "pursuit"
    assert run["note"] == "water 21 C"
    assert run["gains"] == {"k_theta": 0.37}
    assert run["joints"]["model"] == "pd"
    assert (run["joints"]["kp_nm_per_rad"], run["joints"]["kd_nms_per_rad"]) == (0.08, 0.003)
    assert run["eelbot_version"] and len(run["git_commit"]) == 40
    assert run["date"][:4].isdigit() and "T" in run["date"]
    bundled = resources.files("eelsim.data").joinpath("paper_robot.toml").read_text()
    assert (tmp_path / "take1.robot.toml").read_text() == bundled
    assert load_calibration(tmp_path / "take1.calibration.json").method == "tank_corners"
    frames = (tmp_path / "take1.frames.csv").read_text().splitlines()
    assert frames[0] == "t_s,status,markers" and len(frames) - 1 == exp.camera["frames"] == 91
    assert exp.source["recording"]["complete"] is True


def test_an_existing_take_is_not_overwritten_without_force(tmp_path, capsys):
    stem = tmp_path / "t"
    args = ["run", *FAST, "--waypoints", "1.4,0", "--duration", "1", "--out", str(stem)]
    assert main(args) == 0
    before = (tmp_path / "t.csv").read_text()
    assert main(args) == 2
    assert "t.json exists (an earlier take)" in capsys.readouterr().err
    assert (tmp_path / "t.csv").read_text() == before
    assert main([*args, "--duration", "2", "--force"]) == 0
    assert read_experiment(stem).scenario.duration_s == pytest.approx(2.0)


def test_a_camera_that_does_not_open_fails_before_anything_is_sent(tmp_path, capsys, monkeypatch):
    sent = []
    real_send = Link.send
    monkeypatch.setattr(Link, "send", lambda self, msg, want_ack=False: sent.append(msg) or
                        real_send(self, msg, want_ack))
    cal = tmp_path / "cal.json"
    assert main(["calibrate", "--camera", "synthetic", "--calibration", str(cal)]) == 0
    assert main(["run", "--link", "sim://?speed=0", "--camera", "7", "--calibration", str(cal),
                 "--waypoints", "1,0", "--gait", "0.87,3.9", "--no-view",
                 "--out", str(tmp_path / "nocam")]) == 2
    assert "camera 7: cannot open" in capsys.readouterr().err
    assert sent == []  # no Start, no Stop
    assert not list(tmp_path.glob("nocam*"))


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.slow
def test_ctrl_c_sigterm_and_sighup_stop_the_robot_and_close_the_take(tmp_path, signum):
    stem = tmp_path / "sig"
    proc = subprocess.Popen(
        [sys.executable, "-m", "eelhost", "run", "--link", "sim://?speed=1", "--camera",
         "synthetic:clean", "--waypoints", "3,0", "--gait", "0.87,3.9", "--no-view", "--out",
         str(stem)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # Wait until the robot swims (frames recorded), then signal.
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            csv = tmp_path / "sig.csv"
            if csv.exists() and csv.read_text().count("\n") > 20:
                break
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.1)
        os.kill(proc.pid, signum)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "interrupted" in out
    meta = json.loads((tmp_path / "sig.json").read_text())
    rec = meta["source"]["recording"]
    assert rec["complete"] is True and rec["reason"] == "interrupted"
    assert rec["detail"] == f"{signal.Signals(signum).name} received"
    assert rec["stop"] == "ack"
    rows = read_commands_csv(tmp_path / "sig.commands.csv")
    stop = [r for r in rows if r["message"] == "Stop"]
    assert stop and stop[-1]["event"] == "ack"
    exp = read_experiment(stem)  # complete: read without --allow-incomplete
    assert np.all(np.diff(exp.t_s) > 0)


def test_the_current_is_recorded_when_known_and_a_sim_robot_takes_its_own(tmp_path, capsys):
    stem = tmp_path / "drift"
    assert main(["run", "--link", "sim://?speed=0&current=0.03,180", "--camera",
                 "synthetic:clean", "--gait", "0.87,3.9", "--no-view", "--waypoints", "1.4,0",
                 "--duration", "1", "--out", str(stem)]) == 0
    exp = read_experiment(stem)
    assert exp.scenario.current_speed_m_s == pytest.approx(0.03)
    assert exp.scenario.current_direction_deg == pytest.approx(180.0)
    assert exp.source["run"]["current_known"] is True
    assert main(["run", *FAST, "--waypoints", "1.4,0", "--current", "0.03,180",
                 "--out", str(tmp_path / "refused")]) == 2
    assert "--current: a sim:// robot's current is set in its URI" in capsys.readouterr().err
