"""The native firmware drives the twin in lockstep (eelhost.xil.lockstep), over a modelled radio link.

Each closed-loop test runs for both joint models of the twin (docs/model.md section 4), on the
straight and turning scenarios: ``pd``, the paper's robot (``paper_robot.toml``), whose joints the
firmware's PD torques drive, and ``servo``, hobby-servo joints (``servo_robot.toml``), where the
angles the firmware commands are the servo references, held over each 10 ms step, and the servo
law moves the joints (eelhost.xil.lockstep.joint_drive); the firmware's own torques drive nothing.

Tolerances, from measurements (hil_tests/README.md):

- float32, both joint models: the firmware against the twin's own laws in float64, evaluated once
  per step and held (eelhost.xil.drivers.HeldTwinDriver), differ by 1.4e-7 m (pd, straight),
  1.6e-7 m (pd, turning) and 5e-8 m (servo; references 1.7e-7 rad) over the whole run; we allow
  1e-5 m and 1e-5 rad.
- hold, ``pd``: the twin evaluates its PD inside every RK4 stage, the firmware once per 10 ms step.
  The held torques make the robot about 2 % slower: the twin and the held laws part by 2.7 cm
  (straight, 16 s) and 3.7 cm (turning, 19 s), mostly along the path, and arrive 0.27-0.37 s
  later. We allow 6 cm (a tenth of a body length) and 0.6 s.
- hold, ``servo``: the twin evaluates the references inside every RK4 stage, the firmware holds
  them over the step; behind the servo's 33 ms lag that parts the paths by 1.2 mm (straight) and
  1.8 mm (turning) and leaves the arrival time the same. We allow 1 cm and one step.
- analog feedback (``servo`` only: setting ``joint_feedback``, docs/firmware.md "Joint loop"): the
  firmware measures the plant's joint angles through its ADC (130.4 counts per rad), runs the PD
  itself with its default gains (k_p = k_s = 1 N m/rad, k_d = 0.02 N m s/rad) and commands
  phi + u / k_s, whose derivative term and ADC rounding move the joints a little away from the
  twin's: measured 2.9 cm (straight) and 4.2 cm (turning) from the twin's path, arriving 0.13 s
  and 0.20 s later. We allow 6 cm (as for the PD joints against the twin) and 0.3 s.

The radio tests (link drop, corruption, loss, the byte model) run on the paper's robot.
"""

import functools
from dataclasses import dataclass

import numpy as np
import pytest

from eelhost.wire import protocol as p
from eelhost.xil.drivers import HeldTwinDriver
from eelhost.xil.lockstep import DT_US, LockstepOptions, run_firmware_in_loop, run_lockstep
from eelhost.xil.radio import RadioModel
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.flags import Failure
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

pytestmark = pytest.mark.firmware_in_loop
# A whole closed-loop run of the firmware and the twin takes 5-30 s: `pytest -m "not slow"` leaves
# those tests out (the radio's byte model stays in).
SLOW = pytest.mark.slow

FLOAT32_TOLERANCE_M = 1e-5
FEEDBACK_PATH_TOLERANCE_M = 0.06
FEEDBACK_ARRIVAL_TOLERANCE_S = 0.3
NOT_MEASURED_MRAD = -32768  # Telemetry's phi_mrad without feedback (docs/firmware.md)
ADC_COUNTS_PER_RAD = p.SETTINGS["adc_counts_per_rad"].default
SCENARIOS = ["straight", "turning"]


@dataclass(frozen=True)
class JointCase:
    """A joint model of the twin and how closely the firmware in the loop follows the twin."""

    robot_file: str | None  # None: the bundled paper robot
    path_tolerance_m: float
    arrival_tolerance_s: float
    kinematic: bool  # the servo law: the firmware's angles are the joints' references


JOINTS = {
    "pd": JointCase(None, path_tolerance_m=0.06, arrival_tolerance_s=0.6, kinematic=False),
    # one step of arrival time (plus rounding of the step count's time)
    "servo": JointCase("servo_robot.toml", path_tolerance_m=0.01, arrival_tolerance_s=0.01 + 1e-9,
                       kinematic=True),
}


@functools.cache
def robot_for(joints):
    case = JOINTS[joints]
    robot = load_robot(case.robot_file) if case.robot_file else load_robot()
    assert robot.joint_model.kinematic == case.kinematic
    return robot


def path_deviation_m(a, b):
    k = min(len(a.t_s), len(b.t_s))
    return float(np.linalg.norm(a.states[:k, 6:8] - b.states[:k, 6:8], axis=1).max())


@functools.cache
def three_runs(joints, scenario_name):
    """The scenario, then the twin alone, the native firmware and the twin's law held per step.

    Cached, so that the tests of one joint model share the runs whichever fixture asks.
    """
    robot = robot_for(joints)
    scenario = load_scenario(scenario_name)
    twin = simulate_closed_loop(robot, scenario, seed=0)
    native = run_firmware_in_loop(robot, scenario, seed=0)
    held = run_lockstep(robot, scenario, HeldTwinDriver(6, robot.joints.command_limit_rad), seed=0)
    return scenario, twin, native, held


