"""``eelbot run`` against the virtual robot: native firmware + twin behind the link, synthetic camera.

The camera is the synthetic one without noise and JPEG (blur only) to keep the tests quick; the
clock runs as fast as the computer can (``speed=0``), so nothing here sleeps.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eelhost.data.experiments import read_experiment
from eelhost.estimation.fitness import N_SAMPLES_VALIDATE, sample_times, validation_errors
from eelhost.field.recorder import Recorder, read_commands_csv
from eelhost.field.runloop import RunConfig, RunLoop, RunOutcome
from eelhost.link import open_link
from eelhost.vision.localise import Localiser
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
from eelhost.wire import protocol
from eelhost.xil.virtual_robot import VirtualCamera
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.control import Gait
from eelsim.robot import BUNDLED_ROBOTS, load_robot
from eelsim.scenario import load_scenario

ROBOT = load_robot()
PATH1 = load_scenario("path1")
BUNDLED = Path(__file__).resolve().parents[2] / "datasets" / "paper_virtual_tank"


def virtual_run(uri: str, waypoints, stem, duration_s: float | None = None, robot=ROBOT,
                scenario=PATH1):
    """Run the host loop against the virtual robot with the scenario's gait; return (outcome, link)."""
    link = open_link(uri, robot=robot)
    cam = SyntheticCamera(robot, options=RenderOptions(noise_sigma=0.0, jpeg_quality=0))
    frames = VirtualCamera(link.transport.robot, cam, keep_truth=False)
    config = RunConfig(scenario.gait, list(waypoints), duration_s=duration_s)
    rec = Recorder(stem, scenario.model_copy(update={"waypoints_m": list(waypoints)}),
                   robot.n_links)
    out: RunOutcome = RunLoop(link, frames, Localiser(cam.calibration(), robot), robot, config,
                              rec).run()
    return out, link


@pytest.mark.parametrize("robot_file", BUNDLED_ROBOTS)
@pytest.mark.slow
def test_virtual_path1_reaches_every_waypoint_and_matches_the_twin(tmp_path, robot_file) -> None:
    # the paper's PD joints, and hobby servos whose references are the firmware's commanded angles
    robot = load_robot(robot_file)
    out, link = virtual_run("sim://?speed=0&seed=0", PATH1.waypoints_m, tmp_path / "path1",
                            robot=robot)
    assert out.reason == "arrived" and out.waypoints_reached == 3
    assert out.stop_outcome == "ack"
    assert link.transport.robot.status()["state"] == protocol.State.IDLE
    exp = read_experiment(tmp_path / "path1")
    assert exp.source["recording"]["complete"] is True
    # The twin runs the recorded task from the recorded start pose.
    sc = exp.scenario.model_copy(update={"duration_s": exp.t_s[-1] + 0.1})
    twin = simulate_closed_loop(robot, sc, LoopOptions(stop_at_goal=False))
    n = robot.n_links
    ts = sample_times(exp.t_s[0], exp.t_s[-1], N_SAMPLES_VALIDATE)
    sim = np.c_[np.interp(ts, twin.t_s, twin.states[:, n]),
                np.interp(ts, twin.t_s, twin.states[:, n + 1])]
    err = validation_errors(ts, exp.position_at(ts), sim, robot.body_length_m())
    assert err["Ex_mean_BL"] < 0.03
    sent = [r for r in read_commands_csv(tmp_path / "path1.commands.csv") if r["event"] == "sent"]
    assert sum(r["message"] == "SetOffset" for r in sent) == out.offsets_sent + 1  # + the initial 0
    assert sent[-1]["message"] == "Stop"


