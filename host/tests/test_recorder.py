"""The recorder: incremental experiment files that survive a crash at any moment."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from eelhost.data.experiments import DataError, read_experiment
from eelhost.field.recorder import Recorder, read_commands_csv
from eelhost.link.base import LinkEvent
from eelhost.wire import protocol
from eelsim.scenario import load_scenario


def _record(tmp_path, frames: int) -> Recorder:
    rec = Recorder(tmp_path / "run", load_scenario("path1"), 6, camera={"fps": 30.0}, fsync=False)
    for k in range(frames):
        t = k / 30
        rec.frame(t, (0.1 * t, 0.02 * t), 0.01 * k, np.full(6, 0.01 * k))
    return rec


def test_recording_reads_back_as_an_experiment_with_its_outcome(tmp_path) -> None:
    rec = _record(tmp_path, 10)
    rec.command(0.5, LinkEvent(0.5, "sent", 4, protocol.SetOffset(0.125)))
    rec.command(0.6, LinkEvent(0.6, "refused", 4, protocol.SetOffset(0.125), "OUT_OF_RANGE"))
    rec.close({"reason": "arrived"})
    exp = read_experiment(tmp_path / "run")
    assert len(exp.t_s) == 10 and exp.link_angles_rad.shape == (10, 6)
    assert exp.motion == "path" and exp.source["recording"]["reason"] == "arrived"
    assert exp.source["recording"]["complete"] is True
    rows = read_commands_csv(tmp_path / "run.commands.csv")
    assert [r["event"] for r in rows] == ["sent", "refused:OUT_OF_RANGE"]
    assert rows[0]["fields"] == {"offset_rad": 0.125}


def test_half_written_last_line_is_dropped_and_every_complete_row_kept(tmp_path) -> None:
    rec = _record(tmp_path, 12)
    with open(tmp_path / "run.csv", "a") as f:
        f.write("0.4,0.04")  # the writer died mid-line
    with pytest.raises(DataError):
        read_experiment(tmp_path / "run")  # a finished file must end cleanly
    exp = read_experiment(tmp_path / "run", allow_truncated_tail=True)
    assert len(exp.t_s) == 12
    meta = json.loads((tmp_path / "run.json").read_text())
    assert meta["source"]["recording"]["complete"] is False
    rec.close()


def test_first_pose_becomes_the_recorded_start_pose(tmp_path) -> None:
    rec = Recorder(tmp_path / "s", load_scenario("path1"), 6, fsync=False)
    rec.frame(0.0, (0.25, -0.5), np.radians(30.0), np.zeros(6))
    meta = json.loads((tmp_path / "s.json").read_text())
    assert meta["scenario"]["start_position_m"] == [0.25, -0.5]
    assert meta["scenario"]["start_heading_deg"] == pytest.approx(30.0)
    rec.close()


def test_recorder_killed_mid_run_leaves_a_readable_experiment(tmp_path) -> None:
    stem = tmp_path / "killed"
    child = textwrap.dedent(
        f"""
        import os, signal
        from eelhost.link import open_link
        from eelhost.xil.virtual_robot import VirtualCamera
        from eelhost.field.recorder import Recorder
        from eelhost.field.runloop import RunConfig, RunLoop
        from eelhost.vision.localise import Localiser
        from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
        from eelsim.robot import load_robot
        from eelsim.scenario import load_scenario

        robot, sc = load_robot(), load_scenario("path1")
        link = open_link("sim://?speed=0", robot=robot)
        cam = SyntheticCamera(robot, options=RenderOptions(noise_sigma=0, jpeg_quality=0))

        def frames():
            for k, item in enumerate(VirtualCamera(link.transport.robot, cam)):
                if k == 40:
                    os.kill(os.getpid(), signal.SIGKILL)  # no cleanup of any kind
                yield item

        rec = Recorder({str(stem)!r}, sc, robot.n_links)
        RunLoop(link, frames(), Localiser(cam.calibration(), robot), robot,
                RunConfig(sc.gait, list(sc.waypoints_m)), rec).run()
        """
    )
    proc = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True)
    assert proc.returncode == -9, proc.stderr
    exp = read_experiment(stem, allow_truncated_tail=True)
    assert len(exp.t_s) == 40 and exp.t_s[-1] == pytest.approx(39 / 30)
    assert exp.source["recording"]["complete"] is False
    events = [r["message"] for r in read_commands_csv(f"{stem}.commands.csv")]
    assert "Start" in events and "SetOffset" in events
