"""The loop of ``eelbot run``: see the robot, steer it towards the waypoints, record, stop safely.

:class:`RunLoop` is driven by the frames of its camera and by a clock (:class:`eelhost.link.base.
Clock`): the wall clock at the tank, the virtual robot's clock for ``sim://`` (whose camera moves
the clock to each frame's time, so a virtual run needs no sleeps and runs as fast as it can).

Before anything is sent, the camera is opened and its first frame read (a camera that is not there
fails the run before the robot moves). Then it sends Hello, SetGains (the robot file's k_p, k_d), SetGait (the gait; slew rates
as configured, 0 = none, as the twin assumes), SetOffset(0) and Start, the configuration commands
with acknowledgement and resends. Then, per camera frame:

1. read the link (Acks, Telemetry);
2. localise the robot (:class:`eelhost.vision.localise.Localiser`); a frame with a pose is
   recorded and fed to the moving median filter (the twin's :class:`eelsim.camera.MedianFilter`),
   and the target moves to the next waypoint when the filtered position is within the acceptance
   radius (docs/model.md section 4);
3. check the stop conditions: a stop request (Ctrl-C), the last waypoint reached, no pose for
   more than ``lost_after_s`` (1 s), no frame from the robot for more than ``link_timeout_s`` (1 s;
   the robot sends Telemetry every 0.1 s), the duration;
4. every control period, compute gamma = k_theta wrap(theta_ref - theta_bar) from the latest
   filtered pose (the twin's law) and send SetOffset (which also feeds the robot's watchdog).

Steps 2 and 4 (filter, waypoint switch, line of sight, clipping) are the twin's own guidance
object, :class:`eelsim.guidance.Guidance`, built with the run's guidance law
(``RunConfig.guidance``: the paper's pure pursuit by default, or integral line-of-sight with the
planner's gains, ``eelbot run --guidance ilos``) and the control period as ILOS's integral step,
so the tank steers exactly as the twin does. Only step 4 advances ILOS's integral, once per
control period, as the twin's control update does. The law is written into the take's metadata
(``source.guidance``).

With a navigator (``eelbot run --plan``: :class:`eelhost.planning.replan.TankReplanner`) every
frame also goes to it after step 2; it may hand over new waypoints (a replan that is ready), end
the run in the goal, or stop the robot (``contact``: its estimated body touches an obstacle;
``no_safe_continuation``), or pause the gait for a restart from rest (SetGait with amplitude 0,
the offset 0 at every control period so the watchdog stays fed, then SetGait with the gait's
amplitude and the new plan's waypoints: docs/planning.md, "A restart from rest"). The planner
runs beside this loop, so steps 1-4 go on at the camera's
rate while it thinks; after each frame the navigator may hold the loop back so that a virtual
robot's clock does not run ahead of the planner's wall time (:meth:`Navigator.pace`). Every plan
and replan is rewritten into the take's metadata (``source.planning``) as it happens. Telemetry
reporting FAILSAFE is counted (``failsafe_reports``); every Telemetry also goes to the navigator
(``on_telemetry``: the measured joint angles and the gait's phase for its state estimate). The
navigator is handed the guidance's own state with every frame (:meth:`eelsim.guidance.Guidance.state`: the present leg's start and the
ILOS integral), and a replan comes with the state its plan was searched from
(``Plan.start_guide``): the new waypoints are steered from that leg start with that integral, so
the robot follows the plan with the controller the planner swam (docs/planning.md, "Execution
and replanning").

Whatever ends the loop, even an exception, Stop is sent and waited for (with resends) for up to
``stop_timeout_s``, and the recording is closed with the outcome. With ``brake_s`` (planned runs:
:data:`BRAKE_S`), Stop is preceded by a brake: SetGait with amplitude :data:`BRAKE_AMPLITUDE_RAD`
and omega 0 freezes the body in a deep S, and SetOffset(0) every control period keeps the
watchdog fed for ``brake_s``, so that the robot does not glide on straight after a deliberate stop
(docs/planning.md, "The brake before the Stop"). Not after ``link_lost`` or an error.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from eelhost.field.recorder import Recorder
from eelhost.link.base import Clock, Link, LinkEvent
from eelhost.vision.localise import Localisation, Localiser
from eelhost.wire import protocol
from eelsim.control import BRAKE_AMPLITUDE_RAD, Gait
from eelsim.guidance import PURSUIT, Guidance, GuidanceLaw
from eelsim.joints import pd_gains
from eelsim.robot import Robot

log = logging.getLogger(__name__)

__all__ = ["Decision", "FrameReport", "Navigator", "RunConfig", "RunLoop", "RunOutcome"]

OFFSET_LIMIT_RAD = 1.0  # SetOffset's range
EPS_S = 1e-9

BRAKE_S = 3.0
"""How long a planned run brakes before its final Stop (``RunConfig.brake_s``).

