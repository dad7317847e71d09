"""Progress fits where it goes: bars on a terminal, timestamped lines in a log, nothing if asked."""

from __future__ import annotations

import io
import re

import pytest

from eelhost import progress
from eelhost.cli import main
from eelhost.progress import Progress

PLAIN_LINE = re.compile(r"^\d\d:\d\d:\d\d .+: (at|done|stopped at) \d+(/\d+)? \w+")


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture(autouse=True)
def back_to_auto():
    yield
    progress.set_mode("auto")


def test_auto_is_a_bar_on_a_terminal_and_plain_lines_elsewhere():
    progress.set_mode("auto")
    assert progress.mode(Terminal()) == "bar"
    assert progress.mode(io.StringIO()) == "plain"
    progress.set_mode("none")
    assert progress.mode(Terminal()) == "none"
    with pytest.raises(ValueError, match="progress mode"):
        progress.set_mode("sometimes")


def test_plain_progress_writes_timestamped_lines_without_escape_codes():
    progress.set_mode("plain")
    log = io.StringIO()
    with Progress("fit straight", 3, "gen", interval_s=0.0, stream=log) as bar:
        for gen in range(1, 4):
            bar.set_postfix(best="0.12")
            bar.set(gen)
    lines = log.getvalue().splitlines()
    assert lines and all(PLAIN_LINE.match(line) for line in lines), lines
    assert "\r" not in log.getvalue() and "\x1b" not in log.getvalue()
    assert lines[-1].split(" ", 1)[1].startswith("fit straight: done 3/3 gen (100 %), best 0.12")


def test_plain_progress_of_a_short_task_leaves_no_line_and_a_failed_one_says_so():
    progress.set_mode("plain")
    log = io.StringIO()
    with Progress("quick", 2, stream=log) as bar:
        bar.set(2)
    assert log.getvalue() == ""
    with pytest.raises(RuntimeError), Progress("fit", 5, "gen", interval_s=0.0, stream=log) as bar:
        bar.set(2)
        raise RuntimeError
    assert "fit: stopped at 2/5 gen" in log.getvalue()


def test_bar_is_redrawn_in_place_and_none_writes_nothing():
    progress.set_mode("bar")
    screen = Terminal()
    with Progress("virtual tank", 4, "experiment", stream=screen) as bar:
        bar.update(2)
        bar.finish()
    assert "\r" in screen.getvalue() and "4/4" in screen.getvalue()
    progress.set_mode("none")
    quiet = io.StringIO()
    with Progress("virtual tank", 4, stream=quiet) as bar:
        bar.update(4)
    assert quiet.getvalue() == ""


def test_simulate_progress_completes_when_the_goal_is_reached(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(progress, "PLAIN_INTERVAL_S", 0.0)
    assert main(["--progress", "plain", "simulate", "turning", "--out", str(tmp_path / "r")]) == 0
    out, err = capsys.readouterr()
    assert "reached the last waypoint" in out
    last = err.strip().splitlines()[-1]
    assert "turning: done" in last and "(100 %)" in last, err


def test_speeds_shows_progress_per_gait_and_says_when_no_gait_swam(capsys, monkeypatch):
    monkeypatch.setattr(progress, "PLAIN_INTERVAL_S", 0.0)
    assert main(["--progress", "plain", "speeds", "--duration", "0.5"]) == 0
    out, err = capsys.readouterr()
    assert "gait grid: at 1/16 gait" in err and "gait grid: done 16/16 gait (100 %)" in err
    assert "no gait swam forward steadily within 0.5 s" in out  # 0.5 s is too short to tell


def test_lines_printed_during_a_bar_start_a_line_of_their_own(monkeypatch):
    screen = Terminal()  # stdout and stderr on one terminal, as a user sees them
    monkeypatch.setattr("sys.stdout", screen)
    monkeypatch.setattr("sys.stderr", screen)
    progress.set_mode("bar")
    with progress.console(), Progress("fit straight", 3, "gen") as bar:
        bar.update(1)
        print("straight: fitness 0.0123")
        bar.update(1)
    text = screen.getvalue()
    before = text[: text.index("straight: fitness")]
    assert before.endswith(("\r", "\n")) and "straight: fitness 0.0123\n" in text
    assert text.endswith("\n")  # a closed bar leaves the line to what comes next


def test_a_phase_without_counts_still_says_every_few_seconds_how_long_it_has_taken(monkeypatch):
    import io
    import time as _time

    from eelhost import progress as prog

    monkeypatch.setattr(prog, "PLAIN_INTERVAL_S", 0.2)
    prog.set_mode("plain")
    stream = io.StringIO()
    monkeypatch.setattr(prog.sys, "stderr", stream)
    try:
        with prog.phase("cross-validation", lambda: {"sims": 7}, tick_s=0.05):
            _time.sleep(0.9)  # a library call that reports nothing
    finally:
        prog.set_mode("auto")
    lines = stream.getvalue().splitlines()
    assert len(lines) >= 3 and all("cross-validation:" in line for line in lines)
    assert "for " in lines[0] and "sims 7" in lines[0]
    assert "done in" in lines[-1] and "\x1b" not in stream.getvalue()


def test_a_phase_s_closing_line_counts_the_work_done_after_its_last_refresh(monkeypatch):
    import time as _time

    monkeypatch.setattr(progress, "PLAIN_INTERVAL_S", 0.1)
    progress.set_mode("plain")
    stream = io.StringIO()
    monkeypatch.setattr(progress.sys, "stderr", stream)
    done = {"sims": 0}
    with progress.phase("fits", lambda: dict(done), tick_s=10.0):  # no refresh in the stage
        _time.sleep(0.2)
        done["sims"] = 42  # the last task came back after the last refresh
    last = stream.getvalue().splitlines()[-1]
    assert "done in" in last and "sims 42" in last
