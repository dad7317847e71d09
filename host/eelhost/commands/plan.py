"""``eelbot plan``: plan a path the twin swims without collision, check it, or benchmark the planner.

``eelbot plan WORLD`` (a world TOML file, the bundled example ``tank_5_obstacles``, or
``bench:SEED`` for a generated benchmark world) refuses what cannot be planned (exit 2 with the
reason), searches with every leg swum in the twin, checks the plan over the coefficients'
uncertainty, and writes ``<out>/plan.json`` (``--plot``: ``<out>/plan.png``). ``--replan`` also
swims it in the twin with closed-loop replanning (:mod:`eelhost.planning.replan`).
``eelbot plan --bench`` runs the benchmark of docs/planning.md over ``--worlds`` generated worlds
and prints its figures; ``--write`` also rewrites the benchmark section of docs/planning.md (or the
file given).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
from pathlib import Path

from eelhost.commands import COMMANDS
from eelhost.commands.common import (
    COUNT,
    SEED,
    OptionError,
    add_robot_options,
    robot_and_coefficients,
)
from eelhost.files import atomic_write, check_output_folder
from eelhost.machine import cpu_model
from eelhost.planning.coverage import action_coverage
from eelhost.planning.planner import (
    AUTO_GUIDANCE,
    AUTO_LAWS,
    CHECK_DRAWS,
    CHECK_MARGIN_M,
    PLANNING_GUIDANCE,
    REPAIR_DRAWS_FACTOR,
    GuidanceChoice,
    Outcome,
    Planner,
    PlanRefused,
    laws_of,
    plan_with_laws,
)
from eelhost.planning.uncertainty import (
    DEFAULT_UNKNOWN_CURRENT_M_S,
    CoefficientModel,
    default_model,
    read_coefficient_model,
)
from eelhost.planning.world import World, load_world
from eelhost.planning.worlds import generate_world
from eelhost.progress import phase
from eelsim.closed_loop import LoopOptions
from eelsim.guidance import GUIDANCE_LAWS, PURSUIT, GuidanceLaw
from eelsim.model import SwimmerModel
from eelsim.robot import Robot

GUIDANCE_CHOICES = [*GUIDANCE_LAWS.names(), AUTO_GUIDANCE]
"""``--guidance``'s choices: each law, or ``auto`` (:data:`AUTO_HELP`)."""

AUTO_HELP = (f"plan with {' then '.join(law.name for law in AUTO_LAWS)} where the one before "
             "finds no checked plan, and steer and replan with the plan's law (docs/planning.md, "
             "\"A guidance law chosen per plan\")")
"""What ``--guidance auto`` does, for the help and the benchmarks' figures."""

REFUSALS = ("blocked_start", "current_too_strong", "goal_blocked", "unreachable")
"""Planner statuses the command reports as refusals (exit 2)."""

BENCH_BEGIN = "<!-- bench: begin (written by eelbot plan --bench) -->"
BENCH_END = "<!-- bench: end -->"


def add_arrival_stop_option(p: argparse.ArgumentParser, when: str = "") -> None:
    """Add ``--arrival-stop-check/--no-arrival-stop-check`` (``eelbot plan``'s and ``run``'s).

    Parameters
    ----------
    p : argparse.ArgumentParser
    when : str
        Where the option applies, put before its help (``run``'s: "with --plan or --bench: ").
    """
    p.add_argument("--arrival-stop-check", dest="arrival_stop",
                   action=argparse.BooleanOptionalAction, default=True,
                   help=f"{when}the planner's check judges each run that arrives on through the "
                   "tank's stop there, its 3 s brake and the glide after it, with the check's "
                   "margin (default: %(default)s; --no-arrival-stop-check: the run ends where it "
                   "enters the goal disc; docs/planning.md, \"The arrival's stop in the check\")")


