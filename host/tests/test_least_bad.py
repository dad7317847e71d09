"""The least-bad swim (docs/planning.md, "The least-bad swim (session 24)"): where the stop decided
would drift into something and no harbour, station or hold keeps clear, the robot swims the
station candidate the twin keeps clear over a few seconds whose stops along it are clearest,
while such a stop beats the stop now, judged again every check, replanning, and stops once the twin
swims the stop clear.

The least-bad swim is on by default (``least_bad``); the tests name it on or off, with holding
station off (its own option, off by default)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_harbour import FINAL, run_frames
from test_station import stream_plan, upstream_body, wall_stream_take
from test_tank_restart import MODEL, OPEN, ROBOT, Blocked, N

from eelhost.field.recorder import read_commands_csv
from eelhost.field.take import run_take
from eelhost.planning.audit import body_gaps_m
from eelhost.planning.harbour import stop_gap_m
from eelhost.planning.planner import Planner
from eelhost.planning.replan import STATION_RETRY_S, outline_clearance_m
from eelhost.planning.station import (
    LEAST_BAD_GAIN_M,
    LEAST_BAD_HORIZON_S,
    LEAST_BAD_LEADS_S,
    LEAST_BAD_STEP_M,
    STATION_CHECK_S,
    LeastBad,
    Station,
    find_least_bad,
)
from eelhost.planning.world import parse_world
from eelsim.scenario import PATH_GAIT


@pytest.fixture(scope="module")
def stream():
    return stream_plan()


def test_a_short_swim_clear_of_the_wall_leaves_a_better_stop_than_the_stream_s(stream):
    world, planner, _ = stream
    twin, model = planner.twin, planner.model
    state = upstream_body(2.6)  # its tail 80 mm from the end wall, the water flowing to it
    t_s = 6.0

    def gap_of(states: np.ndarray, ahead_s: np.ndarray) -> np.ndarray:
        return outline_clearance_m(world, model, states)

    stop = stop_gap_m(twin, PATH_GAIT, state, t_s, FINAL, gap_of)
    assert stop <= 0.0
    least = find_least_bad(twin, PATH_GAIT, state, t_s, world.current_m_s, gap_of, FINAL)
    assert least is not None
    swim = least.swim
    assert swim.gap_m > LEAST_BAD_GAIN_M and least.stop_gap_m > stop + LEAST_BAD_STEP_M
    # its stops along it, swum apart one at a time: the clearest is the one it was chosen for
    swum = twin.run([[swim.waypoint_m]], LEAST_BAD_HORIZON_S + 2 * twin.dt_s, states=state[None],
                    start_steps=[int(round(t_s / twin.dt_s))], stride=3).states[0]
    stops = []
    for lead_s in LEAST_BAD_LEADS_S:
        i = int(round(lead_s / (3 * twin.dt_s)))
        stops.append(stop_gap_m(twin, PATH_GAIT, swum[i], t_s + i * 3 * twin.dt_s, FINAL,
                                gap_of))
    assert max(stops) == pytest.approx(least.stop_gap_m, abs=2e-3)
    # swum again from its waypoint and judged by the audit's shapely centre line
    # (planning/audit.py), not the outline it was chosen by: clear over its horizon
    runs = twin.run([[swim.waypoint_m]], LEAST_BAD_HORIZON_S, states=state[None],
                    start_steps=[int(round(t_s / twin.dt_s))], stride=3)
    swum = runs.states[0]
    assert np.all(np.isfinite(swum[:, N]))
    assert len(swum) * 3 * twin.dt_s > 0.95 * LEAST_BAD_HORIZON_S
    assert float(np.min(body_gaps_m(world, MODEL.swimmer_for(ROBOT), swum))) > 0.0
    # in still water there is no least-bad swim (no current to carry a stop in)
    assert find_least_bad(twin, PATH_GAIT, state, t_s, (0.0, 0.0), gap_of, FINAL) is None


def judged_as(stop_until_s: float, swim_until_s: float):  # noqa: ANN201
    """A replanner whose every replan is refused, the twin's judgement stood in for: the stop
    20 mm deep until ``stop_until_s`` and 50 mm clear after; a swim 30 mm clear whose clearest
    stop is 0 mm (20 mm better than the stop now) until ``swim_until_s``, and 20 mm deep
    (no better) after."""

    class Judged(Blocked):
        def _judge_least_bad(self, t_s, kind):  # noqa: ANN001, ANN202
            stop = -0.02 if t_s < stop_until_s else 0.05
            swim = Station(0, (0.2, 1.4), 0.0, "upstream", 0.03, math.nan, np.zeros((1, 2)),
                           (0.0, 0.0, 0.0, 0.0))
            self._stop_judged = (t_s, stop)
            return stop, LeastBad(swim, 0.0 if t_s < swim_until_s else -0.02)

    return Judged


@pytest.fixture(scope="module")
def open_planned():
    planner = Planner(parse_world(OPEN, "open"), ROBOT, MODEL)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    return planner, outcome


@pytest.mark.parametrize(("least_bad", "stop_until_s", "swim_until_s", "ended"), [
    (True, 4.0, 99.0, "stopped"),  # swum until the twin swims the stop clear, then the stop
    (True, 99.0, 3.0, "none"),  # swum until no swim beats the stop any more, then the stop
    (False, 4.0, 99.0, None),  # the option off: the stop at once, as before
])
def test_a_refused_replan_whose_stop_drifts_in_swims_the_least_bad_swim_until_the_stop_is_clear(
        open_planned, least_bad, stop_until_s, swim_until_s, ended):
    planner, outcome = open_planned
    nav = judged_as(stop_until_s, swim_until_s)(
        lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0, harbour=False,
        least_bad=least_bad)
    decisions = run_frames(nav, (0.8, 1.4), 12.0)  # 0.4 m off the corridor: refused
    t_end, last = decisions[-1]
    assert last.stop == "no_safe_continuation"
    swims = [e for e in nav.events if e["kind"] == "least_bad"]
    refused = [e for e in nav.events if e["kind"] == "replan"]
    if not least_bad:
        assert not swims and len(refused) == 1 and t_end < 1.0  # stopped at the first refusal
        return
    assert len(swims) == 1 and swims[0]["status"] == "swum"
    sw = swims[0]
    assert sw["t_s"] == pytest.approx(refused[0]["t_ready_s"], abs=0.1)  # instead of the stop
    assert sw["stop_gap_m"] == pytest.approx(-0.02) and sw["gap_m"] == pytest.approx(0.03)
    assert sw["swim_stop_gap_m"] == pytest.approx(0.0)
    assert len(sw["judged"]) == sw["checks"]  # every check recorded
    # the frames in between swam its waypoint: no stop, no pause
    during = [d for t, d in decisions if sw["t_s"] - 1e-9 <= t < t_end]
    assert during[0].waypoints == [(0.2, 1.4)]
    assert not any(d.stop or d.pause for d in during)
    # ended at the first check after the stop came clear (or the swim stopped beating it)
    until = stop_until_s if ended == "stopped" else swim_until_s
    assert sw["ended"] == ended and until - 1e-9 <= t_end < until + STATION_CHECK_S + 0.1
    assert "swam the least-bad swim" in last.detail
    # meanwhile replans were asked for, at least 0.5 s apart; none of their refusals stopped it
    asked = [e["t_request_s"] for e in refused if e["reason"] == "least_bad"]
    assert len(asked) >= 3 and min(np.diff(asked)) >= STATION_RETRY_S - 1e-9
    assert "1 least-bad swim" in nav.tally()


def test_still_water_the_stop_keeps_clear_and_no_least_bad_swim_is_judged(open_planned):
    planner, outcome = open_planned
    endings = {}
    for least_bad in (True, False):
        nav = Blocked(lambda extra: planner, planner, outcome, PATH_GAIT, lookahead_s=0.0,
                      least_bad=least_bad)
        decisions = run_frames(nav, (0.8, 1.4), 4.0)
        t_end, last = decisions[-1]
        assert last.stop == "no_safe_continuation"
        assert not [e for e in nav.events if e["kind"] == "least_bad"]
        endings[least_bad] = t_end
    assert endings[True] == endings[False]  # stopped at the same frame either way


@pytest.mark.slow
def test_over_sim_a_stop_the_stream_carries_into_the_wall_swims_and_stops_once_clear(tmp_path):
    # test_station's robot by the wall in the stream, its replans refused
    stem = tmp_path / "least_bad"
    nav, request, world = wall_stream_take(stem, trace_plant=True, least_bad=True)
    result = run_take(request)
    out = result.outcome
    assert out.failsafe_reports == 0
    swims = [e for e in nav.events if e["kind"] == "least_bad" and e["status"] == "swum"]
    assert swims, [e for e in nav.events if e["kind"] != "replan"]
    sw = swims[0]
    assert sw["stop_gap_m"] <= nav.lookahead_margin_m
    assert sw["gap_m"] > LEAST_BAD_GAIN_M
    assert sw["swim_stop_gap_m"] > sw["stop_gap_m"] + LEAST_BAD_STEP_M
    t_end = sw.get("t_end_s", out.t_end_s)
    assert t_end - sw["t_s"] >= STATION_CHECK_S - 1e-9  # swum, not stopped at once
    # meanwhile offsets at the control rate, and replans asked for at least 0.5 s apart
    sent = [float(r["t_s"]) for r in read_commands_csv(f"{stem}.commands.csv")
            if r["event"] == "sent" and r["message"] == "SetOffset"]
    during = [t for t in sent if sw["t_s"] <= t <= t_end + 0.1]
    assert len(during) >= 3 and np.diff(during).max() < 0.35
    asked = [e["t_request_s"] for e in nav.events if e["kind"] == "replan"
             and e["reason"] == "least_bad"]
    assert len(asked) >= 2 and min(np.diff(asked)) >= STATION_RETRY_S - 1e-9
    # it ends with the stop it put off, made once the twin swims it clear, and the true body
    # (the plant's trace, judged by the audit's centre line) kept clear while swimming
    assert out.reason == "no_safe_continuation", out.detail
    assert sw["ended"] == "stopped" and "swam the least-bad swim" in out.detail
    vr = result.virtual_robot
    assert vr is not None and vr.trace is not None
    states = np.asarray(vr.trace)
    assert math.isfinite(float(states[-1, N]))
    assert float(np.min(body_gaps_m(world, vr.model, states))) > 0.0
