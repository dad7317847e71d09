"""The planner's check judges the arrival's stop (docs/planning.md, "The arrival's stop in the check").

A world whose goal lies just upstream of an obstacle in a current: the plan that stops into the
obstacle fails its check, and the chosen plan's arrival stop keeps clear by the independent
shapely audit; in still water with nothing beyond the goal, nothing changes.
"""

from __future__ import annotations

import numpy as np
import pytest

from eelhost.field.runloop import BRAKE_S
from eelhost.planning.audit import body_gaps_m
from eelhost.planning.check import ARRIVAL_STOP_STRIDE
from eelhost.planning.harbour import FINAL_GLIDE_S, stop_states
from eelhost.planning.planner import ARRIVAL_BRAKE_S, Planner, run_failed
from eelhost.planning.replan import STOP_BRAKE_S
from eelhost.planning.uncertainty import default_model
from eelhost.planning.world import World, parse_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)


def _world(box_x_m: float, current_m_s: float) -> World:
    """Start at the west, the goal at (2.3, 1.0) m, a box ``box_x_m`` east, a current towards +x."""
    return parse_world({
        "name": "goal_upstream", "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": [0.5, 1.0]},
        "goal": {"position_m": [2.3, 1.0], "radius_m": 0.2},
        "current": {"speed_m_s": current_m_s, "direction_deg": 0.0},
        "obstacles": [{"kind": "polygon", "vertices_m": [
            [box_x_m, 0.7], [box_x_m + 0.1, 0.7], [box_x_m + 0.1, 1.3], [box_x_m, 1.3]]}]})


def _audit(planner: Planner, plan, seed: int) -> list[float]:  # noqa: ANN001
    """Each fresh draw's smallest gap through the arrival's stop, by the shapely audit."""
    fresh = Planner(planner.world, ROBOT, MODEL, unknown_current_m_s=0.0, seed=seed,
                    check=False)
    runs = fresh.swim_waters(plan, fresh.waters(0)[:20], through_stop=True)
    assert all(r.reached for r in runs)
    return [float(body_gaps_m(planner.world, planner.model, r.states).min()) for r in runs]


def test_the_arrival_brake_is_the_run_loops():
    assert ARRIVAL_BRAKE_S == BRAKE_S == STOP_BRAKE_S


def test_a_plan_whose_arrival_stop_drifts_into_an_obstacle_fails_its_check():
    world = _world(2.75, 0.04)
    off = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, arrival_stop=False)
    unchecked = off.plan()
    assert unchecked.found
    # the plan checked without its stop: in fresh draws the stop drifts into the box
    assert min(_audit(off, unchecked.plan, 7)) <= 0.0
    on = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0)
    runs, _ = on.check_plan(unchecked.plan)
    bad = [r for r in runs if run_failed(r, on.check_margin_m)]
    assert bad and all(r.reached for r in bad)  # it fails on the stop after arriving
    assert bad[0].failed_leg == len(unchecked.plan.legs) - 1
    chosen = on.plan()
    assert chosen.found
    assert chosen.plan.waypoints_m != unchecked.plan.waypoints_m
    # the chosen plan's stop keeps clear in fresh draws, by the independent audit
    assert min(_audit(on, chosen.plan, 7)) > 0.0
    # and its check runs went on through the stop: 3 s of brake and the glide after arriving
    nominal = chosen.checks[0]
    assert nominal.t_s[-1] - nominal.goal_time_s == pytest.approx(
        ARRIVAL_BRAKE_S + FINAL_GLIDE_S, abs=ARRIVAL_STOP_STRIDE * on.twin.dt_s + 1e-9)


def test_the_checks_stop_is_the_harbours():
    """The check's stop of its nominal run is the one the tank's harbour swims from that state."""
    world = _world(2.85, 0.04)
    on = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0)
    outcome = on.plan()
    assert outcome.found
    nominal = outcome.checks[0]
    arrived = int(np.searchsorted(nominal.t_s, nominal.goal_time_s - 1e-9))
    t_arrive = float(nominal.t_s[arrived])
    stop = stop_states(on.twin, on.twin.gait, nominal.states[arrived][None], t_arrive,
                       on.arrival_stop, ARRIVAL_STOP_STRIDE)[0]
    np.testing.assert_allclose(nominal.states[arrived:], stop, atol=1e-9)


def test_in_still_water_with_nothing_beyond_the_goal_nothing_changes():
    world = parse_world({
        "name": "still", "tank": {"size_m": [3.0, 2.0]}, "start": {"position_m": [0.5, 1.0]},
        "goal": {"position_m": [2.0, 1.0], "radius_m": 0.2},
        "obstacles": [{"kind": "circle", "centre_m": [1.25, 1.0], "radius_m": 0.12}]})
    plans = [Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, arrival_stop=a).plan()
             for a in (False, True)]
    assert all(p.found for p in plans)
    assert plans[0].plan.waypoints_m == plans[1].plan.waypoints_m
    assert plans[0].repairs == plans[1].repairs
    assert plans[0].collision_probability == plans[1].collision_probability
