"""The ``eelbot`` command line: one entry point, a subcommand per job.

Each subcommand lives in its own module under ``eelhost.commands`` and registers itself through
``add_parser(subparsers)``; this file only wires them together, sets the level of the library's
logging (``-v`` for more, ``-q`` for less), and turns user errors (bad files, bad options, a URI
that cannot be opened: :class:`eelhost.errors.UserError` and eelsim's robot-file, scenario and
timing errors) into a one-line message and exit status 2. Anything else is a bug and keeps its
traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys

from eelhost.commands import (
    bench,
    calibrate,
    campaign,
    dataset,
    estimate,
    estimate_bench,
    markers,
    plan,
    ports,
    report,
    robot,
    run,
    simulate,
    speeds,
    validate,
    vision_bench,
)
from eelhost.errors import UserError
from eelsim.robot import RobotFileError
from eelsim.scenario import ScenarioError
from eelsim.timing import TimingError

COMMANDS = (
    simulate,
    speeds,
    dataset,
    estimate,
    estimate_bench,
    validate,
    report,
    vision_bench,
    markers,
    calibrate,
    campaign,
    bench,
    run,
    robot,
    ports,
    plan,
)
USER_ERRORS = (UserError, RobotFileError, ScenarioError, TimingError)
LEVELS = (logging.ERROR, logging.WARNING, logging.INFO, logging.DEBUG)  # -q, default, -v, -vv


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="eelbot",
        description="eelbot: firmware, host and digital twin of an anguilliform swimming robot.",
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
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMANDS:
        module.add_parser(sub)
    return parser


def log_level(verbose: int, quiet: int) -> int:
    """The logging level for ``-v`` and ``-q`` counts (WARNING by default)."""
    index = min(max(1 + verbose - quiet, 0), len(LEVELS) - 1)
    return LEVELS[index]


def main(argv: list[str] | None = None) -> int:
    """Run the ``eelbot`` command line; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    # a no-op where logging is already set up (an application embedding the CLI, pytest)
    logging.basicConfig(format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    logging.getLogger().setLevel(log_level(args.verbose, args.quiet))
    try:
        return int(args.run(args) or 0)
    except USER_ERRORS as err:
        print(f"eelbot {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
