"""The loop of ``eelbot run``: see the robot, steer it towards the waypoints, record, stop safely.

:class:`RunLoop` is driven by the frames of its camera and by a clock (:class:`eelhost.link.base.
Clock`): the wall clock at the tank, the virtual robot's clock for ``sim://`` (whose camera moves
the clock to each frame's time, so a virtual run needs no sleeps and runs as fast as it can).

At the start it sends Hello, SetGains (the robot file's k_p, k_d), SetGait (the gait; slew rates
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
object, :class:`eelsim.guidance.Guidance`, so the tank steers exactly as the twin does.

Whatever ends the loop, even an exception, Stop is sent and waited for (with resends) for up to
``stop_timeout_s``, and the recording is closed with the outcome.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from eelhost.field.recorder import Recorder
from eelhost.link.base import Clock, Link, LinkEvent
from eelhost.vision.localise import Localiser
from eelhost.wire import protocol
from eelsim.control import Gait
from eelsim.guidance import Guidance
from eelsim.joints import pd_gains
from eelsim.robot import Robot

log = logging.getLogger(__name__)

__all__ = ["RunConfig", "RunLoop", "RunOutcome"]

OFFSET_LIMIT_RAD = 1.0  # SetOffset's range
EPS_S = 1e-9


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
    amplitude_rate_rad_s, beta_rate_rad_s, offset_rate_rad_s : float
        SetGait's slew limits (0 = no limit, as the twin).
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
    amplitude_rate_rad_s: float = 0.0
    beta_rate_rad_s: float = 0.0
    offset_rate_rad_s: float = 0.0


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
    stop_outcome : str
        What became of the final Stop: ``ack``, ``refused``, ``lost``, ``pending``.
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
    stop_outcome: str = ""
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
            "stop": self.stop_outcome,
        }


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
        self.outcome = RunOutcome()
        self.guidance = Guidance(
            config.waypoints_m,
            config.acceptance_radius_m,
            config.gait.k_theta,
            config.median_window,
            offset_limit_rad=OFFSET_LIMIT_RAD,
        )
        self._stop_request: str | None = None
        self._t_start = 0.0
        link.listeners.append(self._on_event)

    @property
    def target(self) -> int:
        """Index of the waypoint being steered to (the number reached so far)."""
        return self.guidance.target_index

    @property
    def filtered(self) -> NDArray[np.float64] | None:
        """The latest filtered pose (x, y, heading), or None before the first."""
        return self.guidance.filtered_pose

    def request_stop(self, reason: str = "interrupted") -> None:
        """Ask the loop to stop at the next frame (safe from a signal handler)."""
        self._stop_request = reason

    def _on_event(self, event: LinkEvent) -> None:
        self.outcome.events.append(event)
        if self.recorder is not None:
            self.recorder.command(event.t_s - self._t_start, event)

    def _start_robot(self) -> None:
        c = self.config
        g = c.gait
        # the robot file's PD gains; with the servo joint model the servos close their own loop
        # and the firmware keeps its defaults
        gains = pd_gains(self.robot.joints)
        self.link.send(protocol.Hello())
        self.link.send(protocol.SetGains(*gains) if gains is not None else protocol.SetGains(),
                       want_ack=True)
        self.link.send(
            protocol.SetGait(
                g.amplitude_rad,
                g.omega_rad_s,
                g.beta_rad,
                c.amplitude_rate_rad_s,
                c.beta_rate_rad_s,
                c.offset_rate_rad_s,
            ),
            want_ack=True,
        )
        self.link.send(protocol.SetOffset(0.0))
        self.link.send(protocol.Start(), want_ack=True)

    def run(self) -> RunOutcome:
        """Run until a stop condition; always send Stop at the end.

        Returns
        -------
        RunOutcome
        """
        out = self.outcome
        self._t_start = self.clock.now()
        try:
            self._start_robot()
            self._loop()
        except BaseException as err:
            out.reason = "interrupted" if isinstance(err, KeyboardInterrupt) else "error"
            out.detail = f"{type(err).__name__}: {err}"
            raise
        finally:
            out.waypoints_reached = self.target
            out.stop_outcome = self._stop_robot()
            log.info("run ended: %s (%s); Stop %s", out.reason, out.detail, out.stop_outcome)
            if out.stop_outcome != "ack":
                log.warning("the final Stop was not acknowledged (%s)", out.stop_outcome)
            if self.recorder is not None:
                self.recorder.close(out.as_dict())
        return out

    def _loop(self) -> None:
        c, out = self.config, self.outcome
        offset_to_clock: float | None = None
        next_control = 0.0
        last_pose_t: float | None = None
        for t_src, frame in self.frames:
            now = self.clock.now()
            if offset_to_clock is None:
                # Frame times have their own origin; anchor them to the loop's clock once.
                offset_to_clock = now - t_src
                next_control = now - self._t_start
                last_pose_t = now - self._t_start
            t = t_src + offset_to_clock - self._t_start  # since the gait started
            self.link.poll()
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
            if self._should_stop(t, last_pose_t):
                return
            if t >= next_control - EPS_S:
                # Sent even before the first pose (0 then): it keeps the robot's watchdog fed.
                self.link.send(protocol.SetOffset(self.guidance.offset()))
                out.offsets_sent += 1
                next_control += c.control_period_s
        out.reason, out.detail = "camera_ended", "the camera delivered no more frames"

    def _should_stop(self, t: float, last_pose_t: float | None) -> bool:
        c, out = self.config, self.outcome
        if self._stop_request is not None:
            out.reason, out.detail = self._stop_request, "stop requested"
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

