"""``eelbot run``: steer the robot (or the virtual robot) along waypoints and record the run."""

from __future__ import annotations

import argparse
import math
import re
import signal
import time
from collections.abc import Iterable
from pathlib import Path

from eelhost.commands.common import floats
from eelhost.field.recorder import Recorder
from eelhost.field.runloop import RunConfig, RunLoop
from eelhost.link.base import Link
from eelhost.link.replay_transport import RxLogWriter
from eelhost.link.sim_transport import SimTransport, VirtualCamera
from eelhost.link.uri import open_link, parse_link_uri
from eelhost.vision.calibration import load_calibration
from eelhost.vision.localise import Localiser
from eelhost.vision.sources import CameraSource, open_source
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
from eelsim.control import Gait
from eelsim.robot import Robot, load_robot
from eelsim.scenario import Scenario

SYNTHETIC = ("synthetic", "synthetic:clean")


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
    p.add_argument("--waypoints", required=True, metavar="x,y;x,y", help="waypoints, m")
    p.add_argument(
        "--gait",
        required=True,
        metavar="A,omega[,beta]",
        type=lambda s: floats(s, None, "--gait"),
        help="gait amplitude (rad), frequency (rad/s), optionally phase shift (rad, 1.04)",
    )
    p.add_argument("--k-theta", type=float, default=0.37, help="heading gain (default 0.37)")
    p.add_argument("--radius", type=float, default=0.15, help="acceptance radius, m (0.15)")
    p.add_argument("--control-period", type=float, default=0.3, help="offset period, s (0.3)")
    p.add_argument("--duration", type=float, help="stop after this long, s (default: no limit)")
    p.add_argument(
        "--speed",
        type=float,
        help="sim:// only: simulated s per wall s, 0 = as fast as possible (overrides the URI)",
    )
    p.add_argument("--out", required=True, metavar="STEM", help="output path without extension")
    p.set_defaults(run=run)


def parse_waypoints(text: str) -> list[tuple[float, float]]:
    """Parse ``"x,y;x,y"`` into waypoints (metres)."""
    out = []
    for part in text.split(";"):
        if part.strip():
            x, y = floats(part, 2, "--waypoints")
            out.append((x, y))
    if not out:
        raise ValueError("--waypoints: give at least one x,y")
    return out


def _gait(values: list[float], k_theta: float) -> Gait:
    if len(values) not in (2, 3):
        raise ValueError("--gait: give A,omega or A,omega,beta")
    beta = values[2] if len(values) == 3 else 1.04
    return Gait(values[0], values[1], beta, k_theta)


def _frames(args: argparse.Namespace, link: Link, robot: Robot) -> tuple[Iterable, Localiser, dict]:
    """The frame source, its localiser and the camera facts to record."""
    spec = args.camera
    if isinstance(link.transport, SimTransport):
        spec = spec or "synthetic"
        if spec in SYNTHETIC:
            options = (
                RenderOptions(noise_sigma=0.0, jpeg_quality=0) if spec.endswith("clean") else None
            )
            cam = SyntheticCamera(robot, options=options, seed=0)
            source = VirtualCamera(link.transport.robot, cam, keep_truth=False)
            facts = {"fps": source.fps, "median_window": 5, "source": spec}
            return source, Localiser(cam.calibration(), robot), facts
    if spec is None:
        raise ValueError("--camera: give a camera index, video file or image folder")
    if spec in SYNTHETIC:
        raise ValueError(f"--camera {spec}: the synthetic camera needs --robot sim://")
    if args.calibration is None:
        raise ValueError("--calibration: needed to localise in a real camera's frames")
    calibration = load_calibration(args.calibration)
    if re.fullmatch(r"\d+", spec.strip()):
        source = CameraSource(int(spec), clock=link.clock.now)
    else:
        source = open_source(spec)
    return source, Localiser(calibration, robot), {"fps": 30.0, "median_window": 5, "source": spec}


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    parse_link_uri(args.robot)  # a bad URI is reported before anything is opened
    robot = load_robot(args.robot_file)
    waypoints = parse_waypoints(args.waypoints)
    gait = _gait(args.gait, args.k_theta)
    link = open_link(args.robot, robot=robot)
    virtual = link.transport.robot if isinstance(link.transport, SimTransport) else None
    if args.speed is not None:
        if virtual is None:
            raise ValueError("--speed: only a sim:// robot can run faster than real time")
        if args.speed < 0:
            raise ValueError("--speed: must be >= 0")
        virtual.clock.speed = args.speed
    frames, localiser, camera = _frames(args, link, robot)
    current = (0.0, 0.0) if virtual is None else virtual.current_m_s
    speed = float((current[0] ** 2 + current[1] ** 2) ** 0.5)
    direction = math.degrees(math.atan2(current[1], current[0])) if speed else 0.0
    scenario = Scenario(
        name=Path(args.out).name,
        amplitude_rad=gait.amplitude_rad,
        omega_rad_s=gait.omega_rad_s,
        beta_rad=gait.beta_rad,
        k_theta=gait.k_theta,
        waypoints_m=waypoints,
        acceptance_radius_m=args.radius,
        current_speed_m_s=speed,
        current_direction_deg=direction,
        duration_s=args.duration or 600.0,
    )
    config = RunConfig(
        gait,
        waypoints,
        acceptance_radius_m=args.radius,
        control_period_s=args.control_period,
        duration_s=args.duration,
    )
    recorder = Recorder(
        args.out,
        scenario,
        robot.n_links,
        camera=camera,
        timing={"control_period_s": args.control_period, "extra_delay_s": 0.0, "jitter_s": 0.0},
        source={"link": args.robot, "virtual": virtual is not None},
    )
    rx_log = RxLogWriter(f"{args.out}.rx.bin")
    link.rx_log = rx_log
    loop = RunLoop(link, frames, localiser, robot, config, recorder)
    previous = signal.signal(signal.SIGINT, lambda *_: loop.request_stop("interrupted"))
    wall0 = time.monotonic()
    try:
        out = loop.run()
    finally:
        signal.signal(signal.SIGINT, previous)
        rx_log.close()
        link.close()
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
    print(
        f"wrote {recorder.csv_path}, {recorder.json_path}, {recorder.commands_path}, {rx_log.path}"
    )
    return 0 if out.reason in ("arrived", "duration", "interrupted") else 1
