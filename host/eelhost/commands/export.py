"""``eelbot export``: a take as an MCAP file for Foxglove and ROS 2 tools."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from eelhost.commands.common import OptionError
from eelhost.field.mcap_export import export_take_mcap, take_stem
from eelhost.files import check_output_stem
from eelhost.progress import Progress


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "export",
        help="write a take as MCAP (pose, joints, commands, telemetry, camera) for Foxglove",
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
                   "frames (default: the take's camera source when it is a file or folder; a "
                   "synthetic or live camera kept no images)")
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
    if video is not None:
        from itertools import islice

        from eelhost.vision.sources import open_source

        source = open_source(video)
        frames = islice((frame for _t, frame in source), skip, None)
    with Progress("export", None, "frame") as bar:
        summary = export_take_mcap(stem, out, frames,
                                   progress=lambda done, _total: bar.set(done))
    print(f"wrote {summary.path}: {summary.line()}")
    if video is None:
        print("no camera frames: the take's camera kept no images (give --video SOURCE, the "
              "video it was filmed from)")
    return 0
