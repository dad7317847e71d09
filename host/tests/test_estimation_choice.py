"""The model choice: the joint model x law grid, each candidate from its own starts.

docs/estimation.md, "Model comparison" and "Model choice".
"""

import shutil
from dataclasses import replace

import numpy as np
import pytest

from eelhost.data.experiments import load_dataset, manifest_text, write_experiment, write_manifest
from eelhost.data.plants import PLANTS
from eelhost.data.virtual_tank import record_experiment
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.methods import FitSettings
from eelhost.estimation.pipeline import training_experiments
from eelhost.estimation.selection import (
    CandidateScore,
    candidate_spaces,
    carry_over,
    cross_validate,
    default_laws,
    family,
    multi_start_fit,
    pass_screen,
    recommend,
    screen_rank,
    table_markdown,
)
from eelhost.estimation.space import ParameterSpace
from eelsim.fluid import get_fluid_law
from eelsim.robot import SERVO_ROBOT, load_robot
from eelsim.scenario import load_scenario

GAITS = ["straight_A0.87_w3.9", "straight_A0.61_w2.7", "straight_A0.78_w3.5"]


def _short(name, far_m):
    return load_scenario(name).model_copy(update={"waypoints_m": [(far_m, 0.0)]})


def test_a_failed_candidate_is_shown_failed_and_never_ranked_by_a_penalty():
    ok = CandidateScore("pd x morison", 4, {"straight": 0.1}, {"straight": np.array([0.2, 0.3])})
    # one fold whose every refit failed: its error is unknown, not a penalty
    failed = CandidateScore("servo x morison", 6, {"straight": 0.05},
                            {"straight": np.array([0.01, np.nan])},
                            failed="straight: held out g2: every refit fails (penalty)")
    assert failed.mean_held_out == np.inf and failed.worst_held_out == np.inf
    assert recommend([failed, ok]) is ok
    assert recommend([failed]) is None
    table = table_markdown([ok, failed])
    assert "failed (straight: held out g2" in table
    assert "e+" not in table and "inf" not in table and "nan" not in table



def test_the_screen_passes_the_best_few_within_a_factor_and_every_familys_best():
    def cand(name, errors, failed=None, fitness=0.1):
        return CandidateScore(name, 4, {"straight": fitness}, {"straight": np.array(errors)},
                              failed=failed)

    grid = [cand("pd x morison", [0.5, 0.7]), cand("pd x galilean", [0.1, 0.1]),
            cand("pd x linear_quadratic", [0.15, 0.17]), cand("pd x resistive_lift", [0.19, 0.23]),
            cand("pd x resistive", [0.3, 0.3]),
            cand("servo x morison", [0.01, np.nan], "fold", fitness=1e9),
            cand("servo x galilean", [np.nan, np.nan], "fit", fitness=1e8)]
    # galilean 0.1 best; linear_quadratic 0.16 within twice it; the servo joints' best passes
    # although every servo candidate failed the short screen (fewer of its folds failed)
    assert pass_screen(grid, survivors=4, factor=2.0, family_factor=0.0) == [1, 2, 5]
    assert pass_screen(grid, survivors=1, factor=10.0, family_factor=0.0) == [1, 5]
    # every law family's best within four times the best: resistive by its lift variant
    # (0.21), not morison (0.6); the family's second (pd x resistive) does not pass
    assert pass_screen(grid, survivors=4, factor=2.0, family_factor=4.0) == [1, 2, 3, 5]
    # a short search may fail where the full one does not: when all failed, all go on
    assert pass_screen([grid[5], grid[6]], survivors=1) == [0, 1]
    assert family("servo x morison_lift, one set") == ("servo", "morison")
    assert screen_rank(grid[5]) < screen_rank(grid[6])
    dropped = replace(grid[0], screened_out=True, held_out={"straight": np.array([0.01, 0.01])})
    assert recommend([dropped, grid[1]]) is grid[1] and recommend([dropped]) is None
    assert "pd x morison (screened out) | 4 | 0.1000 | 0.0100 (screen)" in table_markdown(
        [dropped])


def test_a_lift_variant_starts_from_its_base_laws_fit_with_the_lift_switched_off():
    base = ParameterSpace(get_fluid_law("morison"))
    lift = ParameterSpace(get_fluid_law("morison_lift"))
    fitted = base.bounds[:, 0] + 0.3 * (base.bounds[:, 1] - base.bounds[:, 0])
    start = carry_over(base.as_dict(fitted), lift, lift.bounds.mean(axis=1))
    # the variant's terms (lift, drag rise and stall) start switched off
    assert lift.names[-3:] == ("C_L", "C_D_alpha", "alpha_stall")
    np.testing.assert_array_equal(start[-3:], [0.0, 0.0, np.pi / 2])
    np.testing.assert_array_equal(start[:-3], fitted)
    # the default grid tries every candidate law with and without its lift
    assert {"morison_lift", "morison", "resistive_lift"} <= set(default_laws())


