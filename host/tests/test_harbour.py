"""The harbour (docs/planning.md, "The harbour"): a stop the current would carry into something
is made after a short swim to where it stays clear, at the goal and where no continuation exists."""

from __future__ import annotations

import time

import numpy as np
import pytest
from test_tank_restart import MODEL, ROBOT, Blocked, N, pose_at

from eelhost.planning.audit import body_gaps_m
from eelhost.planning.harbour import (
    FINAL_GLIDE_S,
    HARBOUR_CUSHION_M,
    HARBOUR_SWIMS_S,
    StopWindow,
    find_harbour,
    stop_states,
)
from eelhost.planning.planner import Outcome, Planner
from eelhost.planning.replan import (
    HARBOURS_PER_PLAN,
    STOP_BRAKE_S,
    Decision,
    outline_clearance_m,
)
from eelhost.planning.restart import paused_drift, stopped_twin
from eelhost.planning.search import Plan
from eelhost.planning.twin import Twin
from eelhost.planning.world import parse_world
from eelsim.control import braked_gait
from eelsim.scenario import PATH_GAIT


def disc_world(current_m_s: float) -> dict:
    """A disc 0.55 m downstream of the goal's centre, the current flowing towards it."""
    return {
        "name": "disc",
        "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": [0.6, 1.0], "heading_deg": 0.0},
        "goal": {"position_m": [1.3, 1.0], "radius_m": 0.2},
        "current": {"speed_m_s": current_m_s, "direction_deg": 0.0},
        "obstacles": [{"kind": "circle", "centre_m": [1.85, 1.0], "radius_m": 0.15}],
    }


def up_world():
    """The disc world with the goal up the tank: the disc downstream of a body beside the plan."""
    return parse_world({**disc_world(0.03), "goal": {"position_m": [0.6, 1.6], "radius_m": 0.2},
                        "start": {"position_m": [0.6, 0.9], "heading_deg": 90.0}}, "up")


