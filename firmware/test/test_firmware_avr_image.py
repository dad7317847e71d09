"""The real AVR image in simavr (tools/eel_avrsim): radio link, Timer1 servo pulses, the gait, the
loop under a flood, the failsafe, the watchdog, the EEPROM, the ADC (joint feedback, battery).

The harness corrects two things simavr 1.6 gets wrong (tools/eel_avrsim.c): its UART takes the
true 10 bit times a byte of 8N1 (simavr counts a parity bit: 5195 bytes/s instead of 5760), so the
floods below run at the real line rate; and an EEPROM byte takes the chip's 3.4 ms to program
(simavr: at once), so a save's cost to the control loop shows.

Unless a test gives an EEPROM, the AVR boots one holding the default settings in slot 0 (a robot
that has been set up); BLANK is an erased one.
"""

import functools
import os
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from eelhost.wire import protocol as p

FIRMWARE = Path(__file__).resolve().parents[1]
# EEL_AVR_ELF runs the tests against another image (e.g. an older firmware, to see a test fail).
ELF = Path(os.environ.get("EEL_AVR_ELF", FIRMWARE / "build" / "avr" / "eelbot.elf"))
SIM = FIRMWARE / "build" / "tools" / "eel_avrsim"
SETTINGS_IMAGE = FIRMWARE / "build" / "tools" / "settings_image"
pytestmark = pytest.mark.slow  # a few seconds of emulated AVR per test

SERVO_PINS = ["D2", "D3", "D4", "D5", "D6"]  # firmware/hal/avr/pins.h, joint 1 first
BUSY_PIN = "D7"  # high while a control update runs
# Another interrupt (Timer0's millis tick, the UART) can delay a servo edge by up to ~80 cycles.
JITTER_US = 6.0
# simavr's ADC: counts = millivolts * 1023 / 5000 (AVCC reference), truncated.
ADC_MV_PER_COUNT = 5000 / 1023
BATTERY_ADC = 6  # A6 (firmware/hal/avr/pins.h)
BYTE_US = 1e6 / 5760  # 8N1 at 57600 baud, as the harness feeds the UART
BLANK = b"\xff" * 1024  # an erased EEPROM
FLOOD = FIRMWARE / "build" / "tools" / "flood"
# One settings slot (firmware/core/settings_store.h): version, generation, settings, CRC-32.
WIRE_BYTES = {"u8": 1, "i16": 2, "u16": 2, "f32": 4}
SLOT_BYTES = 4 + sum(i.count * WIRE_BYTES[i.wire_type] for i in p.SETTINGS.values()) + 4


def assert_centred(widths_us, centre_us=1500.0):
    """Straight joint: the centre within the interrupt latency (a few cycles), but for the odd
    edge delayed by another interrupt.
    """
    err = np.abs(widths_us - centre_us)
    assert np.median(err) <= 0.5 and err.max() <= JITTER_US


@dataclass
class AvrRun:
    """What the AVR did in one run: its report, the frames it sent, the pulses, its EEPROM."""

    stdout: str
    sent: list = field(default_factory=list)  # (t_us of the frame's last byte, message)
    pulses: dict = field(default_factory=dict)  # pin -> array of (rise_us, width_us)
    eeprom: bytes = b""
    output: list = field(default_factory=list)  # (t_us, byte) of every byte sent

    def messages(self, kind):
        return [m for _, m in self.sent if isinstance(m, kind)]

    @property
    def watchdog_resets(self):
        line = next(x for x in self.stdout.splitlines() if x.startswith("watchdog resets:"))
        return int(line.split(":")[1])

    def control_updates_us(self):
        """(rise, duration) of every control update, from the busy pin."""
        return self.pulses[BUSY_PIN]


