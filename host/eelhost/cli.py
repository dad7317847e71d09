"""The ``eelbot`` command line: one entry point, a subcommand per job.

Each subcommand lives in its own module under ``eelhost.commands`` and registers its
``add_parser(subparsers)`` in :data:`eelhost.commands.COMMANDS` (plug-ins: the ``eelbot.commands``
entry-point group); this file only wires them together and owns what every command shares:

- the level of the library's logging (``-v`` for more, ``-q`` for less);
- the form of progress (``--progress``, :mod:`eelhost.progress`);
- every ``--help`` shows the defaults (:class:`DefaultsHelpFormatter`) and the top-level one the
  exit statuses (:mod:`eelhost.errors`);
- negative numbers as option values: ``--gait -0.6,2.7`` works as ``--gait=-0.6,2.7`` does
  (:func:`join_negative_values`; argparse alone takes ``-0.6,2.7`` for an option);
- user errors (bad files, bad options, a URI that cannot be opened:
  :class:`eelhost.errors.UserError` and eelsim's robot-file, scenario and timing errors) become a
  one-line message and exit status 2 (``--debug`` adds their traceback). Anything else is a bug
  and keeps its traceback;
- an output that cannot be written (a read-only folder, a full disk, ``--out`` naming a file, a
  closed or full stdout: :func:`eelhost.files.output_failure`) is said on one line too, with exit
  status 2; stdout is flushed before the command returns, so a full stdout is found while the
  message can still be given, not in Python's shutdown.
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import sys

from eelhost import progress
from eelhost.commands import COMMANDS, AddParser
from eelhost.errors import EXIT_INTERRUPTED, EXIT_USER_ERROR, UserError, exit_status_table
from eelhost.files import output_failure
from eelsim.registry import PluginError, RegistryError, UnknownNameError
from eelsim.robot import RobotFileError
from eelsim.scenario import ScenarioError
from eelsim.timing import TimingError

log = logging.getLogger(__name__)

USER_ERRORS = (UserError, RobotFileError, ScenarioError, TimingError, UnknownNameError)
LEVELS = (logging.ERROR, logging.WARNING, logging.INFO, logging.DEBUG)  # -q, default, -v, -vv
# an option value that starts with a minus and a digit: -0.6,2.7  -.5  -1e3  "-0.5,0.2;1,0"
NEGATIVE_VALUE = re.compile(r"^-(\d|\.\d)[\d.eE+\-,;\s]*$")


class DefaultsHelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows every option's default, unless its help already says it or there is none."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        if (
            default is None
            or default is False
            or default is argparse.SUPPRESS
            or "%(default)" in text
            or "default" in text
            or (text and str(default) in text)
            or not action.option_strings
        ):
            return text
        return f"{text} (default: %(default)s)".lstrip()


class TopHelpFormatter(argparse.RawDescriptionHelpFormatter, DefaultsHelpFormatter):
    """The top level's: defaults shown, the epilog (exit statuses) kept as written."""


class CommandParser(argparse.ArgumentParser):
    """A parser whose ``--help`` shows the defaults and whose errors take one line.

    argparse prints the whole usage before an error; here the message names the option and
    points to ``--help``, as every other user error does (one line on stderr, exit status 2).
    """

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", DefaultsHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):  # type: ignore[override]
        """Raise :class:`UsageError`: ``PROG: error: MESSAGE (PROG --help ...)``."""
        raise UsageError(f"{self.prog}: error: {message} ({self.prog} --help lists the options)")


class UsageError(UserError):
    """A command line argparse refuses; the message starts with the (sub)command's name."""


def join_negative_values(argv: list[str]) -> list[str]:
    """Join ``--opt -0.6,2.7`` into ``--opt=-0.6,2.7`` so that argparse reads it as a value.

    argparse takes any word that starts with a minus for an option unless it is a plain number,
    so a list of numbers that starts negative (``--gait -0.6,2.7``, ``--current -0.02,0``,
    ``--waypoints "-0.5,0.2;1,0"``) would be refused. A word that looks like such a number right
    after a long option without ``=`` is that option's value.
    """
    out: list[str] = []
    for word in argv:
        previous = out[-1] if out else ""
        if (
            NEGATIVE_VALUE.match(word)
            and previous.startswith("--")
            and "=" not in previous
            and previous != "--"
        ):
            out[-1] = f"{previous}={word}"
        else:
            out.append(word)
    return out


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    parser = CommandParser(
        prog="eelbot",
        description="eelbot: firmware, host and digital twin of an anguilliform swimming robot.",
        epilog="exit status:\n" + exit_status_table(),
        formatter_class=TopHelpFormatter,
    )
    parser.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=0,
        help="log more: -v what the library does (INFO), -vv everything (DEBUG)",
    )
    parser.add_argument(
        "-q", "--quiet", action="count", default=0, help="log errors only (no warnings)"
    )
    parser.add_argument(
        "--progress",
        choices=progress.MODES,
        default="auto",
        help="progress of long commands: bar (a terminal), plain (timestamped lines every few "
        "seconds, for a log), none; auto: bar on a terminal, else plain",
    )
    parser.add_argument(
        "--debug", action="store_true", help="show the traceback of user errors too"
    )
    sub = parser.add_subparsers(
        dest="command", metavar="COMMAND", required=True, parser_class=CommandParser
    )
    for name, add_parser in sorted(COMMANDS.items()):  # alphabetical, plug-ins among them
        _add_command(sub, name, add_parser)
    return parser


