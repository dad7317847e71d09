"""The planner's check in the water it does not know: joint draws, an unknown current, confidence.

Contact is judged here by the independent audit (:mod:`eelhost.planning.audit`, shapely), not by
the planner's own geometry.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.stats import chi2

from eelhost.planning.audit import body_gaps_m, centre_lines
from eelhost.planning.body import link_endpoints
from eelhost.planning.execute import swim
from eelhost.planning.planner import CHECK_MARGIN_M, REPAIR_DRAWS_FACTOR, Planner
from eelhost.planning.uncertainty import (
    CURRENT_DIRECTIONS,
    clopper_pearson,
    default_model,
    read_coefficient_model,
)
from eelhost.planning.world import load_world, parse_world
from eelsim.robot import load_robot

ROBOT = load_robot()
MODEL = default_model(ROBOT)


def test_clopper_pearson_interval_of_no_failures_is_close_to_the_rule_of_three():
    low, high = clopper_pearson(0, 60)
    assert low == 0.0 and high == pytest.approx(1 - 0.025 ** (1 / 60))
    assert 3 / 60 < high < 3.7 / 60  # the one-sided rule of three is 3 / n
    low, high = clopper_pearson(5, 50)  # a textbook value: 3.3 % to 21.8 %
    assert low == pytest.approx(0.0333, abs=5e-4) and high == pytest.approx(0.2181, abs=5e-4)
    assert clopper_pearson(7, 7)[1] == 1.0


def test_draws_move_every_coefficient_together_and_stay_in_the_fits_95_percent_region():
    rng = np.random.default_rng(3)
    draws = np.array([MODEL.draw(rng, "straight").as_array() for _ in range(400)])
    dev = (draws - MODEL.fits["straight"].as_array()) / MODEL.std["straight"]
    # every draw moves all four coefficients (not one at a time) ...
    assert np.all(np.count_nonzero(np.abs(dev) > 1e-9, axis=1) == 4)
    # ... within the region holding 95 % of the fit's normal, and fills it
    radius2 = (dev**2).sum(axis=1)
    assert radius2.max() <= chi2.ppf(0.95, 4) + 1e-9
    assert np.quantile(radius2, 0.9) > 0.8 * chi2.ppf(0.85, 4)


def test_bootstrap_replicates_in_the_file_give_the_draws_their_correlation(tmp_path):
    names = type(MODEL.fits["straight"]).names()
    fit = dict(zip(names, [0.01, 0.8, 0.6, 0.01], strict=True))
    rng = np.random.default_rng(0)
    z = rng.standard_normal(40)
    # C_d and C_a move together in the replicates, C_f against them
    samples = [{"C_f": 0.01 - 0.001 * a, "C_d": 0.8 + 0.05 * a, "C_a": 0.6 + 0.04 * a,
                "C_m": 0.01 + 0.001 * b} for a, b in zip(z, rng.standard_normal(40), strict=True)]
    lower = {"C_f": 0.008, "C_d": 0.7, "C_a": 0.52, "C_m": 0.008}
    upper = {"C_f": 0.012, "C_d": 0.9, "C_a": 0.68, "C_m": 0.012}
    path = tmp_path / "coefficients.json"
    path.write_text(json.dumps({
        "fits": {"joint": {"coefficients": fit}},
        "uncertainty": {"joint": {"level": 0.95, "lower": lower, "upper": upper,
                                  "samples": samples}},
    }))
    model = read_coefficient_model(path, ROBOT)
    assert "correlation from the bootstrap replicates" in model.source
    # the marginal spread is the reported interval's (half width over 1.96)
    assert model.std["straight"][1] == pytest.approx(0.1 / 1.96, rel=1e-4)
    draws = np.array([model.draw(rng, "straight").as_array() for _ in range(300)])
    corr = np.corrcoef(draws, rowvar=False)
    assert corr[1, 2] > 0.9 and corr[0, 1] < -0.9 and abs(corr[1, 3]) < 0.3


def directions_deg(draws):
    offsets = np.array([d.current_offset_m_s for d in draws])
    return np.degrees(np.arctan2(offsets[:, 1], offsets[:, 0])) % 360, np.hypot(*offsets.T)


def test_check_draws_put_one_current_direction_in_every_sector_in_random_order():
    draws = MODEL.water_draws(np.random.default_rng(5), 60, 0.02)
    angles, speeds = directions_deg(draws)
    assert np.allclose(speeds, 0.02)
    # one draw in each 6-degree sector, so every band of directions 12 degrees wide holds one
    assert sorted((angles // 6).astype(int)) == list(range(60))
    # the first draws (the screen among them) are spread round the circle, not in 72 degrees
    assert np.ptp(angles[:12]) > 180


def test_a_band_of_failing_directions_between_the_lattices_is_found_only_by_the_check_draws():
    # a plan failing for currents towards 10-30 degrees (5.6 % of directions): 60 lattice draws
    # (8 directions) miss the band in most seeds, the check's stratified draws never do
    missed = {"stratified": 0, "lattice": 0}
    for seed in range(40):
        for way in missed:
            angles, _ = directions_deg(MODEL.water_draws(np.random.default_rng(seed), 60, 0.02,
                                                          way))
            missed[way] += not np.any((angles > 10) & (angles < 30))
    assert missed["stratified"] == 0 and missed["lattice"] > 15


def test_lattice_draws_put_the_unknown_current_at_its_bound_round_the_circle():
    draws = MODEL.water_draws(np.random.default_rng(5), 2 * CURRENT_DIRECTIONS, 0.02, "lattice")
    offsets = np.array([d.current_offset_m_s for d in draws])
    assert np.allclose(np.hypot(*offsets.T), 0.02)
    angles = np.sort(np.degrees(np.arctan2(offsets[:CURRENT_DIRECTIONS, 1],
                                           offsets[:CURRENT_DIRECTIONS, 0])) % 360)
    assert np.allclose(np.diff(angles), 360 / CURRENT_DIRECTIONS)
    # each draw has both sets, each moved from its own fit
    for d in draws[:4]:
        for motion, drawn in (("straight", d.straight), ("turning", d.turning)):
            assert not np.allclose(drawn.as_array(), MODEL.fits[motion].as_array())


def test_audit_body_outline_is_the_planners_link_chain():
    rng = np.random.default_rng(2)
    planner = Planner(load_world("tank_5_obstacles"), ROBOT, MODEL, check=False)
    n = ROBOT.n_links
    states = np.zeros((5, 2 * n + 4))
    states[:, :n] = rng.uniform(-1, 1, (5, n))
    states[:, n : n + 2] = rng.uniform(0.5, 1.5, (5, 2))
    assert np.allclose(centre_lines(planner.model, states), link_endpoints(planner.model, states))


def test_audit_finds_contact_where_the_body_lies_across_an_obstacle():
    world = parse_world({"tank": {"size_m": [3.0, 2.0]}, "start": {"position_m": [0.5, 1.0]},
                         "goal": {"position_m": [2.5, 1.0]}, "obstacles": [
                             {"kind": "circle", "centre_m": [1.5, 1.0], "radius_m": 0.05},
                             {"kind": "polygon", "vertices_m": [[2.0, 0.0], [2.1, 0.0],
                                                                [2.1, 0.5], [2.0, 0.5]]}]})
    planner = Planner(world, ROBOT, MODEL, check=False)
    n = ROBOT.n_links
    straight = np.zeros((4, 2 * n + 4))
    straight[:, n : n + 2] = [[1.5, 1.0], [1.5, 1.3], [2.05, 0.45], [0.1, 1.0]]
    gaps = body_gaps_m(world, planner.model, straight)
    half = float(planner.model.half_axis_horizontal_m.max())
    assert gaps[0] < 0 and gaps[2] < 0 and gaps[3] < 0  # across the disc, into the box, the wall
    assert gaps[1] == pytest.approx(0.3 - 0.05 - half, abs=1e-9)


@pytest.fixture(scope="module")
def example_searched():
    """The example's plan as the time-only search found it: the plan the old check (each
    coefficient at +-2 std, one at a time, no unknown current) passed. The search's soft margin
    (docs/planning.md, "The search") now keeps plans further from the discs, so it is switched
    off here to keep the issue's plan, the one these tests are about."""
    world = load_world("tank_5_obstacles")
    planner = Planner(world, ROBOT, MODEL, check=False, soft_margin=False)
    outcome = planner.plan()
    assert outcome.found
    return planner, outcome.plan