Why: a straight body glides far (the twin: let go at 0.08 m/s it still moves at 0.054 m/s 3 s
later, and has glided 0.47 m when it falls under 0.02 m/s). Frozen in the brake's S over
``sim://`` it is at 0.002-0.011 m/s 3 s after the brake began, by the gait's phase
(docs/planning.md, "The brake before the Stop")."""

NO_BRAKE_AFTER = ("link_lost", "error")
"""Ends after which the brake is not tried: the robot does not hear it, or the host is failing."""

GuideState = tuple[float, float, float, float]
"""The guidance's own state: the present leg's start (x, y), m, and the ILOS integral, s."""


class Decision(Protocol):
    """What a navigator makes of a frame (:class:`eelhost.planning.replan.Decision`)."""

    waypoints: list[tuple[float, float]] | None
    guide: GuideState | None
    stop: str | None
    detail: str
    arrived: bool
    recorded: bool
    # optional (a navigator's Decision may lack them): ``pause`` stops the gait (SetGait with
    # amplitude 0, or ``pause_gait``'s amplitude and beta) and keeps the run; ``restart`` with
    # waypoints sets the gait's amplitude and beta back (docs/planning.md, "A restart from rest")


class Navigator(Protocol):
    """Plans beside the loop (``eelbot run --plan``; :class:`eelhost.planning.replan.TankReplanner`)."""

    replans: int

    def on_frame(self, t_s: float, loc: Localisation, pose: NDArray[np.float64] | None,
                 target: int, offset_rad: float, guide: GuideState | None = None) -> Decision:
        """Take one frame; say whether to switch waypoints, stop, or that the goal holds.

        ``offset_rad`` is the offset last sent (the one the robot steers with), ``guide`` the
        guidance's state (:meth:`eelsim.guidance.Guidance.state`).
        """
        ...

    def pace(self, t_s: float) -> None:
        """Hold the loop while a virtual robot's clock is ahead of the planner's wall time."""
        ...

    # A navigator may also have ``on_telemetry(t_received_s, msg, t_polled_before_s)``: the loop
    # hands it every Telemetry with the time of the poll that read it and of the poll before
    # (it arrived in between), since the gait started: the robot's joint angles and gait phase
    # for the state estimate (docs/planning.md, "The robot's state at the tank").

    def close(self) -> None:
        """Stop planning."""
        ...

    def record(self) -> dict[str, Any]:
        """Every plan and replan, for the take's metadata."""
        ...


