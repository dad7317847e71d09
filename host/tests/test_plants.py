"""Test plants that test: each records something else than the bundled tank (issue 32)."""

from pathlib import Path

import numpy as np
import pytest

from eelhost.data.experiments import load_dataset
from eelhost.data.plant_laws import FOIL, FoilCoefficients
from eelhost.data.plants import PLANTS, SMALL_SERVO_STALL_NM
from eelhost.data.virtual_tank import (
    TABLE3,
    TankSettings,
    paper_experiment_plan,
    record_experiment,
    true_robot,
)
from eelhost.estimation.coefficients_file import FittedModel
from eelhost.estimation.evaluate import Evaluator
from eelsim.fluid import candidate_laws
from eelsim.robot import SERVO_ROBOT, load_robot
from eelsim.scenario import load_scenario

REPO = Path(__file__).resolve().parents[2]
BUNDLED = REPO / "datasets" / "paper_virtual_tank"
FAST_GAIT = "straight_A0.87_w3.9"  # where the small servo's line binds hardest
PIXEL_M = 0.0038


@pytest.fixture(scope="module")
def bundled_fast():
    """The bundled dataset's fast straight experiment, its plan index (its seed) and task."""
    ds = load_dataset(BUNDLED)
    index, (motion, _split, task) = next(
        (i, p) for i, p in enumerate(paper_experiment_plan()) if p[2].name == FAST_GAIT)
    recorded = next(e for e in ds.train[motion] + ds.test[motion] if e.name == FAST_GAIT)
    # its first 6 s: the recording is causal, so a shorter run records the same frames
    return ds.robot, index, motion, task.model_copy(update={"duration_s": 6.0}), recorded


def _prefix_gap(exp, recorded):
    n = min(len(exp.t_s), len(recorded.t_s)) - 3  # a centred median's last frames differ
    return float(np.linalg.norm(exp.position_m[:n] - recorded.position_m[:n], axis=1).max())


def test_the_bundled_tanks_settings_record_the_bundled_dataset_again(bundled_fast):
    # what makes the test below meaningful: the same plan index and seed reproduce the file
    robot, index, motion, task, recorded = bundled_fast
    exp = record_experiment(robot, task, motion, TABLE3[motion], TankSettings(), seed=index)
    assert _prefix_gap(exp, recorded) == 0.0


@pytest.mark.parametrize("plant", sorted(PLANTS))
def test_every_plant_records_something_else_than_the_bundled_dataset(bundled_fast, plant):
    # issue 32: servo_limits recorded exactly the bundled figures (the paper's soft PD joints
    # ask 2.6 % of the robot file's servo's stall torque, so its line never bound)
    robot, index, motion, task, recorded = bundled_fast
    p = PLANTS[plant]
    exp = record_experiment(robot, task, motion, p.truths()[motion], p.settings, seed=index)
    assert _prefix_gap(exp, recorded) > 1.5 * PIXEL_M, plant


def test_the_servo_limits_plant_clips_its_joints_on_a_small_servos_line():
    p = PLANTS["servo_limits"]
    robot = load_robot()
    plant_robot = true_robot(robot, p.settings)
    assert p.settings.servo_limits
    assert plant_robot.joints.servo_max_torque_nm == SMALL_SERVO_STALL_NM
    assert plant_robot.joints.kp_nm_per_rad == robot.joints.kp_nm_per_rad  # the same PD loop


def test_plant_only_laws_are_no_candidate_and_two_plants_swim_in_them():
    assert FOIL.name not in candidate_laws()
    foil_plants = {n for n, p in PLANTS.items() if p.law == FOIL.name}
    assert {"foil_lift", "no_added_mass"} <= foil_plants
    still = PLANTS["no_added_mass"].truths()
    assert still["straight"].C_a == 0.0 and still["turning"].C_m == 0.0
    lift = PLANTS["foil_lift"].truths()["straight"]
    assert lift.C_a == TABLE3["straight"].C_a and lift.C_L > 0


def test_foil_lift_does_no_work_and_its_drag_only_dissipates():
    robot = load_robot()
    c = FoilCoefficients(C_D0=0.008, C_D2=1.0, C_L=1.0, C_a=0.6, C_m=0.0)
    fluid = FOIL.link_coefficients(robot.link.half_length_m, robot.link.half_axis_vertical_m,
                                   robot.link.half_axis_horizontal_m, c.as_array(), 1000.0)
    rng = np.random.default_rng(0)
    vt, vn, om = rng.normal(0, 0.1, (3, 1000))
    ft, fn, tq = FOIL.drag(fluid, vt, vn, om)
    power = ft * vt + fn * vn
    assert np.all(power <= 1e-15) and np.all(tq * om <= 0)
    no_lift = FoilCoefficients(C_D0=0.008, C_D2=1.0, C_L=0.0, C_a=0.6, C_m=0.0)
    f0 = FOIL.link_coefficients(robot.link.half_length_m, robot.link.half_axis_vertical_m,
                                robot.link.half_axis_horizontal_m, no_lift.as_array(), 1000.0)
    ft0, fn0, _ = FOIL.drag(f0, vt, vn, om)
    # the lift's power is zero: both laws dissipate the same
    np.testing.assert_allclose(power, ft0 * vt + fn0 * vn, rtol=1e-9, atol=1e-18)
    # and it is across the flow, against the normal flow at a small angle of attack
    lift = np.stack([ft - ft0, fn - fn0])
    np.testing.assert_allclose(lift[0] * vt + lift[1] * vn, 0.0, atol=1e-15)
    small = np.abs(vn) < 0.1 * np.abs(vt)
    assert np.all(lift[1][small] * vn[small] <= 0)
    # at rest relative to the water: no force, no division by zero
    assert FOIL.drag(fluid, np.zeros(1), np.zeros(1), np.zeros(1))[0][0] == 0.0


@pytest.mark.parametrize("plant", sorted(n for n, p in PLANTS.items() if p.law == FOIL.name))
def test_the_batched_kernel_swims_the_foil_plants_as_the_reference_twin_does(plant):
    # the virtual tank records with the readable closed loop; the evaluator swims the batched
    # kernel's generated foil law: the truth must score 0 on a recording without noise
    p = PLANTS[plant]
    servo = load_robot(SERVO_ROBOT)
    clean = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0,
                         joints=p.settings.joints)
    task = load_scenario(FAST_GAIT).model_copy(update={"waypoints_m": [(0.3, 0.0)]})
    truth = p.truths()["straight"]
    exp = record_experiment(servo, task, "straight", truth, clean, seed=1)
    model = FittedModel.of_coefficients(truth, servo)
    ev = Evaluator(servo, [exp], backend="batch", space=model.space)
    assert ev.errors(model.values[None])[0, 0] < 1e-9
