"""Session 24's cuts of the planner's processor time: the same results, less work.

docs/planning.md, "Swum once, judged again" and "The check's judge: a bound carried from state
to state": a repair's search judges the children a raised margin came near again from the
samples it kept instead of swimming them again (:meth:`eelhost.planning.search.Search.raise_margin`),
and the check's judge measures the body's quarter points only every few states, carrying a bound
to the states between (:func:`eelhost.planning.check.judged_clearance_m`). Each is compared here
with what it replaces.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_planning_raise import DISC, tank

from eelhost.planning import check
from eelhost.planning.body import body_points, link_endpoints
from eelhost.planning.execute import body_clearance_m, quarter_point_values
from eelhost.planning.field import clearance_field
from eelhost.planning.planner import CHECK_MARGIN_M, Planner
from eelhost.planning.uncertainty import default_model
from eelhost.planning.worlds import generate_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)
SWIMMER = MODEL.swimmer_for(ROBOT)
N = ROBOT.n_links


def nearest_site(planner, plan):
    """The body point where the fits' run of ``plan`` comes closest to anything."""
    swum = planner.swim_waters(plan, planner.check_waters([]))[0]
    pts = body_points(planner.model, swum.states, 2)
    clear = planner.clearance(pts)
    k, i = np.unravel_index(int(np.argmin(clear)), clear.shape)
    return (float(pts[k, i, 0]), float(pts[k, i, 1]))


def legs_of(plan):
    return [(leg.waypoint_m, leg.start_step, leg.end_step, leg.min_clearance_m, leg.goal)
            for leg in plan.legs]


def test_a_search_after_a_raise_judges_again_what_it_swam_and_finds_what_swimming_again_finds():
    searches = {}
    for rejudge in (False, True):
        planner = Planner(tank([DISC]), ROBOT, MODEL, check=False)
        search = planner.search
        search.rejudge = rejudge
        first = search.plan()
        assert first.found, first.message
        site = nearest_site(planner, first)
        swum_before = search.simulations
        search.raise_margin(site, 0.05)
        second = search.plan()
        assert second.found, second.message
        searches[rejudge] = (first, second, search.simulations - swum_before)
    (first_a, second_a, swum_a), (first_b, second_b, swum_b) = searches[False], searches[True]
    assert legs_of(first_a) == legs_of(first_b)
    # the raise moved the plan, and both ways find the same one, leg for leg, at the same cost
    assert legs_of(second_a) != legs_of(first_a)
    assert legs_of(second_b) == legs_of(second_a)
    assert second_b.cost_s == second_a.cost_s
    assert second_b.expansions == second_a.expansions
    # judged again, not swum again: fewer manoeuvres swum
    assert swum_b < swum_a


def test_a_raise_that_refuses_a_swum_child_refuses_it_when_judged_again():
    # a raise of the whole margin's worth right on the first plan's closest point: the child that
    # passed there is refused when judged again, exactly as when swum again
    outcome = {}
    for rejudge in (False, True):
        planner = Planner(tank([DISC]), ROBOT, MODEL, check=False, soft_margin=False)
        search = planner.search
        search.rejudge = rejudge
        first = search.plan()
        search.raise_margin(nearest_site(planner, first), 0.15)
        second = search.plan()
        outcome[rejudge] = (second.status, legs_of(second), second.expansions)
    assert outcome[True] == outcome[False]


def test_a_planning_call_with_repairs_returns_the_same_whether_raised_children_are_swum_or_judged():
    # a generated world whose first plan fails its check and is repaired with raised margins
    # (development seed 45049: planned after four repairs at session 24's base; judged again
    # with the cost its children had from their parent when first swum, not the parent's cost
    # now, it was planned after two, another plan)
    world = generate_world(45049)
    got = {}
    for rejudge in (False, True):
        planner = Planner(world, ROBOT, MODEL, seed=45049, unknown_current_m_s=0.0,
                          swimmer=SWIMMER)
        planner.search.rejudge = rejudge
        out = planner.plan()
        got[rejudge] = (out.status, out.repairs, legs_of(out.plan),
                        [(c.label, c.reached, c.min_clearance_m, c.failed_leg)
                         for c in out.checks], planner.search.simulations)
    assert got[True][0] == got[False][0] and got[True][1] == got[False][1] >= 1
    assert got[True][2:4] == got[False][2:4]
    assert got[True][4] < got[False][4]