@dataclass(frozen=True)
class RunConfig:
    """What to do and when to stop.

    Attributes
    ----------
    gait : Gait
        A, omega, beta and the heading gain k_theta.
    waypoints_m : list of (float, float)
        Targets, in order.
    acceptance_radius_m : float
        A waypoint is reached within this distance of the filtered position.
    control_period_s : float
        Period of the offset updates (0.3 s in the paper).
    median_window : int
        Frames in the moving median filter.
    lost_after_s : float
        Stop when no frame has given a pose for longer than this.
    link_timeout_s : float
        Stop when nothing has come from the robot for longer than this.
    duration_s : float or None
        Stop after this long (None: no limit).
    stop_timeout_s : float
        How long to keep trying to get the final Stop acknowledged.
    brake_s : float
        Before the final Stop, hold the body in the brake's frozen S this long (0: Stop at
        once, as the paper's runs; planned runs :data:`BRAKE_S`).
    amplitude_rate_rad_s, beta_rate_rad_s, offset_rate_rad_s : float
        SetGait's slew limits (0 = no limit, as the twin).
    guidance : GuidanceLaw
        The line-of-sight law that turns the filtered pose into the offset (default the paper's
        pure pursuit; a plan must be followed with the law it was searched and checked with).
    start_guide : (x, y, I_x, I_y), optional
        The guidance state to start the first leg with (a plan's ``start_guide``: its first leg's
        start and the ILOS integral); default the first leg from the first filtered position,
        with no integral.
    """

    gait: Gait
    waypoints_m: list[tuple[float, float]]
    acceptance_radius_m: float = 0.15
    control_period_s: float = 0.3
    median_window: int = 5
    lost_after_s: float = 1.0
    link_timeout_s: float = 1.0
    duration_s: float | None = None
    stop_timeout_s: float = 1.0
    brake_s: float = 0.0
    amplitude_rate_rad_s: float = 0.0
    beta_rate_rad_s: float = 0.0
    offset_rate_rad_s: float = 0.0
    guidance: GuidanceLaw = PURSUIT
    start_guide: GuideState | None = None


@dataclass
class RunOutcome:
    """How a run ended.

    Attributes
    ----------
    reason : str
        ``arrived``, ``interrupted``, ``lost_from_view``, ``link_lost``, ``duration``,
        ``camera_ended`` or ``error`` (an exception, re-raised after the Stop).
    detail : str
        Human-readable explanation.
    waypoints_reached : int
        How many waypoints were reached.
    t_end_s : float
        Time of the last frame, since the gait started.
    frames : int
        Frames processed.
    frames_with_pose : int
        Frames that gave a pose (the recorded rows).
    offsets_sent : int
        SetOffset commands sent.
    failsafe_reports : int
        Telemetry messages that reported the robot in FAILSAFE.
    stop_outcome : str
        What became of the final Stop: ``ack``, ``refused``, ``lost``, ``pending``.
    braked_s : float
        How long the robot was braked before the Stop (0: no brake).
    stopping_s : float
        The clock's time from the loop's end (the decision to stop) to the Stop's answer, the
        brake included.
    events : list of LinkEvent
        Every link event of the run.
    """

    reason: str = ""
    detail: str = ""
    waypoints_reached: int = 0
    t_end_s: float = 0.0
    frames: int = 0
    frames_with_pose: int = 0
    offsets_sent: int = 0
    failsafe_reports: int = 0
    stop_outcome: str = ""
    braked_s: float = 0.0
    stopping_s: float = 0.0
    events: list[LinkEvent] = field(default_factory=list)

    def as_dict(self) -> dict:
        """The outcome without the events, for the recording's metadata."""
        return {
            "reason": self.reason,
            "detail": self.detail,
            "waypoints_reached": self.waypoints_reached,
            "t_end_s": self.t_end_s,
            "frames_seen": self.frames,
            "frames_with_pose": self.frames_with_pose,
            "offsets_sent": self.offsets_sent,
            "failsafe_reports": self.failsafe_reports,
            "stop": self.stop_outcome,
            "braked_s": self.braked_s,
        }


@dataclass(frozen=True)
class FrameReport:
    """What the loop made of one frame, for observers (the live view).

    Attributes
    ----------
    t_s : float
        Time since the gait started.
    frame : ndarray
        The camera frame.
    localisation : Localisation
        The markers seen and the pose.
    filtered_pose : ndarray (3,) or None
        The guidance's filtered (x, y, heading).
    target_index : int
        The waypoint being steered to.
    waypoints_m : list of (float, float) or None
        The waypoints steered to now (a replan's once it is adopted); None: the run's own.
    """

    t_s: float
    frame: NDArray[np.uint8]
    localisation: Localisation
    filtered_pose: NDArray[np.float64] | None
    target_index: int
    waypoints_m: list[tuple[float, float]] | None = None


