"""One take, from options to a closed recording: what ``eelbot run`` and ``eelbot campaign`` share.

:func:`run_take` opens the link and the camera (reading a frame before anything is sent), builds
the :class:`~eelhost.field.session.TankSession` with its optional live view, runs it with SIGINT,
SIGTERM and SIGHUP turned into a clean stop, and closes everything.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from eelhost.errors import UserError
from eelhost.field.recorder import take_paths
from eelhost.field.runloop import FrameReport, Navigator, RunConfig, RunOutcome
from eelhost.field.session import TakeNotes, TankSession, open_camera, virtual_robot
from eelhost.field.signals import stop_on_signals
from eelhost.link.base import LinkEvent
from eelhost.link.uri import open_link
from eelhost.progress import Progress
from eelhost.vision.calibration import Calibration
from eelhost.vision.markers import MarkerLayout
from eelhost.vision.synthetic import TankView
from eelhost.xil.virtual_robot import VirtualRobot
from eelsim.robot import Robot

__all__ = ["LiveDisplay", "TakeExistsError", "TakeOptionError", "TakeRequest", "TakeResult",
           "ViewOpener", "refuse_overwrite", "run_take"]


class TakeExistsError(UserError, FileExistsError):
    """An earlier take is where a new one would be written."""


class TakeOptionError(UserError, ValueError):
    """A take's option that does not fit its link (``--speed`` for a real robot)."""


class LiveDisplay(Protocol):
    """A live view of a take: told every frame's report, closed after the take.

    Attributes
    ----------
    on_stop : callable or None
        ``on_stop(why)``: set by :func:`run_take` once the take can be stopped; the view calls it
        when its operator asks for a stop (the page's Stop button).
    """

    on_stop: Callable[[str], None] | None

    @property
    def url(self) -> str:
        """Where the operator looks at it (announced when the take starts)."""
        ...

    def update(self, report: FrameReport) -> None:
        """Take one frame's report (called by the run loop; must be cheap)."""
        ...

    def close(self) -> None:
        """Stop serving."""
        ...


ViewOpener = Callable[[Calibration, Robot, RunConfig], LiveDisplay]
"""Opens a take's live view from the camera's calibration, the robot and the task."""


@dataclass(frozen=True)
class TakeRequest:
    """Everything one take needs.

    Attributes
    ----------
    robot : Robot
        The robot.
    config : RunConfig
        The task and stop conditions.
    out : str
        Output path without extension.
    notes : TakeNotes
        Link URI, robot file, motion, current, note.
    camera : str or None
        The frame source (``--camera``).
    calibration : str or None
        The calibration file.
    layout : MarkerLayout or None
        The robot's markers.
    speed : float or None
        ``sim://`` only: simulated seconds per wall second.
    navigator : Navigator or None
        Plans beside the run loop (``eelbot run --plan``; see
        :class:`~eelhost.field.runloop.RunLoop`).
    camera_view : TankView or None
        What the synthetic camera of ``sim://`` films (default: the paper's tank view).
    trace_plant : bool
        ``sim://`` only: keep the virtual robot's true state at every physics step
        (:attr:`eelhost.xil.virtual_robot.VirtualRobot.trace`; benchmarks).
    """

    robot: Robot
    config: RunConfig
    out: str
    notes: TakeNotes
    camera: str | None = None
    calibration: str | None = None
    layout: MarkerLayout | None = None
    speed: float | None = None
    navigator: Navigator | None = None
    camera_view: TankView | None = None
    trace_plant: bool = False


@dataclass
class TakeResult:
    """How a take went: outcome, files, wall time, replans, the virtual robot (None: a real one)."""

    outcome: RunOutcome
    paths: list[Path]
    wall_s: float
    virtual: bool
    signals: list[str]
    replans: int = 0
    virtual_robot: VirtualRobot | None = None


def refuse_overwrite(stem: str | Path, force: bool) -> None:
    """Refuse to write over an earlier take at ``stem``, or remove its files with ``force``."""
    existing = [p for p in take_paths(stem) if p.exists()]
    if existing and not force:
        raise TakeExistsError(f"--out: {existing[0]} exists (an earlier take); choose another "
                              "--out or add --force to replace it")
    for p in existing:
        p.unlink()


def run_take(request: TakeRequest, open_view: ViewOpener | None = None,
             announce: Callable[[str], None] = lambda _msg: None,
             stop_flag: list[str] | None = None) -> TakeResult:
    """Run one take and close it, whatever happens.

    Parameters
    ----------
    request : TakeRequest
        What to do.
    open_view : callable or None
        Opens the live view once the camera is open (``open_view(calibration, robot, config)``,
        e.g. :class:`eelhost.web.liveview.LiveView` with its port bound); None: no view.
    announce : callable
        Told the live view's address.
    stop_flag : list of str, optional
        Signals received are appended here too (a campaign stops after the take).

    Returns
    -------
    TakeResult

    Raises
    ------
    TakeOptionError
        For ``speed`` on a link that is not ``sim://``; and whatever opening the link or the
        camera raises (nothing has been sent then).
    """
    link = open_link(request.notes.link_uri, robot=request.robot)
    virtual = virtual_robot(link)
    try:
        if request.speed is not None:
            if virtual is None:
                raise TakeOptionError("--speed: only a sim:// robot can run faster than real time")
            if request.speed < 0:
                raise TakeOptionError("--speed: must be >= 0")
            virtual.clock.speed = request.speed
        if request.trace_plant and virtual is not None:
            virtual.trace = []
        camera = open_camera(link, request.robot, request.camera, request.calibration,
                             request.layout, request.camera_view)
        camera.prime()  # the camera opens and gives a frame before the robot is started
    except BaseException:
        link.close()
        raise
    view = None
    if open_view is not None:
        try:
            view = open_view(camera.calibration, request.robot, request.config)
        except BaseException:
            link.close()
            raise
        announce(f"live view: {view.url}")
    wall0 = time.monotonic()
    try:
        try:
            session = TankSession(link, camera, request.robot, request.config, request.out,
                                  request.notes, observers=[view.update] if view else None,
                                  navigator=request.navigator)
        except BaseException:
            link.close()
            raise

        def stop(name: str) -> None:
            session.loop.request_stop("interrupted", f"{name} received")
            if stop_flag is not None:
                stop_flag.append(name)

        if view is not None:
            view.on_stop = stop  # the page's Stop button stops as Ctrl-C does
        loop = session.loop
        with stop_on_signals(stop) as received, Progress(
            "run", len(request.config.waypoints_m), "waypoint"
        ) as bar:

            def show(_event: LinkEvent) -> None:  # at each command sent: every control period
                bar.set_postfix(t=f"{loop.outcome.t_end_s:.0f} s")
                bar.set(loop.target)

            session.link.listeners.append(show)
            outcome = session.run()
    finally:
        if view is not None:
            view.close()
    return TakeResult(outcome, [p for p in session.paths if p.exists()],
                      time.monotonic() - wall0, virtual is not None, list(received),
                      session.loop.replans, virtual)
