"""``eelbot run --plan`` at the (virtual) tank: planning beside the loop, body state, contact, record.

Over ``sim://`` at ``speed=0`` the virtual robot runs as fast as it can except while a replan is
running: then the planner's wall time passes on the robot's clock (``TankReplanner.pace``), so a
planner slower than the robot's watchdog is a real stall here, as it would be at the tank.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from concurrent.futures import Future

import numpy as np
import pytest

from eelhost.cli import main
from eelhost.commands.run import exit_status
from eelhost.errors import EXIT_CONTACT
from eelhost.field.recorder import read_commands_csv
from eelhost.field.runloop import RunConfig
from eelhost.field.session import TakeNotes
from eelhost.field.take import TakeRequest, run_take
from eelhost.planning.deadline import Deadline
from eelhost.planning.execute import body_clearance_m
from eelhost.planning.field import ClearanceField
from eelhost.planning.geometry import FloatArray
from eelhost.planning.planner import PLANNING_GUIDANCE, Outcome, Planner
from eelhost.planning.replan import (
    CALM_REPLAN_BUDGET_S,
    ESCAPE_FLOOR_M,
    ESCAPE_RAMP_S,
    STOP_ALLOWANCE_S,
    Ahead,
    Decision,
    TankReplanner,
    current_spread_m_s,
    escape_margin_m,
    outline_clearance_m,
    predict_state,
)
from eelhost.planning.search import Leg, Plan
from eelhost.planning.state_estimate import BodyStateEstimator, CurrentWindow
from eelhost.planning.tank import plan_for_run, replan_planners, with_extra_current
from eelhost.planning.uncertainty import default_model, read_coefficient_model
from eelhost.planning.world import parse_world
from eelhost.vision.localise import Localisation
from eelhost.vision.synthetic import TankView
from eelhost.wire import protocol
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.guidance import PURSUIT, Guidance, GuidanceLaw
from eelsim.model import SwimmerModel
from eelsim.robot import load_robot
from eelsim.scenario import PATH_GAIT, Scenario

ROBOT = load_robot()
MODEL = default_model(ROBOT)
N = ROBOT.n_links
BODY = SwimmerModel.from_robot(ROBOT, MODEL.fits["straight"])

OPEN = {
    "name": "open",
    "tank": {"size_m": [3.0, 2.0]},
    "start": {"position_m": [0.6, 1.0], "heading_deg": 0.0},
    "goal": {"position_m": [2.1, 1.0], "radius_m": 0.2},
    "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
    "obstacles": [{"kind": "circle", "centre_m": [1.4, 0.25], "radius_m": 0.1}],
}


def offsets_by_hand(frames: np.ndarray, sent: list[dict], waypoints: list, law: GuidanceLaw,
                    start: tuple[float, float] | None = None, offset_limit_rad: float = 1.0,
                    ) -> list[float]:
    """The offsets ``law`` gives for a take's measured poses at each SetOffset's time.

    ``frames``: the take's (t, x, y, theta) rows; ``sent``: its SetOffset commands; the guidance
    from ``start`` (default the first pose seen) over ``waypoints``.
    """
    g = Guidance(waypoints, 0.15, PATH_GAIT.k_theta, 5, offset_limit_rad=offset_limit_rad,
                 law=law, leg_start_m=start)
    out, f = [], 0
    for r in sent:
        while f < len(frames) and frames[f][0] <= r["t_s"] + 1e-4:
            g.observe(*(float(v) for v in frames[f]))
            f += 1
        out.append(g.offset())
    return out


def swimming_state(t_s: float = 6.0):
    """A state of the robot swimming a path: bent, moving, mid-stroke; and its run."""
    sc = Scenario.swimming(PATH_GAIT, name="swim", waypoints_m=[(2.5, 1.3)], duration_s=t_s + 0.5,
                           start_position_m=(0.6, 1.0), start_heading_deg=0.0)
    run = simulate_closed_loop(ROBOT, sc, LoopOptions(stop_at_goal=False))
    return run


def test_estimator_recovers_the_whole_body_state_of_a_swimming_robot_from_camera_poses():
    run = swimming_state()
    est = BodyStateEstimator(BODY, PATH_GAIT)
    frames = np.arange(0.0, 6.0 + 1e-9, 1 / 30)
    for t in frames:
        x = np.array([np.interp(t, run.t_s, run.states[:, i]) for i in range(run.states.shape[1])])
        est.observe(t, x[N : N + 2], x[:N])
    e = est.estimate()
    assert e is not None and e.t_s == pytest.approx(6.0)
    k = int(np.argmin(np.abs(run.t_s - 6.0)))
    truth = run.states[k]
    body = truth[:N] - truth[:N].mean()
    assert np.ptp(body) > 0.2  # the body is bent
    assert np.hypot(*truth[2 * N + 2 :]) > 0.03  # and moving
    assert np.allclose(e.state[: N + 2], truth[: N + 2], atol=2e-3)  # pose and shape as seen
    assert np.abs(e.state[N + 2 : 2 * N + 2] - truth[N + 2 : 2 * N + 2]).max() < 0.15  # rad/s
    assert np.abs(e.state[2 * N + 2 :] - truth[2 * N + 2 :]).max() < 0.01  # m/s


def test_a_replan_starts_from_the_moving_bent_body_the_twin_predicts():
    world = parse_world(OPEN, "open")
    planner = Planner(world, ROBOT, MODEL)
    run = swimming_state(4.5)
    est = BodyStateEstimator(planner.model, PATH_GAIT)
    for t in np.arange(0.0, 4.5 + 1e-9, 1 / 30):
        x = np.array([np.interp(t, run.t_s, run.states[:, i]) for i in range(run.states.shape[1])])
        est.observe(t, x[N : N + 2], x[:N])
    e = est.estimate()
    assert e is not None
    step = 180  # 1.8 s after the estimate, a restart point (0.3 s periods)
    start = predict_state(planner.twin, e, [(2.5, 1.3)], int(round(4.5 / 0.01)) + step)
    assert start is not None
    assert np.ptp(start[:N] - start[:N].mean()) > 0.1 and np.hypot(*start[2 * N + 2 :]) > 0.03
    outcome = planner.plan(start, int(round(4.5 / 0.01)) + step)
    assert outcome.found, outcome.message
    first = outcome.plan.legs[0].com_m[0]
    assert np.hypot(*(first - start[N : N + 2])) < 0.02  # the plan swims from that body


def slow_replanner(delay_s: float):
    """A TankReplanner whose every replan takes ``delay_s`` more wall time."""

    class Slow(TankReplanner):
        def _replan(self, *args):  # noqa: ANN002, ANN202
            time.sleep(delay_s)
            return super()._replan(*args)

    return Slow


@pytest.fixture(scope="module")
def slow_take(tmp_path_factory):
    """A run whose replans each take 1.5 s of wall time: longer than the robot's 1 s watchdog."""
    world = parse_world(OPEN, "open")
    planned = plan_for_run(world, ROBOT, "sim://?speed=0&current=0.05,90", PATH_GAIT, MODEL)
    base = planned.navigator
    # a budget far beyond the 1.5 s stall and a loaded CI machine's slowest search (replans took
    # up to 46 s under a load average of 20): the replans still find their plans, and the take
    # records the budget they had
    navigator = slow_replanner(1.5)(base.planner_for, base.planner, base.outcome, PATH_GAIT,
                                    replan_budget_s=120.0)
    stem = tmp_path_factory.mktemp("slow") / "take"
    config = RunConfig(PATH_GAIT, planned.waypoints_m, duration_s=40.0)
    request = TakeRequest(ROBOT, config, str(stem), TakeNotes(planned.uri), "synthetic:clean",
                          navigator=navigator, camera_view=TankView.covering((3.0, 2.0)))
    result = run_take(request)
    return result, stem, navigator


@pytest.mark.slow
def test_no_failsafe_while_a_slow_replan_runs_beside_the_loop_in_lockstep(slow_take):
    result, stem, navigator = slow_take
    out = result.outcome
    replans = [e for e in navigator.events if e["kind"] == "replan"]
    assert replans, out.detail
    for e in replans:
        # the planner's wall time passed on the robot's clock before its plan was used
        assert e["wall_s"] >= 1.5
        assert e["t_ready_s"] - e["t_request_s"] >= 1.5 - 1e-3
    # meanwhile the loop kept sending offsets at the control rate, and the watchdog never fired
    sent = [float(r["t_s"]) for r in read_commands_csv(f"{stem}.commands.csv")
            if r["event"] == "sent" and r["message"] == "SetOffset"]
    e = replans[0]
    during = [t for t in sent if e["t_request_s"] <= t <= e["t_ready_s"]]
    assert len(during) >= 4 and np.diff(during).max() < 0.35
    assert out.failsafe_reports == 0
    assert result.virtual_robot is not None
    assert out.reason in ("arrived", "duration"), out.detail


def test_the_take_records_every_plan_and_replan(slow_take):
    result, stem, navigator = slow_take
    meta = json.loads(open(f"{stem}.json").read())
    planning = meta["source"]["planning"]
    plans = planning["plans"]
    assert plans[0]["kind"] == "plan" and plans[0]["reason"] == "start"
    # replans that took effect were switched in; a found one may still wait at the goal
    assert planning["replans"] == result.replans == sum(1 for p in plans if "t_switch_s" in p)
    assert all(p["status"] == "found" for p in plans if "t_switch_s" in p)
    assert len(plans) == len(navigator.events) >= 2
    for p in plans[1:]:
        assert p["reason"] in ("left_corridor", "predicted_contact", "current_estimate")
        assert len(p["start_state"]) == 2 * N + 4
        assert p["t_request_s"] < p["t_start_s"]
        assert p["waypoints_m"] and p["wall_s"] > 0
        assert len(p["current_m_s"]) == 2
        assert p["budget_s"] == 120.0
    assert planning["replan_budget_s"] == 120.0 and plans[0]["budget_s"] is None
    # every plan and replan says the law it was searched with: the run's (pure pursuit)
    assert all(p["guidance"] == "pursuit" for p in plans)
    # the current estimate (0.05 m/s towards +y, unknown to the planner) is recorded; its
    # accuracy is tested without threads in test_state_estimate.py
    windows = planning["current_estimate"]
    last = windows[-1]["current_m_s"]
    assert last[1] > 0.02 and abs(last[0]) < 0.02
    # each window compared the twin with one plan's waypoints: none spans a switch of plans
    switches = [p["t_switch_s"] for p in plans if "t_switch_s" in p]
    for w in windows:
        assert w["t_start_s"] < w["t_s"]
        assert not any(w["t_start_s"] < t < w["t_s"] for t in switches), (w, switches)


def test_a_contact_stops_the_run_with_its_own_exit_status(tmp_path):
    # the robot is put 4 cm short of a disc the plan goes round, facing it; the corridor is too
    # wide and the look-ahead off, so nothing replans it away: it swims into the disc
    world = parse_world(OPEN, "open")
    planned = plan_for_run(world, ROBOT, "sim://?speed=0&start=1.0,0.25,0", PATH_GAIT, MODEL)
    base = planned.navigator
    navigator = TankReplanner(base.planner_for, base.planner, base.outcome, PATH_GAIT,
                              corridor_m=10.0, lookahead_s=0.0)
    config = RunConfig(PATH_GAIT, [(2.0, 0.25)], duration_s=20.0)
    stem = tmp_path / "hit"
    request = TakeRequest(ROBOT, config, str(stem), TakeNotes(planned.uri), "synthetic:clean",
                          navigator=navigator, camera_view=TankView.covering((3.0, 2.0)))
    result = run_take(request)
    out = result.outcome
    assert out.reason == "contact", out.detail
    assert exit_status(out.reason) == EXIT_CONTACT == 6
    assert out.stop_outcome == "ack"
    assert result.virtual_robot is not None
    assert result.virtual_robot.status()["state"] == protocol.State.IDLE
    meta = json.loads(open(f"{stem}.json").read())
    assert meta["source"]["recording"]["reason"] == "contact"
    # the robot really was at the disc: its true body within a few mm of it
    x = result.virtual_robot.state_at(out.t_end_s)
    gap = body_clearance_m(world, ClearanceField(world), BODY, x[None])[0]
    assert gap < 0.005


def test_run_plan_reads_the_fitted_model_as_plan_does(tmp_path, capsys):
    bad = tmp_path / "coefficients.json"
    bad.write_text(json.dumps({"fits": {"joint": {"coefficients": {"C_f": 0.01, "C_d": -0.8,
                                                                   "C_a": 0.6, "C_m": 0.01}}}}))
    code = main(["run", "--link", "sim://?speed=0", "--plan", "tank_5_obstacles",
                 "--coefficients-file", str(bad), "--out", str(tmp_path / "x")])
    assert code == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "C_d" in err
    code = main(["run", "--link", "sim://?speed=0", "--waypoints", "1,0", "--gait", "0.87,3.9",
                 "--coefficients-file", str(bad), "--out", str(tmp_path / "y")])
    assert code == 2 and "--coefficients-file" in capsys.readouterr().err


