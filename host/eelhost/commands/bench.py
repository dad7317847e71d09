"""``eelbot bench``: how fast the twin runs (see :mod:`eelhost.benchmarks.twin_speed`).

Prints the markdown report as it is measured; ``--write`` also writes it to ``docs/benchmarks.md``
(or the file given).
"""

from __future__ import annotations

import argparse
import sys

from eelhost.benchmarks.twin_speed import TwinBenchSettings, twin_speed_report
from eelhost.commands import COMMANDS
from eelhost.commands.common import (
    COUNT,
    add_robot_options,
    add_write_option,
    robot_and_coefficients,
    write_report,
)


@COMMANDS.add("bench", "speed of the twin: single run, one GA generation, MuJoCo comparison")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "bench",
        help=COMMANDS.description("bench"),
        description="Benchmark the batched closed-loop kernel (and MuJoCo on the same robot, each "
        "engine timed alone in its own process, in rounds) and print the report (--write: also "
        "docs/benchmarks.md). Ratios are measured within each round: on a loaded machine they "
        "hold better than the absolute figures.",
    )
    add_robot_options(p)
    p.add_argument(
        "--runs", type=COUNT, default=600, help="runs in the batch (600: one GA generation)"
    )
    p.add_argument("--steps", type=COUNT, default=3000, help="RK4 steps per run")
    p.add_argument("--threads", type=COUNT, default=None, help="threads for 'all cores' (nproc)")
    p.add_argument("--no-mujoco", action="store_true", help="skip the MuJoCo comparison")
    p.add_argument(
        "--no-cold-compile",
        action="store_true",
        help="skip the cold-compile measurement (it takes about a minute)",
    )
    p.add_argument(
        "--no-ga", action="store_true", help="skip the end-to-end GA (it takes about 40 s)"
    )
    p.add_argument(
        "--rounds", type=COUNT, default=15,
        help="rounds of the engine comparison per thread count: one window of each engine, "
        "each in its own process, back to back (15)",
    )
    p.add_argument("--note", default="", help="a remark for the report (e.g. other load)")
    add_write_option(p, "docs/benchmarks.md")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    robot, coeffs = robot_and_coefficients(args)
    settings = TwinBenchSettings(
        runs=args.runs,
        steps=args.steps,
        threads=args.threads,
        mujoco=not args.no_mujoco,
        cold_compile=not args.no_cold_compile,
        ga=not args.no_ga,
        rounds=args.rounds,
        note=args.note,
        command=" ".join(["eelbot", *sys.argv[1:]]),  # global options included
    )
    lines = twin_speed_report(robot, coeffs, settings, emit=lambda line: print(line, flush=True))
    text = "\n".join(lines) + "\n"
    if args.write:
        from eelhost.benchmarks.cluster_speed import keep_block

        text = keep_block(args.write, text)  # measured by its own command: kept
    if write_report(args.write, text):
        print(f"wrote {args.write}")
    return 0
