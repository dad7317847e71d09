"""The tank's unknown ambient current, fitted as a nuisance parameter of the estimation."""

import json

import numpy as np
import pytest

from eelhost.cli import main
from eelhost.data.experiments import load_dataset, manifest_text, write_experiment, write_manifest
from eelhost.data.virtual_tank import TABLE3, TankSettings, record_experiment
from eelhost.estimation.coefficients_file import (
    CoefficientsError,
    read_coefficients,
    write_coefficients,
)
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.identify import identifiability
from eelhost.estimation.methods import FitSettings, method_names
from eelhost.estimation.optimise import FitResult
from eelhost.estimation.pipeline import fit_motion
from eelhost.estimation.space import CURRENT_BOUND_M_S, CURRENT_NAMES, ParameterSpace
from eelhost.estimation.validate import validate
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

TRUTH = TABLE3["straight"]
GAITS = ["straight_A0.87_w3.9", "straight_A0.61_w2.7", "straight_A0.78_w3.5"]
STRAY_M_S, STRAY_DEG = 0.005, 120.0  # the paper's robot swims about 0.1 m/s


def _short(name, far_m=0.6):
    return load_scenario(name).model_copy(update={"waypoints_m": [(far_m, 0.0)]})


@pytest.fixture(scope="module")
def robot():
    return load_robot()


@pytest.fixture(scope="module")
def stray_tank(tmp_path_factory, robot):
    """Three short straight gaits in a tank with an undeclared steady current (two to train)."""
    folder = tmp_path_factory.mktemp("stray")
    settings = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0,
                            stray_current_m_s=STRAY_M_S, stray_current_direction_deg=STRAY_DEG)
    for i, name in enumerate(GAITS):
        write_experiment(record_experiment(robot, _short(name), "straight", TRUTH, settings,
                                           seed=i), folder)
    write_manifest(folder, manifest_text(
        "paper_robot.toml", {"straight": {"train": GAITS[:2], "test": GAITS[2:]}}, [],
        {"straight": TRUTH}))
    return load_dataset(folder)


def _speed_direction(current):
    vx, vy = current
    return float(np.hypot(vx, vy)), float(np.degrees(np.arctan2(vy, vx)))


def test_a_fitted_current_adds_to_the_declared_one_as_a_vector():
    declared = load_scenario("straight_A0.87_w3.9").model_copy(
        update={"current_speed_m_s": 0.03, "current_direction_deg": 180.0})
    both = declared.with_added_current((0.0, 0.03))
    np.testing.assert_allclose(both.current_m_s, (-0.03, 0.03), atol=1e-12)
    assert both.current_speed_m_s == pytest.approx(0.03 * np.sqrt(2))
    assert both.current_direction_deg == pytest.approx(135.0)
    assert declared.with_added_current((0.0, 0.0)) is declared  # still water stays plain


def test_the_current_comes_last_by_name_and_starts_in_still_water(robot):
    space = ParameterSpace.for_robot(robot, current=True)
    assert space.names == ("C_f", "C_d", "C_a", "C_m") + CURRENT_NAMES
    np.testing.assert_array_equal(space.bounds[-2:], [[-CURRENT_BOUND_M_S, CURRENT_BOUND_M_S]] * 2)
    start = space.start(robot)
    np.testing.assert_array_equal(start[-2:], [0.0, 0.0])
    x = np.concatenate([TRUTH.as_array(), [0.01, -0.02]])
    np.testing.assert_array_equal(space.current_array(x), [0.01, -0.02])
    assert space.joint_array(x).size == 0  # the joints' part does not take the current
    np.testing.assert_allclose(space.from_unit(space.to_unit(x)), x)
    assert not ParameterSpace.for_robot(robot).current_names


