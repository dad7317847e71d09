"""The tube search: plans whose legs stay clear in the unknown current's bound, else the nominal."""

from __future__ import annotations

import math

import pytest

import eelhost.planning.planner as planner_module
from eelhost.planning.planner import PLANNING_GUIDANCE, TUBE_DIRECTIONS, TUBE_MARGIN_M, Planner
from eelhost.planning.uncertainty import WaterDraw, default_model
from eelhost.planning.world import parse_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)


def tank_with_a_disc():
    return parse_world({
        "name": "disc",
        "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": [0.5, 1.0], "heading_deg": 0.0},
        "goal": {"position_m": [2.2, 1.0], "radius_m": 0.2},
        "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
        "obstacles": [{"kind": "circle", "centre_m": [1.35, 1.15], "radius_m": 0.12}],
    })


@pytest.mark.slow
def test_a_tube_plan_stays_clear_in_every_current_of_its_tube_when_the_check_swims_it():
    # the search's extra waters are swum leg by leg from their own states; the check's swim of
    # the plan in the same waters (written apart: check.swim_legs) must agree that the body
    # keeps the tube's gap in each of them
    planner = Planner(tank_with_a_disc(), ROBOT, MODEL, check=False, robust_first=True,
                      guidance=PLANNING_GUIDANCE)
    assert planner.tube_search is not None
    outcome = planner.plan()
    assert outcome.found and outcome.tube, outcome.message
    u = planner.unknown_current_m_s
    waters = [WaterDraw(f"{q}", MODEL.fits["straight"], MODEL.fits["turning"],
                        (u * math.cos(2 * math.pi * q / TUBE_DIRECTIONS),
                         u * math.sin(2 * math.pi * q / TUBE_DIRECTIONS)))
              for q in range(TUBE_DIRECTIONS)]
    runs = planner.swim_waters(outcome.plan, waters)
    assert all(r.reached for r in runs), [r.message for r in runs]
    # the search keeps TUBE_MARGIN_M less its clearance map's error bound; the first offset's
    # one-frame median filter at each restart moves a run by a few millimetres
    assert min(r.min_clearance_m for r in runs) > TUBE_MARGIN_M - 0.008


def test_without_a_tube_the_nominal_search_plans(monkeypatch):
    # a gap no extra water's body can keep: the tube search finds nothing, the nominal one plans
    monkeypatch.setattr(planner_module, "TUBE_MARGIN_M", 0.6)
    planner = Planner(tank_with_a_disc(), ROBOT, MODEL, check=False, robust_first=True)
    outcome = planner.plan()
    assert outcome.found and not outcome.tube, outcome.message
    assert outcome.repairs == 0  # the tube's empty search is not a checked plan


@pytest.mark.parametrize("kwargs", [{"unknown_current_m_s": 0.0}, {"robust_search": True}])
def test_the_tube_search_is_off_without_an_unknown_current_or_with_the_robust_search(kwargs):
    planner = Planner(tank_with_a_disc(), ROBOT, MODEL, robust_first=True, **kwargs)
    assert planner.tube_search is None


def test_the_bench_counts_what_the_tube_search_did_and_the_plans_it_gave():
    from collections import Counter

    from eelhost.planning.bench import BenchSummary, WorldResult

    results = [
        WorldResult("a", "found", "", 0.5, 0.4, 0.5, 0, True, False, 0.05, 0.1, 0.06,
                    (20.0, 18.0, 24.0), 20.0, tube=True, tube_status="found"),
        WorldResult("b", "found", "", 0.9, 0.7, 0.8, 1, True, False, 0.02, 0.5, 0.06,
                    (20.0, 18.0, 30.0), 20.0, tube=False, tube_status="found"),
        WorldResult("c", "check_failed", "", 0.2, 0.1, 0.2, 4, tube_status="exhausted"),
        WorldResult("d", "unreachable", "", 0.2, 0.1, 0.2, 0),
    ]
    text = "\n".join(BenchSummary(results, Counter(r.status for r in results)).lines())
    # b's tube plan failed its check and the nominal search's repair passed: not a tube plan
    assert ("the tube search first: exhausted 1, found 2 (worlds it ran in); plans from it "
            "that passed the check: 1 of 2") in text
    plain = [WorldResult("d", "unreachable", "", 0.2, 0.1, 0.2, 0)]
    assert "tube" not in "\n".join(BenchSummary(plain, Counter(["unreachable"])).lines())


def test_a_tube_plan_that_fails_its_check_is_repaired_by_the_nominal_search(monkeypatch):
    import numpy as np

    from eelhost.planning.execute import Swim

    planner = Planner(tank_with_a_disc(), ROBOT, MODEL, robust_first=True)
    checked = []

    def check_failing_the_first_plan(plan, state=None, step=0, waters=None):
        checked.append(plan)
        ok = len(checked) > 1
        run = Swim("a draw", ok, 30.0 if ok else None, True, 0.1, None, 0.0,
                   None if ok else 0, "", np.zeros(1), np.zeros((1, 2 * ROBOT.n_links + 4)))
        return [run], 0.0

    monkeypatch.setattr(planner, "check_plan", check_failing_the_first_plan)
    outcome = planner.plan()
    assert outcome.tube_status == "found" and len(checked) == 2
    assert outcome.found and not outcome.tube and outcome.repairs == 1, outcome.message
    # the family of checked plans is the same as without the tube search
    assert outcome.family == planner.repairs + 1


def test_plan_json_records_what_the_tube_search_did():
    from eelhost.commands.plan import plan_json
    from eelhost.planning.planner import Outcome
    from eelhost.planning.search import Plan

    outcome = Outcome(Plan(False, "exhausted", "no plan"), "exhausted", "no plan",
                      tube_status="exhausted")
    record = plan_json(tank_with_a_disc(), outcome)
    assert record["tube_search"] == "exhausted" and record["from_tube"] is False
