"""``eelbot simulate``: run a scenario in the twin and write its trajectory (and figures)."""

from __future__ import annotations

import argparse
from pathlib import Path

from eelhost.commands import COMMANDS
from eelhost.commands.common import (
    FINITE,
    POSITIVE,
    SCENARIO_OPTIONS,
    SEED,
    add_loop_options,
    add_robot_options,
    current_values,
    gait_values,
    loop_options,
    rejected_as,
    robot_and_coefficients,
    waypoints,
)
from eelhost.errors import exit_status_for_flag
from eelhost.files import check_output_stem
from eelhost.progress import Progress
from eelsim.closed_loop import simulate_closed_loop
from eelsim.model import SwimmerModel
from eelsim.record import write_run
from eelsim.scenario import load_scenario


@COMMANDS.add("simulate", "run a scenario in the twin and write its trajectory")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "simulate",
        help=COMMANDS.description("simulate"),
        description="Run a named scenario (straight, turning, path1, path2, "
        "straight_A0.61_w2.7, ...) "
        "or a scenario TOML file in the closed-loop twin; write <out>.csv and <out>.json, and "
        "optionally a PNG (--plot) and a GIF (--animate).",
    )
    p.add_argument("scenario", help="scenario name or .toml file")
    add_robot_options(p)
    g = p.add_argument_group("scenario overrides")
    g.add_argument(
        "--gait",
        metavar="A,omega[,beta]",
        type=gait_values,
        help="gait amplitude (rad), frequency (rad/s) and optionally phase shift (rad)",
    )
    g.add_argument("--k-theta", type=FINITE, help="heading controller gain")
    g.add_argument("--waypoints", metavar="x,y;x,y", type=waypoints, help="waypoints, m")
    g.add_argument(
        "--current",
        metavar="speed,direction_deg",
        type=current_values,
        help="current speed (m/s) and the direction it flows towards (deg)",
    )
    g.add_argument("--duration", type=POSITIVE, help="T_max, s")
    g.add_argument(
        "--full", action="store_true", help="run until T_max even after the last waypoint"
    )
    add_loop_options(p)
    p.add_argument("--seed", type=SEED, default=0, help="seed of jitter and noise")
    p.add_argument("--out", default="out/simulate/run", help="output path without extension")
    p.add_argument(
        "--plot", action="store_true", help="write <out>.png (path, x(t), y(t), heading)"
    )
    p.add_argument("--animate", action="store_true", help="write <out>.gif of the swimming robot")
    p.set_defaults(run=run)


def _overrides(args: argparse.Namespace) -> dict:
    upd: dict = {}
    if args.gait:
        upd["amplitude_rad"], upd["omega_rad_s"] = args.gait[:2]
        if len(args.gait) == 3:
            upd["beta_rad"] = args.gait[2]
    if args.k_theta is not None:
        upd["k_theta"] = args.k_theta
    if args.waypoints:
        upd["waypoints_m"] = args.waypoints
    if args.current:
        upd["current_speed_m_s"], upd["current_direction_deg"] = args.current
    if args.duration is not None:
        upd["duration_s"] = args.duration
    return upd


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    robot, coeffs = robot_and_coefficients(args)
    scenario = load_scenario(args.scenario)
    check_output_stem(args.out, (".csv", ".json", ".png", ".gif"))  # before the run, not after
    with rejected_as("scenario overrides", SCENARIO_OPTIONS):
        upd = _overrides(args)
        if upd:
            scenario = type(scenario).model_validate({**scenario.model_dump(), **upd})
    options = loop_options(args, stop_at_goal=not args.full)
    with Progress(scenario.name, scenario.total_steps(options.timing.dt_s), "step") as bar:
        result = simulate_closed_loop(
            robot,
            scenario,
            options,
            seed=args.seed,
            coefficients=coeffs,
            progress=lambda step, _total: bar.set(step),
        )
        if result.arrival_time_s is not None:
            bar.finish()  # the run ends at the goal: its task is done
    csv_path, json_path = write_run(result, robot, scenario, options, args.seed, args.out, coeffs)
    outcome = "reached the last waypoint" if result.arrival_time_s is not None else "did not arrive"
    print(
        f"{scenario.name}: {outcome}; flag {result.failure.name}"
        + (f" at t = {result.failure_time_s:.2f} s ({result.reason})" if result.reason else "")
        + (f"; arrival {result.arrival_time_s:.2f} s" if result.arrival_time_s is not None else "")
    )
    if result.saturated_steps:
        print(
            f"warning: at {result.saturated_steps} of {len(result.t_s)} steps a joint needed more "
            f"torque than the servo's torque-speed line allows (largest |u| "
            f"{result.max_torque_ratio:.2f} x the stall torque; docs/model.md section 4)"
        )
    print(f"wrote {csv_path} and {json_path}")
    if args.plot or args.animate:
        from eelhost.plots import animate_run, plot_run

        model = SwimmerModel.from_robot(robot, coeffs)
        if args.plot:
            print(f"wrote {plot_run(result, model, scenario, Path(args.out).with_suffix('.png'))}")
        if args.animate:
            print(
                f"wrote {animate_run(result, model, scenario, Path(args.out).with_suffix('.gif'))}"
            )
    return exit_status_for_flag(result.failure)
