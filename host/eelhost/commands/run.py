"""``eelbot run``: steer the robot (or the virtual robot) along waypoints and record the run."""

from __future__ import annotations

import argparse
import functools
import math
import os
import time
from pathlib import Path

from eelhost.commands import COMMANDS
from eelhost.commands.common import (
    COUNT,
    COUNT_OR_NONE,
    FINITE,
    NON_NEGATIVE,
    PORT,
    POSITIVE,
    SCENARIO_OPTIONS,
    SEED,
    OptionError,
    current_values,
    gait_values,
    rejected_as,
    waypoints,
)
from eelhost.commands.link_options import add_link_options, resolve_link_options
from eelhost.commands.plan import (
    AUTO_HELP,
    GUIDANCE_CHOICES,
    add_arrival_stop_option,
    add_coefficient_model_option,
    describe_guidance,
    guidance_choice,
    guidance_law,
)
from eelhost.errors import EXIT_CONTACT, EXIT_NOT_REACHED, EXIT_OK
from eelhost.field.recorder import MOTIONS
from eelhost.field.runloop import BRAKE_S, RunConfig
from eelhost.field.session import TakeNotes
from eelhost.field.take import TakeRequest, ViewOpener, refuse_overwrite, run_take
from eelhost.files import check_output_stem
from eelhost.link.uri import parse_link_uri
from eelhost.planning.planner import AUTO_GUIDANCE
from eelhost.planning.replan import CALM_REPLAN_BUDGET_S, EARLY_MARGIN_M
from eelhost.planning.restart import RESTARTS
from eelhost.progress import phase
from eelhost.vision.markerfile import load_marker_file
from eelhost.web.liveview import LiveView
from eelsim.control import BRAKE_AMPLITUDE_RAD, Gait
from eelsim.guidance import PURSUIT
from eelsim.robot import Robot, load_robot


