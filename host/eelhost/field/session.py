"""One run at the tank, wired together: the link, the camera and its localiser, the recorder.

``eelbot run`` and ``eelbot campaign`` hand their options here: :func:`open_camera` chooses the
frame source for the link (the synthetic camera filming the virtual robot for ``sim://``, a camera,
a video or an image folder otherwise) and reads its first frame, and :class:`TankSession` builds
the recording of the take (``<out>.json``, ``.csv``, ``.frames.csv``, ``.commands.csv``,
``.rx.bin``, and copies of the robot file and the calibration: :func:`eelhost.field.recorder.
take_paths`) and the :class:`~eelhost.field.runloop.RunLoop`, runs it and closes everything,
whatever happens.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from eelhost.errors import UserError
from eelhost.field.provenance import robot_file_text, software
from eelhost.field.recorder import Recorder, take_paths
from eelhost.field.runloop import (
    FrameReport,
    Navigator,
    RunConfig,
    RunLoop,
    RunOutcome,
    open_frames,
)
from eelhost.files import atomic_write
from eelhost.link.base import Link
from eelhost.link.replay_transport import RxLogWriter
from eelhost.link.sim_transport import SimTransport
from eelhost.vision.calibration import Calibration, load_calibration, save_calibration
from eelhost.vision.localise import Localiser
from eelhost.vision.markers import MarkerLayout
from eelhost.vision.sources import CameraSource, open_source
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera, TankView
from eelhost.xil.virtual_robot import VirtualCamera, VirtualRobot
from eelsim.robot import Robot
from eelsim.scenario import Scenario

__all__ = ["SYNTHETIC", "CameraChoiceError", "CameraSetup", "TakeNotes", "TankSession",
           "open_camera"]

SYNTHETIC = ("synthetic", "synthetic:clean")
MEDIAN_WINDOW = 5  # frames in the run loop's median filter (RunConfig's default)


class CameraChoiceError(UserError, ValueError):
    """A camera that cannot be used with this link (or without a calibration)."""


@dataclass
class CameraSetup:
    """Where the frames come from and how they are read.

    Attributes
    ----------
    frames : iterable of (t_s, frame)
        The frame source.
    localiser : Localiser
        Pose from a frame.
    facts : dict
        What the recording keeps of the camera (nominal fps, median window, source).
    """

    frames: Iterable[tuple[float, NDArray[np.uint8]]]
    localiser: Localiser
    facts: dict[str, Any] = field(default_factory=dict)

    @property
    def calibration(self) -> Calibration:
        """The calibration the localiser maps pixels to metres with."""
        return self.localiser.calibration

    def prime(self) -> None:
        """Open the source and read its first frame now (before the robot is started)."""
        self.frames = open_frames(self.frames)


def virtual_robot(link: Link) -> VirtualRobot | None:
    """The virtual robot behind a ``sim://`` link (None for any other link)."""
    transport = link.transport
    return transport.robot if isinstance(transport, SimTransport) else None


def open_camera(
    link: Link,
    robot: Robot,
    camera: str | None,
    calibration: str | None,
    layout: MarkerLayout | None = None,
    view: TankView | None = None,
) -> CameraSetup:
    """The frame source of a run, its localiser and the camera facts to record.

    Parameters
    ----------
    link : Link
        The opened link (for ``sim://`` the synthetic camera films its virtual robot).
    robot : Robot
        The robot the localiser looks for.
    camera : str or None
        A camera index, a video file or an image folder; for ``sim://`` also ``synthetic``
        (noise and JPEG; the default there) or ``synthetic:clean`` (blur only).
    calibration : str or None
        The calibration JSON of a real camera; with the synthetic camera, the localiser uses it
        instead of the synthetic camera's exact one (to test a calibration in the loop).
    layout : MarkerLayout, optional
        The markers on the robot (default: one per link, ids 0..N-1).
    view : TankView, optional
        What the synthetic camera films (default: the paper's tank view); ``eelbot run --plan``
        films the world's whole tank (:meth:`TankView.covering`).

    Returns
    -------
    CameraSetup

    Raises
    ------
    CameraChoiceError
        No camera for a real link, the synthetic camera without ``sim://``, or a real camera
        without a calibration.
    """
    vr = virtual_robot(link)
    spec = camera
    if vr is not None:
        spec = spec or "synthetic"
        if spec in SYNTHETIC:
            options = (
                RenderOptions(noise_sigma=0.0, jpeg_quality=0) if spec.endswith("clean") else None
            )
            cam = SyntheticCamera(robot, layout=layout, view=view, options=options, seed=0)
            source = VirtualCamera(vr, cam, keep_truth=False)
            facts = {"fps": source.fps, "median_window": MEDIAN_WINDOW, "source": spec}
            cal = load_calibration(calibration) if calibration else cam.calibration()
            return CameraSetup(source, Localiser(cal, robot, layout), facts)
    if spec is None:
        raise CameraChoiceError("--camera: give a camera index, video file or image folder")
    if spec in SYNTHETIC:
        raise CameraChoiceError(f"--camera {spec}: the synthetic camera needs --link sim://")
    if calibration is None:
        raise CameraChoiceError("--calibration: needed to localise in a real camera's frames")
    cal = load_calibration(calibration)
    frames: Iterable[tuple[float, NDArray[np.uint8]]]
    if re.fullmatch(r"\d+", spec.strip()):
        frames = CameraSource(int(spec), clock=link.clock.now)
    else:
        frames = open_source(spec)
    facts = {"median_window": MEDIAN_WINDOW, "source": spec}  # fps: measured by the recorder
    return CameraSetup(frames, Localiser(cal, robot, layout), facts)


