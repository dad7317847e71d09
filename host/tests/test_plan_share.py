"""The first plan's fallback from a cramped start: wider first turns when the search is
exhausted (docs/planning_history.md, "A wider turn from a cramped start")."""

from __future__ import annotations

from eelhost.planning.planner import CRAMPED_ACTIONS, Planner
from eelhost.planning.search import Actions
from eelhost.planning.uncertainty import default_model
from eelhost.planning.world import parse_world
from eelhost.planning.worlds import generate_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)

CRAMPED_SEED = 28574
"""A generated world (development seed) whose start leaves the plain search no way out: every
leg of up to 60 degrees from it comes within the margin, and the fallback's wider turns find a
plan that passes its check."""


def test_a_cramped_start_is_planned_with_wider_turns_and_the_full_margin():
    world = generate_world(CRAMPED_SEED)
    plain = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, seed=CRAMPED_SEED).plan()
    assert plain.status == "exhausted"
    planner = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, seed=CRAMPED_SEED,
                      cramped_start=True)
    outcome = planner.plan()
    assert outcome.status == "found"
    widest = max(abs(b) for b in Actions().bearings_deg)
    legs = outcome.plan.legs
    # the wider turns are what found it: the first leg turns further than the plain actions
    # can, and only the first legs are offered them
    assert abs(legs[0].bearing_deg) > widest + 1e-6
    assert all(abs(leg.bearing_deg) <= widest + 1e-6 for leg in legs[1:] if not leg.goal)
    assert set(CRAMPED_ACTIONS.bearings_deg) > set(Actions().bearings_deg)
    # every leg keeps the search's whole margin (nothing is relaxed), and every check run the
    # check's margin
    assert all(leg.min_clearance_m >= planner.settings.margin_m for leg in legs)
    assert all(run.min_clearance_m > planner.check_margin_m for run in outcome.checks)


def test_a_start_the_plain_search_plans_from_gets_the_same_plan():
    world = parse_world({
        "name": "open",
        "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": [0.7, 1.0], "heading_deg": 0.0},
        "goal": {"position_m": [2.2, 1.0], "radius_m": 0.2},
        "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
        "obstacles": [{"kind": "circle", "centre_m": [1.45, 1.0], "radius_m": 0.1}],
    })
    with_fallback = Planner(world, ROBOT, MODEL, check=False, cramped_start=True)
    found = with_fallback.plan()
    without = Planner(world, ROBOT, MODEL, check=False, cramped_start=False).plan()
    assert found.status == without.status == "found"
    assert found.plan.waypoints_m == without.plan.waypoints_m
    assert with_fallback._cramped_search is None  # the fallback never ran


def test_a_replan_from_a_given_state_gets_no_fallback():
    world = generate_world(CRAMPED_SEED)
    planner = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, check=False,
                      cramped_start=True)
    outcome = planner.plan(planner.search.twin_start_state())
    assert outcome.status == "exhausted"
    assert planner._cramped_search is None