@pytest.fixture(scope="module")
def run_avr(tmp_path_factory):
    subprocess.run(["make", "-s", "-C", str(FIRMWARE), "avr", "tools"], check=True)
    tmp = tmp_path_factory.mktemp("avrsim")

    def run(frames_at_us, run_ms, *, adc=(), eeprom=None, reset_at_us=(), hang_at_us=None,
            uart_file=None, bootloader="none", elf=None):
        uart_in, uart_out, pulses = tmp / "in.txt", tmp / "out.txt", tmp / "pulses.txt"
        eeprom_out, adc_in = tmp / "eeprom_out.bin", tmp / "adc.txt"
        if uart_file is not None:
            uart_in = uart_file
        else:
            uart_in.write_text(
                "".join(f"{t} {frame.hex(' ')}\n" for t, frame in frames_at_us), encoding="ascii"
            )
        adc_in.write_text("".join(f"{t} {i} {mv}\n" for t, i, mv in adc), encoding="ascii")
        args = [
            str(SIM), "--elf", str(elf or ELF), "--run-ms", str(run_ms), "--uart-in", str(uart_in),
            "--bootloader", bootloader,
            "--uart-out", str(uart_out), "--pulse-pins", ",".join([*SERVO_PINS, BUSY_PIN]),
            "--pulses", str(pulses), "--adc", str(adc_in), "--eeprom-out", str(eeprom_out),
        ]  # fmt: skip
        (tmp / "eeprom_in.bin").write_bytes(settings_image() if eeprom is None else eeprom)
        args += ["--eeprom-in", str(tmp / "eeprom_in.bin")]
        if reset_at_us:
            args += ["--reset-at-us", ",".join(str(t) for t in reset_at_us)]
        if hang_at_us is not None:
            args += ["--hang-at-us", str(hang_at_us)]
        proc = subprocess.run(args, capture_output=True, text=True, check=True)
        out = AvrRun(proc.stdout, eeprom=eeprom_out.read_bytes())
        reader = p.FrameReader()
        for line in uart_out.read_text().splitlines():
            t_us, byte = line.split()
            out.output.append((float(t_us), int(byte, 16)))
            out.sent += [(float(t_us), m) for _, m in reader.feed(bytes([int(byte, 16)]))]
        assert reader.bad == {}
        edges = {pin: [] for pin in [*SERVO_PINS, BUSY_PIN]}
        for line in pulses.read_text().splitlines():
            rise, pin, width = line.split()
            edges[pin].append((float(rise), float(width)))
        out.pulses = {k: np.array(v).reshape(-1, 2) for k, v in edges.items()}
        return out

    return run


@functools.cache
def settings_image(*assignments):
    """An EEPROM image of the default settings with some changed (``"11=1"``: joint_feedback)."""
    proc = subprocess.run(
        [str(SETTINGS_IMAGE), "/dev/stdout", *assignments], capture_output=True, check=True
    )
    return proc.stdout


def session(start_at_us, amplitude, omega, rates=0.0, keep_alive_until_us=3_000_000):
    gait = p.SetGait(amplitude, omega, 1.04, rates, rates, rates)
    frames = [
        (100_000, p.encode_frame(p.Hello(), 0)),
        (120_000, p.encode_frame(gait, 1)),
        (start_at_us, p.encode_frame(p.Start(), 2)),
    ]
    for k, t in enumerate(range(start_at_us + 300_000, keep_alive_until_us, 300_000)):
        frames.append((t, p.encode_frame(p.SetOffset(0.0), (3 + k) % 256)))
    return frames


def test_avr_answers_hello_and_acknowledges_commands_over_its_uart(run_avr):
    run = run_avr(session(200_000, 0.8, 2 * np.pi), 600)
    versions = run.messages(p.Version)
    assert versions and versions[0].schema_hash == p.SCHEMA_HASH
    assert versions[0].settings_version == p.SETTINGS_VERSION
    assert [m.msg_id for m in run.messages(p.Ack)][:2] == [p.MsgId.SET_GAIT, p.MsgId.START]
    telemetry = run.messages(p.Telemetry)
    assert telemetry[-1].state == p.State.RUNNING and telemetry[-1].frames_bad == 0
    status = run.messages(p.Status)[0]
    assert status.reset_flags == p.ResetFlags.POWER_ON and status.resets == 0
    assert status.settings_source == p.SettingsSource.EEPROM
    assert not status.flags & p.Flags.SETTINGS_LOST
    assert status.flags & p.Flags.HW_WATCHDOG and not status.flags & p.Flags.JOINT_FEEDBACK