def test_world_with_an_extra_current_adds_the_velocities():
    world = parse_world({**OPEN, "current": {"speed_m_s": 0.02, "direction_deg": 0.0}}, "w")
    moved = with_extra_current(world, np.array([0.0, 0.02]))
    assert moved.current_m_s == pytest.approx((0.02, 0.02))
    assert moved.obstacles == world.obstacles


def pose_at(t_s: float, com, heading: float = 0.0) -> Localisation:
    """A localisation of the straight body at ``com`` (what the loop hands the replanner)."""
    theta = np.full(N, heading)
    return Localisation(t_s, "ok", np.asarray(com, float), heading, theta, np.zeros((N, 2)),
                        (True,) * N, (), 0.0, "")


def failing_replanner(status: str):
    """A TankReplanner whose replans fail at once with ``status``; it counts its requests."""

    class Failing(TankReplanner):
        requests: list[float] = []

        def _replan(self, est, left, start_step, extra, guide=None,  # noqa: ANN001, ANN202
                    deadline_s=None):  # noqa: ANN001
            self.requests.append(est.t_s)
            plan = Plan(False, status, f"failed ({status})")
            return (Outcome(plan, status, plan.message), est.state, 0.0, 0.0, np.zeros(2),
                    time.monotonic(), start_step)

    return Failing


def failing_with_clear_look_ahead(status: str):
    """A :func:`failing_replanner` whose look-ahead swims the present waypoints 200 mm clear."""

    class ClearAhead(failing_replanner(status)):  # type: ignore[misc]
        def _look_ahead(self, est, left, extra, guide=None):  # noqa: ANN001, ANN202
            return 0.2, 0.2

    return ClearAhead


@pytest.fixture(scope="module")
def open_plan():
    planner = Planner(parse_world(OPEN, "open"), ROBOT, MODEL)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    return planner, outcome


def drive_off_corridor(nav: TankReplanner, seconds: float):
    """Frames of a robot 0.4 m off the planned corridor until the replanner stops it."""
    for k in range(int(seconds * 30)):
        t = k / 30
        d = nav.on_frame(t, pose_at(t, (0.8, 1.4)), np.array([0.8, 1.4, 0.0]), 0, 0.0)
        if d.stop is not None:
            return t, d
        nav._worker.submit(lambda: None).result()  # the worker's jobs are done: deterministic
    return None, None


def drive_and_close(nav: TankReplanner, seconds: float):
    """:func:`drive_off_corridor` from no recorded request, closing the replanner's workers."""
    nav.requests.clear()  # type: ignore[attr-defined]
    try:
        return drive_off_corridor(nav, seconds)
    finally:
        nav.close()


def drive_with_failing_replans(open_plan, status: str, seconds: float):
    """Drive off the corridor with every replan failing ``status``, without look-ahead."""
    planner, outcome = open_plan
    nav = failing_replanner(status)(lambda extra: planner, planner, outcome, PATH_GAIT,
                                    lookahead_s=0.0)
    t_stop, d = drive_and_close(nav, seconds)
    return nav, t_stop, d


def test_failed_replans_back_off_then_stop_the_robot_with_the_reason(open_plan):
    nav, _, d = drive_with_failing_replans(open_plan, "exhausted", 12.0)
    assert d is not None and d.stop == "no_safe_continuation"
    assert "3 failed in a row" in d.detail and "failed (exhausted)" in d.detail
    assert len(nav.requests) == 3  # not one per frame
    gaps = np.diff(nav.requests)
    assert gaps[0] >= 1.0 - 0.05 and gaps[1] >= 2.0 - 0.05  # 1 s, then 2 s between tries
    assert [e["status"] for e in nav.events[1:]] == ["exhausted"] * 3


def test_a_refused_replan_stops_the_robot_at_once(open_plan):
    nav, t_stop, d = drive_with_failing_replans(open_plan, "blocked_start", 5.0)
    assert d is not None and d.stop == "no_safe_continuation" and len(nav.requests) == 1
    assert t_stop is not None and t_stop < 0.5


def test_the_virtual_tanks_camera_films_the_worlds_whole_tank():
    from eelhost.vision.localise import Localiser
    from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
    from eelsim.dynamics import straight_state

    cam = SyntheticCamera(ROBOT, view=TankView.covering((3.0, 2.0)),
                          options=RenderOptions(noise_sigma=0.0, jpeg_quality=0))
    loc = Localiser(cam.calibration(), ROBOT)
    for x, y, heading in ((0.4, 0.1, 0.0), (2.6, 1.9, 0.0), (2.8, 1.0, 1.57), (0.35, 1.9, 3.1)):
        frame, truth = cam.render(straight_state(BODY, heading, (x, y)), 0.0)
        found = loc.localise(0.0, frame)
        assert found.found, (x, y)
        assert np.hypot(*(found.com_m - truth.com_m)) < 0.003


def test_run_plan_plans_with_the_fitted_model_and_its_tanks_current(tmp_path, capsys):
    fitted = tmp_path / "coefficients.json"
    fitted.write_text(json.dumps({"fits": {"joint": {
        "coefficients": {"C_f": 0.008, "C_d": 0.7, "C_a": 0.6, "C_m": 0.007},
        "ambient_current": {"current_x_m_s": 0.01, "current_y_m_s": 0.0}}}}))
    world = tmp_path / "open.toml"
    world.write_text(
        'name = "open"\n[tank]\nsize_m = [3.0, 2.0]\n[start]\nposition_m = [0.6, 1.0]\n'
        "heading_deg = 0.0\n[goal]\nposition_m = [2.1, 1.0]\nradius_m = 0.2\n[current]\n"
        'speed_m_s = 0.0\ndirection_deg = 0.0\n[[obstacles]]\nkind = "circle"\n'
        "centre_m = [1.4, 0.25]\nradius_m = 0.1\n")
    code = main(["run", "--link", "sim://?speed=0", "--plan", str(world), "--coefficients-file",
                 str(fitted), "--duration", "1", "--camera", "synthetic:clean", "--no-view",
                 "--out", str(tmp_path / "take")])
    out = capsys.readouterr().out
    assert code == 0, out
    model = read_coefficient_model(fitted, ROBOT)
    assert f"coefficients: {model.describe()}" in out  # the reader of eelbot plan, not a copy
    plans = json.loads((tmp_path / "take.json").read_text())["source"]["planning"]["plans"]
    assert plans[0]["current_m_s"] == pytest.approx([0.01, 0.0])  # the tank's fitted current


def test_failed_replans_keep_a_present_plan_the_twin_swims_clear(open_plan):
    planner, outcome = open_plan

    nav = failing_with_clear_look_ahead("exhausted")(lambda extra: planner, planner, outcome,
                                                     PATH_GAIT)
    t_stop, d = drive_and_close(nav, 14.0)
    assert d is None  # never stopped: it keeps its plan
    assert len(nav.requests) >= 4 and np.diff(nav.requests)[2:].min() >= 4.0 - 0.05


def test_a_failed_replan_with_contact_ahead_stops_the_robot_at_once(open_plan):
    planner, outcome = open_plan

    class HitAhead(failing_replanner("exhausted")):  # type: ignore[misc]
        def _look_ahead(self, est, left, extra, guide=None):  # noqa: ANN001, ANN202
            return -0.01, -0.01  # the present waypoints are swum 10 mm into something

    nav = HitAhead(lambda extra: planner, planner, outcome, PATH_GAIT)
    t_stop, d = drive_and_close(nav, 5.0)
    assert d is not None and d.stop == "no_safe_continuation"
    assert "into an obstacle or wall" in d.detail and len(nav.requests) == 1


def test_the_lookaheads_outline_is_the_benchmarks_independent_true_body():
    # two implementations of the same body (each link the stadium of its own length and width):
    # the replanner's on the world's polyline distances, the benchmark's on shapely
    from eelhost.benchmarks.closed_loop import true_clearance_m
    from eelhost.planning.body import link_endpoints
    from eelsim.dynamics import straight_state

    world = parse_world({**OPEN, "obstacles": OPEN["obstacles"] + [
        {"kind": "polygon", "vertices_m": [[2.0, 0.2], [2.4, 0.2], [2.4, 0.5], [2.0, 0.5]]}]},
        "w")
    rng = np.random.default_rng(11)
    states = []
    for _ in range(400):
        s = straight_state(BODY, rng.uniform(-np.pi, np.pi), (rng.uniform(0.1, 2.9),
                                                              rng.uniform(0.1, 0.9)))
        s[:N] += np.cumsum(rng.normal(0, 0.25, N))
        states.append(s)
    states = np.asarray(states)
    ours = outline_clearance_m(world, BODY, states)
    truth = true_clearance_m(world, BODY, states)
    assert (truth < 0).sum() > 20 and (truth > 0).sum() > 20
    assert np.array_equal(ours <= 0, truth <= 0)  # the same contacts
    clear = truth > 0
    assert np.allclose(ours[clear], truth[clear], atol=1e-9)
    # never nearer than the planner's capsule (the centre line widened by the largest half width)
    b = float(BODY.half_axis_horizontal_m.max())
    capsule = world.body_clearance(link_endpoints(BODY, states)) - b
    assert np.all(ours >= capsule - 1e-9) and np.any(ours > capsule + 0.01)


class _Scripted:
    """A planner whose ``plan`` answers ``status`` before ``found_from_step``, else plans."""

    def __init__(self, planner: Planner, status: str, found_from_step: float) -> None:
        self._planner, self.status, self.found_from_step = planner, status, found_from_step
        self.starts: list[int] = []

    def __getattr__(self, name: str):  # noqa: ANN204
        return getattr(self._planner, name)

    def plan(self, state, start_step, guide=None, deadline_s=None):  # noqa: ANN001, ANN201
        self.starts.append(start_step)
        if start_step < self.found_from_step:
            plan = Plan(False, self.status, f"scripted {self.status}")
            return Outcome(plan, self.status, plan.message)
        return self._planner.plan(state, start_step, guide=guide)


def estimate_at(t_s: float, shift_m=(0.0, 0.0)):
    """The estimator's state of the swimming robot at ``t_s``, its whole run moved by ``shift_m``."""
    run = swimming_state(t_s)
    est = BodyStateEstimator(BODY, PATH_GAIT)
    for t in np.arange(t_s - 0.5, t_s + 1e-9, 1 / 30):
        x = np.array([np.interp(t, run.t_s, run.states[:, i]) for i in range(run.states.shape[1])])
        est.observe(t, x[N : N + 2] + np.asarray(shift_m), x[:N])
    e = est.estimate()
    assert e is not None
    return e


def test_a_blocked_replan_start_is_retried_from_the_moving_body_further_on(open_plan):
    planner, outcome = open_plan
    e = estimate_at(3.0)
    now = int(round(3.0 / 0.01))
    scripted = _Scripted(planner, "blocked_start", now + 120)  # blocked until 1.2 s ahead
    nav = TankReplanner(lambda extra: scripted, scripted, outcome, PATH_GAIT)  # type: ignore[arg-type]
    try:
        found, state, *_, start = nav._replan(e, [(2.1, 1.0)], now + 60, np.zeros(2))
    finally:
        nav.close()
    assert scripted.starts == [now + 60, now + 90, now + 120]  # a restart period further each
    assert found.found and start == now + 120
    assert np.hypot(*(found.plan.legs[0].com_m[0] - state[N : N + 2])) < 0.02
    # refused from every start tried: the refusal stands (the robot stops unless its plan is clear)
    never = _Scripted(planner, "blocked_start", np.inf)
    nav = TankReplanner(lambda extra: never, never, outcome, PATH_GAIT)  # type: ignore[arg-type]
    try:
        refused, *_ = nav._replan(e, [(2.1, 1.0)], now + 60, np.zeros(2))
    finally:
        nav.close()
    assert refused.status == "blocked_start" and len(never.starts) == 1 + nav.blocked_retries


def test_a_refused_replan_keeps_a_present_plan_the_twin_swims_clear(open_plan):
    planner, outcome = open_plan

    nav = failing_with_clear_look_ahead("blocked_start")(lambda extra: planner, planner, outcome,
                                                     PATH_GAIT)
    t_stop, d = drive_and_close(nav, 6.0)
    assert d is None and len(nav.requests) >= 2  # kept its plan, and tried again later


