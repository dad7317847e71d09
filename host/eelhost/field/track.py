"""A video filmed without eelbot, tracked into an experiment (``eelbot track``).

Labs often film first and analyse later. :func:`track_video` runs, over a video file or a folder
of images, what ``eelbot run`` runs over its camera: the same :class:`~eelhost.vision.localise.
Localiser` (markers, calibration, rebuilt interior links) on every frame and the same moving
median (:func:`~eelhost.vision.localise.filtered_poses`, the window recorded as
``camera.median_window``, as a take records it), and writes the same files a take writes
(docs/host.md, "What is recorded"): ``<out>.csv`` with the raw pose of every frame that gave one,
``<out>.frames.csv`` with every frame's status, ``<out>.json`` in the experiment format
(docs/data.md), and copies of the robot file and the calibration. ``eelbot estimate`` and
``eelbot validate`` read it as they read a take.

Frame times are the video container's presentation times (a folder of images: index / ``fps``),
less ``start_s``, the video time at which the gait started (earlier frames are not used): an
experiment's times are seconds since the gait started. A frame that gives no pose is reported,
never filled in: it is a row of ``<out>.frames.csv`` with its status, and the runs of such frames
are listed in ``source.tracked.lost`` and printed. The provenance goes into ``source.tracked``:
the video's path, size and modification time, where the frame times came from, the calibration
and marker files, and the counts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from eelhost.data.experiments import Experiment, write_experiment
from eelhost.errors import UserError
from eelhost.field.provenance import robot_file_text, software
from eelhost.field.recorder import FRAME_COLUMNS, infer_motion
from eelhost.files import atomic_write
from eelhost.vision.calibration import load_calibration
from eelhost.vision.localise import Localisation, Localiser, filtered_poses
from eelhost.vision.markers import MarkerLayout
from eelhost.vision.sources import FolderSource, VideoFileSource, open_source
from eelsim.robot import Robot
from eelsim.scenario import Scenario

__all__ = ["LostRun", "TrackError", "TrackRequest", "TrackResult", "frame_count", "track_video"]


class TrackError(UserError, ValueError):
    """A video that cannot be tracked into an experiment; the message says why."""


@dataclass(frozen=True)
class TrackRequest:
    """What to track and how.

    Attributes
    ----------
    video : str
        A video file or a folder of images.
    calibration : str
        The calibration JSON of the camera that filmed it.
    robot : Robot
    robot_file : str or None
        The robot file (None: the bundled paper robot), copied beside the experiment.
    layout : MarkerLayout
        The robot's markers.
    gait : (float, float, float)
        Amplitude (rad), frequency (rad/s), phase shift (rad) the robot swam with.
    out : str
        Output path without extension.
    k_theta : float
        Heading gain the robot steered with (0: an open-loop gait).
    waypoints_m : list of (float, float) or None
        The waypoints it steered to (None: the last tracked position, for an open-loop gait).
    acceptance_radius_m : float
    current_m_s : (float, float) or None
        The water's current (speed m/s, direction deg) when known.
    start_s : float
        Video time at which the gait started.
    folder_fps : float
        Frame rate of a folder of images.
    median_window : int
        Frames of the moving median (``eelbot run``'s: 5).
    control_period_s : float
        The offset update period the robot ran with.
    motion : str
        ``straight``, ``turning``, ``path`` or ``auto``.
    """

    video: str
    calibration: str
    robot: Robot
    robot_file: str | None
    layout: MarkerLayout
    gait: tuple[float, float, float]
    out: str
    k_theta: float = 0.0
    waypoints_m: list[tuple[float, float]] | None = None
    acceptance_radius_m: float = 0.15
    current_m_s: tuple[float, float] | None = None
    start_s: float = 0.0
    folder_fps: float = 30.0
    median_window: int = 5
    control_period_s: float = 0.3
    motion: str = "auto"


@dataclass(frozen=True)
class LostRun:
    """Consecutive frames without a pose: first and last time, count, and why (the first's)."""

    t_first_s: float
    t_last_s: float
    frames: int
    status: str
    message: str

    def text(self) -> str:
        """``4.20-4.57 s (12 frames, partial: links 5, 6 not seen)``."""
        return (f"{self.t_first_s:.2f}-{self.t_last_s:.2f} s ({self.frames} frame"
                f"{'s' if self.frames != 1 else ''}, {self.status}"
                + (f": {self.message}" if self.message else "") + ")")


@dataclass
class TrackResult:
    """What tracking found and wrote."""

    paths: list[Path]
    frames: int
    frames_with_pose: int
    lost: list[LostRun] = field(default_factory=list)
    skipped_before_start: int = 0
    filtered_end_pose: tuple[float, float, float] | None = None


def frame_count(source: object) -> int | None:
    """Frames in a folder or video source (the container's count), None when unknown."""
    if isinstance(source, FolderSource):
        return len(source.paths)
    if isinstance(source, VideoFileSource):
        import cv2

        cap = cv2.VideoCapture(str(source.path))
        try:
            count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        finally:
            cap.release()
        return count if count > 0 else None
    return None


def _lost_runs(rows: list[tuple[float, Localisation]]) -> list[LostRun]:
    runs: list[LostRun] = []
    current: list[tuple[float, Localisation]] = []
    for t, loc in [*rows, (math.inf, None)]:  # type: ignore[list-item]
        if loc is not None and not loc.found:
            current.append((t, loc))
            continue
        if current:
            first = current[0][1]
            runs.append(LostRun(current[0][0], current[-1][0], len(current), first.status,
                                first.message))
            current = []
    return runs


def track_video(request: TrackRequest,
                progress: Callable[[int, int | None], None] | None = None) -> TrackResult:
    """Localise the robot in every frame of a video and write the experiment.

    Parameters
    ----------
    request : TrackRequest
    progress : callable, optional
        ``progress(frames done, frames in all or None)``.

    Returns
    -------
    TrackResult

    Raises
    ------
    TrackError
        No frame after ``start_s``, or no frame with a pose; the calibration's and the sources'
        own errors (a frame of another size than the calibration's, a missing video) as theirs.
    """
    calibration = load_calibration(request.calibration)
    localiser = Localiser(calibration, request.robot, request.layout)
    video = Path(request.video)
    source = open_source(request.video, request.folder_fps)
    if not isinstance(source, FolderSource | VideoFileSource):
        raise TrackError(f"{request.video}: give a video file or a folder of images (a camera "
                         "is eelbot run's)")
    total = frame_count(source)
    seen: list[tuple[float, Localisation]] = []
    skipped = 0

    def located() -> Iterator[Localisation]:
        nonlocal skipped
        last_t = -math.inf
        for n, (t_video, frame) in enumerate(source, start=1):
            if n == 1:
                calibration.check_frame(frame, where=str(video))
            t = t_video - request.start_s
            if t < 0 or t <= last_t:  # before the gait started, or a repeated container time
                skipped += 1
            else:
                last_t = t
                loc = localiser.localise(t, frame)
                seen.append((t, loc))
                yield loc
            if progress:
                progress(n, total)

    end_pose = None
    for _t, pose in filtered_poses(located(), request.median_window):
        if pose is not None:
            end_pose = (float(pose[0]), float(pose[1]), float(pose[2]))
    if not seen:
        raise TrackError(f"{request.video}: no frame at or after --start {request.start_s:g} s")
    posed = [(t, loc) for t, loc in seen if loc.found]
    if not posed:
        first = seen[0][1]
        raise TrackError(f"{request.video}: the robot was not found in any of {len(seen)} frames "
                         f"(first frame: {first.status}, {first.message}); check --markers and "
                         "--calibration")
    paths = _write(request, calibration, seen, posed, skipped, source)
    return TrackResult(paths, len(seen), len(posed), _lost_runs(seen), skipped, end_pose)


def _write(request: TrackRequest, calibration: Any, seen: list[tuple[float, Localisation]],
           posed: list[tuple[float, Localisation]], skipped: int, source: object) -> list[Path]:
    out = Path(request.out)
    t = np.array([tt for tt, _ in posed])
    com = np.array([loc.com_m for _, loc in posed], dtype=float)
    heading = np.array([loc.heading_rad for _, loc in posed], dtype=float)
    angles = np.array([loc.link_angles_rad for _, loc in posed], dtype=float)
    waypoints = request.waypoints_m or [(round(float(com[-1, 0]), 6), round(float(com[-1, 1]), 6))]
    motion = request.motion
    if motion == "auto":
        motion = infer_motion(waypoints, (float(com[0, 0]), float(com[0, 1])), float(heading[0]))
    speed, direction = request.current_m_s or (0.0, 0.0)
    a, omega, beta = request.gait
    scenario = Scenario(
        name=out.name, amplitude_rad=a, omega_rad_s=omega, beta_rad=beta,
        k_theta=request.k_theta, waypoints_m=waypoints,
        acceptance_radius_m=request.acceptance_radius_m, current_speed_m_s=speed,
        current_direction_deg=direction, duration_s=float(max(t[-1], 1e-3)),
        start_position_m=(float(com[0, 0]), float(com[0, 1])),
        start_heading_deg=float(np.degrees(heading[0])),
    )
    times = np.array([tt for tt, _ in seen])
    camera: dict[str, Any] = {"median_window": request.median_window, "source": str(request.video),
                              "frames": len(seen)}
    if len(times) > 1:
        dt = np.diff(times)
        camera["fps"] = float((len(times) - 1) / (times[-1] - times[0]))
        camera["frame_interval_s"] = {"mean": float(dt.mean()), "std": float(dt.std()),
                                      "max": float(dt.max())}
    camera["pixel_m"] = float(calibration.pixel_size_m(com.mean(axis=0)))
    video = Path(request.video)
    stat = video.stat()
    lost = _lost_runs(seen)
    tracked = {
        "video": str(video.resolve()),
        "kind": "image folder" if video.is_dir() else "video file",
        "bytes": None if video.is_dir() else stat.st_size,
        "modified": datetime.fromtimestamp(stat.st_mtime, UTC).isoformat(timespec="seconds"),
        "frame_times": (f"index / {request.folder_fps:g} fps (a folder has no times)"
                        if isinstance(source, FolderSource) else "the container's presentation "
                        "times"),
        "start_s": request.start_s,
        "calibration": str(Path(request.calibration).resolve()),
        "frames": len(seen),
        "frames_with_pose": len(posed),
        "frames_without_pose": len(seen) - len(posed),
        "frames_before_start": skipped,
        "lost": [{"t_first_s": r.t_first_s, "t_last_s": r.t_last_s, "frames": r.frames,
                  "status": r.status, "message": r.message} for r in lost],
    }
    robot_copy = Path(f"{out}.robot.toml")
    calibration_copy = Path(f"{out}.calibration.json")
    source_meta = {
        "tracked": tracked,
        "run": {**software(), "date": datetime.now(UTC).isoformat(timespec="seconds"),
                "robot_file": request.robot_file or "paper_robot.toml (bundled)",
                "robot_copy": robot_copy.name, "calibration_copy": calibration_copy.name,
                "gains": {"k_theta": request.k_theta},
                "current_known": request.current_m_s is not None,
                "reprojection_rms_px": calibration.rms_reprojection_px},
        "recording": {"complete": True, "frames": len(posed), "reason": "tracked",
                      "frames_seen": len(seen), "frames_with_pose": len(posed)},
    }
    exp = Experiment(
        name=out.name, t_s=t, position_m=com, scenario=scenario, motion=motion,
        heading_rad=heading, link_angles_rad=angles, camera=camera,
        timing={"control_period_s": request.control_period_s, "extra_delay_s": 0.0,
                "jitter_s": 0.0},
        source=source_meta,
    )
    frames_csv = Path(f"{out}.frames.csv")
    lines = [",".join(FRAME_COLUMNS)] + [f"{tt:.6f},{loc.status},{len(loc.sightings)}"
                                         for tt, loc in seen]
    atomic_write(frames_csv, "\n".join(lines) + "\n")
    atomic_write(robot_copy, robot_file_text(request.robot_file))
    atomic_write(calibration_copy, Path(request.calibration).read_bytes())
    csv_path, json_path = write_experiment(exp, out.parent)
    return [json_path, csv_path, frames_csv, robot_copy, calibration_copy]