@COMMANDS.add("run", "steer the robot along waypoints from the camera, and record the run")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "run",
        help=COMMANDS.description("run"),
        description="Localise the robot in the camera frames, send the heading offset every "
        "control period, record every pose, frame and command (<out>.csv, .json, .frames.csv, "
        ".commands.csv, .rx.bin, and copies of the robot file and calibration). Stops the robot "
        "on Ctrl-C, SIGTERM or SIGHUP, when it is out of view for more than 1 s, when nothing "
        "comes from it for 1 s, at the last waypoint and after --duration. "
        "Example: eelbot run --link sim:// --waypoints '0.43,0.25;0.93,0.25;1.37,0.5' "
        "--gait 0.87,3.9 --k-theta 0.37 --out out/run/path1 --speed 0",
    )
    add_link_options(p, "required unless --bench")
    p.add_argument(
        "--camera",
        metavar="SOURCE",
        help="camera index, video file or image folder; for sim:// 'synthetic' (default, with "
        "noise and JPEG) or 'synthetic:clean' (blur only, faster)",
    )
    p.add_argument("--calibration", metavar="FILE", help="calibration JSON (docs/vision.md); "
                   "with the synthetic camera, localise with it instead of the exact one")
    p.add_argument("--markers", metavar="FILE", help="markers.json from eelbot markers "
                   "(default: ids 0..N-1, tail first)")
    p.add_argument("--waypoints", metavar="x,y;x,y", type=waypoints, help="waypoints, m (or --plan)")
    p.add_argument(
        "--plan",
        metavar="WORLD",
        help="plan in WORLD (world TOML, 'tank_5_obstacles' or 'bench:SEED') from its start, "
        "follow the plan and replan when the robot leaves the planned corridor "
        "(docs/planning.md); a sim:// robot is put at the world's start in its current. "
        "The planner runs beside the control loop; the run stops (exit 6) if the body touches "
        "an obstacle, or (exit 1) when replanning finds no safe continuation",
    )
    add_coefficient_model_option(p)
    p.add_argument(
        "--gait",
        metavar="A,omega[,beta]",
        type=gait_values,
        help="gait amplitude (rad), frequency (rad/s), optionally phase shift (rad, 1.04)",
    )
    p.add_argument("--k-theta", type=FINITE, default=0.37, help="heading gain")
    p.add_argument("--radius", type=POSITIVE, default=0.15, help="acceptance radius, m")
    p.add_argument("--control-period", type=POSITIVE, default=0.3, help="offset period, s")
    p.add_argument("--replan-budget", type=NON_NEGATIVE, default=1.0, metavar="S",
                   help="with --plan or --bench: each replan's wall-clock budget from its "
                   "request; its searches stop there and it returns what it has (1.0 s; 0: no "
                   "deadline; docs/planning.md, \"The replan's deadline\")")
    p.add_argument("--calm-budget", type=NON_NEGATIVE, default=CALM_REPLAN_BUDGET_S, metavar="S",
                   help="with --plan or --bench and a --replan-budget: the budget of a replan "
                   "asked for in a moved current estimate while the robot is on its plan; a "
                   "replan on leaving the corridor or a predicted contact cuts it short (3.0 s; "
                   "0: the --replan-budget; docs/planning.md, \"Calm replans get more time\")")
    p.add_argument("--early-margin", type=NON_NEGATIVE, default=0.0, metavar="M",
                   help="with --plan or --bench: a look-ahead that swims the planner's capsule "
                   "within this of an obstacle or wall (but not within its 10 mm) asks for an "
                   f"early replan, whose failure keeps the plan (0: off, the default; "
                   f"{EARLY_MARGIN_M:g} m is the value developed; it gained no goal on unseen "
                   "seeds: docs/planning.md, \"An earlier replan\")")
    p.add_argument("--escape", action="store_true",
                   help="with --plan or --bench: a replan from a start whose body is inside the "
                   "check's margin (but more than 10 mm clear) plans an escape whose margin "
                   "ramps from the start's gap to the full margin over 4 s (off by default: "
                   "no such start on its development seeds; docs/planning.md, \"An escape from "
                   "inside the margin\")")
    p.add_argument("--restarts", type=COUNT_OR_NONE, default=RESTARTS, metavar="N",
                   help="with --plan or --bench: where no safe swimming continuation is left, "
                   "stop the gait (amplitude 0), let the robot drift towards rest and restart on "
                   f"a plan from rest, at most N times per run ({RESTARTS}, the default: on its "
                   "development seeds it reached 2 more goals with no contact; 0: off; "
                   "docs/planning.md, \"A restart from rest\")")
    p.add_argument("--harbour", action=argparse.BooleanOptionalAction, default=True,
                   help="with --plan or --bench: before a stop the twin drifts into an obstacle "
                   "(a current towards it), first swim a short harbour swim to where the stop "
                   "stays clear (default: %(default)s; --no-harbour: stop where the stop is "
                   "decided; docs/planning.md, \"The harbour\")")
    p.add_argument("--station", action=argparse.BooleanOptionalAction, default=False,
                   help="with --plan or --bench: where the stop (no safe continuation, a "
                   "failed pause, a harbour's end, the arrival) would drift into an obstacle "
                   "with no harbour, swim into the current (holding station) while the twin "
                   "swims that clear, replanning, until a plan or a clear stop (default: "
                   "%(default)s: on development seeds 39000-39099 no such stop had a station "
                   "swim either; docs/planning.md, \"Holding station (session 21)\")")
    p.add_argument("--least-bad", action=argparse.BooleanOptionalAction, default=True,
                   help="with --plan or --bench: where the stop (no safe continuation, a "
                   "failed pause, a harbour's end) would drift into an obstacle with no "
                   "harbour, station or hold, swim a short swim the twin keeps clear for 1.5 s "
                   "towards a stop 10 mm clearer, judged again every 0.5 s, replanning, until "
                   "a plan or a clear stop (default: %(default)s; --no-least-bad: the stop as "
                   "decided; docs/planning.md, \"The least-bad swim (session 24)\")")
    p.add_argument("--brake", type=NON_NEGATIVE, default=None, metavar="S",
                   help="before the final Stop, freeze the body in a deep S (the gait's "
                   f"amplitude {BRAKE_AMPLITUDE_RAD:g} rad, omega 0) for S seconds, the watchdog fed, so that it does "
                   f"not glide on straight (default {BRAKE_S:g} s with --plan or --bench, 0 "
                   "otherwise; 0: Stop at once; docs/planning.md, \"The brake before the Stop\")")
    p.add_argument("--guidance", choices=GUIDANCE_CHOICES, default=PURSUIT.name,
                   help="the line-of-sight law that steers the robot: pursuit (the paper's pure "
                   "pursuit of each waypoint), ilos (integral line-of-sight along each "
                   "leg with the planner's gains), pursuit_ff (pure pursuit aimed off by the "
                   "current the planner knows; with --plan or --bench only) or auto (with --plan "
                   "or --bench only: " + AUTO_HELP + "); with --plan or "
                   "--bench the planner searches and checks with the same law (default: "
                   "%(default)s; docs/planning.md, \"The guidance\")")
    p.add_argument("--duration", type=POSITIVE, help="stop after this long, s (default: no limit)")
    p.add_argument("--motion", choices=MOTIONS, default="auto",
                   help="what the take is, for a dataset: straight, turning, path, or auto "
                   "(path for several waypoints; one waypoint within 10 deg of the start heading "
                   "is straight, else turning)")
    p.add_argument(
        "--speed",
        type=NON_NEGATIVE,
        help="sim:// only: simulated s per wall s, 0 = as fast as possible (overrides the URI)",
    )
    add_take_options(p)
    p.add_argument("--out", metavar="STEM", help="output path without extension (with --bench: "
                   "the folder of results.jsonl, default out/run_bench)")
    p.add_argument("--force", action="store_true", help="replace an existing take at --out")
    b = p.add_argument_group("closed-loop benchmark (docs/planning.md)")
    b.add_argument("--bench", action="store_true",
                   help="plan --worlds generated worlds and swim each plan over sim:// in water "
                   "the planner does not know, replanning in real time; resumes from --out")
    b.add_argument("--worlds", type=COUNT, default=100, help="benchmark worlds (100)")
    b.add_argument("--seed", type=SEED, default=BENCH_SEED,
                   help=f"first benchmark world's seed ({BENCH_SEED})")
    b.add_argument("--check-unknown-current", type=NON_NEGATIVE, metavar="M_S",
                   help="with --plan or --bench: the unknown current the planner's check "
                   "allows for, as eelbot plan's --unknown-current (default: the planner's, "
                   "0.02 m/s); a --bench world's water still has up to 0.02 m/s")
    add_arrival_stop_option(b, "with --plan or --bench: ")
    b.add_argument("--write", nargs="?", const="docs/planning.md", metavar="FILE",
                   help="with --bench, also rewrite its section of FILE (bare: docs/planning.md)")
    p.set_defaults(run=run)