def test_batch_and_reference_backends_agree_on_a_candidate_current(stray_tank):
    space = ParameterSpace.for_robot(stray_tank.robot, current=True)
    cands = np.array([np.concatenate([TRUTH.as_array(), c]) for c in ([0, 0], [0.01, -0.005])])
    exps = stray_tank.train["straight"][:1]
    ref = Evaluator(stray_tank.robot, exps, backend="reference", workers=1, space=space)
    fast = Evaluator(stray_tank.robot, exps, backend="batch", space=space)
    a, b = ref.simulate(cands), fast.simulate(cands)
    np.testing.assert_allclose(a.positions_m, b.positions_m, rtol=0, atol=1e-9)
    # and the current moves the robot: 1 cm/s for several seconds is centimetres
    drift = np.linalg.norm(b.positions_m[1, 0, -1] - b.positions_m[0, 0, -1])
    assert drift > 0.01


def test_fit_recovers_an_undeclared_steady_current_and_predicts_held_out_gaits_better(
    stray_tank,
):
    settings = FitSettings("cmaes", seed=0, budget=400, polish_iterations=8)
    with_current, ev = fit_motion(stray_tank, "straight", settings)
    without, _ = fit_motion(stray_tank, "straight",
                            FitSettings("cmaes", seed=0, budget=400, polish_iterations=8,
                                        fit_current=False))
    speed, direction = _speed_direction(with_current.model.current_m_s)
    assert speed == pytest.approx(STRAY_M_S, rel=0.25)
    assert abs((direction - STRAY_DEG + 180) % 360 - 180) < 20
    assert with_current.fitness < without.fitness
    # the held-out gait, simulated in the fitted current, is predicted better
    test = stray_tank.test["straight"]
    err_with = validate(stray_tank.robot, {"straight": with_current.model}, test)[0].row
    err_without = validate(stray_tank.robot, {"straight": without.model}, test)[0].row
    assert err_with.Ex_mean_unaligned_BL < 0.5 * err_without.Ex_mean_unaligned_BL
    # a current is judged against its search range, not against its (possibly zero) value
    ident = identifiability(ev, with_current.values)
    assert np.all(np.isfinite(ident.rel_std_error[-2:]))


def test_a_tank_without_stray_current_fits_still_water_and_the_truth(robot, tmp_path):
    # no pixel rounding: the truth in still water scores 0, so any current the fit kept would be
    # an error of the method, not noise it explains
    clean = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0)
    for i, name in enumerate(GAITS[:2]):
        write_experiment(record_experiment(robot, _short(name), "straight", TRUTH, clean,
                                           seed=i), tmp_path)
    write_manifest(tmp_path, manifest_text(
        "paper_robot.toml", {"straight": {"train": GAITS[:2], "test": []}}, []))
    res, _ = fit_motion(load_dataset(tmp_path), "straight",
                        FitSettings("cmaes", seed=0, budget=400, polish_iterations=8))
    speed, _ = _speed_direction(res.model.current_m_s)
    assert speed < 1e-5  # 0.01 mm/s
    got, want = res.coefficients.as_array(), TRUTH.as_array()
    np.testing.assert_allclose(got[:3], want[:3], rtol=0.01)  # C_f, C_d, C_a (C_m is not seen)


def _fit_with_current(robot, current):
    space = ParameterSpace.for_robot(robot, current=True)
    return FitResult("lsq", space, np.concatenate([TRUTH.as_array(), current]), 0.1, [(0, 0.1, 1)],
                     1)


def test_coefficients_json_round_trip_keeps_the_current_and_validation_swims_in_it(
    robot, stray_tank, tmp_path
):
    fit = _fit_with_current(robot, [0.004, -0.003])
    path = write_coefficients(tmp_path / "coefficients.json", {"straight": fit})
    entry = json.loads(path.read_text())["fits"]["straight"]["ambient_current"]
    assert entry["speed_m_s"] == pytest.approx(0.005)
    back = read_coefficients(str(path), robot)["straight"]
    assert back.space.names == fit.space.names
    np.testing.assert_array_equal(back.values, fit.values)
    # validation simulates in the stored current: unlike the same coefficients in still water
    test = stray_tank.test["straight"]
    still = _fit_with_current(robot, [0.0, 0.0]).model
    moved = validate(robot, {"straight": back}, test, align_s=0.0)[0].sim_positions_m
    calm = validate(robot, {"straight": still}, test, align_s=0.0)[0].sim_positions_m
    assert np.abs(moved - calm).max() > 0.005


