"""The brake before the final Stop: over ``sim://`` in lockstep, the firmware in the loop."""

from __future__ import annotations

import numpy as np
import pytest

from eelhost.field.recorder import Recorder, read_commands_csv
from eelhost.field.runloop import RunConfig, RunLoop
from eelhost.link import open_link
from eelhost.vision.localise import Localiser
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
from eelhost.wire import protocol
from eelhost.xil.virtual_robot import DT_US, VirtualCamera
from eelsim.control import Gait
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

ROBOT = load_robot()
GAIT = Gait(0.87, 3.9, 1.04, 0.37)


def test_a_braked_robot_is_nearly_still_at_its_stop_and_never_fails_safe(tmp_path):
    # 4 s of swimming, then the brake for 1.2 s (longer than the link's 1 s watchdog) and Stop
    link = open_link("sim://?speed=0&seed=3", robot=ROBOT)
    robot = link.transport.robot
    robot.trace = []
    cam = SyntheticCamera(ROBOT, options=RenderOptions(noise_sigma=0.0, jpeg_quality=0))
    config = RunConfig(GAIT, [(3.0, 0.0)], duration_s=4.0, brake_s=1.2)
    rec = Recorder(tmp_path / "brake", load_scenario("path1").model_copy(
        update={"waypoints_m": [(3.0, 0.0)]}), ROBOT.n_links)
    out = RunLoop(link, VirtualCamera(robot, cam, keep_truth=False),
                  Localiser(cam.calibration(), ROBOT), ROBOT, config, rec).run()
    assert out.reason == "duration" and out.braked_s == pytest.approx(1.2, abs=0.05)
    assert out.failsafe_reports == 0 and out.stop_outcome == "ack"
    assert out.braked_s <= out.stopping_s < out.braked_s + 0.2  # the brake, then Stop's answer
    assert robot.status()["state"] == protocol.State.IDLE
    events = read_commands_csv(tmp_path / "brake.commands.csv")
    assert not [r for r in events if r["event"].startswith("refused")]  # omega 0, A 1.5: taken
    rows = [r for r in events if r["event"] == "sent"]
    brake = max(i for i, r in enumerate(rows) if r["message"] == "SetGait")
    assert rows[-1]["message"] == "Stop"
    assert [r["message"] for r in rows[brake + 1 : -1]] == ["SetOffset"] * 4  # every 0.3 s
    # the plant's speed: swimming when the brake began, nearly still at the Stop, and the body
    # coasts a few centimetres after it where a straight one glides on
    n, step_s = ROBOT.n_links, DT_US * 1e-6
    stop = len(robot.trace) - 1
    robot.advance_to(robot.now_us + 4_000_000)
    states = np.asarray(robot.trace)
    speed = np.hypot(states[:, 2 * n + 2], states[:, 2 * n + 3])
    began = stop - round(out.braked_s / step_s)
    assert speed[began] > 0.05 and speed[stop] < 0.3 * speed[began]
    assert np.hypot(*(states[-1, n : n + 2] - states[stop, n : n + 2])) < 0.05

