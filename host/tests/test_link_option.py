"""``--link URI`` names the link of ``run``, ``campaign`` and ``robot``; ``--robot FILE`` is the
robot file in every command; the old spellings (``--robot URI``, ``--robot-file FILE``) still work
for one release, each with a deprecation message on stderr (docs/cli.md)."""

from __future__ import annotations

import pytest

from eelhost import cli
from eelhost.commands.common import OptionError
from eelhost.commands.link_options import is_link_uri, resolve_link_options

# the three commands that talk to a robot over a link, with what else each needs to parse
LINK_COMMANDS = {
    "run": ["run"],
    "campaign": ["campaign"],
    "robot": ["robot", "status"],
}
SIM = "sim://?speed=0"


def parsed(argv: list[str]):
    return cli.build_parser().parse_args(argv)


@pytest.mark.parametrize("command", LINK_COMMANDS)
def test_link_and_robot_file_are_told_apart_by_their_options(command, capsys):
    args = parsed([*LINK_COMMANDS[command], "--link", SIM, "--robot", "servo_robot.toml"])
    resolve_link_options(args)
    assert (args.link, args.robot_file) == (SIM, "servo_robot.toml")
    assert "deprecated" not in capsys.readouterr().err


@pytest.mark.parametrize("command", LINK_COMMANDS)
def test_the_old_robot_uri_spelling_still_names_the_link_and_says_it_is_deprecated(command,
                                                                                   capsys):
    args = parsed([*LINK_COMMANDS[command], "--robot", SIM, "--robot-file", "servo_robot.toml"])
    resolve_link_options(args)
    assert (args.link, args.robot_file) == (SIM, "servo_robot.toml")
    err = capsys.readouterr().err
    assert f"eelbot {command}: warning: --robot URI is deprecated" in err
    assert f"--link {SIM}" in err
    assert "--robot-file is deprecated" in err


@pytest.mark.parametrize("command", LINK_COMMANDS)
def test_a_link_given_both_ways_is_refused(command):
    args = parsed([*LINK_COMMANDS[command], "--robot", "sim://", "--link", SIM])
    with pytest.raises(OptionError, match="give the link once"):
        resolve_link_options(args)


def test_a_robot_file_given_both_ways_is_refused():
    args = parsed(["run", "--robot", "a.toml", "--robot-file", "b.toml"])
    with pytest.raises(OptionError, match="given twice"):
        resolve_link_options(args)


@pytest.mark.parametrize("value,link", [
    ("sim://", True), ("sim://?speed=0", True), ("serial:///dev/ttyUSB0?baud=57600", True),
    ("serial://COM3", True), ("replay:///tmp/run.rx.bin", True),
    ("servo_robot.toml", False), ("lab/robot.toml", False), ("/tmp/a:b/robot.toml", False),
    ("C:\\robots\\eel.toml", False),
])
def test_a_value_is_a_link_uri_only_with_a_scheme(value, link):
    assert is_link_uri(value) is link


def test_robot_status_over_the_old_spelling_answers_as_over_link_with_a_warning(capsys):
    assert cli.main(["robot", "status", "--link", SIM]) == 0
    new = capsys.readouterr()
    assert cli.main(["robot", "status", "--robot", SIM]) == 0
    old = capsys.readouterr()
    assert old.out == new.out
    assert "deprecated" not in new.err
    assert "eelbot robot: warning: --robot URI is deprecated" in old.err


def test_robot_reads_its_robot_file_and_names_a_missing_one(tmp_path, capsys):
    missing = tmp_path / "nowhere.toml"
    assert cli.main(["robot", "status", "--link", SIM, "--robot", str(missing)]) == 2
    assert "nowhere.toml" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["run", "--out", "x"], ["robot", "status"]])
def test_a_missing_link_is_a_usage_error_naming_link(argv, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "--link: required" in err and "sim://" in err


def test_run_over_link_swims_the_robot_file_given_and_keeps_a_copy_of_it(tmp_path, capsys):
    # a bundled robot by name (the working folder holds no such file): the take's copy is its text
    from importlib import resources

    stem = tmp_path / "take"
    assert cli.main(["run", "--link", SIM, "--robot", "servo_robot.toml", "--waypoints", "1,0",
                     "--gait", "0.87,3.9", "--no-view", "--camera", "synthetic:clean",
                     "--duration", "1", "--out", str(stem)]) == 0
    assert "deprecated" not in capsys.readouterr().err
    bundled = resources.files("eelsim.data").joinpath("servo_robot.toml").read_text()
    assert (tmp_path / "take.robot.toml").read_text() == bundled


@pytest.mark.parametrize("command", LINK_COMMANDS)
def test_a_transport_registered_later_is_in_the_link_help_and_message(command, monkeypatch,
                                                                      capsys):
    from eelhost.link import uri

    toy = uri.TransportScheme(name="toy", parameters=(), target="", open=lambda *a: None,
                              list_ports=list, example="toy://tank-3", description="a toy")
    monkeypatch.setattr(uri.TRANSPORTS, "_entries", dict(uri.TRANSPORTS._entries))
    uri.register_transport(toy)
    with pytest.raises(SystemExit):
        cli.main([*LINK_COMMANDS[command], "--help"])
    assert "toy://tank-3" in capsys.readouterr().out
    args = parsed(LINK_COMMANDS[command])
    with pytest.raises(OptionError, match="toy://tank-3"):
        resolve_link_options(args, required="here")
