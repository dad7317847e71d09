"""Benchmark worlds, action coverage, the benchmark's figures and the plan command's bench block."""

from __future__ import annotations

import json
import math
from collections import Counter

import numpy as np
import pytest

from eelhost.commands.plan import BENCH_BEGIN, BENCH_END, _write_block
from eelhost.planning.bench import BenchSummary, WorldResult
from eelhost.planning.coverage import DIRECTIONS_DEG, action_coverage
from eelhost.planning.field import ClearanceField, signed_clearance
from eelhost.planning.uncertainty import default_model, read_coefficient_model
from eelhost.planning.worlds import MIN_GAP_M, TANK_M, _gap, _wall_gap, generate_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)


@pytest.mark.parametrize("seed", range(12))
def test_generated_worlds_keep_the_benchmark_rules(seed):
    world = generate_world(seed)
    assert world.tank.size_m == TANK_M
    assert 5 <= len(world.obstacles) <= 8
    assert 0.0 <= world.current.speed_m_s <= 0.06
    start, goal = np.asarray(world.start.position_m), np.asarray(world.goal.position_m)
    assert np.hypot(*(goal - start)) >= 1.5
    obstacles = [o.model_dump(mode="json") for o in world.obstacles]
    for i, a in enumerate(obstacles):
        wall = _wall_gap(a)
        assert wall <= 1e-9 or wall >= MIN_GAP_M - 1e-9
        for b in obstacles[:i]:
            gap = _gap(a, b)
            assert gap <= 1e-9 or gap >= MIN_GAP_M - 0.01  # outlines are sampled
    assert generate_world(seed) == world  # the seed decides everything


def test_clearance_field_never_overstates_the_clearance():
    world = generate_world(3)
    field = ClearanceField(world)
    rng = np.random.default_rng(0)
    pts = rng.uniform((0, 0), TANK_M, size=(2000, 2))
    exact = signed_clearance(world, pts)
    approx = field(pts)
    assert np.all(approx - field.error_m <= exact + 1e-12)
    assert np.abs(approx - exact).max() <= field.error_m + 1e-12


@pytest.mark.parametrize("speed", [0.0, 0.03, 0.06])
def test_every_current_direction_has_actions_at_every_benchmark_speed(speed):
    coverage = action_coverage(ROBOT, MODEL, speed)
    assert coverage.directions_deg == DIRECTIONS_DEG
    assert coverage.complete, coverage.line()
    assert coverage.line().startswith(f"current {speed:g} m/s: 0 deg: ")


def test_coverage_reports_lost_actions_in_a_current_faster_than_the_robot():
    coverage = action_coverage(ROBOT, MODEL, 0.2)
    assert sum(coverage.counts) < len(coverage.legs) * len(DIRECTIONS_DEG)


def test_coefficient_file_gives_fits_and_bootstrap_std_and_names_bad_keys(tmp_path):
    path = tmp_path / "coefficients.json"
    names = type(MODEL.fits["straight"]).names()
    fit = dict(zip(names, [0.01, 0.8, 0.6, 0.01], strict=True))
    path.write_text(json.dumps({
        "fits": {"straight": {"coefficients": fit}, "turning": {"coefficients": fit}},
        "uncertainty": {"straight": {"std": dict.fromkeys(names, 0.002)}},
    }))
    model = read_coefficient_model(path, ROBOT)
    assert np.allclose(model.std["straight"], 0.002)
    assert np.allclose(model.std["turning"], 0.1 * np.asarray(list(fit.values())))
    assert "no reported uncertainty for turning C_f" in model.source
    assert "drawn independently" in model.source
    drawn = model.draw(np.random.default_rng(1), "straight")
    # within the 95 % region of 4 independent coefficients: at most sqrt(chi2_4(0.95)) std
    assert np.all(np.abs(drawn.as_array() - model.fits["straight"].as_array())
                  <= 0.002 * 3.09)
    path.write_text('{"fits": {"straight": {"coefficients": {"C_f": "x"}}}}')
    with pytest.raises(ValueError, match="fits.straight: missing C_d, C_a, C_m"):
        read_coefficient_model(path, ROBOT)
    path.write_text(json.dumps({"fits": {"straight": {"coefficients": {**fit, "C_f": -0.1}}}}))
    with pytest.raises(ValueError, match="fits.straight.coefficients: not a morison coefficient "
                                         "set .*C_f.*greater than or equal to 0"):
        read_coefficient_model(path, ROBOT)


