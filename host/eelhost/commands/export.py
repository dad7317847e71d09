"""``eelbot export``: a take as an MCAP file for Foxglove and ROS 2 tools."""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from eelhost.commands import COMMANDS
from eelhost.commands.common import OptionError
from eelhost.field.mcap_export import export_take_mcap, take_stem
from eelhost.field.session import SYNTHETIC
from eelhost.files import check_output_stem
from eelhost.progress import Progress


@COMMANDS.add(
    "export",
    "write a take as MCAP (pose, joints, commands, telemetry, camera) for Foxglove",
)
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "export",
        help=COMMANDS.description("export"),
        description="Write a take of eelbot run (or campaign, or track) as an MCAP file whose "
        "topics use Foxglove's well-known schemas (foxglove.PoseInFrame, FrameTransform, "
        "CompressedImage) and eelbot's own JSON schemas (docs/data.md, 'Takes as MCAP'). "
        "Example: eelbot export out/run/path1 --mcap",
    )
    p.add_argument("take", help="the take: its stem, or its .csv or .json")
    p.add_argument("--mcap", action="store_true", required=True,
                   help="write MCAP (the one format export writes now; required, so that a "
                   "second format can be added without changing what this command means)")
    p.add_argument("--out", metavar="FILE", help="the MCAP file (default: <take>.mcap)")
    p.add_argument("--video", metavar="SOURCE",
                   help="the video file or image folder the take was filmed from, for the camera "
                   "frames (default: the take's camera source when it is a file or folder; the "
                   "synthetic camera's frames are drawn again at the recorded poses; a live "
                   "camera kept no images)")
    p.add_argument("--force", action="store_true", help="replace an existing MCAP file")
    p.set_defaults(run=run)


def _video_of(stem: str, given: str | None) -> tuple[str | None, int]:
    """The frames' source and how many of its first frames the take did not see.

    ``--video``, else the take's camera source if it is a file or folder (a take of ``eelbot
    track`` names its video, and the frames before its ``--start`` it did not use).
    """
    try:
        meta = json.loads(Path(stem + ".json").read_text())
    except (OSError, json.JSONDecodeError):
        return given, 0  # read_experiment names the problem
    tracked = meta.get("source", {}).get("tracked", {}) if isinstance(meta, dict) else {}
    skip = int(tracked.get("frames_before_start", 0)) if isinstance(tracked, dict) else 0
    if given is not None:
        return given, skip
    camera = meta.get("camera", {}) if isinstance(meta, dict) else {}
    source = camera.get("source") if isinstance(camera, dict) else None
    if isinstance(source, str) and not source.isdigit() and Path(source).exists():
        return source, skip
    return None, 0


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    stem = take_stem(args.take)
    out = Path(args.out) if args.out else Path(stem + ".mcap")
    check_output_stem(out.with_suffix(""), (out.suffix,), "--out")
    if out.exists() and not args.force:
        raise OptionError(f"--out: {out} exists; choose another --out or add --force to "
                          "replace it")
    video, skip = _video_of(stem, args.video)
    frames = None
    times = None
    note = "the video the take was filmed from"
    if video is None and _camera_source(stem) in SYNTHETIC:
        times, frames = _rendered(stem)
        note = ("drawn again by the synthetic camera at the recorded poses (it keeps no "
                "images; frames without a pose are not drawn)")
    elif video is not None:
        from itertools import islice

        from eelhost.vision.sources import open_source

        source = open_source(video)
        frames = islice((frame for _t, frame in source), skip, None)
    with Progress("export", None, "frame") as bar:
        summary = export_take_mcap(stem, out, frames,
                                   progress=lambda done, _total: bar.set(done),
                                   frame_times_s=times, frames_note=note)
    print(f"wrote {summary.path}: {summary.line()}")
    if frames is None:
        print("no camera frames: the take's camera kept no images (give --video SOURCE, the "
              "video it was filmed from)")
    elif times is not None:
        print(f"camera frames: {note}")
    return 0


def _camera_source(stem: str) -> str | None:
    try:
        camera = json.loads(Path(stem + ".json").read_text()).get("camera", {})
    except (OSError, json.JSONDecodeError, AttributeError):
        return None
    source = camera.get("source") if isinstance(camera, dict) else None
    return source if isinstance(source, str) else None


def _rendered(stem: str) -> tuple[list[float], Iterator[np.ndarray]]:
    """The synthetic camera's frames drawn again at the take's recorded poses, and their times.

    The view is the one the take's calibration copy was made for (the synthetic camera's exact
    calibration: the tank's four corners in metres and pixels); the robot is the take's copy.
    """
    from eelhost.data.experiments import read_experiment
    from eelhost.vision.calibration import load_calibration
    from eelhost.vision.synthetic import RenderOptions, SyntheticCamera, TankView
    from eelsim.robot import load_robot

    exp = read_experiment(stem, allow_incomplete=True)
    calibration = load_calibration(stem + ".calibration.json")
    if exp.link_angles_rad is None or len(calibration.points_m) != 4:
        return [], iter(())
    copy = Path(stem + ".robot.toml")
    robot = load_robot(copy if copy.exists() else None)
    width, height = calibration.image_size_px
    view = TankView((int(width), int(height)),
                    tuple(map(tuple, calibration.points_m)), tuple(map(tuple, calibration.points_px)))
    camera = SyntheticCamera(robot, view=view, options=RenderOptions(noise_sigma=0.0,
                                                                     jpeg_quality=0))
    n = robot.n_links
    angles = exp.link_angles_rad

    def frames() -> Iterator[np.ndarray]:
        for k in range(len(exp.t_s)):
            state = np.concatenate([angles[k], exp.position_m[k], np.zeros(n + 2)])
            yield camera.render(state, float(exp.t_s[k]))[0]

    return [float(t) for t in exp.t_s], frames()