def test_a_state_s_link_ends_do_not_depend_on_the_states_computed_with_it():
    rng = np.random.default_rng(24)
    states = rng.normal(size=(50, 2 * N + 4))
    together = link_endpoints(SWIMMER, states)
    for i in (0, 7, 49):
        assert np.array_equal(link_endpoints(SWIMMER, states[i : i + 1])[0], together[i])


def test_the_end_motion_bound_is_never_below_how_far_a_link_end_moved():
    rng = np.random.default_rng(2401)
    a = rng.normal(size=(2000, 2 * N + 4))
    b = a.copy()
    # small moves, large ones and whole turns of a link
    b[:, : N + 2] += rng.normal(size=(2000, N + 2)) * rng.choice([1e-3, 0.05, 3.0], (2000, 1))
    moved = np.linalg.norm(link_endpoints(SWIMMER, a) - link_endpoints(SWIMMER, b),
                           axis=2).max(axis=1)
    bound = check.end_motion_bound_m(SWIMMER, a, b)
    assert np.all(bound >= moved - 1e-12)
    assert np.median(bound / np.maximum(moved, 1e-12)) < 3.0  # a bound, not a wild one


def swims_fast_into_things(world, rng, paths=10):
    """Straight paths of a body undulating fast and far, 1-20 mm a step: the carried bound
    spans long moves, and many paths end in an obstacle or a wall."""
    w, h = world.tank.size_m
    out = []
    for _ in range(paths):
        start = rng.uniform([0.3, 0.3], [w - 0.3, h - 0.3])
        heading = rng.uniform(0.0, 2.0 * np.pi)
        steps = int(rng.integers(20, 400))
        speed = rng.uniform(0.001, 0.02)
        t = np.arange(steps)[:, None]
        states = np.zeros((steps, 2 * N + 4))
        states[:, :N] = heading + 0.8 * np.sin(0.3 * t + 1.04 * np.arange(N)[None, :])
        states[:, N : N + 2] = start + speed * t * np.array([np.cos(heading), np.sin(heading)])
        out.append(states)
    return out


@pytest.mark.parametrize("margin_m", [0.0, CHECK_MARGIN_M, 0.1])
def test_the_carried_judge_gives_the_reference_verdict_on_fast_swims(margin_m):
    rng = np.random.default_rng(2402)
    kinds = set()
    for seed in (45000, 45001, 45002):
        world = generate_world(seed)
        field = clearance_field(world)
        for states in swims_fast_into_things(world, rng):
            ref = body_clearance_m(world, field, SWIMMER, states)
            fast = check.judged_clearance_m(world, field, SWIMMER, states, margin_m)
            assert float(fast.min()) == float(ref.min())
            for limit in (0.0, margin_m):
                assert (np.flatnonzero(fast <= limit)[:1].tolist()
                        == np.flatnonzero(ref <= limit)[:1].tolist())
            kinds.add("touched" if ref.min() <= 0.0 else
                      "near" if ref.min() <= margin_m else "clear")
    assert {"touched", "clear"} <= kinds


def test_the_raise_measured_only_near_its_sites_is_the_raise_measured_everywhere():
    search = Planner(tank([DISC]), ROBOT, MODEL, check=False).search
    rng = np.random.default_rng(2403)
    states = np.zeros((3000, 2 * N + 4))
    states[:, :N] = rng.uniform(-np.pi, np.pi, (3000, N))
    states[:, N : N + 2] = rng.uniform([0.0, 0.0], [3.0, 2.0], (3000, 2))
    pts = body_points(search.model, states, search.settings.per_link)
    for site, extra in (((1.0, 1.0), 0.05), ((1.3, 0.9), 0.12), ((2.5, 0.2), 0.03)):
        search.raise_margin(site, extra)
        near = search._raised_near(states[:, N : N + 2], pts)
        everywhere = search.raised_m(pts)
        assert np.array_equal(near, everywhere)
        assert np.any(everywhere > 0) and np.any(everywhere == 0)