def test_coefficients_without_a_current_still_read_as_still_water(robot, tmp_path):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"format": "eelbot-coefficients/2", "fits": {"straight": {
        "law": "morison", "joint_model": "pd", "coefficients": TRUTH.model_dump(),
        "joint_parameters": {}}}}))
    model = read_coefficients(str(path), robot)["straight"]
    assert not model.space.current and model.current_m_s == (0.0, 0.0)


@pytest.mark.parametrize(
    ("current", "message"),
    [
        ({"current_x_m_s": "fast", "current_y_m_s": 0.0}, "every value must be a number"),
        ({"current_x_m_s": float("nan"), "current_y_m_s": 0.0}, "current_x_m_s must be finite"),
        ({"current_x_m_s": 0.001}, "missing current_y_m_s"),
        ({"current_x_m_s": 0.0, "current_y_m_s": 0.0, "current_z_m_s": 0.0},
         "unknown current_z_m_s"),
        ([0.001, 0.002], "ambient_current: expected current_x_m_s, current_y_m_s"),
    ],
)
def test_a_malformed_stored_current_is_refused_naming_the_fit_and_the_field(
    robot, tmp_path, current, message
):
    fit = _fit_with_current(robot, [0.001, 0.002]).to_json()
    fit["ambient_current"] = current
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"format": "eelbot-coefficients/3", "fits": {"turning": fit}}))
    with pytest.raises(CoefficientsError, match="fits.turning") as err:
        read_coefficients(str(path), robot)
    assert message in str(err.value)


def test_a_coefficient_its_law_refuses_is_refused_when_the_file_is_read(robot, tmp_path):
    # before anything swims with it: validate and the planner read fits through one reader
    fit = _fit_with_current(robot, [0.001, 0.002]).to_json()
    fit["coefficients"]["C_d"] = -0.5
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"format": "eelbot-coefficients/3", "fits": {"turning": fit}}))
    with pytest.raises(CoefficientsError, match=r"fits.turning.coefficients: not a morison "
                                                r"coefficient set .*C_d.*greater than or equal"):
        read_coefficients(str(path), robot)


def test_the_command_line_turns_the_current_off(stray_tank, tmp_path, capsys):
    out = tmp_path / "fit"
    args = ["estimate", str(stray_tank.folder), "--motion", "straight", "--budget", "12",
            "--out", str(out)]
    assert main(args + ["--no-fit-current"]) == 0
    stored = json.loads((out / "coefficients.json").read_text())["fits"]["straight"]
    assert "ambient_current" not in stored
    assert main(args) == 0  # the default fits it
    stored = json.loads((out / "coefficients.json").read_text())["fits"]["straight"]
    assert set(stored["ambient_current"]) >= set(CURRENT_NAMES)
    assert "ambient current" in capsys.readouterr().out


@pytest.mark.slow
def test_the_report_bounds_and_judges_the_current_like_the_coefficients(stray_tank, tmp_path):
    from eelhost.estimation.report import run_report

    settings = FitSettings("cmaes", seed=0, budget=60, polish_iterations=4)
    # a comparison of two candidates (the default grid's dozens take 90 s and test no more here)
    report = run_report(stray_tank, tmp_path, motions=("straight",), settings=settings,
                        bootstrap_replicates=3, compare_models=True, laws=("morison", "galilean"),
                        joint_models=("pd",))
    data = json.loads((tmp_path / "coefficients.json").read_text())
    fit = data["fits"]["straight"]
    est = [fit["ambient_current"][n] for n in CURRENT_NAMES]
    unc = data["uncertainty"]["straight"]
    for n, v in zip(CURRENT_NAMES, est, strict=True):
        assert unc["lower"][n] <= v <= unc["upper"][n]
        assert n in data["identifiability"]["straight"]["verdict"]
    # every candidate model of the comparison fits the current too: Morison's 4 + 2
    candidates = data["model_comparison"]["candidates"]
    assert candidates["pd x morison"]["parameters"] == 6
    assert all(c["parameters"] >= 3 for c in candidates.values()) and len(candidates) >= 2
    assert "Ambient current of the tank" in report.read_text()


