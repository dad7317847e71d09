"""Holding station (docs/planning.md, "Holding station (session 21)"): where no safe continuation
exists and the stop would drift into something, the robot swims into the current while the twin
swims that clear, replanning, instead of stopping; not where the stop keeps clear.

Holding station is an option (``station_keeping``, off by default); the tests turn it on. The
harbour is off in most of the replanner's tests, to isolate the station (a harbour swim of 4.5 s
and the stop after it may also keep clear of a wall the current flows to)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_harbour import FINAL, disc_world, run_frames, up_world
from test_tank_replanning import drive_and_close, open_plan  # noqa: F401 (open_plan: the fixture)
from test_tank_restart import MODEL, OPEN, ROBOT, Blocked, N

from eelhost.field.recorder import read_commands_csv
from eelhost.field.runloop import RunConfig
from eelhost.field.session import TakeNotes
from eelhost.field.take import TakeRequest, run_take
from eelhost.planning.audit import body_gaps_m
from eelhost.planning.harbour import FINAL_GLIDE_S, stop_gap_m
from eelhost.planning.planner import Planner
from eelhost.planning.replan import (
    STATION_RETRY_S,
    STOP_BRAKE_S,
    outline_clearance_m,
)
from eelhost.planning.restart import paused_drift, stopped_twin
from eelhost.planning.station import STATION_HORIZON_S, Station, find_station
from eelhost.planning.tank import sim_uri_for_world
from eelhost.planning.world import World, parse_world
from eelhost.vision.synthetic import TankView
from eelsim.control import braked_gait
from eelsim.scenario import PATH_GAIT


def stream_world(current_m_s: float) -> dict:
    """A stream along +x to the tank's end wall (x = 3 m); the goal far upstream."""
    return {
        "name": "stream",
        "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": [1.6, 1.0], "heading_deg": 180.0},
        "goal": {"position_m": [0.5, 1.0], "radius_m": 0.2},
        "current": {"speed_m_s": current_m_s, "direction_deg": 0.0},
        "obstacles": [{"kind": "circle", "centre_m": [0.6, 1.7], "radius_m": 0.1}],
    }


def upstream_body(x_m: float) -> np.ndarray:
    """The straight body at rest headed upstream (-x), its centre of mass at (x, 1)."""
    state = np.zeros(2 * N + 4)
    state[:N] = math.pi
    state[N : N + 2] = (x_m, 1.0)
    return state


def stream_plan() -> tuple[World, Planner, Any]:
    """The 0.045 m/s stream towards the end wall: its world, planner and plan from the start."""
    world = parse_world(stream_world(0.045), "stream")
    planner = Planner(world, ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    return world, planner, outcome


@pytest.fixture(scope="module")
def stream():
    return stream_plan()


def test_in_a_current_towards_a_wall_the_stop_touches_and_the_station_swim_keeps_clear(stream):
    world, planner, _ = stream
    twin = planner.twin
    model = planner.model
    state = upstream_body(2.6)  # its tail 80 mm from the end wall, the water flowing to it
    t_s = 6.0

    def gap_of(states: np.ndarray, ahead_s: np.ndarray) -> np.ndarray:
        return outline_clearance_m(world, model, states)

    assert stop_gap_m(twin, PATH_GAIT, state, t_s, FINAL, gap_of) <= 0.0
    best, clearest = find_station(twin, state, t_s, world.current_m_s, gap_of, 0.02)
    assert best is not None and clearest is not None
    assert best.gap_m > 0.02 and best.drift_m < 0.0  # clear, and headway against the water
    # judged again apart: the stop swum by the pause's code, the station swim swum again, both
    # by the audit's shapely centre line (planning/audit.py), not the outline it was judged by
    audit_model = MODEL.swimmer_for(ROBOT)
    drift = paused_drift(stopped_twin(twin, braked_gait(PATH_GAIT, t_s)), stopped_twin(twin),
                         state, t_s, t_s + STOP_BRAKE_S, STOP_BRAKE_S + FINAL_GLIDE_S, 3)
    assert np.all(np.isfinite(drift[:, N]))
    assert float(np.min(body_gaps_m(world, audit_model, drift))) < 0.0
    runs = twin.run([[best.waypoint_m]], STATION_HORIZON_S, states=state[None],
                    start_steps=[int(round(t_s / twin.dt_s))], stride=3)
    swum = runs.states[0]
    assert np.all(np.isfinite(swum[:, N]))
    assert len(swum) * 3 * twin.dt_s > 0.95 * STATION_HORIZON_S
    assert float(np.min(body_gaps_m(world, audit_model, swum))) > 0.01
    assert swum[-1, N] < state[N]  # upstream of where the stop was decided


def test_still_water_the_stop_keeps_clear_and_no_station_is_held():
    planner = Planner(parse_world(OPEN, "open"), ROBOT, MODEL)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    endings = {}
    for station in (True, False):
        nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                      station_keeping=station)
        decisions = run_frames(nav, (0.8, 1.4), 4.0)  # 0.4 m off the corridor: refused
        t_end, last = decisions[-1]
        assert last.stop == "no_safe_continuation"
        assert not [e for e in nav.events if e["kind"] == "station"]
        endings[station] = t_end
    assert endings[True] == endings[False]  # stopped at the same frame either way


