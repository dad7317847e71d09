"""The command line: bugs keep their traceback; -v/-q; help shows defaults; negative values."""

from __future__ import annotations

import logging
import subprocess
import sys

import pytest

from eelhost import cli
from eelhost.cli import main
from eelhost.commands import speeds


@pytest.fixture(autouse=True)
def keep_the_root_loggers_level():
    level = logging.getLogger().level
    yield
    logging.getLogger().setLevel(level)


# The table of bad inputs and their messages is the probe suite (test_probe_suite.py).


def test_a_bug_is_not_taken_for_a_user_error(monkeypatch):
    def broken(args):
        raise ValueError("an internal inconsistency")

    monkeypatch.setattr(speeds, "run", broken)
    with pytest.raises(ValueError, match="internal inconsistency"):
        main(["speeds"])


def test_verbose_and_quiet_set_the_level_of_the_librarys_logging():
    assert cli.log_level(0, 0) == logging.WARNING
    assert cli.log_level(1, 0) == logging.INFO
    assert cli.log_level(2, 0) == cli.log_level(5, 0) == logging.DEBUG
    assert cli.log_level(0, 1) == cli.log_level(0, 3) == logging.ERROR


def test_ports_lists_the_virtual_robot_and_the_schemes(capsys):
    assert main(["-q", "ports"]) == 0
    out = capsys.readouterr().out
    assert "sim://\t" in out and "serial://" in out and "replay://" in out
    assert logging.getLogger().level == logging.ERROR


def test_python_m_eelhost_runs_the_command_line():
    proc = subprocess.run(
        [sys.executable, "-m", "eelhost", "--help"], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 0 and "simulate" in proc.stdout and "-v" in proc.stdout


def test_every_option_of_every_command_has_help_and_shows_its_default():
    parser = cli.build_parser()
    commands = parser._subparsers._group_actions[0].choices  # the registered subcommands
    for name, sub in commands.items():
        for action in sub._actions:
            if not action.option_strings or action.dest == "help":
                continue
            assert action.help, f"eelbot {name} {action.option_strings[0]} has no help"
            if action.default not in (None, False):
                shown = sub.formatter_class(prog="x")._get_help_string(action) % vars(action)
                assert str(action.default) in shown, f"eelbot {name} {action.option_strings[0]}"


def test_top_level_help_lists_the_exit_statuses(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    assert "exit status:" in out and "ILL_CONDITIONED" in out and "--progress" in out


@pytest.mark.parametrize(
    ("argv", "joined"),
    [
        (["--gait", "-0.6,2.7"], ["--gait=-0.6,2.7"]),
        (["--current", "-0.02,0"], ["--current=-0.02,0"]),
        (["--waypoints", "-0.5,0.2;1,0"], ["--waypoints=-0.5,0.2;1,0"]),
        (["--k-theta", "-.5", "--dt", "0.01"], ["--k-theta=-.5", "--dt", "0.01"]),
        (["--gait=-0.6,2.7"], ["--gait=-0.6,2.7"]),
        (["-v", "simulate"], ["-v", "simulate"]),
        (["--full", "-q"], ["--full", "-q"]),
    ],
)
def test_negative_numbers_after_an_option_are_its_value(argv, joined):
    assert cli.join_negative_values(argv) == joined


def test_a_negative_waypoint_reaches_the_scenario(tmp_path):
    stem = tmp_path / "r"
    main(["simulate", "straight", "--waypoints", "-0.5,0.2", "--duration", "1", "--out", str(stem)])
    assert '"waypoints_m": [\n      [\n        -0.5,' in stem.with_suffix(".json").read_text()


def test_ctrl_c_ends_with_a_line_and_status_130(monkeypatch, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(speeds, "run", interrupted)
    assert main(["speeds"]) == 130
    assert capsys.readouterr().err.strip() == "eelbot speeds: interrupted"
