"""Link URIs, the framed link and its transports (sim, serial, replay)."""

from __future__ import annotations

import os
import pty
import select

import pytest

from eelhost.link import (
    Link,
    LinkURIError,
    Port,
    TransportError,
    list_ports,
    open_link,
    parse_link_uri,
    register_transport,
    uri,
)
from eelhost.link.replay_transport import ReplayTransport, RxLogWriter, read_rx_log
from eelhost.link.serial_transport import SerialTransport
from eelhost.link.uri import TransportScheme
from eelhost.wire import protocol


class ManualClock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def wait_until(self, t_s: float) -> None:
        self.t = max(self.t, t_s)


@pytest.mark.parametrize(
    ("uri", "named"),
    [
        ("tcp://robot:5760", "'tcp'"),
        ("/dev/ttyUSB0", "not a link URI"),
        ("serial://", "no port"),
        ("serial:///dev/ttyUSB0?baud=fast", "baud='fast'"),
        ("serial:///dev/ttyUSB0?baudrate=57600", "'baudrate'"),
        ("sim://?speed=-1", "speed=-1"),
        ("sim://?drop=3:2", "drop='3:2'"),
        ("sim://?radio=wifi", "radio='wifi'"),
        ("sim://?start=1,2", "start='1,2'"),
        ("sim://?coefficients=0.01,0.8,0.6", "coefficients='0.01,0.8,0.6'.*C_f, C_d, C_a, C_m"),
        ("sim://?coefficients=0.01,-0.8,0.6,0.01", "coefficients='0.01,-0.8,0.6,0.01'"),
        ("replay://", "no log file path"),
    ],
)
def test_bad_uri_error_names_the_bad_part(uri: str, named: str) -> None:
    with pytest.raises(LinkURIError, match=named.replace("?", r"\?")):
        open_link(uri)


def test_serial_uri_gives_port_and_baud() -> None:
    u = parse_link_uri("serial:///dev/ttyUSB0?baud=57600")
    assert (u.scheme, u.target, u.number("baud", 0, int)) == ("serial", "/dev/ttyUSB0", 57600)


def test_virtual_robot_acknowledges_start_and_reports_running() -> None:
    link = open_link("sim://?speed=0&seed=3")
    seq = link.send(protocol.Start(), want_ack=True)
    for k in range(1, 51):
        link.clock.wait_until(k * 0.01)
        link.poll()
    assert link.outcome(seq) == "ack"
    assert link.telemetry is not None and link.telemetry.state == protocol.State.RUNNING
    assert link.counters.bad_frames == {}


def test_unacknowledged_command_is_resent_then_reported_lost(tmp_path) -> None:
    clock = ManualClock()
    log = tmp_path / "silent.rx.bin"
    writer = RxLogWriter(log)
    writer(0.0, b"")  # a robot that never answers
    writer(100.0, b"")
    writer.close()
    link = Link(ReplayTransport(log, clock.now), clock, resend_after_s=0.2, max_attempts=3)
    link.open()
    seq = link.send(protocol.Start(), want_ack=True)
    for k in range(1, 11):
        clock.wait_until(k * 0.1)
        link.poll()
    assert link.outcome(seq) == "lost"
    assert (link.counters.resends, link.counters.lost) == (2, 1)


def test_replay_gives_back_recorded_frames_and_then_goes_silent(tmp_path) -> None:
    clock = ManualClock()
    path = tmp_path / "run.rx.bin"
    writer = RxLogWriter(path)
    tele = protocol.Telemetry(time_us=5, state=int(protocol.State.RUNNING))
    writer(10.0, protocol.encode_frame(tele, 0))
    writer(10.5, protocol.encode_frame(protocol.Ack(protocol.MsgId.START, 7), 1) + b"\x01\x02")
    writer.close()
    with open(path, "ab") as f:
        f.write(b"\x00\x01\x02")  # a record cut by a crash
    assert len(read_rx_log(path)) == 2
    link = open_link(f"replay://{path}", clock=clock)
    got = link.poll()
    clock.wait_until(0.6)
    got += link.poll()
    assert got == [tele, protocol.Ack(protocol.MsgId.START, 7)]
    assert not link.transport.is_connected
    with pytest.raises(TransportError):
        link.transport.open()


def test_serial_loopback_carries_frames() -> None:
    link = Link(SerialTransport("loop://", 57600), ManualClock())
    link.open()
    link.send(protocol.SetOffset(0.25))
    assert link.poll() == [protocol.SetOffset(0.25)]


def test_serial_port_that_comes_back_is_reconnected(tmp_path) -> None:
    master, slave = pty.openpty()
    port = tmp_path / "ttyXBEE"
    clock = ManualClock()
    link = Link(SerialTransport(str(port)), clock, reconnect_every_s=0.25)
    with pytest.raises(TransportError):
        link.open()  # the adapter is not plugged in
    assert link.send(protocol.Stop()) >= 0 and link.counters.not_sent == 1
    os.symlink(os.ttyname(slave), port)  # plugged in
    clock.wait_until(1.0)
    link.poll()
    assert link.transport.is_connected and link.counters.reconnects == 1
    os.write(master, protocol.encode_frame(protocol.Telemetry(state=1), 3))
    # the pty hands the bytes over asynchronously: wait (bounded) until they are readable
    assert select.select([slave], [], [], 5.0)[0], "the pty never delivered the frame"
    clock.wait_until(1.1)
    assert isinstance(link.poll()[0], protocol.Telemetry)
    link.close()
    os.close(master)
    os.close(slave)


def test_a_registered_transport_opens_by_its_scheme_and_lists_its_ports(monkeypatch) -> None:
    monkeypatch.setattr(uri.TRANSPORTS, "_entries", dict(uri.TRANSPORTS._entries))  # ends with the test

    def open_loopback(u, robot, clock):
        return Link(SerialTransport("loop://"), clock or ManualClock())

    register_transport(
        TransportScheme(
            "loopback", ("delay",), "", open_loopback,
            lambda: [Port("loopback://", "bytes come back")], "loopback://",
            description="bytes sent come back",
        )
    )
    link = open_link("loopback://?delay=0")
    link.send(protocol.SetOffset(0.25))
    assert link.poll() == [protocol.SetOffset(0.25)]
    assert Port("loopback://", "bytes come back") in list_ports()
    assert Port("sim://", uri.transport_schemes()["sim"].list_ports()[0].description) in list_ports()
    with pytest.raises(LinkURIError, match="'speed' for loopback://"):
        parse_link_uri("loopback://?speed=1")