@COMMANDS.add("plan", "plan a path the twin swims without collision, or benchmark the planner")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "plan",
        help=COMMANDS.description("plan"),
        description="Plan with every manoeuvre swum in the calibrated twin (A*), check the plan "
        "in the twin over the coefficients' uncertainty, repair or refuse it. WORLD is a world "
        "TOML file, the bundled example 'tank_5_obstacles', or 'bench:SEED' (a generated "
        "benchmark world). Exit status: 0 plan found, 1 none found, 2 refused (blocked start, "
        "goal outside the tank or in an obstacle, current too strong, no corridor) or bad input.",
    )
    p.add_argument("world", nargs="?", help="world TOML file, 'tank_5_obstacles' or 'bench:SEED'")
    add_robot_options(p)
    add_coefficient_model_option(p)
    add_check_options(p)
    p.add_argument("--out", default="out/plan", help="output folder (default out/plan)")
    p.add_argument("--plot", action="store_true", help="write <out>/plan.png")
    p.add_argument("--replan", action="store_true",
                   help="also swim the plan in the twin with closed-loop replanning")
    p.add_argument("--threads", type=COUNT, default=1, help="threads of the batched twin")
    p.add_argument("--bench", action="store_true",
                   help="run the benchmark over --worlds generated worlds and print its figures")
    p.add_argument("--worlds", type=COUNT, default=100, help="benchmark worlds")
    p.add_argument("--budget", type=_budget, default=None, metavar="S",
                   help="with --bench: give each world's planning call a deadline S seconds "
                   "after it starts, its check included, as a replan at the tank has (default: "
                   "none); the figures count the calls that returned after it")
    p.add_argument("--seed", type=SEED, default=0, help="first benchmark world's seed")
    p.add_argument("--jobs", type=COUNT, default=1,
                   help="benchmark worlds planned at once, one process each")
    p.add_argument("--write", nargs="?", const="docs/planning.md", metavar="FILE",
                   help="with --bench, also rewrite the benchmark section of FILE (bare --write: "
                   "docs/planning.md)")
    p.set_defaults(run=run)


def add_coefficient_model_option(p: argparse.ArgumentParser) -> None:
    """--coefficients-file: fits and their uncertainty."""
    p.add_argument(
        "--coefficients-file", metavar="FILE",
        help="coefficients.json from 'eelbot report' (straight and turning fits with bootstrap "
        "std); default: the robot's coefficients with 10%% std (docs/planning.md)",
    )
    p.add_argument(
        "--allow-other-robot", action="store_true",
        help="use a coefficients file fitted on another robot than --robot (refused by default: "
        "its name, N or geometry differ)",
    )


def add_check_options(p: argparse.ArgumentParser) -> None:
    """The check's draws of the water: how many, the unknown current's bound, the seed."""
    p.add_argument("--draws", type=COUNT, default=CHECK_DRAWS,
                   help=f"draws of the water the plan is checked over (default {CHECK_DRAWS}; 0 "
                   "failures in n bound the collision probability by about 3/n)")
    p.add_argument("--unknown-current", type=_unknown_current, default=DEFAULT_UNKNOWN_CURRENT_M_S,
                   metavar="M_S",
                   help="bound of a current the planner is not told of, checked in every draw "
                   f"towards directions round the circle (default {DEFAULT_UNKNOWN_CURRENT_M_S} "
                   "m/s, a lab tank's residual flow; 0 to leave it out)")
    p.add_argument("--check-seed", type=SEED, default=0, help="seed of the check's draws")
    p.add_argument("--check-margin", type=_check_margin, default=CHECK_MARGIN_M, metavar="M",
                   help="every check run must keep the body this far from everything (default "
                   f"{CHECK_MARGIN_M} m: plans checked merely clear touched in fresh draws; 0 "
                   "for clear alone; docs/planning.md, \"The planner\")")
    add_arrival_stop_option(p)
    p.add_argument("--robust-search", action="store_true",
                   help="also swim every leg of the search in the unknown current (fewer plans "
                   "fail their check, about 4 times the search's time)")
    p.add_argument("--guidance", choices=GUIDANCE_CHOICES, default=PURSUIT.name,
                   help="the robot's guidance law for the search and the check (default: "
                   "%(default)s): "
                   + "; ".join(f"{name}: {text}" for name, text in GUIDANCE_LAWS.descriptions().items())
                   + f"; {AUTO_GUIDANCE}: {AUTO_HELP}"
                   + f" ({PLANNING_GUIDANCE.name} has the planner's stiffer heading gain; a plan "
                   "is followed with the law it was checked with: eelbot run --plan WORLD "
                   "--guidance ...; docs/planning.md, \"The guidance\")")