@pytest.fixture(scope="module")
def robot():
    return robot_for("pd")


@pytest.fixture(scope="module", params=list(JOINTS))
def joints(request):
    return request.param


@pytest.fixture(scope="module", params=SCENARIOS)
def runs(request, joints):
    return JOINTS[joints], three_runs(joints, request.param)


@pytest.fixture(scope="module", params=SCENARIOS)
def servo_runs(request):
    return three_runs("servo", request.param)


@SLOW
def test_native_firmware_reaches_the_waypoint_with_every_command_executed(runs):
    _, (scenario, _, native, _) = runs
    assert native.failure == Failure.NONE, native.reason
    goal = np.array(scenario.waypoints_m[-1])
    assert np.linalg.norm(native.states[-1, 6:8] - goal) < 2 * scenario.acceptance_radius_m
    assert all(cmd.matches for cmd in native.executed)
    assert native.host_bad_frames == {}


@SLOW
def test_native_firmware_follows_the_twins_path_within_the_hold_tolerance(runs):
    case, (_, twin, native, _) = runs
    assert path_deviation_m(twin, native) < case.path_tolerance_m
    assert abs(native.arrival_time_s - twin.arrival_time_s) < case.arrival_tolerance_s


@SLOW
def test_native_firmware_equals_the_twins_laws_held_per_step_to_float32(runs):
    _, (_, _, native, held) = runs
    assert len(native.t_s) == len(held.t_s)
    assert path_deviation_m(native, held) < FLOAT32_TOLERANCE_M
    np.testing.assert_allclose(native.alpha_rad, held.alpha_rad, atol=1e-5)


@SLOW
def test_firmware_without_feedback_says_so_and_reports_no_measured_angles(runs):
    _, (_, _, native, _) = runs
    assert native.telemetry
    for _, m in native.telemetry:
        assert not m.flags & p.Flags.JOINT_FEEDBACK
        assert list(m.phi_mrad) == [NOT_MEASURED_MRAD] * 5


@SLOW
def test_servo_joints_lag_the_firmwares_commanded_angles_as_in_the_twin(servo_runs):
    _, _, native, _ = servo_runs
    n = 6
    phi = np.diff(native.states[:, :n], axis=1)
    lag = np.abs(phi - native.alpha_rad)[100:]
    assert 0.0 < lag.max() < 0.3


@SLOW
def test_servo_torques_are_recorded_and_saturation_counted_in_the_lockstep_run(servo_runs):
    _, twin, native, _ = servo_runs
    assert native.joint_torque_nm.shape == (len(native.t_s), 5)
    assert np.all(np.isfinite(native.joint_torque_nm))
    # the start from rest asks more than the stall torque (counted, not failed), as in the twin
    assert native.saturated_steps > 0
    assert native.max_torque_ratio == pytest.approx(twin.max_torque_ratio, rel=1e-3)


@pytest.fixture(scope="module", params=SCENARIOS)
def feedback_runs(request):
    robot = robot_for("servo")
    scenario = load_scenario(request.param)
    twin = simulate_closed_loop(robot, scenario, seed=0)
    native = run_firmware_in_loop(
        robot, scenario, seed=0, options=LockstepOptions(joint_feedback=True)
    )
    return scenario, twin, native


@SLOW
def test_firmware_with_feedback_servos_reaches_the_waypoint_near_the_twins_path(feedback_runs):
    scenario, twin, native = feedback_runs
    assert native.failure == Failure.NONE, native.reason
    goal = np.array(scenario.waypoints_m[-1])
    assert np.linalg.norm(native.states[-1, 6:8] - goal) < 2 * scenario.acceptance_radius_m
    assert path_deviation_m(twin, native) < FEEDBACK_PATH_TOLERANCE_M
    assert abs(native.arrival_time_s - twin.arrival_time_s) <= FEEDBACK_ARRIVAL_TOLERANCE_S
    assert all(cmd.matches for cmd in native.executed)


@SLOW
def test_firmware_with_feedback_says_so_and_reports_the_plants_angles_to_an_adc_count(
    feedback_runs,
):
    _, _, native = feedback_runs
    assert native.telemetry
    checked = 0
    for _, m in native.telemetry:
        assert m.flags & p.Flags.JOINT_FEEDBACK
        k = round(m.time_us / DT_US)  # telemetry is sent at the step it was measured in
        if k >= len(native.t_s):
            continue
        phi = np.diff(native.states[k, :6])
        # half an ADC count of rounding, then half a milliradian of the telemetry's integer field
        err = np.abs(np.asarray(m.phi_mrad) * 1e-3 - phi)
        assert err.max() <= 0.5 / ADC_COUNTS_PER_RAD + 0.5e-3 + 1e-6
        checked += 1
    assert checked > 50