def test_a_bundled_turning_take_rerun_over_sim_in_its_water_follows_the_recorded_track(
    tmp_path,
) -> None:
    # The bundled turning takes were recorded with table 3's turning row as the water (their
    # source.truth, datasets/README.md); the virtual robot swims in the robot file's water (the
    # straight row) unless coefficients= says otherwise. In the take's own water it retraces the
    # recorded track to 0.3 cm over 4 s (camera quantisation); in the straight row it parts by
    # 2.5 cm by then and by 11 cm at 10 s (docs/host.md, "The virtual robot and replays").
    take = read_experiment(BUNDLED / "turning_A0.61_w2.7")
    truth = [take.source["truth"][name] for name in type(ROBOT.hydrodynamics).names()]
    sc = take.scenario
    out, link = virtual_run(f"sim://?speed=0&coefficients={','.join(map(repr, truth))}",
                            sc.waypoints_m, tmp_path / "turning", duration_s=4.0, scenario=sc)
    assert out.reason == "duration"
    assert list(link.transport.robot.robot.hydrodynamics.as_array()) == truth
    rerun = read_experiment(tmp_path / "turning")
    ts = rerun.t_s[rerun.t_s <= 4.0]
    apart = np.linalg.norm(rerun.position_at(ts) - take.position_at(ts), axis=1)
    assert apart.max() < 0.01
    assert rerun.position_at(ts[-1:])[0, 0] > 0.0  # it has got going (it backs up at first)


def test_robot_leaving_the_view_is_stopped(tmp_path) -> None:
    # Starts near the tank's +x edge (3.1 m) and swims out of the picture.
    out, link = virtual_run("sim://?speed=0&start=2.75,0,0", [(4.5, 0.0)], tmp_path / "away",
                            duration_s=20.0)
    assert out.reason == "lost_from_view"
    assert out.stop_outcome == "ack"
    assert link.transport.robot.status()["state"] == protocol.State.IDLE
    exp = read_experiment(tmp_path / "away")
    assert out.t_end_s - exp.t_s[-1] == pytest.approx(1.0, abs=0.05)


def test_short_link_drop_is_ridden_through_by_reconnecting(tmp_path) -> None:
    out, link = virtual_run("sim://?speed=0&drop=1.5:2.0", [(3.0, 0.0)], tmp_path / "blip",
                            duration_s=4.0)
    assert out.reason == "duration"
    assert (link.counters.disconnects, link.counters.reconnects) == (1, 1)
    assert link.counters.not_sent > 0
    kinds = [e.kind for e in out.events]
    assert "disconnected" in kinds and "reconnected" in kinds
    assert out.stop_outcome == "ack"


def test_long_link_drop_stops_the_run_and_the_robot(tmp_path) -> None:
    out, link = virtual_run("sim://?speed=0&drop=1.5:3.0", [(3.0, 0.0)], tmp_path / "drop",
                            duration_s=10.0)
    assert out.reason == "link_lost"
    assert 2.4 < out.t_end_s < 2.7  # the last telemetry before the drop + 1 s
    # The robot's own watchdog stopped it meanwhile; the Stop lands once the link is back.
    assert out.stop_outcome == "ack"
    assert link.transport.robot.status()["state"] == protocol.State.IDLE
    rows = read_commands_csv(tmp_path / "drop.commands.csv")
    assert rows[-1]["message"] == "Stop" and rows[-1]["event"] == "ack"


def test_stop_request_ends_the_run_with_a_stop(tmp_path) -> None:
    link = open_link("sim://?speed=0", robot=ROBOT)
    cam = SyntheticCamera(ROBOT, options=RenderOptions(noise_sigma=0.0, jpeg_quality=0))
    loop = RunLoop(link, VirtualCamera(link.transport.robot, cam), Localiser(cam.calibration(), ROBOT),
                   ROBOT, RunConfig(Gait(0.87, 3.9, 1.04, 0.37), [(3.0, 0.0)]))

    def frames():
        for k, item in enumerate(VirtualCamera(link.transport.robot, cam)):
            if k == 15:
                loop.request_stop()  # what the Ctrl-C handler of eelbot run does
            yield item

    loop.frames = frames()
    out = loop.run()
    assert out.reason == "interrupted" and out.frames == 16 and out.stop_outcome == "ack"