@pytest.fixture(scope="module")
def disc_plan():
    # the plan whose arrival stop drifts into the disc: the planner's own check of that stop
    # (docs/planning.md, "The arrival's stop in the check") would pass it over, and these tests
    # are about the tank's answer to such a stop
    world = parse_world(disc_world(0.03), "disc")
    planner = Planner(world, ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    return world, planner, outcome


def body_at(x_m: float, u_m_s: float) -> np.ndarray:
    """The straight body along +x with its centre of mass at (x, 1), moving at ``u`` along x."""
    state = np.zeros(2 * N + 4)
    state[N : N + 2] = (x_m, 1.0)
    state[2 * N + 2] = u_m_s
    return state


FINAL = StopWindow(lambda t: t + STOP_BRAKE_S, FINAL_GLIDE_S)


def test_the_stop_is_swum_as_the_brake_then_the_straight_glide_as_the_pause_s_drift_swims_it(
        disc_plan):
    # the batched stops of several bodies against restart.paused_drift (one body, the braked
    # run then the straight one, written for the pause): the same motion
    _world, planner, _ = disc_plan
    twin = planner.twin
    starts = np.stack([body_at(1.0, 0.1), body_at(1.2, 0.03)])
    t_s = 6.0
    batched = stop_states(twin, PATH_GAIT, starts, t_s, FINAL, 3)
    for j, start in enumerate(starts):
        one = paused_drift(stopped_twin(twin, braked_gait(PATH_GAIT, t_s)), stopped_twin(twin),
                           start, t_s, t_s + STOP_BRAKE_S, STOP_BRAKE_S + FINAL_GLIDE_S, 3)
        rows = min(len(one), len(batched[j]))
        assert rows > 0.9 * (STOP_BRAKE_S + FINAL_GLIDE_S) / (3 * twin.dt_s)
        assert np.allclose(batched[j, :rows, N : N + 2], one[:rows, N : N + 2], atol=2e-3)
    # braked, the body slows: its speed through the water at the brake's end is below a third
    # of where it started (0.1 m/s forward; the water moves at 0.03 m/s along x)
    braked_end = batched[0, int(round(STOP_BRAKE_S / (3 * twin.dt_s)))]
    assert abs(braked_end[2 * N + 2] - 0.03) < 0.1 / 3


def test_a_harbour_keeps_its_swim_and_its_stop_clear_by_geometry_written_apart(disc_plan):
    world, planner, _ = disc_plan
    twin = planner.twin
    state = body_at(1.3, 0.03)  # carried by the water towards the disc, its nose 0.23 m from it
    t_s = 6.0

    def gap_of(states: np.ndarray, ahead_s: np.ndarray) -> np.ndarray:
        return outline_clearance_m(world, twin.model, states)

    at_once, harbour, clearest = find_harbour(twin, PATH_GAIT, state, t_s, FINAL, gap_of, 0.02)
    # asked for more than any swim keeps: none, and the clearest of all is at least as clear
    _, none, clearest_all = find_harbour(twin, PATH_GAIT, state, t_s, FINAL, gap_of, 1.0)
    assert none is None and clearest_all is not None and clearest is not None
    assert clearest_all.gap_m >= clearest.gap_m >= harbour.gap_m  # type: ignore[union-attr]
    assert at_once.swim_s == 0.0 and at_once.gap_m < 0.01  # stopping here drifts into the disc
    assert harbour is not None and harbour.swim_s in HARBOUR_SWIMS_S
    assert harbour.gap_m > 0.02 and harbour.gap_m == min(harbour.swim_gap_m, harbour.stop_gap_m)
    # swum again, the stop by the pause's code, and judged by the audit's shapely centre line
    dt = twin.dt_s
    swim = twin.run([[harbour.waypoint_m]], harbour.swim_s + 2 * dt, states=state[None],
                    start_steps=[harbour.start_step], stride=1).states[0]
    end_step = int(round(harbour.swim_s / dt))
    swum = swim[: end_step + 1]
    assert np.all(np.isfinite(swum[:, 0]))
    t_end = t_s + end_step * dt
    stop = paused_drift(stopped_twin(twin, braked_gait(PATH_GAIT, t_end)), stopped_twin(twin),
                        swum[-1], t_end, t_end + STOP_BRAKE_S, STOP_BRAKE_S + FINAL_GLIDE_S, 3)
    assert len(stop) > 0.9 * (STOP_BRAKE_S + FINAL_GLIDE_S) / (3 * dt)
    assert float(np.min(body_gaps_m(world, MODEL.swimmer_for(ROBOT), swum[::3]))) > 0.01
    assert float(np.min(body_gaps_m(world, MODEL.swimmer_for(ROBOT), stop))) > 0.01
    # and the stop straight after arriving there, swum the same way, would touch
    now = paused_drift(stopped_twin(twin, braked_gait(PATH_GAIT, t_s)), stopped_twin(twin),
                       state, t_s, t_s + STOP_BRAKE_S, STOP_BRAKE_S + FINAL_GLIDE_S, 3)
    assert float(np.min(body_gaps_m(world, MODEL.swimmer_for(ROBOT), now))) < 0.01


def run_frames(nav, com, seconds: float, until=lambda d: d.stop is not None, blind_s=0.0,
               heading_rad=0.0):
    """Frames of the body seen still at ``com`` (the water carries it: it holds its place).

    ``com`` may be a function of the time instead: the body seen there, straight and headed
    ``heading_rad``. For the first ``blind_s`` the guidance has no filtered pose (the estimate
    gathers frames).
    """
    com_at = com if callable(com) else (lambda _t: com)
    decisions: list[tuple[float, Decision]] = []
    try:
        for k in range(int(seconds * 30)):
            t = k / 30
            seen = com_at(t)
            pose = None if t < blind_s else np.array([*seen, heading_rad])
            d = nav.on_frame(t, pose_at(t, seen, heading_rad), pose, 0, 0.0)
            decisions.append((t, d))
            nav.pace(t)
            if until(d):
                break
            nav._worker.submit(lambda: None).result()
            nav._side.submit(lambda: None).result()
    finally:
        nav.close()
    return decisions


def test_an_arrival_the_current_would_carry_into_an_obstacle_swims_a_harbour_then_arrives(
        disc_plan):
    _world, planner, outcome = disc_plan
    com = (1.3, 1.0)  # in the goal disc
    for harbour in (True, False):
        # holding station off: without the harbour it would hold station before the arrival
        # (test_station.py)
        nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                      harbour=harbour, station_keeping=False)
        decisions = run_frames(nav, com, 6.0, until=lambda d: d.arrived or d.stop is not None,
                               blind_s=0.5)
        t_end, last = decisions[-1]
        assert last.arrived and last.stop is None
        first_t, first = next((t, d) for t, d in decisions if t >= 0.5)
        if not harbour:  # as before: arrived at the first frame seen in the disc
            assert t_end == first_t and not any(d.waypoints for _, d in decisions)
            continue
        assert first.waypoints and not first.arrived  # a harbour swim instead of the arrival
        events = [e for e in nav.events if e["kind"] == "harbour"]
        for event in events:
            assert event["reason"] == "arrived" and event["swim_s"] in HARBOUR_SWIMS_S
            assert event["at_once_gap_m"] <= nav.lookahead_margin_m
            assert event["gap_m"] > nav.lookahead_margin_m + HARBOUR_CUSHION_M
        # the body is seen where it was (this script does not move it): at the harbour's end
        # the stop is judged again, still drifts into the disc, and a second harbour follows;
        # after HARBOURS_PER_PLAN the arrival stands, at the last one's end
        assert len(events) == HARBOURS_PER_PLAN
        assert events[1]["t_request_s"] == pytest.approx(events[0]["t_end_s"])
        assert t_end == pytest.approx(first_t + sum(e["swim_s"] for e in events),
                                      abs=2 / 30 + 1e-9)
        assert "harbour" in last.detail and events[-1]["t_end_s"] == pytest.approx(t_end)
        assert not any(d.arrived for _, d in decisions[:-1])


