"""A replan's search exhausted with the default actions tries the finer ones (opt-in).

The start is a replan's recorded on development seed 17210 (session 10, closed loop, pure
pursuit, the check told of no unknown current): every default leg from it broke the world's
margin within ten expansions (docs/planning.md, "Session 10's development figures: the replans'
search").
"""

from __future__ import annotations

import numpy as np

from eelhost.planning.planner import FINE_ACTIONS, Planner
from eelhost.planning.tank import with_extra_current
from eelhost.planning.uncertainty import default_model
from eelhost.planning.worlds import generate_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)
START = np.array([-2.52551, -3.05736, -3.54285, -3.64582, -3.5095, -3.47413, 1.49512, 0.98093,
                  2.16329, -0.09434, -0.80207, -0.26979, 0.15236, 0.01043, -0.1063, -0.00211])
START_T_S = 12.3
CURRENT_M_S = (-0.0156, -0.0155)  # the replan's water: the world's plus the estimated extra


def replan_planner(fine: bool) -> Planner:
    world = generate_world(17210)
    planner = Planner(world, ROBOT, MODEL, unknown_current_m_s=0.0, fine_fallback=fine)
    extra = np.subtract(CURRENT_M_S, planner.world.current_m_s)
    return Planner(with_extra_current(world, extra), ROBOT, MODEL, unknown_current_m_s=0.0,
                   fine_fallback=fine, swimmer=planner.model)


def test_a_replan_start_exhausted_by_the_default_actions_is_planned_with_the_finer_ones():
    coarse = replan_planner(fine=False)
    step = int(round(START_T_S / coarse.twin.dt_s))
    assert coarse.plan(START, step).status == "exhausted"
    planner = replan_planner(fine=True)
    outcome = planner.plan(START, step)
    assert outcome.found, outcome.message
    assert "with the finer actions" in outcome.message
    # it passed the unchanged check: every run clear by the check's margin
    assert planner.fine_search().settings.actions == FINE_ACTIONS
    assert outcome.checks and all(c.min_clearance_m > planner.check_margin_m
                                  for c in outcome.checks)


def test_the_first_plan_from_the_start_never_uses_the_finer_actions():
    planner = replan_planner(fine=True)
    outcome = planner.plan()
    assert "finer actions" not in outcome.message
    assert planner._fine_search is None