def glides_into_things(world, rng, paths=10):
    """A straight body gliding 5-20 mm a step without turning (its ends move as far as its
    centre of mass, so the motion bound is tight and the field's slope alone makes the carried
    bound hold), many into a wall or an obstacle."""
    w, h = world.tank.size_m
    out = []
    for _ in range(paths):
        start = rng.uniform([0.3, 0.3], [w - 0.3, h - 0.3])
        heading = rng.uniform(0.0, 2.0 * np.pi)
        steps = int(rng.integers(20, 200))
        t = np.arange(steps)[:, None]
        states = np.zeros((steps, 2 * N + 4))
        states[:, :N] = heading
        states[:, N : N + 2] = start + rng.uniform(0.005, 0.02) * t * np.array(
            [np.cos(heading), np.sin(heading)])
        out.append(states)
    return out


def test_the_carried_bound_is_never_above_the_reference_s_own_bound():
    # the reference's lower bound at every state (its quarter points), against the bound the
    # judge carries from the anchors: fast, turning swims, in the open water and at the walls
    rng = np.random.default_rng(2404)
    half_link = float(SWIMMER.half_length_m.max())
    carried = 0
    for seed in (45003, 45004):
        world = generate_world(seed)
        field = clearance_field(world)
        for states in [*swims_fast_into_things(world, rng, paths=20),
                       *glides_into_things(world, rng, paths=20)]:
            bound, ceiling = check.carried_lower_m(field, SWIMMER, states)
            own = (quarter_point_values(field, link_endpoints(SWIMMER, states))
                   - field.error_m - half_link / 4.0)
            assert np.all(bound <= own)
            assert ceiling >= float(own.min()) + 2 * field.error_m + half_link / 4.0 - 1e-12
            carried += int(np.sum(bound < own))
    assert carried  # the states between the anchors carry a bound below their own


def test_a_body_clearance_told_a_bound_is_the_one_measured_against_every_obstacle():
    # paths into and through obstacles and walls, each step told the field's bound (negative
    # inside an obstacle): the same distances as without it, and as the field left out
    rng = np.random.default_rng(2405)
    touched = 0
    for seed in (45000, 45005, 45011):
        world = generate_world(seed)
        field = clearance_field(world)
        for states in [*swims_fast_into_things(world, rng), *glides_into_things(world, rng)]:
            ends = link_endpoints(SWIMMER, states)
            upper = quarter_point_values(field, ends) + field.error_m
            told = world.body_clearance(ends, upper)
            assert np.array_equal(told, world.body_clearance(ends))
            assert np.all(told <= np.maximum(upper, 0.0) + 1e-12)
            touched += int(np.sum(told == 0.0))
    assert touched


def test_the_field_read_in_place_is_the_field_read_apart():
    # ClearanceField.__call__ writes its grid coordinates into place: the values of dividing,
    # clipping and joining them apart, inside the grid and beyond it
    from scipy.ndimage import map_coordinates

    field = clearance_field(generate_world(45001))
    rng = np.random.default_rng(2406)
    for shape in [(400, 13, 2), (7, 2), (2,)]:
        p = rng.uniform([-0.3, -0.3], [3.4, 2.4], shape)
        u, v = p[..., 0] / field.cell_m, p[..., 1] / field.cell_m
        uc, vc = np.clip(u, 0.0, field.nx - 1.0), np.clip(v, 0.0, field.ny - 1.0)
        apart = map_coordinates(field.values, [uc.ravel(), vc.ravel()], order=1,
                                prefilter=False, mode="nearest").reshape(u.shape)
        apart = apart - np.hypot(u - uc, v - vc) * field.cell_m
        assert np.array_equal(field(p), apart)
