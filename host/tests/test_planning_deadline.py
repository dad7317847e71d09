"""One deadline for the whole planning call: the search leaves the check its time, the check stops.

Every test runs on a fake clock that advances only when the twin swims (a fixed cost per
run-step), so what the deadline decides does not depend on the machine's load.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

# the still open tank and the default robot of the repairs' tests
from test_planning_repairs import MODEL, ROBOT, open_tank

from eelhost.cli import main
from eelhost.planning.planner import DEADLINE_DRAWS_MIN, PlanLengths, Planner
from eelhost.planning.search import SwimCost
from eelhost.planning.twin import Twin

STEP_COST_S = 1e-6
"""The fake clock's seconds per run-step the twin swims."""


class WorkClock:
    """A clock that moves only when the twin swims: STEP_COST_S per run-step."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


@pytest.fixture
def clock(monkeypatch):
    fake = WorkClock()
    real = Twin.run

    def run(self, *args, **kwargs):
        runs = real(self, *args, **kwargs)
        fake.now_s += STEP_COST_S * float(np.sum(runs.final_step + 1))
        return runs

    monkeypatch.setattr(Twin, "run", run)
    return fake


def planner(clock, check_rate_s=None):
    p = Planner(open_tank(), ROBOT, MODEL, draws=6, unknown_current_m_s=0.0, seed=3)
    p.clock = clock
    p.check_cost = SwimCost()  # this test's own measurements, not the process's
    p.plan_lengths = PlanLengths()
    if check_rate_s is not None:
        p.check_cost.record(1_000_000, check_rate_s * 1_000_000)
    return p


def test_the_swim_cost_is_the_ratio_of_its_recent_sums_and_unknown_before_any():
    cost = SwimCost(window=2)
    assert cost.rate_s is None and cost.predict_s(100) is None
    cost.record(100, 1.0)
    cost.record(300, 1.0)
    assert cost.rate_s == pytest.approx(2.0 / 400)
    cost.record(100, 3.0)  # the first one leaves the window
    assert cost.predict_s(10) == pytest.approx(10 * 4.0 / 400)


def test_the_expected_plan_length_is_the_measured_ratio_to_the_free_path(clock):
    p = planner(clock)
    current = open_tank().current.speed_m_s  # still water: the slowest speed is the swimming one
    assert current == 0.0
    free = p.expected_steps()
    # 0.9 m from the start to the goal disc's edge, at the swimming speed
    assert free == pytest.approx(0.9 / p.swimming_speed_m_s / p.twin.dt_s, rel=0.1)
    outcome = p.plan()  # a found plan records its length over the free path
    assert outcome.found
    ratio = (outcome.plan.legs[-1].end_step - 0) / free
    assert p.expected_steps() == pytest.approx(free * ratio)
    for r in (0.5, 4.0):  # the median of the recorded ratios
        p.plan_lengths.record(r)
    assert p.expected_steps() == pytest.approx(free * sorted([0.5, ratio, 4.0])[1])


def test_without_a_deadline_the_plan_and_its_check_do_not_depend_on_the_clock(clock):
    plain = Planner(open_tank(), ROBOT, MODEL, draws=6, unknown_current_m_s=0.0, seed=3).plan()
    jumpy = planner(clock)
    readings = iter(np.random.default_rng(0).uniform(0, 1e6, 100_000))
    jumpy.clock = lambda: float(next(readings))  # a clock that makes no sense at all
    outcome = jumpy.plan()
    assert plain.found and outcome.found, (plain.message, outcome.message)
    assert outcome.plan.waypoints_m == plain.plan.waypoints_m
    assert [(c.ok, c.min_clearance_m) for c in outcome.checks] == [
        (c.ok, c.min_clearance_m) for c in plain.checks]
    # and a deadline far beyond the work changes nothing either
    far = planner(clock).plan(deadline_s=clock() + 1e9)
    assert far.found and far.plan.waypoints_m == plain.plan.waypoints_m


def test_the_search_stops_early_enough_to_leave_the_check_its_predicted_time(clock):
    # how long the search and the check take on the fake clock, without a deadline
    free = planner(clock, check_rate_s=STEP_COST_S)
    t0 = clock()
    alone = free.search.plan()
    search_s = clock() - t0
    assert alone.found
    p = planner(clock, check_rate_s=STEP_COST_S)
    reserve = p.check_time_s(p.expected_steps())
    assert reserve > 0
    # a deadline with room for half the search after the check's predicted time
    start = clock()
    deadline = start + reserve + search_s / 2
    outcome = p.plan(deadline_s=deadline)
    assert outcome.status == "out_of_time" and not outcome.found and not outcome.plan.found
    assert outcome.checks == []  # no check was started
    assert p.search.swim_cost.rate_s == pytest.approx(STEP_COST_S)
    # it stopped before the room for the check: no batch was in flight past it
    assert clock() <= deadline - reserve
    assert clock() > start  # and it did search while there was time


def test_a_check_that_cannot_finish_by_the_deadline_stops_and_the_plan_is_not_checked(clock):
    # a search that keeps no room for the check (it expects a plan of no length)
    p = planner(clock, check_rate_s=STEP_COST_S)
    p.expected_steps = lambda state=None: 0.0
    searched = p.search.plan()  # swum once: the planner's search replays it from its memo
    p.search._node_walls.clear()  # at no cost: forget the batches' cost of swimming it
    t0 = clock()
    runs, _ = planner(clock).check_plan(searched)
    check_s = clock() - t0
    assert all(r.ok for r in runs) and check_s > 0
    start = clock()
    deadline = start + check_s / 2  # the search takes no time now; half the check's does
    outcome = p.plan(deadline_s=deadline)
    assert outcome.status == "out_of_time", outcome.message
    assert not outcome.found and not outcome.plan.found
    assert outcome.checks == [] and outcome.draws == 0
    assert "not checked" in outcome.message and "the check stopped at its deadline" in (
        outcome.message)
    assert outcome.plan.waypoints_m == searched.waypoints_m  # the same plan, unchecked
    # it started no leg it predicted would end after the deadline
    assert start < clock() <= deadline


def test_a_check_that_fits_before_the_deadline_passes_as_without_one(clock):
    p = planner(clock, check_rate_s=STEP_COST_S)
    plain = planner(clock).plan()
    outcome = p.plan(deadline_s=clock() + 1.0)  # the work takes well under 1 s of fake time
    assert outcome.found, outcome.message
    assert outcome.plan.waypoints_m == plain.plan.waypoints_m
    assert len(outcome.checks) == 1 + 6


def test_the_bench_budget_is_refused_without_the_bench_or_when_not_positive(tmp_path, capsys):
    assert main(["plan", "tank_5_obstacles", "--budget", "1", "--out", str(tmp_path)]) == 2
    assert "--budget" in capsys.readouterr().err
    assert main(["plan", "--bench", "--budget", "0"]) == 2
    assert "expected a budget above 0 s" in capsys.readouterr().err


def test_the_bench_records_how_late_a_budgeted_call_came_back():
    from eelhost.planning.bench import BenchSummary, bench_world

    result = bench_world(open_tank(), ROBOT, MODEL, seed=3, unknown_current_m_s=0.0,
                         budget_s=1e-9)  # gone before the search can start
    assert result.status == "out_of_time" and result.reached is None
    assert 0.0 < result.overshoot_s < 60.0  # returned after a deadline it could not meet
    free = bench_world(open_tank(), ROBOT, MODEL, seed=3, unknown_current_m_s=0.0)
    assert free.overshoot_s != free.overshoot_s  # NaN: no budget, nothing to record
    summary = BenchSummary(results=[result, free])
    assert any("returned after its deadline in 1 of 1 worlds" in line
               for line in summary.lines())


def test_a_repairs_search_keeps_free_the_time_of_its_own_larger_check(clock):
    p = planner(clock, check_rate_s=STEP_COST_S)
    assert p.repair_draws == 3 * p.draws
    assert p.check_time_s(1000.0, p.repair_draws) == pytest.approx(
        p.check_time_s(1000.0) * (1 + p.repair_draws) / (1 + p.draws))
    reserves = []
    search = p.search.plan

    def recording(*args, reserve_s=None, **kwargs):
        reserves.append(reserve_s())
        return search(*args, reserve_s=reserve_s, **kwargs)

    p.search.plan = recording
    real = p.check_plan

    def first_fails(plan, state=None, step=0, waters=None, deadline_s=None):
        runs, took = real(plan, state, step, waters, deadline_s)
        if len(reserves) == 1:  # the first plan's check: a run made to touch, so a repair
            runs[1] = dataclasses.replace(runs[1], collision_free=False, failed_leg=0,
                                          first_collision_s=1.0)
        return runs, took

    p.check_plan = first_fails
    outcome = p.plan(deadline_s=clock() + 1e9)
    assert outcome.found and outcome.repairs == 1, outcome.message
    # the same plan length expected by both searches, the repair's check 19 runs against 7
    assert len(reserves) == 2 and reserves[0] > 0
    assert reserves[1] / reserves[0] == pytest.approx((1 + p.repair_draws) / (1 + p.draws))


def test_a_check_too_long_for_the_deadline_is_cut_to_fewer_draws_instead_of_no_search(clock):
    # session 9: under load the kept-free check of 60 draws alone exceeded a replan's 1 s, so the
    # search started no expansion; now the check swims as many draws as half the time allows
    free = Planner(open_tank(), ROBOT, MODEL, draws=40, unknown_current_m_s=0.0, seed=3)
    free.clock, free.check_cost, free.plan_lengths = clock, SwimCost(), PlanLengths()
    t0 = clock()
    assert free.search.plan().found
    search_s = clock() - t0
    p = Planner(open_tank(), ROBOT, MODEL, draws=40, unknown_current_m_s=0.0, seed=3)
    p.clock, p.check_cost, p.plan_lengths = clock, SwimCost(), PlanLengths()
    expected = p.expected_steps()
    # the check's measured cost per run-step set so that one run is predicted to take as long
    # as the whole search (the check itself then swims at the fake clock's own, lower cost)
    rate = search_s / expected
    p.check_cost.record(1_000_000, rate * 1_000_000)
    one_run = p.check_time_s(expected, 0)
    whole = p.check_time_s(expected)
    assert whole == pytest.approx(41 * one_run)
    start = clock()
    deadline = start + 1.5 * whole  # the whole check is more than half the time left
    kept = p.draws_within(expected, p.draws, deadline)
    assert kept == int(np.floor(0.75 * 41)) - 1 == 29  # as many as half the time holds
    outcome = p.plan(deadline_s=deadline)
    assert outcome.found, outcome.message
    assert outcome.draws == kept and len(outcome.checks) == 1 + kept
    assert f"over {kept} draws" in outcome.message  # the stated interval is over those swum
    assert clock() <= deadline
    # never fewer than DEADLINE_DRAWS_MIN, however little time is left; all without a deadline
    assert p.draws_within(expected, p.draws, clock() + 0.1 * one_run) == DEADLINE_DRAWS_MIN
    assert p.draws_within(expected, p.draws, None) == p.draws
    # a repaired plan's check keeps at least the first plan's draws
    assert p.draws_within(expected, p.repair_draws, clock() + 0.1 * one_run, p.draws) == p.draws