def test_an_arrival_the_stream_would_carry_into_the_wall_holds_station_then_arrives():
    # the goal by the end wall: the body arrives there headed upstream, its tail 80 mm from the
    # wall; seen swimming upstream at 0.05 m/s from 1 s, as the station swim would take it
    world = parse_world({**stream_world(0.045), "start": {"position_m": [1.6, 1.0],
                                                          "heading_deg": 0.0},
                         "goal": {"position_m": [2.6, 1.0], "radius_m": 0.2}}, "wall goal")
    planner = Planner(world, ROBOT, MODEL, check=False)  # a plan to be in the goal disc by
    outcome = planner.plan()
    assert outcome.found, outcome.message

    def com_at(t_s: float) -> tuple[float, float]:
        return (2.6 - 0.05 * max(t_s - 1.0, 0.0), 1.0)

    for station in (False, True):
        nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                      harbour=False, station_keeping=station)
        # the straight body headed upstream, until an arrival or a stop
        decisions = run_frames(nav, com_at, 12.0, until=lambda d: d.arrived or d.stop is not None,
                               blind_s=0.5, heading_rad=math.pi)
        t_end, last = decisions[-1]
        assert last.arrived and last.stop is None
        first_t, first = next((t, d) for t, d in decisions if t >= 0.5)
        if not station:  # arrived at the first frame seen in the disc
            assert t_end == first_t
            continue
        assert first.waypoints and not first.arrived  # holding station instead of the arrival
        st = next(e for e in nav.events if e["kind"] == "station")
        assert st["reason"] == "arrived" and st["status"] == "held"
        assert st["stop_gap_m"] <= nav.lookahead_margin_m < st["gap_m"]
        # it arrives once the twin swims the stop clear from where the body is seen
        assert st["ended"] == "stopped" and t_end >= first_t + 0.5 - 1e-9  # a check later
        assert nav._stop_judged[1] > nav.lookahead_margin_m
        assert not [e for e in nav.events if e["kind"] == "replan"]  # arrived: none asked


def wall_stream_take(stem: Path, trace_plant: bool = False,
                     **options: Any) -> tuple[Blocked, TakeRequest, World]:
    """A take over ``sim://`` whose every replan is refused, the robot by a wall in a stream.

    The plan starts at (1.6, 1); the robot is put at (2.6, 1) headed upstream, its tail 80 mm
    from the wall the 0.045 m/s stream flows to: off the plan's corridor. The look-ahead is
    off, so nothing keeps the present plan and the first refused replan decides a stop; the
    harbour is off. ``options`` go to the replanner (the tier under test).
    """
    world = parse_world(stream_world(0.045), "stream")
    planner = Planner(world, ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    uri = sim_uri_for_world("sim://?speed=0&start=2.6,1.0,180", world)
    nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, harbour=False,
                  lookahead_s=0.0, replan_budget_s=1.0, **options)
    config = RunConfig(PATH_GAIT, list(outcome.plan.waypoints_m), duration_s=20.0)
    request = TakeRequest(ROBOT, config, str(stem), TakeNotes(uri), "synthetic:clean",
                          navigator=nav, camera_view=TankView.covering((3.0, 2.0)),
                          trace_plant=trace_plant)
    return nav, request, world