def open_frames(frames: Iterable[tuple[float, NDArray[np.uint8]]]
                ) -> Iterator[tuple[float, NDArray[np.uint8]]]:
    """Open a frame source and read its first frame now; yield it and the rest in order.

    Raises whatever the source raises when it cannot be opened (a camera that is not there), and
    yields nothing when the source has no frame at all.
    """
    it = iter(frames)
    try:
        first = next(it)
    except StopIteration:
        return iter(())
    return itertools.chain([first], it)


class RunLoop:
    """One run of the robot along waypoints.

    Parameters
    ----------
    link : Link
        Opened link to the robot.
    frames : iterable of (t_s, frame)
        The camera (times in seconds, any origin).
    localiser : Localiser
        Pose from a frame.
    robot : Robot
        The robot (joint gains sent with SetGains).
    config : RunConfig
        Task and stop conditions.
    recorder : Recorder, optional
        Where to record frames and link events.
    clock : Clock, optional
        Time of the loop (default: the link's clock).
    observers : list of callable, optional
        Each called with a :class:`FrameReport` for every frame.
    navigator : Navigator, optional
        Given every frame (``eelbot run --plan``): new waypoints to steer to from now on (a
        replan), the goal reached, or a stop with its reason.
    """

    def __init__(
        self,
        link: Link,
        frames: Iterable[tuple[float, NDArray[np.uint8]]],
        localiser: Localiser,
        robot: Robot,
        config: RunConfig,
        recorder: Recorder | None = None,
        clock: Clock | None = None,
        observers: list[Callable[[FrameReport], None]] | None = None,
        navigator: Navigator | None = None,
    ) -> None:
        if not config.waypoints_m:
            raise ValueError("a run needs at least one waypoint")
        self.link = link
        self.frames = frames
        self.localiser = localiser
        self.robot = robot
        self.config = config
        self.recorder = recorder
        self.clock = clock or link.clock
        self.observers = list(observers or [])
        self.outcome = RunOutcome()
        self.guidance = self._guidance_for(config.waypoints_m, config.start_guide)
        self._offset_rad = 0.0  # the offset last sent: the one the robot steers with
        self._stop_request: str | None = None
        self._stop_detail = ""
        self._t_start = 0.0
        self._last_poll_s: float | None = None  # the loop's last link poll, since the gait started
        self.navigator = navigator
        self.replans = 0
        self._goal_reached = False
        self._goal_detail = ""  # the navigator's word on the arrival (a harbour swim before it)
        # the navigator paused the gait (amplitude 0): offsets of 0 go on feeding the watchdog
        self._paused = False
        self.pauses = 0
        link.listeners.append(self._on_event)

    def _guidance_for(self, waypoints: list[tuple[float, float]],
                      guide: GuideState | None) -> Guidance:
        """The guidance along ``waypoints`` with the run's law, from ``guide`` when given.

        A leg start that is not finite (a state taken before any pose) is left to the first
        filtered position, as without ``guide``.
        """
        c = self.config
        start = None
        integral = (0.0, 0.0)
        if guide is not None:
            if np.isfinite(guide[0]) and np.isfinite(guide[1]):
                start = (float(guide[0]), float(guide[1]))
            integral = (float(guide[2]), float(guide[3]))
        return Guidance(waypoints, c.acceptance_radius_m, c.gait.k_theta, c.median_window,
                        offset_limit_rad=OFFSET_LIMIT_RAD, law=c.guidance, leg_start_m=start,
                        integral_s=integral, control_period_s=c.control_period_s)

    @property
    def target(self) -> int:
        """Index of the waypoint being steered to (the number reached so far)."""
        return self.guidance.target_index

    @property
    def filtered(self) -> NDArray[np.float64] | None:
        """The latest filtered pose (x, y, heading), or None before the first."""
        return self.guidance.filtered_pose

    def request_stop(self, reason: str = "interrupted", detail: str = "stop requested") -> None:
        """Ask the loop to stop at the next frame (safe from a signal handler)."""
        self._stop_request = reason
        self._stop_detail = detail

    def _on_event(self, event: LinkEvent) -> None:
        self.outcome.events.append(event)
        if self.recorder is not None:
            self.recorder.command(event.t_s - self._t_start, event)

    def _set_gait(self, amplitude_rad: float, beta_rad: float | None = None,
                  omega_rad_s: float | None = None) -> None:
        """SetGait with the run's slew rates, this amplitude, the run's beta and omega or these."""
        c = self.config
        g = c.gait
        self.link.send(
            protocol.SetGait(
                amplitude_rad,
                g.omega_rad_s if omega_rad_s is None else omega_rad_s,
                g.beta_rad if beta_rad is None else beta_rad,
                c.amplitude_rate_rad_s,
                c.beta_rate_rad_s,
                c.offset_rate_rad_s,
            ),
            want_ack=True,
        )

    def _start_robot(self) -> None:
        # the robot file's PD gains; with the servo joint model the servos close their own loop
        # and the firmware keeps its defaults
        gains = pd_gains(self.robot.joints)
        self.link.send(protocol.Hello())
        self.link.send(protocol.SetGains(*gains) if gains is not None else protocol.SetGains(),
                       want_ack=True)
        self._set_gait(self.config.gait.amplitude_rad)
        self.link.send(protocol.SetOffset(0.0))
        self.link.send(protocol.Start(), want_ack=True)

    def run(self) -> RunOutcome:
        """Run until a stop condition; always send Stop at the end.

        Returns
        -------
        RunOutcome
        """
        out = self.outcome
        frames = open_frames(self.frames)  # the camera first: nothing is sent if it fails
        self._t_start = self.clock.now()
        if self.recorder is not None:
            self.recorder.update_metadata(source={"guidance": self._guidance_record()})
        try:
            self._start_robot()
            self._loop(frames)
        except BaseException as err:
            out.reason = "interrupted" if isinstance(err, KeyboardInterrupt) else "error"
            out.detail = f"{type(err).__name__}: {err}"
            raise
        finally:
            out.waypoints_reached = self.target
            decided = self.clock.now()
            if self.config.brake_s > 0.0 and out.reason not in NO_BRAKE_AFTER:
                out.braked_s = self._brake()
            out.stop_outcome = self._stop_robot()
            out.stopping_s = self.clock.now() - decided
            if self.navigator is not None:
                self.navigator.close()
                self._record_planning()
            log.info("run ended: %s (%s); Stop %s", out.reason, out.detail, out.stop_outcome)
            if out.stop_outcome != "ack":
                log.warning("the final Stop was not acknowledged (%s)", out.stop_outcome)
            if self.recorder is not None:
                self.recorder.close(out.as_dict())
        return out

    def _guidance_record(self) -> dict[str, Any]:
        """The guidance law the run steers with, for the take's metadata (``source.guidance``)."""
        c = self.config
        law = c.guidance
        return {"law": law.name, "description": law.describe(),
                "heading_gain": law.gain(c.gait.k_theta),
                "lookahead_m": law.lookahead_m if law.integral else None,
                "integral_gain_m_s": law.integral_gain if law.integral else None,
                "current_m_s": list(law.current_m_s) if law.feed_forward else None,
                "speed_m_s": law.speed_m_s if law.feed_forward else None,
                "control_period_s": c.control_period_s,
                "start_guide": None if c.start_guide is None else list(c.start_guide)}

    def _loop(self, frames: Iterable[tuple[float, NDArray[np.uint8]]]) -> None:
        c, out = self.config, self.outcome
        offset_to_clock: float | None = None
        next_control = 0.0
        last_pose_t: float | None = None
        for t_src, frame in frames:
            now = self.clock.now()
            if offset_to_clock is None:
                # Frame times have their own origin; anchor them to the loop's clock once.
                offset_to_clock = now - t_src
                next_control = now - self._t_start
                last_pose_t = now - self._t_start
            t = t_src + offset_to_clock - self._t_start  # since the gait started
            polled_before, polled = self._last_poll_s, self.clock.now() - self._t_start
            self._last_poll_s = polled
            for msg in self.link.poll():
                self._count_failsafe(msg)
                if isinstance(msg, protocol.Telemetry) and self.navigator is not None:
                    # the joint angles and gait phase for the state estimate (optional method)
                    on_telemetry = getattr(self.navigator, "on_telemetry", None)
                    if on_telemetry is not None:
                        on_telemetry(polled, msg, polled_before)
            out.frames += 1
            out.t_end_s = t
            loc = self.localiser.localise(t, frame)
            if loc.found:
                assert loc.com_m is not None and loc.heading_rad is not None
                out.frames_with_pose += 1
                last_pose_t = t
                if self.recorder is not None:
                    self.recorder.frame(t, loc.com_m, loc.heading_rad, loc.link_angles_rad)
                self.guidance.observe(t, float(loc.com_m[0]), float(loc.com_m[1]), loc.heading_rad)
            if self.navigator is not None:
                self._consult_navigator(t, loc)
            if self.recorder is not None:
                self.recorder.frame_seen(t, loc.status, sum(loc.seen))
            if self.observers:
                steered = [(float(x), float(y)) for x, y in self.guidance.waypoints_m]
                report = FrameReport(t, frame, loc, self.filtered, self.target, steered)
                for observer in self.observers:
                    observer(report)
            if self._should_stop(t, last_pose_t):
                return
            if t >= next_control - EPS_S:
                # Sent even before the first pose (0 then): it keeps the robot's watchdog fed.
                # The only call of offset(): each is a control update (ILOS's integral step).
                # Paused (amplitude 0), the offset is 0: the body drifts straight, as the twin
                # swims it, and the robot stays running with its watchdog fed.
                self._offset_rad = 0.0 if self._paused else self.guidance.offset()
                self.link.send(protocol.SetOffset(self._offset_rad))
                out.offsets_sent += 1
                next_control += c.control_period_s
            if self.navigator is not None:
                self.navigator.pace(t)
        out.reason, out.detail = "camera_ended", "the camera delivered no more frames"

    def _consult_navigator(self, t: float, loc: Localisation) -> None:
        """Hand the frame to the navigator: go on, steer to new waypoints, stop, or arrive."""
        assert self.navigator is not None
        decision = self.navigator.on_frame(t, loc, self.guidance.filtered_pose, self.target,
                                           self._offset_rad, guide=self.guidance.state())
        if decision.recorded:
            self._record_planning()
        if decision.stop is not None:
            self.request_stop(decision.stop, decision.detail)
        elif decision.arrived:
            self._goal_reached = True
            self._goal_detail = getattr(decision, "detail", "")
        elif getattr(decision, "pause", False):
            # stop swimming but keep the run: the gait's amplitude to 0 (the phase runs on, the
            # robot stays running), the offset to 0 now and at every control period after; a
            # pause while paused changes the paused gait only (a brake's end)
            if not self._paused:
                self.pauses += 1
                log.info("gait paused at t = %.2f s: %s", t, decision.detail)
            self._paused = True
            # a navigator's paused gait (the brake's frozen S, or the reversed wave that brakes
            # or backs the body out; docs/planning.md, "A restart from rest"), else amplitude 0;
            # the twin's stopped gait carries a 1e-9 rad stand-in amplitude and the brake's a
            # 1e-9 rad/s stand-in omega (its scenarios need them), sent as 0
            paused = getattr(decision, "pause_gait", None)
            if paused is None:
                self._set_gait(0.0)
            else:
                self._set_gait(paused.amplitude_rad if paused.amplitude_rad > 1e-6 else 0.0,
                               paused.beta_rad,
                               paused.omega_rad_s if paused.omega_rad_s > 1e-6 else 0.0)
            self._offset_rad = 0.0
            self.link.send(protocol.SetOffset(0.0))
            self.outcome.offsets_sent += 1
        elif decision.waypoints:
            if getattr(decision, "restart", False) and self._paused:
                self._paused = False
                log.info("gait restarted at t = %.2f s", t)
                self._set_gait(self.config.gait.amplitude_rad)
            self.replans += 1
            log.info("new plan at t = %.2f s: %d waypoints", t, len(decision.waypoints))
            pose = self.guidance.filtered_pose
            # the new plan is steered from the guidance state it was searched from
            self.guidance = self._guidance_for(decision.waypoints, decision.guide)
            if loc.found and loc.com_m is not None and loc.heading_rad is not None:
                self.guidance.observe(t, float(loc.com_m[0]), float(loc.com_m[1]),
                                      loc.heading_rad)
            elif pose is not None:
                self.guidance.observe(t, float(pose[0]), float(pose[1]), float(pose[2]))

    def _record_planning(self) -> None:
        if self.recorder is not None and self.navigator is not None:
            self.recorder.update_metadata(source={"planning": self.navigator.record()})

    def _should_stop(self, t: float, last_pose_t: float | None) -> bool:
        c, out = self.config, self.outcome
        if self._stop_request is not None:
            out.reason, out.detail = self._stop_request, self._stop_detail
        elif self._goal_reached:
            out.reason = "arrived"
            out.detail = f"in the planned goal disc ({self.replans} replans)" + (
                f", {self._goal_detail}" if self._goal_detail else "")
        elif self.guidance.arrived:
            out.reason, out.detail = "arrived", f"reached all {len(c.waypoints_m)} waypoints"
        elif last_pose_t is not None and t - last_pose_t > c.lost_after_s:
            out.reason = "lost_from_view"
            out.detail = f"no pose for {t - last_pose_t:.2f} s (limit {c.lost_after_s:g} s)"
        elif self.link.silent_for_s(self._t_start) > c.link_timeout_s:
            silent = self.link.silent_for_s(self._t_start)
            out.reason = "link_lost"
            out.detail = f"nothing from the robot for {silent:.2f} s (limit {c.link_timeout_s:g} s)"
        elif c.duration_s is not None and t >= c.duration_s - EPS_S:
            out.reason, out.detail = "duration", f"ran for {c.duration_s:g} s"
        else:
            return False
        return True

    def _count_failsafe(self, msg: object) -> None:
        """Count a Telemetry that reports the robot in FAILSAFE (``failsafe_reports``)."""
        if isinstance(msg, protocol.Telemetry) and msg.state == protocol.State.FAILSAFE:
            self.outcome.failsafe_reports += 1

    def _brake(self) -> float:
        """Freeze the body in a deep S (omega 0) for ``brake_s``, the watchdog fed; time braked.

        A second Ctrl-C during the brake ends it at once: the Stop still follows.
        """
        c = self.config
        t0 = self.clock.now()
        try:
            self._set_gait(BRAKE_AMPLITUDE_RAD, omega_rad_s=0.0)
            end, due = t0 + c.brake_s, t0
            while self.clock.now() < end - EPS_S:
                if self.clock.now() >= due - EPS_S:
                    self.link.send(protocol.SetOffset(0.0))  # feeds the watchdog
                    self.outcome.offsets_sent += 1
                    due += c.control_period_s
                self.clock.wait_until(min(due, end))
                for msg in self.link.poll():
                    self._count_failsafe(msg)
        except KeyboardInterrupt:
            log.warning("the brake was interrupted; stopping at once")
        return self.clock.now() - t0

    def _stop_robot(self) -> str:
        """Send Stop and keep polling (the link resends) until it is answered or time runs out."""
        seq = self.link.send(protocol.Stop(), want_ack=True)
        deadline = self.clock.now() + self.config.stop_timeout_s
        step = 0.01
        while self.link.outcome(seq) == "pending" and self.clock.now() < deadline:
            self.clock.wait_until(min(self.clock.now() + step, deadline))
            self.link.poll()
        result = self.link.outcome(seq)
        return "lost" if result == "unknown" else result

