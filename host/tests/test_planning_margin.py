"""The check's margin: a run that comes within it of anything fails the check.

docs/planning.md ("The planner", step 3): a plan whose worst draw came a few millimetres from
contact is not returned as checked; the run's contact verdict stays its own, the leg it came
close on is the one a repair bans, and the stated interval counts such runs as failures.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

# the still open tank and the default robot of the repairs' tests
from test_planning_repairs import MODEL, ROBOT, open_tank

from eelhost.planning.planner import CHECK_MARGIN_M, Planner, run_failed


@pytest.fixture(scope="module")
def checked():
    planner = Planner(open_tank(), ROBOT, MODEL, draws=4, unknown_current_m_s=0.0,
                      seed=5, check_margin_m=0.0, repairs=0)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    return planner, outcome


def test_a_run_inside_the_margin_fails_the_check_though_it_touched_nothing(checked):
    planner, outcome = checked
    closest = min(r.min_clearance_m for r in outcome.checks)
    assert closest > 0.0 and all(r.ok for r in outcome.checks)
    # the same plan, the same waters, a margin just above the closest run's gap
    planner.check_margin_m = closest + 0.005
    runs, _ = planner.check_plan(outcome.plan, waters=planner.waters(0))
    close = [r for r in runs if r.min_clearance_m <= planner.check_margin_m]
    assert close and all(r.collision_free and r.reached for r in close)  # its own verdict kept
    assert all(run_failed(r, planner.check_margin_m) for r in close)
    # the leg it came that close on is named, so a repair can ban it
    assert all(r.failed_leg is not None and 0 <= r.failed_leg < len(outcome.plan.legs)
               for r in close)
    assert "inside the check's" in planner.verdict(close[0])
    # and the planning call refuses the plan (no repairs allowed here)
    again = planner.plan()
    assert again.status == "check_failed" and "margin" in again.message, again.message
    planner.check_margin_m = 0.0
    assert planner.plan().found  # without the margin the same plan passes


def test_the_stated_interval_counts_runs_inside_the_margin_as_failures(checked):
    _, outcome = checked
    clear = min(r.min_clearance_m for r in outcome.drawn_checks)
    plain = outcome.collision_probability
    assert plain[0] == 0.0
    within = dataclasses.replace(outcome, margin_m=clear + 0.001)
    inside = sum(r.min_clearance_m <= clear + 0.001 for r in outcome.drawn_checks)
    p, low, high = within.collision_probability
    assert inside >= 1 and p == pytest.approx(inside / outcome.draws)
    assert low > 0.0 and high > plain[2]
    assert "mm clear" in within.confidence()


def test_the_default_margin_is_kept_and_a_negative_one_is_refused():
    assert Planner(open_tank(), ROBOT, MODEL, draws=2).check_margin_m == CHECK_MARGIN_M
    with pytest.raises(ValueError, match="check_margin_m"):
        Planner(open_tank(), ROBOT, MODEL, draws=2, check_margin_m=-0.01)
    assert np.isfinite(CHECK_MARGIN_M) and CHECK_MARGIN_M > 0.0
