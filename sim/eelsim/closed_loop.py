"""The twin swimming under the robot's own control stack (docs/model.md sections 4, 5 and 7).

Per physics step (RK4, dt = 0.01 s by default):

- the joints track the gait alpha_j(t) (with the held offset gamma) through the robot's joint
  model (``[joints] model``, :mod:`eelsim.joints`), evaluated inside every RK4 stage as the
  robot's fast joint loop does: the PD law's torques on free joints (optionally through a
  hobby-servo torque-speed limit), or the servo law's joint accelerations with x, y and the
  heading from the prescribed-shape dynamics; the torque each joint gives (or must give) is
  recorded at every step and steps outside the servo's torque-speed line are counted;
- the camera takes its frames (30 fps) between steps and quantises positions to pixels; the
  guidance (:class:`eelsim.guidance.Guidance`) filters them with the moving median and switches
  to the next waypoint when the filtered position is inside the acceptance circle;
- every control period (0.3 s, optionally jittered) the guidance's line-of-sight law computes a
  new offset from the latest filtered pose; it reaches the joints after the extra delay and is
  held;
- the failure conditions are checked; a failed run stops and returns its flag, time and reason.

The joints are the one part that can be swapped: a :class:`JointController` turns the offset and
the plant's state into the torques (or joint accelerations) of each step. The default,
:class:`TwinJoints`, is the robot's joint model above; ``eelhost.xil`` plugs in the robot's
firmware (native or emulated AVR) behind a radio link, which is ticked once per step and whose
torques (or, with the servo model, commanded angles) are held over it. Everything else (camera,
waypoints, control updates, failures, recording) is this one loop, so a firmware run and a twin
run differ only where the robot differs.

This is the readable reference implementation; ``eelsim.batch`` runs the same physics fast.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from eelsim.camera import CameraModel, hermite, quantise_position
from eelsim.control import Gait, gait_reference
from eelsim.dynamics import (
    link_positions,
    mass_matrix,
    prescribed_shape_derivative,
    state_derivative,
    straight_state,
)
from eelsim.flags import DIVERGENCE_RATE, ILL_CONDITION_THRESHOLD, Failure, penalty, self_collision
from eelsim.fluid import FluidCoefficients
from eelsim.guidance import PURSUIT, Guidance, GuidanceLaw
from eelsim.integrate import rk4_step
from eelsim.joints import PD, stiffness_hint
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
        Limit the PD model's joint torques by the servos' torque-speed line (stall torque,
        no-load speed). The servo joint model has its own limits (rate limit; torque counted
        as saturation) and ignores this.
    stop_at_goal : bool
        End the run when the last waypoint is reached (not before the scenario's
        ``min_duration_s``).
    guidance : GuidanceLaw
        The line-of-sight law (default the paper's pure pursuit; docs/model.md section 4).
    """

    timing: LoopTiming = field(default_factory=LoopTiming)
    camera: CameraModel = field(default_factory=CameraModel)
    servo_limits: bool = False
    stop_at_goal: bool = True
    guidance: GuidanceLaw = PURSUIT


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
    joint_torque_nm : ndarray, shape (K, N-1)
        The torque each joint gives at each recorded step: the PD law at the step's start (held
        torques for a controller that holds them), or what the servos must give for the servo
        model (prescribed-shape dynamics); NaN where it could not be computed.
    saturated_steps : int
        Recorded steps at which some joint's torque is outside the servo's torque-speed line
        (stall torque ``servo_max_torque_nm``, falling to zero at ``servo_max_speed_rad_s``): a
        warning, not a failure (docs/model.md section 4). With the PD model and the loop's
        ``servo_limits`` the torque is clipped to the line and never counts.
    torque_limit_nm : float
        The stall torque that :attr:`max_torque_ratio` divides by.
    integral_s : ndarray, shape (K, 2)
        The guidance's ILOS integral vector at each recorded step, before that step's control
        update (zero with pure pursuit; docs/model.md section 4).
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
    joint_torque_nm: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    saturated_steps: int = 0
    torque_limit_nm: float = float("inf")
    integral_s: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def max_torque_ratio(self) -> float:
        """Largest |u| over the recorded steps and joints, as a fraction of the stall torque.

        Steps whose torque is not finite are left out (0 when none is).
        """
        finite = self.joint_torque_nm[np.isfinite(self.joint_torque_nm)]
        return float(np.abs(finite).max() / self.torque_limit_nm) if finite.size else 0.0

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
AccelerationLaw = Callable[[float, FloatArray], FloatArray]
"""Joint accelerations as a function of time and state, ``phi_ddot(t_s, state)``."""


