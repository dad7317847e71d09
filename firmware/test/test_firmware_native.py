"""The native firmware library against the twin's control laws (eelsim.control), through Python."""

import numpy as np
import pytest

from eelhost.wire import protocol as p
from eelhost.xil.native_firmware import NativeFirmware
from eelsim.control import Gait, gait_reference, joint_pd_torque

N_LINKS = p.N_JOINTS + 1


def f32(x):
    return float(np.float32(x))


def keep_alive(fw, t_us, offset, seq):
    """Resend the offset every 300 ms as the host does (it also feeds the link watchdog)."""
    if t_us % 300_000 == 0:
        fw.send(p.SetOffset(offset), seq % 256)


def started(t0_us, amplitude, omega, beta, offset, rates=0.0):
    """A firmware in lockstep mode, running the given gait from t0_us with no slew limits."""
    fw = NativeFirmware(now_us=t0_us, control_period_us=0)
    fw.send(p.SetGait(amplitude, omega, beta, rates, rates, rates), 0)
    fw.send(p.SetOffset(offset), 1)
    fw.send(p.Start(), 2)
    fw.tick(t0_us)
    acks = [m for _, m in fw.read_frames() if isinstance(m, p.Ack)]
    assert [a.msg_id for a in acks] == [p.MsgId.SET_GAIT, p.MsgId.SET_OFFSET, p.MsgId.START]
    return fw


@pytest.mark.parametrize(
    ("amplitude", "omega", "beta", "offset"),
    [(0.5, 3.1416, 1.04, 0.0), (0.9, 6.0, 0.6, 0.12), (0.3, 1.1, -2.0, -0.4)],
)
def test_gait_equals_the_twins_gait_reference_to_float32_precision(amplitude, omega, beta, offset):
    t0 = 1_000_000
    fw = started(t0, amplitude, omega, beta, offset)
    gait = Gait(f32(amplitude), f32(omega), f32(beta))
    worst = worst_rate = 0.0
    for k in range(1, 3001):  # 30 s at the twin's 10 ms step
        t_us = k * 10_000
        keep_alive(fw, t_us, offset, k)
        out = fw.tick(t0 + t_us)
        alpha, alpha_dot = gait_reference(t_us * 1e-6, gait, f32(offset), N_LINKS)
        worst = max(worst, float(np.max(np.abs(out.alpha_rad - alpha))))
        worst_rate = max(worst_rate, float(np.max(np.abs(out.alpha_dot_rad_s - alpha_dot))))
    assert worst < 5e-7  # 4 float32 ulps at 1 rad (measured: 2e-7)
    assert worst_rate < 5e-6  # measured: 1e-6 at omega = 6 rad/s


def test_gait_stays_equal_to_the_twin_across_the_micros_wrap():
    t0 = 2**32 - 3_000_000  # the robot's micros() wraps 3 s into the run
    fw = started(t0, 0.6, 4.0, 1.0, 0.05)
    gait = Gait(0.6, 4.0, 1.0)
    for k in range(1, 601):
        t_us = k * 10_000
        keep_alive(fw, t_us, 0.05, k)
        out = fw.tick(t0 + t_us)  # the binding passes the time modulo 2^32, like micros()
        alpha, _ = gait_reference(t_us * 1e-6, gait, f32(0.05), N_LINKS)
        np.testing.assert_allclose(out.alpha_rad, alpha, atol=5e-7)


def test_pd_torque_equals_the_twins_joint_pd_torque():
    fw = started(0, 0.5, 3.0, 1.0, 0.0)
    fw.send(p.SetGains(kp_nm_per_rad=2.5, kd_nms_per_rad=0.04, torque_limit_nm=10.0), 3)
    rng = np.random.default_rng(7)
    for k in range(1, 50):
        phi = rng.uniform(-0.5, 0.5, p.N_JOINTS).astype(np.float32)
        phi_dot = rng.uniform(-3, 3, p.N_JOINTS).astype(np.float32)
        out = fw.tick(k * 10_000, phi, phi_dot)
        want = joint_pd_torque(out.alpha_rad, out.alpha_dot_rad_s, phi, phi_dot, 2.5, f32(0.04))
        np.testing.assert_allclose(out.torque_nm, want, rtol=1e-5, atol=1e-6)