def test_a_lift_variants_screening_restart_from_its_base_fit_ends_at_or_below_the_bases_fitness(
    tmp_path
):
    # the screen's restart (selection._screen_stage) polishes the best carried-over start: its
    # base's fit with the lift off is one and scores exactly the base's fitness, so the
    # variant's screening fit is never worse than its base's own
    ds = _small_tank(tmp_path, "no_added_mass", "paper_robot.toml")
    base, lift = candidate_spaces(ds, ["morison", "morison_lift"], False, ["pd"])
    experiments = training_experiments(ds, "straight")
    evs = [Evaluator(ds.robot, experiments, space=s) for s in (base, lift)]
    fitted = base.bounds[:, 0] + 0.4 * (base.bounds[:, 1] - base.bounds[:, 0])
    start = carry_over(base.as_dict(fitted), lift, lift.bounds.mean(axis=1))
    base_fitness = evs[0].fitness(fitted[None])[0]
    assert evs[1].fitness(start[None])[0] == pytest.approx(base_fitness, rel=1e-9)
    # beside a worse start (the middle of the bounds: strong lift) the base's is polished
    restart = multi_start_fit(evs[1], 0, [lift.bounds.mean(axis=1), start], iterations=1,
                              budget=0)
    assert restart.fitness[0] <= base_fitness


def test_every_joint_model_is_tried_with_every_law_in_the_same_order_from_either_robot_file(
    tmp_path
):
    laws = ["morison", "linear_quadratic"]
    pd_file = _small_tank(tmp_path / "pd", "head_tail", "paper_robot.toml")
    servo_file = replace(pd_file, robot=load_robot(SERVO_ROBOT))
    grid = candidate_spaces(pd_file, laws, True, None)
    assert [s.model_name for s in grid] == ["pd x linear_quadratic", "pd x morison",
                                            "servo x linear_quadratic", "servo x morison"]
    for a, b in zip(grid, candidate_spaces(servo_file, laws, True, None), strict=True):
        assert a.names == b.names and np.array_equal(a.bounds, b.bounds)
        assert a.model_robot(pd_file.robot).joints == b.model_robot(servo_file.robot).joints


def _small_tank(folder, plant, robot_file, turning=()):
    """Three short straight gaits (and ``turning`` ones) of a plant, under a bundled robot file."""
    p = PLANTS[plant]
    truths = p.truths()
    for i, n in enumerate(GAITS):
        write_experiment(record_experiment(load_robot(), _short(n, 0.3), "straight",
                                           truths["straight"], p.settings, seed=i), folder)
    for i, n in enumerate(turning):
        task = load_scenario(n)
        (x, y), = task.waypoints_m
        task = task.model_copy(update={"waypoints_m": [(0.3 * x, 0.3 * y)]})
        write_experiment(record_experiment(load_robot(), task, "turning", truths["turning"],
                                           p.settings, seed=10 + i), folder)
    motions = {"straight": {"train": GAITS, "test": []}}
    if turning:
        motions["turning"] = {"train": list(turning), "test": []}
    write_manifest(folder, manifest_text(robot_file, motions, [], truths))
    return load_dataset(folder)


TINY = FitSettings(method="minimax", polish_iterations=2)


def _compare(ds, motions, **screen):
    # four candidates, two of which pass a short screen (docs/estimation.md, "Model comparison");
    # one finalist refitted from more starts (its spread and carried starts are the choice's too)
    return cross_validate(ds, motions, TINY, laws=["morison", "linear_quadratic"], iterations=2,
                          fold_iterations=2, budget=24, **({"screen_budget": 12, "survivors": 2,
                                                            "final": 1} | screen))


@pytest.mark.parametrize("plant", sorted(PLANTS))
@pytest.mark.slow
def test_the_chosen_model_is_the_same_from_either_bundled_robot_file_on_every_test_plant(
    plant, tmp_path
):
    # the comparison starts nothing from the robot file: the PD file and the servo file give the
    # same candidates, fits and held-out errors, so the same choice
    scores = {}
    pd_tank = _small_tank(tmp_path / "pd", plant, "paper_robot.toml")
    # the same recordings under the servo robot file
    shutil.copytree(tmp_path / "pd", tmp_path / "servo")
    manifest = (tmp_path / "servo" / "manifest.toml").read_text()
    (tmp_path / "servo" / "manifest.toml").write_text(
        manifest.replace('robot = "paper_robot.toml"', f'robot = "{SERVO_ROBOT}"'))
    servo_tank = load_dataset(tmp_path / "servo")
    for robot_file, ds in (("paper_robot.toml", pd_tank), (SERVO_ROBOT, servo_tank)):
        assert ds.robot.joints.model_name == ("servo" if robot_file == SERVO_ROBOT else "pd")
        scores[robot_file] = _compare(ds, ["straight"])
    pd_file, servo_file = scores.values()
    assert [s.model for s in pd_file] == [s.model for s in servo_file]
    for a, b in zip(pd_file, servo_file, strict=True):
        assert a.failed == b.failed and a.screened_out == b.screened_out
        np.testing.assert_array_equal(a.held_out["straight"], b.held_out["straight"])
    assert recommend(pd_file) is not None
    assert recommend(pd_file).model == recommend(servo_file).model


@pytest.mark.slow
def test_one_set_for_every_motion_is_a_candidate_scored_on_the_same_held_out_gaits(tmp_path):
    turning = ["turning_A0.87_w3.9", "turning_A0.61_w2.7"]
    ds = _small_tank(tmp_path, "head_tail", "paper_robot.toml", turning)
    scores = _compare(ds, ["straight", "turning"], screen_budget=0)
    one = [s for s in scores if s.one_set]
    assert [s.model for s in one] == [f"{recommend(scores[:4]).model}, one set"]
    # its folds hold out every training gait of both motions, as the separate sets' do
    assert one[0].held_out["joint"].shape == (len(GAITS) + len(turning),)
    assert one[0].parameters == one[0].space.size and scores[0].parameters == 2 * scores[
        0].space.size
    assert recommend(scores) is not None
