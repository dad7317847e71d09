"""``eelbot vision-bench``: accuracy and speed of the vision (see :mod:`eelhost.benchmarks.vision_accuracy`).

Renders synthetic frames of a twin run, localises them, compares with the truth, prints the
figures, and with ``--write`` writes ``docs/vision.md``.
"""

from __future__ import annotations

import argparse

from eelhost.benchmarks.vision_accuracy import (
    figures_markdown,
    machine_description,
    run_benchmark,
    vision_doc,
)
from eelhost.commands import COMMANDS
from eelhost.commands.common import COUNT, SEED, add_write_option, write_report
from eelhost.progress import Progress
from eelsim.robot import load_robot


@COMMANDS.add("vision-bench", "accuracy and speed of the vision on synthetic frames")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "vision-bench",
        help=COMMANDS.description("vision-bench"),
        description="Render synthetic 1280 x 720 overhead frames of a twin run, localise the robot "
        "in them, and report position and heading errors against the truth and frames per "
        "second on one core; --write also writes docs/vision.md.",
    )
    p.add_argument("--frames", type=COUNT, default=300, help="number of frames")
    p.add_argument("--scenario", default="path1", help="scenario to render (path1)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of the camera noise")
    p.add_argument("--robot", metavar="FILE", help="robot TOML file (default: the paper robot)")
    add_write_option(p, "docs/vision.md")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    robot = load_robot(args.robot)
    with Progress("vision frames", args.frames, "frame") as bar:
        r = run_benchmark(
            robot, args.scenario, args.frames, args.seed, progress=lambda d, _t: bar.set(d)
        )
    machine = machine_description()
    print(figures_markdown(r, args.scenario, args.seed, machine))
    if write_report(args.write, vision_doc(r, args.scenario, args.seed, machine)):
        print(f"wrote {args.write}")
    return 0
