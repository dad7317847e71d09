"""The twin swimming under the robot's own control stack (docs/model.md sections 4, 5 and 7).

Per physics step (RK4, dt = 0.01 s by default):

- the joints track the gait alpha_j(t) (with the held offset gamma) through the PD law, evaluated
  inside every RK4 stage as the robot's fast joint loop does; optionally through a hobby-servo
  torque-speed limit;
- the camera takes its frames (30 fps) between steps and quantises positions to pixels; the
  guidance (:class:`eelsim.guidance.Guidance`) filters them with the moving median and switches
  to the next waypoint when the filtered position is inside the acceptance circle;
- every control period (0.3 s, optionally jittered) the guidance's line-of-sight law computes a
  new offset from the latest filtered pose; it reaches the joints after the extra delay and is
  held;
- the failure conditions are checked; a failed run stops and returns its flag, time and reason.

The joints are the one part that can be swapped: a :class:`JointController` turns the offset and
the plant's state into the torques of each step. The default, :class:`TwinJoints`, is the PD law
above; ``eelhost.cosim`` plugs in the robot's firmware (native or emulated AVR) behind a radio
link, which is ticked once per step and whose torques are held over it. Everything else (camera,
waypoints, control updates, failures, recording) is this one loop, so a firmware run and a twin
run differ only where the robot differs.

This is the readable reference implementation; ``eelsim.batch`` runs the same physics fast.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from eelsim.camera import CameraModel, hermite, quantise_position
from eelsim.control import Gait, gait_reference, joint_pd_torque
from eelsim.dynamics import link_positions, mass_matrix, state_derivative, straight_state
from eelsim.flags import DIVERGENCE_RATE, ILL_CONDITION_THRESHOLD, Failure, penalty, self_collision
from eelsim.fluid import FluidCoefficients
from eelsim.guidance import Guidance
from eelsim.integrate import rk4_step
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import Scenario
from eelsim.timing import LoopTiming

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LoopOptions:
    """How the loop is run (everything but the robot and the task).

    Attributes
    ----------
    timing : LoopTiming
        Physics step, control period, extra delay, jitter.
    camera : CameraModel
        Frame rate, pixel size, median filter.
    servo_limits : bool
        Limit joint torques by the servos' torque-speed line (stall torque, no-load speed).
    stop_at_goal : bool
        End the run when the last waypoint is reached (not before the scenario's
        ``min_duration_s``).
    """

    timing: LoopTiming = field(default_factory=LoopTiming)
    camera: CameraModel = field(default_factory=CameraModel)
    servo_limits: bool = False
    stop_at_goal: bool = True


@dataclass
class RunResult:
    """What a closed-loop run produced.

    Attributes
    ----------
    t_s : ndarray, shape (K,)
        Times of the recorded steps.
    states : ndarray, shape (K, 2 N + 4)
        State at each recorded step.
    offset_rad : ndarray, shape (K,)
        Offset gamma acting on the joints.
    alpha_rad : ndarray, shape (K, N-1)
        Joint references.
    target_index : ndarray, shape (K,)
        Index of the waypoint being steered to.
    camera_t_s : ndarray, shape (F,)
        Times of the camera frames.
    camera_pose : ndarray, shape (F, 3)
        Filtered (x, y, heading) the controller saw.
    failure : Failure
        Flag (``Failure.NONE`` when the run succeeded).
    failure_time_s : float or None
        When the failure was detected.
    reason : str
        Human-readable explanation of the flag, empty when none.
    arrival_time_s : float or None
        When the last waypoint was reached.
    distance_left_m : float
        Path length left to the last waypoint at the end of the run.
    """

    t_s: FloatArray
    states: FloatArray
    offset_rad: FloatArray
    alpha_rad: FloatArray
    target_index: NDArray[np.int64]
    camera_t_s: FloatArray
    camera_pose: FloatArray
    failure: Failure
    failure_time_s: float | None
    reason: str
    arrival_time_s: float | None
    distance_left_m: float

    @property
    def penalty(self) -> float:
        """The paper's fitness value for this run's failure (0 if none)."""
        return penalty(self.failure, self.distance_left_m)


def servo_limited(
    torque_nm: FloatArray, phi_dot_rad_s: FloatArray, stall_nm: float, no_load_rad_s: float
) -> FloatArray:
    """Clip joint torques to a DC servo's torque-speed line.

    Driving torque falls linearly from the stall torque at rest to zero at the no-load speed;
    braking torque is limited to the stall torque.

    Parameters
    ----------
    torque_nm : ndarray
        Requested torques.
    phi_dot_rad_s : ndarray
        Joint speeds.
    stall_nm, no_load_rad_s : float
        Servo stall torque and no-load speed.

    Returns
    -------
    ndarray
    """
    r = phi_dot_rad_s / no_load_rad_s
    upper = stall_nm * np.minimum(1.0, 1.0 - r)
    lower = -stall_nm * np.minimum(1.0, 1.0 + r)
    return np.clip(torque_nm, lower, upper)


def distance_left(p: FloatArray, waypoints: FloatArray, target: int) -> float:
    """Path length from ``p`` through the waypoints not yet reached (index ``target`` on)."""
    if target >= len(waypoints):
        return 0.0
    d = float(np.linalg.norm(waypoints[target] - p))
    if target + 1 < len(waypoints):
        d += float(np.linalg.norm(np.diff(waypoints[target:], axis=0), axis=1).sum())
    return d


TorqueLaw = Callable[[float, FloatArray], FloatArray]
"""Joint torques as a function of time and state, ``torque_nm(t_s, state)``."""


@dataclass(frozen=True)
class JointDrive:
    """What drives the joints over one physics step, and what the run records of it.

    Attributes
    ----------
    torque_nm : ndarray of shape (N-1,), or callable
        Either torques held over the whole step (a zero-order hold: a controller ticked once per
        step), or a :data:`TorqueLaw` evaluated at every RK4 stage (a joint loop much faster than
        the step, as the twin models the servos).
    alpha_rad : ndarray, shape (N-1,)
        The joint references in force at the start of the step (recorded).
    offset_rad : float
        The offset gamma acting on the joints (recorded).
    """

    torque_nm: FloatArray | TorqueLaw
    alpha_rad: FloatArray
    offset_rad: float


class JointController(Protocol):
    """The robot's joint side: turns the control stack's offset and the plant into torques.

    :func:`simulate_closed_loop` calls :meth:`on_step` once at the start of every physics step,
    before the state is recorded and checked, and integrates the step with the torques it returns.
    """

    def on_step(
        self, step: int, t_s: float, state: FloatArray, offset_command: float | None
    ) -> JointDrive:
        """Take the physics step ``step`` (starting at ``t_s = step dt``).

        Parameters
        ----------
        step : int
            Index of the step (0 at the start of the run; one call per step, in order).
        t_s : float
            Its start time.
        state : ndarray, shape (2 N + 4,)
            The plant's state at ``t_s``.
        offset_command : float or None
            The offset the line-of-sight controller computed, arriving now that the loop's extra
            delay has passed; ``None`` when none arrives at this step (the last one holds).

        Returns
        -------
        JointDrive
        """
        ...


class TwinJoints:
    """The twin's joints: the gait and the PD law, evaluated inside every RK4 stage.

    The offset is held from one command to the next (a zero-order hold). The default
    :class:`JointController` of :func:`simulate_closed_loop`.

    Parameters
    ----------
    robot : Robot
        Gains, reference clamp and servo figures.
    gait : Gait
        The gait the joints follow (its phase starts at t = 0).
    n_links : int
        Number of links N.
    servo_limits : bool
        Clip the torques to the servos' torque-speed line.
    """

    def __init__(self, robot: Robot, gait: Gait, n_links: int, servo_limits: bool = False) -> None:
        self._gait = gait
        self._n = n_links
        self._kp, self._kd = robot.joints.kp_nm_per_rad, robot.joints.kd_nms_per_rad
        self._clamp = robot.joints.command_limit_rad
        self._servo = (
            (robot.joints.servo_max_torque_nm, robot.joints.servo_max_speed_rad_s)
            if servo_limits
            else None
        )
        self.offset_rad = 0.0

    def on_step(
        self, step: int, t_s: float, state: FloatArray, offset_command: float | None
    ) -> JointDrive:
        """See :meth:`JointController.on_step`; the state is only read inside the RK4 stages."""
        if offset_command is not None:
            self.offset_rad = offset_command
        alpha = gait_reference(t_s, self._gait, self.offset_rad, self._n)[0]
        return JointDrive(
            self.torque_nm, np.clip(alpha, -self._clamp, self._clamp), self.offset_rad
        )

    def torque_nm(self, t_s: float, state: FloatArray) -> FloatArray:
        """Joint torques at ``t_s`` in ``state`` (a :data:`TorqueLaw`)."""
        n = self._n
        alpha, alpha_dot = gait_reference(t_s, self._gait, self.offset_rad, n)
        alpha = np.clip(alpha, -self._clamp, self._clamp)
        w = state[n + 2 : 2 * n + 2]
        u = joint_pd_torque(alpha, alpha_dot, np.diff(state[:n]), np.diff(w), self._kp, self._kd)
        if self._servo is not None:
            u = servo_limited(u, np.diff(w), *self._servo)
        return u


def simulate_closed_loop(
    robot: Robot,
    scenario: Scenario,
    options: LoopOptions | None = None,
    seed: int = 0,
    coefficients: FluidCoefficients | None = None,
    progress: Callable[[int, int], None] | None = None,
    joints: JointController | None = None,
) -> RunResult:
    """Run the twin under its control stack on a scenario.

    Parameters
    ----------
    robot : Robot
        The robot (geometry, gains, limits).
    scenario : Scenario
        Gait, waypoints, current, duration, start pose.
    options : LoopOptions, optional
        Timing, camera, servo limits, stopping rule.
    seed : int
        Seed of the period jitter and heading noise.
    coefficients : FluidCoefficients, optional
        Overrides the robot's hydrodynamic coefficients (e.g. ``HydroCoefficients``).
    progress : callable, optional
        Called as ``progress(step, total_steps)`` every 100 steps.
    joints : JointController, optional
        Where the joint torques come from; by default :class:`TwinJoints` (the scenario's gait
        through the robot's PD law, servo limits as ``options`` says). Another controller
        applies any servo limits itself.

    Returns
    -------
    RunResult
        Never raises for a run that goes wrong: failures come back as flags.
    """
    opts = options or LoopOptions()
    timing, cam = opts.timing, opts.camera
    model = SwimmerModel.from_robot(robot, coefficients)
    rng = np.random.default_rng(seed)
    n = model.n_links
    dt = timing.dt_s
    total = scenario.total_steps(dt)
    goal_from = scenario.goal_steps(dt)
    gait = scenario.gait
    limit = robot.joints.limit_rad
    vc = np.asarray(scenario.current_m_s)
    waypoints = np.asarray(scenario.waypoints_m, dtype=float)
    guide = Guidance(waypoints, scenario.acceptance_radius_m, gait.k_theta, cam.median_window)
    if joints is None:
        joints = TwinJoints(robot, gait, n, opts.servo_limits)

    updates = set(timing.update_steps(total, rng).tolist())
    frame_times = cam.frame_times(total * dt)

    x = straight_state(model, np.radians(scenario.start_heading_deg), scenario.start_position_m)
    pending: list[tuple[int, float]] = []  # (step at which it acts, offset)
    failure, fail_t, reason = Failure.NONE, None, ""

    rec_t, rec_x, rec_g, rec_a, rec_w = [], [], [], [], []
    cam_t: list[float] = []
    cam_pose: list[FloatArray] = []
    next_frame = 0

    def observe(t_frame: float, pose_true: FloatArray) -> None:
        # the camera model (pixels, heading noise), then the host's guidance
        pos = quantise_position(pose_true[:2], cam.pixel_m)
        head = pose_true[2] + (
            rng.normal(0.0, cam.heading_noise_rad) if cam.heading_noise_rad else 0.0
        )
        filtered = guide.observe(t_frame, pos[0], pos[1], head)
        cam_t.append(t_frame)
        cam_pose.append(filtered.copy())

    def pose_and_rate(state: FloatArray) -> tuple[FloatArray, FloatArray]:
        return (
            np.array([state[n], state[n + 1], np.mean(state[:n])]),
            np.array([state[-2], state[-1], np.mean(state[n + 2 : 2 * n + 2])]),
        )

    # The frame at t = 0 sees the initial pose.
    if frame_times.size and frame_times[0] <= 0.0:
        observe(0.0, pose_and_rate(x)[0])
        next_frame = 1

    step = 0
    with np.errstate(all="ignore"):
        while True:
            t = step * dt
            if step in updates:
                pending.append((step + timing.delay_steps, guide.offset()))
            # An offset reaches the joints the loop's extra delay after its update.
            offset_command = None
            while pending and pending[0][0] <= step:
                offset_command = pending.pop(0)[1]
            # The joints' torques for this step: the twin's PD law by default; in
            # eelhost.cosim the robot's firmware, ticked once, with its torques held.
            drive = joints.on_step(step, t, x, offset_command)

            rec_t.append(t)
            rec_x.append(x.copy())
            rec_g.append(drive.offset_rad)
            rec_a.append(drive.alpha_rad)
            rec_w.append(guide.target_index)

            failure, reason = check_failures(model, x, limit, step in updates)
            if failure != Failure.NONE:
                fail_t = t
                break
            if (guide.arrived and opts.stop_at_goal and step >= goal_from) or step >= total:
                break

            try:
                x_next = rk4_step(plant_rhs(model, drive.torque_nm, vc), t, x, dt)
            except np.linalg.LinAlgError:
                failure, fail_t, reason = (
                    Failure.ILL_CONDITIONED,
                    t,
                    "mass matrix is not positive definite",
                )
                break
            if not np.all(np.isfinite(x_next)):
                failure, fail_t = Failure.ILL_CONDITIONED, t + dt
                reason = "state is not finite (the integration blew up)"
                break
            # Camera frames that fall in (t, t + dt] see the interpolated pose.
            y0, dy0 = pose_and_rate(x)
            y1, dy1 = pose_and_rate(x_next)
            while next_frame < frame_times.size and frame_times[next_frame] <= t + dt + 1e-12:
                s = (frame_times[next_frame] - t) / dt
                observe(float(frame_times[next_frame]), hermite(y0, dy0, y1, dy1, dt, s))
                next_frame += 1
            x = x_next
            step += 1
            if progress is not None and step % 100 == 0:
                progress(step, total)

    if failure == Failure.NONE and not guide.arrived:
        failure, fail_t = Failure.TOO_SLOW, rec_t[-1]
        reason = (
            f"reached {guide.target_index} of {len(waypoints)} waypoints by "
            f"T_max = {scenario.duration_s:g} s"
        )
    return RunResult(
        t_s=np.array(rec_t),
        states=np.array(rec_x),
        offset_rad=np.array(rec_g),
        alpha_rad=np.array(rec_a),
        target_index=np.array(rec_w, dtype=np.int64),
        camera_t_s=np.array(cam_t),
        camera_pose=np.array(cam_pose).reshape(-1, 3),
        failure=failure,
        failure_time_s=fail_t,
        reason=reason,
        arrival_time_s=guide.arrival_time_s,
        distance_left_m=distance_left(x[n : n + 2], waypoints, guide.target_index),
    )


def plant_rhs(
    model: SwimmerModel, torque_nm: FloatArray | TorqueLaw, current_m_s: FloatArray
) -> Callable[[float, FloatArray], FloatArray]:
    """The plant's right-hand side ``f(t, state)`` for RK4, driven by the joints.

    Parameters
    ----------
    model : SwimmerModel
        The plant.
    torque_nm : ndarray of shape (N-1,), or callable
        Torques held over the step, or a :data:`TorqueLaw` evaluated at every call (see
        :class:`JointDrive`).
    current_m_s : ndarray, shape (2,)
        Uniform current velocity.

    Returns
    -------
    callable
    """
    if callable(torque_nm):
        law = torque_nm

        def rhs(t: float, state: FloatArray) -> FloatArray:
            return state_derivative(model, state, law(t, state), current_m_s)

    else:
        held = np.asarray(torque_nm, dtype=float)

        def rhs(t: float, state: FloatArray) -> FloatArray:
            return state_derivative(model, state, held, current_m_s)

    return rhs


def check_failures(
    model: SwimmerModel, x: FloatArray, limit: float, check_condition: bool
) -> tuple[Failure, str]:
    """The failure conditions of a state (non-finite or diverged, ill-conditioned, self-collision).

    Parameters
    ----------
    model : SwimmerModel
    x : ndarray
        The state.
    limit : float
        Mechanical joint limit.
    check_condition : bool
        Also compute the mass matrix's condition number (done at control updates only).

    Returns
    -------
    (Failure, str)
        The flag and its reason (``Failure.NONE`` and an empty string when none).
    """
    n = model.n_links
    if not np.all(np.isfinite(x)):
        return Failure.ILL_CONDITIONED, "state is not finite (the integration blew up)"
    if np.abs(x[n + 2 :]).max() > DIVERGENCE_RATE:
        return (
            Failure.ILL_CONDITIONED,
            "rates beyond any physical motion (the integration diverged)",
        )
    if check_condition:
        cond = np.linalg.cond(mass_matrix(model, x))
        if not cond < ILL_CONDITION_THRESHOLD:
            return (
                Failure.ILL_CONDITIONED,
                f"mass matrix condition number {cond:.3g} is above {ILL_CONDITION_THRESHOLD:.0e}",
            )
    X, Y = link_positions(model, x)
    why = self_collision(X, Y, x[:n], model.half_length_m, limit)
    if why is not None:
        return Failure.SELF_COLLISION, why
    return Failure.NONE, ""
