"""Options shared by several subcommands (robot, coefficients, loop timing)."""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager

from pydantic import ValidationError

from eelhost.errors import UserError
from eelsim.camera import CameraModel
from eelsim.closed_loop import LoopOptions
from eelsim.fluid import FluidCoefficients
from eelsim.robot import Robot, load_robot
from eelsim.timing import LoopTiming


class OptionError(UserError, ValueError):
    """A command-line option that cannot be used; the message names the option."""


@contextmanager
def rejected_as(options: str) -> Iterator[None]:
    """Report values the twin's models reject as an :class:`OptionError` naming the options.

    Wraps the building of a model from command-line values: a pydantic ``ValidationError`` (the
    model's own checks) or an ``argparse.ArgumentTypeError`` (a list of numbers that does not
    parse) becomes a one-line :class:`OptionError`; anything else passes through.

    Parameters
    ----------
    options : str
        The options the values came from, as the message names them.
    """
    try:
        yield
    except ValidationError as err:
        fields = "; ".join(
            f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']} (got {e.get('input')!r})"
            for e in err.errors()
        )
        raise OptionError(f"{options}: {fields}") from None
    except argparse.ArgumentTypeError as err:
        raise OptionError(str(err)) from None


def floats(text: str, count: int | None = None, what: str = "value") -> list[float]:
    """Parse "a,b,c" into floats, checking the count; errors name ``what``."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{what}: expected comma-separated numbers, got {text!r}"
        ) from None
    if count is not None and len(values) != count:
        raise argparse.ArgumentTypeError(
            f"{what}: expected {count} numbers, got {len(values)} in {text!r}"
        )
    return values


def add_robot_options(p: argparse.ArgumentParser) -> None:
    """--robot and --coefficients."""
    p.add_argument(
        "--robot", metavar="FILE", help="robot TOML file (default: the bundled paper robot)"
    )
    p.add_argument(
        "--coefficients",
        metavar="Cf,Cd,Ca,Cm",
        type=lambda s: floats(s, 4, "--coefficients"),
        help="hydrodynamic coefficients (default: the robot file's)",
    )


def robot_and_coefficients(args: argparse.Namespace) -> tuple[Robot, FluidCoefficients]:
    """Load the robot and the coefficients chosen on the command line."""
    robot = load_robot(args.robot)
    if not args.coefficients:
        return robot, robot.hydrodynamics
    with rejected_as("--coefficients"):
        return robot, type(robot.hydrodynamics).from_array(args.coefficients)


def add_loop_options(p: argparse.ArgumentParser) -> None:
    """Timing, camera and servo options of the closed loop."""
    g = p.add_argument_group("closed-loop timing")
    g.add_argument("--dt", type=float, default=0.01, help="physics step, s (default 0.01)")
    g.add_argument(
        "--control-period", type=float, default=0.3, help="offset update period, s (0.3)"
    )
    g.add_argument("--delay", type=float, default=0.0, help="extra delay before an offset acts, s")
    g.add_argument("--jitter", type=float, default=0.0, help="control period jitter, +- s")
    g.add_argument("--fps", type=float, default=30.0, help="camera frame rate (30)")
    g.add_argument("--pixel", type=float, default=0.0038, help="camera pixel size, m (0.0038)")
    g.add_argument("--median", type=int, default=5, help="median filter length, frames (5)")
    g.add_argument(
        "--servo-limits", action="store_true", help="limit joints by the servos' torque-speed line"
    )


def loop_options(args: argparse.Namespace, stop_at_goal: bool = True) -> LoopOptions:
    """Build :class:`LoopOptions` from the parsed options."""
    try:
        camera = CameraModel(args.fps, args.pixel, args.median)
    except ValueError as err:  # CameraModel checks its three values and names the bad one
        raise OptionError(f"--fps/--pixel/--median: {err}") from None
    return LoopOptions(
        timing=LoopTiming(args.dt, args.control_period, args.delay, args.jitter),
        camera=camera,
        servo_limits=args.servo_limits,
        stop_at_goal=stop_at_goal,
    )


def add_fit_options(p: argparse.ArgumentParser) -> None:
    """Options of a coefficient fit (method, budgets, backend, clock offsets, resume)."""
    from eelhost.estimation.pipeline import METHODS

    g = p.add_argument_group("fitting")
    g.add_argument(
        "--method",
        choices=METHODS,
        default="cmaes",
        help="cmaes (+ least-squares polish; default), ga (the paper's), lsq (polish only)",
    )
    g.add_argument("--seed", type=int, default=0)
    g.add_argument(
        "--budget", type=int, default=1500, help="CMA-ES candidates per fit at most (1500)"
    )
    g.add_argument("--pop-size", type=int, default=150, help="GA population (150)")
    g.add_argument("--generations", type=int, default=130, help="GA generations (130)")
    g.add_argument("--backend", choices=["auto", "batch", "reference"], default="auto")
    g.add_argument(
        "--align",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="while fitting, search each recording's clock offset within +-SECONDS "
        "(default 0: the paper's protocol; with few experiments the offsets absorb model error)",
    )
    g.add_argument(
        "--resume", action="store_true", help="continue interrupted fits from their checkpoints"
    )


def fit_settings(args: argparse.Namespace):
    """The :class:`~eelhost.estimation.pipeline.FitSettings` chosen on the command line."""
    from eelhost.estimation.pipeline import FitSettings

    return FitSettings(
        args.method,
        args.seed,
        args.budget,
        args.pop_size,
        args.generations,
        backend=args.backend,
        align_s=args.align,
    )