def add_take_options(p: argparse.ArgumentParser) -> None:
    """What a take records beyond the task, and the live view (shared with ``campaign``)."""
    p.add_argument("--note", default="", help="operator's note, kept in the record")
    p.add_argument("--current", metavar="SPEED,DIR",
                   type=current_values,
                   help="the water's current if known: m/s, direction in degrees (sim:// has "
                   "its own)")
    p.add_argument("--no-view", action="store_true",
                   help="no live view (headless); by default a web page on localhost shows the "
                   "camera, the markers, the track, the waypoints and the twin's prediction")
    p.add_argument("--view-port", type=PORT, default=8765,
                   help="port of the live view on 127.0.0.1 (8765; 0: any free port)")


def view_opener(args: argparse.Namespace, twin: Robot | None = None,
                current: tuple[float, float] | None = None) -> ViewOpener | None:
    """The live view a take opens (``--view-port``), or None with ``--no-view``.

    Parameters
    ----------
    args : argparse.Namespace
        The command's options.
    twin : Robot, optional
        The robot its prediction swims (a planned run's model), default the robot file's.
    current : (float, float), optional
        The current its prediction swims in, as (speed m/s, direction deg towards).
    """
    if args.no_view:
        return None
    speed, towards = current if current is not None else (0.0, 0.0)
    flow = (speed * math.cos(math.radians(towards)), speed * math.sin(math.radians(towards)))
    return functools.partial(LiveView, port=args.view_port, twin=twin, current_m_s=flow)


