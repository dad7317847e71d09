"""A repair raises the search's margin where the check failed (docs/planning_history.md, "A repair with
the margin raised where the check failed")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eelhost.planning.body import body_points
from eelhost.planning.execute import Swim
from eelhost.planning.planner import RAISE_SAFETY_M, Planner
from eelhost.planning.search import RAISE_INNER_M, RAISE_OUTER_M
from eelhost.planning.uncertainty import default_model
from eelhost.planning.world import parse_world
from eelsim.dynamics import straight_state
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)
N = ROBOT.n_links
DISC = {"kind": "circle", "centre_m": [1.25, 1.05], "radius_m": 0.1}


def tank(obstacles=()):
    return parse_world({
        "name": "open",
        "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": [0.7, 1.0], "heading_deg": 0.0},
        "goal": {"position_m": [2.2, 1.0], "radius_m": 0.2},
        "current": {"speed_m_s": 0.0, "direction_deg": 0.0},
        "obstacles": list(obstacles),
    })


def run(states, clearance_m, touched=False, reached=True):
    return Swim("draw", reached, 10.0 if reached else None, not touched, clearance_m,
                1.0 if touched else None, 0.0, 0, "", np.zeros(len(states)), states)


def test_a_raised_margin_counts_whole_near_its_site_fades_out_and_is_undone():
    search = Planner(tank(), ROBOT, MODEL, check=False).search
    pts = np.array([[1.0, 1.0], [1.0 + RAISE_INNER_M, 1.0],
                    [1.0 + 0.5 * (RAISE_INNER_M + RAISE_OUTER_M), 1.0],
                    [1.0, 1.0 + RAISE_OUTER_M + 0.01]])
    assert np.all(search.raised_m(pts) == 0.0)
    search.raise_margin((1.0, 1.0), 0.05)
    search.raise_margin((1.0, 1.0), 0.02)  # overlapping raises: the largest counts
    assert search.raised_m(pts) == pytest.approx([0.05, 0.05, 0.025, 0.0])
    search.clear_raised()
    assert np.all(search.raised_m(pts) == 0.0)


def test_a_search_with_the_margin_raised_where_its_plan_passed_close_passes_further_away():
    planner = Planner(tank([DISC]), ROBOT, MODEL, check=False, soft_margin=False)
    search = planner.search
    fits = planner.check_waters([])

    def nearest(plan):
        """The fits' run of the plan: its smallest body gap, and the body point there."""
        swum = planner.swim_waters(plan, fits)[0]
        pts = body_points(planner.model, swum.states, 2)
        clear = planner.clearance(pts)
        k, i = np.unravel_index(int(np.argmin(clear)), clear.shape)
        return swum.min_clearance_m, (float(pts[k, i, 0]), float(pts[k, i, 1]))

    first = search.plan()
    assert first.found, first.message
    gap, site = nearest(first)
    search.raise_margin(site, 0.05)
    second = search.plan()
    assert second.found, second.message
    assert nearest(second)[0] > gap + 0.03
    # a new planning call starts without the raise, and finds the first plan again
    again = planner.plan()
    assert again.found and nearest(again.plan)[0] == pytest.approx(gap)


def test_a_failing_run_names_its_closest_body_point_and_the_room_the_next_plan_needs():
    planner = Planner(tank([DISC]), ROBOT, MODEL, check=False)
    # the straight body below the disc, its centre line 45 mm from it (body gap 25 mm)
    half = planner.body_half_width_m
    y = 1.05 - 0.1 - 0.045
    bad = straight_state(planner.model, 0.0, (1.25, y))[None]
    nominal = straight_state(planner.model, 0.0, (1.25, y - 0.04))[None]  # 40 mm further off
    gap = 0.045 - half
    sites = planner.failure_sites([run(nominal, gap + 0.04), run(bad, gap)],
                                  [run(bad, gap)])
    assert len(sites) == 1
    (x, yy), extra = sites[0]
    assert math.hypot(x - 1.25, yy - (1.05 - 0.1)) < 0.05  # the body point nearest the disc
    kept = 0.045 + 0.04  # the fits' run's centre line there
    lacked = planner.check_margin_m - gap
    want = kept + lacked + RAISE_SAFETY_M - planner.settings.margin_m
    assert extra == pytest.approx(want, abs=0.012)  # the field's interpolation and sampling
    # a run that only missed the goal has no place to keep away from
    assert planner.failure_sites([run(nominal, 0.2)], [run(nominal, 0.2, reached=False)]) == []