@dataclass(frozen=True)
class TakeNotes:
    """What a take's record keeps beyond the task: where it came from and what was said.

    Attributes
    ----------
    link_uri : str
        The link's URI.
    robot_file : str or None
        The robot TOML used (None: the bundled paper robot); copied beside the take.
    motion : str
        ``straight``, ``turning``, ``path`` or ``auto`` (see :class:`~eelhost.field.recorder.
        Recorder`).
    current_m_s : (float, float) or None
        The water's current (speed, direction in degrees) when known; ``sim://`` gives its own.
    note : str
        The operator's note.
    extra : dict
        More keys for ``source.run`` (a campaign's plan and take).
    """

    link_uri: str
    robot_file: str | None = None
    motion: str = "auto"
    current_m_s: tuple[float, float] | None = None
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


class TankSession:
    """One recorded run: the task's record, the byte log, the run loop, and their closing.

    Parameters
    ----------
    link : Link
        The opened link; closed when the run ends.
    camera : CameraSetup
        Frames and localiser.
    robot : Robot
        The robot (its gains go out with SetGains).
    config : RunConfig
        Task and stop conditions.
    out : str
        Output path without extension.
    notes : TakeNotes
        The link URI, robot file, motion, current and note to record.
    observers : list of callable, optional
        Called with every frame's :class:`~eelhost.field.runloop.FrameReport` (the live view).
    navigator : Navigator, optional
        Plans beside the run loop (``eelbot run --plan``; see :class:`RunLoop`).
    """

    def __init__(
        self,
        link: Link,
        camera: CameraSetup,
        robot: Robot,
        config: RunConfig,
        out: str,
        notes: TakeNotes,
        observers: list[Callable[[FrameReport], None]] | None = None,
        navigator: Navigator | None = None,
    ) -> None:
        self.link = link
        self.virtual = virtual_robot(link)
        if self.virtual is not None:
            vx, vy = self.virtual.current_m_s
            speed = float(math.hypot(vx, vy))
            direction = math.degrees(math.atan2(vy, vx)) if speed else 0.0
        else:
            speed, direction = notes.current_m_s or (0.0, 0.0)
        gait = config.gait
        scenario = Scenario.swimming(
            gait,
            name=Path(out).name,
            waypoints_m=config.waypoints_m,
            acceptance_radius_m=config.acceptance_radius_m,
            current_speed_m_s=speed,
            current_direction_deg=direction,
            duration_s=config.duration_s or 600.0,  # until the end: then the time it lasted
        )
        robot_copy = Path(f"{out}.robot.toml")
        atomic_write(robot_copy, robot_file_text(notes.robot_file))
        calibration_copy = save_calibration(camera.calibration, f"{out}.calibration.json")
        j = robot.joints
        run_facts = {
            **software(),
            "note": notes.note,
            "robot_file": notes.robot_file or "paper_robot.toml (bundled)",
            "robot_copy": robot_copy.name,
            "calibration_copy": calibration_copy.name,
            # every joint model records its own fields (PD gains, servo lag, ...) under its name
            "joints": {"model": j.model_name, **j.model_dump(mode="json")},
            "gains": {"k_theta": gait.k_theta},
            "current_known": self.virtual is not None or notes.current_m_s is not None,
            "duration_limit_s": config.duration_s,
            "reprojection_rms_px": camera.calibration.rms_reprojection_px,
            **notes.extra,
        }
        self.recorder = Recorder(
            out,
            scenario,
            robot.n_links,
            camera=camera.facts,
            timing={
                "control_period_s": config.control_period_s,
                "extra_delay_s": 0.0,
                "jitter_s": 0.0,
            },
            source={"link": notes.link_uri, "virtual": self.virtual is not None,
                    "run": run_facts},
            motion=notes.motion,
            pixel_size_m=camera.calibration.pixel_size_m,
        )
        self.out = out
        self.rx_log = RxLogWriter(f"{out}.rx.bin")
        link.rx_log = self.rx_log
        self.loop = RunLoop(link, camera.frames, camera.localiser, robot, config, self.recorder,
                            observers=observers, navigator=navigator)

    @property
    def paths(self) -> list[Path]:
        """The files the run writes."""
        return take_paths(self.out)

    def run(self) -> RunOutcome:
        """Run the loop (it always sends Stop), then close the byte log and the link.

        Returns
        -------
        RunOutcome
        """
        try:
            return self.loop.run()
        finally:
            self.rx_log.close()
            self.link.close()