BENCH_SEED = 5000
"""First seed of the closed-loop benchmark: a range no planner setting was developed on."""
BENCH_BEGIN = "<!-- run-bench: begin (written by eelbot run --bench) -->"
BENCH_END = "<!-- run-bench: end -->"

# Ends that are not failures: arrived, ran its --duration, or stopped by the operator (a signal).
STOPPED_ON_PURPOSE = ("arrived", "duration", "interrupted")


def exit_status(reason: str) -> int:
    """0 for an end on purpose, 6 for a contact (docs/cli.md), else 1."""
    if reason in STOPPED_ON_PURPOSE:
        return EXIT_OK
    return EXIT_CONTACT if reason == "contact" else EXIT_NOT_REACHED


def _planner_options(args: argparse.Namespace) -> dict:
    """The planner's options of ``eelbot run --plan`` and ``--bench``.

    The guidance law (``auto``: the laws tried in turn), and the check's unknown current when
    ``--check-unknown-current`` is given (else the planner's default).
    """
    options: dict = {"guidance": guidance_choice(args.guidance)}
    if not args.arrival_stop:
        options["arrival_stop"] = False
    if args.check_unknown_current is not None:
        options["unknown_current_m_s"] = args.check_unknown_current
    return options


def _brake_s(args: argparse.Namespace) -> float:
    """``--brake``, or its default: :data:`BRAKE_S` for a planned run or the bench, else 0."""
    if args.brake is not None:
        return float(args.brake)
    return BRAKE_S if (args.plan is not None or args.bench) else 0.0


def _gait(values: list[float], k_theta: float) -> Gait:
    """The gait of ``--gait`` (checked against the robot's ranges when parsed), beta 1.04 rad."""
    beta = values[2] if len(values) == 3 else 1.04
    return Gait(values[0], values[1], beta, k_theta)


