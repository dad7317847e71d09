"""``eelbot campaign`` against ``sim://`` at reduced size, and the lab's whole sequence.

The lab's sequence is read from docs/host.md ("The day without hardware": markers -> calibrate on a
synthetic frame -> check it -> campaign -> estimate -> validate) and run through the eelbot command,
with a plan of two gaits of one motion, short takes and a small fitting budget.
"""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import time
import tomllib
import urllib.request
from pathlib import Path

import pytest

from eelhost.cli import main
from eelhost.data.experiments import load_dataset
from eelhost.field.campaign import load_plan, plan_takes

DOCS = Path(__file__).resolve().parents[2] / "docs" / "host.md"

PLAN = """
name = "reduced"
motions = ["straight"]
amplitudes_rad = [0.61, 0.87]
omegas_rad_s = [3.9]
train = [[0.87, 3.9]]
duration_s = {duration}
"""


def _plan(tmp_path, duration=4.0):
    path = tmp_path / "plan.toml"
    path.write_text(PLAN.format(duration=duration))
    return path


def test_the_paper_protocol_is_the_default_plan():
    takes = plan_takes(load_plan(None))
    assert len(takes) == 32
    train = sorted(t.name for t in takes if t.split == "train")
    assert train == sorted(f"{m}_A{a}_w{w}" for m in ("straight", "turning")
                           for a in ("0.61", "0.87") for w in ("2.7", "3.9"))
    turning = next(t for t in takes if t.motion == "turning")
    assert turning.waypoint_m == pytest.approx((1.4 * 0.8660254, 0.7)) and turning.k_theta == 0.37


def test_a_bad_plan_is_refused_naming_the_key(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text('motions = ["sideways"]\n')
    assert main(["campaign", str(path), "--link", "sim://", "--out", str(tmp_path / "d")]) == 2
    assert "bad.toml: motions: Value error, motion 'sideways'" in capsys.readouterr().err


def test_the_written_plan_reads_back_as_the_same_plan(tmp_path, capsys):
    written = tmp_path / "plan.toml"
    assert main(["campaign", "--write-plan", str(written)]) == 0  # no robot needed to write it
    assert plan_takes(load_plan(written)) == plan_takes(load_plan(None))  # the same takes
    edited = written.read_text().replace("repeats = 1", "repeats = 2")
    written.write_text(edited)
    assert len(plan_takes(load_plan(written))) == 64
    assert main(["campaign", str(written), "--out", str(tmp_path / "d")]) == 2
    assert "--link: required to run a campaign" in capsys.readouterr().err


def _stand_in_take(ran: list[str]):
    """A stand-in for run_take that writes a finished take (no robot or camera needed)."""
    from eelhost.field.runloop import RunOutcome
    from eelhost.field.take import TakeResult

    def run_take(request, open_view=None, announce=None, stop_flag=None):
        ran.append(request.out)
        meta = {"source": {"recording": {"complete": True, "reason": "arrived"}}}
        Path(f"{request.out}.json").write_text(json.dumps(meta))
        Path(f"{request.out}.csv").write_text("t_s,x_m,y_m\n")
        return TakeResult(RunOutcome(reason="arrived", stop_outcome="ack"), [], 0.0, False, [])

    return run_take


def test_a_real_robots_campaign_rests_and_asks_for_a_reset_between_takes(tmp_path, monkeypatch,
                                                                        capsys):
    import eelhost.commands.campaign as campaign

    ran: list[str] = []
    prompts: list[str] = []
    rests: list[float] = []
    monkeypatch.setattr(campaign, "run_take", _stand_in_take(ran))
    monkeypatch.setattr(campaign, "_wait_rest", lambda seconds, stopped: rests.append(seconds))
    monkeypatch.setattr("builtins.input", lambda text: prompts.append(text) or "")
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN.format(duration=5.0) + "rest_s = 45.0\nstart = [0.3, 0.2, 10.0]\n")
    argv = ["campaign", str(plan), "--link", "serial:///dev/ttyUSB9", "--camera", "0",
            "--out", str(tmp_path / "ds"), "--no-view"]
    assert main(argv) == 0
    assert [Path(p).name for p in ran] == ["straight_A0.61_w3.9", "straight_A0.87_w3.9"]
    # Before the second take only: the plan's rest, then the operator puts the robot back.
    assert rests == [45.0]
    assert prompts == ["put the robot at x 0.3 m, y 0.2 m, heading 10 deg, still, then press "
                       "Enter: "]
    assert "2/2 takes done" in capsys.readouterr().out