def test_avr_servo_pulses_repeat_at_50hz_and_follow_the_gait(run_avr):
    run = run_avr(session(500_000, 0.8, 2 * np.pi), 2500)
    edges = run.pulses
    # Joint 1's pulse starts every frame of 20 ms (50 Hz); each next joint's pulse starts when the
    # previous one ends (one after the other, as the Timer1 driver sequences them).
    np.testing.assert_allclose(np.diff(edges["D2"][:, 0]), p.SERVO_FRAME_US, atol=2 * JITTER_US)
    n = min(len(edges[pin]) for pin in SERVO_PINS)
    for prev, pin in zip(SERVO_PINS, SERVO_PINS[1:], strict=False):
        end_prev = edges[prev][:n, 0] + edges[prev][:n, 1]
        np.testing.assert_allclose(edges[pin][:n, 0], end_prev, atol=JITTER_US)
    for j, pin in enumerate(SERVO_PINS):
        rise, width = edges[pin][:, 0], edges[pin][:, 1]
        assert_centred(width[rise < 450_000])  # straight until Start
        after = width[rise > 600_000]  # a whole 1 Hz cycle and more
        swing = 636.6 * 0.8 * (p.N_JOINTS - j) / (p.N_JOINTS + 2)  # calibration x A_j
        assert after.max() - 1500 == pytest.approx(swing, rel=0.03, abs=JITTER_US)
        assert 1500 - after.min() == pytest.approx(swing, rel=0.03, abs=JITTER_US)


def test_avr_fades_to_straight_by_0_9_s_with_the_default_rates_and_reports_failsafe_at_1_s(
    run_avr,
):
    # The largest gait SetGait allows, with the default slew rates, the link quiet after 2.1 s.
    d = p.SetGait()
    gait = p.SetGait(1.5, d.omega_rad_s, d.beta_rad, d.amplitude_rate_rad_s, d.beta_rate_rad_s,
                     d.offset_rate_rad_s)  # fmt: skip
    last_us = 3_900_000
    frames = [(100_000, p.encode_frame(gait, 0)), (110_000, p.encode_frame(p.Start(), 1))]
    frames += [
        (t, p.encode_frame(p.SetOffset(1.0), 2 + k))
        for k, t in enumerate(range(300_000, last_us + 1, 300_000))
    ]
    run = run_avr(frames, 5500)
    arrived_us = last_us + 16 * BYTE_US  # the SetOffset's 16 bytes at the line rate
    widths = run.pulses["D2"]
    before = widths[(widths[:, 0] > last_us - 1_000_000) & (widths[:, 0] < last_us)]
    assert np.abs(before[:, 1] - 1500).max() > 500  # undulating about a large offset before
    # 0.9 s after the last command the references are straight: every pulse from the next servo
    # frame on is centred.
    assert_centred(widths[widths[:, 0] > arrived_us + 0.9e6 + p.SERVO_FRAME_US, 1])
    # The robot's clock starts with the emulation (micros() from reset, ~0.1 ms of boot).
    states = [(m.time_us, p.State(m.state)) for m in run.messages(p.Telemetry)]
    failsafe_us = min(t for t, s in states if s == p.State.FAILSAFE)
    assert 1.0e6 <= failsafe_us - arrived_us <= 1.0e6 + 12_000  # the first update after 1 s
    assert all(s == p.State.RUNNING for t, s in states if 300_000 < t < arrived_us + 0.95e6)


def flood(n, start_us=200_000):
    """n valid commands back to back from start_us: new gaits (a new omega each time), offsets,
    starts, all acknowledged."""
    frames = []
    for k in range(n):
        kind = k % 3
        if kind == 0:
            m = p.SetGait(0.5, 2.0 + 0.5 * (k % 7), 1.0, 0.5, 1.0, 2.0)
        elif kind == 1:
            m = p.SetOffset(0.01 * (k % 20))
        else:
            m = p.Start()
        frames.append((start_us, p.encode_frame(m, k % 256)))
    return frames


