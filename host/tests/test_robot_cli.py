"""``eelbot robot config | trim | status`` over sim:// (the native firmware behind the radio model),
through the real command line, and the maintenance session they are built on."""

from __future__ import annotations

import io

import numpy as np
import pytest

from eelhost import cli
from eelhost.commands.robot_trim import trim_session
from eelhost.link.base import Link
from eelhost.link.maintenance import (
    Maintenance,
    RobotAnswerError,
    SettingError,
    parse_assignment,
)
from eelhost.link.uri import open_link
from eelhost.wire import framing, protocol
from eelhost.xil.virtual_robot import VirtualRobot

SIM = "sim://?speed=0"


def eelbot(capsys, *argv: str, stdin: str | None = None, monkeypatch=None) -> tuple[int, str, str]:
    if stdin is not None:
        monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    rc = cli.main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def report(out: str) -> dict[str, str]:
    return dict(line.split(": ", 1) for line in out.splitlines() if ": " in line)


def sim_link(uri: str = SIM) -> tuple[Link, VirtualRobot]:
    link = open_link(uri)
    robot = link.transport.robot  # type: ignore[attr-defined]
    return link, robot


# ---------------------------------------------------------------- status
def test_status_of_a_fresh_robot_says_power_on_no_feedback_no_battery(capsys):
    rc, out, _ = eelbot(capsys, "robot", "status", "--link", SIM)
    assert rc == 0
    r = report(out)
    assert r["state"] == "IDLE"
    assert r["joint feedback"].startswith("none")
    assert r["battery"].startswith("not measured")
    assert r["reset cause"] == "POWER_ON; resets since power-on: 0"
    assert r["settings from"] == "EEPROM"  # the virtual robot comes set up, its settings saved
    for counter in ("bad_crc", "bad_crc32", "duplicates", "tx_dropped", "bad_direction"):
        assert r[counter] == "0"


def test_status_of_a_robot_with_feedback_servos_and_a_battery_divider_says_so(capsys):
    rc, out, _ = eelbot(capsys, "robot", "status", "--link", SIM + "&feedback=1&battery=7.4")
    assert rc == 0
    r = report(out)
    assert r["joint feedback"].startswith("analog feedback")
    volts = float(r["battery"].split()[0])
    assert volts == pytest.approx(7.4, abs=3.2 * 5 / 1023)  # one ADC count behind the divider
    assert r["settings from"] == "EEPROM"
    assert "JOINT_FEEDBACK" in r["flags"] and "BATTERY_SENSE" in r["flags"]


def test_the_link_knows_whether_the_robot_has_joint_feedback():
    for uri, expected in ((SIM, False), (SIM + "&feedback=1", True)):
        link, _ = sim_link(uri)
        assert link.joint_feedback is None  # nothing heard yet
        link.clock.wait_until(0.25)  # two telemetry periods
        link.poll()
        assert link.telemetry is not None
        assert link.joint_feedback is expected


def test_status_counters_equal_the_injected_faults():
    link, robot = sim_link(SIM + "&radio=ideal")
    fw = robot.firmware
    clock = link.clock
    session = Maintenance(link)
    # Resets first: a reset starts the counters afresh, the reset count goes on.
    clock.wait_until(0.05)
    for _ in range(2):
        fw.reboot(robot.now_us, protocol.ResetFlags.WATCHDOG)
    session.hello()
    write = link.transport.write

    def reframed(frame: bytes, change) -> bytes:
        raw = bytearray(framing.cobs_decode(frame[:-1]))
        change(raw)
        return framing.cobs_encode(bytes(raw)) + b"\x00"

    def fix_crc16(raw: bytearray) -> None:
        raw[-2:] = framing.crc16_ccitt_false(bytes(raw[:-2])).to_bytes(2, "little")

    def bad_crc32(raw: bytearray) -> None:
        raw[-3] ^= 0x5A  # inside the CRC-32, and the CRC-16 made to match
        fix_crc16(raw)

    def bad_crc16(raw: bytearray) -> None:
        raw[-1] ^= 0x01

    injected = {"bad_crc": 3, "bad_crc32": 2, "bad_direction": 4, "duplicates": 2}
    seq = 200
    for _ in range(injected["bad_crc"]):
        write(reframed(protocol.encode_frame(protocol.Stop(), seq), bad_crc16))
        seq += 1
    for _ in range(injected["bad_crc32"]):
        write(reframed(protocol.encode_frame(protocol.Stop(), seq), bad_crc32))
        seq += 1
    for _ in range(injected["bad_direction"]):  # an echo: a frame only the robot sends
        write(protocol.encode_frame(protocol.Telemetry(), seq))
        seq += 1
    stop = protocol.encode_frame(protocol.Stop(), seq)
    for _ in range(1 + injected["duplicates"]):  # a radio retry repeats the frame
        write(stop)
    # Dropped replies: the robot's UART stalls while it is asked for answers, between telemetry
    # frames (every 100 ms) and status frames (every 1 s), so only the answers drop.
    while link.telemetry is None or link.telemetry.time_us < 300_000:
        clock.wait_until(clock.now() + 0.005)
        link.poll()
    fw.set_uart_tx_stalled(True)
    hellos = 30
    for _ in range(hellos):
        link.send(protocol.Hello())
    clock.wait_until(clock.now() + 0.03)
    fw.set_uart_tx_stalled(False)
    clock.wait_until(clock.now() + 0.03)
    versions = sum(isinstance(m, protocol.Version) for m in link.poll())
    injected["tx_dropped"] = hellos - versions
    assert 0 < versions < hellos

    health = session.health()
    counters = health.counters()
    for name, count in injected.items():
        assert counters[name] == count, name
    assert counters["resets"] == 2
    assert health.status.reset_flags == protocol.ResetFlags.WATCHDOG
    for name in ("bad_cobs", "bad_short", "bad_oversize", "bad_schema", "bad_unknown_id"):
        assert counters[name] == 0, name
    # ... and eelbot robot status prints exactly these
    lines = report("\n".join(health.lines()))
    for name, count in injected.items():
        assert lines[name] == str(count)
    assert lines["reset cause"] == "WATCHDOG; resets since power-on: 2"


