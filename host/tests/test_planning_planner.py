"""The planner: refusals with their reasons, plans the twin swims as planned, one goal test."""

from __future__ import annotations

import json

import numpy as np
import pytest

from eelhost.cli import main
from eelhost.planning.planner import (
    SOFT_MARGIN_BASE_M,
    SOFT_MARGIN_DRIFT_S,
    SOFT_MARGIN_FLOOR_M,
    Planner,
)
from eelhost.planning.search import in_goal
from eelhost.planning.uncertainty import CoefficientModel, default_model
from eelhost.planning.world import WorldError, load_world, parse_world
from eelhost.planning.worlds import issue_worlds
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)
N = ROBOT.n_links


def open_tank(start=(0.5, 1.0), goal=(2.0, 1.0), speed=0.0, direction=0.0, obstacles=()):
    return parse_world({
        "name": "open",
        "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": list(start), "heading_deg": 0.0},
        "goal": {"position_m": list(goal), "radius_m": 0.2},
        "current": {"speed_m_s": speed, "direction_deg": direction},
        "obstacles": list(obstacles),
    })


def write_world(path, **kwargs):
    w = open_tank(**kwargs).model_dump(mode="json")
    lines = [f'name = "{w["name"]}"', f"clearance_m = {w['clearance_m']}", "[tank]",
             f"size_m = {list(w['tank']['size_m'])}", "[start]",
             f"position_m = {list(w['start']['position_m'])}", "heading_deg = 0.0", "[goal]",
             f"position_m = {list(w['goal']['position_m'])}", "radius_m = 0.2", "[current]",
             f"speed_m_s = {w['current']['speed_m_s']}",
             f"direction_deg = {w['current']['direction_deg']}"]
    for o in w["obstacles"]:
        lines += ["[[obstacles]]", 'kind = "circle"', f"centre_m = {list(o['centre_m'])}",
                  f"radius_m = {o['radius_m']}"]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_start_inside_an_obstacle_is_refused_as_blocked():
    world = open_tank(obstacles=[{"kind": "circle", "centre_m": [0.6, 1.0], "radius_m": 0.1}])
    outcome = Planner(world, ROBOT, MODEL).plan()
    assert outcome.status == "blocked_start"
    assert "start blocked" in outcome.message and "(0.50, 1.00)" in outcome.message


def test_current_faster_than_the_robot_swims_is_refused():
    planner = Planner(open_tank(speed=0.15, direction=180.0), ROBOT, MODEL)
    outcome = planner.plan()
    assert outcome.status == "current_too_strong"
    assert f"{planner.swimming_speed_m_s:.3f} m/s" in outcome.message


def test_goal_behind_a_wall_is_refused_as_unreachable_without_searching():
    outcome = Planner(issue_worlds()["walled_off_goal"], ROBOT, MODEL).plan()
    assert outcome.status == "unreachable"
    assert "no corridor" in outcome.message
    assert outcome.plan.simulations == 0


def test_goal_inside_an_obstacle_is_refused_at_once_without_searching():
    world = open_tank(obstacles=[{"kind": "circle", "centre_m": [2.0, 1.0], "radius_m": 0.1}])
    outcome = Planner(world, ROBOT, MODEL).plan()
    assert outcome.status == "goal_blocked"
    assert "goal blocked" in outcome.message and "inside an obstacle" in outcome.message
    assert outcome.plan.simulations == 0


@pytest.mark.parametrize("vertices, reason", [
    ([[1.0, 0.2], [2.0, 1.2], [2.0, 0.2], [1.0, 1.2]], "self-intersecting polygon"),
    ([[1.0, 1.0], [2.0, 1.0], [1.5, 1.0]], "degenerate polygon"),
    ([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0]], "degenerate polygon"),
])
def test_self_intersecting_or_flat_polygon_is_refused_when_the_world_is_read(vertices, reason):
    with pytest.raises(WorldError, match=f"obstacles.0.*{reason}"):
        open_tank(obstacles=[{"kind": "polygon", "vertices_m": vertices}])


def test_goal_outside_the_tank_is_refused_when_the_world_is_read():
    with pytest.raises(WorldError, match="goal.position_m .* outside the tank"):
        open_tank(goal=(3.4, 1.0))