def test_avr_control_period_holds_under_a_flood_of_commands_and_replies_keep_flowing(run_avr):
    commands = flood(450)
    in_bytes = sum(len(f) for _, f in commands)
    flood_end_us = 200_000 + in_bytes * BYTE_US
    ask = (round(flood_end_us) + 100_000, p.encode_frame(p.GetStatus(), len(commands) % 256))
    run = run_avr([*commands, ask], round(flood_end_us / 1000) + 300)
    rises = run.control_updates_us()[:, 0]
    during = (rises > 200_000) & (rises < flood_end_us)
    periods = np.diff(rises)[during[1:]]
    assert len(periods) > 150
    # The 10 ms period holds within 0.3 ms (measured: 9.99 .. 10.01 ms).
    assert np.all(np.abs(periods - p.CONTROL_PERIOD_US) < 300)
    status = run.messages(p.Status)[-1]
    assert status.control_late_max_us < 300
    assert status.frames_ok == len(commands) + 1
    assert sum(getattr(status, f) for f in status.__dataclass_fields__ if f.startswith("bad_")) == 0
    assert status.lost == 0 and status.duplicates == 0
    # Replies: every command answered. Replies take precedence in the transmit queue
    # (docs/firmware.md, "Link") and an Ack is shorter than any command, so none is dropped
    # (before, 1 % were: the queue kept room for the Telemetry instead).
    answers = len(run.messages(p.Ack)) + len(run.messages(p.Refuse))
    assert status.tx_dropped == 0
    assert answers == len(commands)
    # Telemetry every 100 ms all the way through: the Acks leave the line room for it.
    times = np.array([m.time_us for m in run.messages(p.Telemetry)])
    assert times[-1] >= flood_end_us
    assert np.diff(times).max() <= p.TELEMETRY_PERIOD_US + 1000


def test_avr_hang_in_the_main_loop_ends_in_a_watchdog_reset_that_status_reports(run_avr):
    run = run_avr([(900_000, p.encode_frame(p.GetStatus(), 0))], 1300, hang_at_us=300_000)
    assert run.watchdog_resets == 1
    statuses = run.messages(p.Status)
    assert statuses[0].reset_flags == p.ResetFlags.POWER_ON and statuses[0].resets == 0
    assert statuses[-1].reset_flags == p.ResetFlags.WATCHDOG and statuses[-1].resets == 1
    # The servos held their pulse through the hang (Timer1 runs on), missed a frame or two while
    # the AVR reset and booted, and came back centred.
    widths = run.pulses["D2"]
    hung = widths[(widths[:, 0] > 320_000) & (widths[:, 0] < 540_000)]
    assert len(hung) >= 10
    assert np.diff(widths[:, 0]).max() < 3 * p.SERVO_FRAME_US
    assert_centred(widths[widths[:, 0] > 1_000_000, 1])


def test_avr_keeps_its_settings_across_a_reset_and_boots_defaults_from_a_corrupt_eeprom(run_avr):
    frames = [
        (100_000, p.encode_frame(p.SetSetting(p.SettingKey.TRIM_US, 0, 40.0), 0)),
        (120_000, p.encode_frame(p.SaveSettings(), 1)),
        (900_000, p.encode_frame(p.GetStatus(), 0)),
    ]
    run = run_avr(frames, 1200, reset_at_us=(700_000,))
    assert [m.msg_id for m in run.messages(p.Ack)] == [p.MsgId.SET_SETTING, p.MsgId.SAVE_SETTINGS]
    after = run.messages(p.Status)[-1]
    assert after.reset_flags == p.ResetFlags.EXTERNAL and after.resets == 1
    assert after.settings_source == p.SettingsSource.EEPROM
    widths = run.pulses["D2"]
    assert_centred(widths[widths[:, 0] > 800_000, 1], centre_us=1540.0)
    # The EEPROM as the AVR left it, one bit flipped in each slot: the defaults, and Status says
    # why.
    corrupt = bytearray(run.eeprom)
    corrupt[5] ^= 0x10
    corrupt[SLOT_BYTES + 5] ^= 0x10
    run = run_avr([], 300, eeprom=bytes(corrupt))
    assert run.messages(p.Status)[0].settings_source == p.SettingsSource.CORRUPT
    assert_centred(run.pulses["D2"][:, 1])