def _bounded(text: str, quantity: str, unit: str, high: float) -> float:
    """An option's number from 0 to ``high``, or argparse's error naming the quantity."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a {quantity} in {unit}, got {text!r}") from None
    if not 0.0 <= value <= high:
        raise argparse.ArgumentTypeError(f"expected a {quantity} from 0 to {high:g} {unit}, "
                                         f"got {text}")
    return value


def _unknown_current(text: str) -> float:
    return _bounded(text, "speed", "m/s", 1.0)


def _check_margin(text: str) -> float:
    return _bounded(text, "margin", "m", 0.5)


def _budget(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a budget above 0 s, got {text}")
    return value


def planner_options(args: argparse.Namespace) -> dict:
    """The Planner's keyword arguments for the check options on the command line."""
    return {"draws": getattr(args, "draws", CHECK_DRAWS),
            "unknown_current_m_s": getattr(args, "unknown_current", DEFAULT_UNKNOWN_CURRENT_M_S),
            "seed": getattr(args, "check_seed", 0),
            "check_margin_m": getattr(args, "check_margin", CHECK_MARGIN_M),
            "robust_search": getattr(args, "robust_search", False),
            "arrival_stop": getattr(args, "arrival_stop", True),
            "guidance": guidance_choice(getattr(args, "guidance", PURSUIT.name))}


def guidance_law(name: str) -> GuidanceLaw:
    """The planner's guidance law by name: ILOS with the planner's gains, or pure pursuit."""
    return PLANNING_GUIDANCE if name == PLANNING_GUIDANCE.name else GuidanceLaw(name)


def guidance_choice(name: str) -> GuidanceChoice:
    """The planner's ``guidance`` for ``--guidance``: one law, or ``auto``'s laws in turn."""
    return AUTO_LAWS if name == AUTO_GUIDANCE else guidance_law(name)


def describe_guidance(name: str) -> str:
    """One line on ``--guidance``'s choice, for a benchmark's figures."""
    if name == AUTO_GUIDANCE:
        return f"{AUTO_GUIDANCE}: " + AUTO_HELP
    return guidance_law(name).describe()


def coefficient_model(args: argparse.Namespace, robot: Robot) -> CoefficientModel:
    """The coefficient model chosen on the command line."""
    if getattr(args, "coefficients_file", None):
        return read_coefficient_model(args.coefficients_file, robot,
                                      getattr(args, "allow_other_robot", False))
    _, coeffs = robot_and_coefficients(args)
    return default_model(robot, coeffs)


def world_from_name(name: str) -> World:
    """A world file, a bundled example, or ``bench:SEED``."""
    m = re.fullmatch(r"bench:(\d+)", name)
    if m:
        return generate_world(int(m.group(1)))
    return load_world(name)