def test_where_no_continuation_exists_the_harbour_comes_before_the_pause_or_the_final_stop():
    # the goal up the tank, the body seen 0.75 m off the plan's corridor in the disc's stream:
    # every replan is refused, and the stop it leads to would drift into the disc
    world = up_world()
    planner = Planner(world, ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    for restarts in (1, 0):
        # holding station and the least-bad swim off: at a harbour's end either would swim
        # (test_station.py, test_least_bad.py)
        nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                      max_restarts=restarts, station_keeping=False, least_bad=False)
        decisions = run_frames(nav, (1.35, 1.0), 8.0,
                               until=lambda d: d.stop is not None or d.pause)
        events = [e for e in nav.events if e["kind"] == "harbour"]
        t_end, last = decisions[-1]
        assert {e["reason"] for e in events} == {"pause" if restarts else "stop"}
        t_harbour = next(t for t, d in decisions if d.waypoints)  # at the refused replan
        assert t_harbour < 0.5 and events[0]["t_request_s"] == pytest.approx(t_harbour)
        # the body seen still: judged again at the first's end, a second harbour (as above)
        assert len(events) == HARBOURS_PER_PLAN
        assert t_end == pytest.approx(t_harbour + sum(e["swim_s"] for e in events),
                                      abs=2 / 30 + 1e-9)
        # the line eelbot run prints says what the replanner did (it said "replans: 0")
        tally = nav.tally()
        refused = sum(e["kind"] == "replan" and e["status"] != "found" for e in nav.events)
        assert refused >= 1 and tally.startswith(f"0 switched in, {refused} failed (")
        assert tally.endswith(f"{HARBOURS_PER_PLAN} harbour swims")
        if restarts:
            assert last.pause and nav._pause is not None  # then the pause, as before
            assert nav.events[-1]["kind"] == "halt" and "harbour swim" in nav.events[-1]["detail"]
            assert "1 pause, 0 of 1 restarts from rest made" in tally
        else:
            assert last.stop == "no_safe_continuation" and "harbour swim" in last.detail
            assert "pause" not in tally


