"""Stopped while the stop keeps clear (docs/planning.md): after a failed replan, a stop the twin
swims clear now but not after another replan's time is made now, instead of the retry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_harbour import disc_world
from test_tank_replanning import (  # noqa: F401 (open_plan: the fixture)
    MODEL,
    ROBOT,
    drive_and_close,
    failing_replanner,
    open_plan,
)

from eelhost.planning.harbour import StopWindow, stop_gap_m
from eelhost.planning.planner import Planner
from eelhost.planning.replan import HARBOUR_CUSHION_M, Ahead, TankReplanner, outline_clearance_m
from eelhost.planning.world import parse_world
from eelsim.scenario import PATH_GAIT


def stops_ahead(now_m: float, later_m: float):  # noqa: ANN201
    """A failing replanner whose look-ahead swims the present plan within the margin, its
    contact 10 s ahead (far enough for retries), and the stops now and later ``now_m`` and
    ``later_m`` clear."""

    class StopsAhead(failing_replanner("exhausted")):  # type: ignore[misc]
        def _look_ahead(self, est, left, extra, guide=None, horizon_s=None):  # noqa: ANN001, ANN202
            return Ahead(-0.01, -0.01, est.t_s + 10.0, est.t_s, math.nan, now_m, later_m)

    return StopsAhead


@pytest.mark.parametrize(("now_m", "later_m", "in_reach", "stopped_at_once"), [
    (0.05, 0.0, True, True),  # clear now, within the margin after a retry: stop now
    (0.05, 0.0, False, False),  # the rule off: retried, as before
    (0.05, 0.05, True, False),  # clear after a retry too: retried
    (0.015, 0.0, True, False),  # now within the margin and the cushion: no better, retried
])
def test_a_stop_clear_now_but_not_after_another_replan_is_made_instead_of_the_retry(
        open_plan, now_m, later_m, in_reach, stopped_at_once):  # noqa: F811
    planner, outcome = open_plan
    nav = stops_ahead(now_m, later_m)(lambda extra: planner, planner, outcome, PATH_GAIT,
                                      replan_budget_s=1.0, stop_in_reach=in_reach)
    t_stop, d = drive_and_close(nav, 8.0)
    assert d is not None and d.stop == "no_safe_continuation"
    early = [e for e in nav.events if e["kind"] == "stop_in_reach"]
    if stopped_at_once:
        assert len(nav.requests) == 1  # the first replan, failed: no retry
        assert "stopped while it keeps clear" in d.detail
        assert len(early) == 1 and early[0]["stop_now_m"] == pytest.approx(now_m)
        assert early[0]["t_s"] == pytest.approx(t_stop, abs=1e-3)
    else:
        assert len(nav.requests) == nav.max_failures  # retried until the failures ran out
        assert not early and "stopped while it keeps clear" not in d.detail


def test_the_look_ahead_s_stops_are_the_stop_now_and_after_a_retry_on_the_present_plan():
    # a body swimming straight at a disc in a 0.03 m/s stream towards it: stopping now keeps
    # clear, stopping after the 1.8 s another replan needs drifts into the disc
    world = parse_world({**disc_world(0.03), "goal": {"position_m": [2.6, 1.0], "radius_m": 0.2},
                         "obstacles": [{"kind": "circle", "centre_m": [1.85, 1.0],
                                        "radius_m": 0.15}]}, "at the disc")
    planner = Planner(world, ROBOT, MODEL)
    nav = TankReplanner(lambda extra: planner, planner, planner.plan(), PATH_GAIT,
                        replan_budget_s=1.0)
    try:
        twin = nav._twin_in(np.zeros(2))
        n = twin.n_links
        state = np.zeros(2 * n + 4)
        state[n : n + 2] = (1.0, 1.0)  # its nose 0.38 m from the disc
        state[2 * n + 2] = 0.08  # swimming along x through the water
        t_s = 6.0
        now = int(round(t_s / twin.dt_s))
        runs = twin.run([[(2.6, 1.0)]], 4.0, states=state[None], start_steps=[now], stride=3)
        states = runs.states[0][np.isfinite(runs.states[0][:, 0])]

        class Est:  # the estimate _stops_ahead reads: a state and its time
            pass

        est = Est()
        est.state, est.t_s = state, t_s  # type: ignore[attr-defined]
        stop_now, stop_later = nav._stops_ahead(twin, est, states, 3)  # type: ignore[arg-type]
    finally:
        nav.close()
    # the same stops judged here with the final stop's window (no restarts: the final stop)
    window = StopWindow(lambda t: t + nav.stop_brake_s, 2.0)

    def gap_of(run: np.ndarray, ahead_s: np.ndarray) -> np.ndarray:
        return outline_clearance_m(world, twin.model, run)

    k = int(round(nav._retry_need_s() / (3 * twin.dt_s)))
    assert stop_now == pytest.approx(stop_gap_m(twin, PATH_GAIT, state, t_s, window, gap_of))
    assert stop_later == pytest.approx(stop_gap_m(twin, PATH_GAIT, states[k],
                                                  t_s + k * 3 * twin.dt_s, window, gap_of))
    assert stop_now > nav.lookahead_margin_m + HARBOUR_CUSHION_M >= nav.lookahead_margin_m
    assert stop_later <= nav.lookahead_margin_m