@pytest.mark.slow
def test_over_sim_a_run_that_would_stop_holds_station_without_failsafe(tmp_path):
    stem = tmp_path / "station"
    nav, request, _ = wall_stream_take(stem, station_keeping=True)
    result = run_take(request)
    out = result.outcome
    assert out.failsafe_reports == 0
    stations = [e for e in nav.events if e["kind"] == "station" and e["status"] == "held"]
    assert stations, [e for e in nav.events if e["kind"] != "replan"]
    st = stations[0]
    assert st["stop_gap_m"] <= nav.lookahead_margin_m < st["gap_m"]
    t_end = st.get("t_end_s", out.t_end_s)
    assert t_end - st["t_s"] >= 1.0  # held, not stopped at once
    # meanwhile offsets at the control rate, and replans asked for, each after the last by
    # at least the station's retry
    sent = [float(r["t_s"]) for r in read_commands_csv(f"{stem}.commands.csv")
            if r["event"] == "sent" and r["message"] == "SetOffset"]
    during = [t for t in sent if st["t_s"] + 0.1 <= t <= t_end]
    assert len(during) >= 4 and np.diff(during).max() < 0.35
    asked = [e["t_request_s"] for e in nav.events if e["kind"] == "replan"
             and e["reason"] == "station"]
    assert len(asked) >= 2
    assert min(np.diff(asked)) >= STATION_RETRY_S - 1e-9
    assert "1 station held" in nav.tally()
    # it ends with the stop it put off (no restart, no plan): made once the twin swims it clear
    assert out.reason == "no_safe_continuation", out.detail
    assert st["ended"] == "stopped"
    assert result.virtual_robot is not None


def test_at_a_harbour_s_end_with_the_stop_still_drifting_in_the_station_is_held():
    # test_harbour's refused replan in a 0.03 m/s stream towards a disc, the body seen still:
    # the harbour is swum, and at its end the stop drifts into the disc again; with the
    # harbours used up, the robot holds station there instead of stopping
    world = parse_world(disc_world(0.03), "disc")
    planner = Planner(world, ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                  station_keeping=True)
    decisions = run_frames(nav, (1.35, 1.0), 8.0, until=lambda d: d.stop is not None or d.pause)
    harbours = [e for e in nav.events if e["kind"] == "harbour" and e["status"] == "harbour"]
    stations = [e for e in nav.events if e["kind"] == "station" and e["status"] == "held"]
    assert harbours and stations
    assert stations[0]["t_s"] == pytest.approx(harbours[-1]["t_end_s"], abs=1e-3)
    assert stations[0]["stop_gap_m"] <= nav.lookahead_margin_m < stations[0]["gap_m"]
    at = next(d for t, d in decisions if t == pytest.approx(stations[0]["t_s"]))
    assert at.waypoints and at.stop is None and not at.pause