def joint_mv(counts):
    return round((counts + 0.5) * ADC_MV_PER_COUNT)


def test_avr_measures_the_joints_and_its_pd_commands_the_reference_when_kp_is_the_stiffness(
    run_avr,
):
    # Feedback on, kp = stiffness = 1.5, kd = 0 (and a torque limit that does not bind): the
    # robot's PD reduces to the reference, so the pulses must be those of the feedback-free
    # image, whatever the joints measure.
    image = settings_image("11=1", "4=1.5", "5=0", "6=10", "14=1.5")
    counts = [512 + 40 * j - 80 for j in range(p.N_JOINTS)]
    adc = [(0, j, joint_mv(c)) for j, c in enumerate(counts)]
    closed = run_avr(session(200_000, 0.6, 1.0), 1500, adc=adc, eeprom=image)
    open_ = run_avr(session(200_000, 0.6, 1.0), 1500)
    telemetry = closed.messages(p.Telemetry)[-1]
    assert telemetry.flags & p.Flags.JOINT_FEEDBACK
    assert list(telemetry.phi_mrad) == [round((c - 512) / 130.4 * 1000) for c in counts]
    assert set(open_.messages(p.Telemetry)[-1].phi_mrad) == {-32768}
    # A pulse carries the last update's command; the update with feedback ends 0.5 ms later, so a
    # pulse starting in between carries the update 10 ms before: at omega = 1 rad/s a reference
    # moves at most A_1 omega 10 ms = 0.0043 rad (2.7 us) in that time.
    for pin in SERVO_PINS:
        a, b = closed.pulses[pin], open_.pulses[pin]
        n = min(len(a), len(b))
        np.testing.assert_allclose(a[:n, 0], b[:n, 0], atol=2 * JITTER_US)  # the same frames
        np.testing.assert_allclose(a[:n, 1], b[:n, 1], atol=3 + JITTER_US)
    # The cost of the joint loop with feedback, within the 2 ms of a control update.
    assert closed.control_updates_us()[:, 1].max() < 2000


def test_avr_stops_on_a_low_battery_and_says_so(run_avr):
    image = settings_image("15=3")  # divider 3: 7.5 V at 2.5 V
    adc = [(0, BATTERY_ADC, 2500), (600_000, BATTERY_ADC, 1950)]  # 7.5 V, then 5.85 V (< 6.4)
    frames = session(200_000, 0.6, 2 * np.pi, keep_alive_until_us=4_000_000)
    run = run_avr(frames, 3500, adc=adc, eeprom=image)
    states = [(m.time_us, p.State(m.state)) for m in run.messages(p.Telemetry)]
    assert any(s == p.State.RUNNING for _, s in states)
    assert states[-1][1] == p.State.LOW_BATTERY
    status = run.messages(p.Status)[-1]
    assert status.flags & p.Flags.BATTERY_SENSE
    # The filtered voltage (1 s time constant) of the readings 511 then 398 counts, times 3.
    high, low = (int(mv / ADC_MV_PER_COUNT) * 5 / 1024 * 3 for mv in (2500, 1950))
    filtered = low + (high - low) * np.exp(-(status.time_us - 600_000) / 1e6)
    assert status.battery_v == pytest.approx(filtered, abs=0.02)
    assert_centred(run.pulses["D2"][run.pulses["D2"][:, 0] > 3_000_000, 1])


@pytest.mark.parametrize(
    ("override", "message"),
    [("FLASH_BUDGET=8000", "flash over budget"), ("RAM_BUDGET=512", "static RAM over budget")],
)
def test_avr_build_fails_when_the_image_exceeds_a_budget(override, message):
    proc = subprocess.run(
        ["make", "-s", "-C", str(FIRMWARE), "avr", override], capture_output=True, text=True
    )
    assert proc.returncode != 0
    assert f"FAIL: {message}" in proc.stdout