@pytest.mark.parametrize("method", method_names())
def test_every_method_fits_the_current_after_the_coefficients(stray_tank, method):
    settings = FitSettings(method, seed=0, budget=24, pop_size=6, generations=2,
                           polish_iterations=2)
    res, ev = fit_motion(stray_tank, "straight", settings)
    assert res.space.names[-2:] == CURRENT_NAMES and ev.space is res.space
    # the second stage starts from the still-water fit, so it can only improve on it
    still, _ = fit_motion(stray_tank, "straight", FitSettings(
        method, seed=0, budget=24, pop_size=6, generations=2, polish_iterations=2,
        fit_current=False))
    assert res.fitness <= still.fitness
    assert res.simulations == ev.simulations > still.simulations


def test_a_report_on_a_tank_whose_truth_is_in_another_law_says_so_instead_of_comparing(
        stray_tank, tmp_path):
    """A virtual tank's truth may follow another law than the fitted model (a test plant)."""
    import shutil

    from eelhost.data.plants import law_truths
    from eelhost.estimation.report import run_report

    folder = tmp_path / "tank"
    shutil.copytree(stray_tank.folder, folder)
    write_manifest(folder, manifest_text(
        "paper_robot.toml", {"straight": {"train": GAITS[:2], "test": GAITS[2:]}}, [],
        {"straight": law_truths("reynolds")["straight"]}))
    settings = FitSettings("cmaes", seed=0, budget=24, polish_iterations=1, fit_current=False)
    report = run_report(load_dataset(folder), tmp_path / "out", motions=("straight",),
                        settings=settings, bootstrap_replicates=0, compare_models=False)
    assert ("straight: the truth is in the reynolds law, the fit in morison"
            in report.read_text())


@pytest.mark.parametrize("joint_model", ["pd", "servo"])
@pytest.mark.slow
def test_a_steady_current_is_recovered_within_a_mm_s_and_15_degrees_by_either_joint_model(
    joint_model, robot, tmp_path
):
    # the tank swims on the joints of the model fitted (the paper's PD joints, or the bundled
    # servo file's), in a steady 5 mm/s current towards 120 deg that its metadata does not declare
    from eelhost.data.plants import PLANTS
    from eelhost.estimation.space import spaces_of

    joints = None if joint_model == "pd" else PLANTS["stiff_servos"].settings.joints
    settings = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, joints=joints,
                            stray_current_m_s=STRAY_M_S, stray_current_direction_deg=STRAY_DEG)
    names = ["straight_A0.87_w3.9", "straight_A0.61_w2.7", "straight_A0.61_w3.9"]
    for i, name in enumerate(names):
        write_experiment(record_experiment(robot, _short(name), "straight", TRUTH, settings,
                                           seed=i), tmp_path)
    write_manifest(tmp_path, manifest_text(
        "paper_robot.toml", {"straight": {"train": names, "test": []}}, [], {"straight": TRUTH}))
    ds = load_dataset(tmp_path)
    space = next(s for s in spaces_of(ds.robot, ["morison"], current=True)
                 if s.joints.model == joint_model)
    fit, _ = fit_motion(ds, "straight", FitSettings(budget=600), space=space)
    speed, direction = _speed_direction(fit.model.current_m_s)
    assert abs(speed - STRAY_M_S) < 0.001
    assert abs((direction - STRAY_DEG + 180) % 360 - 180) < 15
