"""The command line: user errors give one line and exit 2, bugs keep their traceback; -v/-q."""

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


RUN = ["run", "--waypoints", "1,0", "--gait", "0.87,3.9", "--duration", "1"]


def one_line_error(capsys, *named: str) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("eelbot ") and "\n" not in err, err
    for part in named:
        assert part in err, err
    return err


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["run", "--robot", "tcp://robot:5760", *RUN[1:], "--out", "x"], ("unknown scheme",)),
        (["run", "--robot", "replay:///nowhere/run.rx.bin", *RUN[1:], "--out", "x"],
         ("/nowhere/run.rx.bin", "no such replay log")),
        (["run", "--robot", "serial:///dev/eelbot-no-such-port", *RUN[1:], "--out", "x"],
         ("/dev/eelbot-no-such-port", "cannot open")),
        (["run", "--robot", "sim://", "--waypoints", "1,0", "--gait", "2.0,3.9", "--out", "x"],
         ("--gait", "amplitude_rad")),
        (["run", "--robot", "sim://", *RUN[1:], "--camera", "take1.mp4", "--out", "x"],
         ("--calibration",)),
        (["run", "--robot", "sim://", "--waypoints", "1,0;2", "--gait", "0.87,3.9", "--out", "x"],
         ("--waypoints", "expected 2 numbers")),
        (["run", "--robot", "sim://", *RUN[1:], "--radius", "-1", "--out", "x"],
         ("--radius", "acceptance_radius_m")),
        (["simulate", "straight", "--coefficients=-1,0.7,0.6,0.01", "--out", "x"],
         ("--coefficients", "C_f")),
        (["simulate", "straight", "--gait", "0.8,-4", "--out", "x"], ("--gait", "omega_rad_s")),
        (["simulate", "straight", "--waypoints", "1,0;2", "--out", "x"], ("--waypoints",)),
        (["simulate", "straight", "--fps", "0", "--out", "x"], ("--fps", "fps must be positive")),
        (["validate", "nowhere/coefficients.json", "nowhere"], ("nowhere/coefficients.json",)),
        (["plan", "nowhere_world.toml"], ("nowhere_world.toml",)),
        (["dataset", "x", "--joints-from", "nowhere_robot.toml"],
         ("--joints-from", "nowhere_robot.toml")),
        (["dataset", "x", "--truth", "0.01,0.8"], ("--truth", "expected 4 numbers")),
        (["dataset", "x", "--fluid-law", "reynolds", "--truth", "1,1,5,0.6"],
         ("--truth", "C_f_lam", "expected 5 numbers")),
        (["estimate-bench", "--tanks", "bundled,nosuch", "--write", "-"],
         ("unknown tanks", "nosuch")),
    ],
)
def test_user_error_gives_one_line_naming_what_is_wrong_and_exit_2(argv, named, tmp_path, capsys):
    argv = [str(tmp_path / a) if a == "x" else a for a in argv]
    assert main(argv) == 2
    one_line_error(capsys, *named)


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