def test_after_a_failed_pause_the_final_stop_that_drifts_in_holds_station_swimming_again():
    # a pause without the brake (amplitude 0 at once) in the stream towards the disc, the body
    # seen still 60 mm from it, the goal up the tank: the pause's drift keeps clear, its rest
    # replan is refused, and the final stop would drift into the disc; with no harbour, the
    # gait is swum again to hold station
    planner = Planner(up_world(), ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    assert outcome.found, outcome.message

    class StationAfterThePause(Blocked):  # the station is first judged after the pause
        def _halt(self, t_s, d):  # noqa: ANN001, ANN202
            paused = super()._halt(t_s, d)
            self.station_keeping = True
            return paused

    nav = StationAfterThePause(lambda extra: planner, planner, outcome, PATH_GAIT,
                               lookahead_s=0.0, max_restarts=1, harbour=False,
                               rest_brake_s=None, station_keeping=False)
    decisions = run_frames(nav, (1.30, 1.0), 8.0, until=lambda d: d.stop is not None
                           or d.restart)
    t_end, last = decisions[-1]
    assert any(d.pause for _, d in decisions)  # paused first
    assert last.restart and last.waypoints and last.stop is None
    st = next(e for e in nav.events if e["kind"] == "station")
    assert st["status"] == "held" and st["reason"] == "stop"
    assert st["t_s"] == pytest.approx(t_end, abs=1e-3)
    assert st["stop_gap_m"] <= nav.lookahead_margin_m < st["gap_m"]
    assert nav._pause is None and nav.estimator.gait is nav.gait


def in_reach_station(clear_until_s: float):  # noqa: ANN201
    """test_stop_in_reach's failing replanner whose stop keeps 50 mm now and none after a retry
    (the stop-while-clear rule stops), and whose station swims keep 50 mm clear until
    ``clear_until_s`` and none after (the twin's judgement stood in for)."""
    from test_stop_in_reach import stops_ahead

    class InReach(stops_ahead(0.05, 0.0)):  # type: ignore[misc]
        def _judge_station(self, t_s, kind, always=False):  # noqa: ANN001, ANN202
            if not always:
                return None  # only the station instead of a stop while clear is looked at
            swim = Station(0, (0.2, 1.0), 0.0, "upstream", 0.05, -0.01, np.zeros((1, 2)),
                           (0.0, 0.0, 0.0, 0.0))
            return 0.05, (swim if t_s < clear_until_s else None), swim

    return InReach


@pytest.mark.parametrize(("station", "clear_until_s"), [
    (True, 4.0),  # a station swim keeps clear for a while: held, replanning, then the stop
    (True, 0.0),  # none keeps clear: the stop as before
    (False, 4.0),  # the option off: the stop as before
])
def test_where_the_stop_while_clear_rule_stops_a_clear_station_swim_is_held_replanning(
        open_plan, station, clear_until_s):  # noqa: F811
    planner, outcome = open_plan
    nav = in_reach_station(clear_until_s)(lambda extra: planner, planner, outcome, PATH_GAIT,
                                          replan_budget_s=1.0, station_keeping=station)
    t_stop, d = drive_and_close(nav, 10.0)
    assert d is not None and d.stop == "no_safe_continuation"
    assert "stopped while it keeps clear" in d.detail  # the stop-while-clear detail either way
    in_reach = [e for e in nav.events if e["kind"] == "stop_in_reach"]
    held = [e for e in nav.events if e["kind"] == "station" and e["status"] == "held"]
    assert len(in_reach) == 1
    if not (station and clear_until_s > 0.0):
        assert not held and len(nav.requests) == 1  # stopped at the rule's frame, no retry
        assert in_reach[0]["t_s"] == pytest.approx(t_stop, abs=1e-3)
        assert "station" not in in_reach[0]
        return
    st = held[0]
    assert st["stop_in_reach"] and in_reach[0]["station"]
    assert st["t_s"] == pytest.approx(in_reach[0]["t_s"], abs=1e-3)
    # held until the check after the station swim stopped keeping clear, then the stop
    assert st["ended"] == "none" and t_stop >= clear_until_s - 1e-9 > st["t_s"]
    assert t_stop < clear_until_s + STATION_RETRY_S + 0.1
    # meanwhile replans were asked for, each at least 0.5 s after the last; none stopped it
    asked = [e["t_request_s"] for e in nav.events
             if e["kind"] == "replan" and e["reason"] == "station"]
    assert len(asked) >= 2 and min(np.diff(asked)) >= STATION_RETRY_S - 1e-9
    assert "instead of a stop while clear" in nav.tally()
