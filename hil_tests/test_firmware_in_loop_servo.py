"""The native firmware drives the twin with hobby-servo joints (``servo_robot.toml``) in lockstep.

With the servo joint model (docs/model.md section 4) the angles the firmware commands are the
servo references, held over each 10 ms step, and the servo law moves the joints
(eelhost.xil.lockstep.joint_drive); the firmware's own torques drive nothing.

Tolerances, from measurements: the twin evaluates the references inside every RK4 stage, the
firmware holds them over the step; behind the servo's 33 ms lag that parts the paths by 1.2 mm
(straight) and 1.8 mm (turning) and leaves the arrival time the same. We allow 1 cm and one
step. Against the twin's laws in float64 held per step (HeldTwinDriver) the firmware differs by
float32 rounding only (5e-8 m; references 1.7e-7 rad): we allow 1e-5 m and 1e-5 rad.

Both of the firmware's joint modes run (docs/firmware.md, "Joint loop"): without feedback it
commands each servo to its reference; with analog feedback (setting ``joint_feedback``) it measures
the plant's joint angles through its ADC (130.4 counts per rad), runs the PD itself with its
default gains (k_p = k_s = 1 N m/rad, k_d = 0.02 N m s/rad) and commands phi + u / k_s, whose
derivative term and ADC rounding move the joints a little away from the twin's: measured 2.9 cm
(straight) and 4.2 cm (turning) from the twin's path, arriving 0.13 s and 0.20 s later. We allow
6 cm (a tenth of a body length, as for the PD joints against the twin) and 0.3 s.
"""

import numpy as np
import pytest
from test_firmware_in_loop import (
    assert_reaches_the_waypoint_with_every_command_executed,
    path_deviation_m,
    three_runs,
)

from eelhost.wire import protocol
from eelhost.xil.lockstep import LockstepOptions, run_firmware_in_loop
from eelsim.closed_loop import simulate_closed_loop
from eelsim.flags import Failure
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

pytestmark = pytest.mark.firmware_in_loop

PATH_TOLERANCE_M = 0.01
FLOAT32_TOLERANCE_M = 1e-5
FEEDBACK_PATH_TOLERANCE_M = 0.06
FEEDBACK_ARRIVAL_TOLERANCE_S = 0.3
NOT_MEASURED_MRAD = -32768  # Telemetry's phi_mrad without feedback (docs/firmware.md)
ADC_COUNTS_PER_RAD = protocol.SETTINGS["adc_counts_per_rad"].default


@pytest.fixture(scope="module")
def robot():
    robot = load_robot("servo_robot.toml")
    assert robot.joint_model.kinematic
    return robot


@pytest.fixture(scope="module", params=["straight", "turning"])
def runs(request, robot):
    return three_runs(robot, request.param)


def test_native_firmware_with_servo_joints_reaches_the_waypoint(runs):
    scenario, _, native, _ = runs
    assert_reaches_the_waypoint_with_every_command_executed(scenario, native)


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


@pytest.fixture(scope="module", params=["straight", "turning"])
def feedback_runs(request, robot):
    scenario = load_scenario(request.param)
    twin = simulate_closed_loop(robot, scenario, seed=0)
    native = run_firmware_in_loop(
        robot, scenario, seed=0, options=LockstepOptions(joint_feedback=True)
    )
    return scenario, twin, native


def test_firmware_with_feedback_servos_reaches_the_waypoint_near_the_twins_path(feedback_runs):
    scenario, twin, native = feedback_runs
    assert native.failure == Failure.NONE, native.reason
    goal = np.array(scenario.waypoints_m[-1])
    assert np.linalg.norm(native.states[-1, 6:8] - goal) < 2 * scenario.acceptance_radius_m
    assert path_deviation_m(twin, native) < FEEDBACK_PATH_TOLERANCE_M
    assert abs(native.arrival_time_s - twin.arrival_time_s) <= FEEDBACK_ARRIVAL_TOLERANCE_S
    assert all(cmd.matches for cmd in native.executed)


def test_firmware_with_feedback_says_so_and_reports_the_plants_angles_to_an_adc_count(
    feedback_runs,
):
    _, _, native = feedback_runs
    assert native.telemetry
    checked = 0
    for _, m in native.telemetry:
        assert m.flags & protocol.Flags.JOINT_FEEDBACK
        k = round(m.time_us / 10_000)  # telemetry is sent at the step it was measured in
        if k >= len(native.t_s):
            continue
        phi = np.diff(native.states[k, :6])
        # half an ADC count of rounding, then half a milliradian of the telemetry's integer field
        err = np.abs(np.asarray(m.phi_mrad) * 1e-3 - phi)
        assert err.max() <= 0.5 / ADC_COUNTS_PER_RAD + 0.5e-3 + 1e-6
        checked += 1
    assert checked > 50


def test_firmware_without_feedback_says_so_and_reports_no_measured_angles(runs):
    _, _, native, _ = runs
    assert native.telemetry
    for _, m in native.telemetry:
        assert not m.flags & protocol.Flags.JOINT_FEEDBACK
        assert list(m.phi_mrad) == [NOT_MEASURED_MRAD] * 5