# ---------------------------------------------------------------- issue 29: replay, power, traffic


def test_avr_a_replayed_frame_is_answered_but_the_robot_still_fades_and_fails_safe(run_avr):
    frames = session(200_000, 0.8, 2 * np.pi, keep_alive_until_us=600_000)
    last_t, last = frames[-1]
    # A stuck radio sends the last frame again every 50 ms for 2.5 s.
    copies = list(range(last_t + 50_000, last_t + 2_550_000, 50_000))
    frames += [(t, last) for t in copies]
    run = run_avr(frames, 3000)
    arrived_us = last_t + len(last) * BYTE_US
    states = [(m.time_us, p.State(m.state), m.flags) for m in run.messages(p.Telemetry)]
    failsafe_us = min(t for t, s, _ in states if s == p.State.FAILSAFE)
    assert 1.0e6 <= failsafe_us - arrived_us <= 1.0e6 + 12_000
    assert any(f & p.Flags.FADING for t, _, f in states if t < failsafe_us)
    status = run.messages(p.Status)[-1]
    copies_in = sum(t + len(last) * BYTE_US < status.time_us - 1000 for t in copies)
    assert status.duplicates == copies_in  # every copy counted ...
    acks = [m for m in run.messages(p.Ack) if m.seq == p.decode_frame(last[:-1])[0]]
    assert len(acks) >= 45  # ... and answered as the first was


def test_avr_a_save_runs_beside_the_control_loop_at_the_eeproms_real_write_time(run_avr):
    # A trim changed and saved while idle, the robot then started: the save's bytes take 3.4 ms
    # each, and the 10 ms control period and the telemetry go on meanwhile.
    frames = [
        (100_000, p.encode_frame(p.SetSetting(p.SettingKey.TRIM_US, 2, -30.0), 0)),
        (110_000, p.encode_frame(p.SaveSettings(), 1)),
        (120_000, p.encode_frame(p.SetGait(0.6, 2 * np.pi, 1.04, 0, 0, 0), 2)),
        (130_000, p.encode_frame(p.Start(), 3)),
    ]
    run = run_avr(frames, 1000)
    saved_at = next(t for t, m in run.sent if isinstance(m, p.Ack)
                    and m.msg_id == p.MsgId.SAVE_SETTINGS)  # fmt: skip
    save_us = saved_at - (110_000 + 12 * BYTE_US)
    written = sum(a != b for a, b in zip(run.eeprom, settings_image(), strict=True))
    assert written >= SLOT_BYTES - 8  # the other slot, from erased (bytes that match are skipped)
    assert save_us >= written * 3400  # the EEPROM's own pace: it cannot be quicker
    rises = run.control_updates_us()[:, 0]
    during = rises[(rises > 110_000) & (rises < saved_at + 20_000)]
    assert np.abs(np.diff(during) - p.CONTROL_PERIOD_US).max() < 300
    times = np.array([t for t, m in run.sent if isinstance(m, p.Telemetry)])
    assert np.diff(times[times < saved_at + 200_000]).max() < p.TELEMETRY_PERIOD_US + 2000
    assert run.messages(p.Telemetry)[-1].state == p.State.RUNNING
    # and it holds: a power cycle boots the saved trim
    after = run_avr([(100_000, p.encode_frame(p.GetSetting(p.SettingKey.TRIM_US, 2), 0))], 200,
                    eeprom=run.eeprom)  # fmt: skip
    assert after.messages(p.Setting)[0].value == -30.0


