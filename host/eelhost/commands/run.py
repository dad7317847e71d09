"""``eelbot run``: steer the robot (or the virtual robot) along waypoints and record the run."""

from __future__ import annotations

import argparse
import signal
import time

from eelhost.commands.common import (
    FINITE,
    NON_NEGATIVE,
    POSITIVE,
    SCENARIO_OPTIONS,
    OptionError,
    gait_values,
    rejected_as,
    waypoints,
)
from eelhost.field.runloop import RunConfig
from eelhost.field.session import TankSession, open_camera, virtual_robot
from eelhost.link.base import LinkEvent
from eelhost.link.uri import open_link, parse_link_uri
from eelhost.progress import Progress
from eelsim.control import Gait
from eelsim.robot import load_robot


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "run",
        help="steer the robot along waypoints from the camera, and record the run",
        description="Localise the robot in the camera frames, send the heading offset every "
        "control period, record every pose and command (<out>.csv, .json, .commands.csv, "
        ".rx.bin). Stops the robot on Ctrl-C, when it is out of view for more than 1 s, when "
        "nothing comes from it for 1 s, at the last waypoint and after --duration. "
        "Example: eelbot run --robot sim:// --waypoints '0.43,0.25;0.93,0.25;1.37,0.5' "
        "--gait 0.87,3.9 --k-theta 0.37 --out out/run/path1 --speed 0",
    )
    p.add_argument(
        "--robot",
        required=True,
        metavar="URI",
        help="serial:///dev/ttyUSB0?baud=57600, sim://?speed=1&seed=0, replay:///path/run.rx.bin",
    )
    p.add_argument(
        "--camera",
        metavar="SOURCE",
        help="camera index, video file or image folder; for sim:// 'synthetic' (default, with "
        "noise and JPEG) or 'synthetic:clean' (blur only, faster)",
    )
    p.add_argument("--calibration", metavar="FILE", help="calibration JSON (docs/vision.md)")
    p.add_argument("--robot-file", metavar="FILE", help="robot TOML (default: the paper robot)")
    p.add_argument(
        "--waypoints", required=True, metavar="x,y;x,y", type=waypoints, help="waypoints, m"
    )
    p.add_argument(
        "--gait",
        required=True,
        metavar="A,omega[,beta]",
        type=gait_values,
        help="gait amplitude (rad), frequency (rad/s), optionally phase shift (rad, 1.04)",
    )
    p.add_argument("--k-theta", type=FINITE, default=0.37, help="heading gain")
    p.add_argument("--radius", type=POSITIVE, default=0.15, help="acceptance radius, m")
    p.add_argument("--control-period", type=POSITIVE, default=0.3, help="offset period, s")
    p.add_argument("--duration", type=POSITIVE, help="stop after this long, s (default: no limit)")
    p.add_argument(
        "--speed",
        type=NON_NEGATIVE,
        help="sim:// only: simulated s per wall s, 0 = as fast as possible (overrides the URI)",
    )
    p.add_argument("--out", required=True, metavar="STEM", help="output path without extension")
    p.set_defaults(run=run)


def _gait(values: list[float], k_theta: float) -> Gait:
    """The gait of ``--gait`` (checked against the robot's ranges when parsed), beta 1.04 rad."""
    beta = values[2] if len(values) == 3 else 1.04
    return Gait(values[0], values[1], beta, k_theta)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    parse_link_uri(args.robot)  # a bad URI is reported before anything is opened
    robot = load_robot(args.robot_file)
    waypoints = args.waypoints
    gait = _gait(args.gait, args.k_theta)
    link = open_link(args.robot, robot=robot)
    virtual = virtual_robot(link)
    if args.speed is not None:
        if virtual is None:
            raise OptionError("--speed: only a sim:// robot can run faster than real time")
        virtual.clock.speed = args.speed
    camera = open_camera(link, robot, args.camera, args.calibration)
    config = RunConfig(
        gait,
        waypoints,
        acceptance_radius_m=args.radius,
        control_period_s=args.control_period,
        duration_s=args.duration,
    )
    with rejected_as("--waypoints/--gait/--radius/--duration", SCENARIO_OPTIONS):
        session = TankSession(link, camera, robot, config, args.out, args.robot)
    previous = signal.signal(signal.SIGINT, lambda *_: session.loop.request_stop("interrupted"))
    wall0 = time.monotonic()
    loop = session.loop
    try:
        with Progress("run", len(waypoints), "waypoint") as bar:

            def show(_event: LinkEvent) -> None:  # at each command sent: every control period
                bar.set_postfix(t=f"{loop.outcome.t_end_s:.0f} s")
                bar.set(loop.target)

            session.link.listeners.append(show)
            out = session.run()
    finally:
        signal.signal(signal.SIGINT, previous)
    wall = time.monotonic() - wall0
    print(
        f"{out.reason}: {out.detail}; {out.waypoints_reached}/{len(waypoints)} waypoints, "
        f"{out.frames_with_pose}/{out.frames} frames with a pose, {out.offsets_sent} offsets, "
        f"Stop {out.stop_outcome}"
    )
    if virtual is not None and wall > 0:
        print(
            f"simulated {out.t_end_s:.1f} s in {wall:.1f} s ({out.t_end_s / wall:.1f}x real time)"
        )
    print("wrote " + ", ".join(str(path) for path in session.paths))
    return 0 if out.reason in ("arrived", "duration", "interrupted") else 1