def test_a_body_braked_in_a_hard_turn_drifts_whole_in_the_twin():
    # swum 3 s round towards its tail in a 0.05 m/s stream, the body is braked mid-turn: its
    # brake's S overshoots the joints' mechanical limit by millimetres of a radian, a flag that
    # ended the drift's run after 0.1 s; the stopped twin swims the whole stop
    world = parse_world({**disc_world(0.05), "obstacles": []}, "stream")
    twin = Planner(world, ROBOT, MODEL, arrival_stop=False).twin
    dt = twin.dt_s
    state = body_at(1.5, 0.05)
    start = int(round(6.0 / dt))
    swum = twin.run([[(-0.5, 1.0)]], 3.0 + 2 * dt, states=state[None], start_steps=[start],
                    stride=1).states[0]
    turning = swum[int(round(3.0 / dt))]
    t_s = (start + int(round(3.0 / dt))) * dt
    stop = stop_states(twin, PATH_GAIT, turning[None], t_s, FINAL, 3)[0]
    assert np.all(np.isfinite(stop[:, 0]))
    assert len(stop) >= (STOP_BRAKE_S + FINAL_GLIDE_S) / (3 * dt)
    # with the robot's own limit, the braked run is flagged and ends early
    limited = stopped_twin(twin, braked_gait(PATH_GAIT, t_s))
    limited = Twin(twin.robot, limited.coefficients, limited.gait, limited.options,
                   limited.current_m_s, limited.acceptance_radius_m, limited.threads,
                   limited.model)
    heading = float(np.mean(turning[:N]))
    far = (turning[N] + 1e3 * np.cos(heading), turning[N + 1] + 1e3 * np.sin(heading))
    runs = limited.run([[far]], STOP_BRAKE_S, states=turning[None],
                       start_steps=[int(round(t_s / dt))], stride=3)
    assert "beyond its limit" in runs.reasons[0]
    assert stopped_twin(twin).robot.joints.limit_rad > np.pi - 1e-12


def test_a_pause_s_rest_budget_leaves_the_final_stop_room_in_the_drift():
    # the stopped body drifts towards the disc and comes within the margin some seconds on: the
    # rest replan's budget ends early enough that, should it fail, the final stop's brake and
    # glide after it still keep clear; without a final brake the budget is longer
    world = up_world()
    planner = Planner(world, ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    budgets = {}
    for brake_s in (STOP_BRAKE_S, 0.0):
        nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                      max_restarts=1, harbour=False, stop_brake_s=brake_s,
                      rest_budget_max_s=8.0)
        try:
            for k in range(30):
                t = k / 30
                d = nav.on_frame(t, pose_at(t, (1.1, 1.0)), np.array([1.1, 1.0, 0.0]), 0, 0.0)
                if d.pause:
                    break
                nav._worker.submit(lambda: None).result()
            pause = nav._pause
            assert pause is not None and pause.drift is not None
            gap, budget, clear_s = pause.drift.result()
        finally:
            nav.close()
        assert gap > nav.lookahead_margin_m  # the pause is clear at first
        if brake_s:  # and the drift comes within the margin within the horizon
            assert clear_s < nav.rest_settle_s + 8.0 + brake_s + FINAL_GLIDE_S - 0.5
        assert budget == pytest.approx(max(nav.rest_budget_s, min(
            8.0, clear_s - nav.rest_settle_s - max(0.5, brake_s + FINAL_GLIDE_S))), abs=1e-9)
        budgets[brake_s] = budget
    assert budgets[STOP_BRAKE_S] < budgets[0.0] - 1.0