@pytest.mark.parametrize("cut", [0.02, 0.35, 0.97, 1.3])
def test_avr_reset_while_saving_boots_the_old_or_the_new_settings(run_avr, cut):
    """A reset at a point of the save (fraction of its bytes' programming time): the trims are
    those before or those after, never the defaults (every byte: firmware/test/test_robot.cpp)."""
    old = settings_image("1.0=25", "1.4=-15")
    frames = [
        (100_000, p.encode_frame(p.SetSetting(p.SettingKey.TRIM_US, 0, -60.0), 0)),
        (110_000, p.encode_frame(p.SaveSettings(), 1)),
        (900_000, p.encode_frame(p.GetSetting(p.SettingKey.TRIM_US, 0), 0)),
    ]
    save_starts_us = 110_000 + 12 * BYTE_US
    reset_us = round(save_starts_us + cut * SLOT_BYTES * 3400)
    run = run_avr(frames, 1000, eeprom=old, reset_at_us=(reset_us,))
    status = run.messages(p.Status)[-1]
    assert status.settings_source == p.SettingsSource.EEPROM
    assert not status.flags & p.Flags.SETTINGS_LOST
    trim = run.messages(p.Setting)[-1].value
    assert trim in (25.0, -60.0)
    if cut < 0.9:
        assert trim == 25.0  # the CRC-32, committed last, was not in yet
    if cut > 1.1:
        assert trim == -60.0


def test_avr_with_no_valid_settings_refuses_start_until_the_host_takes_the_defaults(run_avr):
    frames = [
        (100_000, p.encode_frame(p.Start(), 0)),
        (200_000, p.encode_frame(p.DefaultSettings(), 1)),
        (300_000, p.encode_frame(p.Start(), 2)),
    ]
    run = run_avr(frames, 500, eeprom=BLANK)
    refusal = run.messages(p.Refuse)[0]
    assert refusal.msg_id == p.MsgId.START and refusal.reason == p.RefuseReason.SETTINGS_LOST
    assert [m.msg_id for m in run.messages(p.Ack)] == [p.MsgId.DEFAULT_SETTINGS, p.MsgId.START]
    first = run.messages(p.Status)[0]
    assert first.settings_source == p.SettingsSource.BLANK
    assert first.flags & p.Flags.SETTINGS_LOST and first.flags & p.Flags.BATTERY_SENSE
    assert run.messages(p.Telemetry)[-1].state == p.State.RUNNING


FLOOD_KINDS = ["commands", "queries", "garbage", "corrupted", "echoes", "replays", "mixed"]


@pytest.mark.parametrize("kind", FLOOD_KINDS)
def test_avr_period_and_update_time_hold_under_a_line_rate_flood(run_avr, tmp_path, kind):
    """Joint feedback and battery on, the line full at 5760 bytes/s with one kind of traffic and
    a save at its start: every period within 10 +- 0.3 ms, every update within its 2 ms with the
    UART's interrupts counted. 2 s here; `make -C firmware bench-long` runs 10.5 s a kind for the
    figures of docs/firmware.md."""
    run_ms = 2000
    flood_file = tmp_path / "flood.txt"
    with flood_file.open("w") as f:
        subprocess.run([str(FLOOD), kind, str(run_ms)], stdout=f, check=True)
    counts = [512] * p.N_JOINTS
    adc = [(0, j, joint_mv(c)) for j, c in enumerate(counts)]
    run = run_avr([], run_ms, adc=adc, eeprom=settings_image("11=1"), uart_file=flood_file)
    line = run.stdout
    delivered = int(line.split("uart: ")[1].split(" of")[0])
    assert delivered >= 0.99 * 5760 * (run_ms - 200) / 1000  # the true line rate, from 0.2 s
    rises, widths = run.control_updates_us()[:, 0], run.control_updates_us()[:, 1]
    periods = np.diff(rises[rises > 50_000])
    assert len(periods) >= run_ms / 10 - 10
    assert np.abs(periods - p.CONTROL_PERIOD_US).max() <= 300
    assert widths.max() <= 2000
    # Replies take precedence over Telemetry in the transmit queue (docs/firmware.md, "Link").
    statuses = run.messages(p.Status)
    if kind == "queries":
        # The answers asked for exceed the line (a Status of 50 bytes for a GetStatus of 12, a
        # Version of 22 for a Hello of 12): the queue stays full of replies, so the Telemetry
        # waits for the whole flood. The replies fill the line to the end, and the Status
        # answers among them go on saying how the robot is.
        out_us = np.array([t for t, _ in run.output])
        assert (out_us > 300_000).sum() >= 0.97 * 5760 * (run_ms - 300) / 1000
        last = statuses[-1]
        assert [t for t, m in run.sent if isinstance(m, p.Status)][-1] >= (run_ms - 100) * 1000
    else:
        # Every answer shorter than what it answers (or none): no reply is dropped, and the
        # Telemetry comes every 100 ms to the end, at worst one waiting for the next control
        # update (10.5 s of mixed traffic: once, a 110 ms gap).
        assert statuses[-1].tx_dropped == 0
        last = run.messages(p.Telemetry)[-1]
        times = np.array([m.time_us for m in run.messages(p.Telemetry)])
        assert times[-1] >= (run_ms - 110) * 1000
        assert np.diff(times).max() <= p.TELEMETRY_PERIOD_US + p.CONTROL_PERIOD_US + 2000
    assert last.state == p.State.RUNNING  # the keep-alive got through
    assert last.flags & p.Flags.JOINT_FEEDBACK
    # The save went through beside it (its Ack may be one of the replies a full queue drops).
    eeprom_writes = int(line.split("eeprom writes: ")[1].split()[0])
    assert eeprom_writes >= SLOT_BYTES - 8
    assert run.eeprom[SLOT_BYTES:2 * SLOT_BYTES] != BLANK[:SLOT_BYTES]