def test_refusals_exit_2_with_the_reason(tmp_path, capsys):
    blocked = write_world(tmp_path / "blocked.toml", obstacles=[
        {"kind": "circle", "centre_m": [0.6, 1.0], "radius_m": 0.1}])
    assert main(["plan", str(blocked), "--out", str(tmp_path / "out")]) == 2
    assert "start blocked" in capsys.readouterr().err
    strong = write_world(tmp_path / "strong.toml", speed=0.15, direction=180.0)
    assert main(["plan", str(strong), "--out", str(tmp_path / "out")]) == 2
    assert "current too strong" in capsys.readouterr().err
    saved = json.loads((tmp_path / "out" / "plan.json").read_text())
    assert saved["status"] == "current_too_strong" and not saved["found"]


@pytest.fixture(scope="module")
def example():
    # in known water (no unknown current): the example has a plan that passes every draw
    world = load_world("tank_5_obstacles")
    planner = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, draws=24)
    return world, planner, planner.plan()


def test_example_plan_passes_every_check_run_without_contact(example):
    world, planner, outcome = example
    assert outcome.found, outcome.message
    assert len(outcome.checks) == 1 + 24 and outcome.draws == 24
    p, low, high = outcome.collision_probability
    # 0 in 24, 95 % over the first plan and its 4 repairs: Clopper-Pearson at 99 %, 19.8 %
    assert p == 0.0 and low == 0.0 and high == pytest.approx(1 - 0.005 ** (1 / 24))
    median, t5, t95 = outcome.arrival_s
    assert t5 <= median <= t95
    assert "collision probability 0.0% (0 of 24 draws" in outcome.message
    for run in outcome.checks:
        assert run.reached and run.collision_free, run.message
        # the run goes on through the arrival's stop (docs/planning.md, "The arrival's stop in
        # the check"): its state at the goal time is in the disc
        arrived = run.states[run.t_s <= run.goal_time_s + 1e-9]
        assert in_goal(world, arrived[-1, N : N + 2])
    last = outcome.plan.legs[-1]
    assert last.goal and last.waypoint_m == tuple(world.goal.position_m)


def test_search_and_execution_use_the_same_goal_test(example):
    world, planner, outcome = example
    entered = outcome.plan.legs[-1].com_m[-1]
    assert in_goal(world, entered, planner.settings.goal_margin_m)
    # the centre of mass one sample earlier was not in the disc the search tests against
    before = outcome.plan.legs[-1].com_m[-2]
    assert not in_goal(world, before, planner.settings.goal_margin_m)


def test_chained_legs_are_the_run_the_robot_swims(example):
    """With one coefficient set for every leg, the plan's chained legs and one run of its
    waypoints from the start are the same physics: same path, same goal time."""
    world, _, _ = example
    one = CoefficientModel({"straight": MODEL.fits["straight"], "turning": MODEL.fits["straight"]},
                           MODEL.std, "straight only")
    planner = Planner(world, ROBOT, one, check=False)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    from eelhost.planning.execute import swim

    (run,) = swim(world, outcome.plan.waypoints_m, planner.twin,
                  [("straight", MODEL.fits["straight"])], 2 * outcome.plan.cost_s + 30,
                  clearance=planner.clearance)
    planned = np.concatenate([leg.com_m for leg in outcome.plan.legs])
    assert run.reached and run.collision_free
    assert abs(run.goal_time_s - outcome.plan.cost_s) < 1.0
    # every swum position lies within a few centimetres of the planned path
    from eelhost.planning.replan import distance_to_path

    assert distance_to_path(planned, run.states[:, N : N + 2]).max() < 0.03


def test_check_swims_the_fits_leg_by_leg_exactly_as_the_search_did(example):
    world, planner, outcome = example
    nominal = outcome.checks[0]
    assert nominal.label == "the fits as fitted"
    # straight legs with the straight fit, turns with the turning fit, restarted where the
    # search restarted them: the search's own path, into the goal disc (the search's goal time
    # is for the disc shrunk by its margin, so a little later)
    margin_s = planner.settings.goal_margin_m / 0.05
    assert outcome.plan.cost_s - margin_s <= nominal.goal_time_s <= outcome.plan.cost_s
    planned = np.concatenate([leg.com_m for leg in outcome.plan.legs])
    from eelhost.planning.replan import distance_to_path

    swum = nominal.states[nominal.t_s <= nominal.goal_time_s + 1e-9]  # before the stop
    assert distance_to_path(planned, swum[:, N : N + 2]).max() < 0.001


