"""Repairs and the stated bound: every plan a planning call checks has its own fresh draws.

docs/planning.md ("The planner", step 4): a repaired plan is checked over draws independent of
the ones its predecessors failed, and its interval is a simultaneous one over every plan the
repairs may check (Bonferroni), so a plan picked as the first of several to pass is not stated
safer than it is.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from eelhost.planning.planner import CHECK_LEVEL, REPAIR_DRAWS_FACTOR, Planner
from eelhost.planning.uncertainty import default_model
from eelhost.planning.world import parse_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)


def open_tank():
    return parse_world({
        "name": "open", "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": [0.5, 1.0], "heading_deg": 0.0},
        "goal": {"position_m": [1.6, 1.0], "radius_m": 0.2},
        "current": {"speed_m_s": 0.0, "direction_deg": 0.0}, "obstacles": [],
    })


def drawn(waters):
    return np.stack([np.r_[w.straight.as_array(), w.turning.as_array(), w.current_offset_m_s]
                     for w in waters])


def test_each_plan_has_its_own_reproducible_draws():
    planner = Planner(open_tank(), ROBOT, MODEL, draws=6, seed=11)
    first, second, third = (drawn(planner.waters(k)) for k in range(3))
    assert planner.waters(0) is planner.water  # the first plan's draws are the seed's
    # a repaired plan is checked over REPAIR_DRAWS_FACTOR times as many draws, its own
    assert len(first) == 6 and len(second) == len(third) == REPAIR_DRAWS_FACTOR * 6
    assert not np.allclose(first, second[:6]) and not np.allclose(second, third)
    again = Planner(open_tank(), ROBOT, MODEL, draws=6, seed=11)
    assert np.array_equal(drawn(again.waters(2)), third)  # the same seed, the same draws
    assert planner.waters(2) is planner.waters(2)  # a replan checks over the same ones
    assert len(Planner(open_tank(), ROBOT, MODEL, draws=6, repair_draws=7).waters(1)) == 7
    with pytest.raises(ValueError, match="repair_draws"):
        Planner(open_tank(), ROBOT, MODEL, draws=6, repair_draws=0)


def test_a_repaired_plan_is_judged_on_its_own_draws_with_a_simultaneous_bound():
    planner = Planner(open_tank(), ROBOT, MODEL, draws=4, unknown_current_m_s=0.0, repairs=2,
                      seed=5)
    checked = []
    real = planner.check_plan

    def first_two_fail(plan, state=None, step=0, waters=None, deadline_s=None):
        runs, took = real(plan, state, step, waters, deadline_s)
        checked.append(waters)
        if len(checked) < 3:  # a drawn run made to touch on the first leg: repair
            runs[1] = dataclasses.replace(runs[1], collision_free=False, failed_leg=0,
                                          first_collision_s=1.0)
        return runs, took

    planner.check_plan = first_two_fail
    outcome = planner.plan()
    assert outcome.found and outcome.repairs == 2, outcome.message
    repaired = REPAIR_DRAWS_FACTOR * 4
    assert [len(w) for w in checked] == [4, repaired, repaired]
    assert checked[0] is planner.waters(0) and checked[2] is planner.waters(2)
    assert not np.allclose(drawn(checked[1]), drawn(checked[2]))
    # the returned plan's runs are over the third plan's draws, not the first's
    assert [r.label for r in outcome.drawn_checks] == [w.label for w in checked[2]]
    # 0 in 12 at 1 - 0.05 / 3 two-sided: the upper end 1 - (0.05 / 6)^(1/12)
    assert outcome.family == 3 and outcome.draws == repaired
    assert outcome.level == pytest.approx(1 - (1 - CHECK_LEVEL) / 3)
    assert outcome.collision_probability[2] == pytest.approx(1 - (0.05 / 6) ** (1 / repaired))
    assert "simultaneous over the 3 plan(s)" in outcome.message
