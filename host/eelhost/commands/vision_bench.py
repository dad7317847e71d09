"""``eelbot vision-bench``: accuracy and speed of the vision (see :mod:`eelhost.benchmarks.vision_accuracy`).

Renders synthetic frames of a twin run, localises them, compares with the truth, prints the
figures and writes ``docs/vision.md``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from eelhost.benchmarks.vision_accuracy import (
    figures_markdown,
    machine_description,
    run_benchmark,
    vision_doc,
)
from eelhost.commands.common import OptionError
from eelsim.robot import load_robot


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "vision-bench",
        help="accuracy and speed of the vision on synthetic frames",
        description="Render synthetic 1280 x 720 overhead frames of a twin run, localise the robot "
        "in them, and report position and heading errors against the truth and frames per "
        "second on one core; write docs/vision.md.",
    )
    p.add_argument("--frames", type=int, default=300, help="number of frames (300)")
    p.add_argument("--scenario", default="path1", help="scenario to render (path1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the camera noise (0)")
    p.add_argument("--robot", metavar="FILE", help="robot TOML file (default: the paper robot)")
    p.add_argument(
        "--write",
        metavar="FILE",
        default="docs/vision.md",
        help="markdown file to write (docs/vision.md); '-' writes nothing",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    if args.frames < 1:
        raise OptionError(f"--frames must be at least 1, got {args.frames}")
    robot = load_robot(args.robot)
    r = run_benchmark(robot, args.scenario, args.frames, args.seed)
    machine = machine_description()
    print(figures_markdown(r, args.scenario, args.seed, machine))
    if args.write != "-":
        out = Path(args.write)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(vision_doc(r, args.scenario, args.seed, machine))
        print(f"wrote {out}")
    return 0
