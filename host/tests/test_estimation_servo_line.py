"""The estimator's simulation on the servos' torque-speed line (issue 32, plant ``servo_limits``):
the plant's own robot swum on its line reproduces its recording with either backend, so the
bench's "plant itself" is the real plant.
"""

from dataclasses import replace

import numpy as np
import pytest

from eelhost.data.plants import PLANTS
from eelhost.data.virtual_tank import TABLE3, record_experiment, true_robot
from eelhost.estimation.coefficients_file import FittedModel
from eelhost.estimation.evaluate import Evaluator
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario


@pytest.fixture(scope="module")
def small_servo_tank():
    """The servo_limits plant's robot and a 4 s recording of its fastest straight gait, no noise."""
    plant = PLANTS["servo_limits"]
    settings = replace(plant.settings, timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0)
    task = load_scenario("straight_A0.87_w3.9").model_copy(
        update={"duration_s": 4.0, "waypoints_m": [(0.6, 0.0)]})
    robot = load_robot()
    exp = record_experiment(robot, task, "straight", TABLE3["straight"], settings, seed=0)
    return true_robot(robot, settings), exp


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["reference", "batch"])
def test_the_plant_swum_on_its_servo_line_reproduces_its_recording_and_without_it_does_not(
        small_servo_tank, backend):
    robot, exp = small_servo_tank
    model = FittedModel.of_coefficients(TABLE3["straight"], robot)
    gaps = {}
    for on_line in (True, False):
        ev = Evaluator(robot, [exp], n_samples=20, backend=backend, workers=1, space=model.space,
                       servo_limits=on_line)
        sim = ev.simulate(model.values[None])
        gaps[on_line] = float(np.linalg.norm(sim.positions_m[0, 0] - ev.prepared[0].exp_positions_m,
                                             axis=-1).max())
    assert gaps[True] < 1e-6  # the same loop, the same camera: the recording itself
    assert gaps[False] > 0.01  # the robot without its line swims centimetres further


def test_the_grid_holds_the_servo_line_model_with_every_law_only_when_asked_alike_from_either_file(
):
    # by default it joins after the screen with a few laws (test_estimation_after_screen.py)
    from eelhost.data.experiments import BUNDLED_DATASET, load_dataset
    from eelhost.estimation.selection import candidate_spaces
    from eelsim.robot import SERVO_ROBOT

    ds = load_dataset(BUNDLED_DATASET)
    default = [s.model_name for s in candidate_spaces(ds, ["morison"], False, None)]
    assert default == ["pd x morison", "servo x morison"]
    asked = ["pd", "pd_limited", "servo"]
    tables = []
    for robot in (ds.robot, load_robot(SERVO_ROBOT)):
        spaces = candidate_spaces(replace(ds, robot=robot), ["morison"], False, asked)
        limited = next(s for s in spaces if s.model_name == "pd_limited x morison")
        assert limited.joints.names == ("servo_max_torque_nm", "servo_max_speed_rad_s")
        tables.append(limited.joints.table)
    # from either robot file the same table: the paper's PD gains, whose line the fit moves
    assert tables[0] == tables[1]
    assert tables[0].kp_nm_per_rad == ds.robot.joints.kp_nm_per_rad
    # a robot file of this model has it in the default grid
    own = replace(ds, robot=ds.robot.with_joints(tables[0]))
    assert "pd_limited x morison" in [s.model_name
                                      for s in candidate_spaces(own, ["morison"], False, None)]


def test_an_unknown_joint_model_on_the_command_line_is_a_usage_error_naming_the_known_ones(capsys):
    from eelhost.cli import main

    assert main(["report", "--joint-models", "pd,stepper"]) == 2
    assert "expected joint models from pd, pd_limited, servo, got 'pd,stepper'" in (
        capsys.readouterr().err)
