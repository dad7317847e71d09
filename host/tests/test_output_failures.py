"""Outputs that cannot be written end with one line, and every output is written whole.

A read-only folder, a full disk, ``--out`` naming a file and a closed or full stdout are the user's
situation, not bugs: each gives ``eelbot CMD: error: ...`` on one line and exit status 2, and what
was written before is still there (docs/cli.md, "Outputs"). The read-only folder and the full disk
are made by making the file system calls fail as those would (the suite may run as root, whom
permissions do not stop); stdout is a real /dev/full and a real closed descriptor.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from eelhost import cli
from eelsim import files as sim_files

ENV = {**os.environ, "PYTHONWARNINGS": "ignore"}


def one_line_error(err: str, command: str) -> str:
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"eelbot {command}: error:"), err
    assert "Traceback" not in err
    return lines[0]


def test_a_full_stdout_gives_one_line_and_status_2():
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "eelhost", "ports"], stdout=full,
                              stderr=subprocess.PIPE, text=True, check=False, env=ENV, timeout=120)
    assert proc.returncode == 2
    assert "cannot write stdout" in one_line_error(proc.stderr, "ports")


def test_a_closed_stdout_gives_one_line_and_status_2():
    proc = subprocess.run([sys.executable, "-m", "eelhost", "ports"], stderr=subprocess.PIPE,
                          text=True, check=False, env=ENV, timeout=120,
                          preexec_fn=lambda: os.close(1))
    assert proc.returncode == 2
    assert "stdout is closed" in one_line_error(proc.stderr, "ports")


# Each output command with --out (or its output argument) naming an existing file.
OUT_IS_A_FILE = {
    "simulate": "simulate straight --duration 1 --out {file}/run",
    "markers": "markers --out {file}",
    "validate": "validate 0.008,0.776,0.618,0.007 {tmp}/nowhere --out {file}",
    "plan": "plan tank_5_obstacles --out {file}",
    "run": "run --link sim:// --waypoints 1,0 --gait 0.87,3.9 --no-view --out {file}/take",
    "dataset": "dataset {file}",
    "campaign": "campaign --link sim:// --out {file}",
    "campaign --write-plan": "campaign --write-plan {tmp}",
    "estimate": "estimate {tmp}/nowhere --out {file}",
    "report": "report --out {file}",
    "track": "track {tmp} --calibration c.json --markers m.json --gait 0.8,3 --out {file}/x",
    "export": "export {tmp}/take --mcap --out {file}/take.mcap",
}


@pytest.mark.parametrize("command", list(OUT_IS_A_FILE))
def test_out_naming_a_file_or_folder_is_said_on_one_line_before_any_work(command, tmp_path, capsys):
    file = tmp_path / "a_file"
    file.write_text("keep me")
    argv = OUT_IS_A_FILE[command].format(file=file, tmp=tmp_path).split()
    assert cli.main(argv) == 2
    line = one_line_error(capsys.readouterr().err, command.split()[0])
    assert str(file if "write-plan" not in command else tmp_path) in line
    assert file.read_text() == "keep me"


@pytest.fixture
def read_only(monkeypatch, tmp_path):
    """A folder in which creating a file fails as on a read-only file system."""
    folder = tmp_path / "readonly"
    folder.mkdir()
    real = tempfile.mkstemp

    def mkstemp(*args, **kwargs):
        if Path(kwargs.get("dir", "")).resolve().is_relative_to(folder.resolve()):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(kwargs["dir"]))
        return real(*args, **kwargs)

    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    return folder


READ_ONLY = {
    "simulate": "simulate straight --duration 1 --out {ro}/run",
    "markers": "markers --out {ro}/lab",
    "validate": "validate 0.008,0.776,0.618,0.007 {tmp}/nowhere --out {ro}/validate",
    "plan": "plan tank_5_obstacles --out {ro}/plan",
    "run": "run --link sim:// --waypoints 1,0 --gait 0.87,3.9 --no-view --out {ro}/take",
    "dataset": "dataset {ro}/tank",
    "campaign": "campaign --link sim:// --out {ro}/campaign",
    "campaign --write-plan": "campaign --write-plan {ro}/plan.toml",
    "estimate": "estimate {tmp}/nowhere --out {ro}/fit",
    "report": "report --out {ro}/report",
}


@pytest.mark.parametrize("command", list(READ_ONLY))
def test_a_read_only_folder_is_said_on_one_line(command, read_only, tmp_path, capsys):
    argv = READ_ONLY[command].format(ro=read_only, tmp=tmp_path).split()
    assert cli.main(argv) == 2
    line = one_line_error(capsys.readouterr().err, command.split()[0])
    assert str(read_only) in line and "read-only" in line


class _FullDisk:
    """A file whose writes fail with ENOSPC after ``room`` bytes, as on a full disk."""

    def __init__(self, f, room: int) -> None:
        self._f, self._room = f, room

    def write(self, data):
        self._room -= len(data)
        if self._room < 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return self._f.__exit__(*exc)


def test_a_full_disk_keeps_the_earlier_run_and_leaves_no_part_file(monkeypatch, tmp_path, capsys):
    stem = tmp_path / "run"
    assert cli.main(["simulate", "straight", "--duration", "1", "--out", str(stem)]) == 3
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert set(before) == {"run.csv", "run.json"}
    real = os.fdopen
    monkeypatch.setattr(sim_files.os, "fdopen", lambda *a, **k: _FullDisk(real(*a, **k), 2000))
    capsys.readouterr()
    status = cli.main(["simulate", "straight", "--duration", "2", "--out", str(stem)])
    assert status == 2
    line = one_line_error(capsys.readouterr().err, "simulate")
    assert f"cannot write {stem}.csv" in line and "disk is full" in line
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before  # no cut CSV, no .tmp


def test_campaign_write_plan_keeps_an_edited_plan_unless_forced(tmp_path, capsys):
    plan = tmp_path / "plan.toml"
    assert cli.main(["campaign", "--write-plan", str(plan)]) == 0
    plan.write_text(plan.read_text() + "# edited\n")
    assert cli.main(["campaign", "--write-plan", str(plan)]) == 2
    line = one_line_error(capsys.readouterr().err, "campaign")
    assert str(plan) in line and "--force" in line
    assert plan.read_text().endswith("# edited\n")
    assert cli.main(["campaign", "--write-plan", str(plan), "--force"]) == 0
    assert "# edited" not in plan.read_text()


def test_the_hardware_tests_without_a_robot_say_so_in_one_line():
    repo = Path(__file__).resolve().parents[2]
    port = "/dev/eelbot-no-robot-here"
    proc = subprocess.run([sys.executable, "-m", "pytest", "hil_tests", "-m", "hardware",
                           "--port", port, "-q", "-p", "no:cacheprovider"], cwd=repo,
                          capture_output=True, text=True, check=False, env=ENV, timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert "hardware tests:" in out and f"could not open port {port}" in out
    assert "plug the robot in" in out
    assert "Traceback" not in out and "SerialException" not in out and len(out) < 1000


FULL_DISK = {
    "markers": ("markers --out {tmp}/lab", "markers.pdf"),
    "campaign --write-plan": ("campaign --write-plan {tmp}/lab/plan.toml", "plan.toml"),
}


@pytest.mark.parametrize("command", list(FULL_DISK))
def test_a_disk_that_fills_up_gives_one_line_and_no_part_file(command, monkeypatch, tmp_path,
                                                             capsys):
    line, first_file = FULL_DISK[command]
    real = os.fdopen
    monkeypatch.setattr(sim_files.os, "fdopen", lambda *a, **k: _FullDisk(real(*a, **k), 100))
    assert cli.main(line.format(tmp=tmp_path).split()) == 2
    message = one_line_error(capsys.readouterr().err, command.split()[0])
    assert first_file in message and "disk is full" in message
    assert not [p for p in tmp_path.rglob("*") if p.is_file()]  # no part file, no temporary
