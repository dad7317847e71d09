"""The geometric ceiling (eelhost.planning.ceiling) against worlds whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from eelhost.planning.ceiling import CELL_M, distance_field, share_at_least, world_ceiling
from eelhost.planning.field import signed_clearance
from eelhost.planning.world import parse_world
from eelhost.planning.worlds import generate_world

LENGTH_M = 0.64


def _world(obstacles, start=(0.5, 1.0), heading=0.0):
    return parse_world({
        "name": "hand_made",
        "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": list(start), "heading_deg": heading},
        "goal": {"position_m": [2.5, 1.0], "radius_m": 0.2},
        "obstacles": obstacles,
    })


def _barrier_with_gap(gap_m, centre_y=1.0):
    """A wall-to-wall barrier at x = 1.4-1.6 m with one gap of ``gap_m`` centred at ``centre_y``."""
    low, high = centre_y - gap_m / 2, centre_y + gap_m / 2
    return [
        {"kind": "polygon", "vertices_m": [[1.4, 0.0], [1.6, 0.0], [1.6, low], [1.4, low]]},
        {"kind": "polygon", "vertices_m": [[1.4, high], [1.6, high], [1.6, 2.0], [1.4, 2.0]]},
    ]


@pytest.mark.parametrize("gap_m", [0.15, 0.3, 0.45])
def test_a_single_gap_limits_the_route_to_half_its_width(gap_m):
    ceiling = world_ceiling(_world(_barrier_with_gap(gap_m, centre_y=0.9)), LENGTH_M)
    assert ceiling.bottleneck_m == pytest.approx(gap_m / 2, abs=CELL_M)


def test_an_empty_tank_is_limited_by_the_wall_behind_the_goal_disc():
    # the widest route ends at the goal disc's nearest point, 3.0 - 2.5 + 0.2 m from the wall
    ceiling = world_ceiling(_world([]), LENGTH_M)
    assert ceiling.bottleneck_m == pytest.approx(0.7, abs=CELL_M)


def test_a_closed_barrier_leaves_no_route():
    closed = [{"kind": "polygon", "vertices_m": [[1.4, 0.0], [1.6, 0.0], [1.6, 2.0], [1.4, 2.0]]}]
    assert world_ceiling(_world(closed), LENGTH_M).bottleneck_m == 0.0


def test_a_disc_in_the_way_is_passed_on_its_wider_side():
    # a disc of radius 0.2 m at y = 0.7: the wider side is above it, 2.0 - 0.9 = 1.1 m wide
    # (below: 0.5 m), so the route keeps half of 1.1 m
    disc = [{"kind": "circle", "centre_m": [1.5, 0.7], "radius_m": 0.2}]
    assert world_ceiling(_world(disc), LENGTH_M).bottleneck_m == pytest.approx(0.55, abs=CELL_M)
    # a barrier that leaves only gaps of 0.3 m on either side of a disc: half of 0.3 m
    gate = _barrier_with_gap(1.0) + [{"kind": "circle", "centre_m": [1.5, 1.0], "radius_m": 0.2}]
    assert world_ceiling(_world(gate), LENGTH_M).bottleneck_m == pytest.approx(0.15, abs=CELL_M)


def test_the_start_clearance_is_the_straight_body_from_the_nearest_wall():
    near_wall = world_ceiling(_world([], start=(0.5, 0.12)), LENGTH_M)
    assert near_wall.start_clearance_m == pytest.approx(0.12, abs=1e-9)
    across = world_ceiling(_world([], start=(1.0, 1.0), heading=90.0), LENGTH_M)
    assert across.start_clearance_m == pytest.approx(1.0 - LENGTH_M / 2, abs=1e-9)
    assert across.room_m() == min(across.bottleneck_m, across.start_clearance_m)


def test_shares_count_values_at_or_above_each_threshold():
    assert share_at_least([0.1, 0.2, 0.3, 0.4], [0.1, 0.25, 0.5]) == [1.0, 0.5, 0.0]


def test_the_ceiling_distance_field_agrees_with_the_planners_exact_clearance():
    # two implementations written apart: shapely's distance (the ceiling) and the planner's
    # signed clearance (eelhost.planning.field), on a generated world, outside the obstacles
    world = generate_world(8000)
    xs, ys, clearance = distance_field(world, 0.05)
    gx, gy = np.meshgrid(xs, ys)
    planner = signed_clearance(world, np.c_[gx.ravel(), gy.ravel()]).reshape(gx.shape)
    outside = planner > 0
    assert outside.mean() > 0.5
    assert np.allclose(clearance[outside], planner[outside], atol=1e-4)
    assert np.all(clearance[~outside] <= 1e-9)
