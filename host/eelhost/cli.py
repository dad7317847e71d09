"""The ``eelbot`` command line: one entry point, a subcommand per job.

Each subcommand lives in its own module under ``eelhost.commands`` and registers itself through
``add_parser(subparsers)``; this file only wires them together and turns expected errors (bad files,
bad options) into a one-line message and exit status 2.
"""

from __future__ import annotations

import argparse
import sys

from eelhost.commands import (
    bench,
    dataset,
    estimate,
    estimate_bench,
    plan,
    report,
    run,
    simulate,
    speeds,
    validate,
    vision_bench,
)
from eelhost.data.experiments import DataError
from eelsim.robot import RobotFileError
from eelsim.scenario import ScenarioError
from eelsim.timing import TimingError

COMMANDS = (simulate, speeds, dataset, estimate, estimate_bench, validate, report, vision_bench, bench, run, plan)
USER_ERRORS = (RobotFileError, ScenarioError, TimingError, DataError, ValueError, FileNotFoundError)


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="eelbot",
        description="eelbot: firmware, host and digital twin of an anguilliform swimming robot.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMANDS:
        module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``eelbot`` command line; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except USER_ERRORS as err:
        print(f"eelbot {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