def outside_torque_speed_line(
    torque_nm: FloatArray, phi_dot_rad_s: FloatArray, stall_nm: float, no_load_rad_s: float
) -> bool:
    """Whether some joint's torque lies outside the servo's torque-speed line (saturation).

    The line of :func:`servo_limited`: up to the stall torque at rest, driving torque falling
    to zero at the no-load speed; with a relative tolerance of 1e-9 of the stall torque, so that
    a torque clipped to the line does not count. The batched kernel counts with the same
    expression.

    Parameters
    ----------
    torque_nm, phi_dot_rad_s : ndarray, shape (N-1,)
    stall_nm, no_load_rad_s : float

    Returns
    -------
    bool
        False for torques that are not finite.
    """
    q = phi_dot_rad_s * (stall_nm * (1.0 / no_load_rad_s))
    tol = 1e-9 * stall_nm
    upper = np.minimum(stall_nm, stall_nm - q)
    lower = np.maximum(-stall_nm, -stall_nm - q)
    return bool(np.any((torque_nm > upper + tol) | (torque_nm < lower - tol)))


@dataclass(frozen=True)
class JointDrive:
    """What drives the joints over one physics step, and what the run records of it.

    Attributes
    ----------
    torque_nm : ndarray of shape (N-1,), callable, or None
        Either torques held over the whole step (a zero-order hold: a controller ticked once per
        step), or a :data:`TorqueLaw` evaluated at every RK4 stage (a joint loop much faster than
        the step, as the twin models the PD loop); None with ``joint_acceleration``.
    alpha_rad : ndarray, shape (N-1,)
        The joint references in force at the start of the step (recorded).
    offset_rad : float
        The offset gamma acting on the joints (recorded).
    joint_acceleration : callable, optional
        An :data:`AccelerationLaw` evaluated at every RK4 stage: the joint angles follow it
        whatever the water does (kinematic joints, the servo model) and the plant is the
        prescribed-shape dynamics (``eelsim.dynamics.prescribed_shape_derivative``).
    """

    torque_nm: FloatArray | TorqueLaw | None
    alpha_rad: FloatArray
    offset_rad: float
    joint_acceleration: AccelerationLaw | None = None


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
    """The twin's joints: the gait and the robot's joint model, evaluated inside every RK4 stage.

    The PD model gives torques (optionally clipped to the servos' torque-speed line), the servo
    model joint accelerations (:mod:`eelsim.joints`). The offset is held from one command to the
    next (a zero-order hold). The default :class:`JointController` of
    :func:`simulate_closed_loop`.

    Parameters
    ----------
    robot : Robot
        Joint model and its parameters, reference clamp and servo figures.
    gait : Gait
        The gait the joints follow (its phase starts at t = 0).
    n_links : int
        Number of links N.
    servo_limits : bool
        Clip the PD model's torques to the servos' torque-speed line.
    """

    def __init__(self, robot: Robot, gait: Gait, n_links: int, servo_limits: bool = False) -> None:
        self._gait = gait
        self._n = n_links
        self._joints = robot.joints
        self._model = robot.joint_model
        self._clamp = robot.joints.command_limit_rad
        self._servo = (
            (robot.joints.servo_max_torque_nm, robot.joints.servo_max_speed_rad_s)
            if servo_limits and not self._model.kinematic
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
        alpha = np.clip(alpha, -self._clamp, self._clamp)
        if self._model.kinematic:
            return JointDrive(None, alpha, self.offset_rad, joint_acceleration=self.law)
        return JointDrive(self.law, alpha, self.offset_rad)

    def law(self, t_s: float, state: FloatArray) -> FloatArray:
        """The joint model's law at ``t_s`` in ``state``: torques or joint accelerations."""
        n = self._n
        alpha, alpha_dot = gait_reference(t_s, self._gait, self.offset_rad, n)
        alpha = np.clip(alpha, -self._clamp, self._clamp)
        w = state[n + 2 : 2 * n + 2]
        u = self._model.drive(self._joints, alpha, alpha_dot, np.diff(state[:n]), np.diff(w))
        if self._servo is not None:
            u = servo_limited(u, np.diff(w), *self._servo)
        return u

    torque_nm = law  # the PD model's law by its earlier name (a TorqueLaw)


def held_reference_drive(robot: Robot, alpha_rad: FloatArray, offset_rad: float) -> JointDrive:
    """Kinematic joints following references held over the step, as the robot's joint model does.

    For a controller ticked once per step whose joints are servos (the firmware in the loop,
    ``eelhost.xil``): the angles it commands are the servo references, held over the step; the
    joint law (:meth:`eelsim.joints.JointModel.drive`, reference rate 0) acts at every RK4 stage
    and the plant is the prescribed-shape dynamics (docs/model.md section 4).

    Parameters
    ----------
    robot : Robot
        Its joint model must be kinematic (``[joints] model = "servo"``).
    alpha_rad : ndarray, shape (N-1,)
        The commanded joint angles.
    offset_rad : float
        The offset acting (recorded).

    Returns
    -------
    JointDrive

    Raises
    ------
    ValueError
        When the robot's joint model gives torques (its controller must give them).
    """
    model, spec = robot.joint_model, robot.joints
    if not model.kinematic:
        raise ValueError(f"the {model.name!r} joint model is driven by torques, not references")
    alpha = np.array(alpha_rad, dtype=float)
    zero = np.zeros_like(alpha)
    n = alpha.size + 1

    def law(_t_s: float, state: FloatArray) -> FloatArray:
        return model.drive(spec, alpha, zero, np.diff(state[:n]), np.diff(state[n + 2 : 2 * n + 2]))

    return JointDrive(None, alpha, offset_rad, joint_acceleration=law)


def simulate_closed_loop(
    robot: Robot,
    scenario: Scenario,
    options: LoopOptions | None = None,
    seed: int = 0,
    coefficients: FluidCoefficients | None = None,
    progress: Callable[[int, int], None] | None = None,
    joints: JointController | None = None,
    guidance_state: tuple[float, float, float, float] | None = None,
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
        through the robot's joint model, servo limits as ``options`` says). Another controller
        applies any servo limits itself.
    guidance_state : (x, y, I_x, I_y), optional
        The guidance's state at the start: where the first leg starts (NaN: at the first
        filtered pose, the default) and the ILOS integral vector (default zero). A run restarted
        from another run's state and step carries that run's (``RunResult.integral_s``).

    Returns
    -------
    RunResult
        Never raises for a run that goes wrong: failures come back as flags.

    Raises
    ------
    ValueError
        When the robot's joint model refuses the physics step (the servo model at a step where
        RK4 is unstable on its law; the message names the largest stable step).
    """
    opts = options or LoopOptions()
    timing, cam = opts.timing, opts.camera
    model = SwimmerModel.from_robot(robot, coefficients)
    robot.joint_model.check_step(robot.joints, model, timing.dt_s)
    rng = np.random.default_rng(seed)
    n = model.n_links
    dt = timing.dt_s
    total = scenario.total_steps(dt)
    goal_from = scenario.goal_steps(dt)
    gait = scenario.gait
    limit = robot.joints.limit_rad
    vc = np.asarray(scenario.current_m_s)
    waypoints = np.asarray(scenario.waypoints_m, dtype=float)
    g0 = (math.nan, math.nan, 0.0, 0.0) if guidance_state is None else guidance_state
    guide = Guidance(waypoints, scenario.acceptance_radius_m, gait.k_theta, cam.median_window,
                     law=opts.guidance,
                     leg_start_m=None if math.isnan(g0[0] + g0[1]) else (g0[0], g0[1]),
                     integral_s=(g0[2], g0[3]), control_period_s=timing.control_period_s)
    if joints is None:
        joints = TwinJoints(robot, gait, n, opts.servo_limits)

    updates = set(timing.update_steps(total, rng).tolist())
    frame_times = cam.frame_times(total * dt)

    x = straight_state(model, np.radians(scenario.start_heading_deg), scenario.start_position_m)
    pending: list[tuple[int, float]] = []  # (step at which it acts, offset)
    failure, fail_t, reason = Failure.NONE, None, ""

    rec_t, rec_x, rec_g, rec_a, rec_w, rec_u = [], [], [], [], [], []
    rec_i: list[FloatArray] = []
    stall, no_load = robot.joints.servo_max_torque_nm, robot.joints.servo_max_speed_rad_s
    saturated = 0
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
            rec_i.append(guide.integral_s.copy())
            if step in updates:
                pending.append((step + timing.delay_steps, guide.offset()))
            # An offset reaches the joints the loop's extra delay after its update.
            offset_command = None
            while pending and pending[0][0] <= step:
                offset_command = pending.pop(0)[1]
            # The joints' torques for this step: the twin's PD law by default; in
            # eelhost.xil.lockstep the robot's firmware, ticked once, with its torques held.
            drive = joints.on_step(step, t, x, offset_command)
            rhs = plant_rhs(model, drive, vc)
            # the torque at the step's start (for the servo model the first RK4 stage's
            # solve gives it, and that stage is reused)
            first_stage, torque = _step_start(model, drive, vc, t, x)

            rec_t.append(t)
            rec_x.append(x.copy())
            rec_g.append(drive.offset_rad)
            rec_a.append(drive.alpha_rad)
            rec_w.append(guide.target_index)
            rec_u.append(torque)
            saturated += outside_torque_speed_line(torque, np.diff(x[n + 2 : 2 * n + 2]), stall,
                                                   no_load)

            failure, reason = check_failures(model, x, limit, step in updates)
            if failure != Failure.NONE:
                fail_t = t
                break
            if (guide.arrived and opts.stop_at_goal and step >= goal_from) or step >= total:
                break

            try:
                x_next = rk4_step(rhs, t, x, dt, first_stage)
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

    if failure == Failure.ILL_CONDITIONED and not reason.startswith("mass matrix condition"):
        reason += blow_up_hint(robot, model, dt)
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
        joint_torque_nm=np.array(rec_u, dtype=float).reshape(-1, n - 1),
        saturated_steps=saturated,
        torque_limit_nm=stall,
        integral_s=np.array(rec_i, dtype=float).reshape(-1, 2),
    )


def blow_up_hint(robot: Robot, model: SwimmerModel, dt_s: float) -> str:
    """What to add to the reason of a run that blew up: the PD joints' stiffness, if that is why.

    Parameters
    ----------
    robot : Robot
    model : SwimmerModel
        Its model (the hint's stable step is computed with the robot's own coefficients, so that
        the batched kernel words it the same for every candidate).
    dt_s : float

    Returns
    -------
    str
        Empty unless the robot's joints are the PD model's and ``dt_s`` is beyond RK4's
        stability on their fastest mode (:func:`eelsim.joints.stiffness_hint`).
    """
    if robot.joint_model is not PD:
        return ""
    # the hint is the robot's own (its file's coefficients either way): a planner packs a batch
    # every few milliseconds with the same robot object, and the stable step took a third of
    # the packing. Robots are frozen, and the entry holds the robot, so its id is not reused
    key = (id(robot), float(dt_s))
    known = _BLOW_UP_HINTS.get(key)
    if known is not None and known[0] is robot:
        return known[1]
    own = model if model.coefficients == robot.hydrodynamics else SwimmerModel.from_robot(robot)
    hint = stiffness_hint(robot.joints, PD.largest_stable_step_s(robot.joints, own), dt_s)
    if len(_BLOW_UP_HINTS) >= 64:
        _BLOW_UP_HINTS.clear()
    _BLOW_UP_HINTS[key] = (robot, hint)
    return hint


_BLOW_UP_HINTS: dict[tuple[int, float], tuple[Robot, str]] = {}
""":func:`blow_up_hint`'s words by robot (the frozen object itself) and step."""


