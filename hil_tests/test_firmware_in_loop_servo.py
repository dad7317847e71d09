"""The native firmware drives the twin with hobby-servo joints (``servo_robot.toml``) in lockstep.

With the servo joint model (docs/model.md section 4) the angles the firmware commands are the
servo references, held over each 10 ms step, and the servo law moves the joints
(eelhost.xil.lockstep.joint_drive); the firmware's own torques drive nothing.

Tolerances, from measurements: the twin evaluates the references inside every RK4 stage, the
firmware holds them over the step; behind the servo's 33 ms lag that parts the paths by 1.2 mm
(straight) and 1.8 mm (turning) and leaves the arrival time the same. We allow 1 cm and one
step. Against the twin's laws in float64 held per step (HeldTwinDriver) the firmware differs by
float32 rounding only (5e-8 m; references 1.7e-7 rad): we allow 1e-5 m and 1e-5 rad.
"""

import numpy as np
import pytest

from eelhost.xil.drivers import HeldTwinDriver
from eelhost.xil.lockstep import run_firmware_in_loop, run_lockstep
from eelsim.closed_loop import simulate_closed_loop
from eelsim.flags import Failure
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

pytestmark = pytest.mark.firmware_in_loop

PATH_TOLERANCE_M = 0.01
FLOAT32_TOLERANCE_M = 1e-5


@pytest.fixture(scope="module")
def robot():
    robot = load_robot("servo_robot.toml")
    assert robot.joint_model.kinematic
    return robot


def path_deviation_m(a, b):
    k = min(len(a.t_s), len(b.t_s))
    return float(np.linalg.norm(a.states[:k, 6:8] - b.states[:k, 6:8], axis=1).max())


@pytest.fixture(scope="module", params=["straight", "turning"])
def runs(request, robot):
    scenario = load_scenario(request.param)
    twin = simulate_closed_loop(robot, scenario, seed=0)
    native = run_firmware_in_loop(robot, scenario, seed=0)
    held = run_lockstep(robot, scenario, HeldTwinDriver(6, robot.joints.command_limit_rad), seed=0)
    return scenario, twin, native, held


def test_native_firmware_with_servo_joints_reaches_the_waypoint(runs):
    scenario, _, native, _ = runs
    assert native.failure == Failure.NONE, native.reason
    goal = np.array(scenario.waypoints_m[-1])
    assert np.linalg.norm(native.states[-1, 6:8] - goal) < 2 * scenario.acceptance_radius_m
    assert all(cmd.matches for cmd in native.executed)
    assert native.host_bad_frames == {}


def test_servo_joints_follow_the_firmwares_commanded_angles_as_the_twin_follows_its_gait(runs):
    _, twin, native, _ = runs
    assert path_deviation_m(twin, native) < PATH_TOLERANCE_M
    assert abs(native.arrival_time_s - twin.arrival_time_s) <= 0.01 + 1e-9
    # the joint angles lag the commanded ones (the servo law), as in the twin
    n = 6
    phi = np.diff(native.states[:, :n], axis=1)
    lag = np.abs(phi - native.alpha_rad)[100:]
    assert 0.0 < lag.max() < 0.3


def test_servo_torques_are_recorded_and_saturation_counted_in_the_lockstep_run(runs):
    _, twin, native, _ = runs
    assert native.joint_torque_nm.shape == (len(native.t_s), 5)
    assert np.all(np.isfinite(native.joint_torque_nm))
    # the start from rest asks more than the stall torque (counted, not failed), as in the twin
    assert native.saturated_steps > 0
    assert native.max_torque_ratio == pytest.approx(twin.max_torque_ratio, rel=1e-3)


def test_native_firmware_with_servo_joints_equals_the_twins_laws_held_to_float32(runs):
    _, _, native, held = runs
    assert len(native.t_s) == len(held.t_s)
    assert path_deviation_m(native, held) < FLOAT32_TOLERANCE_M
    np.testing.assert_allclose(native.alpha_rad, held.alpha_rad, atol=1e-5)