def _add_command(sub: argparse._SubParsersAction, name: str, add_parser: AddParser) -> None:
    """Add one registered subcommand; a plug-in's that fails is said and left out.

    A bundled command's failure is a bug and raises; a plug-in's (``eelbot.commands`` entry
    point) must not take the whole command line down with it, so it is logged, naming the entry
    point, and the other commands work.
    """
    origin = COMMANDS.entry(name).origin
    if origin == "built-in":
        add_parser(sub)
        return
    try:
        add_parser(sub)
        if name not in sub.choices:
            raise RegistryError(f"its add_parser added no subcommand named {name!r}")
    except Exception as err:  # a plug-in's bug: said, and the rest of the CLI works
        sub.choices.pop(name, None)
        sub._choices_actions[:] = [a for a in sub._choices_actions if a.dest != name]
        log.warning("%s", PluginError(str(COMMANDS.group), origin, f"{type(err).__name__}: {err}"))


def log_level(verbose: int, quiet: int) -> int:
    """The logging level for ``-v`` and ``-q`` counts (WARNING by default)."""
    index = min(max(1 + verbose - quiet, 0), len(LEVELS) - 1)
    return LEVELS[index]


def main(argv: list[str] | None = None) -> int:
    """Run the ``eelbot`` command line; return the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(join_negative_values(sys.argv[1:] if argv is None else argv))
    except UsageError as err:
        print(err, file=sys.stderr)
        return EXIT_USER_ERROR
    # a no-op where logging is already set up (an application embedding the CLI, pytest)
    logging.basicConfig(format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    logging.getLogger().setLevel(log_level(args.verbose, args.quiet))
    progress.set_mode(args.progress)
    if sys.stdout is None:  # started with stdout closed (`eelbot ports >&-`): print would drop
        progress.message(f"eelbot {args.command}: error: stdout is closed; eelbot prints its "
                         "results there (redirect it to a file, or to /dev/null)")
        return EXIT_USER_ERROR
    real_stdout = sys.stdout
    sys.stdout = _NamedStdout(real_stdout)  # type: ignore[assignment]
    try:
        with progress.console():
            status = int(args.run(args) or 0)
            sys.stdout.flush()  # a full or closed stdout fails here, where it can be said
            return status
    except (*USER_ERRORS, KeyboardInterrupt, OSError) as err:
        failure = output_failure(err)
        if isinstance(err, OSError) and not isinstance(err, USER_ERRORS) and failure is None:
            raise  # an OSError that is not about an output: a bug, with its traceback
        progress.close_all()  # the message goes on a line of its own, after what was printed
        if args.debug:
            raise
        if not _flush_stdout() and failure is None:
            failure = "cannot write stdout: it is closed or full"
        interrupted = isinstance(err, KeyboardInterrupt)
        text = "interrupted" if interrupted else f"error: {failure or err}"
        progress.message(f"eelbot {args.command}: {text}")
        return EXIT_INTERRUPTED if interrupted else EXIT_USER_ERROR
    finally:
        progress.close_all()
        sys.stdout = real_stdout


class _NamedStdout:
    """stdout, whose write errors name it: ``cannot write stdout: ...`` rather than no file."""

    def __init__(self, wrapped: object) -> None:
        self._wrapped = wrapped

    def write(self, text: str) -> int:
        try:
            return self._wrapped.write(text)  # type: ignore[attr-defined,no-any-return]
        except OSError as err:
            raise OSError(err.errno, err.strerror, "stdout") from err

    def flush(self) -> None:
        try:
            self._wrapped.flush()  # type: ignore[attr-defined]
        except OSError as err:
            raise OSError(err.errno, err.strerror, "stdout") from err

    def __getattr__(self, name: str) -> object:  # fileno, isatty, encoding ... of the real one
        return getattr(self._wrapped, name)


def _flush_stdout() -> bool:
    """Flush stdout; if it cannot be written, point it at /dev/null and say False.

    Python flushes stdout once more when it exits; a stdout that is full or whose reader is gone
    would then print its own traceback-like report. Pointing the descriptor at /dev/null (what
    Python's documentation advises for a broken pipe) leaves only eelbot's one line.
    """
    try:
        sys.stdout.flush()
        return True
    except OSError:
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError, AttributeError):  # a stream without a descriptor (a test's)
            pass
        return False


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
