import math

import numpy as np
import pytest

from eelhost.planning.execute import execute_plan
from eelhost.planning.primitives import REST, SWIMMING, Discretisation, load_or_build
from eelhost.planning.search import heuristic_s, place, plan_path
from eelhost.planning.world import load_world, parse_world
from eelsim.control import wrap_angle
from eelsim.robot import load_robot

SMALL = Discretisation(distances_m=(0.35,), bearings_deg=(-45.0, 0.0, 45.0))


@pytest.fixture(scope="module")
def robot():
    return load_robot()


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("primitives")


def library(robot, cache, speed, disc=SMALL):
    lib, _ = load_or_build(robot, robot.hydrodynamics, speed, disc, cache_dir=cache)
    return lib


def open_tank(speed, direction, start, goal, obstacles=()):
    return parse_world({
        "tank": {"size_m": [3.0, 2.0]},
        "start": {"position_m": list(start), "heading_deg": 0.0},
        "goal": {"position_m": list(goal), "radius_m": 0.2},
        "current": {"speed_m_s": speed, "direction_deg": direction},
        "obstacles": list(obstacles),
    })


def test_library_is_cached_on_disk_and_reloaded_unchanged(robot, tmp_path):
    first, built = load_or_build(robot, robot.hydrodynamics, 0.02, SMALL, cache_dir=tmp_path)
    again, built_again = load_or_build(robot, robot.hydrodynamics, 0.02, SMALL,
                                       cache_dir=tmp_path)
    assert built and not built_again
    assert again.key == first.key
    np.testing.assert_array_equal(again.end_pose, first.end_pose)
    np.testing.assert_array_equal(again.hulls, first.hulls)
    other, _ = load_or_build(robot, robot.hydrodynamics, 0.04, SMALL, cache_dir=tmp_path)
    assert other.key != first.key  # another current speed is another library


def test_primitives_start_at_the_origin_and_their_hull_holds_the_path(robot, cache):
    lib = library(robot, cache, 0.03)
    assert lib.success.any()
    for i in np.flatnonzero(lib.success):
        hull = lib.hulls[i]
        edges = np.roll(hull, -1, axis=0) - hull
        for point in (np.zeros(2), lib.end_pose[i, :2]):
            rel = point - hull
            assert np.all(edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0] >= -1e-12)
        assert lib.duration_s[i] > 0


def test_path_around_obstacles_is_found_and_collision_free_when_executed(robot, cache):
    world = load_world("tank_5_obstacles")
    lib = library(robot, cache, world.current.speed_m_s, Discretisation())
    plan = plan_path(world, lib)
    assert plan.found, plan.message
    assert plan.steps[0].kind == "rest"
    assert all(s.kind == "swimming" for s in plan.steps[1:])
    for step in plan.steps:
        assert world.hull_is_free(step.hull, world.clearance_m + lib.body_half_width_m)
    run = execute_plan(world, plan, robot, robot.hydrodynamics)
    assert run.reached, run.message
    assert run.collision_free, run.message


def test_walled_off_goal_is_reported_unreachable(robot, cache):
    wall = {"kind": "polygon", "vertices_m": [[1.8, 0.0], [2.0, 0.0], [2.0, 2.0], [1.8, 2.0]]}
    world = open_tank(0.03, 180.0, (0.5, 1.0), (2.5, 1.0), [wall])
    plan = plan_path(world, library(robot, cache, 0.03))
    assert not plan.found
    assert plan.message.startswith("goal unreachable")
    assert plan.steps == [] and math.isnan(plan.cost_s)
    assert plan.expansions > 1  # it searched, and ran out of poses rather than hitting a limit


def test_heuristic_never_exceeds_the_cost_of_sampled_primitive_chains(robot, cache):
    lib = library(robot, cache, 0.03)
    rng = np.random.default_rng(9)
    for _ in range(200):
        pose = (1.5, 1.0, float(rng.uniform(-math.pi, math.pi)))
        start = pose
        cost, kind = 0.0, REST
        for _ in range(int(rng.integers(1, 6))):
            rows = lib.group(kind, int(rng.integers(8)))
            if rows.size == 0:
                continue
            row = int(rng.choice(rows))
            xy = place(pose, lib.end_pose[row, :2])
            pose = (float(xy[0]), float(xy[1]), float(wrap_angle(pose[2] + lib.end_pose[row, 2])))
            cost += float(lib.duration_s[row])
            kind = SWIMMING
        # a goal disc placed where the chain ended: the chain is one way to reach it
        world = open_tank(0.03, 0.0, start[:2], (1.5, 1.0), [])
        world = world.model_copy(update={"goal": world.goal.model_copy(
            update={"position_m": (pose[0] + 0.1, pose[1]), "radius_m": 0.1})})
        assert heuristic_s(world, lib, np.array(start[:2])) <= cost + 1e-9


def test_heuristic_is_a_lower_bound_on_the_planned_cost(robot, cache):
    lib = library(robot, cache, 0.03)
    world = open_tank(0.03, 90.0, (0.5, 1.0), (2.4, 1.3))
    plan = plan_path(world, lib)
    assert plan.found
    assert heuristic_s(world, lib, np.array([0.5, 1.0])) <= plan.cost_s


def test_following_current_makes_the_plan_faster_than_an_opposing_one(robot, cache):
    lib = library(robot, cache, 0.03)
    with_current = plan_path(open_tank(0.03, 0.0, (0.5, 1.0), (2.5, 1.0)), lib)
    against = plan_path(open_tank(0.03, 180.0, (0.5, 1.0), (2.5, 1.0)), lib)
    assert with_current.found and against.found
    assert with_current.cost_s < against.cost_s


def test_cross_current_plan_uses_primitives_for_the_current_on_the_correct_side(robot, cache):
    lib = library(robot, cache, 0.03)
    # heading 0 deg (+x); a current towards +y comes from the robot's right and pushes it left
    left = plan_path(open_tank(0.03, 90.0, (0.5, 1.0), (2.5, 1.0)), lib)
    right = plan_path(open_tank(0.03, -90.0, (0.5, 1.0), (2.5, 1.0)), lib)
    assert left.found and right.found
    first_left, first_right = left.steps[0], right.steps[0]
    assert first_left.current_rel_deg == pytest.approx(90.0)
    assert first_right.current_rel_deg == pytest.approx(270.0)
    # mirrored currents give mirrored plans: the robot's first move is pushed to opposite sides
    assert (first_left.end_pose[1] - 1.0) * (first_right.end_pose[1] - 1.0) < 0
