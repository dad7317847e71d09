"""``eelbot calibrate``: pixels to metres at the markers' height, from a board or the tank's corners.

The frame comes from an image file, a camera (index, video, image folder: its first frame) or, for
the virtual tank, ``--camera synthetic`` (the synthetic camera's tank, with the board lying at
``--board-origin`` unless corners are given). With ``--corners`` or ``--click`` the four tank
corners are used (clicked on a local web page with ``--click``); otherwise the ChArUco board is found
automatically. ``--lens`` adds OpenCV's camera calibration from views of the board at several
poses. ``--check`` measures an existing calibration on a new frame instead of writing one.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from eelhost.commands import COMMANDS
from eelhost.commands.common import OptionError, floats
from eelhost.vision.calibration import (
    Calibration,
    Lens,
    calibrate_lens,
    charuco_points,
    from_charuco,
    from_tank_corners,
    load_calibration,
    save_calibration,
)
from eelhost.vision.markerfile import MarkerFile, load_marker_file
from eelhost.vision.sources import IMAGE_SUFFIXES, FrameSourceError, open_source

SYNTHETIC_BOARD_ORIGIN = "0.2,0.6"  # the default board lies in the synthetic tank's view there


@COMMANDS.add(
    "calibrate",
    "calibrate the camera (ChArUco board or tank corners; optional lens) or check it",
)
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "calibrate",
        help=COMMANDS.description("calibrate"),
        description="Find the ChArUco board in a frame (or take the four tank corners, clicked or "
        "given), fit the pixels <-> metres homography at the markers' height, print the "
        "reprojection error in pixels and metres, and write the calibration file. Example: "
        "eelbot calibrate --image frame.png --board-origin 0.5,0.8 --calibration calibration.json",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--image", metavar="FILE", help="an image of the tank")
    src.add_argument("--camera", metavar="SOURCE", help="camera index, video file, image folder, "
                     "or 'synthetic' (the virtual tank's camera)")
    p.add_argument("--markers", metavar="FILE", help="markers.json from eelbot markers (the board)")
    p.add_argument("--calibration", default="calibration.json", metavar="FILE",
                   help="the calibration file written (or read with --check); calibration.json")
    p.add_argument("--check", action="store_true", help="measure the existing --calibration on "
                   "this frame instead of writing one")
    p.add_argument("--max-error-px", type=float, default=1.0,
                   help="with --check: exit 1 when the rms error exceeds this (1.0 px)")
    g = p.add_argument_group("ChArUco board (the default)")
    g.add_argument("--board-origin", metavar="X,Y", help="world position of the board's origin "
                   "(its printed top-left corner), m; default 0,0 (synthetic: "
                   f"{SYNTHETIC_BOARD_ORIGIN})")
    g.add_argument("--board-angle", type=float, default=0.0, metavar="DEG",
                   help="world angle of the board's x axis, deg (0)")
    g = p.add_argument_group("tank corners")
    g.add_argument("--corners", metavar="U,V;U,V;U,V;U,V", help="pixels of the four corners: "
                   "origin, along +x, opposite, along +y")
    g.add_argument("--click", action="store_true", help="click the four corners on a local web "
                   "page (the address is printed)")
    g.add_argument("--port", type=int, default=8766, help="--click page's port (8766; 0: any)")
    g.add_argument("--tank-size", metavar="L,W", default="4.6,2.5",
                   help="tank length along x and width along y, m (4.6,2.5)")
    g.add_argument("--corners-m", metavar="X,Y;X,Y;X,Y;X,Y",
                   help="world coordinates of the corners instead of --tank-size")
    g.add_argument("--camera-height", type=float, metavar="M",
                   help="camera height above the corners' plane, m")
    g.add_argument("--marker-height", type=float, default=0.0, metavar="M",
                   help="markers' height above the corners' plane, m (negative below; 0)")
    g = p.add_argument_group("lens distortion")
    g.add_argument("--lens", nargs="+", metavar="IMAGE_OR_FOLDER",
                   help="views of the board at several poses (tilted, over the whole image)")
    p.add_argument("--save-frame", metavar="FILE", help="also save the frame used")
    p.set_defaults(run=run)


def _points(text: str, what: str) -> list[tuple[float, float]]:
    pts = []
    for part in text.split(";"):
        if part.strip():
            try:
                x, y = floats(part, 2, what)
            except argparse.ArgumentTypeError as err:
                raise OptionError(str(err)) from None
            pts.append((x, y))
    if len(pts) != 4:
        raise OptionError(f"{what}: expected four x,y pairs separated by ';', got {len(pts)}")
    return pts


def _pair(text: str, what: str) -> tuple[float, float]:
    try:
        x, y = floats(text, 2, what)
    except argparse.ArgumentTypeError as err:
        raise OptionError(str(err)) from None
    return x, y


def _read_image(path: str | Path) -> NDArray[np.uint8]:
    frame = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if frame is None:
        raise FrameSourceError(f"{path}: cannot read as an image")
    return np.asarray(frame, np.uint8)


def _frame(args: argparse.Namespace, markers: MarkerFile, origin: tuple[float, float]
           ) -> NDArray[np.uint8]:
    if args.image:
        return _read_image(args.image)
    if args.camera.strip().lower() == "synthetic":
        from eelhost.vision.synthetic import SyntheticCamera
        from eelsim.robot import load_robot

        cam = SyntheticCamera(load_robot(), layout=markers.layout)
        if args.corners or args.click:
            return cam.render_board(markers.board, (-100.0, -100.0))  # the board out of view
        return cam.render_board(markers.board, origin, math.radians(args.board_angle))
    frame = None
    for count, (_, image) in enumerate(open_source(args.camera)):
        frame = image
        if count == 9:  # the tenth frame: a camera's exposure has settled
            break
    if frame is None:
        raise FrameSourceError(f"{args.camera}: gave no frame")
    return frame


def _lens_frames(specs: list[str]) -> list[NDArray[np.uint8]]:
    paths: list[Path] = []
    for spec in specs:
        p = Path(spec)
        if p.is_dir():
            paths += sorted(q for q in p.iterdir() if q.suffix.lower() in IMAGE_SUFFIXES)
        else:
            paths.append(p)
    return [_read_image(p) for p in paths]


def _corner_pixels(args: argparse.Namespace, frame: NDArray[np.uint8]) -> list[tuple[float, float]]:
    if args.corners:
        return _points(args.corners, "--corners")
    from eelhost.web.picker import pick_points

    return pick_points(frame, 4, port=args.port, announce=lambda url: print(
        f"click the tank's four corners at {url} (origin, along +x, opposite, along +y)",
        flush=True))


def _world_corners(args: argparse.Namespace) -> list[tuple[float, float]]:
    if args.corners_m:
        return _points(args.corners_m, "--corners-m")
    length, width = _pair(args.tank_size, "--tank-size")
    return [(0.0, 0.0), (length, 0.0), (length, width), (0.0, width)]


def _describe(cal: Calibration) -> str:
    centre = cal.points_m.mean(axis=0)
    return (f"{cal.method}, {len(cal.points_m)} points: reprojection rms "
            f"{cal.rms_reprojection_px:.3f} px = {cal.rms_reprojection_m * 1000:.2f} mm; pixel "
            f"{cal.pixel_size_m(centre) * 1000:.2f} mm at ({centre[0]:.2f}, {centre[1]:.2f}) m")


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    markers = load_marker_file(args.markers)
    corners_mode = bool(args.corners or args.click)
    if args.corners and args.click:
        raise OptionError("--corners and --click: give one")
    synthetic = bool(args.camera) and args.camera.strip().lower() == "synthetic"
    origin = _pair(args.board_origin or (SYNTHETIC_BOARD_ORIGIN if synthetic else "0,0"),
                   "--board-origin")
    angle = math.radians(args.board_angle)
    frame = _frame(args, markers, origin)
    if args.save_frame:
        Path(args.save_frame).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(args.save_frame), frame)
        print(f"wrote {args.save_frame}")
    if args.check:
        cal = load_calibration(args.calibration)
        cal.check_frame(frame, f"--camera {args.camera}" if args.camera else f"--image {args.image}")
        if corners_mode:
            points_m, points_px = np.array(_world_corners(args)), np.array(_corner_pixels(args, frame))
        else:
            points_m, points_px = charuco_points(frame, markers.board, origin, angle)
        e_px, e_m = cal.errors(points_m, points_px)
        print(f"{args.calibration} on this frame: rms {e_px:.3f} px = {e_m * 1000:.2f} mm over "
              f"{len(points_m)} points (when made: {cal.rms_reprojection_px:.3f} px = "
              f"{cal.rms_reprojection_m * 1000:.2f} mm)")
        if e_px > args.max_error_px:
            print(f"more than --max-error-px {args.max_error_px:g}: recalibrate (has the camera "
                  "moved?)")
            return 1
        return 0
    lens: Lens | None = None
    if args.lens:
        lens = calibrate_lens(_lens_frames(args.lens), markers.board)
        k, d = lens.camera_matrix, lens.distortion
        print(f"lens: {lens.views} views, rms {lens.rms_px:.3f} px; f {k[0, 0]:.1f}, {k[1, 1]:.1f} "
              f"px, centre ({k[0, 2]:.1f}, {k[1, 2]:.1f}) px, k1 {d[0]:.4f} k2 {d[1]:.4f} "
              f"p1 {d[2]:.5f} p2 {d[3]:.5f}")
    if corners_mode:
        cal = from_tank_corners(
            _corner_pixels(args, frame), (frame.shape[1], frame.shape[0]),
            corners_m=_world_corners(args), camera_height_m=args.camera_height,
            marker_height_m=args.marker_height, lens=lens,
        )
    else:
        cal = from_charuco(frame, markers.board, origin, angle, lens=lens)
    path = save_calibration(cal, args.calibration)
    print(f"{path}: {_describe(cal)}")
    return 0
