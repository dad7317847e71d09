"""One run at the tank, wired together: the link, the camera and its localiser, the recorder.

``eelbot run`` parses its options and hands them here: :func:`open_camera` chooses the frame
source for the link (the synthetic camera filming the virtual robot for ``sim://``, a camera, a
video or an image folder otherwise), and :class:`TankSession` builds the recording of the task
(``<out>.json``, ``.csv``, ``.commands.csv``, ``.rx.bin``) and the :class:`~eelhost.field.runloop.
RunLoop`, runs it and closes everything, whatever happens.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from eelhost.errors import UserError
from eelhost.field.recorder import Recorder
from eelhost.field.runloop import RunConfig, RunLoop, RunOutcome
from eelhost.link.base import Link
from eelhost.link.replay_transport import RxLogWriter
from eelhost.link.sim_transport import SimTransport
from eelhost.vision.calibration import load_calibration
from eelhost.vision.localise import Localiser
from eelhost.vision.sources import CameraSource, open_source
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
from eelhost.xil.virtual_robot import VirtualCamera, VirtualRobot
from eelsim.robot import Robot
from eelsim.scenario import Scenario

__all__ = ["SYNTHETIC", "CameraChoiceError", "CameraSetup", "TankSession", "open_camera"]

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
        What the recording keeps of the camera (fps, median window, source).
    """

    frames: Iterable[tuple[float, NDArray[np.uint8]]]
    localiser: Localiser
    facts: dict[str, Any] = field(default_factory=dict)


def virtual_robot(link: Link) -> VirtualRobot | None:
    """The virtual robot behind a ``sim://`` link (None for any other link)."""
    transport = link.transport
    return transport.robot if isinstance(transport, SimTransport) else None


def open_camera(
    link: Link, robot: Robot, camera: str | None, calibration: str | None
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
        The calibration JSON of a real camera.

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
            cam = SyntheticCamera(robot, options=options, seed=0)
            source = VirtualCamera(vr, cam, keep_truth=False)
            facts = {"fps": source.fps, "median_window": MEDIAN_WINDOW, "source": spec}
            return CameraSetup(source, Localiser(cam.calibration(), robot), facts)
    if spec is None:
        raise CameraChoiceError("--camera: give a camera index, video file or image folder")
    if spec in SYNTHETIC:
        raise CameraChoiceError(f"--camera {spec}: the synthetic camera needs --robot sim://")
    if calibration is None:
        raise CameraChoiceError("--calibration: needed to localise in a real camera's frames")
    cal = load_calibration(calibration)
    frames: Iterable[tuple[float, NDArray[np.uint8]]]
    if re.fullmatch(r"\d+", spec.strip()):
        frames = CameraSource(int(spec), clock=link.clock.now)
    else:
        frames = open_source(spec)
    facts = {"fps": 30.0, "median_window": MEDIAN_WINDOW, "source": spec}
    return CameraSetup(frames, Localiser(cal, robot), facts)


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
    link_uri : str
        The link's URI, for the record.
    """

    def __init__(
        self,
        link: Link,
        camera: CameraSetup,
        robot: Robot,
        config: RunConfig,
        out: str,
        link_uri: str,
    ) -> None:
        self.link = link
        self.virtual = virtual_robot(link)
        current = (0.0, 0.0) if self.virtual is None else self.virtual.current_m_s
        speed = float(math.hypot(*current))
        direction = math.degrees(math.atan2(current[1], current[0])) if speed else 0.0
        gait = config.gait
        scenario = Scenario(
            name=Path(out).name,
            amplitude_rad=gait.amplitude_rad,
            omega_rad_s=gait.omega_rad_s,
            beta_rad=gait.beta_rad,
            k_theta=gait.k_theta,
            waypoints_m=config.waypoints_m,
            acceptance_radius_m=config.acceptance_radius_m,
            current_speed_m_s=speed,
            current_direction_deg=direction,
            duration_s=config.duration_s or 600.0,
        )
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
            source={"link": link_uri, "virtual": self.virtual is not None},
        )
        self.rx_log = RxLogWriter(f"{out}.rx.bin")
        link.rx_log = self.rx_log
        self.loop = RunLoop(link, camera.frames, camera.localiser, robot, config, self.recorder)

    @property
    def paths(self) -> list[Path]:
        """The files the run writes."""
        r = self.recorder
        return [r.csv_path, r.json_path, r.commands_path, self.rx_log.path]

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
