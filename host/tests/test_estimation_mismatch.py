"""Estimation under mismatch: honest intervals, warnings, model comparison, test plants."""

import json

import numpy as np
import pytest

from eelhost.data.experiments import load_dataset, manifest_text, write_experiment, write_manifest
from eelhost.data.plants import PLANTS, law_truths
from eelhost.data.virtual_tank import (
    TABLE3,
    TankSettings,
    record_experiment,
    true_robot,
)
from eelhost.estimation.adopt import fit_and_choose
from eelhost.estimation.coefficients_file import FittedModel
from eelhost.estimation.diagnostics import NOISE_RATIO, at_bounds, fit_warnings
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.methods import FitSettings
from eelhost.estimation.selection import (
    CandidateScore,
    carry_over,
    cross_validate,
    nested_in,
    recommend,
)
from eelhost.estimation.space import ParameterSpace, spaces_of
from eelhost.estimation.uncertainty import BootstrapResult, parametric_bootstrap, regenerate
from eelhost.estimation.validate import validate, worst_ex
from eelsim.camera import MEDIAN_PLACEMENTS
from eelsim.flags import PENALTY_ILL_CONDITIONED
from eelsim.robot import SERVO_ROBOT, load_robot
from eelsim.scenario import load_scenario

TRUTH = TABLE3["straight"]
CLEAN = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0)
GAITS = ["straight_A0.87_w3.9", "straight_A0.61_w2.7", "straight_A0.78_w3.5"]


def _short(name, far_m=0.4):
    return load_scenario(name).model_copy(update={"waypoints_m": [(far_m, 0.0)]})


@pytest.fixture(scope="module")
def robot():
    return load_robot()


@pytest.fixture(scope="module")
def noisy_experiments(robot):
    """Two short straight gaits recorded as the bundled tank records (offsets, jitter, pixels)."""
    return [record_experiment(robot, _short(n), "straight", TRUTH, TankSettings(), seed=i)
            for i, n in enumerate(GAITS[:2])]