@SLOW
def test_link_drop_mid_run_makes_the_failsafe_stop_the_gait_within_1s_and_the_robot_coasts(robot):
    drop_s = 5.0
    scenario = load_scenario("straight").model_copy(update={"duration_s": 9.0})
    radio = RadioModel.xbee(outages_us=((int(drop_s * 1e6), 10**12),))
    res = run_firmware_in_loop(
        robot, scenario, seed=3, radio=radio, options=LockstepOptions(LoopOptions(stop_at_goal=False))
    )
    t, state = res.t_s, res.firmware_state
    assert np.all(state[(t > 0.1) & (t < drop_s)] == p.State.RUNNING)
    k_fs = int(np.argmax(state == p.State.FAILSAFE))
    assert state[k_fs] == p.State.FAILSAFE and np.all(state[k_fs:] == p.State.FAILSAFE)
    assert t[k_fs] - drop_s <= 1.0
    # Straight references from 0.9 s after the last frame on (the link-loss envelope), undulating
    # 0.5 s before FAILSAFE.
    assert np.all(res.alpha_rad[k_fs - 9 :] == 0.0)
    assert np.abs(res.alpha_rad[k_fs - 50 : k_fs - 40]).max() > 0.3
    # The robot coasts: it straightens, keeps gliding forward and slows down.
    x, vx = res.states[:, 6], res.states[:, -2]
    phi_end = np.abs(np.diff(res.states[-1, :6])).max()
    assert phi_end < 0.01
    assert x[-1] - x[k_fs] > 0.05
    assert 0.0 < vx[-1] < 0.8 * vx[k_fs]
    assert res.uplink.lost > 0


@SLOW
def test_one_percent_of_bytes_corrupted_never_executes_a_wrong_command_and_the_run_completes(
    robot,
):
    scenario = load_scenario("straight")
    radio = RadioModel.xbee(corruption_probability=0.01)
    res = run_firmware_in_loop(robot, scenario, seed=1, radio=radio)
    assert res.failure == Failure.NONE, res.reason
    assert res.uplink.corrupted > 0 and res.downlink.corrupted > 0
    assert res.firmware_counters["frames_bad"] > 0  # the firmware saw and dropped bad frames
    assert sum(res.host_bad_frames.values()) > 0  # and so did the host
    # Every command the firmware executed is one the host sent under that sequence number ...
    assert res.executed and all(cmd.matches for cmd in res.executed)
    assert res.refused == []
    # ... and the firmware only ever held offsets, gains and gait the host sent.
    sent_offsets = {np.float32(m.offset_rad) for _, _, m in res.sent if isinstance(m, p.SetOffset)}
    assert set(np.float32(res.offset_rad).tolist()) <= sent_offsets | {0.0}
    c = res.firmware_counters
    assert c["kp_nm_per_rad"] == np.float32(robot.joints.kp_nm_per_rad)
    assert c["kd_nms_per_rad"] == np.float32(robot.joints.kd_nms_per_rad)
    assert c["target_amplitude_rad"] == np.float32(scenario.amplitude_rad)
    assert c["target_omega_rad_s"] == np.float32(scenario.omega_rad_s)


@SLOW
def test_a_lossy_run_is_the_same_for_the_same_seed(robot):
    scenario = load_scenario("turning").model_copy(update={"duration_s": 2.0})
    radio = RadioModel.xbee(loss_probability=0.02, corruption_probability=0.02)
    a, b = (run_firmware_in_loop(robot, scenario, seed=5, radio=radio) for _ in range(2))
    np.testing.assert_array_equal(a.states, b.states)
    assert a.sent == b.sent and a.executed == b.executed
    c = run_firmware_in_loop(robot, scenario, seed=6, radio=radio)
    assert c.uplink != a.uplink or c.downlink != a.downlink


def test_radio_delivers_bytes_at_the_baud_rate_after_the_latency():
    link = RadioModel.xbee(baud=57600, latency_us=5000).channel(np.random.default_rng(0))
    link.send(1000, bytes(range(1, 11)))
    assert link.deliver(6000) == []
    got = link.deliver(10**9)
    assert [b for _, b in got] == list(range(1, 11))
    times = [t for t, _ in got]
    assert times[0] == 1000 + 174 + 5000 and times[-1] == 1000 + 1737 + 5000
    link.send(1100, b"\x01")  # queues behind the first ten bytes
    assert link.deliver(10**9)[0][0] == 2910 + 5000  # 1000 + 11 x 173.6 us, rounded up


def test_radio_loses_and_corrupts_bytes_at_the_given_rates():
    link = RadioModel(loss_probability=0.1, corruption_probability=0.05).channel(
        np.random.default_rng(1)
    )
    data = bytes([0x55]) * 20000
    link.send(0, data)
    got = link.deliver_bytes(0)
    assert len(got) == link.counters.delivered == 20000 - link.counters.lost
    assert link.counters.lost == pytest.approx(2000, rel=0.1)
    assert sum(b != 0x55 for b in got) == link.counters.corrupted
    assert link.counters.corrupted == pytest.approx(0.05 * len(got), rel=0.1)


def test_radio_outage_loses_everything_sent_inside_it():
    link = RadioModel(outages_us=((100, 200),)).channel(np.random.default_rng(0))
    for t in (50, 100, 199, 200):
        link.send(t, bytes([t % 256]))
    assert link.deliver_bytes(1000) == bytes([50, 200])