def test_the_goal_approachs_smaller_margin_is_tried_near_the_goal_or_when_no_pose_is_left(
        open_plan):
    planner, outcome = open_plan
    tight = _Scripted(planner, "", -np.inf)  # the goal approach's planner: it plans (counted)
    far = estimate_at(3.0)  # about 1 m from the goal disc
    near = estimate_at(3.0, (1.0, -0.1))  # its centre of mass some 0.2 m short of the disc
    step = int(round(3.0 / 0.01)) + 60

    def replan(status, est):  # noqa: ANN001, ANN202
        failing = _Scripted(planner, status, np.inf)
        nav = TankReplanner(lambda extra: failing, failing, outcome,  # type: ignore[arg-type]
                            PATH_GAIT, goal_planner_for=lambda extra: tight, goal_approach_m=0.5,
                            shift_repair=False)  # the goal approach alone
        try:
            return nav._replan(est, [(2.1, 1.0)], step, np.zeros(2))
        finally:
            nav.close()

    out, *_ = replan("check_failed", far)  # a failed check far from the goal: no second try
    assert out.status == "check_failed" and not tight.starts
    out, state, *_ = replan("check_failed", near)
    assert np.hypot(state[N] - 2.1, state[N + 1] - 1.0) - 0.2 < 0.5
    assert len(tight.starts) == 1 and out.found, out.message
    out, *_ = replan("exhausted", far)  # no pose left with the world's margin: tried anywhere
    assert len(tight.starts) == 2 and out.found, out.message


def test_a_plan_ready_long_after_its_start_with_the_robot_off_its_corridor_is_not_used(open_plan):
    from concurrent.futures import Future

    from eelhost.planning.replan import Decision, _Job

    planner, outcome = open_plan
    for com, used in (((0.8, 1.4), False), ((0.7, 1.0), True)):  # 0.4 m off / on its path
        nav = TankReplanner(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0)
        try:
            for t in np.arange(3.5, 4.0, 1 / 30):
                nav.estimator.observe(t, np.asarray(com), np.zeros(N))
            done: Future = Future()
            state = np.zeros(2 * N + 4)
            done.set_result(((outcome, state, 0.1, 0.1, np.zeros(2), time.monotonic(), 150),
                             None))
            nav._job = _Job(done, 1.0, time.monotonic(), 1.5, "left_corridor")
            d = Decision()
            assert nav._collect(4.0, d) and d.stop is None
        finally:
            nav.close()
        if used:
            assert nav._pending is not None and nav.failures == 0
            assert nav.events[-1]["status"] == "found"
        else:  # 2.5 s late and the robot off the new corridor: kept its plan, replans at once
            assert nav._pending is None and nav.failures == 1 and nav._next_try_s == 4.0
            assert nav.events[-1]["status"] == "stale" and "not used" in nav.events[-1]["message"]


def stuck_replanner(release, ahead) -> type[TankReplanner]:  # noqa: ANN001
    """A :class:`TankReplanner` whose replans wait for ``release`` (a planner starved of
    processor time) and whose look-ahead from an estimate is ``ahead(est)``."""

    class Stuck(TankReplanner):
        def _replan(self, *args):  # noqa: ANN002, ANN202
            release.wait(30.0)
            return super()._replan(*args)

        def _look_ahead(self, est, left, extra, guide=None):  # noqa: ANN001, ANN202
            return ahead(est)

    return Stuck


def swim_until_stopped(nav: TankReplanner, release) -> tuple:  # noqa: ANN001
    """Frames at 30 Hz along the test path for up to 5 s, until ``nav`` stops the robot; then
    ``release`` the held replan and close ``nav``. Returns (the last decision, its time)."""
    d, t = None, 0.0
    try:
        for k in range(5 * 30):
            t = k / 30
            d = nav.on_frame(t, pose_at(t, (0.8, 1.4)), np.array([0.8, 1.4, 0.0]), 0, 0.0)
            if d.stop is not None:
                break
            nav._side.submit(lambda: None).result()  # the look-ahead's thread is done
    finally:
        release.set()
        nav.close()
    return d, t


def test_a_late_replan_with_contact_ahead_stops_the_robot_without_waiting_for_it(open_plan):
    import threading

    planner, outcome = open_plan
    release = threading.Event()
    # the present waypoints swum 5 mm into something (a bare verdict: contact now)
    nav = stuck_replanner(release, lambda est: (-0.005, -0.025))(
        lambda extra: planner, planner, outcome, PATH_GAIT)
    d, t = swim_until_stopped(nav, release)
    assert d is not None and d.stop == "no_safe_continuation", d
    assert "has not come back" in d.detail and nav._job is not None
    assert t > nav._job.t_start_s  # only once the replan was late


def contact_ahead_replanner(status: str, contact_in_s: float):
    """A :func:`failing_replanner` whose look-ahead swims the present waypoints into contact
    ``contact_in_s`` after its estimate (10 mm deep)."""

    class ContactAhead(failing_replanner(status)):  # type: ignore[misc]
        def _look_ahead(self, est, left, extra, guide=None):  # noqa: ANN001, ANN202
            return Ahead(-0.01, -0.01, est.t_s + contact_in_s)

    return ContactAhead


@pytest.mark.parametrize(("contact_in_s", "budget_s", "allowance_s", "retried"), [
    (10.0, 1.0, STOP_ALLOWANCE_S, True),  # contact far ahead: time for another replan before it
    (1.0, 1.0, STOP_ALLOWANCE_S, False),  # nearer than a replan's budget, grace and lead: stop
    # time for a replan's 1.8 s but not for a stop after it too (seed 28056): stop now, while
    # the brake has room; without the stop's allowance it was retried
    (2.5, 1.0, STOP_ALLOWANCE_S, False),
    (2.5, 1.0, 0.0, True),
    (10.0, None, STOP_ALLOWANCE_S, False),  # no budget, no bound on a retry's return: stop
])
def test_a_failed_replan_is_retried_at_once_only_while_the_contact_ahead_leaves_time_for_it(
        open_plan, contact_in_s, budget_s, allowance_s, retried):
    planner, outcome = open_plan
    nav = contact_ahead_replanner("exhausted", contact_in_s)(
        lambda extra: planner, planner, outcome, PATH_GAIT, replan_budget_s=budget_s,
        stop_allowance_s=allowance_s)
    t_stop, d = drive_and_close(nav, 8.0)
    assert d is not None and d.stop == "no_safe_continuation"
    assert "into an obstacle or wall within" in d.detail and ", first in " in d.detail  # when
    if retried:
        # no back-off between the tries (1 s, then 2 s, without contact ahead), and still
        # stopped after max_failures of them
        assert len(nav.requests) == nav.max_failures == 3
        assert np.diff(nav.requests).max() < 0.5
        assert nav.retries_before_contact == 2 and nav.record()["retries_before_contact"] == 2
    else:
        assert len(nav.requests) == 1 and nav.retries_before_contact == 0
        assert t_stop is not None and t_stop < 0.5


def near_outline_replanner(near_in_s: float):
    """A :func:`failing_replanner` whose look-ahead swims the present waypoints with the outline
    8 mm clear (under the 10 mm margin, never touching) and the capsule within the margin
    ``near_in_s`` after its estimate."""

    class NearOutline(failing_replanner("exhausted")):  # type: ignore[misc]
        def _look_ahead(self, est, left, extra, guide=None):  # noqa: ANN001, ANN202
            return Ahead(0.008, -0.01, math.inf, est.t_s + near_in_s)

    return NearOutline


@pytest.mark.parametrize(("near_in_s", "retried"), [(0.5, False), (10.0, True)])
def test_an_outline_within_the_margin_after_a_failed_replan_counts_as_contact(
        open_plan, near_in_s, retried):
    # seed 18036 (docs/planning.md, "The outline's margin"): the twin swam the outline 3-8 mm
    # clear after two failed replans, the robot kept its plan, and the body touched 4 mm deep
    planner, outcome = open_plan
    nav = near_outline_replanner(near_in_s)(
        lambda extra: planner, planner, outcome, PATH_GAIT, replan_budget_s=1.0)
    t_stop, d = drive_and_close(nav, 8.0)
    assert d is not None and d.stop == "no_safe_continuation"
    assert "within 8 mm of an obstacle or wall" in d.detail
    if retried:  # the capsule far enough ahead: replanned again at once, no back-off
        assert len(nav.requests) == nav.max_failures
        assert np.diff(nav.requests).max() < 0.5 and nav.retries_before_contact >= 1
    else:  # too near for another replan to steer: stopped at the first failure
        assert len(nav.requests) == 1 and t_stop < 0.5


def test_a_failed_replans_older_look_ahead_never_replaces_a_newer_one(open_plan):
    # the replan's own look-ahead swims from the estimate of its request; look-aheads from later
    # estimates ran beside it, and the newest judges the present plan
    import threading

    planner, outcome = open_plan
    release = threading.Event()

    asked: list[float] = []  # the requests' estimate times, as they are asked for

    class HeldFailing(failing_replanner("exhausted")):  # type: ignore[misc]
        def _replan(self, est, *args):  # noqa: ANN001, ANN002, ANN202
            asked.append(est.t_s)
            release.wait(30.0)
            return super()._replan(est, *args)

        def _look_ahead(self, est, left, extra, guide=None):  # noqa: ANN001, ANN202
            first = not asked or est.t_s <= asked[0] + 1e-9
            # from the request's estimate: clear; from later ones: the outline 8 mm clear
            return Ahead(0.05, 0.05) if first else Ahead(0.008, 0.02)

    nav = HeldFailing(lambda extra: planner, planner, outcome, PATH_GAIT, replan_budget_s=None)
    nav.requests.clear()
    try:
        for k in range(4 * 30):
            t = k / 30
            d = nav.on_frame(t, pose_at(t, (0.8, 1.4)), np.array([0.8, 1.4, 0.0]), 0, 0.0)
            assert d.stop is None, d
            nav._side.submit(lambda: None).result()
            if asked and nav._last_gap[0] > asked[0] and not release.is_set():
                release.set()  # a later estimate's verdict is in: let the replan fail now
                nav._worker.submit(lambda: None).result()
            if nav.failures:
                break
    finally:
        release.set()
        nav.close()
    assert nav.failures == 1
    t_gap, gap = nav._last_gap
    assert t_gap > asked[0] and gap == pytest.approx(0.008)
    # the newer verdict is within the margin: another replan asked for at once instead of a
    # back-off (counted when asked for; its worker may not have started it yet)
    assert nav.retries_before_contact == 1


@pytest.mark.parametrize("contact_in_s", [10.0, 0.5])
def test_a_replan_past_its_start_is_waited_for_within_its_budget_only_with_time_before_contact(
        open_plan, contact_in_s):
    import threading

    from eelhost.planning.replan import SHIFT_GRACE_S

    planner, outcome = open_plan
    release = threading.Event()
    nav = stuck_replanner(release, lambda est: Ahead(-0.005, -0.025, est.t_s + contact_in_s))(
        lambda extra: planner, planner, outcome, PATH_GAIT, replan_budget_s=1.0)
    d, t = swim_until_stopped(nav, release)
    assert d is not None and d.stop == "no_safe_continuation", d
    job = nav._job
    assert "has not come back" in d.detail and job is not None
    assert job.due_s == pytest.approx(job.t_request_s + 1.0 + SHIFT_GRACE_S)
    if contact_in_s > 5.0:  # waited for until its budget and grace were over
        assert t > job.due_s
    else:  # the contact too near to wait: stopped once the replan was past its start
        assert job.t_start_s < t < job.due_s


def capsule_near_replanner(near_in_s: float, outline_late_m: float):
    """A :func:`failing_replanner` on its corridor whose look-ahead swims the present waypoints
    with the outline 50 mm clear but the capsule within the margin ``near_in_s`` after its
    estimate (no current windows); after the third failure, the look-aheads from later
    estimates keep the outline only ``outline_late_m`` clear."""

    class CapsuleNear(failing_replanner("exhausted")):  # type: ignore[misc]
        def _estimate_current(self, est, left, pose):  # noqa: ANN001, ANN202
            return False

        def _look_ahead(self, est, left, extra, guide=None, horizon_s=None):  # noqa: ANN001, ANN202
            if horizon_s is not None:
                return 0.2, 0.2
            late = len(self.requests) >= 3 and est.t_s > self.requests[-1] + 1e-9
            return Ahead(outline_late_m if late else 0.05, 0.0, math.inf, est.t_s + near_in_s)

    return CapsuleNear


