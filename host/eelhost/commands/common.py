"""Options shared by several subcommands (robot, coefficients, loop timing) and their checks.

The argparse types here refuse a value when it is read, so argparse names the option in its
message: :func:`number` (finite, within bounds), :func:`floats` (a list of finite numbers),
:func:`gait_values` (within the robot's protocol ranges), :func:`current_values` and
:func:`waypoints`. :func:`rejected_as` turns the twin's own model checks into a message naming
the option a value came from.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from typing import Any

from pydantic import ValidationError

from eelhost.errors import UserError
from eelhost.wire.limits import MAX_CURRENT_M_S, gait_problem
from eelsim.camera import CameraModel
from eelsim.closed_loop import LoopOptions
from eelsim.fluid import FluidCoefficients
from eelsim.registry import Registry
from eelsim.robot import Robot, load_robot
from eelsim.timing import LoopTiming


class OptionError(UserError, ValueError):
    """A command-line option that cannot be used; the message names the option."""


# Which option a field of a scenario (or of a run's task) comes from, for the messages.
SCENARIO_OPTIONS = {
    "amplitude_rad": "--gait",
    "omega_rad_s": "--gait",
    "beta_rad": "--gait",
    "k_theta": "--k-theta",
    "waypoints_m": "--waypoints",
    "acceptance_radius_m": "--radius",
    "current_speed_m_s": "--current",
    "current_direction_deg": "--current",
    "duration_s": "--duration",
}


@contextmanager
def rejected_as(options: str, fields: Mapping[str, str] | None = None) -> Iterator[None]:
    """Report values the twin's models reject as an :class:`OptionError` naming the option.

    Wraps the building of a model from command-line values: a pydantic ``ValidationError`` (the
    model's own checks) or an ``argparse.ArgumentTypeError`` (a list of numbers that does not
    parse) becomes a one-line :class:`OptionError`; anything else passes through.

    Parameters
    ----------
    options : str
        The options the values came from, as the message names them.
    fields : mapping of str to str, optional
        The option each field of the model comes from (e.g. :data:`SCENARIO_OPTIONS`); a field
        found here is reported under its own option instead of ``options``.
    """
    try:
        yield
    except ValidationError as err:
        parts = []
        for e in err.errors():
            loc = [str(p) for p in e["loc"]]
            option = (fields or {}).get(loc[0] if loc else "", options)
            msg = e["msg"].replace("Input should be", "should be")
            parts.append(f"{option}: {'.'.join(loc)} {msg} (got {e.get('input')!r})")
        raise OptionError("; ".join(parts)) from None
    except argparse.ArgumentTypeError as err:
        raise OptionError(str(err)) from None


def number(
    kind: type = float,
    *,
    minimum: float | None = None,
    above: float | None = None,
    maximum: float | None = None,
) -> Callable[[str], float]:
    """An argparse ``type``: a finite number, at least ``minimum`` / above ``above`` / at most.

    argparse reports a refusal as ``argument --OPTION: <why>``, so the option is named.

    Parameters
    ----------
    kind : type
        ``float`` or ``int``.
    minimum, above, maximum : float, optional
        Bounds: ``value >= minimum``, ``value > above``, ``value <= maximum``.
    """

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            what = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum:g}, got {text}")
        if above is not None and value <= above:
            raise argparse.ArgumentTypeError(f"must be greater than {above:g}, got {text}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum:g}, got {text}")
        return value

    parse.__name__ = kind.__name__
    return parse


def registered_names(registry: Registry[Any], plural: str) -> Callable[[str], tuple[str, ...]]:
    """An argparse ``type``: comma-separated names registered in ``registry`` (``--laws``).

    Parameters
    ----------
    registry : eelsim.registry.Registry
        Read when a value is parsed (plug-ins included).
    plural : str
        What the names are, for the message: ``expected fluid laws from a, b, got 'x'``.
    """

    def parse(text: str) -> tuple[str, ...]:
        names = tuple(n.strip() for n in text.split(",") if n.strip())
        unknown = [n for n in names if n not in registry]
        if not names or unknown:
            raise argparse.ArgumentTypeError(
                f"expected {plural} from {', '.join(sorted(registry))}, got {text!r}")
        return names

    return parse


POSITIVE = number(above=0.0)
NON_NEGATIVE = number(minimum=0.0)
FINITE = number()
COUNT = number(int, minimum=1)
COUNT_OR_NONE = number(int, minimum=0)  # a count where 0 turns the thing off
SEED = number(int, minimum=0)
PORT = number(int, minimum=0, maximum=65535)


def floats(text: str, count: int | None = None, what: str | None = None) -> list[float]:
    """Parse "a,b,c" into finite floats, checking the count (an argparse ``type``).

    ``what`` (an option's name) starts the message, for values parsed after argparse, whose own
    messages name the option already.
    """
    where = f"{what}: " if what else ""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{where}expected comma-separated numbers, got {text!r}"
        ) from None
    if count is not None and len(values) != count:
        raise argparse.ArgumentTypeError(
            f"{where}expected {count} numbers, got {len(values)} in {text!r}"
        )
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{where}numbers must be finite, got {text!r}")
    return values


def gait_values(text: str) -> list[float]:
    """An argparse ``type`` for ``--gait A,omega[,beta]``: within the robot's protocol ranges.

    The ranges are those the firmware accepts (:func:`eelhost.wire.limits.gait_problem`,
    docs/firmware.md), so the twin is never asked for a gait the robot would refuse.
    """
    values = floats(text)
    if len(values) not in (2, 3):
        raise argparse.ArgumentTypeError(f"give A,omega or A,omega,beta, got {text!r}")
    problem = gait_problem(values)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return values


def current_values(text: str) -> list[float]:
    """An argparse ``type`` for ``--current speed,direction_deg`` (speed 0 to 1 m/s)."""
    speed, direction = floats(text, 2)
    if speed < 0.0:
        raise argparse.ArgumentTypeError(
            f"speed must be >= 0 (a direction turns it: {-speed:g},"
            f"{(direction + 180.0) % 360.0:g}), got {text!r}"
        )
    if speed > MAX_CURRENT_M_S:
        raise argparse.ArgumentTypeError(
            f"speed {speed:g} m/s is beyond any tank current the twin is made for "
            f"(at most {MAX_CURRENT_M_S:g} m/s, ten times the robot's fastest speed)"
        )
    return [speed, direction]


def waypoints(text: str) -> list[tuple[float, float]]:
    """An argparse ``type`` for ``--waypoints "x,y;x,y"`` (metres): at least one, finite."""
    out = []
    for part in text.split(";"):
        if part.strip():
            x, y = floats(part, 2)
            out.append((x, y))
    if not out:
        raise argparse.ArgumentTypeError(f"give at least one x,y, got {text!r}")
    return out


def add_robot_options(p: argparse.ArgumentParser) -> None:
    """--robot and --coefficients."""
    p.add_argument(
        "--robot", metavar="FILE", help="robot TOML file (default: the bundled paper robot)"
    )
    p.add_argument(
        "--coefficients",
        metavar="NAME=VALUE,...",
        type=coefficient_text,
        help="the robot file's fluid law's coefficients, by name (C_d=0.8,C_a=1.0: the others "
        "keep the robot file's values) or all in the law's order (0.008,0.776,0.618,0.007 for "
        "morison's C_f,C_d,C_a,C_m) (default: the robot file's)",
    )


def coefficient_text(text: str) -> str:
    """``--coefficients``'s argparse ``type``: the text, checked for form only.

    The law, and so the names and the count, are the robot file's, known after parsing;
    :func:`robot_and_coefficients` reads the values (:meth:`FluidCoefficients.from_text`).
    """
    items = [item.strip() for item in text.split(",") if item.strip()]
    if not items:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE,... or numbers, got {text!r}")
    return text


def robot_and_coefficients(args: argparse.Namespace) -> tuple[Robot, FluidCoefficients]:
    """Load the robot and the coefficients chosen on the command line.

    ``--coefficients`` names coefficients of the robot file's law, or gives them all in its
    order (:meth:`eelsim.fluid.FluidCoefficients.from_text`); a wrong name or count is an
    :class:`OptionError` naming the law's coefficients.
    """
    robot = load_robot(args.robot)
    if not args.coefficients:
        return robot, robot.hydrodynamics
    return robot, coefficients_from_option(type(robot.hydrodynamics), args.coefficients,
                                           "--coefficients", robot.hydrodynamics)


def coefficients_from_option(record: type[FluidCoefficients], text: str, option: str,
                             base: FluidCoefficients | None = None) -> FluidCoefficients:
    """A law's coefficients from an option's text, by name or in order (``from_text``).

    Parameters
    ----------
    record : type of FluidCoefficients
        The law's record.
    text : str
    option : str
        The option, which the error names.
    base : FluidCoefficients, optional
        The values of the coefficients not named (None: every one must be given).

    Raises
    ------
    OptionError
        A wrong name, count or value, naming the option and the law's coefficients.
    """
    with rejected_as(option):
        try:
            return record.from_text(text, base)
        except ValidationError:
            raise
        except ValueError as err:
            raise OptionError(f"{option}: {err}") from None


def add_loop_options(p: argparse.ArgumentParser) -> None:
    """Timing, camera and servo options of the closed loop."""
    g = p.add_argument_group("closed-loop timing")
    g.add_argument("--dt", type=POSITIVE, default=0.01, help="physics step, s")
    g.add_argument("--control-period", type=POSITIVE, default=0.3, help="offset update period, s")
    g.add_argument(
        "--delay", type=NON_NEGATIVE, default=0.0, help="extra delay before an offset acts, s"
    )
    g.add_argument("--jitter", type=NON_NEGATIVE, default=0.0, help="control period jitter, +- s")
    g.add_argument("--fps", type=FINITE, default=30.0, help="camera frame rate, 1/s")
    g.add_argument("--pixel", type=FINITE, default=0.0038, help="camera pixel size, m")
    g.add_argument("--median", type=number(int), default=5, help="median filter length, frames")
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
    from eelhost.estimation.methods import method_descriptions, method_names

    g = p.add_argument_group("fitting")
    g.add_argument(
        "--method",
        choices=method_names(),  # read now, so a plug-in's method is offered
        default="cmaes",
        # the registry's own descriptions, so the help says what the code does
        help="; ".join(f"{name}: {text}" for name, text in method_descriptions().items()),
    )
    g.add_argument("--seed", type=SEED, default=0, help="seed of the optimiser")
    g.add_argument("--budget", type=COUNT, default=1500,
                   help="candidates of the global search (CMA-ES) per fit, at most; the polish "
                   "after it adds its own (up to 30 iterations)")
    g.add_argument("--pop-size", type=number(int, minimum=2), default=150, help="GA population")
    g.add_argument("--generations", type=COUNT, default=130, help="GA generations")
    add_backend_option(g)
    g.add_argument(
        "--align",
        type=NON_NEGATIVE,
        default=0.0,
        metavar="SECONDS",
        help="while fitting, search each recording's clock offset within +-SECONDS "
        "(default 0: the paper's protocol; with few experiments the offsets absorb model error)",
    )
    add_current_option(g)
    g.add_argument(
        "--resume", action="store_true", help="continue interrupted fits from their checkpoints"
    )


def add_current_option(p: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """--fit-current / --no-fit-current: fit the tank's unknown ambient current as a nuisance."""
    p.add_argument(
        "--fit-current",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="fit an unknown uniform current in the tank (v_x, v_y within +-0.03 m/s, shared by a "
        "fit's experiments and added to the current each declares) with the coefficients "
        "(default: %(default)s; --no-fit-current: the paper's protocol, the declared currents "
        "only)",
    )


def add_write_option(p: argparse.ArgumentParser, page: str) -> None:
    """--write [FILE]: a benchmark's report goes to stdout, and to a file only when asked.

    Parameters
    ----------
    p : ArgumentParser
    page : str
        The documentation page the report is, written by a bare ``--write``.
    """
    p.add_argument(
        "--write",
        nargs="?",
        const=page,
        metavar="FILE",
        help=f"also write the report to FILE (bare --write: {page}, the page in the docs); "
        "without it the report only goes to stdout",
    )


def write_report(path: str | None, text: str) -> str | None:
    """Write a report where ``--write`` said (atomically); return the path, or None if not asked."""
    if not path:
        return None
    from eelhost.files import atomic_write

    atomic_write(path, text)
    return path


def add_backend_option(p: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """--backend: which implementation of the twin evaluates the candidates."""
    from eelhost.estimation.evaluate import AUTO_BACKEND, BACKENDS  # read when the parser is built

    p.add_argument(
        "--backend",
        choices=[AUTO_BACKEND, *BACKENDS],
        default=AUTO_BACKEND,
        help="; ".join(f"{name}: {text}".replace("%", "%%")
                       for name, text in BACKENDS.descriptions().items())
        + f"; {AUTO_BACKEND}: batch when it loads, else reference",
    )


def fit_settings(args: argparse.Namespace):
    """The :class:`~eelhost.estimation.methods.FitSettings` chosen on the command line."""
    from eelhost.estimation.methods import FitSettings

    return FitSettings(
        args.method,
        args.seed,
        args.budget,
        args.pop_size,
        args.generations,
        backend=args.backend,
        align_s=args.align,
        fit_current=args.fit_current,
    )
