"""``eelbot speeds``: the steady speed of every gait of the paper's grid (calibration table)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from eelhost.commands import COMMANDS
from eelhost.commands.common import POSITIVE, add_robot_options, robot_and_coefficients
from eelhost.files import atomic_write
from eelhost.progress import Progress
from eelsim.speeds import grid_speeds, speed_table_markdown


@COMMANDS.add("speeds", "steady speed of every gait of the 4 x 4 grid")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "speeds",
        help=COMMANDS.description("speeds"),
        description="Simulate each gait of the paper's grid swimming straight and "
        "print the steady speeds (m/s and BL/s) as a markdown table.",
    )
    add_robot_options(p)
    p.add_argument("--duration", type=POSITIVE, default=20.0, help="length of each run, s")
    p.add_argument("--write", metavar="FILE", help="also write the table to this markdown file")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    robot, coeffs = robot_and_coefficients(args)
    with Progress("gait grid", 16, "gait") as bar:
        speeds = grid_speeds(robot, args.duration, coeffs, lambda done, _total: bar.set(done))
    table = speed_table_markdown(speeds, robot.body_length_m())
    print(table)
    if np.isnan(speeds).all():
        print(f"no gait swam forward steadily within {args.duration:g} s (NaN: failed or backwards)")
    else:
        print(
            f"fastest {np.nanmax(speeds):.4f} m/s, slowest {np.nanmin(speeds):.4f} m/s; "
            f"NaN = failed or swam backwards"
        )
    if args.write:
        atomic_write(Path(args.write), table + "\n")
        print(f"wrote {args.write}")
    return 0
