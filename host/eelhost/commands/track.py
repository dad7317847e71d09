"""``eelbot track``: a video filmed without eelbot, localised into an experiment."""

from __future__ import annotations

import argparse

from eelhost.commands import COMMANDS
from eelhost.commands.common import (
    FINITE,
    NON_NEGATIVE,
    POSITIVE,
    current_values,
    gait_values,
    number,
    waypoints,
)
from eelhost.commands.link_options import add_robot_file_option, resolve_robot_file_option
from eelhost.field.recorder import MOTIONS
from eelhost.field.take import refuse_overwrite
from eelhost.field.track import TrackRequest, frame_count, track_video
from eelhost.files import check_output_stem
from eelhost.progress import Progress
from eelhost.vision.markerfile import load_marker_file
from eelhost.vision.sources import open_source
from eelsim.robot import load_robot

DEFAULT_BETA_RAD = 1.04  # as eelbot run's --gait


@COMMANDS.add(
    "track",
    "localise the robot in a video (or image folder) filmed without eelbot, into an "
    "experiment",
)
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "track",
        help=COMMANDS.description("track"),
        description="Run eelbot run's localisation and median filter over every frame of a video "
        "file or a folder of images and write an experiment (<out>.csv, .json, .frames.csv and "
        "copies of the robot file and calibration) that estimate and validate read as a take. "
        "Frames where the robot is not found are reported, not filled in. Example: eelbot track "
        "tank/take7.mp4 --calibration lab/calibration.json --markers lab/markers.json "
        "--gait 0.78,3.1 --out lab/tracked/take7",
    )
    p.add_argument("video", help="a video file or a folder of images (natural name order)")
    p.add_argument("--calibration", required=True, metavar="FILE",
                   help="calibration JSON of the camera that filmed it (eelbot calibrate)")
    p.add_argument("--markers", required=True, metavar="FILE",
                   help="markers.json from eelbot markers (the plates on the robot)")
    p.add_argument("--gait", required=True, metavar="A,omega[,beta]", type=gait_values,
                   help="the gait the robot swam with: amplitude (rad), frequency (rad/s), "
                   "optionally phase shift (rad, 1.04)")
    p.add_argument("--out", required=True, metavar="STEM", help="output path without extension")
    add_robot_file_option(p)
    p.add_argument("--k-theta", type=FINITE, default=0.0,
                   help="heading gain the robot steered with (0: an open-loop gait)")
    p.add_argument("--waypoints", metavar="x,y;x,y", type=waypoints,
                   help="waypoints it steered to, m (default: where it was last seen)")
    p.add_argument("--radius", type=POSITIVE, default=0.15, help="acceptance radius, m")
    p.add_argument("--current", metavar="SPEED,DIR", type=current_values,
                   help="the water's current if known: m/s, direction in degrees")
    p.add_argument("--start", type=NON_NEGATIVE, default=0.0, metavar="SECONDS",
                   help="video time at which the gait started (earlier frames are not used)")
    p.add_argument("--fps", type=POSITIVE, default=30.0,
                   help="frame rate of a folder of images (a video's times are its own)")
    p.add_argument("--median", type=number(int, minimum=1), default=5,
                   help="median filter length, frames (eelbot run's)")
    p.add_argument("--control-period", type=POSITIVE, default=0.3,
                   help="offset update period the robot ran with, s")
    p.add_argument("--motion", choices=MOTIONS, default="auto",
                   help="straight, turning, path, or auto (as eelbot run)")
    p.add_argument("--force", action="store_true", help="replace an existing experiment at --out")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    resolve_robot_file_option(args)
    check_output_stem(args.out)
    refuse_overwrite(args.out, args.force)
    robot = load_robot(args.robot_file)
    markers = load_marker_file(args.markers)
    gait = (args.gait[0], args.gait[1], args.gait[2] if len(args.gait) == 3 else DEFAULT_BETA_RAD)
    request = TrackRequest(
        video=args.video, calibration=args.calibration, robot=robot, robot_file=args.robot_file,
        layout=markers.layout, gait=gait, out=args.out, k_theta=args.k_theta,
        waypoints_m=args.waypoints, acceptance_radius_m=args.radius,
        current_m_s=tuple(args.current) if args.current else None, start_s=args.start,
        folder_fps=args.fps, median_window=args.median, control_period_s=args.control_period,
        motion=args.motion,
    )
    with Progress("track", frame_count(open_source(args.video, args.fps)), "frame") as bar:
        result = track_video(request, lambda done, _total: bar.set(done))
    print(f"{result.frames_with_pose}/{result.frames} frames with a pose"
          + (f"; {result.skipped_before_start} frames before --start not used"
             if result.skipped_before_start else ""))
    if result.lost:
        lost = result.frames - result.frames_with_pose
        print(f"the robot was not found in {lost} frames (reported, not filled in):")
        for run_ in result.lost:
            print(f"  {run_.text()}")
    if result.filtered_end_pose is not None:
        x, y, h = result.filtered_end_pose
        print(f"last filtered pose: x {x:.3f} m, y {y:.3f} m, heading {h:.3f} rad "
              f"(median of {args.median} frames)")
    print("wrote " + ", ".join(str(p) for p in result.paths))
    return 0
