"""User errors and the command line's exit statuses.

Every module that rejects what a user gave it (a file, an option, a URI, a dataset) raises its own
subclass of :class:`UserError`, with a message that names what is wrong and where. The ``eelbot``
command line prints such a message on one line and exits with status :data:`EXIT_USER_ERROR` (as
it does for eelsim's ``RobotFileError``, ``ScenarioError`` and ``TimingError``); any other
exception is a bug and keeps its traceback.

The subclasses also derive from ``ValueError`` (or ``ConnectionError`` for a transport), as they
did before this base existed, so callers that catch those still do.

Exit statuses (listed by ``eelbot --help`` and docs/cli.md): 0 the command did what was asked;
1 a run or plan ended without reaching its goal for a reason that is not a twin flag; 2 a user
error; 3, 4, 5 a twin run that ended flagged TOO_SLOW, ILL_CONDITIONED or SELF_COLLISION
(:func:`exit_status_for_flag`); 130 interrupted (Ctrl-C).
"""

from __future__ import annotations

from eelsim.flags import Failure

__all__ = [
    "EXIT_CONTACT",
    "EXIT_INTERRUPTED",
    "EXIT_NOT_REACHED",
    "EXIT_OK",
    "EXIT_USER_ERROR",
    "UserError",
    "exit_status_for_flag",
    "exit_status_table",
]

EXIT_OK = 0
EXIT_NOT_REACHED = 1
EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130  # the shell's status for a command ended by Ctrl-C (128 + SIGINT)
_FLAG_BASE = 2  # TOO_SLOW (1) -> 3, ILL_CONDITIONED (2) -> 4, SELF_COLLISION (3) -> 5
EXIT_CONTACT = 6  # eelbot run --plan: the robot's body touched an obstacle or wall (after the flags)
assert EXIT_CONTACT > _FLAG_BASE + max(Failure), "a twin flag's status would be the contact's"


class UserError(Exception):
    """Input that cannot be used; the message says what is wrong and where."""


def exit_status_for_flag(failure: Failure) -> int:
    """The exit status of a twin run that ended with ``failure`` (0 for ``Failure.NONE``).

    Parameters
    ----------
    failure : Failure
        The run's outcome flag.

    Returns
    -------
    int
        0, or 3, 4, 5 for TOO_SLOW, ILL_CONDITIONED, SELF_COLLISION.
    """
    return EXIT_OK if failure == Failure.NONE else _FLAG_BASE + int(failure)


def exit_status_table() -> str:
    """The exit statuses as the lines ``--help`` shows."""
    rows = [
        (EXIT_OK, "done"),
        (EXIT_NOT_REACHED, "a run or plan ended without reaching its goal (not a twin flag)"),
        (EXIT_USER_ERROR, "a user error: bad option, file, URI or dataset (one-line message)"),
    ]
    rows += [
        (exit_status_for_flag(f), f"a twin run ended flagged {f.name}")
        for f in Failure
        if f != Failure.NONE
    ]
    rows.append((EXIT_CONTACT, "a run (eelbot run --plan) stopped: the body touched an obstacle "
                               "or wall"))
    rows.append((EXIT_INTERRUPTED, "interrupted (Ctrl-C)"))
    return "\n".join(f"  {code:>3}  {text}" for code, text in rows)
