"""``eelbot robot trim``'s answers to bad input and its exit status, and settings that persist over
``sim://?eeprom=FILE`` and come back lost over a blank EEPROM (docs/firmware.md, "Settings in the
EEPROM"; issue 29)."""

from __future__ import annotations

import io

from eelhost import cli
from eelhost.link.maintenance import Maintenance, RobotAnswerError
from eelhost.link.uri import open_link
from eelhost.wire import protocol


def eelbot(capsys, monkeypatch, *argv: str, stdin: str = "") -> tuple[int, str]:
    monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    rc = cli.main(list(argv))
    out, _ = capsys.readouterr()
    return rc, out


def test_a_trim_that_is_not_a_number_gets_a_clear_message_and_changes_nothing(capsys, monkeypatch):
    rc, out = eelbot(capsys, monkeypatch, "robot", "trim", "--link", "sim://?speed=0",
                     stdin="=abc\n+1.5\n-\nq\n")  # fmt: skip
    assert rc == 0
    assert "'=abc': the trim is a whole number of microseconds, not 'abc'" in out
    assert "'+1.5': the trim is a whole number of microseconds, not '+1.5'" in out
    assert "'-': the trim is a whole number of microseconds" in out
    assert "invalid literal" not in out  # Python's own words never reach the user
    assert "quit: trims put back, nothing saved" in out


def test_quitting_the_trim_dialogue_is_a_normal_end(capsys, monkeypatch):
    rc, out = eelbot(capsys, monkeypatch, "robot", "trim", "--link", "sim://?speed=0",
                     stdin="+20\nq\n")  # fmt: skip
    assert rc == 0 and "quit: trims put back" in out
    rc, out = eelbot(capsys, monkeypatch, "robot", "trim", "--link", "sim://?speed=0",
                     stdin="+20\n")  # end of input: also a quit
    assert rc == 0 and "quit: trims put back" in out


def test_settings_saved_over_sim_with_an_eeprom_file_are_there_in_the_next_invocation(
    capsys, monkeypatch, tmp_path
):
    uri = f"sim://?speed=0&eeprom={tmp_path / 'robot.eeprom'}"
    rc, _ = eelbot(capsys, monkeypatch, "robot", "trim", "--link", uri, stdin="+25\n\n-10\ns\n")
    assert rc == 0
    rc, out = eelbot(capsys, monkeypatch, "robot", "config", "--link", uri, "--get", "trim_us")
    assert rc == 0 and "trim_us = 25, -10, 0, 0, 0" in out
    rc, out = eelbot(capsys, monkeypatch, "robot", "config", "--link", "sim://?speed=0",
                     "--get", "trim_us")  # fmt: skip
    assert "trim_us = 0, 0, 0, 0, 0" in out  # without the file, a new robot


def test_a_blank_eeprom_refuses_start_until_the_host_takes_the_defaults(capsys, monkeypatch,
                                                                       tmp_path):  # fmt: skip
    blank = tmp_path / "blank.eeprom"
    blank.write_bytes(b"\xff" * 1024)
    uri = f"sim://?speed=0&eeprom={blank}"
    rc, out = eelbot(capsys, monkeypatch, "robot", "status", "--link", uri)
    assert "SETTINGS_LOST" in out and "BLANK" in out
    link = open_link(uri)
    session = Maintenance(link, timeout_s=2.0)
    session.hello()
    try:
        session.start()
        raise AssertionError("Start was accepted with the settings lost")
    except RobotAnswerError as err:
        assert "SETTINGS_LOST" in str(err)
    link.close()
    # `eelbot robot config --defaults --save` is the host's acknowledgement
    rc, out = eelbot(capsys, monkeypatch, "robot", "config", "--link", uri, "--defaults",
                     "--save", "--get", "battery_divider")  # fmt: skip
    assert rc == 0 and "battery_divider = 3.2" in out  # the low-voltage stop stays armed
    rc, out = eelbot(capsys, monkeypatch, "robot", "status", "--link", uri)
    assert "SETTINGS_LOST" not in out and "settings from: EEPROM" in out
    assert protocol.Flags.SETTINGS_LOST == 32