def test_pd_torque_is_clamped_to_the_commanded_limit():
    fw = started(0, 0.5, 3.0, 1.0, 0.0)
    fw.send(p.SetGains(kp_nm_per_rad=50.0, kd_nms_per_rad=0.0, torque_limit_nm=0.5), 3)
    out = fw.tick(10_000, np.full(p.N_JOINTS, 1.0), np.zeros(p.N_JOINTS))
    assert np.all(out.torque_nm == np.float32(-0.5))


def test_with_the_default_rates_the_joints_are_straight_0_9_s_after_the_last_frame():
    # The largest gait and offset, the default slew rates; the last command at 3 s.
    d = p.SetGait()
    fw = NativeFirmware(now_us=0)
    fw.send(p.SetGait(1.5, d.omega_rad_s, d.beta_rad, d.amplitude_rate_rad_s,
                      d.beta_rate_rad_s, d.offset_rate_rad_s), 0)  # fmt: skip
    fw.send(p.Start(), 1)
    states = {}
    for t_ms in range(0, 5001, 10):
        if t_ms <= 3000 and t_ms % 300 == 0:
            fw.send(p.SetOffset(-1.0), 2 + t_ms // 300)
        out = fw.tick(t_ms * 1000)
        states[t_ms] = fw.status()["state"], float(np.abs(out.alpha_rad).max())
    assert states[2990] == (p.State.RUNNING, pytest.approx(1.2))  # at the joint limit
    assert states[3500][0] == p.State.RUNNING and states[3500][1] > 0.5
    assert all(states[t][1] == 0.0 for t in range(3900, 5001, 10))
    assert all(states[t][0] == p.State.RUNNING for t in range(3000, 4000, 10))
    assert all(states[t][0] == p.State.FAILSAFE for t in range(4000, 5001, 10))


def test_an_echo_of_the_robots_own_frames_does_not_keep_the_link_alive():
    fw = NativeFirmware(now_us=0)
    fw.send(p.Start(), 0)
    for t_ms in range(0, 1200, 10):
        fw.tick(t_ms * 1000)
        fw.feed(fw.take())  # a radio that echoes everything the robot sends
        if t_ms == 990:
            assert fw.status()["state"] == p.State.RUNNING
    s = fw.status()
    assert s["state"] == p.State.FAILSAFE
    assert s["bad_direction"] > 10 and s["frames_ok"] == 1


def test_bad_frames_from_python_are_counted_and_ignored():
    fw = NativeFirmware(now_us=0)
    good = p.encode_frame(p.Start(), 0)
    flipped = bytearray(good)
    flipped[3] ^= 0x10
    fw.feed(b"\x07\x04\x00")  # garbage
    fw.feed(good[:-3] + b"\x00")  # truncated on the air
    fw.feed(b"\x05" * 100 + b"\x00")  # oversize
    fw.feed(bytes(flipped))  # one bit flipped: CRC
    fw.tick(10_000)
    s = fw.status()
    assert s["state"] == p.State.IDLE
    assert (s["bad_oversize"], s["bad_crc"]) == (1, 1)
    assert s["frames_bad"] == 4 and s["frames_ok"] == 0
    fw.feed(good)
    fw.tick(20_000)
    assert fw.status()["state"] == p.State.RUNNING


def test_refused_command_comes_back_with_its_reason():
    fw = NativeFirmware()
    fw.send(p.SetOffset(offset_rad=3.0), 9)
    fw.tick(1000)
    replies = [m for _, m in fw.read_frames() if isinstance(m, p.Refuse)]
    assert replies == [p.Refuse(p.MsgId.SET_OFFSET, 9, p.RefuseReason.OUT_OF_RANGE)]


def test_servo_pulses_follow_the_references_through_the_calibration():
    fw = started(0, 0.8, 2.0, 1.0, 0.1)
    out = fw.tick(400_000)
    expected = np.clip(np.floor(1500 + 636.6 * out.alpha_rad.astype(np.float64) + 0.5), 700, 2300)
    np.testing.assert_array_equal(out.pulse_us, expected)


def test_control_updates_run_every_10ms_by_default():
    fw = NativeFirmware(now_us=0)
    ran = [fw.tick(t).control_ran for t in range(1000, 50_001, 1000)]
    assert sum(ran) == 5


def test_bad_arguments_get_clear_errors():
    fw = NativeFirmware()
    with pytest.raises(ValueError, match="shape"):
        fw.tick(0, np.zeros(4))
    with pytest.raises(ValueError, match="non-negative"):
        fw.tick(-1)
    with pytest.raises(BufferError, match="queue full"):
        fw.feed(b"\x01" * 5000)