class PausedThenRefused(Blocked):
    """A pause judged clear whose rest replan fails at once; no harbour before the pause itself.

    It isolates the final stop after a failed pause (the halt's own harbour is the tests' above).
    """

    def _stop_safely(self, t_s, kind, detail, gait=None):  # noqa: ANN001, ANN202
        return None if kind == "pause" else super()._stop_safely(t_s, kind, detail, gait)

    def _drift_gap(self, est, extra, pause):  # noqa: ANN001, ANN202
        return 1.0, self.rest_budget_s, 30.0

    def _rest_replan(self, est, start_step, extra, deadline_s, recheck, pause):  # noqa: ANN001, ANN202
        plan = Plan(False, "exhausted", "no plan (exhausted)")
        return (Outcome(plan, "exhausted", plan.message), est.state, 0.0, 0.0, np.zeros(2),
                time.monotonic(), start_step)


def test_a_final_stop_after_a_failed_pause_swims_a_harbour_from_the_brake_s_frozen_phase():
    world = up_world()
    planner = Planner(world, ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    # the least-bad swim off: after the harbour, the final stop would swim it (test_least_bad.py)
    nav = PausedThenRefused(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                            max_restarts=1, least_bad=False)
    decisions = run_frames(nav, (1.35, 1.0), 8.0)
    paused = [t for t, d in decisions if d.pause]
    restarted = [(t, d) for t, d in decisions if d.restart]
    assert paused and len(restarted) == 1
    t_restart, d = restarted[0]
    halt = next(e for e in nav.events if e["kind"] == "halt")
    assert t_restart < halt["brake_until_s"]  # the rest replan failed while braked
    assert d.waypoints and d.stop is None
    event = next(e for e in nav.events if e["kind"] == "harbour")
    assert event["reason"] == "stop" and event["t_request_s"] == pytest.approx(t_restart, abs=1e-3)
    # the harbour swims the gait on from the phase the brake froze (the firmware's)
    braked = braked_gait(PATH_GAIT, paused[0])
    resumed = nav.estimator.gait
    lead = resumed.phase_rad + PATH_GAIT.omega_rad_s * t_restart - braked.phase_rad
    assert abs(np.remainder(lead + np.pi, 2 * np.pi) - np.pi) < 1e-9
    assert resumed.amplitude_rad == PATH_GAIT.amplitude_rad
    t_end, last = decisions[-1]
    assert last.stop == "no_safe_continuation" and "harbour swim" in last.detail
    assert t_end >= t_restart + event["swim_s"] - 1e-9


def test_where_no_harbour_keeps_the_margin_the_clearest_is_swum_when_predicted_clear(
        disc_plan, monkeypatch):
    # a cushion no swim keeps: the stop here drifts into the disc, the clearest swim does not,
    # and it is swum as the lesser risk (marked within the margin)
    import eelhost.planning.replan as replan

    monkeypatch.setattr(replan, "HARBOUR_CUSHION_M", 1.0)
    _world, planner, outcome = disc_plan
    nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0)
    decisions = run_frames(nav, (1.3, 1.0), 3.0, until=lambda d: bool(d.waypoints),
                           blind_s=0.5)
    assert decisions[-1][1].waypoints
    event = next(e for e in nav.events if e["kind"] == "harbour")
    assert event["within_margin"] and event["status"] == "harbour"
    assert event["gap_m"] > 0.0
    assert event["gap_m"] >= event["at_once_gap_m"] + replan.HARBOUR_GAIN_M


def test_the_replanner_s_final_brake_is_the_run_loop_s():
    # the planning layer may not import the run loop: its default is the same figure, kept so
    from eelhost.field.runloop import BRAKE_S

    assert STOP_BRAKE_S == BRAKE_S