@pytest.mark.parametrize(("near_in_s", "outline_late_m"), [(1.0, 0.005), (1.0, 0.05), (4.5, 0.05)])
def test_the_back_off_yields_to_a_lookahead_that_puts_the_capsule_near_before_a_later_replan(
        open_plan, near_in_s, outline_late_m):
    # seed 12041 (docs/planning.md): after a failed replan the back-off asked for no replan
    # whatever the look-ahead said, and the robot swam into an obstacle meanwhile
    planner, outcome = open_plan
    nav = capsule_near_replanner(near_in_s, outline_late_m)(
        lambda extra: planner, planner, outcome, PATH_GAIT, replan_budget_s=1.0)
    nav.requests.clear()
    start = np.asarray(outcome.plan.legs[0].com_m[0])
    stop = None
    try:
        for k in range(int(9.0 * 30)):
            t = k / 30
            d = nav.on_frame(t, pose_at(t, start), np.array([*start, 0.0]), 0, 0.0)
            if d.stop is not None:
                stop = (t, d)
                break
            nav._worker.submit(lambda: None).result()
            nav._side.submit(lambda: None).result()
    finally:
        nav.close()
    need = nav._retry_need_s() + nav.stop_allowance_s  # a stop keeps its room
    gaps = np.diff(nav.requests)
    if near_in_s + nav.lookahead_every_s < nav.backoff_s + need:
        # the capsule comes near before a replan after the 1 s back-off could steer: every
        # failed replan is followed by the next look-ahead's replan, within the back-off
        assert len(nav.requests) >= nav.max_failures
        assert gaps[: nav.max_failures - 1].max() < nav.backoff_s
        assert nav.backoff_yields == nav.max_failures - 1 and nav.retries_before_contact == 0
        assert nav.record()["backoff_yields"] == nav.max_failures - 1
        if outline_late_m < nav.lookahead_margin_m:
            # then no failure is left and the present plan is no longer known clear: the robot
            # is stopped deliberately, with the reason
            assert stop is not None and stop[1].stop == "no_safe_continuation"
            # (the outline within the margin counts as contact after a failed replan)
            assert "within 5 mm of an obstacle or wall" in stop[1].detail
            assert "the last replan failed" in stop[1].detail
            assert len(nav.requests) == nav.max_failures
        else:  # its outline still swims clear by the margin: kept, as after a last failure,
            # and the back-off (4 s) holds until the next try
            assert stop is None and len(nav.requests) > nav.max_failures
            assert gaps[nav.max_failures - 1] >= 4.0 * nav.backoff_s - 0.05
    else:
        # far enough ahead: the back-off holds (1 s, then 2 s between tries), as before
        assert nav.backoff_yields == 0 and len(nav.requests) >= 2
        assert gaps[0] >= nav.backoff_s - 0.05 and (len(gaps) < 2 or gaps[1] >= 2.0 - 0.05)


def _disc_some_4_s_ahead():
    """A planner without check in the open world with a small disc some 4 s ahead of the robot
    swimming at 3 s (:func:`estimate_at`), a no-plan outcome, and that estimate."""
    world = parse_world({**OPEN, "obstacles": [
        {"kind": "circle", "centre_m": [1.25, 1.03], "radius_m": 0.05}]}, "disc")
    planner = Planner(world, ROBOT, MODEL, check=False)
    return planner, Outcome(Plan(False, "none", "none"), "none", "none"), estimate_at(3.0)


def test_the_lookahead_asks_for_a_replan_5_s_ahead_but_judges_stops_on_the_next_3_s():
    # a disc some 4 s ahead of the swimming robot: within the replan horizon, beyond the stops'
    planner, outcome, e = _disc_some_4_s_ahead()
    verdicts = {}
    for horizon in (3.0, 5.0):
        nav = TankReplanner(lambda extra: planner, planner, outcome, PATH_GAIT,
                            replan_horizon_s=horizon)
        try:
            verdicts[horizon] = nav._look_ahead(e, [(2.5, 1.3)], np.zeros(2))
        finally:
            nav.close()
        margin = nav.lookahead_margin_m
    outline_3, capsule_3, contact_3, near_3 = verdicts[3.0][:4]
    outline_5, capsule_5, contact_5, near_5 = verdicts[5.0][:4]
    assert capsule_3 > margin + 0.005  # 3 s ahead the capsule stays clear: no replan asked for
    assert capsule_5 < margin  # 5 s ahead it meets the disc: a replan is asked for in time
    assert outline_5 == outline_3 > margin  # the stop's verdict is still the next 3 s's
    assert contact_3 == contact_5 == math.inf  # no contact of the outline within those 3 s
    assert near_3 == math.inf and e.t_s + 3.0 < near_5 <= e.t_s + 5.0  # when it comes near


def test_the_lookaheads_margin_grows_with_the_current_estimates_uncertainty():
    # the disc of the test above, judged over 3 s only: clear by more than the 10 mm margin in the
    # estimated water, but not by the drift that an uncertain current estimate allows over 3 s
    planner, outcome, e = _disc_some_4_s_ahead()
    # one window with a sample of 20 mm/s north moved the estimate (gain 0.6) to 12 mm/s:
    # the estimate may still be 8 mm/s off
    history = [{"current_m_s": [0.0, 0.012], "sample_m_s": [0.0, 0.02]}]
    assert current_spread_m_s(history) == pytest.approx(0.008)
    assert current_spread_m_s([]) == 0.0  # nothing measured: no allowance
    # two more windows that agree with the estimate shrink it
    agree = {"current_m_s": [0.0, 0.012], "sample_m_s": [0.0, 0.012]}
    assert current_spread_m_s(history + [agree] * 2) < 0.005
    verdicts = []
    for h in ([], history):
        nav = TankReplanner(lambda extra: planner, planner, outcome, PATH_GAIT,
                            replan_horizon_s=3.0)
        nav.current.history = h
        try:
            verdicts.append(nav._look_ahead(e, [(2.5, 1.3)], np.zeros(2)))
        finally:
            nav.close()
        margin = nav.lookahead_margin_m
    known, uncertain = verdicts
    assert known.capsule_m > margin and known.near_s == math.inf  # no replan asked for
    # the allowance (8 mm/s times the time ahead, at most 20 mm) takes it within the margin
    assert known.capsule_m - 0.02 - 1e-9 <= uncertain.capsule_m < margin
    assert e.t_s < uncertain.near_s <= e.t_s + 3.0
    # the stops' verdict (the outline, its contact) does not move with the allowance
    assert (uncertain.outline_m, uncertain.contact_s) == (known.outline_m, known.contact_s)


def test_a_slow_replan_does_not_push_the_next_replans_start_beyond_the_lead_cap(open_plan):
    planner, outcome = open_plan
    nav = failing_replanner("exhausted")(lambda extra: planner, planner, outcome, PATH_GAIT,
                                         lookahead_s=0.0)
    e = estimate_at(3.0)
    period_s = planner.twin.restart_steps * planner.twin.dt_s
    try:
        starts = []
        for last_wall in (0.0, 0.3, 5.0):  # no replan yet, a quick one, one of 5 s of wall time
            nav._last_wall_s = last_wall
            nav._request(3.0, e, [(2.1, 1.0)], "left_corridor")
            assert nav._job is not None
            starts.append(nav._job.t_start_s - e.t_s)
            nav._job.future.result()
            nav._job = None
    finally:
        nav.close()
    # the start is a restart point at least the lead ahead: at most the cap plus one period,
    # so a plan ready by then steers within 1 s of the request (issue 28)
    assert starts[0] >= nav.lead_s - 1e-9
    assert max(starts) <= nav.max_lead_s + period_s + 1e-9 <= 1.0
    assert starts[1] >= 1.5 * 0.3 - 1e-9  # 1.5 times the last wall time while under the cap


# -- the guidance law at the tank (issue 28: --guidance ilos) --------------------------------------

ILOS_LAW = PLANNING_GUIDANCE


def ilos_offsets_by_hand(frames, sends, waypoints, start, switches, law, k_theta, period_s,
                         window=5, limit_rad=1.0):
    """The offsets docs/model.md section 4's ILOS law gives for measured poses, written here.

    ``frames``: (t, x, y, heading) of every pose the loop measured; ``sends``: the times offsets
    were sent; ``switches``: {t: (waypoints, (x0, y0, I_x, I_y))} new waypoints handed over at a
    frame's time with their guidance state; ``start`` the first leg's start. Independent of
    eelsim.guidance (its own median, unwrapping, acceptance and law).
    """
    buf, last, target, integral = [], None, 0, np.zeros(2)
    start = np.asarray(start, float)
    filtered = None
    out, f = [], 0
    for t_send in sends:
        while f < len(frames) and frames[f][0] <= t_send + 1e-4:
            t, x, y, h = frames[f]
            for ts, (new, guide) in switches.items():
                if abs(ts - t) < 1e-4:  # the loop's new guidance sees this frame afresh
                    waypoints, buf, last, target = new, [], None, 0
                    start, integral = np.array(guide[:2]), np.array(guide[2:], dtype=float)
            h = h if last is None else last + math.remainder(h - last, 2 * math.pi)
            last = h
            buf = (buf + [(x, y, h)])[-window:]
            filtered = np.median(np.array(buf), axis=0)
            if target < len(waypoints) and np.hypot(*(filtered[:2] - waypoints[target])) < 0.15:
                target += 1
            f += 1
        if filtered is None:
            out.append(0.0)
            continue
        k = min(target, len(waypoints) - 1)
        w = np.asarray(waypoints[k], float)
        a = np.asarray(waypoints[k - 1], float) if k > 0 else start
        along = (w - a) / np.linalg.norm(w - a)
        normal = np.array([-along[1], along[0]])
        e = float((filtered[:2] - a) @ normal)
        ahead = min(law.lookahead_m, float(np.linalg.norm(w - a) - (filtered[:2] - a) @ along))
        lateral = e + law.integral_gain * float(integral @ normal)
        theta_ref = math.atan2(along[1], along[0]) + math.atan2(-lateral, ahead)
        integral = integral + period_s * law.lookahead_m * e / (
            lateral ** 2 + law.lookahead_m ** 2) * normal
        gamma = k_theta * math.remainder(theta_ref - filtered[2], 2 * math.pi)
        out.append(float(np.clip(gamma, -limit_rad, limit_rad)))
    return out


class SwitchAt:
    """A navigator that hands over new waypoints with a guidance state once, at ``t_s``."""

    replans = 0

    def __init__(self, t_s, waypoints, guide):  # noqa: ANN001
        self.t_s, self.waypoints, self.guide = t_s, waypoints, guide
        self.switched_at = None
        self.guides = []  # the guidance state the loop handed over with each frame

    def on_frame(self, t_s, loc, pose, target, offset_rad, guide=None):  # noqa: ANN001, ANN201
        self.guides.append((t_s, guide))
        if self.switched_at is None and t_s >= self.t_s:
            self.switched_at = t_s
            return Decision(waypoints=self.waypoints, guide=self.guide)
        return Decision()

    def pace(self, t_s):  # noqa: ANN001, ANN201
        pass

    def close(self):  # noqa: ANN201
        pass

    def record(self):  # noqa: ANN201
        return {}


def test_the_run_loops_ilos_offsets_are_the_law_for_its_measured_poses_across_a_handover(tmp_path):
    # a cross current pushes the robot off its first leg; at 4 s new waypoints come with a
    # guidance state (leg start, integral) that the loop must steer them with
    first = [(0.9, 0.0), (1.6, 0.0)]
    later = [(1.2, 0.3), (1.8, 0.3)]
    guide = (0.4, 0.05, 2.5, -1.5)
    nav = SwitchAt(4.0, later, guide)
    config = RunConfig(PATH_GAIT, first, duration_s=7.0, guidance=ILOS_LAW,
                       start_guide=(0.0, 0.0, 0.0, 0.0))
    stem = tmp_path / "ilos"
    request = TakeRequest(ROBOT, config, str(stem), TakeNotes("sim://?speed=0&current=0.04,90"),
                          "synthetic:clean", navigator=nav)
    run_take(request)
    frames = [tuple(float(v) for v in row[:4])
              for row in np.loadtxt(f"{stem}.csv", delimiter=",", skiprows=1, ndmin=2)]
    sent = [r for r in read_commands_csv(f"{stem}.commands.csv")
            if r["event"] == "sent" and r["message"] == "SetOffset"][1:]  # after Start's 0
    assert nav.switched_at is not None and len(sent) >= 20
    expected = ilos_offsets_by_hand(frames, [r["t_s"] for r in sent], first, (0.0, 0.0),
                                    {nav.switched_at: (later, guide)}, ILOS_LAW,
                                    ILOS_LAW.heading_gain, 0.3)
    got = [r["fields"]["offset_rad"] for r in sent]
    assert np.allclose(got, expected, atol=1e-5), np.abs(np.subtract(got, expected)).max()
    assert max(abs(o) for o in got) > 0.1
    # the state the loop hands the navigator after the switch carries the handed-over integral
    after = [g for t, g in nav.guides if t > nav.switched_at]
    assert after and after[0][:2] == guide[:2]
    assert np.hypot(after[0][2] - guide[2], after[0][3] - guide[3]) < 0.5
    # the take records the law it steered with
    meta = json.loads(open(f"{stem}.json").read())
    assert meta["source"]["guidance"]["law"] == "ilos"
    assert meta["source"]["guidance"]["heading_gain"] == ILOS_LAW.heading_gain
    assert meta["source"]["guidance"]["start_guide"] == [0.0, 0.0, 0.0, 0.0]