def plan_json(world: World, outcome: Outcome) -> dict:
    """What ``plan.json`` holds."""
    plan = outcome.plan
    return {
        "world": world.model_dump(mode="json"),
        "status": outcome.status,
        "message": outcome.message,
        "found": outcome.found,
        "cost_s": plan.cost_s if outcome.found else None,
        "expansions": plan.expansions,
        "simulations": plan.simulations,
        "planning_time_s": outcome.planning_time_s,
        "repairs": outcome.repairs,
        # the law the plan was searched and checked with, and those tried before it (auto)
        "guidance": outcome.guidance,
        "laws_tried": outcome.laws_tried,
        "check": _check_json(outcome),
        "waypoints_m": plan.waypoints_m if outcome.found else [],
        "legs": [
            {"waypoint_m": leg.waypoint_m, "distance_m": leg.distance_m,
             "bearing_deg": leg.bearing_deg, "goal": leg.goal,
             "min_clearance_m": leg.min_clearance_m}
            for leg in plan.legs
        ] if outcome.found else [],
        "checks": [
            {"coefficients": c.label, "reached": c.reached, "collision_free": c.collision_free,
             "min_clearance_m": c.min_clearance_m, "goal_time_s": c.goal_time_s,
             "goal_distance_m": c.goal_distance_m}
            for c in outcome.checks
        ],
    }


def _check_json(outcome: Outcome) -> dict:
    """The check's confidence: draws, failures, collision probability, arrival spread."""
    p, low, high = outcome.collision_probability
    median, t5, t95 = outcome.arrival_s

    def num(v: float) -> float | None:
        return None if v != v else v  # NaN: not checked

    return {"draws": outcome.draws,
            "failures": sum(outcome.failed(r) for r in outcome.drawn_checks),
            # a run within the margin of anything failed the check (docs/planning.md)
            "margin_m": outcome.margin_m,
            "collision_probability": num(p), "interval_95": [num(low), num(high)],
            # the interval is 95 % over every plan the repairs may check (Bonferroni): each
            # plan's own is taken at this level (docs/planning.md, "The planner", step 4)
            "interval_level": outcome.level, "plans_checked_at_most": outcome.family,
            "arrival_s": {"median": num(median), "p5": num(t5), "p95": num(t95)},
            "summary": outcome.confidence()}


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    robot, _ = robot_and_coefficients(args)
    model = coefficient_model(args, robot)
    # the robot's model, built once here and handed on (docs/architecture.md, "The planning room")
    swimmer = model.swimmer_for(robot)
    if args.bench:
        return _bench(args, robot, model, swimmer)
    if getattr(args, "budget", None) is not None:
        raise OptionError("--budget is for the benchmark: give it with --bench")
    if not args.world:
        raise OptionError("give a WORLD (or --bench)")
    world = world_from_name(args.world)
    out = check_output_folder(args.out)  # before the search, not after it
    options = planner_options(args)
    laws = laws_of(options.pop("guidance"))

    def planner_with(law: GuidanceLaw) -> Planner:
        return Planner(world, robot, model, threads=args.threads, swimmer=swimmer,
                       guidance=law, **options)

    with phase(f"plan {world.name}: search and check in the twin"):
        # with auto, the laws in turn until one's plan passes its check (docs/planning.md)
        planner, outcome = plan_with_laws(planner_with, laws)
    atomic_write(out / "plan.json", json.dumps(plan_json(world, outcome), indent=1))
    if outcome.status in REFUSALS:
        raise PlanRefused(outcome.status, f"{world.name}: {outcome.message}")
    print(f"{world.name}: {outcome.message} ({outcome.planning_time_s:.2f} s)")
    for k, leg in enumerate(outcome.plan.legs if outcome.found else []):
        print(f"  {k + 1:2d}. {leg.distance_m:.2f} m at {leg.bearing_deg:+4.0f} deg -> waypoint "
              f"({leg.waypoint_m[0]:.2f}, {leg.waypoint_m[1]:.2f}) m"
              + (" (goal)" if leg.goal else ""))
    print(f"guidance: {planner.options.guidance.describe()}"
          + (f" (chosen: {', '.join(t['law'] + ' ' + t['status'] for t in outcome.laws_tried)})"
             if outcome.laws_tried else ""))
    print(f"coefficients: {model.describe()}")
    coverage = action_coverage(planner.robot, model, planner.world.current.speed_m_s,
                               planner.settings, swimmer=swimmer)
    print(f"action coverage: {coverage.line()}")
    print(f"wrote {out / 'plan.json'}")
    if args.plot and outcome.found:
        from eelhost.planning.figures import plot_plan

        check = outcome.checks[0] if outcome.checks else None
        figure = plot_plan(world, outcome.plan, check, planner.model, out / "plan.png",
                           checks=outcome.checks)  # the title: the worst over every check
        print(f"wrote {figure}")
    if args.replan and outcome.found:
        from eelhost.planning.replan import execute_with_replanning

        run_ = execute_with_replanning(planner, model.fits["straight"])
        print(f"swum with replanning: {run_.message}")
    return 0 if outcome.found else 1


