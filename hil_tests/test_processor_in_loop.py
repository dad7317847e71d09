"""The real AVR image, emulated in simavr, drives the twin (eelhost.xil.simavr).

A 5 s straight run costs ~7 s of CPU (simavr interprets every instruction), so the tests share
one run. Tolerances (measured figures in hil_tests/README.md):

- pulse widths: the Timer1 driver makes widths exact to a tick (0.5 us); another interrupt (the
  millis tick, the UART) can delay an edge by a few us; the references are rounded to whole us.
  Measured: median 1 us, max 7.75 us. The issue asks for 10 us.
- distance: the servo model acts on 50 Hz pulses, 10-20 ms behind the control update, with the
  rate from the slope of successive pulses; the native firmware's PD acts on every 10 ms update.
  Measured: the emulated AVR moves the robot 5 % further in 5 s. We allow 15 %.
"""

import numpy as np
import pytest

from eelhost.wire import protocol as p
from eelhost.xil.lockstep import LockstepOptions, run_firmware_in_loop
from eelhost.xil.simavr import AvrSimulator, expected_pulse_widths_us, run_processor_in_loop
from eelsim.closed_loop import LoopOptions
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

# slow: the emulated AVR costs 1-2 CPU s per simulated s (about 30 s for the file)
pytestmark = [pytest.mark.processor_in_loop, pytest.mark.slow]

PULSE_TOLERANCE_US = 10.0
DISTANCE_TOLERANCE = 0.15


@pytest.fixture(scope="module")
def straight_runs():
    robot = load_robot()
    scenario = load_scenario("straight").model_copy(update={"duration_s": 5.0})
    options = LockstepOptions(LoopOptions(stop_at_goal=False))
    # Every frame the emulated AVR sends, read off its UART as the run takes it (the run itself
    # keeps only the Telemetry; the Status frames carry tx_dropped).
    sent_by_robot: list[p.Message] = []
    reader = p.FrameReader()
    take_uart = AvrSimulator.take_uart

    def take_uart_and_read(sim: AvrSimulator) -> list[tuple[float, int]]:
        out = take_uart(sim)
        sent_by_robot.extend(msg for _, msg in reader.feed(bytes(b for _, b in out)))
        return out

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(AvrSimulator, "take_uart", take_uart_and_read)
        pil = run_processor_in_loop(robot, scenario, seed=0, options=options)
    native = run_firmware_in_loop(robot, scenario, seed=0, options=options)
    return scenario, pil, native, sent_by_robot


def test_emulated_avr_servo_pulses_match_the_gait_references_within_10us(straight_runs):
    scenario, pil, _, _ = straight_runs
    assert not pil.crashed
    # 5 servos at 50 Hz for 5 s, and a control update every 10 ms.
    assert len(pil.pulses_us) >= 5 * 50 * 5 - 10 and len(pil.control_updates_us) >= 495
    expected, valid = expected_pulse_widths_us(
        pil, scenario.amplitude_rad, scenario.omega_rad_s, scenario.beta_rad
    )
    assert valid.mean() > 0.9  # few pulses are ambiguous (next to a frame or an update)
    err = np.abs(pil.pulses_us[valid, 2] - expected[valid])
    assert err.max() <= PULSE_TOLERANCE_US
    # The pulses really swing with the gait: joint 1 over most of +-636.6 A_1 us.
    joint1 = pil.pulses_us[(pil.pulses_us[:, 1] == 0) & (pil.pulses_us[:, 0] > 1e6), 2]
    swing = 636.6 * scenario.amplitude_rad * 5 / 7
    assert joint1.max() - 1500 > 0.9 * swing and 1500 - joint1.min() > 0.9 * swing


def test_emulated_avr_executes_the_hosts_commands_and_reports_running(straight_runs):
    _, pil, _, sent_by_robot = straight_runs
    kinds = [type(cmd.sent) for cmd in pil.executed]
    # The host sends Hello and the four configuration commands at once at boot. Replies take
    # precedence over Telemetry in the robot's transmit queue (docs/firmware.md, "Link"), so the
    # Version and the first Telemetry leave room for every Ack: all four come, in the order sent,
    # from the first copy (the host resends nothing), and no reply was ever dropped.
    assert kinds[:4] == [p.SetGains, p.SetGait, p.SetOffset, p.Start]
    config = [type(m) for _, _, m in pil.sent if not isinstance(m, p.SetOffset)]
    assert config == [p.Hello, p.SetGains, p.SetGait, p.Start]
    statuses = [m for m in sent_by_robot if isinstance(m, p.Status)]
    assert len(statuses) >= 4  # one a second
    assert statuses[-1].tx_dropped == 0
    assert all(cmd.matches for cmd in pil.executed)
    assert pil.telemetry and pil.telemetry[-1][1].state == p.State.RUNNING
    assert pil.host_bad_frames == {}


def test_short_straight_run_driven_by_the_emulated_avr_moves_forward_like_the_native_one(
    straight_runs,
):
    _, pil, native, _ = straight_runs
    travelled_pil = pil.states[-1, 6] - pil.states[0, 6]
    travelled_native = native.states[-1, 6] - native.states[0, 6]
    assert travelled_native > 0.15
    assert abs(travelled_pil - travelled_native) < DISTANCE_TOLERANCE * travelled_native
    assert abs(pil.states[-1, 7]) < 0.02  # still on the line


def test_emulated_avr_pulses_drive_servo_joints_like_the_native_firmware():
    # servo_robot.toml: each pulse's angle is the servo's reference (docs/model.md section 4).
    # Measured: the pulses, 10-20 ms behind the native firmware's references, move the robot
    # 2.7 % less far in 3 s; we allow 15 % as above
    robot = load_robot("servo_robot.toml")
    scenario = load_scenario("straight").model_copy(update={"duration_s": 3.0})
    options = LockstepOptions(LoopOptions(stop_at_goal=False))
    pil = run_processor_in_loop(robot, scenario, seed=0, options=options)
    native = run_firmware_in_loop(robot, scenario, seed=0, options=options)
    assert not pil.crashed
    travelled_pil = pil.states[-1, 6] - pil.states[0, 6]
    travelled_native = native.states[-1, 6] - native.states[0, 6]
    assert travelled_native > 0.3
    assert abs(travelled_pil - travelled_native) < DISTANCE_TOLERANCE * travelled_native
    # the joints follow the pulses' angles within the servo's lag
    phi = np.diff(pil.states[100:, :6], axis=1)
    assert np.abs(phi - pil.alpha_rad[100:]).max() < 0.2