class GuideRecorder:
    """An ILOS planner whose ``plan`` records the guidance state it is given and answers with
    ``template``'s legs as a plan searched from that state (no search: the twin's runs of the
    prediction are the ILOS law's own)."""

    def __init__(self, planner: Planner, template: Outcome) -> None:
        self._planner, self.template = planner, template
        self.guides: list = []

    def __getattr__(self, name: str):  # noqa: ANN204
        return getattr(self._planner, name)

    def plan(self, state, start_step, guide=None, deadline_s=None):  # noqa: ANN001, ANN201
        self.guides.append(guide)
        return dataclasses.replace(self.template,
                                   plan=dataclasses.replace(self.template.plan, start_guide=guide))


def test_a_replan_carries_the_loops_ilos_integral_into_its_plan_and_hands_that_state_on(
        open_plan):
    # the robot is 0.4 m off the planned corridor with an integral the controller has learnt;
    # the replan must start from it (not from zero) and the loop must get the plan's own state
    pursuit_planner, outcome = open_plan
    planner = GuideRecorder(Planner(parse_world(OPEN, "open"), ROBOT, MODEL, guidance=ILOS_LAW),
                            outcome)
    nav = TankReplanner(lambda extra: planner, planner, outcome, PATH_GAIT,  # type: ignore[arg-type]
                        lookahead_s=0.0, estimate_current=False)
    handed = (0.6, 1.0, 2.0, -1.0)
    d = None
    try:
        for k in range(10 * 30):
            t = k / 30
            d = nav.on_frame(t, pose_at(t, (0.8, 1.4)), np.array([0.8, 1.4, 0.0]), 0, 0.0,
                             guide=handed)
            if d.waypoints is not None or d.stop is not None:
                break
            nav._worker.submit(lambda: None).result()
    finally:
        nav.close()
    assert d is not None and d.waypoints is not None, (d, nav.events[-1])
    replan = nav.events[-1]
    assert replan["kind"] == "replan" and replan["status"] == "found"
    assert len(planner.guides) == 1
    guide = d.guide
    assert guide is not None and tuple(guide) == planner.guides[0]
    assert replan["start_guide"] == pytest.approx(list(guide), abs=1e-5)  # recorded in the take
    # a new leg from the predicted start's centre of mass, with the integral carried on: a few
    # control updates of the law (at most 0.15 s each) from the loop's, not reset to zero
    assert guide[:2] == pytest.approx(replan["start_state"][N : N + 2], abs=1e-4)
    assert math.hypot(guide[2] - handed[2], guide[3] - handed[3]) < 0.6
    assert math.hypot(guide[2], guide[3]) > 1.5
    assert guide[2:] != handed[2:]  # the twin's law moved it over the lead to the start