@pytest.mark.parametrize("median", MEDIAN_PLACEMENTS)
def test_regenerated_recording_is_the_tanks_when_no_noise_is_declared(robot, median):
    # the bootstrap's recorder (batched kernel, camera applied afterwards) and the virtual
    # tank's (reference closed loop) are independent implementations of the same recording
    settings = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0,
                            median=median)
    exp = record_experiment(robot, _short(GAITS[0]), "straight", TRUTH, settings, seed=3)
    model = FittedModel.of_coefficients(TRUTH, robot)
    again = regenerate(robot, model, [exp], 2, np.random.default_rng(0))
    for replica in again:
        assert replica is not None
        np.testing.assert_allclose(replica[0].position_m, exp.position_m, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(replica[0].t_s, exp.t_s)


def test_bootstrap_intervals_hold_the_estimate_and_widen_by_the_excess_over_the_noise_floor(
    robot, noisy_experiments
):
    ev = Evaluator(robot, noisy_experiments, backend="batch")
    x = TRUTH.as_array()
    fitness = float(ev.fitness(x[None])[0])
    # the declared noise's part alone (misfit=False): the residuals' parts are tested in
    # test_estimation_intervals.py; without the search for other valleys (valleys=False), whose
    # points would widen an interval by what they find rather than by the excess
    # (test_estimation_valleys.py)
    near = parametric_bootstrap(ev, x, fitness, replicates=4, seed=1, max_iterations=3,
                                misfit=False, valleys=False)
    assert near.noise_floor > 0 and near.failed == 0
    assert np.all(near.lower <= x) and np.all(x <= near.upper)
    assert np.any(near.upper > near.lower)
    far = parametric_bootstrap(ev, x, 10 * near.noise_floor * max(near.excess, 1.0),
                               replicates=4, seed=1, max_iterations=3, unidentified=["C_m"],
                               misfit=False, valleys=False)
    assert far.excess == pytest.approx(10 * max(near.excess, 1.0))
    # a parameter the data does not identify gets its whole search range
    assert (far.lower[3], far.upper[3]) == tuple(ev.space.bounds[3])
    free_k = np.arange(4) < 3
    # half-widths grow by the ratio of the excesses wherever no bound cuts them
    half_near = near.estimate - near.lower
    half_far = far.estimate - far.lower
    free = (far.lower > ev.space.bounds[:, 0]) & (half_near > 0) & free_k
    np.testing.assert_allclose(half_far[free] / half_near[free], far.excess / near.excess)


def test_coefficients_at_a_bound_are_warned_about_and_middle_ones_are_not(robot):
    space = ParameterSpace.for_robot(robot)
    b = space.bounds
    x = b.mean(axis=1)
    assert at_bounds(space, x) == []
    x[2] = b[2, 1]  # C_a at its upper bound
    (name, value, bound), = at_bounds(space, x)
    assert (name, value, bound) == ("C_a", b[2, 1], b[2, 1])
    warnings = fit_warnings("straight", space, x, None)
    assert len(warnings) == 1 and "C_a" in warnings[0] and "bound" in warnings[0]


def _boot(fitness, floor, names=("C_f",)):
    k = len(names)
    return BootstrapResult(names, np.ones(k), np.ones((3, k)), np.full(3, floor), fitness,
                           np.zeros(k), np.full(k, 2.0))


def test_a_fit_far_above_its_noise_floor_is_warned_about(robot):
    space = ParameterSpace.for_robot(robot)
    x = space.bounds.mean(axis=1)
    high = fit_warnings("turning", space, x, _boot(fitness=0.5, floor=0.5 / (NOISE_RATIO + 1)))
    assert len(high) == 1 and "noise floor" in high[0]
    assert fit_warnings("turning", space, x, _boot(fitness=0.1, floor=0.05)) == []


def test_a_split_law_starts_from_the_papers_coefficients_carried_over_by_name(robot):
    space = ParameterSpace.for_robot(robot, "linear_quadratic")
    start = carry_over(TRUTH.model_dump(), space, space.start(robot))
    got = space.as_dict(start)
    assert got["C_f_lin"] == got["C_f_quad"] == TRUTH.C_f
    assert got["C_d_lin"] == got["C_d_quad"] == TRUTH.C_d
    assert got["C_a"] == TRUTH.C_a


def test_recommendation_is_the_lowest_held_out_error_and_ties_go_to_the_simpler_model():
    def score(model, k, err):
        return CandidateScore(model, k, {"straight": 0.1}, {"straight": np.array(err)})

    simple, rich = score("pd x morison", 4, [0.100, 0.102]), score(
        "pd x morison_lift", 6, [0.100, 0.100])
    bad = score("pd x galilean", 3, [0.3, 0.3])
    assert recommend([rich, simple, bad]) is simple  # within 2 %: fewer parameters
    much_better = score("pd x morison_lift", 6, [0.05, 0.05])
    assert recommend([simple, much_better, bad]) is much_better


def test_a_tie_between_laws_that_do_not_nest_goes_to_the_lower_held_out_error():
    def score(model, k, err):
        return CandidateScore(model, k, {"straight": 0.1}, {"straight": np.array(err)})

    # servo_limits dev seed 27: Lighthill's law (3 coefficients) within one standard error of
    # Morison's (4), but not Morison's with a term switched off: the lower error is chosen
    morison = score("pd_limited x morison", 16, [0.02, 0.10, 0.16, 0.40])
    lighthill = score("pd_limited x lighthill", 14, [0.05, 0.12, 0.20, 0.40])
    assert lighthill.mean_held_out - morison.mean_held_out < morison.standard_error
    assert recommend([lighthill, morison]) is morison
    # the same tie with the simpler model nested in the better one: the simpler is chosen
    base = score("pd x lighthill", 10, lighthill.held_out["straight"])
    line = score("pd_limited x lighthill", 14, morison.held_out["straight"])
    assert recommend([line, base]) is base
    assert nested_in("pd x morison", "pd_limited x morison_lift")
    assert nested_in("pd_limited x morison, one set", "pd_limited x morison")
    assert not nested_in("pd_limited x morison", "pd_limited x morison, one set")
    assert not nested_in("servo x morison", "pd x morison_lift")


def test_a_richer_model_whose_lead_is_inside_one_standard_error_of_the_folds_is_not_recommended():
    def score(model, k, err):
        return CandidateScore(model, k, {"straight": 0.1}, {"straight": np.array(err)})

    # 7 % lower mean, but the best's folds spread by far more than that: the simpler law stays
    base = score("pd x morison", 12, [0.060, 0.055, 0.028, 0.078, 0.036, 0.039, 0.033, 0.055])
    nested = score("pd x morison_lift", 16,
                   [0.053, 0.051, 0.027, 0.061, 0.040, 0.039, 0.031, 0.055])
    assert nested.mean_held_out < base.mean_held_out / 1.02
    assert base.mean_held_out - nested.mean_held_out < nested.standard_error
    assert recommend([nested, base]) is base
    # the same lead with folds that agree is evidence: the richer model is recommended
    tight = score("pd x morison_lift", 16, [nested.mean_held_out] * 8)
    assert recommend([tight, base]) is tight
    # a failed candidate has no standard error to lend
    assert not np.isfinite(score("x", 3, [np.nan, 0.1]).standard_error)


@pytest.mark.slow
def test_cross_validation_holds_out_each_gait_and_keeps_the_law_that_made_the_tank(
    robot, tmp_path
):
    names = []
    for i, n in enumerate(GAITS):
        write_experiment(record_experiment(robot, _short(n), "straight", TRUTH, CLEAN, seed=i),
                         tmp_path)
        names.append(n)
    write_manifest(tmp_path, manifest_text("paper_robot.toml",
                                           {"straight": {"train": names, "test": []}}, []))
    ds = load_dataset(tmp_path)
    scores = cross_validate(ds, ["straight"], FitSettings(),
                            laws=["morison", "linear_quadratic"], joint_models=["pd"])
    assert [s.model for s in scores] == ["pd x linear_quadratic", "pd x morison"]
    for s in scores:
        assert s.held_out["straight"].shape == (3,)
        assert np.all(np.isfinite(s.held_out["straight"])) and s.simulations > 0
    assert recommend(scores).model == "pd x morison"


def test_candidates_are_the_robots_joints_with_every_law_and_each_other_joint_model_with_its_law():
    laws = ["morison", "galilean", "linear_quadratic"]
    paper = [s.model_name for s in spaces_of(load_robot(), laws)]
    assert paper == ["pd x morison", "pd x galilean", "pd x linear_quadratic", "servo x morison"]
    servo = [s.model_name for s in spaces_of(load_robot(SERVO_ROBOT), laws)]
    assert servo == ["servo x morison", "servo x galilean", "servo x linear_quadratic",
                     "pd x morison"]


def test_another_joint_model_brings_its_bundled_table_onto_the_datasets_robot(robot):
    servo_file = load_robot(SERVO_ROBOT)
    # a robot of another geometry and coefficients than either bundled file: they must stay
    robot = robot.model_copy(update={
        "n_links": 5, "link": robot.link.model_copy(update={"half_length_m": 0.07})})
    servo = next(s for s in spaces_of(robot, ["morison"]) if s.model_name == "servo x morison")
    model_robot = servo.model_robot(robot)
    assert model_robot.joints == servo_file.joints
    assert (model_robot.n_links, model_robot.link, model_robot.hydrodynamics) == (
        robot.n_links, robot.link, robot.hydrodynamics)
    # the fitted joint parameters start at the bundled file's and are set on the robot by name
    start = servo.as_dict(servo.start(robot))
    assert start["lag_s"] == pytest.approx(1 / servo_file.joints.position_gain_1_s)
    assert start["motor_time_constant_s"] == servo_file.joints.motor_time_constant_s
    x = servo.from_dict({**start, "lag_s": 0.05})
    fitted = FittedModel(servo, x).robot(robot)
    assert fitted.joints.position_gain_1_s == pytest.approx(20.0)
    assert fitted.joints.deadband_rad == servo_file.joints.deadband_rad
    assert fitted.n_links == 5
    # coefficients.json names the joint model and reads back into the same model
    again = FittedModel.from_json(FittedModel(servo, x).to_json(), robot, "fits.straight")
    assert again.space.model_name == "servo x morison"
    assert again.robot(robot).joints == fitted.joints
    # the PD candidate of a servo robot has the paper robot's gains and nothing to fit
    pd = next(s for s in spaces_of(load_robot(SERVO_ROBOT), ["morison"]) if s.model_name ==
              "pd x morison")
    assert pd.model_robot(load_robot(SERVO_ROBOT)).joints == robot.joints and not pd.joints.names


def test_cross_validation_on_a_stiff_servo_tank_recommends_the_servo_model(robot, tmp_path):
    # the tank's joints are the bundled servo robot's; the dataset's robot file has PD joints
    plant = PLANTS["stiff_servos"]
    settings = TankSettings(joints=plant.settings.joints, timestamp_jitter_s=0.0,
                            control_jitter_s=0.0, pixel_m=0.0)
    for i, n in enumerate(GAITS):
        write_experiment(record_experiment(robot, _short(n), "straight", TRUTH, settings, seed=i),
                         tmp_path)
    write_manifest(tmp_path, manifest_text("paper_robot.toml",
                                           {"straight": {"train": GAITS, "test": []}}, []))
    ds = load_dataset(tmp_path)
    scores = cross_validate(ds, ["straight"], FitSettings(method="minimax", polish_iterations=2),
                            laws=["morison"], iterations=2)
    by_model = {s.model: s for s in scores}
    assert set(by_model) == {"pd x morison", "servo x morison"}
    assert by_model["servo x morison"].mean_held_out < 0.1 * by_model["pd x morison"].mean_held_out
    assert recommend(scores).model == "servo x morison"


def test_a_servo_candidate_rk4_cannot_integrate_fails_as_ill_conditioned_beside_a_good_one(robot):
    servo = next(s for s in spaces_of(robot, ["morison"]) if s.model_name == "servo x morison")
    task = _short(GAITS[0])
    exp = record_experiment(servo.model_robot(robot), task, "straight", TRUTH, CLEAN, seed=0)
    ev = Evaluator(robot, [exp], space=servo)
    start = servo.as_dict(servo.vector(TRUTH.as_array(), robot))
    # K = 18.9 1/s with tau_m = 3.2 ms (below the fit's bound, which keeps out of it): unstable for
    # RK4 at dt = 0.01 s
    unstable = servo.from_dict({**start, "lag_s": 1 / 18.9, "motor_time_constant_s": 0.0032})
    errors = ev.errors(np.stack([servo.from_dict(start), unstable]))[:, 0]
    assert errors[0] < 0.01
    assert errors[1] == PENALTY_ILL_CONDITIONED


def test_every_test_plant_differs_from_the_fitted_model_and_has_a_truth():
    plants = PLANTS
    assert {"head_tail", "servo_limits", "stray_current", "reynolds", "centred_median",
            "all"} <= set(plants)
    default = TankSettings()
    for p in plants.values():
        assert p.settings != default or p.law != "morison", p.name
        truths = p.truths()
        assert set(truths) == {"straight", "turning"}
        assert type(truths["straight"]).law_name == p.law
        # the plant's robot is a valid robot file (the paper robot's reasons for its PD gains
        # must not follow it onto servo joints)
        plant_robot = true_robot(load_robot(), p.settings)
        if p.settings.joints:
            assert plant_robot.joints.model_name == p.settings.joints.get("model", "pd")


@pytest.mark.parametrize("plant", sorted(PLANTS))
@pytest.mark.parametrize("gait", ["straight_A0.61_w2.7", "straight_A0.87_w3.9"])
def test_every_test_plants_robot_swims_head_first_on_a_straight_task(robot, plant, gait):
    # a tank is only a test of the estimator if its robot swims as the paper's did (forward,
    # at the paper's few centimetres per second); the paper's soft PD joints in water without
    # the Morison law's linear drag swam backwards (docs/estimation.md, "Test plants")
    p = PLANTS[plant]
    task = load_scenario(gait).model_copy(update={"duration_s": 8.0, "waypoints_m": [(5.0, 0.0)]})
    e = record_experiment(robot, task, "straight", p.truths()["straight"], p.settings, seed=0)
    t = e.t_s - e.t_s[0]
    after_start = np.searchsorted(t, 3.0)  # from rest: the wave takes a few periods
    speed = (e.position_m[-1, 0] - e.position_m[after_start, 0]) / (t[-1] - t[after_start])
    assert speed > 0.01, f"{plant}: {speed:.4f} m/s"  # twice any plant's stray current


def test_another_laws_truth_keeps_table_3s_added_mass():
    r = law_truths("reynolds")
    assert r["turning"].C_a == TABLE3["turning"].C_a
    with pytest.raises(ValueError, match="unknown fluid law .nosuch."):
        law_truths("nosuch")


@pytest.fixture(scope="module")
def stiff_servo_tank(robot, tmp_path_factory):
    """A small clean tank swum on stiff servo joints, its robot file the paper's (PD joints)."""
    folder = tmp_path_factory.mktemp("stiff_servo_tank")
    plant = PLANTS["stiff_servos"]
    settings = TankSettings(joints=plant.settings.joints, timestamp_jitter_s=0.0,
                            control_jitter_s=0.0, pixel_m=0.0)
    held_out = "straight_A0.69_w3.1"
    for i, n in enumerate([*GAITS, held_out]):
        write_experiment(record_experiment(robot, _short(n), "straight", TRUTH, settings, seed=i),
                         folder)
    write_manifest(folder, manifest_text("paper_robot.toml",
                                         {"straight": {"train": GAITS, "test": [held_out]}}, []))
    return load_dataset(folder)


CHEAP = FitSettings(method="minimax", polish_iterations=3, fit_current=False)


def test_the_recommended_model_is_fitted_in_place_of_the_robot_files_and_predicts_better(
    stiff_servo_tank
):
    chosen = fit_and_choose(stiff_servo_tank, ("straight",), CHEAP, laws=["morison"])
    assert chosen.adopted and chosen.model == "servo x morison"
    assert chosen.robot_file_fits is not None
    assert chosen.robot_file_fits["straight"].space.model_name == "pd x morison"
    assert chosen.fits["straight"].fitness < 0.1 * chosen.robot_file_fits["straight"].fitness
    assert chosen.evaluators["straight"].space.model_name == "servo x morison"
    tests = stiff_servo_tank.test["straight"]
    adopted = worst_ex(validate(stiff_servo_tank.robot,
                                {m: r.model for m, r in chosen.fits.items()}, tests))
    kept = worst_ex(validate(stiff_servo_tank.robot,
                             {m: r.model for m, r in chosen.robot_file_fits.items()}, tests))
    assert adopted["straight"] < 0.2 * kept["straight"]
    # asked to keep the robot file's model, the comparison is made and only reported
    kept_model = fit_and_choose(stiff_servo_tank, ("straight",), CHEAP, adopt=False,
                                laws=["morison"])
    assert not kept_model.adopted and kept_model.model == "pd x morison"
    assert kept_model.comparison is not None
    assert recommend(kept_model.comparison).model == "servo x morison"


def test_a_model_the_comparison_does_not_prefer_is_not_adopted(robot, tmp_path):
    # a tank made by the robot file's own model: the comparison keeps it, nothing is refitted
    for i, n in enumerate(GAITS):
        write_experiment(record_experiment(robot, _short(n), "straight", TRUTH, CLEAN, seed=i),
                         tmp_path)
    write_manifest(tmp_path, manifest_text("paper_robot.toml",
                                           {"straight": {"train": GAITS, "test": []}}, []))
    chosen = fit_and_choose(load_dataset(tmp_path), ("straight",), CHEAP, laws=["morison"])
    assert not chosen.adopted and chosen.model == "pd x morison"
    assert chosen.robot_file_fits is None


@pytest.mark.slow
def test_the_report_fits_and_writes_the_recommended_model_and_validate_reads_it_back(
    stiff_servo_tank, tmp_path, capsys
):
    from eelhost.cli import main

    out = tmp_path / "report"
    folder = str(stiff_servo_tank.folder)
    assert main(["report", folder, "--out", str(out), "--method", "minimax", "--bootstrap", "0",
                 "--no-fit-current", "--laws", "morison"]) == 0
    data = json.loads((out / "coefficients.json").read_text())
    assert data["fits"]["straight"]["joint_model"] == "servo"
    assert data["model_comparison"] == {**data["model_comparison"], "recommended":
                                        "servo x morison", "adopted": True}
    assert data["robot_file_fits"]["fits"]["straight"]["joint_model"] == "pd"
    text = (out / "report.md").read_text()
    assert "Fitted: **servo x morison**" in text and "; adopted: the fits above" in text
    # the file written is a model validate can run: the servo joints come with it
    capsys.readouterr()
    assert main(["validate", str(out / "coefficients.json"), folder, "--out",
                 str(tmp_path / "validate")]) == 0  # not out/validate in the clone
    assert "straight_A0.69_w3.1" in capsys.readouterr().out
    kept = tmp_path / "kept"
    assert main(["report", folder, "--out", str(kept), "--method", "minimax", "--bootstrap", "0",
                 "--no-fit-current", "--keep-model", "--laws", "morison"]) == 0
    data = json.loads((kept / "coefficients.json").read_text())
    assert data["fits"]["straight"]["joint_model"] == "pd" and "robot_file_fits" not in data
    assert "not adopted (`--keep-model`)" in (kept / "report.md").read_text()