def current_option(value: list[float] | None, virtual: bool) -> tuple[float, float] | None:
    """The ``--current`` as (speed, direction), refused for ``sim://`` (its URI sets it)."""
    if value is None:
        return None
    if virtual:
        raise OptionError("--current: a sim:// robot's current is set in its URI (current=)")
    return (value[0], value[1])  # a negative speed is refused when parsed (current_values)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    resolve_link_options(args, required=None if args.bench else "to run")
    if args.bench:
        return _bench(args)
    if args.out is None:
        raise OptionError("--out: required (the take's path without extension)")
    parse_link_uri(args.link)  # a bad URI is reported before anything is opened
    robot = load_robot(args.robot_file)
    markers = load_marker_file(args.markers)
    if (args.waypoints is None) == (args.plan is None):
        raise OptionError("give either --waypoints or --plan WORLD")
    if args.gait is None and args.plan is None:
        raise OptionError("--gait: required with --waypoints")
    if args.coefficients_file is not None and args.plan is None:
        raise OptionError("--coefficients-file: only with --plan (the planner's model)")
    if args.plan is None and args.guidance == AUTO_GUIDANCE:
        raise OptionError(f"--guidance {AUTO_GUIDANCE}: only with --plan or --bench (the planner "
                          "chooses the law per plan)")
    if args.plan is None and guidance_law(args.guidance).feed_forward:
        raise OptionError(f"--guidance {args.guidance}: only with --plan or --bench (the planner "
                          "gives it the known current and the robot's speed)")
    current = current_option(args.current, args.link.startswith("sim:"))
    check_output_stem(args.out)  # a read-only folder or a file is said before the link opens
    refuse_overwrite(args.out, args.force)
    navigator = None
    view = None
    uri = args.link
    # with --plan the plan's law replaces it (auto: the law the plan was found with)
    law = PURSUIT if args.guidance == AUTO_GUIDANCE else guidance_law(args.guidance)
    start_guide = None
    view_twin, view_current = None, current
    if args.plan is not None:
        from eelhost.commands.plan import world_from_name
        from eelhost.planning.tank import plan_for_run
        from eelhost.planning.uncertainty import default_model, read_coefficient_model
        from eelhost.vision.synthetic import TankView
        from eelsim.scenario import PATH_GAIT

        gait = PATH_GAIT if args.gait is None else _gait(args.gait, args.k_theta)
        world = world_from_name(args.plan)
        # the fitted model as eelbot plan reads it (law, joints, current), or the robot file's
        model = (read_coefficient_model(args.coefficients_file, robot)
                 if args.coefficients_file else default_model(robot))
        # the robot's model, built once here and handed to the planner, its twin, search and
        # check, and every replan (docs/architecture.md, "The planning room")
        swimmer = model.swimmer_for(robot)
        with phase(f"plan {world.name}: search and check in the twin"):
            planned = plan_for_run(world, robot, args.link, gait, coefficients=model,
                                   acceptance_radius_m=args.radius, swimmer=swimmer,
                                   planner_options=_planner_options(args),
                                   replan_budget_s=args.replan_budget or None,
                                   calm_budget_s=args.calm_budget or None,
                                   early_margin_m=args.early_margin or None,
                                   escape=args.escape, restarts=args.restarts,
                                   harbour=args.harbour, stop_brake_s=_brake_s(args),
                                   station=args.station, least_bad=args.least_bad)
        print(planned.outcome.message)
        print(f"guidance: {planned.guidance.describe()}")
        print(f"coefficients: {model.describe()}")
        waypoints, navigator, uri = planned.waypoints_m, planned.navigator, planned.uri
        start_guide = planned.start_guide
        law = planned.guidance  # as the planner filled it in (a feed-forward's water)
        view = TankView.covering(world.tank.size_m)
        # the live view predicts with the planner's model, in the current the planner knows
        tank_world = model.in_tank(world)
        view_twin = model.robot_for(robot)
        view_current = (tank_world.current.speed_m_s, tank_world.current.direction_deg)
    else:
        waypoints = args.waypoints
        gait = _gait(args.gait, args.k_theta)
    config = RunConfig(
        gait,
        waypoints,
        acceptance_radius_m=args.radius,
        control_period_s=args.control_period,
        duration_s=args.duration,
        guidance=law,
        start_guide=start_guide,
        brake_s=_brake_s(args),
    )
    notes = TakeNotes(uri, args.robot_file, args.motion, current, args.note)
    request = TakeRequest(robot, config, args.out, notes, args.camera, args.calibration,
                          markers.layout, args.speed, navigator, view)
    with rejected_as("--waypoints/--gait/--radius/--duration", SCENARIO_OPTIONS):
        result = run_take(request, view_opener(args, view_twin, view_current),
                          announce=lambda msg: print(msg, flush=True))
    out = result.outcome
    print(
        f"{out.reason}: {out.detail}; {out.waypoints_reached}/{len(waypoints)} waypoints, "
        f"{out.frames_with_pose}/{out.frames} frames with a pose, {out.offsets_sent} offsets, "
        + (f"braked {out.braked_s:.1f} s, " if out.braked_s else "")
        + f"Stop {out.stop_outcome}"
    )
    if result.virtual and result.wall_s > 0:
        print(f"simulated {out.t_end_s:.1f} s in {result.wall_s:.1f} s "
              f"({out.t_end_s / result.wall_s:.1f}x real time)")
    if navigator is not None:
        print(f"replans: {navigator.tally()}")
        if out.failsafe_reports:
            print(f"the robot reported FAILSAFE {out.failsafe_reports} times")
    print("wrote " + ", ".join(str(path) for path in result.paths))
    return exit_status(out.reason)


