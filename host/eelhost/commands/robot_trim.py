"""``eelbot robot trim``: calibrate the servo trims, one joint at a time, from typed commands.

The robot is stopped (it then holds every joint at its straight reference, the pulse 1500 us plus
the joint's trim: docs/firmware.md, "Settings"); each trim change is sent at once, so the servo
moves while you watch. The commands are read line by line from standard input, so a script can
drive it (see ``DESCRIPTION``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from eelhost.link.maintenance import Maintenance, SettingError, setting_info

DESCRIPTION = (
    "Calibrate the servo trims: the robot is stopped and holds its joints straight; for each "
    "joint in turn (joint 1 = tail) type +N or -N to nudge its trim by N us, =N to set it, "
    "Enter (or n) for the next joint, b for the previous one, s to save the trims to the EEPROM "
    "and finish, q to quit with the trims put back. After the last joint, Enter saves and "
    "finishes. Commands are read from standard input one a line, so a script can drive it."
)
HELP_LINE = "+N/-N nudge by N us, =N set, Enter/n next joint, b back, s save and finish, q quit"


def trim_session(
    session: Maintenance,
    read_line: Callable[[str], str | None],
    write: Callable[[str], None],
) -> list[int] | None:
    """Run the trim calibration dialogue.

    Parameters
    ----------
    session : Maintenance
        On the robot's link.
    read_line : callable
        ``read_line(prompt)``: the user's next line, None at the end of the input.
    write : callable
        Prints one line for the user.

    Returns
    -------
    list of int or None
        The trims saved, joint 1 first; None when the user quit (the trims are then put back
        as they were).

    Raises
    ------
    eelhost.link.maintenance.RobotAnswerError
        When the robot refuses a change or stops answering.
    """
    info = setting_info("trim_us")
    session.stop()
    original = [int(v) for v in session.get("trim_us")]
    trims = list(original)
    write(f"trims now (us, joint 1 first): {', '.join(str(v) for v in trims)}")
    write(HELP_LINE)
    j = 0
    while True:
        line = read_line(f"joint {j + 1}: trim {trims[j]} us > ")
        if line is None or line.strip().lower() == "q":
            for k, value in enumerate(original):
                if trims[k] != value:
                    session.set("trim_us", k, value)
            write("quit: trims put back, nothing saved")
            return None
        cmd = line.strip().lower()
        if cmd in ("", "n"):
            if j + 1 < info.count:
                j += 1
                continue
            cmd = "s"
        if cmd == "s":
            session.save()
            saved = [int(v) for v in session.get("trim_us")]
            write(f"saved trims (us, joint 1 first): {', '.join(str(v) for v in saved)}")
            return saved
        if cmd == "b":
            j = max(j - 1, 0)
            continue
        try:
            value = _new_trim(cmd, trims[j])
            info.check(value, j)
        except (ValueError, SettingError) as err:
            write(f"  {err}; {HELP_LINE}")
            continue
        session.set("trim_us", j, value)
        trims[j] = int(value)


def _new_trim(cmd: str, now: int) -> int:
    """The trim a command asks for: ``+N``/``-N`` from ``now``, ``=N`` absolute (us)."""
    if cmd[0] in "+-=":
        number = cmd[1:].strip() if cmd[0] == "=" else cmd
        try:
            value = int(number)
        except ValueError:
            raise ValueError(
                f"{cmd!r}: the trim is a whole number of microseconds, not {number or 'nothing'!r}"
            ) from None
        return now + value if cmd[0] in "+-" else value
    raise ValueError(f"{cmd!r} is not a command")


def run(args: argparse.Namespace) -> int:
    """Run ``eelbot robot trim`` (lines from standard input, the dialogue on standard output)."""
    from eelhost.commands.robot import open_maintenance

    def read_line(prompt: str) -> str | None:
        sys.stdout.write(prompt)
        sys.stdout.flush()
        line = sys.stdin.readline()
        if not line:
            sys.stdout.write("\n")
            return None
        if not sys.stdin.isatty():
            sys.stdout.write(line if line.endswith("\n") else line + "\n")  # echo scripted input
        return line

    link, session = open_maintenance(args)
    try:
        trim_session(session, read_line, print)
    finally:
        link.close()
    return 0  # saved, or quit with the trims put back: both a normal end (errors raise)