def test_issue_world_with_a_035_m_gate_off_the_start_goal_line_is_planned_through_it():
    world = issue_worlds()["gap_0.35_off_line"]
    outcome = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, draws=12).plan()
    assert outcome.found, outcome.message
    assert all(c.reached and c.collision_free for c in outcome.checks)
    # the gate is at x = 1.5 m between y = 1.25 and 1.6 m: the plan goes through it
    com = np.concatenate([leg.com_m for leg in outcome.plan.legs])
    at_wall = com[np.abs(com[:, 0] - 1.5) < 0.02]
    assert at_wall.size and np.all((at_wall[:, 1] > 1.25) & (at_wall[:, 1] < 1.6))


def test_an_ilos_plan_is_checked_with_the_guidance_state_the_search_left_at_each_leg():
    # integral line-of-sight: the controller's integral and leg are part of the state a leg
    # restarts from; the check's run with the fits retraces the search's legs to the millimetre
    # only if both carry them from leg to leg (docs/planning.md, "The guidance")
    from eelhost.planning.planner import PLANNING_GUIDANCE
    from eelhost.planning.replan import distance_to_path

    world = open_tank(goal=(2.3, 1.3), speed=0.02, direction=100.0,
                      obstacles=[{"kind": "circle", "centre_m": [1.4, 1.05], "radius_m": 0.12}])
    planner = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, draws=2,
                      guidance=PLANNING_GUIDANCE)
    assert planner.options.guidance == PLANNING_GUIDANCE
    outcome = planner.plan()
    assert outcome.found, outcome.message
    assert outcome.plan.start_guide == (0.5, 1.0, 0.0, 0.0)
    planned = np.concatenate([leg.com_m for leg in outcome.plan.legs])
    nominal = outcome.checks[0]
    swum = nominal.states[nominal.t_s <= nominal.goal_time_s + 1e-9]  # before the stop
    assert distance_to_path(planned, swum[:, N : N + 2]).max() < 0.001


def test_the_soft_margin_costs_time_only_under_the_preferred_clearance():
    planner = Planner(open_tank(), ROBOT, MODEL)
    s = planner.settings
    # the default soft margin: the hard margin plus room for the check's unknown current
    assert s.preferred_clearance_m > s.margin_m and s.clearance_cost > 0
    search = planner.search
    dt = 3 * planner.twin.dt_s
    assert search.soft_cost_s(np.full(100, s.preferred_clearance_m + 0.01), 3) == 0.0
    at_margin = search.soft_cost_s(np.full(100, s.margin_m), 3)
    assert at_margin == pytest.approx(s.clearance_cost * 100 * dt)
    halfway = search.soft_cost_s(np.full(100, 0.5 * (s.margin_m + s.preferred_clearance_m)), 3)
    assert halfway == pytest.approx(at_margin / 4)  # quadratic in the shortfall
    # NaN samples (after a run's end) cost nothing
    assert search.soft_cost_s(np.full(10, np.nan), 3) == 0.0
    assert Planner(open_tank(), ROBOT, MODEL, soft_margin=False).settings.clearance_cost == 0.0


def test_the_soft_margin_keeps_its_floor_of_room_when_no_unknown_current_is_checked():
    # the coefficients alone still stray the check's runs: the preferred room never falls
    # under SOFT_MARGIN_FLOOR_M (docs/planning_history.md, "Session 16's development figures")
    calm = Planner(open_tank(), ROBOT, MODEL, unknown_current_m_s=0.0).settings
    assert calm.preferred_clearance_m == pytest.approx(calm.margin_m + SOFT_MARGIN_FLOOR_M)
    drifting = Planner(open_tank(), ROBOT, MODEL, unknown_current_m_s=0.02).settings
    assert drifting.preferred_clearance_m == pytest.approx(
        drifting.margin_m + SOFT_MARGIN_BASE_M + SOFT_MARGIN_DRIFT_S * 0.02)


def test_the_soft_margin_keeps_the_plan_further_from_an_obstacle_beside_the_direct_line():
    # a disc 0.1 m beside the start-goal line: the fastest plan passes close, the soft margin
    # pays some time for room (both plans keep the hard margin)
    world = open_tank(obstacles=[{"kind": "circle", "centre_m": [1.25, 1.2], "radius_m": 0.1}])
    clear = {}
    for soft in (False, True):
        planner = Planner(world, ROBOT, MODEL, check=False, soft_margin=soft)
        outcome = planner.plan()
        assert outcome.found, outcome.message
        clear[soft] = min(leg.min_clearance_m for leg in outcome.plan.legs)
        assert clear[soft] >= planner.settings.margin_m
    assert clear[True] > clear[False] + 0.02, clear
