"""``eelbot dataset``: generate the virtual tank's dataset (the paper's 32 experiments, 2 paths)."""

from __future__ import annotations

import argparse
import dataclasses
import tomllib
from pathlib import Path

from eelhost.commands import COMMANDS
from eelhost.commands.common import (
    COUNT,
    NON_NEGATIVE,
    SEED,
    add_robot_options,
    coefficients_from_option,
)
from eelhost.data.plants import PLANTS, law_truths
from eelhost.data.virtual_tank import TankSettings, generate_dataset
from eelhost.errors import UserError
from eelhost.files import check_output_folder
from eelhost.progress import Progress
from eelsim.camera import MEDIAN_PLACEMENTS
from eelsim.fluid import DEFAULT_FLUID_LAW, FLUID_LAWS
from eelsim.robot import load_robot


@COMMANDS.add("dataset", "generate a virtual-tank dataset")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "dataset",
        help=COMMANDS.description("dataset"),
        description="Record the paper's 32 experiments and its two paths from the twin "
        "with true coefficients (default: table 3, straight and turning rows).",
    )
    p.add_argument("out", help="dataset folder to write")
    add_robot_options(p)
    p.add_argument(
        "--truth",
        metavar="NAME=VALUE,...",
        help="one true coefficient set for every experiment: the law's coefficients all by name "
        "or all in its order (default: table 3 per motion)",
    )
    p.add_argument(
        "--mismatch",
        action="store_true",
        help="head/tail shape, servo limits, stray current 0.005 m/s",
    )
    p.add_argument(
        "--plant",
        choices=sorted(PLANTS),  # read now, so a lab's plug-in plant is offered
        help="a named test plant (docs/estimation.md, 'Test plants'; a lab adds its own through "
        "the eelbot.plants entry points); other options add to it: " + plant_help(),
    )
    p.add_argument(
        "--fluid-law",
        choices=sorted(FLUID_LAWS),
        help="the water's fluid law (truth: table 3 carried into it)",
    )
    p.add_argument(
        "--median", choices=MEDIAN_PLACEMENTS, help="the recording's median filter"
    )
    p.add_argument(
        "--joints-from",
        metavar="ROBOT.toml",
        help="the plant's joints: the [joints] table of this robot file (e.g. stiff servos)",
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
    check_output_folder(args.out, "OUT")  # before 34 experiments are simulated
    plant = PLANTS[args.plant] if args.plant else None
    base = plant.settings if plant else TankSettings()
    law = args.fluid_law or (plant.law if plant else DEFAULT_FLUID_LAW)
    try:
        # a named plant's own truth (it may set some of its law's coefficients otherwise)
        truth = plant.truths() if plant and not args.fluid_law else law_truths(law)
    except ValueError as err:
        if not args.truth:
            raise UserError(f"--fluid-law: {err}") from None
    if args.truth:
        c = coefficients_from_option(FLUID_LAWS[law].coefficients, args.truth, "--truth")
        truth = {"straight": c, "turning": c}
    settings = dataclasses.replace(
        base,
        timestamp_jitter_s=args.timestamp_jitter,
        head_tail=base.head_tail or args.head_tail or args.mismatch,
        servo_limits=base.servo_limits or args.servo_limits or args.mismatch,
        stray_current_m_s=args.stray_current
        or (0.005 if args.mismatch else base.stray_current_m_s),
        median=args.median or base.median,
        joints=_joints_table(args.joints_from) if args.joints_from else base.joints,
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


def plant_help() -> str:
    """Every registered plant with its one-line description, for help texts."""
    # argparse formats help with %: a plug-in's "5 % salt" must not break --help
    return "; ".join(f"{name}: {text}".replace("%", "%%")
                     for name, text in PLANTS.descriptions().items())


def _joints_table(path: str) -> dict:
    """The ``[joints]`` table of a robot file (a plant's joint model)."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise UserError(f"--joints-from: cannot read {path}: {err}") from None
    joints = data.get("joints")
    if not isinstance(joints, dict):
        raise UserError(f"--joints-from: {path} has no [joints] table")
    return joints