def _bench(args: argparse.Namespace, robot: Robot, model: CoefficientModel,
           swimmer: SwimmerModel) -> int:
    from eelhost.planning.bench import run_bench

    def progress(k: int, r) -> None:  # noqa: ANN001
        extra = ("" if r.reached is None else
                 f" reached={r.reached} collision={r.collision} "
                 f"clearance={r.min_clearance_m * 1000:.0f}mm")
        print(f"{k + 1:3d} {r.name}: {r.status} {r.planning_time_s:.2f} s "
              f"(cpu {r.cpu_time_s:.2f} s){extra}", flush=True)

    guidance = guidance_choice(args.guidance)
    # the coverage's runs steer with the same law (auto: the law it tries first)
    options = LoopOptions(guidance=laws_of(guidance)[0])
    summary = run_bench(robot, model, args.worlds, args.seed, args.threads, progress,
                        max(args.jobs, 1), args.unknown_current, guidance, swimmer,
                        args.budget, args.check_margin, args.arrival_stop)
    lines = summary.lines()
    lines += ["- action coverage (successful actions per current direction relative to the "
              "heading):"]
    coverage = [action_coverage(model.robot_for(robot), model, speed, options=options,
                                swimmer=swimmer) for speed in (0.0, 0.02, 0.04, 0.06)]
    lines += [f"  - {c.line()}" for c in coverage]
    command = (f"nice eelbot plan --bench --worlds {args.worlds} --seed {args.seed}"
               + (f" --threads {args.threads}" if args.threads != 1 else "")
               + (f" --jobs {args.jobs}" if args.jobs > 1 else "")
               + (f" --unknown-current {args.unknown_current:g}"
                  if args.unknown_current != DEFAULT_UNKNOWN_CURRENT_M_S else "")
               + (f" --guidance {args.guidance}" if args.guidance != PURSUIT.name else "")
               + (f" --budget {args.budget:g}" if args.budget is not None else "")
               + (f" --check-margin {args.check_margin:g}"
                  if args.check_margin != CHECK_MARGIN_M else ""))
    block = [
        BENCH_BEGIN,
        f"Command: `{command}`",
        "",
        f"- machine: {cpu_model()}, {os.cpu_count()} cores visible (shared with other work), "
        f"{args.threads} thread(s) of the batched twin, {max(args.jobs, 1)} world(s) at once; "
        f"Python {platform.python_version()}",
        f"- coefficients: {model.describe()}",
        f"- the check: the fits as fitted and {CHECK_DRAWS} draws of the water per plan (coefficients "
        f"jointly within the fit's 95 % region; unknown current {args.unknown_current:g} m/s, "
        "its directions stratified round the circle; each repair its own draws, "
        f"{REPAIR_DRAWS_FACTOR} times as many; every run "
        f"{args.check_margin * 1000:g} mm clear of everything); the fresh "
        "draws below keep 8 directions 45 degrees apart",
        f"- guidance: {describe_guidance(args.guidance)}",
        *lines,
        BENCH_END,
    ]
    print("\n".join(lines))
    if args.write:
        _write_block(Path(args.write), block)
        print(f"wrote {args.write}")
    return 0


def _write_block(path: Path, block: list[str]) -> None:
    """Replace the benchmark block of a markdown file (append it when absent)."""
    from eelhost.files import replace_marked_block

    replace_marked_block(path, BENCH_BEGIN, BENCH_END, "\n".join(block))