def test_bench_summary_counts_plans_collisions_and_goals():
    results = [
        WorldResult("a", "found", "", 0.5, 0.4, 0.5, 0, True, False, 0.05, 0.1, 0.06,
                    (20.0, 18.0, 24.0), 20.0),
        WorldResult("b", "found", "", 0.9, 0.7, 0.8, 1, False, True, -0.01, 0.5, 0.06,
                    (20.0, 18.0, 30.0), 20.0),
        WorldResult("c", "unreachable", "", 0.2, 0.1, 0.2, 0),
    ]
    s = BenchSummary(results, Counter(r.status for r in results))
    assert len(s.planned) == 2 and s.collisions == 1 and s.reached == 1
    assert math.isclose(s.median_planning_time_s, 0.5)
    text = "\n".join(s.lines())
    assert "with a plan: 2 (67%)" in text and "1 of 2 (50.0%)" in text
    assert "processor time of the planning (the same span; " in text and "median 0.50 s" in text
    assert "collision probability at most 6.0%" in text
    # b, repaired once, touched; a passed at once and did not
    assert ("repaired after a failed check: 1 (worlds with contact in the fresh draws: 1 of the 1 "
            "repaired plans, 0 of the 1 plans that passed at once)") in text
    assert "over the search's planned time, median 1.35 (max 1.50)" in text


def test_bench_block_replaces_only_its_own_section(tmp_path):
    page = tmp_path / "planning.md"
    page.write_text(f"# Title\n\nbefore\n{BENCH_BEGIN}\nold\n{BENCH_END}\nafter\n")
    _write_block(page, [BENCH_BEGIN, "new", BENCH_END])
    assert page.read_text() == f"# Title\n\nbefore\n{BENCH_BEGIN}\nnew\n{BENCH_END}\nafter\n"


@pytest.mark.slow
def test_bench_gives_the_same_outcomes_in_worker_processes():
    from eelhost.planning.bench import run_bench

    here = run_bench(ROBOT, MODEL, count=1, seed=0)
    there = run_bench(ROBOT, MODEL, count=1, seed=0, jobs=2)
    (a,), (b,) = here.results, there.results
    assert a.name == b.name == "bench_0"
    assert (a.status, a.reached, a.collision) == (b.status, b.reached, b.collision)
    assert a.status == b.status
    if a.status == "found":
        assert a.min_clearance_m == pytest.approx(b.min_clearance_m)


def test_a_coefficient_file_of_another_model_is_planned_in_as_fitted(tmp_path):
    # what `eelbot report` writes when it adopted another model than the robot file's
    from eelhost.estimation.coefficients_file import FittedModel
    from eelhost.estimation.joint_fit import joint_model_name
    from eelhost.estimation.space import spaces_of
    from eelhost.planning.planner import Planner

    space = next(s for s in spaces_of(ROBOT, ["linear_quadratic"], current=True)
                 if s.model_name == "pd x linear_quadratic")
    servo = next(s for s in spaces_of(ROBOT, ["morison"], current=True)
                 if s.model_name == "servo x morison")
    straight = servo.from_dict({**servo.as_dict(servo.start(ROBOT)), "lag_s": 0.04,
                                "current_x_m_s": 0.01, "current_y_m_s": 0.0})
    turning = servo.from_dict({**servo.as_dict(servo.start(ROBOT)), "current_x_m_s": 0.0,
                               "current_y_m_s": 0.02})
    path = tmp_path / "coefficients.json"
    path.write_text(json.dumps({"fits": {
        "straight": FittedModel(servo, straight).to_json(),
        "turning": FittedModel(servo, turning).to_json()}}))
    model = read_coefficient_model(path, ROBOT)
    assert model.robot is not None and joint_model_name(model.robot) == "servo"
    assert model.robot.joints.position_gain_1_s == pytest.approx(25.0)  # 1 / lag
    assert model.ambient_current_m_s == pytest.approx((0.005, 0.01))  # the fits' mean
    assert "servo x morison" in model.source and "fitted current" in model.describe()
    world = generate_world(3)
    planner = Planner(world, ROBOT, model, check=False)
    assert planner.robot is model.robot
    assert planner.world.current_m_s == pytest.approx(
        tuple(np.add(world.current_m_s, (0.005, 0.01))))
    assert planner.twin.current_m_s == pytest.approx(planner.world.current_m_s)
    # another law's coefficients are read by that law, not the robot file's
    lq = space.start(ROBOT)
    path.write_text(json.dumps({"fits": {"joint": FittedModel(space, lq).to_json()}}))
    model = read_coefficient_model(path, ROBOT)
    assert type(model.fits["straight"]).law_name == "linear_quadratic"
    assert model.robot is not None and model.robot.fluid_law.name == "linear_quadratic"