def test_avr_stack_peak_is_measured_and_the_build_fails_over_the_ram_limit():
    ok = subprocess.run(["make", "-s", "-C", str(FIRMWARE), "bench"], capture_output=True,
                        text=True)  # fmt: skip
    assert ok.returncode == 0, ok.stdout + ok.stderr
    line = next(x for x in ok.stdout.splitlines() if x.startswith("RAM: static"))
    peak = int(line.split("stack peak ")[1].split()[0])
    assert 300 < peak < 1024
    over = subprocess.run(["make", "-s", "-C", str(FIRMWARE), "bench", "RAM_LIMIT=1200"],
                          capture_output=True, text=True)  # fmt: skip
    assert over.returncode != 0
    assert "FAIL: static RAM plus the stack's peak exceeds 1200" in over.stdout


def test_avr_behind_the_old_bootloader_still_tells_a_watchdog_reset_and_a_power_on(run_avr):
    """The old Nano bootloader clears MCUSR: the watchdog's interrupt marks its reset in RAM and
    a power-on shows as a reset record that does not check out; the reset pin reads 0 (unknown)."""
    frames = [(900_000, p.encode_frame(p.GetStatus(), 0))]
    run = run_avr(frames, 1300, hang_at_us=300_000, bootloader="old")
    assert run.watchdog_resets == 1
    statuses = run.messages(p.Status)
    assert statuses[0].reset_flags == p.ResetFlags.POWER_ON and statuses[0].resets == 0
    assert statuses[-1].reset_flags == p.ResetFlags.WATCHDOG and statuses[-1].resets == 1
    run = run_avr(frames, 1000, reset_at_us=(500_000,), bootloader="old")
    assert run.messages(p.Status)[-1].reset_flags == 0 and run.messages(p.Status)[-1].resets == 1


def test_avr_built_for_optiboot_reads_the_reset_cause_it_leaves_in_r2(run_avr):
    build = FIRMWARE / "build" / "optiboot"
    subprocess.run(["make", "-s", "-C", str(FIRMWARE), "avr", "B=build/optiboot",
                    "BOOTLOADER=optiboot"], check=True, capture_output=True)  # fmt: skip
    elf = build / "avr" / "eelbot.elf"
    frames = [(900_000, p.encode_frame(p.GetStatus(), 0))]
    run = run_avr(frames, 1000, reset_at_us=(500_000,), bootloader="optiboot", elf=elf)
    statuses = run.messages(p.Status)
    assert statuses[0].reset_flags == p.ResetFlags.POWER_ON
    assert statuses[-1].reset_flags == p.ResetFlags.EXTERNAL and statuses[-1].resets == 1
