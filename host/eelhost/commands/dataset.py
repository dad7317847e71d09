"""``eelbot dataset``: generate the virtual tank's dataset (the paper's 32 experiments, 2 paths)."""

from __future__ import annotations

import argparse

from eelhost.commands.common import (
    COUNT,
    NON_NEGATIVE,
    SEED,
    add_robot_options,
    floats,
    rejected_as,
)
from eelhost.data.virtual_tank import TABLE3, TankSettings, generate_dataset
from eelhost.progress import Progress
from eelsim.robot import HydroCoefficients, load_robot


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "dataset",
        help="generate a virtual-tank dataset",
        description="Record the paper's 32 experiments and its two paths from the twin "
        "with true coefficients (default: table 3, straight and turning rows).",
    )
    p.add_argument("out", help="dataset folder to write")
    add_robot_options(p)
    p.add_argument(
        "--truth",
        metavar="Cf,Cd,Ca,Cm",
        type=lambda s: floats(s, 4),
        help="one true coefficient set for every experiment (default: table 3 per motion)",
    )
    p.add_argument(
        "--mismatch",
        action="store_true",
        help="all mismatch knobs: head/tail shape, servo limits, stray current 0.005 m/s",
    )
    p.add_argument(
        "--head-tail", action="store_true", help="true head and tail unlike the body links"
    )
    p.add_argument("--servo-limits", action="store_true", help="true joints obey the servo limits")
    p.add_argument(
        "--stray-current", type=NON_NEGATIVE, default=0.0, help="unmodelled current speed, m/s"
    )
    p.add_argument(
        "--timestamp-jitter", type=NON_NEGATIVE, default=0.1, help="clock offset half-width, s"
    )
    p.add_argument("--seed", type=SEED, default=0, help="seed of the recordings' noise")
    p.add_argument("--workers", type=COUNT, default=2, help="processes simulating experiments")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    robot = load_robot(args.robot)
    truth = TABLE3
    if args.truth:
        with rejected_as("--truth"):
            c = HydroCoefficients.from_array(args.truth)
        truth = {"straight": c, "turning": c}
    settings = TankSettings(
        timestamp_jitter_s=args.timestamp_jitter,
        head_tail=args.head_tail or args.mismatch,
        servo_limits=args.servo_limits or args.mismatch,
        stray_current_m_s=args.stray_current or (0.005 if args.mismatch else 0.0),
    )
    with Progress("virtual tank", 34, "experiment") as bar:
        manifest = generate_dataset(
            args.out,
            robot,
            truth,
            settings,
            args.seed,
            args.workers,
            progress=lambda done, _total: bar.set(done),
        )
    print(f"wrote {manifest}")
    return 0
