"""A real robot on a serial port: `pytest hil_tests -m hardware --port /dev/ttyUSB0 [--rig FILE]`.

Skipped without a port (see conftest.py). The robot is sent Stop after every test, whatever
happened, and is never left undulating: the tests run the gait with amplitude 0.3 rad at most.
These tests use the wall clock (a real robot has its own), unlike the simulated ones.
"""

import time

import pytest

from eelhost.wire import protocol as p

pytestmark = pytest.mark.hardware

SAFE_GAIT = p.SetGait(0.3, 3.1416, 1.04, 0.5, 1.0, 2.0)


class RobotLink:
    """Frames over a serial port, with the sequence numbering the firmware expects."""

    def __init__(self, port):
        self.port = port
        self.reader = p.FrameReader()
        self.seq = 0
        self.inbox = []

    def send(self, message):
        seq = self.seq
        self.port.write(p.encode_frame(message, seq))
        self.port.flush()
        self.seq = (self.seq + 1) % 256
        return seq

    def poll(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            data = self.port.read(256)
            now = time.monotonic()
            self.inbox.extend((now, m) for _, m in self.reader.feed(data))

    def wait_for(self, predicate, timeout_s):
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for item in self.inbox:
                if predicate(item[1]):
                    self.inbox.remove(item)
                    return item[1]
            self.poll(0.05)
        return None

    def command(self, message, timeout_s):
        seq = self.send(message)
        ack = self.wait_for(
            lambda m: isinstance(m, p.Ack | p.Refuse) and m.seq == seq, timeout_s
        )
        assert ack is not None, f"no answer to {type(message).__name__} within {timeout_s} s"
        assert isinstance(ack, p.Ack), f"{type(message).__name__} refused: {ack}"
        return ack


@pytest.fixture
def link(rig):
    serial = pytest.importorskip("serial")
    try:
        port = serial.Serial(rig["port"], rig["baud"], timeout=0.02)
    except serial.SerialException as err:
        # no robot there: one line for the whole run, not a traceback per test
        pytest.exit(f"hardware tests: {err}; plug the robot in, or give its port with --port",
                    returncode=2)
    time.sleep(rig["boot_wait_s"])  # opening the port may reset the Nano
    port.reset_input_buffer()
    robot = RobotLink(port)
    try:
        yield robot
    finally:
        # Always leave the robot safe, twice in case the first frame is lost.
        for _ in range(2):
            robot.send(p.Stop())
            time.sleep(0.05)
        port.close()


def test_robot_answers_hello_with_its_version_and_our_schema(link, rig):
    link.send(p.Hello())
    version = link.wait_for(lambda m: isinstance(m, p.Version), rig["reply_timeout_s"])
    assert version is not None, "no Version within the reply timeout: check port, baud, power"
    assert version.schema_hash == p.SCHEMA_HASH
    assert version.n_joints == p.N_JOINTS
    assert version.protocol_version == p.PROTOCOL_VERSION


def test_robot_starts_and_stops_on_command(link, rig):
    timeout = rig["reply_timeout_s"]
    link.send(p.Hello())
    link.command(SAFE_GAIT, timeout)
    link.command(p.Start(), timeout)
    running = link.wait_for(
        lambda m: isinstance(m, p.Telemetry) and m.state == p.State.RUNNING, timeout
    )
    assert running is not None
    link.command(p.Stop(), timeout)
    idle = link.wait_for(lambda m: isinstance(m, p.Telemetry) and m.state == p.State.IDLE, timeout)
    assert idle is not None


def test_robot_sends_telemetry_at_its_rate(link, rig):
    link.inbox.clear()
    window_s = 3.0
    link.poll(window_s)
    count = sum(isinstance(m, p.Telemetry) for _, m in link.inbox)
    assert count == pytest.approx(
        rig["telemetry_hz"] * window_s, rel=rig["telemetry_rate_tolerance"]
    )


def test_robot_fails_safe_when_the_link_goes_silent(link, rig):
    timeout = rig["reply_timeout_s"]
    link.send(p.Hello())
    link.command(SAFE_GAIT, timeout)
    link.command(p.Start(), timeout)
    link.inbox.clear()
    link.poll(rig["failsafe_timeout_s"] + rig["failsafe_margin_s"])  # say nothing
    states = [m.state for _, m in link.inbox if isinstance(m, p.Telemetry)]
    assert p.State.FAILSAFE in states, f"telemetry states while silent: {states}"
