"""The hold (docs/planning.md, "The hold"): where no safe continuation exists and the stop would
drift into something with no harbour found, the robot swims its present plan on while the twin
swims it clearer than the stop, replanning, until a plan, a harbour or a clear stop exists. The
harbour and holding station (docs/planning.md, "Holding station (session 21)") are off here, to
isolate the hold."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_harbour import run_frames, up_world
from test_tank_restart import MODEL, ROBOT, Blocked, N

from eelhost.planning.audit import body_gaps_m
from eelhost.planning.harbour import FINAL_GLIDE_S
from eelhost.planning.planner import Planner
from eelhost.planning.replan import (
    HOLD_CHECK_S,
    HOLD_RETRY_S,
    STOP_BRAKE_S,
    Ahead,
    Decision,
)
from eelhost.planning.restart import paused_drift, stopped_twin
from eelsim.control import braked_gait
from eelsim.scenario import PATH_GAIT


@pytest.fixture(scope="module")
def up_plan():
    """The goal up the tank; the disc downstream of where the body will be seen."""
    world = up_world()
    planner = Planner(world, ROBOT, MODEL, arrival_stop=False)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    return world, planner, outcome


def ahead_of(outline_m):  # noqa: ANN001, ANN201
    """A blocked replanner whose look-ahead swims the present plan ``outline_m(t)`` clear."""

    class Ahead_(Blocked):
        def _look_ahead(self, est, left, extra, guide=None, horizon_s=None):  # noqa: ANN001, ANN202
            gap = outline_m(est.t_s)
            contact = est.t_s + 2.0 if gap <= 0.0 else math.inf
            return Ahead(gap, gap, contact, est.t_s, math.nan)

    return Ahead_


def drive(nav, com_at, seconds: float) -> list[tuple[float, Decision]]:  # noqa: ANN001
    """Frames of the straight body seen at ``com_at(t)`` until a stop, a pause or ``seconds``."""
    return run_frames(nav, com_at, seconds, until=lambda d: d.stop is not None or d.pause)


def still(t_s: float) -> tuple[float, float]:
    """The body held with its nose 10 mm from the disc's edge: a stop drifts into it."""
    return (1.36, 1.0)


def test_a_stop_the_current_would_carry_into_a_disc_is_put_off_while_the_plan_swims_clearer(
        up_plan):
    _world, planner, outcome = up_plan
    clear_5mm = ahead_of(lambda t: 0.005)  # under the look-ahead's 10 mm, but clear
    # without the hold: stopped at the first refused replan (no harbour, station or least-bad
    # swim, to isolate the hold)
    nav = clear_5mm(lambda extra: planner, planner, outcome, PATH_GAIT, harbour=False,
                    station_keeping=False, hold_plan=False, least_bad=False)
    decisions = drive(nav, still, 4.0)
    assert decisions[-1][1].stop == "no_safe_continuation" and decisions[-1][0] < 2.0
    # with it: the robot swims on, replanning with a back-off, the stop judged again
    nav = clear_5mm(lambda extra: planner, planner, outcome, PATH_GAIT, harbour=False,
                    station_keeping=False, least_bad=False)
    decisions = drive(nav, still, 4.0)
    assert not any(d.stop or d.pause for _, d in decisions)
    holds = [e for e in nav.events if e["kind"] == "hold"]
    assert len(holds) == 1
    hold = holds[0]
    assert hold["reason"] == "stop" and "ended" not in hold
    assert hold["stop_gap_m"] <= nav.lookahead_margin_m  # the stop drifts into the disc
    assert hold["plan_gap_m"] == pytest.approx(0.005)
    assert hold["checks"] >= (4.0 - hold["t_s"]) / HOLD_CHECK_S - 2
    asked = [e["t_request_s"] for e in nav.events if e["kind"] == "replan"]
    during = [t for t in asked if t > hold["t_s"]]
    assert len(during) >= 3  # replans go on while holding, each after the back-off
    assert min(np.diff(during)) >= HOLD_RETRY_S - 1e-9


def test_the_hold_ends_in_the_stop_once_the_plan_is_no_longer_the_lesser_risk(up_plan):
    _world, planner, outcome = up_plan
    # the plan swum 5 mm clear, then from 2 s 15 mm into something: a plan swum into contact
    # is never held on to
    worse = ahead_of(lambda t: 0.005 if t < 2.0 else -0.015)
    nav = worse(lambda extra: planner, planner, outcome, PATH_GAIT, harbour=False,
                    station_keeping=False, least_bad=False)
    decisions = drive(nav, still, 6.0)
    t_end, last = decisions[-1]
    assert last.stop == "no_safe_continuation"
    assert 2.0 <= t_end < 2.0 + 2 * nav.lookahead_every_s + 0.1
    hold = next(e for e in nav.events if e["kind"] == "hold")
    assert hold["ended"] == "stopped" and hold["t_end_s"] == pytest.approx(t_end, abs=1e-3)


def test_the_hold_ends_in_a_stop_the_twin_swims_clear_and_so_does_geometry_written_apart(
        up_plan):
    world, planner, outcome = up_plan
    # the body, seen still at first, is then carried across the stream at 0.1 m/s: from about
    # 0.2 m off the disc's axis the stop's drift passes beside it
    def across(t_s: float) -> tuple[float, float]:
        return (1.36, 1.0 + 0.1 * max(t_s - 1.0, 0.0))

    nav = ahead_of(lambda t: 0.005)(lambda extra: planner, planner, outcome, PATH_GAIT,
                                    harbour=False, station_keeping=False, least_bad=False)
    estimates = []
    original = nav.estimator.estimate

    def kept():  # noqa: ANN202
        est = original()
        if est is not None:
            estimates.append(est)
        return est

    nav.estimator.estimate = kept  # type: ignore[method-assign]
    decisions = drive(nav, across, 8.0)
    t_end, last = decisions[-1]
    assert last.stop == "no_safe_continuation" and t_end > 1.5
    hold = next(e for e in nav.events if e["kind"] == "hold")
    assert hold["ended"] == "stopped" and "harbour" not in {e["kind"] for e in nav.events}
    # the stop made is clear in the twin, where the stop the hold put off was not
    assert nav._stop_judged[0] == pytest.approx(t_end)
    assert nav._stop_judged[1] > nav.lookahead_margin_m >= hold["stop_gap_m"]
    # swum by the pause's code from the estimates of both decisions and judged by the audit's
    # shapely centre line: the one put off touches the disc, the one made keeps clear
    twin = nav._twin_in(np.zeros(2))
    model = MODEL.swimmer_for(ROBOT)

    def stop_from(t_s: float) -> float:
        est = next(e for e in reversed(estimates) if e.t_s <= t_s + 1e-9)
        drift = paused_drift(stopped_twin(twin, braked_gait(PATH_GAIT, est.t_s)),
                             stopped_twin(twin), est.state, est.t_s, est.t_s + STOP_BRAKE_S,
                             STOP_BRAKE_S + FINAL_GLIDE_S, 3)
        assert len(drift) > 0.9 * (STOP_BRAKE_S + FINAL_GLIDE_S) / (3 * twin.dt_s)
        assert np.all(np.isfinite(drift[:, N]))
        return float(np.min(body_gaps_m(world, model, drift)))

    assert stop_from(hold["t_s"]) < 0.0
    assert stop_from(t_end) > 0.0