def test_plan_the_one_at_a_time_check_passed_touches_in_an_unknown_002_current(example_searched):
    planner, plan = example_searched
    # the old check: each fit, and each with one coefficient at +-2 std, in the known current
    sets = []
    for m in ("straight", "turning"):
        nominal = MODEL.fits[m].as_array()
        for i in range(len(nominal)):
            for sign in (-2.0, 2.0):
                v = nominal.copy()
                v[i] += sign * MODEL.std[m][i]
                sets.append((f"{m} {i} {sign}", type(MODEL.fits[m]).from_array(v)))
    duration = 2.0 * plan.cost_s + 30.0
    old = swim(planner.world, plan.waypoints_m, planner.twin, sets, duration,
               clearance=planner.clearance)
    assert all(r.ok for r in old)
    assert all(body_gaps_m(planner.world, planner.model, r.states).min() > 0 for r in old)
    # the same plan in a 0.02 m/s current the planner is not told of, 8 directions: the
    # independent audit finds contact in some runs
    vx, vy = planner.world.current_m_s
    currents = [(vx + 0.02 * math.cos(a), vy + 0.02 * math.sin(a))
                for a in np.radians(np.arange(0, 360, 45))]
    water = [("straight fit", MODEL.fits["straight"])] * 8
    runs = swim(planner.world, plan.waypoints_m, planner.twin, water, duration,
                clearance=planner.clearance, currents=currents)
    touched = [body_gaps_m(planner.world, planner.model, r.states).min() <= 0 for r in runs]
    assert any(touched)
    # and the new check fails it
    checks, _ = planner.check_plan(plan)
    assert not all(c.ok for c in checks)


