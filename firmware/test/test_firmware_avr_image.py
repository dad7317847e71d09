"""The real AVR image in simavr (tools/eel_avrsim): radio link, Timer1 servo pulses, the gait."""

import subprocess
from pathlib import Path

import numpy as np
import pytest

from eelhost.wire import protocol as p

FIRMWARE = Path(__file__).resolve().parents[1]
ELF = FIRMWARE / "build" / "avr" / "eelbot.elf"
SIM = FIRMWARE / "build" / "tools" / "eel_avrsim"
pytestmark = pytest.mark.slow  # a few seconds of emulated AVR per test

SERVO_PINS = ["D2", "D3", "D4", "D5", "D6"]  # firmware/hal/avr/pins.h, joint 1 first
# Another interrupt (Timer0's millis tick, the UART) can delay a servo edge by up to ~80 cycles.
JITTER_US = 6.0


def assert_centred(widths_us):
    """Straight joint: 1500 us within the interrupt latency (a few cycles), but for the odd edge
    delayed by another interrupt.
    """
    err = np.abs(widths_us - 1500.0)
    assert np.median(err) <= 0.5 and err.max() <= JITTER_US


@pytest.fixture(scope="module")
def run_avr(tmp_path_factory):
    subprocess.run(["make", "-s", "-C", str(FIRMWARE), "avr", "tools"], check=True)
    tmp = tmp_path_factory.mktemp("avrsim")

    def run(frames_at_us, run_ms):
        uart_in, uart_out, pulses = tmp / "in.txt", tmp / "out.txt", tmp / "pulses.txt"
        uart_in.write_text(
            "".join(f"{t} {frame.hex(' ')}\n" for t, frame in frames_at_us), encoding="ascii"
        )
        proc = subprocess.run(
            [
                str(SIM),
                "--elf",
                str(ELF),
                "--run-ms",
                str(run_ms),
                "--uart-in",
                str(uart_in),
                "--uart-out",
                str(uart_out),
                "--pulse-pins",
                ",".join(SERVO_PINS),
                "--pulses",
                str(pulses),
                "--busy-pin",
                "D7",
            ],
            capture_output=True,
            text=True,
            check=True,
        )
        sent = bytes(int(line.split()[1], 16) for line in uart_out.read_text().splitlines())
        reader = p.FrameReader()
        frames = [m for _, m in reader.feed(sent)]
        assert reader.bad == {}
        edges = {pin: [] for pin in SERVO_PINS}
        for line in pulses.read_text().splitlines():
            rise, pin, width = line.split()
            edges[pin].append((float(rise), float(width)))
        return proc.stdout, frames, {k: np.array(v) for k, v in edges.items()}

    return run


def session(start_at_us, amplitude, omega):
    gait = p.SetGait(amplitude, omega, 1.04, 0.0, 0.0, 0.0)
    frames = [
        (100_000, p.encode_frame(p.Hello(), 0)),
        (120_000, p.encode_frame(gait, 1)),
        (start_at_us, p.encode_frame(p.Start(), 2)),
    ]
    for k, t in enumerate(range(start_at_us + 300_000, 3_000_000, 300_000)):
        frames.append((t, p.encode_frame(p.SetOffset(0.0), (3 + k) % 256)))
    return frames


def test_avr_answers_hello_and_acknowledges_commands_over_its_uart(run_avr):
    _, frames, _ = run_avr(session(200_000, 0.8, 2 * np.pi), 600)
    versions = [m for m in frames if isinstance(m, p.Version)]
    assert versions and versions[0].schema_hash == p.SCHEMA_HASH
    assert [m.msg_id for m in frames if isinstance(m, p.Ack)][:2] == [
        p.MsgId.SET_GAIT,
        p.MsgId.START,
    ]
    telemetry = [m for m in frames if isinstance(m, p.Telemetry)]
    assert telemetry[-1].state == p.State.RUNNING and telemetry[-1].frames_bad == 0


def test_avr_servo_pulses_repeat_at_50hz_and_follow_the_gait(run_avr):
    stdout, _, edges = run_avr(session(500_000, 0.8, 2 * np.pi), 2500)
    # Joint 1's pulse starts every frame of 20 ms (50 Hz); each next joint's pulse starts when the
    # previous one ends (one after the other, as the Timer1 driver sequences them).
    np.testing.assert_allclose(np.diff(edges["D2"][:, 0]), p.SERVO_FRAME_US, atol=2 * JITTER_US)
    n = min(len(e) for e in edges.values())
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
    assert "control update" in stdout


def test_avr_stops_undulating_one_second_after_the_link_goes_quiet(run_avr):
    frames = session(200_000, 0.6, 2 * np.pi)[:3]  # no keep-alive after Start
    _, sent, edges = run_avr(frames, 2500)
    states = [(m.time_us, m.state) for m in sent if isinstance(m, p.Telemetry)]
    assert all(s == p.State.RUNNING for t, s in states if 300_000 < t < 1_150_000)
    assert all(s == p.State.FAILSAFE for t, s in states if t > 1_250_000)
    assert_centred(edges["D2"][edges["D2"][:, 0] > 2_000_000, 1])  # straight again


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