def test_a_campaign_without_a_terminal_to_ask_stops_naming_no_prompt(tmp_path, monkeypatch,
                                                                     capsys):
    import eelhost.commands.campaign as campaign

    ran: list[str] = []
    monkeypatch.setattr(campaign, "run_take", _stand_in_take(ran))

    def no_terminal(_text: str) -> str:
        raise EOFError

    monkeypatch.setattr("builtins.input", no_terminal)
    argv = ["campaign", str(_plan(tmp_path)), "--link", "serial:///dev/ttyUSB9", "--camera",
            "0", "--out", str(tmp_path / "ds"), "--no-view", "--rest", "0"]
    assert main(argv) == 2
    assert "run it in a terminal, or --no-prompt" in capsys.readouterr().err
    assert len(ran) == 1
    assert main([*argv, "--no-prompt"]) == 0  # resumes with the second take, asking nothing
    assert len(ran) == 2


@pytest.mark.slow
def test_campaign_resumes_after_a_kill_skipping_finished_takes_and_redoing_the_partial_one(tmp_path):
    plan, out = _plan(tmp_path, duration=3.0), tmp_path / "ds"
    cmd = [sys.executable, "-m", "eelhost", "campaign", str(plan), "--link", "sim://?speed=1",
           "--camera", "synthetic:clean", "--out", str(out), "--no-view"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # Killed (no cleanup at all) once the second take has recorded a few frames.
        deadline = time.monotonic() + 120
        second = out / "straight_A0.87_w3.9.csv"
        while not (second.exists() and second.read_text().count("\n") > 10):
            assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    partial = json.loads((out / "straight_A0.87_w3.9.json").read_text())
    assert partial["source"]["recording"]["complete"] is False
    manifest = tomllib.loads((out / "manifest.toml").read_text())
    assert manifest["motions"]["straight"] == {"train": [], "test": ["straight_A0.61_w3.9"]}
    first_csv = (out / "straight_A0.61_w3.9.csv").read_text()

    done = subprocess.run([*cmd[:6], "sim://?speed=0", *cmd[7:]], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[1] == "[1/2] straight_A0.61_w3.9: done earlier, skipped"
    assert lines[2].startswith("[2/2] straight_A0.87_w3.9: duration at 3.0 s (train)")
    assert (out / "straight_A0.61_w3.9.csv").read_text() == first_csv
    ds = load_dataset(out)  # loads directly, no incomplete recording left
    assert [e.name for e in ds.train["straight"]] == ["straight_A0.87_w3.9"]
    assert [e.name for e in ds.test["straight"]] == ["straight_A0.61_w3.9"]
    redone = ds.train["straight"][0]
    assert redone.source["recording"]["complete"] is True
    assert redone.source["run"]["campaign"] == {"plan": "reduced", "take": "straight_A0.87_w3.9",
                                                "split": "train", "repeat": 1}


@pytest.mark.slow
def test_campaign_serves_the_live_view_and_stops_cleanly_on_sigterm(tmp_path):
    plan, out = _plan(tmp_path, duration=30.0), tmp_path / "ds"
    proc = subprocess.Popen(
        [sys.executable, "-m", "eelhost", "campaign", str(plan), "--link", "sim://?speed=1",
         "--camera", "synthetic:clean", "--out", str(out), "--view-port", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        lines = [proc.stdout.readline(), proc.stdout.readline()]
        assert lines[1].startswith("live view: http://127.0.0.1:"), (lines, proc.poll())
        address = lines[1].split(": ", 1)[1].strip()  # the page, with the session's token
        url = address.split("?", 1)[0]
        # the page sets the token's cookie, which the page's own requests then carry
        browser = urllib.request.build_opener(urllib.request.HTTPCookieProcessor())
        page = browser.open(address, timeout=10).read().decode()
        assert 'id="frame"' in page
        # Poll the overlay until the robot is seen swimming and the twin's prediction is drawn.
        deadline = time.monotonic() + 120
        while True:
            state = json.loads(browser.open(url + "state.json", timeout=10).read())
            if len(state["markers"]) == 6 and state["predicted"] and len(state["track"]) > 5:
                break
            assert time.monotonic() < deadline and proc.poll() is None, state
            time.sleep(0.2)
        assert [len(w["circle"]) for w in state["waypoints"]] == [48]
        assert not state["waypoints"][0]["reached"]
        jpeg = browser.open(url + "frame.jpg", timeout=10).read()
        assert jpeg[:2] == b"\xff\xd8"
        os.kill(proc.pid, signal.SIGTERM)
        rest, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1, err  # not every take done
    assert "stopped by SIGTERM: run the same command to go on" in rest
    first = json.loads((out / "straight_A0.61_w3.9.json").read_text())["source"]["recording"]
    assert first["complete"] is True and first["reason"] == "interrupted" and first["stop"] == "ack"
    assert not (out / "straight_A0.87_w3.9.json").exists()  # the campaign went no further
    manifest = tomllib.loads((out / "manifest.toml").read_text())
    assert not manifest.get("motions")  # an interrupted take is not done: the next run redoes it


def documented_sequence() -> list[list[str]]:
    """The commands of docs/host.md's "The day without hardware", one argv each."""
    text = DOCS.read_text()
    section = text.split("## The day without hardware", 1)[1]
    block = section.split("```bash\n", 1)[1].split("```", 1)[0]
    return [shlex.split(line) for line in block.replace("\\\n", " ").splitlines() if line.strip()]


@pytest.mark.slow
def test_the_documented_lab_sequence_gives_a_validation_report(tmp_path):
    sequence = documented_sequence()
    assert [argv[1] for argv in sequence] == ["markers", "calibrate", "calibrate", "campaign",
                                              "estimate", "validate"]
    script = Path(sys.executable).with_name("eelbot")
    eelbot = [str(script)] if script.exists() else [sys.executable, "-m", "eelhost"]
    plan = _plan(tmp_path, duration=6.0)
    printed = []
    for argv in sequence:
        assert argv[0] == ".venv/bin/eelbot"
        args = argv[1:]
        # Reduced size: two straight takes of at most 6 s, and a small fitting budget.
        if args[0] == "campaign":
            args = ["campaign", str(plan), *args[1:]]
        if args[0] == "estimate":
            args += ["--motion", "straight", "--budget", "60"]
        done = subprocess.run([*eelbot, *args], cwd=tmp_path, capture_output=True, text=True,
                              timeout=600)
        assert done.returncode == 0, (args, done.stdout, done.stderr)
        printed.append(done.stdout)
    lab = tmp_path / "lab"
    assert {p.name for p in lab.iterdir()} >= {"markers.pdf", "charuco.pdf", "markers.json",
                                               "calibration.json", "board.png"}
    assert "reprojection rms" in printed[1] and "on this frame: rms" in printed[2]
    assert "2/2 takes done" in printed[3]
    ds = load_dataset(lab / "campaign")
    assert [e.name for e in ds.train["straight"]] == ["straight_A0.87_w3.9"]
    assert all(e.source["run"]["calibration_copy"] for e in ds.train["straight"])
    assert (lab / "fit" / "coefficients.json").exists()
    table = (lab / "validation" / "table4.md").read_text()
    assert "straight_A0.61_w3.9" in table  # the test take
    assert (lab / "validation" / "paths_straight.png").stat().st_size > 0
