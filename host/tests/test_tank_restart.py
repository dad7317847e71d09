"""A restart from rest (docs/planning.md, "A restart from rest"): pause, drift, replan, swim again."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from eelhost.field.recorder import read_commands_csv
from eelhost.field.runloop import RunConfig
from eelhost.field.session import TakeNotes
from eelhost.field.take import TakeRequest, run_take
from eelhost.planning.planner import Outcome, Planner
from eelhost.planning.replan import Decision, TankReplanner
from eelhost.planning.restart import backing_gait, drift, stopped_twin
from eelhost.planning.search import Plan
from eelhost.planning.uncertainty import default_model
from eelhost.planning.world import parse_world
from eelhost.vision.localise import Localisation
from eelsim.robot import load_robot
from eelsim.scenario import PATH_GAIT

ROBOT = load_robot()
MODEL = default_model(ROBOT)
N = ROBOT.n_links

OPEN = {
    "name": "open",
    "tank": {"size_m": [2.0, 2.0]},
    "start": {"position_m": [0.6, 1.0], "heading_deg": 0.0},
    "goal": {"position_m": [1.15, 1.0], "radius_m": 0.2},
    "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
    "obstacles": [{"kind": "circle", "centre_m": [1.4, 0.25], "radius_m": 0.1}],
}


def pose_at(t_s: float, com, heading: float = 0.0) -> Localisation:
    """A localisation of the straight body at ``com``."""
    theta = np.full(N, heading)
    return Localisation(t_s, "ok", np.asarray(com, float), heading, theta, np.zeros((N, 2)),
                        (True,) * N, (), 0.0, "")


class Blocked(TankReplanner):
    """A replanner whose every swimming replan is refused from its start (no continuation)."""

    def _replan(self, est, left, start_step, extra, guide=None,  # noqa: ANN001, ANN202
                deadline_s=None):  # noqa: ANN001
        plan = Plan(False, "blocked_start", "failed (blocked_start)")
        return (Outcome(plan, "blocked_start", plan.message), est.state, 0.0, 0.0, np.zeros(2),
                time.monotonic(), start_step)


@pytest.fixture(scope="module")
def open_plan():
    planner = Planner(parse_world(OPEN, "open"), ROBOT, MODEL)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    return planner, outcome


def test_a_robot_without_a_swimming_continuation_pauses_drifts_replans_from_rest_and_restarts(
        open_plan):
    planner, outcome = open_plan
    nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                  max_restarts=1)
    decisions: list[tuple[float, Decision]] = []
    try:
        # the body sits 0.4 m off the planned corridor (a replan at once, refused); after the
        # restart it is seen 0.8 m off the new plan's corridor (refused again)
        com = (0.8, 1.4)
        for k in range(int(12.0 * 30)):
            t = k / 30
            d = nav.on_frame(t, pose_at(t, com), np.array([*com, 0.0]), 0, 0.0)
            if d.restart:
                com = (0.8, 0.6)
            decisions.append((t, d))
            nav.pace(t)
            if d.stop is not None:
                break
            nav._worker.submit(lambda: None).result()  # the worker's jobs are done
            nav._side.submit(lambda: None).result()
    finally:
        nav.close()
    paused = [(t, d) for t, d in decisions if d.pause]
    restarted = [(t, d) for t, d in decisions if d.restart]
    assert paused[0][0] < 0.5  # the refused replan paused the robot at once: braked
    assert paused[0][1].pause_gait.amplitude_rad == pytest.approx(1.5)
    halt = next(e for e in nav.events if e["kind"] == "halt")
    # then once more: the brake's end (amplitude 0, the gait's omega) at its time, a whole gait
    # period on, and the restart only after the joints straightened
    assert len(paused) == 2 and paused[1][0] == pytest.approx(halt["brake_until_s"], abs=1 / 30)
    assert halt["brake_ended_s"] == pytest.approx(paused[1][0], abs=1e-3)  # on the halt's record
    assert halt["brake_until_s"] - halt["t_s"] == pytest.approx(
        2 * np.pi / PATH_GAIT.omega_rad_s * np.ceil(2.0 * PATH_GAIT.omega_rad_s / (2 * np.pi)),
        abs=2e-3)
    ended = paused[1][1].pause_gait
    assert ended.amplitude_rad < 1e-6 and ended.omega_rad_s == PATH_GAIT.omega_rad_s
    assert len(restarted) == 1
    t_restart, d = restarted[0]
    assert d.waypoints and d.waypoints[-1] == outcome.plan.waypoints_m[-1]  # the goal again
    assert t_restart >= paused[0][0] + nav.rest_settle_s + nav.rest_budget_s - 0.1
    assert t_restart >= halt["brake_until_s"] + nav.rest_settle_s - 1e-6
    # after the restart the swimming replan is refused again, and no restart is left
    t_end, last = decisions[-1]
    assert last.stop == "no_safe_continuation" and t_end > t_restart
    assert nav.restarts == 1
    kinds = [e["kind"] for e in nav.events]
    assert kinds.count("halt") == 1 and kinds.count("restart") == 1
    restart = next(e for e in nav.events if e["kind"] == "restart")
    assert halt["drift_gap_m"] > 0.1 and len(halt["start_state"]) == 2 * N + 4
    assert restart["status"] == "found" and restart["t_switch_s"] == pytest.approx(t_restart)
    assert restart["t_start_s"] <= restart["t_switch_s"] and restart["start_state"]
    assert nav.record()["restarts"] == 1


def test_a_drift_predicted_to_touch_ends_the_run_as_before(open_plan):
    # without the harbour (test_harbour.py's): the pause's drift touches, the run stops
    planner, outcome = open_plan
    nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                  max_restarts=2, harbour=False)
    try:
        stop = None
        for k in range(90):
            t = k / 30
            # the body swims 0.3 m/s towards the wall 0.1 m ahead of its nose
            x = 1.45 + 0.3 * t
            d = nav.on_frame(t, pose_at(t, (x, 1.0)), np.array([x, 1.0, 0.0]), 0, 0.0)
            nav.pace(t)
            if d.stop is not None:
                stop = d
                break
            nav._worker.submit(lambda: None).result()
            nav._side.submit(lambda: None).result()
    finally:
        nav.close()
    assert stop is not None and stop.stop == "no_safe_continuation"
    assert "restart 1 of 2 from rest" in stop.detail and "drifts the stopped body" in stop.detail
    assert nav.restarts == 0


def test_the_stopped_twin_coasts_slower_with_its_joints_straight(open_plan):
    planner, _ = open_plan
    twin = stopped_twin(planner.twin)
    state = np.zeros(2 * N + 4)
    state[N : N + 2] = (1.0, 1.0)
    state[N + 2 : 2 * N + 2] = 0.5 * np.sin(np.arange(N))  # bent joints moving
    state[2 * N + 2] = 0.15  # 0.15 m/s forward
    states = drift(twin, state, 6.0, 4.0)
    speed = np.hypot(states[:, 2 * N + 2], states[:, 2 * N + 3])
    assert np.all(np.diff(speed[::10]) < 0.0) and speed[-1] < 0.7 * speed[0]
    assert np.ptp(states[-1, :N]) < 0.05  # the links in line


class PauseThenRestart:
    """A navigator that pauses the gait at ``t_pause`` and restarts it at ``t_restart``."""

    replans = 0

    def __init__(self, t_pause: float, t_restart: float, waypoints) -> None:  # noqa: ANN001
        self.t_pause, self.t_restart, self.waypoints = t_pause, t_restart, waypoints
        self.state = "swimming"

    def on_frame(self, t_s, loc, pose, target, offset_rad, guide=None):  # noqa: ANN001, ANN201
        if self.state == "swimming" and t_s >= self.t_pause:
            self.state = "paused"
            return Decision(pause=True)
        if self.state == "paused" and t_s >= self.t_restart:
            self.state = "restarted"
            return Decision(waypoints=self.waypoints, restart=True)
        return Decision()

    def pace(self, t_s):  # noqa: ANN001, ANN201
        pass

    def close(self):  # noqa: ANN201
        pass

    def record(self):  # noqa: ANN201
        return {}


def test_the_watchdog_stays_fed_and_no_failsafe_fires_while_the_gait_is_paused(tmp_path):
    waypoints = [(1.5, 0.0), (2.5, 0.0)]
    # paused longer than the firmware's 1 s link timeout
    nav = PauseThenRestart(0.2, 1.4, waypoints)
    config = RunConfig(PATH_GAIT, waypoints, duration_s=1.6)
    stem = tmp_path / "pause"
    request = TakeRequest(ROBOT, config, str(stem), TakeNotes("sim://?speed=0"),
                          "synthetic:clean", navigator=nav)
    result = run_take(request)
    out = result.outcome
    assert out.reason == "duration" and out.failsafe_reports == 0
    sent = [r for r in read_commands_csv(f"{stem}.commands.csv") if r["event"] == "sent"]
    gaits = [(float(r["t_s"]), r["fields"]["amplitude_rad"]) for r in sent
             if r["message"] == "SetGait"]
    assert [a for _, a in gaits] == pytest.approx(
        [PATH_GAIT.amplitude_rad, 0.0, PATH_GAIT.amplitude_rad])
    t_pause, t_restart = gaits[1][0], gaits[2][0]
    assert 0.2 <= t_pause < 0.3 and 1.4 <= t_restart < 1.5
    offsets = [(float(r["t_s"]), r["fields"]["offset_rad"]) for r in sent
               if r["message"] == "SetOffset"]
    during = [(t, o) for t, o in offsets if t_pause <= t < t_restart]
    assert all(o == 0.0 for _, o in during)
    times = [t for t, _ in during]
    assert len(times) >= 4 and np.diff(times).max() < 0.35  # the watchdog (1 s) is fed
    assert not any(r["message"] in ("Stop", "Start") for r in sent
                   if t_pause <= float(r["t_s"]) < t_restart)


class FirstRestFails(Blocked):
    """A :class:`Blocked` replanner whose first replan from rest finds nothing."""

    rest_calls = 0

    def _rest_replan(self, est, start_step, extra, deadline_s, recheck=False,  # noqa: ANN001, ANN202
                     pause=None):  # noqa: ANN001
        self.rest_calls += 1
        if self.rest_calls == 1:
            plan = Plan(False, "exhausted", "search exhausted after 1 expansions")
            return (Outcome(plan, "exhausted", plan.message), est.state, 0.0, 0.0, np.zeros(2),
                    time.monotonic(), start_step)
        return super()._rest_replan(est, start_step, extra, deadline_s, recheck, pause)


def test_a_failed_replan_from_rest_is_tried_again_later_in_the_pause(open_plan):
    planner, outcome = open_plan
    nav = FirstRestFails(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                         max_restarts=1, rest_tries=2)
    restarted = None
    try:
        com = (0.8, 1.4)  # 0.4 m off the corridor: a replan at once, refused
        for k in range(int(14.0 * 30)):
            t = k / 30
            d = nav.on_frame(t, pose_at(t, com), np.array([*com, 0.0]), 0, 0.0)
            nav.pace(t)
            assert d.stop is None, d.detail
            if d.restart:
                restarted = t
                break
            nav._worker.submit(lambda: None).result()
            nav._side.submit(lambda: None).result()
    finally:
        nav.close()
    assert restarted is not None and nav.restarts == 1 and nav.rest_calls == 2
    tries = [e for e in nav.events if e["kind"] == "restart"]
    assert [e["status"] for e in tries] == ["exhausted", "found"]
    assert [e["try"] for e in tries] == [1, 2]
    assert tries[1]["t_request_s"] >= tries[0]["t_ready_s"] + nav.rest_retry_s - 0.05


class LateRest(Blocked):
    """A :class:`Blocked` replanner whose replan from rest does not come back until released."""

    def __init__(self, *args, **kwargs) -> None:  # noqa: ANN002, ANN003
        super().__init__(*args, **kwargs)
        self.release = threading.Event()

    def _rest_replan(self, est, start_step, extra, deadline_s, recheck=False,  # noqa: ANN001, ANN202
                     pause=None):  # noqa: ANN001
        self.release.wait(10.0)
        plan = Plan(False, "out_of_time", "the search ran out of time")
        return (Outcome(plan, "out_of_time", plan.message), est.state, 0.0, 0.0, np.zeros(2),
                time.monotonic(), start_step)


def test_a_replan_from_rest_not_back_by_its_start_ends_the_pause(open_plan):
    planner, outcome = open_plan
    nav = LateRest(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                   max_restarts=1, rest_budget_s=0.5, rest_budget_max_s=0.5)
    stop = None
    try:
        com = (0.8, 1.4)
        for k in range(int(10.0 * 30)):
            t = k / 30
            d = nav.on_frame(t, pose_at(t, com), np.array([*com, 0.0]), 0, 0.0)
            nav.pace(t)
            if d.stop is not None:
                stop = (t, d)
                break
            nav._side.submit(lambda: None).result()
    finally:
        nav.release.set()
        nav.close()
    assert stop is not None
    t_stop, d = stop
    assert d.stop == "no_safe_continuation" and "was not back" in d.detail
    halt = next(e for e in nav.events if e["kind"] == "halt")
    # the paused robot waits no longer than the plan could be used: its start and the lead
    start = max(halt["t_s"] + halt["rest_budget_s"], halt["brake_until_s"]) + nav.rest_settle_s
    period = planner.twin.restart_steps * planner.twin.dt_s  # restarts keep the loop's cadence
    assert t_stop <= np.ceil(start / period) * period + nav.max_lead_s + 0.1


def test_the_reversed_wave_brakes_the_coasting_body(open_plan):
    planner, _ = open_plan
    state = np.zeros(2 * N + 4)
    state[N : N + 2] = (1.0, 1.0)
    state[2 * N + 2] = 0.15  # 0.15 m/s forward, straight
    coasting = drift(stopped_twin(planner.twin), state, 6.0, 3.0)
    backing = drift(stopped_twin(planner.twin, backing_gait(PATH_GAIT, 0.87)), state, 6.0, 3.0)
    assert backing_gait(PATH_GAIT, 0.87).beta_rad == -PATH_GAIT.beta_rad
    assert backing[-1, N] - 1.0 < 0.5 * (coasting[-1, N] - 1.0)  # it glides less than half as far