def _bench(args: argparse.Namespace) -> int:
    """``eelbot run --bench``: the closed-loop benchmark (docs/planning.md)."""
    from eelhost.benchmarks.closed_loop import run_closed_loop_bench, summary_lines
    from eelhost.machine import cpu_model
    from eelhost.planning.uncertainty import default_model, read_coefficient_model
    from eelhost.progress import Progress

    robot = load_robot(args.robot_file)
    model = (read_coefficient_model(args.coefficients_file, robot)
             if args.coefficients_file else default_model(robot))
    out = Path(args.out or "out/run_bench")
    seeds = range(args.seed, args.seed + args.worlds)
    done_file = out / "results.jsonl"
    resumed = len(done_file.read_text().splitlines()) if done_file.exists() else 0
    wall0 = time.monotonic()
    with Progress("run --bench", len(seeds), "world") as bar:

        def show(r) -> None:  # noqa: ANN001
            print(f"seed {r.seed}: {r.status}" + (
                f", {r.reason}, reached={r.reached}, contact={r.contact}, clearance "
                f"{(r.min_clearance_m or 0) * 1000:.0f} mm, failsafe {r.failsafe_reports}, "
                f"replans {r.replans} (+{r.failed_replans} failed)" if r.planned else ""),
                flush=True)
            bar.update(1)

        options = _planner_options(args)
        results = run_closed_loop_bench(robot, model, seeds, out, show, options,
                                        model.swimmer_for(robot), args.replan_budget or None,
                                        calm_budget_s=args.calm_budget or None,
                                        early_margin_m=args.early_margin or None,
                                        escape=args.escape, restarts=args.restarts,
                                        brake_s=_brake_s(args), harbour=args.harbour,
                                        station=args.station, least_bad=args.least_bad)
    command = (f"nice eelbot run --bench --worlds {args.worlds} --seed {args.seed}"
               + ("" if args.arrival_stop else " --no-arrival-stop-check")
               + ("" if args.check_unknown_current is None
                  else f" --check-unknown-current {args.check_unknown_current:g}")
               + (f" --coefficients-file {args.coefficients_file}" if args.coefficients_file
                  else "")
               + (f" --guidance {args.guidance}" if args.guidance != PURSUIT.name else "")
               + (f" --replan-budget {args.replan_budget:g}" if args.replan_budget != 1.0
                  else "")
               + (f" --calm-budget {args.calm_budget:g}"
                  if args.calm_budget != CALM_REPLAN_BUDGET_S else "")
               + (f" --early-margin {args.early_margin:g}" if args.early_margin else "")
               + (" --escape" if args.escape else "")
               + (f" --restarts {args.restarts}" if args.restarts != RESTARTS else "")
               + ("" if args.harbour else " --no-harbour")
               + (" --station" if args.station else "")
               + ("" if args.least_bad else " --no-least-bad")
               + (f" --brake {args.brake:g}" if args.brake is not None else ""))
    lines = summary_lines(results)
    block = [BENCH_BEGIN, f"Command: `{command}`", "",
             f"- machine: {cpu_model()}, {os.cpu_count()} cores visible (shared with other "
             f"work); this run took {time.monotonic() - wall0:.0f} s of wall time"
             + (f" after reading {resumed} worlds' results back from {done_file}" if resumed
                else ""),
             f"- coefficients of the planner: {model.describe()}",
             f"- guidance (planner and run loop): {describe_guidance(args.guidance)}",
             *lines, BENCH_END]
    print("\n".join(lines))
    if args.write:
        _write_section(Path(args.write), block)
        print(f"wrote {args.write}")
    return 0


def _write_section(path: Path, block: list[str]) -> None:
    """Replace the run benchmark's block of a markdown file (append it when absent)."""
    from eelhost.files import replace_marked_block

    replace_marked_block(path, BENCH_BEGIN, BENCH_END, "\n".join(block))