def test_the_benchmark_refuses_to_resume_worlds_run_with_another_guidance_law(tmp_path, capsys):
    out = tmp_path / "bench"
    out.mkdir()
    (out / "results.jsonl").write_text(json.dumps(
        {"seed": 5600, "planned": False, "status": "exhausted"}) + "\n")  # pursuit, by default
    status = main(["run", "--bench", "--worlds", "1", "--seed", "5600", "--guidance", "ilos",
                   "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2
    assert "another guidance law than ilos" in err and "results.jsonl" in err


def test_a_feed_forward_plan_is_steered_and_replanned_with_the_law_the_planner_filled_in(tmp_path):
    # issue 28: pursuit_ff aims off by the current the planner knows; the planner fills in that
    # current and the robot's speed, and the run loop and every replan must use that very law
    world = parse_world({**OPEN, "current": {"speed_m_s": 0.03, "direction_deg": 90.0}}, "open")
    planned = plan_for_run(world, ROBOT, "sim://?speed=0&current=0.03,90", PATH_GAIT, MODEL,
                           planner_options={"guidance": GuidanceLaw("pursuit_ff")})
    law, planner = planned.guidance, planned.navigator.planner
    assert law.feed_forward and not law.needs_water
    assert law.current_m_s == pytest.approx(MODEL.in_tank(world).current_m_s, abs=1e-12)
    assert law.current_m_s[1] == pytest.approx(0.03, abs=1e-9)
    assert law.speed_m_s == planner.swimming_speed_m_s > 0.05
    assert planner.options.guidance == law == planner.twin.options.guidance
    # a replan's planner in an estimated extra current plans with the same law (the known
    # current, not the estimate: the loop keeps steering with the first plan's law)
    replanner = planned.navigator.planner_for(np.array([0.01, -0.02]))
    assert replanner.options.guidance == law
    assert replanner.world.current_m_s != pytest.approx(world.current_m_s)
    # the run loop given the planned law sends the feed-forward's offsets, not pursuit's
    first = [(1.6, 1.0)]
    config = RunConfig(PATH_GAIT, first, duration_s=5.0, guidance=law)
    stem = tmp_path / "ff"
    request = TakeRequest(ROBOT, config, str(stem),
                          TakeNotes("sim://?speed=0&current=0.03,90&start=0.6,1.0,0"),
                          "synthetic:clean")
    run_take(request)
    frames = np.loadtxt(f"{stem}.csv", delimiter=",", skiprows=1, ndmin=2)[:, :4]
    sent = [r for r in read_commands_csv(f"{stem}.commands.csv")
            if r["event"] == "sent" and r["message"] == "SetOffset"][1:]  # after Start's 0
    assert len(sent) >= 10

    def replay(with_law: GuidanceLaw) -> list[float]:
        return offsets_by_hand(frames, sent, first, with_law, offset_limit_rad=1.0)

    got = [r["fields"]["offset_rad"] for r in sent]
    assert np.allclose(got, replay(law), atol=1e-5)
    assert not np.allclose(got, replay(PURSUIT), atol=1e-2)
    meta = json.loads(open(f"{stem}.json").read())
    assert meta["source"]["guidance"]["law"] == "pursuit_ff"
    assert meta["source"]["guidance"]["current_m_s"] == list(law.current_m_s)
    assert meta["source"]["guidance"]["speed_m_s"] == law.speed_m_s


def test_run_refuses_the_feed_forward_without_a_planner(capsys):
    status = main(["run", "--link", "sim://", "--waypoints", "1,0", "--gait", "0.4,6.28",
                   "--guidance", "pursuit_ff", "--out", "/nonexistent/x"])
    assert status == 2
    assert "--guidance pursuit_ff: only with --plan or --bench" in capsys.readouterr().err


WALL_AHEAD = {
    "name": "wall_ahead",
    "tank": {"size_m": [3.0, 2.0]},
    "start": {"position_m": [1.5, 1.0], "heading_deg": 180.0},
    "goal": {"position_m": [1.0, 1.0], "radius_m": 0.2},
    "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
    "obstacles": [],
}


def test_a_replan_that_finds_nothing_is_rescued_by_the_recoverys_sharper_turns():
    # the robot swims at the tank's end wall, 0.6 m from it, and its goal is behind it
    run = plan_for_run(parse_world(WALL_AHEAD, "wall_ahead"), ROBOT, "sim://")
    nav = run.navigator
    com = estimate_at(3.0).state[N]
    est = estimate_at(3.0, (3.0 - 0.6 - com, 0.0))
    step = int(round(3.0 / 0.01)) + 60
    make_recovery, nav.recovery_planner_for = nav.recovery_planner_for, None
    nav.shift_repair = False  # the recovery alone (the shift repair has its own tests)
    try:
        without, *_ = nav._replan(est, [(2.9, 1.1)], step, np.zeros(2))
        nav.recovery_planner_for = make_recovery
        rescued, state, *_ = nav._replan(est, [(2.9, 1.1)], step, np.zeros(2))
    finally:
        nav.close()
    # the planner's actions (turns up to 60 degrees) and margin give no plan that passes its check
    assert not without.found and without.status == "check_failed", without.message
    assert rescued.found and rescued.message.startswith("recovery:"), rescued.message
    legs = rescued.plan.legs
    assert any(abs(leg.bearing_deg) > 60.0 + 1e-6 for leg in legs)  # a turn only it has
    # its plan passed the same check (every draw clear) and starts at the predicted body
    assert rescued.checks and all(c.ok for c in rescued.checks)
    assert np.hypot(*(legs[0].com_m[0] - state[N : N + 2])) < 0.02



class FailingInTheTestsEstimate(TankReplanner):
    """Replans fail at once (exhausted), each call recorded in ``asked`` (a subclass declares its
    own list, and may record less than :meth:`_asked`'s whole call); no current window moves the
    estimate, the test sets it."""

    asked: list

    def _asked(self, est, start_step, extra, deadline_s):  # noqa: ANN001, ANN202
        return (est.t_s, start_step * self.planner.twin.dt_s, (float(extra[0]), float(extra[1])),
                deadline_s)

    def _replan(self, est, left, start_step, extra, guide=None,  # noqa: ANN001, ANN202
                deadline_s=None):  # noqa: ANN001
        self.asked.append(self._asked(est, start_step, extra, deadline_s))
        plan = Plan(False, "exhausted", "failed (exhausted)")
        return (Outcome(plan, "exhausted", plan.message), est.state, 0.0, 0.0, extra.copy(),
                time.monotonic(), start_step)

    def _estimate_current(self, est, left, pose):  # noqa: ANN001, ANN202
        return False


def test_a_moved_current_estimate_replans_only_a_plan_it_breaks_and_a_failure_keeps_the_plan(
        open_plan):
    planner, outcome = open_plan

    class InTheEstimate(FailingInTheTestsEstimate):
        """Replans fail; the estimate is set by the test; the next 5 s are clear, and the whole
        rest of the plan, swum in a moved estimate, comes ``rest_gap_m`` from something."""

        asked: list[tuple[float, tuple[float, float]]] = []
        rest_gap_m = 0.2
        horizons: list[float] = []

        def _asked(self, est, start_step, extra, deadline_s):  # noqa: ANN001, ANN202
            return est.t_s, (float(extra[0]), float(extra[1]))

        def _look_ahead(self, est, left, extra, guide=None, horizon_s=None):  # noqa: ANN001, ANN202
            if horizon_s is None:
                return 0.2, 0.2
            self.horizons.append(horizon_s)
            return 0.2, self.rest_gap_m

    nav = InTheEstimate(lambda extra: planner, planner, outcome, PATH_GAIT)
    nav.asked.clear()
    start = np.asarray(outcome.plan.legs[0].com_m[0])
    stops = []

    def frames(t0: float, seconds: float) -> None:
        for k in range(int(seconds * 30)):
            t = t0 + k / 30
            d = nav.on_frame(t, pose_at(t, start), np.array([*start, 0.0]), 0, 0.0)
            stops.append(d.stop)
            nav._worker.submit(lambda: None).result()
            nav._side.submit(lambda: None).result()

    try:
        frames(0.0, 1.0)
        assert nav.asked == [] and nav.horizons == []  # the plan's own water: nothing to check
        nav.current.value_m_s = np.array([0.0, 0.012])  # the camera's drift says 12 mm/s north
        frames(1.0, 1.0)
        # the rest of the plan (to its goal, beyond the 5 s look-ahead) swum in it: still clear
        assert len(nav.horizons) == 1 and nav.horizons[0] > nav.replan_horizon_s
        assert nav.asked == []  # a plan the new water does not break is kept
        nav.current.value_m_s = np.array([0.0, 0.02])  # it moves on by 8 mm/s, and now the
        nav.rest_gap_m = 0.0  # rest of the plan swims into something: replanned in it, once
        frames(2.0, 2.0)
        assert len(nav.horizons) == 2
        assert len(nav.asked) == 1 and nav.asked[0][1] == (0.0, 0.02)
        assert nav.events[-1]["reason"] == "current_estimate"
        assert nav.failures == 0 and set(stops) == {None}  # its failure keeps the plan
    finally:
        nav.close()


def test_a_replan_in_a_moved_estimate_gets_the_calm_budget_and_starts_when_it_ends(open_plan):
    planner, outcome = open_plan

    class Timed(FailingInTheTestsEstimate):
        """Replans fail and record their start and budget; the look-ahead is clear, the whole
        rest of the plan in the moved estimate is not."""

        asked: list[tuple[float, float, float]] = []
        walls: list[float] = []

        def _asked(self, est, start_step, extra, deadline_s):  # noqa: ANN001, ANN202
            return est.t_s, start_step * self.planner.twin.dt_s, deadline_s

        def _look_ahead(self, est, left, extra, guide=None, horizon_s=None):  # noqa: ANN001, ANN202
            return (0.2, 0.2) if horizon_s is None else (0.2, 0.0)

        def _request(self, *args):  # noqa: ANN002, ANN202
            super()._request(*args)
            self.walls.append(self._job.wall_request_s)  # when its deadline was counted from

    nav = Timed(lambda extra: planner, planner, outcome, PATH_GAIT, replan_budget_s=1.0,
                calm_budget_s=CALM_REPLAN_BUDGET_S)
    nav.asked.clear()
    start = np.asarray(outcome.plan.legs[0].com_m[0])
    try:
        nav.current.value_m_s = np.array([0.0, 0.02])
        for k in range(60):
            t = k / 30
            nav.on_frame(t, pose_at(t, start), np.array([*start, 0.0]), 0, 0.0)
            nav._worker.submit(lambda: None).result()
            nav._side.submit(lambda: None).result()
        assert len(nav.asked) == 1 and nav.events[-1]["reason"] == "current_estimate"
        t_request, t_start, deadline = nav.asked[0]
        assert nav.events[-1]["budget_s"] == nav.calm_budget_s == CALM_REPLAN_BUDGET_S > 1.0
        assert float(deadline) - nav.walls[0] == pytest.approx(nav.calm_budget_s)
        # its start is the state predicted for when the budget ends, not a lead of 0.3-0.9 s
        assert nav.calm_budget_s <= t_start - t_request <= nav.calm_budget_s + 0.3 + 1e-9
        # a replan on leaving the corridor keeps the 1 s and the short lead
        nav.asked.clear()
        nav.walls.clear()
        off = np.array([0.8, 1.4])
        for k in range(60, 90):
            t = k / 30
            nav.on_frame(t, pose_at(t, off), np.array([*off, 0.0]), 0, 0.0)
            nav._worker.submit(lambda: None).result()
            nav._side.submit(lambda: None).result()
        assert nav.asked and nav.events[-1]["reason"] == "left_corridor"
        t_request, t_start, deadline = nav.asked[0]
        assert nav.events[-1]["budget_s"] == 1.0
        assert float(deadline) - nav.walls[0] == pytest.approx(1.0)
        assert t_start - t_request <= nav.max_lead_s + 0.3 + 1e-9
    finally:
        nav.close()


def test_leaving_the_corridor_cuts_a_calm_replan_short_and_replans_at_once_with_one_second(
        open_plan):
    planner, outcome = open_plan

    class Patient(FailingInTheTestsEstimate):
        """A calm replan searches until its deadline (which a cut brings forward), a 1 s one
        fails at once; the look-ahead is clear, the rest of the plan in the estimate is not."""

        asked: list[float] = []

        def _asked(self, est, start_step, extra, deadline_s):  # noqa: ANN001, ANN202
            return float(deadline_s) - time.monotonic()  # the budget left when it returns

        def _replan(self, est, left, start_step, extra, guide=None,  # noqa: ANN001, ANN202
                    deadline_s=None):  # noqa: ANN001
            if float(deadline_s) - time.monotonic() > 1.5:  # the calm one: until its deadline
                while time.monotonic() < float(deadline_s):
                    time.sleep(0.005)
            return super()._replan(est, left, start_step, extra, guide, deadline_s)

        def _look_ahead(self, est, left, extra, guide=None, horizon_s=None):  # noqa: ANN001, ANN202
            return (0.2, 0.2) if horizon_s is None else (0.2, 0.0)

    nav = Patient(lambda extra: planner, planner, outcome, PATH_GAIT, replan_budget_s=1.0,
                  calm_budget_s=CALM_REPLAN_BUDGET_S)
    nav.asked.clear()
    start = np.asarray(outcome.plan.legs[0].com_m[0])
    off = np.array([0.8, 1.4])
    try:
        nav.current.value_m_s = np.array([0.0, 0.02])
        t, k = 0.0, 0
        while nav._job is None and k < 60:  # on the plan: the moved estimate asks a calm replan
            t = k / 30
            nav.on_frame(t, pose_at(t, start), np.array([*start, 0.0]), 0, 0.0)
            nav._side.submit(lambda: None).result()
            k += 1
        calm = nav._job
        assert calm is not None and calm.reason == "current_estimate" and calm.budget_s == 3.0
        wall0 = time.monotonic()
        stops = []
        while not any(e["reason"] == "left_corridor" for e in nav.events) and k < 400:
            t = k / 30  # the robot leaves its corridor while the calm replan searches
            stops.append(nav.on_frame(t, pose_at(t, off), np.array([*off, 0.0]), 0, 0.0).stop)
            time.sleep(0.01)
            k += 1
        cut = next(e for e in nav.events if e["reason"] == "current_estimate")
        assert cut["cut_for"] == "left_corridor" and calm.deadline is not None
        assert calm.deadline.cut and cut["wall_s"] < 1.5  # back long before its 3 s
        assert time.monotonic() - wall0 < 2.5
        urgent = next(e for e in nav.events if e["reason"] == "left_corridor")
        assert urgent["budget_s"] == 1.0 and "cut_for" not in urgent
        assert cut["t_request_s"] < cut["t_cut_s"] <= urgent["t_request_s"]
        assert len(nav.asked) == 2 and nav.asked[0] <= 0.0 < nav.asked[1] <= 1.0  # cut; 1 s
        assert set(stops) == {None}  # no stop while the calm replan was cut and the urgent ran
    finally:
        nav.close()


def test_a_contact_far_ahead_cuts_a_calm_replan_short_instead_of_stopping_the_robot(open_plan):
    from eelhost.planning.replan import _Job

    planner, outcome = open_plan
    nav = TankReplanner(lambda extra: planner, planner, outcome, PATH_GAIT,
                        replan_budget_s=1.0, lookahead_s=0.0, calm_budget_s=3.0)
    start = np.asarray(outcome.plan.legs[0].com_m[0])
    try:
        for k in range(15):
            t = k / 30
            assert nav.on_frame(t, pose_at(t, start), np.array([*start, 0.0]), 0, 0.0).stop is None
        deadline = Deadline(time.monotonic() + 3.0)
        nav._job = _Job(Future(), 0.5, time.monotonic(), 3.5, "current_estimate", 4.0, 3.0,
                        deadline)
        ahead: Future = Future()
        ahead.set_result(Ahead(-0.005, -0.025, 9.0))  # contact 8.5 s ahead: time to replan
        nav._lookahead = ahead
        d = nav.on_frame(0.5, pose_at(0.5, start), np.array([*start, 0.0]), 0, 0.0)
        assert d.stop is None
        assert deadline.cut and float(deadline) <= time.monotonic()
        assert nav._job.cut_for == "predicted_contact"
        assert nav._urgent_after_cut == "predicted_contact"
    finally:
        nav._job = None
        nav.close()


def test_a_deadline_only_comes_earlier_and_reads_as_its_present_value():
    d = Deadline(10.0)
    assert float(d) == 10.0 and not d.cut
    d.cut_to(12.0)  # a cut never moves it later
    assert float(d) == 10.0 and d.cut
    d.cut_to(4.0)
    assert float(d) == 4.0 and d.cut_at_s == 4.0


def test_a_search_stops_at_a_deadline_cut_while_it_runs(open_plan):
    planner, _ = open_plan
    deadline = Deadline(time.monotonic() + 600.0)
    asked = []

    def reserve() -> float:  # asked before every batch: the first one cuts the deadline
        asked.append(1)
        deadline.cut_to(time.monotonic())
        return 0.0

    plan = planner.search.plan(deadline_s=deadline, reserve_s=reserve)
    assert plan.status == "out_of_time" and not plan.found
    assert plan.expansions <= planner.search.settings.batch
    assert len(asked) == 2  # the batch before the cut ran; the next one saw it


@pytest.mark.parametrize("budget_s", [3.0, 1.0])
def test_contact_ahead_before_a_calm_replan_can_steer_stops_the_robot_before_its_start(
        open_plan, budget_s):
    from eelhost.planning.replan import _Job

    planner, outcome = open_plan
    nav = TankReplanner(lambda extra: planner, planner, outcome, PATH_GAIT,
                        replan_budget_s=1.0, lookahead_s=0.0, calm_budget_s=3.0)
    start = np.asarray(outcome.plan.legs[0].com_m[0])
    try:
        for k in range(15):  # frames for an estimate, no look-ahead, no replan
            t = k / 30
            assert nav.on_frame(t, pose_at(t, start), np.array([*start, 0.0]), 0, 0.0).stop is None
        # a replan in flight, its start 3 s after its request (a calm one's, or by a test's
        # hand a 1 s one's), and a look-ahead that swims the present plan into contact in 1 s
        nav._job = _Job(Future(), 0.5, time.monotonic(), 3.5, "current_estimate",
                        0.5 + budget_s + 0.5, budget_s)
        ahead: Future = Future()
        ahead.set_result(Ahead(-0.005, -0.025, 1.5))
        nav._lookahead = ahead
        d = nav.on_frame(0.5, pose_at(0.5, start), np.array([*start, 0.0]), 0, 0.0)
    finally:
        nav._job = None
        nav.close()
    if budget_s > 1.0:  # not waited for until its start: its plan could not steer in time
        assert d.stop == "no_safe_continuation" and "has not come back" in d.detail
    else:  # a replan within its start is waited for, as before
        assert d.stop is None


def test_a_replan_whose_search_is_slow_stops_at_its_budget_without_the_fallback_searches(
        open_plan):
    # every batch of the search takes 0.4 s more: with a 0.6 s budget the replan comes back
    # out of time after a batch or two, and neither the goal approach nor the recovery
    # (each only within what is left of the budget) runs after it
    planner, outcome = open_plan
    tried: list[str] = []

    class Counted:
        """The planner, counting the searches asked of it under ``name``."""

        def __init__(self, name: str) -> None:
            self.name = name

        def __getattr__(self, attr: str):  # noqa: ANN204
            return getattr(planner, attr)

        def plan(self, *args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            tried.append(self.name)
            return planner.plan(*args, **kwargs)

    def other(name):  # noqa: ANN001, ANN202
        return lambda extra: Counted(name)

    nav = TankReplanner(lambda extra: planner, planner, outcome, PATH_GAIT,
                        goal_planner_for=other("goal approach"),
                        recovery_planner_for=other("recovery"), replan_budget_s=0.6)
    expand = planner.search._expand

    def slow_expand(*args):  # noqa: ANN002, ANN202
        time.sleep(0.4)
        return expand(*args)

    planner.search._expand = slow_expand  # type: ignore[method-assign]
    try:
        run = swimming_state(2.0)
        est = BodyStateEstimator(planner.model, PATH_GAIT)
        for t in np.arange(0.0, 2.0 + 1e-9, 1 / 30):
            x = np.array([np.interp(t, run.t_s, run.states[:, i])
                          for i in range(run.states.shape[1])])
            est.observe(t, x[N : N + 2], x[:N])
        e = est.estimate()
        assert e is not None
        wall0 = time.monotonic()
        result = nav._replan(e, [(2.5, 1.3)], 240, np.zeros(2), None, wall0 + 0.6)
        wall = time.monotonic() - wall0
    finally:
        del planner.search._expand
        nav.close()
    got = result[0]
    assert got.status == "out_of_time" and not got.found, got.message
    assert got.plan.expansions <= 2 * planner.search.settings.batch
    assert tried == []
    assert wall < 5.0  # generous: the budget, a batch in progress and the prediction


def test_a_moved_current_estimate_has_its_planner_built_before_the_next_replan(open_plan):
    # a window says the water moves 0.05 m/s towards +y: the estimate moves by 0.6 of it, and the
    # planner in that estimate is built on the replan worker at once; a replan asked for in the
    # same estimate then builds none (the build took 0.4-0.9 s of a 1 s budget under load)
    planner, outcome = open_plan
    built: list[tuple[float, float]] = []

    def planner_for(extra):  # noqa: ANN001, ANN202
        built.append((float(extra[0]), float(extra[1])))
        return planner

    nav = TankReplanner(planner_for, planner, outcome, PATH_GAIT)
    try:
        start, end = estimate_at(1.0), estimate_at(3.0)
        window = CurrentWindow(start, end, (2.5, 1.3), None, np.zeros(2))
        swum: Future = Future()
        swum.set_result(end.state[N : N + 2] - np.array([0.0, 0.05]) * window.span_s)
        nav._window_jobs.append((swum, window))
        pose = np.array([end.state[N], end.state[N + 1], float(np.mean(end.state[:N]))])
        assert nav._estimate_current(end, [(2.5, 1.3)], pose)
        assert nav._prebuild is not None
        nav._prebuild.result(timeout=60)
        assert len(built) == 1 and built[0] == pytest.approx((0.0, 0.03), abs=1e-9)
        nav._prepare_planner(nav.current.value_m_s.copy())
        assert len(built) == 1
    finally:
        nav.close()


BESIDE = {
    "name": "beside",
    "tank": {"size_m": [3.0, 2.0]},
    "start": {"position_m": [0.6, 1.0], "heading_deg": 0.0},
    "goal": {"position_m": [2.3, 1.1], "radius_m": 0.2},
    "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
    # a disc the present waypoints' route grazes (the capsule about 1 mm clear in the twin)
    "obstacles": [{"kind": "circle", "centre_m": [1.55, 0.88], "radius_m": 0.1}],
}
BESIDE_LEFT = [(1.9, 1.1), (2.3, 1.1)]


@pytest.fixture(scope="module")
def grazing():
    """The planner of BESIDE (checked as the benchmark's, no unknown current), the swimming
    robot's predicted start 0.6 s after its estimate at 3 s, and that start's step."""
    planner = Planner(parse_world(BESIDE, "beside"), ROBOT, MODEL, unknown_current_m_s=0.0)
    step = int(round(3.0 / 0.01)) + 60
    state = predict_state(planner.twin, estimate_at(3.0), BESIDE_LEFT, step)
    assert state is not None
    return planner, state, step


def _true_gap(planner: Planner, state, step: int, waypoints) -> float:  # noqa: ANN001
    """The benchmark's shapely body's smallest gap over the twin's swim of ``waypoints`` to the
    goal disc (geometry written apart from the replanner's)."""
    from eelhost.benchmarks.closed_loop import true_clearance_m
    from eelhost.planning.search import goal_mask, leg_start_guide

    runs = planner.twin.run([waypoints], 30.0, states=state[None], start_steps=[step], stride=1,
                            guidance=[leg_start_guide(state, N)])
    states = runs.states[0][np.isfinite(runs.states[0][:, 0])]
    inside = np.flatnonzero(goal_mask(planner.world, states[:, N : N + 2]))
    assert inside.size, "never reaches the goal"
    return float(true_clearance_m(planner.world, planner.model, states[: inside[0] + 1]).min())


def _present_plan_of_beside() -> Plan:
    """A present plan along BESIDE_LEFT, its goal expected at 30 s (the repair's horizon)."""
    com = np.column_stack([np.linspace(0.6, 2.3, 50), np.linspace(1.0, 1.1, 50)])
    return Plan(True, "found", "", [Leg(BESIDE_LEFT[0], 1.3, 0.0, 0, 1500, com, 0.05),
                                    Leg(BESIDE_LEFT[1], 0.4, 0.0, 1500, 2500, com[-1:], 0.05,
                                        goal=True)], 30.0)


def test_the_shift_repair_moves_a_grazing_route_off_the_obstacle_and_keeps_the_goal(grazing):
    from eelhost.planning.replan import shift_repair
    from eelhost.planning.search import leg_start_guide

    planner, state, step = grazing
    outcome = shift_repair(planner, state, step, leg_start_guide(state, N), BESIDE_LEFT, 30.0)
    assert outcome is not None and outcome.found, "no shift passed"
    assert outcome.message.startswith("shift repair:"), outcome.message
    moved = outcome.plan.waypoints_m
    assert len(moved) == 2 and moved[-1] == BESIDE_LEFT[-1] and moved[0] != BESIDE_LEFT[0]
    assert outcome.plan.start_guide == leg_start_guide(state, N)
    # the corridor is the twin's swim from the start
    assert np.hypot(*(outcome.plan.legs[0].com_m[0] - state[N : N + 2])) < 0.02
    # the benchmark's own body: the repaired route clear, and clearer than the grazing one
    before = _true_gap(planner, state, step, BESIDE_LEFT)
    after = _true_gap(planner, state, step, moved)
    assert after > 0.03 and after > before + 0.02


def test_the_shift_repair_refuses_a_route_within_its_margin_even_when_every_check_run_is_clear(
        grazing, monkeypatch):
    # shifts of 2 mm only, and a check over the fits alone (the estimated water's own run) with
    # no check margin: the grazing route's variants swim the capsule a few mm clear, so every
    # check run passes; only the repair's own margin in the estimated water refuses them
    import eelhost.planning.replan as replan
    from eelhost.planning.search import leg_start_guide

    planner, state, step = grazing
    monkeypatch.setattr(replan, "SHIFT_RADII_M", (0.002,))
    monkeypatch.setattr(planner, "waters", lambda attempt: [])
    monkeypatch.setattr(planner, "check_margin_m", 0.0)
    guide = leg_start_guide(state, N)
    monkeypatch.setattr(replan, "SHIFT_MARGIN_M", 0.0)
    grazed = replan.shift_repair(planner, state, step, guide, BESIDE_LEFT, 30.0)
    assert grazed is not None and grazed.found, "nothing clear even without a margin"
    nominal_mm = float(grazed.message.split("the capsule ")[1].split(" mm")[0])
    assert 0.0 <= nominal_mm < 10.0, grazed.message
    monkeypatch.setattr(replan, "SHIFT_MARGIN_M", 0.01)
    assert replan.shift_repair(planner, state, step, guide, BESIDE_LEFT, 30.0) is None
    # and without the repair's own margin, the planner's check margin refuses them as it refuses
    # a searched plan's check runs that come that close
    monkeypatch.setattr(replan, "SHIFT_MARGIN_M", 0.0)
    monkeypatch.setattr(planner, "check_margin_m", 0.03)
    assert replan.shift_repair(planner, state, step, guide, BESIDE_LEFT, 30.0) is None


def test_a_shift_repaired_route_keeps_the_margin_in_the_estimated_water(grazing):
    from eelhost.planning.replan import SHIFT_MARGIN_M, shift_repair
    from eelhost.planning.search import goal_mask, leg_start_guide

    planner, state, step = grazing
    outcome = shift_repair(planner, state, step, leg_start_guide(state, N), BESIDE_LEFT, 30.0)
    assert outcome is not None and outcome.found
    # the repaired route re-swum from the start in the estimated water, judged on its own
    runs = planner.twin.run([outcome.plan.waypoints_m], 30.0, states=state[None],
                            start_steps=[step], stride=3, guidance=[leg_start_guide(state, N)])
    states = runs.states[0][np.isfinite(runs.states[0][:, 0])]
    inside = np.flatnonzero(goal_mask(planner.world, states[:, N : N + 2]))
    assert inside.size
    gaps = body_clearance_m(planner.world, planner.clearance, planner.model,
                            states[: inside[0] + 1])
    assert float(gaps.min()) >= SHIFT_MARGIN_M


def test_a_replan_whose_searches_all_find_nothing_is_shift_repaired_only_when_asked_to(grazing):
    planner, state, step = grazing
    nothing = _Scripted(planner, "exhausted", np.inf)  # every search of the replan: no manoeuvre
    first = _present_plan_of_beside()
    got = {}
    for on in (False, True):
        nav = TankReplanner(lambda extra: nothing, nothing,  # type: ignore[arg-type]
                            Outcome(first, "found", ""), PATH_GAIT,
                            goal_planner_for=lambda extra: nothing,
                            recovery_planner_for=lambda extra: nothing, shift_repair=on)
        try:
            # a start 0.6 s ahead of the estimate at 3 s: the fixture's predicted state
            got[on], start, *_ = nav._replan(estimate_at(3.0), BESIDE_LEFT, step, np.zeros(2))
        finally:
            nav.close()
        assert np.allclose(start, state)
    assert not got[False].found and got[False].status == "exhausted"
    assert got[True].found and got[True].message.startswith("shift repair:"), got[True].message


def test_a_replan_whose_searches_used_up_the_budget_is_still_shift_repaired(grazing, monkeypatch):
    # the searches stop at the budget with nothing (out_of_time): the repair still runs, within
    # its grace past the budget (made long here so the machine's load cannot decide the test)
    import eelhost.planning.replan as replan

    monkeypatch.setattr(replan, "SHIFT_GRACE_S", 600.0)
    planner, state, step = grazing
    late = _Scripted(planner, "out_of_time", np.inf)
    first = _present_plan_of_beside()
    nav = TankReplanner(lambda extra: late, late,  # type: ignore[arg-type]
                        Outcome(first, "found", ""), PATH_GAIT, replan_budget_s=1e-6)
    try:
        got, *_ = nav._replan(estimate_at(3.0), BESIDE_LEFT, step, np.zeros(2),
                              deadline_s=time.monotonic() - 1.0)
    finally:
        nav.close()
    assert got.found and got.message.startswith("shift repair:"), got.message


def test_the_shift_repair_keeps_the_present_waypoints_when_they_hold_from_where_the_robot_is():
    # nothing near the route: no shift is 10 mm clearer, so the route is kept as it is, re-swum
    # from the robot's start (a robot that left its corridor on a route that still holds)
    from eelhost.planning.replan import shift_repair
    from eelhost.planning.search import leg_start_guide

    planner = Planner(parse_world({**BESIDE, "obstacles": []}, "clear"), ROBOT, MODEL,
                      unknown_current_m_s=0.0)
    step = int(round(3.0 / 0.01)) + 60
    left = [(1.6, 1.0), (2.3, 1.0)]
    state = predict_state(planner.twin, estimate_at(3.0), left, step)
    assert state is not None
    outcome = shift_repair(planner, state, step, leg_start_guide(state, N), left, 30.0)
    assert outcome is not None and "kept as they are" in outcome.message, outcome
    assert outcome.plan.waypoints_m == left


def test_the_benchmarks_summary_counts_the_runs_retried_before_a_predicted_contact():
    from eelhost.benchmarks.closed_loop import WorldResult, summary_lines

    plain = WorldResult(5000, True, "found", "arrived", reached=True, min_clearance_m=0.05)
    retried = WorldResult(5001, True, "found", "arrived", reached=True, min_clearance_m=0.04,
                          retries_before_contact=2)
    stopped = WorldResult(5002, True, "found", "no_safe_continuation", min_clearance_m=0.03,
                          retries_before_contact=1)
    lines = summary_lines([plain, retried, stopped])
    assert ("- replans retried at once before a predicted contact instead of a stop: 3, in 2 "
            "runs (1 of them reached the goal)") in lines
    assert not any("retried" in line for line in summary_lines([plain]))


# -- an earlier replan (docs/planning.md, "An earlier replan") ----------------------------------


class EarlyAhead(FailingInTheTestsEstimate):
    """The look-ahead swims the capsule ``bare_m`` from something (``capsule_m`` the same), the
    outline 100 mm clear, the rest of the plan in a moved estimate ``rest_m``; replans fail at
    once (exhausted), or give ``found`` when set, or the first one ``hold`` (``current_estimate``
    or ``early_margin``) waits until its deadline is cut or passes; each call records its
    estimate's time and its budget left."""

    asked: list
    fallbacks: list
    bare_m = 0.02
    outline_m = 0.1
    near_in_s = math.inf
    rest_m = 0.2
    found: Outcome | None = None
    hold = False

    def _asked(self, est, start_step, extra, deadline_s):  # noqa: ANN001, ANN202
        return est.t_s, float(deadline_s) - time.monotonic()

    def _replan(self, est, left, start_step, extra, guide=None,  # noqa: ANN001, ANN202
                deadline_s=None, fallbacks=True):  # noqa: ANN001
        self.fallbacks.append(fallbacks)
        if self.hold and not self.asked:
            while not deadline_s.cut and time.monotonic() < float(deadline_s):
                time.sleep(0.005)
        result = super()._replan(est, left, start_step, extra, guide, deadline_s)
        return result if self.found is None else (self.found, *result[1:])

    def _look_ahead(self, est, left, extra, guide=None, horizon_s=None):  # noqa: ANN001, ANN202
        if horizon_s is not None:
            return Ahead(0.2, self.rest_m)
        return Ahead(self.outline_m, self.bare_m, math.inf, est.t_s + self.near_in_s,
                     self.bare_m)


def early_nav(open_plan, early_margin_m=0.03, **kwargs):  # noqa: ANN001, ANN201
    planner, outcome = open_plan
    nav = EarlyAhead(lambda extra: planner, planner, outcome, PATH_GAIT, replan_budget_s=1.0,
                     calm_budget_s=CALM_REPLAN_BUDGET_S, early_margin_m=early_margin_m, **kwargs)
    nav.asked, nav.fallbacks = [], []
    return nav, np.asarray(outcome.plan.legs[0].com_m[0])


def frames_at(nav: TankReplanner, t0: float, seconds: float, com, until=None) -> list:  # noqa: ANN001
    """Frames of the robot at ``com`` from ``t0``, its workers' jobs done after each (when
    ``until`` is given: the frames go on, 10 ms of wall time each, until ``until()``)."""
    decisions = []
    for k in range(int(seconds * 30)):
        t = t0 + k / 30
        decisions.append(nav.on_frame(t, pose_at(t, com), np.array([*com, 0.0]), 0, 0.0))
        if until is None:
            nav._worker.submit(lambda: None).result()
        elif until():
            break
        else:
            time.sleep(0.01)
        nav._side.submit(lambda: None).result()
    return decisions


@pytest.mark.parametrize(("early_margin_m", "bare_m", "asked"),
                         [(0.03, 0.02, True), (0.03, 0.04, False), (None, 0.02, False)])
def test_an_early_replan_that_finds_nothing_keeps_the_plan_counts_no_failure_and_backs_off(
        open_plan, early_margin_m, bare_m, asked):
    nav, start = early_nav(open_plan, early_margin_m)
    nav.bare_m = bare_m
    try:
        decisions = frames_at(nav, 0.0, 5.0, start)
    finally:
        nav.close()
    assert {d.stop for d in decisions} == {None} and not any(d.waypoints for d in decisions)
    assert nav.failures == 0
    if not asked:  # outside the early margin, or the margin off: the plan swims on unreplanned
        assert nav.asked == [] and len(nav.events) == 1
        return
    replans = nav.events[1:]
    assert len(replans) >= 2 and {e["reason"] for e in replans} == {"early_margin"}
    assert {e["budget_s"] for e in replans} == {1.0}  # the replan budget, not the calm one's
    assert set(nav.fallbacks) == {False}  # the planner alone: a plan at the world's margin
    assert all(0.5 < left <= 1.0 for _, left in nav.asked)
    gaps = np.diff([t for t, _ in nav.asked])
    assert gaps[0] >= 1.0 - 0.05  # backs off 1 s, then 2 s, never one replan per look-ahead
    assert len(gaps) < 2 or gaps[1] >= 2.0 - 0.05
    assert nav.record()["early_margin_m"] == 0.03


def test_an_early_replan_that_finds_a_plan_switches_it_in(open_plan):
    nav, start = early_nav(open_plan)
    nav.found = open_plan[1]
    try:
        decisions = frames_at(nav, 0.0, 2.0, start)
    finally:
        nav.close()
    switched = [d for d in decisions if d.waypoints]
    assert switched and switched[0].waypoints == list(open_plan[1].plan.waypoints_m)
    first = nav.events[1]
    assert first["reason"] == "early_margin" and first["status"] == "found"
    assert "t_switch_s" in first and nav.failures == 0 and nav.replans >= 1
    # the new plan swims within the early margin too (the look-ahead says so): the next early
    # replan backs off as after one that found nothing, not one per look-ahead
    asked = [t for t, _ in nav.asked]
    assert len(asked) >= 2 and np.diff(asked)[0] >= 1.0 - 0.05


@pytest.mark.parametrize(("held", "need"), [("early_margin", "left_corridor"),
                                            ("early_margin", "predicted_contact"),
                                            ("current_estimate", "early_margin")])
def test_a_more_urgent_need_cuts_a_replan_in_flight_short_and_is_replanned_at_once(
        open_plan, held, need):
    nav, start = early_nav(open_plan)
    nav.hold = True
    if held == "current_estimate":  # a calm replan: the look-ahead clear, the rest of the plan
        nav.bare_m, nav.rest_m = 0.2, 0.0  # in the moved estimate not
        nav.current.value_m_s = np.array([0.0, 0.02])
    try:
        frames_at(nav, 0.0, 2.0, start, until=lambda: nav._job is not None)
        job = nav._job
        assert job is not None and job.reason == held and job.deadline is not None
        t0, com = 2.0, start
        if need == "left_corridor":
            com = np.array([0.8, 1.4])
        elif need == "predicted_contact":
            nav.bare_m = 0.005  # within the look-ahead's 10 mm: the urgent replan
        else:
            nav.bare_m = 0.02  # within the early margin: a calm replan's 3 s start is too late
        decisions = frames_at(nav, t0, 4.0, com,
                              until=lambda: len(nav.events) >= 3 or nav.failures > 0)
    finally:
        nav.close()
    assert {d.stop for d in decisions} == {None}
    assert job.deadline.cut and len(nav.asked) == 2
    cut, urgent = nav.events[1], nav.events[2]
    assert cut["reason"] == held and cut["cut_for"] == need
    assert urgent["reason"] == need and urgent["budget_s"] == 1.0 and "cut_for" not in urgent
    assert nav.asked[0][1] <= 0.0 < nav.asked[1][1] <= 1.0  # the cut one's deadline had come
    # the cut replan counted no failure; the urgent one's failure counts when it is urgent
    assert nav.failures == (0 if need == "early_margin" else 1)
    assert nav.fallbacks == [held != "early_margin", need != "early_margin"]


def test_the_early_margin_is_judged_over_a_longer_horizon_than_the_urgent_replan():
    # the disc some 4 s ahead, the urgent replan's horizon 3 s: the capsule clear there (no
    # urgent replan), the bare gap over the early horizon (5 s) within the early margin
    planner, outcome, e = _disc_some_4_s_ahead()
    verdicts = []
    for early in (None, 0.03):
        nav = TankReplanner(lambda extra: planner, planner, outcome, PATH_GAIT,
                            replan_horizon_s=3.0, early_margin_m=early, early_horizon_s=5.0)
        try:
            verdicts.append(nav._look_ahead(e, [(2.5, 1.3)], np.zeros(2)))
        finally:
            nav.close()
    plain, early = verdicts
    assert plain.capsule_m == pytest.approx(early.capsule_m)
    assert early.capsule_m > 0.01 + 0.005  # clear over 3 s: no urgent replan
    assert early.near_s == plain.near_s == math.inf
    assert plain.bare_m == pytest.approx(plain.capsule_m)  # 3 s only without the early margin
    assert early.bare_m < 0.01 < 0.03  # the disc within the early horizon: an early replan


@pytest.mark.parametrize("failures", [0, 1])
def test_an_early_replan_in_flight_leaves_the_stop_after_a_failure_as_without_it(
        open_plan, failures):
    # the outline comes within the margin 0.5 s ahead while an early replan runs: too near for
    # another replan after a failure (stopped at once, as with no replan running), while before
    # any failure the urgent replan is asked as soon as the cut early one is back
    nav, start = early_nav(open_plan)
    nav.hold = True
    try:
        frames_at(nav, 0.0, 2.0, start, until=lambda: nav._job is not None)
        assert nav._job is not None and nav._job.reason == "early_margin"
        nav.failures = failures  # a replan failed before, its back-off over
        nav.bare_m, nav.outline_m, nav.near_in_s = -0.01, 0.005, 0.5
        decisions = frames_at(nav, 2.0, 3.0, start,
                              until=lambda: len(nav.events) >= 3 or nav.failures > failures)
    finally:
        nav.close()
    stops = [d for d in decisions if d.stop]
    if failures:
        assert stops and stops[0].stop == "no_safe_continuation"
        assert "the last replan failed" in stops[0].detail
    else:  # the urgent replan is asked; a stop comes only on its own failure
        assert nav.events[1]["cut_for"] == "predicted_contact"
        assert nav.events[2]["reason"] == "predicted_contact"
        assert all(d.detail.startswith(f"replanning at t = {nav.events[2]['t_request_s']:.2f} s")
                   for d in stops)


def test_early_replans_resume_after_a_failed_replans_back_off(open_plan):
    nav, start = early_nav(open_plan)
    nav.failures, nav._next_try_s = 1, 3.0  # a failed replan kept the plan, next try at 3 s
    try:
        frames_at(nav, 0.0, 4.0, start)
    finally:
        nav.close()
    assert nav.asked and all(t >= 3.0 - 0.7 for t, _ in nav.asked)  # the estimate's time
    assert {e["reason"] for e in nav.events[1:]} == {"early_margin"} and nav.failures == 1


def test_an_early_replan_with_a_longer_budget_starts_when_it_ends(open_plan):
    nav, start = early_nav(open_plan, early_budget_s=2.0)
    try:
        frames_at(nav, 0.0, 2.0, start)
    finally:
        nav.close()
    first = nav.events[1]
    assert first["reason"] == "early_margin" and first["budget_s"] == 2.0
    assert 1.0 < nav.asked[0][1] <= 2.0  # its deadline 2 s after the request
    # the state predicted for when the budget ends, as a calm replan's, not a lead of 0.3-0.9 s
    assert 2.0 <= first["t_start_s"] - first["t_request_s"] <= 2.0 + 0.3 + 1e-9


def _away_run():
    """The robot swimming at 70 degrees off the tank's bottom wall, from (1, 1) m, for 3.5 s."""
    sc = Scenario.swimming(PATH_GAIT, name="away", waypoints_m=[(2.0, 3.75)], duration_s=3.5,
                           start_position_m=(1.0, 1.0), start_heading_deg=70.0)
    return simulate_closed_loop(ROBOT, sc, LoopOptions(stop_at_goal=False))


def _away_from_the_wall(nav: TankReplanner, run, gap_m: float):  # noqa: ANN001
    """The estimate at 3 s of :func:`_away_run` moved down until its body is ``gap_m`` clear.

    The gap is the check's (:func:`body_clearance_m`).
    """

    def at(t_s: float, dy: float) -> FloatArray:
        x = np.array([np.interp(t_s, run.t_s, run.states[:, i])
                      for i in range(run.states.shape[1])])
        x[N + 1] -= dy
        return x

    lo, hi = 0.0, 2.0
    for _ in range(40):  # the shift that leaves the body gap_m from the wall
        mid = (lo + hi) / 2
        gap = float(body_clearance_m(nav.world, nav.planner.clearance, nav.model,
                                     at(3.0, mid)[None])[0])
        lo, hi = (mid, hi) if gap > gap_m else (lo, mid)
    est = BodyStateEstimator(BODY, PATH_GAIT)
    for t in np.arange(2.5, 3.0 + 1e-9, 1 / 30):
        x = at(t, lo)
        est.observe(t, x[N : N + 2], x[:N])
    e = est.estimate()
    assert e is not None
    return e


def test_a_replan_from_inside_the_margin_escapes_keeping_its_ramp_and_only_above_the_floor(
        open_plan):
    # the water pushed the robot to 20 mm from the bottom wall (inside the check's 30 mm) while it
    # swims away from it: every plan's check fails at its first sample, so no tier finds one;
    # the escape finds a plan whose every check run keeps the margin ramped from the start's gap
    # less 10 mm to 30 mm over 4 s (docs/planning.md, "An escape from inside the margin")
    planner, outcome = open_plan
    # 20 draws (the planner's 60 triple the check's time; the ramp is judged the same way)
    tiers = replan_planners(planner, planner.world, ROBOT, MODEL, PATH_GAIT, {"draws": 20})
    nav = TankReplanner(tiers.planner_for, planner, outcome, PATH_GAIT,
                        goal_planner_for=tiers.goal_planner_for,
                        recovery_planner_for=tiers.recovery_planner_for,
                        escape_planner_for=tiers.escape_planner_for)
    nav.shift_repair = False
    try:
        run = _away_run()
        est = _away_from_the_wall(nav, run, 0.02)
        step = int(round(3.0 / planner.twin.dt_s))
        make, nav.escape_planner_for = nav.escape_planner_for, None
        without, *_ = nav._replan(est, [(2.1, 1.0)], step, np.zeros(2))
        nav.escape_planner_for = make
        got, state, *_ = nav._replan(est, [(2.1, 1.0)], step, np.zeros(2))
        gap = float(body_clearance_m(nav.world, planner.clearance, nav.model, state[None])[0])
        # the floor: a start 5 mm clear gets no escape; one outside the margin needs none
        near = _away_from_the_wall(nav, run, 0.005).state
        far = _away_from_the_wall(nav, run, 0.05).state
        assert nav._escape_gap(near) is None and nav._escape_gap(far) is None
        assert nav._escape_gap(state) == pytest.approx(gap)
    finally:
        nav.close()
    assert not without.found, without.message
    assert 0.01 < gap < planner.check_margin_m  # the predicted start is inside the margin
    assert got.found and got.message.startswith(f"escape from {gap * 1000:.0f} mm"), got.message
    assert len(got.checks) > 20  # the fits and the draws of the check
    for swum in got.checks:
        clear = body_clearance_m(nav.world, planner.clearance, nav.model, swum.states)
        t = swum.t_s - swum.t_s[0]
        assert swum.ok and clear.min() > ESCAPE_FLOOR_M  # never nearer than the floor
        assert np.all(clear > escape_margin_m(t, gap, planner.check_margin_m))
        assert clear[t >= ESCAPE_RAMP_S].min() > planner.check_margin_m  # the full margin again
    np.testing.assert_allclose(escape_margin_m(np.array([0.0, 2.0, 4.0, 9.0]), 0.02, 0.03),
                               [0.01, 0.02, 0.03, 0.03])
    assert escape_margin_m(np.array([0.0]), 0.015, 0.03)[0] == ESCAPE_FLOOR_M