def test_plan_the_one_at_a_time_check_passed_collides_in_a_joint_draw(example_searched):
    # the first failure: all coefficients off together, no unknown current at all
    _, plan = example_searched
    planner = Planner(load_world("tank_5_obstacles"), ROBOT, MODEL, unknown_current_m_s=0.0,
                      seed=0)
    checks, _ = planner.check_plan(plan)
    bad = [c for c in checks if not c.ok]
    assert bad and not bad[0].collision_free
    assert body_gaps_m(planner.world, planner.model, bad[0].states).min() <= 0.0


def test_every_run_of_a_passed_check_is_clear_of_everything_by_the_audit():
    # a 0.01 m/s unknown current: the example is planned (seeded draws), every check run audited
    planner = Planner(load_world("tank_5_obstacles"), ROBOT, MODEL, draws=16,
                      unknown_current_m_s=0.01, seed=4)
    outcome = planner.plan()
    assert outcome.found, outcome.message
    # the first plan over its 16 draws, a repaired one over REPAIR_DRAWS_FACTOR times as many
    assert outcome.draws == (16 if outcome.repairs == 0 else REPAIR_DRAWS_FACTOR * 16)
    assert len(outcome.checks) == 1 + outcome.draws
    for run in outcome.checks:
        assert run.reached
        # the audit, written apart, finds every run outside the check's margin too
        gap = body_gaps_m(planner.world, planner.model, run.states).min()
        assert gap > CHECK_MARGIN_M - 0.001, run.label


def test_plan_command_writes_the_checks_confidence_and_refuses_a_bad_bound(tmp_path, capsys):
    from eelhost.cli import main

    out = tmp_path / "plan"
    assert main(["plan", "tank_5_obstacles", "--unknown-current", "0", "--draws", "8",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert ("collision probability 0.0% (0 of 8 draws of the water failed, every run 30 mm "
            "clear; 95 % interval") in printed
    check = json.loads((out / "plan.json").read_text())["check"]
    assert check["draws"] == 8 and check["failures"] == 0
    assert check["margin_m"] == pytest.approx(CHECK_MARGIN_M)
    assert min(c["min_clearance_m"] for c in json.loads((out / "plan.json").read_text())
               ["checks"]) > CHECK_MARGIN_M
    # 95 % over the first plan and its 4 repairs: each plan's interval at 99 % (Bonferroni)
    assert check["plans_checked_at_most"] == 5 and check["interval_level"] == pytest.approx(0.99)
    assert check["interval_95"][1] == pytest.approx(1 - 0.005 ** (1 / 8))
    arrival = check["arrival_s"]
    assert arrival["p5"] <= arrival["median"] <= arrival["p95"]
    assert main(["plan", "tank_5_obstacles", "--unknown-current", "-0.01", "--out",
                 str(out)]) == 2
    assert "--unknown-current: expected a speed from 0 to 1 m/s" in capsys.readouterr().err
    assert main(["plan", "tank_5_obstacles", "--check-margin", "-0.01", "--out",
                 str(out)]) == 2
    assert "--check-margin: expected a margin from 0 to 0.5 m" in capsys.readouterr().err