def _step_start(
    model: SwimmerModel, drive: JointDrive, current_m_s: FloatArray, t_s: float, x: FloatArray
) -> tuple[FloatArray | None, FloatArray]:
    """The first RK4 stage (for kinematic joints, else None) and the joint torques at (t, x)."""
    n = model.n_links
    if drive.joint_acceleration is not None:
        try:
            return prescribed_shape_derivative(model, x, drive.joint_acceleration(t_s, x),
                                               current_m_s)
        except np.linalg.LinAlgError:  # RK4's first stage meets it again and flags the run
            return None, np.full(n - 1, np.nan)
    if callable(drive.torque_nm):
        return None, np.asarray(drive.torque_nm(t_s, x), dtype=float)
    return None, np.asarray(drive.torque_nm, dtype=float)


def plant_rhs(
    model: SwimmerModel, drive: JointDrive | FloatArray | TorqueLaw, current_m_s: FloatArray
) -> Callable[[float, FloatArray], FloatArray]:
    """The plant's right-hand side ``f(t, state)`` for RK4, driven by the joints.

    Parameters
    ----------
    model : SwimmerModel
        The plant.
    drive : JointDrive, ndarray of shape (N-1,), or callable
        What drives the joints over the step (:class:`JointDrive`: torques held or evaluated at
        every stage, or joint accelerations with the prescribed-shape dynamics), or directly the
        torques held over the step or a :data:`TorqueLaw`.
    current_m_s : ndarray, shape (2,)
        Uniform current velocity.

    Returns
    -------
    callable
    """
    if isinstance(drive, JointDrive):
        if drive.joint_acceleration is not None:
            kinematic = drive.joint_acceleration

            def shape_rhs(t: float, state: FloatArray) -> FloatArray:
                return prescribed_shape_derivative(model, state, kinematic(t, state),
                                                   current_m_s)[0]

            return shape_rhs
        if drive.torque_nm is None:
            raise ValueError("a JointDrive needs torques or joint accelerations")
        drive = drive.torque_nm
    if callable(drive):
        law = drive

        def rhs(t: float, state: FloatArray) -> FloatArray:
            return state_derivative(model, state, law(t, state), current_m_s)

    else:
        held = np.asarray(drive, dtype=float)

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
