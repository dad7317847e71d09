"""The check's faster paths against their reference implementations: the same verdicts, values.

docs/planning.md, "The check's processor time": the check's judge screens states by the link
end points before the reference's quarter points and exact geometry
(:func:`eelhost.planning.check.judged_clearance_m` against
:func:`eelhost.planning.execute.body_clearance_m`), the water draws keep each covariance's
decomposition (:func:`eelhost.planning.uncertainty.region_draw`), the body's points are
written in place (:func:`eelhost.planning.body.body_points`) and the point-to-segment distances
are summed by components (:func:`eelhost.planning.geometry.point_segment_distance`). Each is
compared here with the reference it replaces.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from eelhost.planning import check
from eelhost.planning import field as field_module
from eelhost.planning import world as world_module
from eelhost.planning.body import body_points, link_endpoints
from eelhost.planning.execute import body_clearance_m
from eelhost.planning.field import clearance_field, signed_clearance
from eelhost.planning.geometry import point_segment_distance
from eelhost.planning.planner import CHECK_MARGIN_M, Planner
from eelhost.planning.uncertainty import REGION_LEVEL, default_model, region_draw
from eelhost.planning.world import load_world
from eelhost.planning.worlds import generate_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)
SWIMMER = MODEL.swimmer_for(ROBOT)


def swims_into_things(world, rng, paths=12):
    """Straight paths of an undulating body from random starts, 1 mm a step, 0.1-1.5 m long:
    many end in an obstacle or a wall, some pass close by, some stay clear."""
    n = SWIMMER.n_links
    w, h = world.tank.size_m
    out = []
    for _ in range(paths):
        start = rng.uniform([0.3, 0.3], [w - 0.3, h - 0.3])
        heading = rng.uniform(0.0, 2.0 * np.pi)
        steps = int(rng.integers(100, 1500))
        t = np.arange(steps)[:, None]
        states = np.zeros((steps, 2 * n + 4))
        states[:, :n] = heading + 0.4 * np.sin(0.02 * t + 1.04 * np.arange(n)[None, :])
        states[:, n : n + 2] = start + 0.001 * t * np.array([np.cos(heading), np.sin(heading)])
        out.append(states)
    return out


def verdict(clear, margin_m):
    """What the check reads of a run's clearances: the smallest, the first contact, the first
    step inside the margin."""
    first = np.flatnonzero(clear <= 0.0)
    near = np.flatnonzero(clear <= margin_m)
    return (float(clear.min()), first[:1].tolist(), near[:1].tolist())


@pytest.mark.parametrize("margin_m", [0.0, CHECK_MARGIN_M, 0.1])
def test_screened_judge_gives_the_reference_verdict_on_paths_into_obstacles(margin_m):
    rng = np.random.default_rng(28500)
    touched = clear = skipped = rows = 0
    for seed in (28500, 28501, 28502, 28503):
        world = generate_world(seed)
        field = clearance_field(world)
        for states in swims_into_things(world, rng):
            ref = body_clearance_m(world, field, SWIMMER, states)
            fast = check.judged_clearance_m(world, field, SWIMMER, states, margin_m)
            assert verdict(fast, margin_m) == verdict(ref, margin_m)
            # where the screen left the reference out, its bound is above what matters
            touched += bool(ref.min() <= 0.0)
            clear += bool(ref.min() > margin_m)
            skipped += int(np.sum(fast != ref))
            rows += len(states)
    # the paths cover both kinds of run, and the screen did leave states out
    assert touched and clear
    assert 0 < skipped < rows


def test_a_check_judged_by_the_screen_and_by_the_reference_gives_the_same_runs(monkeypatch):
    # the example's time-only plan, checked in a 0.02 m/s unknown current: some runs touch,
    # some come within the margin, some pass (test_planning_check.py's plan)
    world = load_world("tank_5_obstacles")
    plan = Planner(world, ROBOT, MODEL, check=False, soft_margin=False).plan().plan
    checker = Planner(world, ROBOT, MODEL, draws=12, unknown_current_m_s=0.02, seed=0)
    waters = checker.check_waters()
    fast = checker.swim_waters(plan, waters)
    monkeypatch.setattr(check, "judged_clearance_m",
                        lambda w, f, m, s, margin_m=0.0: body_clearance_m(w, f, m, s))
    ref = checker.swim_waters(plan, waters)
    assert [(r.label, r.reached, r.collision_free, r.min_clearance_m, r.first_collision_s,
             r.failed_leg, r.goal_time_s) for r in fast] == [
        (r.label, r.reached, r.collision_free, r.min_clearance_m, r.first_collision_s,
         r.failed_leg, r.goal_time_s) for r in ref]
    assert any(not r.collision_free for r in ref)
    assert any(r.collision_free and r.failed_leg is None for r in ref)


def reference_region_draw(rng, cov, level=REGION_LEVEL):
    """region_draw as it was before the decomposition was kept (eigh and chi2 at every call)."""
    values, vectors = np.linalg.eigh(np.asarray(cov, dtype=float))
    scale = np.sqrt(np.clip(values, 0.0, None))
    dims = int(np.count_nonzero(scale > 0))
    if dims == 0:
        return np.zeros(len(values))
    limit = chi2.ppf(level, dims)
    while True:
        z = rng.standard_normal(len(values)) * (scale > 0)
        if z @ z <= limit:
            return np.asarray(vectors @ (scale * z), dtype=float)


def test_region_draws_with_the_kept_decomposition_are_the_fresh_ones():
    correlated = np.array([[4.0, 1.2, 0.0], [1.2, 1.0, 0.3], [0.0, 0.3, 0.5]]) * 1e-4
    flat = np.diag([1e-4, 0.0, 2e-4])  # a direction of zero variance stays at 0
    for cov in (MODEL.covariance("straight"), MODEL.covariance("turning"), correlated, flat,
                np.zeros((2, 2))):
        fast, ref = np.random.default_rng(7), np.random.default_rng(7)
        for _ in range(200):
            assert np.array_equal(region_draw(fast, cov), reference_region_draw(ref, cov))
        assert fast.random() == ref.random()  # the generator consumed alike
    # and a whole check's draws through the model
    a = MODEL.water_draws(np.random.default_rng(3), 60)
    b = MODEL.water_draws(np.random.default_rng(3), 60)
    assert [(w.straight.as_array().tolist(), w.turning.as_array().tolist(),
             w.current_offset_m_s) for w in a] == [
        (w.straight.as_array().tolist(), w.turning.as_array().tolist(), w.current_offset_m_s)
        for w in b]


def reference_body_points(model, states, per_link=2):
    """body_points as it was: joined and broadcast (the same sums)."""
    n = model.n_links
    theta = states[:, :n]
    c, s = np.cos(theta), np.sin(theta)
    g = model.geometry
    xc = states[:, n : n + 1] + c @ g.T
    yc = states[:, n + 1 : n + 2] + s @ g.T
    lh = model.half_length_m
    x = np.concatenate([xc[:, :1] - lh[0] * c[:, :1], xc + lh * c], axis=1)
    y = np.concatenate([yc[:, :1] - lh[0] * s[:, :1], yc + lh * s], axis=1)
    ends = np.stack([x, y], axis=-1)
    if per_link <= 1:
        return ends
    a, b = ends[:, :-1], ends[:, 1:]
    f = np.arange(per_link) / per_link
    inner = a[:, :, None, :] + f[None, None, :, None] * (b - a)[:, :, None, :]
    return np.concatenate([inner.reshape(len(states), -1, 2), ends[:, -1:]], axis=1)


@pytest.mark.parametrize("per_link", [1, 2, 3, 4])
def test_body_points_written_in_place_are_the_broadcast_ones_bit_for_bit(per_link):
    rng = np.random.default_rng(1)
    n = SWIMMER.n_links
    states = rng.normal(0.0, 1.0, (500, 2 * n + 4))
    states[:, n : n + 2] = rng.uniform(0.0, 3.0, (500, 2))
    assert np.array_equal(body_points(SWIMMER, states, per_link),
                          reference_body_points(SWIMMER, states, per_link))
    assert np.array_equal(link_endpoints(SWIMMER, states),
                          reference_body_points(SWIMMER, states, 1))


def reference_point_segment_distance(points, a, b):
    """point_segment_distance as it was: products summed over the last axis."""
    ab = b - a
    ap = points[..., :, None, :] - a[..., None, :, :]
    denom = np.sum(ab * ab, axis=-1)[..., None, :]
    safe = np.where(denom > 0, denom, 1.0)
    t = np.clip(np.sum(ap * ab[..., None, :, :], axis=-1) / safe, 0.0, 1.0)
    t = np.where(denom > 0, t, 0.0)
    gap = ap - t[..., None] * ab[..., None, :, :]
    return np.sqrt(np.sum(gap * gap, axis=-1))


def test_point_segment_distance_by_components_is_the_summed_one_bit_for_bit(monkeypatch):
    rng = np.random.default_rng(2)
    a = rng.uniform(0.0, 3.0, (40, 7, 2))
    b = a + rng.normal(0.0, 0.1, a.shape)
    b[:, 3] = a[:, 3]  # degenerate segments, as hull padding
    pts = rng.uniform(0.0, 3.0, (40, 9, 2))
    centre = np.array([1.2, 0.7])
    # the shapes the world's and the field's callers pass
    for args in ((pts, a, b), (centre[None, None], a, b), (pts[0], a[0], b[0]),
                 (pts[:1], a, b)):
        assert np.array_equal(point_segment_distance(*args),
                              reference_point_segment_distance(*args))
    # and the signed clearance the field is built from, and the exact body clearance
    world = generate_world(28504)
    where = rng.uniform([-0.1, -0.1], [3.1, 2.1], (20000, 2))
    states = swims_into_things(world, rng, paths=4)
    fast = (signed_clearance(world, where),
            [world.body_clearance(link_endpoints(SWIMMER, s)) for s in states])
    monkeypatch.setattr(field_module, "point_segment_distance", reference_point_segment_distance)
    monkeypatch.setattr(world_module, "point_segment_distance", reference_point_segment_distance)
    assert np.array_equal(fast[0], signed_clearance(world, where))
    for got, s in zip(fast[1], states, strict=True):
        assert np.array_equal(got, world.body_clearance(link_endpoints(SWIMMER, s)))