# ---------------------------------------------------------------- config
def test_config_sets_saves_and_reads_back_settings(capsys):
    rc, out, _ = eelbot(
        capsys, "robot", "config", "--link", SIM,
        "--set", "kp_nm_per_rad=2.5", "--set", "trim_us.2=-40", "--set", "reversed=0,1,0,0,1",
        "--save", "--get", "kp_nm_per_rad", "--get", "trim_us", "--get", "reversed",
    )  # fmt: skip
    assert rc == 0
    assert "settings saved to the EEPROM" in out
    assert "kp_nm_per_rad = 2.5" in out.splitlines()
    assert "trim_us = 0, -40, 0, 0, 0" in out.splitlines()
    assert "reversed = 0, 1, 0, 0, 1" in out.splitlines()


def test_config_without_options_prints_every_setting_at_its_default(capsys):
    rc, out, _ = eelbot(capsys, "robot", "config", "--link", SIM)
    assert rc == 0
    lines = out.splitlines()
    assert [line.split(" = ")[0] for line in lines] == list(protocol.SETTINGS)
    assert "trim_us = 0, 0, 0, 0, 0" in lines
    assert "joint_feedback = 0" in lines


@pytest.mark.parametrize(
    ("assignment", "named"),
    [
        ("nope=1", "no setting 'nope'"),
        ("trim_us.9=1", "joint 9 outside 1..5"),
        ("trim_us.2=600", "outside [-500, 500]"),
        ("kp_nm_per_rad.1=1", "one value, not one per joint"),
        ("trim_us=1,2", "takes 1 or 5 values"),
        ("kp_nm_per_rad=fast", "'fast' is not a number"),
        ("reversed.1=0.5", "a whole number"),
        ("kp_nm_per_rad", "expected NAME=VALUE"),
    ],
)
def test_config_rejects_a_bad_assignment_naming_what_is_wrong(capsys, assignment, named):
    rc, _, err = eelbot(capsys, "robot", "config", "--link", SIM, "--set", assignment)
    assert rc == 2
    assert named in err and assignment in err


def test_saved_settings_survive_a_power_cycle_and_unsaved_ones_do_not():
    link, robot = sim_link()
    session = Maintenance(link)
    session.hello()
    session.set("kd_nms_per_rad", 0, 0.05)
    session.save()
    session.set("kd_nms_per_rad", 0, 0.07)  # not saved
    assert session.get("kd_nms_per_rad") == [pytest.approx(0.07)]
    robot.firmware.reset(robot.now_us)
    session.hello()
    assert session.get("kd_nms_per_rad") == [pytest.approx(0.05)]
    assert session.health().status.settings_source == protocol.SettingsSource.EEPROM


def test_settings_are_refused_while_the_robot_undulates_with_the_reason():
    link, _ = sim_link()
    session = Maintenance(link)
    session.hello()
    link.send(protocol.Start(), want_ack=True)
    with pytest.raises(RobotAnswerError, match="not while it undulates"):
        session.set("kp_nm_per_rad", 0, 2.0)
    session.stop()
    session.set("kp_nm_per_rad", 0, 2.0)
    assert session.get("kp_nm_per_rad") == [2.0]


def test_parse_assignment_gives_one_element_per_joint():
    assert parse_assignment("trim_us=7") == [("trim_us", j, 7.0) for j in range(5)]
    assert parse_assignment("trim_us.5=-3") == [("trim_us", 4, -3.0)]
    assert parse_assignment("battery_low_v=6.8") == [("battery_low_v", 0, 6.8)]
    with pytest.raises(SettingError):
        parse_assignment("trim_us.0=1")  # joints are numbered from 1


# ---------------------------------------------------------------- trim
def test_trim_from_scripted_input_through_the_cli_saves_the_trims(capsys, monkeypatch):
    script = "+20\n-5\nn\n=-30\nbogus\nn\nn\nn\nn\n"
    rc, out, _ = eelbot(
        capsys, "robot", "trim", "--link", SIM, stdin=script, monkeypatch=monkeypatch
    )
    assert rc == 0
    assert "saved trims (us, joint 1 first): 15, -30, 0, 0, 0" in out
    assert "'bogus' is not a command" in out


def test_trim_moves_the_straight_pulses_and_survives_a_power_cycle():
    link, robot = sim_link()
    session = Maintenance(link)
    session.hello()
    lines = iter(["+12", "n", "-8", "n", "n", "n", "=3", "s"])
    said: list[str] = []
    saved = trim_session(session, lambda _prompt: next(lines), said.append)
    assert saved == [12, -8, 0, 0, 3]
    robot.firmware.reset(robot.now_us)
    out = robot.firmware.tick(robot.now_us + 10_000)
    np.testing.assert_array_equal(out.pulse_us, 1500 + np.array(saved))


def test_trim_quit_or_end_of_input_puts_the_trims_back_unsaved():
    link, robot = sim_link()
    session = Maintenance(link)
    session.hello()
    for script in (["+40", "n", "-40", "q"], ["+40", "n", "-40"]):
        lines = iter(script)
        said: list[str] = []
        assert trim_session(session, lambda _p, it=lines: next(it, None), said.append) is None
        assert "nothing saved" in said[-1]
        assert session.get("trim_us") == [0.0] * 5
