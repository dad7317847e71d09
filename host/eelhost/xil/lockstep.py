"""Lockstep: the robot's firmware and the twin's plant on one integer clock, the host on a Link.

One stepper, :class:`Lockstep`, is the robot's side of every lockstep simulation: once per
physics step of ``dt_us`` (10,000 us) at ``t_us = k * dt_us`` its :class:`~eelhost.xil.drivers.
JointDriver` (the native firmware, the AVR image in simavr, or the twin's laws held) is fed the
bytes the uplink of a radio model (:mod:`eelhost.xil.radio`) has delivered, ticks once with the
plant's joint angles and rates, and returns the torques held over the step; what it transmits goes
into the downlink. Two loops drive it:

- :func:`run_lockstep` (and :func:`run_firmware_in_loop`): the twin's closed loop
  (:func:`eelsim.closed_loop.simulate_closed_loop`) with the joint torques from the driver;
- :class:`eelhost.xil.virtual_robot.VirtualRobot`: the robot behind ``sim://``, stepped whenever
  the host's clock moves, the plant advanced by :func:`plant_step`.

On the host's side there is one session, :class:`eelhost.link.base.Link`, as at the tank: here
over :class:`eelhost.link.sim_transport.SimTransport` (the host's end of the radio channels),
timed by a :class:`SimClock`.

In :func:`run_lockstep` the loop itself (camera, waypoints, control updates and their delay,
failure checks, recording, stopping rules) is the twin's; :class:`LinkedJoints` is the
:class:`eelsim.closed_loop.JointController` that takes the joints' place. One physics step, in
this order:

1. the host's clock moves to ``t_us``; the link reads the bytes the downlink has delivered (Acks,
   Telemetry) and resends any configuration command not acknowledged after ``resend_after_us``;
   the host sends Start again if the robot reports FAILSAFE while it wants it running
   (``restart_on_failsafe``);
2. when the loop hands over a heading offset (computed at the twin's control updates from the
   filtered camera pose, exactly as in the twin, and due now that the extra delay has passed), the
   host sends it in a SetOffset frame (which also keeps the firmware's link watchdog fed);
3. the driver ticks once at ``t_us`` (the :class:`Lockstep` step above);
4. the loop records the state and checks it for failures as in the twin;
5. RK4 advances the plant by one step with those torques held constant (a zero-order hold, as a
   firmware that runs its PD once per control update applies them); camera frames falling in the
   step observe the interpolated pose, as in the twin. With the servo joint model
   (``[joints] model = "servo"``) the angles the firmware commands are instead the servo
   references, held over the step, and the servo law drives the joints
   (:func:`eelsim.closed_loop.held_reference_drive`; the firmware's torques are recorded only).

At ``t_us = 0`` the host sends Hello, SetGains (the robot file's k_p, k_d; the protocol's
defaults with the servo joint model, whose firmware torques drive nothing), SetGait (the scenario's
gait with slew rates 0, so the firmware reproduces the twin's zero-order hold of the offset),
SetOffset and Start. Over an ideal link (``radio=None``) these arrive before the first tick, the
gait's phase starts at 0 with the twin's, and the only differences from the twin are float32
arithmetic and the torque hold; see ``hil_tests/README.md`` for the measured size of both.

There are no threads, sleeps or wall clocks (unless a :class:`SimClock` is asked to keep pace
with the wall clock): the same seed gives the same run, byte for byte.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from eelhost.errors import UserError
from eelhost.link.base import Link, LinkEvent
from eelhost.link.sim_transport import SimTransport
from eelhost.wire import protocol
from eelhost.xil.drivers import JointDriver, NativeDriver
from eelhost.xil.native_firmware import N_JOINTS, NativeFirmware, store_settings
from eelhost.xil.radio import ChannelCounters, RadioModel
from eelsim.closed_loop import (
    JointDrive,
    LoopOptions,
    RunResult,
    held_reference_drive,
    plant_rhs,
    servo_limited,
    simulate_closed_loop,
)
from eelsim.integrate import rk4_step
from eelsim.joints import pd_gains
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import Scenario
from eelsim.timing import PHYSICS_STEP_US

__all__ = [
    "DT_US",
    "ExecutedCommand",
    "FirmwareRunResult",
    "LinkedJoints",
    "Lockstep",
    "LockstepError",
    "LockstepOptions",
    "RobotTick",
    "SimClock",
    "joint_drive",
    "plant_step",
    "run_firmware_in_loop",
    "run_lockstep",
]

FloatArray = NDArray[np.float64]
# The twin's physics step: the firmware's control period, from protocol/eelbot.toml through the
# generated eelsim.firmware_timing (docs/firmware.md, "Timing defined once").
DT_US = PHYSICS_STEP_US
# SetGains takes torque limits up to 10 N m; the twin's PD has no limit unless servo limits are on.
NO_TORQUE_LIMIT_NM = 10.0


class LockstepError(UserError, ValueError):
    """A lockstep run that cannot be set up (a robot the firmware cannot drive, a bad step)."""


class SimClock:
    """Simulated time for the host's :class:`~eelhost.link.base.Link`; waiting on it steps the robot.

    Parameters
    ----------
    advance : callable, optional
        ``advance(t_us)`` runs the simulation up to ``t_us`` whenever :meth:`wait_until` moves the
        clock forward (the virtual robot); without it the clock is only set (a loop that owns the
        steps, as :func:`run_lockstep`).
    speed : float
        Simulated seconds per wall second; 0 for as fast as possible.
    """

    def __init__(self, advance: Callable[[int], None] | None = None, speed: float = 0.0) -> None:
        if not (speed >= 0 and np.isfinite(speed)):
            raise LockstepError(f"speed must be finite and >= 0, got {speed}")
        self.speed = speed
        self._advance = advance
        self._t_s = 0.0
        self._wall0 = time.monotonic()

    def now(self) -> float:
        """Simulated time, s."""
        return self._t_s

    def now_us(self) -> int:
        """Simulated time, us (rounded)."""
        return round(self._t_s * 1e6)

    def wait_until(self, t_s: float) -> None:
        """Step the simulation to ``t_s`` (and, with a speed, keep pace with the wall clock)."""
        if t_s <= self._t_s:
            return
        if self._advance is not None:
            self._advance(round(t_s * 1e6))
        self._t_s = t_s
        if self.speed > 0:
            lag = self._wall0 + t_s / self.speed - time.monotonic()
            if lag > 0:
                time.sleep(lag)


@dataclass(frozen=True)
class RobotTick:
    """What the robot's side did in one physics step.

    Attributes
    ----------
    t_us : int
        Start of the step.
    torque_nm : ndarray, shape (N-1,)
        Joint torques held over the step.
    alpha_rad : ndarray, shape (N-1,)
        The joint references in force at ``t_us``.
    phi_dot_rad_s : ndarray, shape (N-1,)
        The plant's joint rates the driver was given.
    servo_command_rad : ndarray, shape (N-1,)
        The angles the robot commands its servos to (the references, or with joint feedback
        phi + u / k_s: the driver's ``servo_command_rad`` where it has one).
    """

    t_us: int
    torque_nm: FloatArray
    alpha_rad: FloatArray
    phi_dot_rad_s: FloatArray
    servo_command_rad: FloatArray


class Lockstep:
    """The robot's side of a lockstep simulation: a driver behind a radio, ticked once per step.

    Parameters
    ----------
    driver : JointDriver
        The robot: native firmware, emulated AVR, or the twin's laws held.
    radio : RadioModel
        The link, both directions.
    seed : int
        Seed of the radio's loss and corruption (see :meth:`RadioModel.channels`).
    n_links : int
        Number of links N of the plant.
    dt_us : int
        Physics step; step k starts at ``k * dt_us``.

    Attributes
    ----------
    uplink, downlink : RadioChannel
        Host -> robot and robot -> host.
    on_transmit : callable or None
        ``on_transmit(t_us, data)`` sees every chunk the robot transmits, before the radio.
    """

    def __init__(
        self, driver: JointDriver, radio: RadioModel, seed: int, n_links: int, dt_us: int = DT_US
    ) -> None:
        self.driver = driver
        self.n_links = n_links
        self.dt_us = dt_us
        self.uplink, self.downlink = radio.channels(seed)
        self.on_transmit: Callable[[int, bytes], None] | None = None

    def tick(self, step: int, state: FloatArray) -> RobotTick:
        """Tick the driver at the start of physics step ``step`` with the plant in ``state``.

        Parameters
        ----------
        step : int
            Index of the step (``t_us = step * dt_us``).
        state : ndarray, shape (2 N + 4,)
            The plant's state at ``t_us``.

        Returns
        -------
        RobotTick
        """
        n = self.n_links
        t_us = step * self.dt_us
        phi = np.diff(state[:n])
        phi_dot = np.diff(state[n + 2 : 2 * n + 2])
        torque, alpha, tx = self.driver.step(t_us, self.dt_us, self.uplink, phi, phi_dot)
        for t_tx, data in tx:
            self.downlink.send(t_tx, data)
            if self.on_transmit is not None:
                self.on_transmit(t_tx, data)
        command = getattr(self.driver, "servo_command_rad", alpha)
        return RobotTick(t_us, torque, alpha, phi_dot, np.array(command, dtype=float))

    def host_transport(self, clock: SimClock) -> SimTransport:
        """The host's end of this radio, stamped by ``clock``."""
        return SimTransport(self.uplink, self.downlink, clock.now_us)


@dataclass(frozen=True)
class LockstepOptions:
    """How a firmware-in-the-loop run is done, besides the robot, the task and the link.

    Attributes
    ----------
    loop : LoopOptions
        The twin's loop options (physics step, control period and delay, camera, servo limits,
        stopping rule), used exactly as :func:`eelsim.closed_loop.simulate_closed_loop` uses them.
    resend_after_us : int
        A configuration command (SetGains, SetGait, Start) not acknowledged this long after it was
        sent is sent again, with a new sequence number.
    restart_on_failsafe : bool
        Send Start again when the robot's telemetry reports FAILSAFE (the host wants it running).
    firmware_control_period_us : int
        The firmware's control period: 0 runs a control update on every tick (the lockstep mode),
        10000 as on the robot (the same thing with ticks every 10 ms).
    host_silent_after_us : int or None
        The host stops from this time on, neither sending nor reading (a host that hangs), or
        never.
    joint_feedback : bool
        The native firmware boots with analog joint feedback on (setting ``joint_feedback`` saved
        in its EEPROM): it measures the plant's joint angles through its ADC and runs the PD
        itself (:class:`eelhost.xil.drivers.NativeDriver`).
    """

    loop: LoopOptions = field(default_factory=LoopOptions)
    resend_after_us: int = 200_000
    restart_on_failsafe: bool = True
    firmware_control_period_us: int = 0
    host_silent_after_us: int | None = None
    joint_feedback: bool = False


@dataclass(frozen=True)
class ExecutedCommand:
    """A command the firmware acknowledged, with the frame the host sent under that number.

    Attributes
    ----------
    t_us : int
        When the firmware sent the Ack (its tick or, in the emulator, the first byte's time).
    seq : int
        Sequence number the firmware acknowledged.
    msg_id : int
        Message id the firmware acknowledged.
    sent : protocol.Message or None
        The message the host last sent with that sequence number (None if it never did).
    """

    t_us: int
    seq: int
    msg_id: int
    sent: protocol.Message | None

    @property
    def matches(self) -> bool:
        """True when the host sent a message of this id under this sequence number."""
        return self.sent is not None and self.sent.MSG_ID == self.msg_id


@dataclass
class FirmwareRunResult(RunResult):
    """A closed-loop run driven by firmware, with what the firmware and the link did.

    The twin's :class:`~eelsim.closed_loop.RunResult` (``alpha_rad`` and ``offset_rad`` are the
    firmware's references and present offset), plus:

    Attributes
    ----------
    torque_nm : ndarray, shape (K, N-1)
        Joint torques applied over each recorded step.
    firmware_state : ndarray of int, shape (K,)
        The robot's state (:class:`eelhost.wire.protocol.State`) after each tick; -1 where unknown.
    sent : list of (int, int, protocol.Message)
        Every frame the host sent: (time, seq, message).
    executed : list of ExecutedCommand
        Every command the firmware acknowledged, read from its UART before the radio.
    refused : list of (int, protocol.Refuse)
        Every Refuse the firmware sent (time, message).
    telemetry : list of (int, protocol.Telemetry)
        Telemetry as the host received it through the downlink (arrival time, message).
    firmware_counters : dict
        The firmware's final link counters (native: ``NativeFirmware.status()``; emulated AVR:
        from its last telemetry).
    host_bad_frames : dict
        Frames from the robot the host could not decode, by kind.
    uplink, downlink : ChannelCounters
        What the radio did to the bytes, per direction.
    cpu_s : float
        CPU time the run took (for reports only).
    """

    torque_nm: FloatArray = field(default_factory=lambda: np.zeros((0, N_JOINTS)))
    firmware_state: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    sent: list[tuple[int, int, protocol.Message]] = field(default_factory=list)
    executed: list[ExecutedCommand] = field(default_factory=list)
    refused: list[tuple[int, protocol.Refuse]] = field(default_factory=list)
    telemetry: list[tuple[int, protocol.Telemetry]] = field(default_factory=list)
    firmware_counters: dict[str, Any] = field(default_factory=dict)
    host_bad_frames: dict[str, int] = field(default_factory=dict)
    uplink: ChannelCounters = field(default_factory=ChannelCounters)
    downlink: ChannelCounters = field(default_factory=ChannelCounters)
    cpu_s: float = 0.0


def plant_step(
    model: SwimmerModel,
    x: FloatArray,
    torque_nm: FloatArray | JointDrive,
    t_s: float,
    dt_s: float,
    current_m_s: tuple[float, float] = (0.0, 0.0),
) -> FloatArray:
    """Advance the twin's plant by one RK4 step with the joint torques held (a zero-order hold).

    The step the twin's closed loop takes in :func:`run_lockstep`, for callers that own their loop
    (the virtual robot, :class:`eelhost.xil.virtual_robot.VirtualRobot`).

    Parameters
    ----------
    model : SwimmerModel
        The plant.
    x : ndarray, shape (2 N + 4,)
        State at ``t_s``.
    torque_nm : ndarray of shape (N-1,), or JointDrive
        Joint torques held over the step, or what drives the joints (:func:`joint_drive`).
    t_s, dt_s : float
        Start and length of the step, s.
    current_m_s : (float, float)
        Uniform current velocity.

    Returns
    -------
    ndarray
        The state at ``t_s + dt_s``.

    Raises
    ------
    FloatingPointError
        When the mass matrix is singular or the new state is not finite (the twin's
        ILL_CONDITIONED flag).
    """
    drive = torque_nm if isinstance(torque_nm, JointDrive) else np.asarray(torque_nm, dtype=float)
    rhs = plant_rhs(model, drive, np.asarray(current_m_s, dtype=float))
    with np.errstate(all="ignore"):
        try:
            x_next = rk4_step(rhs, t_s, x, dt_s)
        except np.linalg.LinAlgError as err:
            raise FloatingPointError("mass matrix is not positive definite") from err
    if not np.all(np.isfinite(x_next)):
        raise FloatingPointError("state is not finite (the integration blew up)")
    return x_next


def _dt_us(options: LoopOptions) -> int:
    dt_us = round(options.timing.dt_s * 1e6)
    if dt_us <= 0 or abs(dt_us * 1e-6 - options.timing.dt_s) > 1e-12:
        raise LockstepError(f"physics step {options.timing.dt_s} s is not a whole number of us")
    return dt_us


class LinkedJoints:
    """A robot-side driver behind the host's link and a radio, as the twin loop's joints.

    The :class:`eelsim.closed_loop.JointController` of :func:`run_lockstep`: each physics step the
    host's clock moves to the step, its :class:`~eelhost.link.base.Link` polls (reading Acks and
    Telemetry, resending what is due) and sends its frames (configuration at step 0, then every
    offset the loop hands over as a SetOffset), the :class:`Lockstep` ticks once with the plant's
    joint angles, and the driver's torques are held over the step. It keeps what the run needs
    besides the twin's records: the torques, the robot's state, what the host sent and received,
    the commands the robot executed or refused.

    Parameters
    ----------
    robot : Robot
        Its k_p, k_d go out with SetGains; its servo figures limit the torques when asked.
    scenario : Scenario
        Its gait goes out with SetGait (slew rates 0).
    lockstep : Lockstep
        The robot's side.
    link : Link
        The host's session, opened, over ``lockstep``'s radio and timed by ``clock``.
    clock : SimClock
        The host's clock (moved to each step's start).
    options : LockstepOptions
        Host options and the loop's servo-limit switch.
    """

    def __init__(
        self,
        robot: Robot,
        scenario: Scenario,
        lockstep: Lockstep,
        link: Link,
        clock: SimClock,
        options: LockstepOptions,
    ) -> None:
        self.lockstep = lockstep
        self.link = link
        self.clock = clock
        self._robot = robot
        self._gait = scenario.gait
        self._options = options
        self.torque_nm: list[FloatArray] = []
        self.firmware_state: list[int] = []
        self.sent: list[tuple[int, int, protocol.Message]] = []
        self.telemetry: list[tuple[int, protocol.Telemetry]] = []
        self.executed: list[ExecutedCommand] = []
        self.refused: list[tuple[int, protocol.Refuse]] = []
        self._raw_reader = protocol.FrameReader()  # the robot's UART before the radio
        link.listeners.append(self._on_link_event)
        lockstep.on_transmit = self._on_transmit

    def _on_link_event(self, event: LinkEvent) -> None:
        if event.kind in ("sent", "resent") and event.message is not None:
            self.sent.append((round(event.t_s * 1e6), event.seq, event.message))

    def _on_transmit(self, t_us: int, data: bytes) -> None:
        for _, msg in self._raw_reader.feed(data):
            if isinstance(msg, protocol.Ack):
                sent = self.link.sent_under(msg.seq)
                self.executed.append(ExecutedCommand(t_us, msg.seq, msg.msg_id, sent))
            elif isinstance(msg, protocol.Refuse):
                self.refused.append((t_us, msg))

    def _send_configuration(self) -> None:
        joints = self._robot.joints
        servo_limits = self._options.loop.servo_limits
        torque_limit = joints.servo_max_torque_nm if servo_limits else NO_TORQUE_LIMIT_NM
        gait = self._gait
        gains = pd_gains(joints)  # None with the servo model: the firmware's torques drive nothing
        self.link.send(protocol.Hello())
        self.link.send(
            protocol.SetGains(*gains, torque_limit)
            if gains is not None
            else protocol.SetGains(torque_limit_nm=torque_limit),
            want_ack=True,
        )
        self.link.send(
            protocol.SetGait(gait.amplitude_rad, gait.omega_rad_s, gait.beta_rad, 0, 0, 0),
            want_ack=True,
        )

    def _service(self, t_us: int) -> None:
        """Read the link (it resends what is due), and restart a robot that fell into FAILSAFE."""
        fresh = [m for m in self.link.poll() if isinstance(m, protocol.Telemetry)]
        self.telemetry.extend((t_us, m) for m in fresh)
        if (
            self._options.restart_on_failsafe
            and fresh
            and fresh[-1].state == protocol.State.FAILSAFE
            and not any(isinstance(m, protocol.Start) for m in self.link.pending())
        ):
            self.link.send(protocol.Start(), want_ack=True)

    def on_step(
        self, step: int, t_s: float, state: FloatArray, offset_command: float | None
    ) -> JointDrive:
        """See :meth:`eelsim.closed_loop.JointController.on_step`."""
        t_us = step * self.lockstep.dt_us
        silent_after = self._options.host_silent_after_us
        if silent_after is None or t_us < silent_after:
            self.clock.wait_until(t_us * 1e-6)
            self._service(t_us)
            if step == 0:
                self._send_configuration()
            if offset_command is not None:
                # SetOffset takes [-1, 1] rad; the twin's k_theta * pi stays inside for k < 0.32.
                self.link.send(protocol.SetOffset(float(np.clip(offset_command, -1.0, 1.0))))
            if step == 0:
                # after the first offset, so that the gait starts with it
                self.link.send(protocol.Start(), want_ack=True)

        tick = self.lockstep.tick(step, state)
        robot_state, offset = self.lockstep.driver.observe()
        self.torque_nm.append(tick.torque_nm)
        self.firmware_state.append(robot_state)

        return joint_drive(self._robot, tick, offset, self._options.loop.servo_limits)


def joint_drive(robot: Robot, tick: RobotTick, offset_rad: float, servo_limits: bool) -> JointDrive:
    """What drives the plant's joints over a step, from what the robot's side did in it.

    The PD joint model: the driver's torques, held (clipped to the servos' torque-speed line when
    ``servo_limits``). The servo joint model: the driver's commanded angles are the servo
    references, held, and the servo law drives the joints
    (:func:`eelsim.closed_loop.held_reference_drive`).

    Parameters
    ----------
    robot : Robot
    tick : RobotTick
    offset_rad : float
        The offset acting (recorded).
    servo_limits : bool
        The loop's option (PD model only).

    Returns
    -------
    JointDrive
    """
    if robot.joint_model.kinematic:
        drive = held_reference_drive(robot, tick.servo_command_rad, offset_rad)
        return replace(drive, alpha_rad=tick.alpha_rad)
    held = np.asarray(tick.torque_nm, dtype=float)
    if servo_limits:
        joints = robot.joints
        held = servo_limited(
            held, tick.phi_dot_rad_s, joints.servo_max_torque_nm, joints.servo_max_speed_rad_s
        )
    return JointDrive(held, tick.alpha_rad, offset_rad)


def run_lockstep(
    robot: Robot,
    scenario: Scenario,
    driver: JointDriver,
    seed: int = 0,
    radio: RadioModel | None = None,
    options: LockstepOptions | None = None,
) -> FirmwareRunResult:
    """Run the twin's closed loop with the joint torques from ``driver`` (any robot-side model).

    Parameters
    ----------
    robot : Robot
        The robot (geometry, gains, limits).
    scenario : Scenario
        Gait, waypoints, current, duration, start pose.
    driver : JointDriver
        The robot's side: native firmware, emulated AVR, the twin's laws held.
    seed : int
        Seed of the twin's period jitter and heading noise (drawn exactly as the twin draws them)
        and, through separate streams, of the radio's loss and corruption.
    radio : RadioModel, optional
        The link, both directions; ``None`` is an ideal link.
    options : LockstepOptions, optional
        Loop, host and firmware options.

    Returns
    -------
    FirmwareRunResult
        Never raises for a run that goes wrong: failures come back as flags, as in the twin.

    Raises
    ------
    LockstepError
        When the robot's joint count is not the firmware's, or the physics step is not a whole
        number of microseconds.
    """
    cpu0 = time.process_time()
    opts = options or LockstepOptions()
    dt_us = _dt_us(opts.loop)
    if robot.n_links - 1 != N_JOINTS:
        raise LockstepError(
            f"the firmware drives {N_JOINTS} joints; this robot has {robot.n_links - 1}"
        )
    lockstep = Lockstep(driver, radio or RadioModel(), seed, robot.n_links, dt_us)
    clock = SimClock()
    # Resent when (now - sent) >= resend_after_us on the integer clock: the half microsecond
    # keeps the link's comparison in seconds exact whatever the rounding of the two times.
    link = Link(
        lockstep.host_transport(clock),
        clock,
        resend_after_s=(opts.resend_after_us - 0.5) * 1e-6,
        max_attempts=None,
    )
    link.open()
    joints = LinkedJoints(robot, scenario, lockstep, link, clock, opts)

    twin = simulate_closed_loop(robot, scenario, opts.loop, seed, joints=joints)

    return FirmwareRunResult(
        **{f.name: getattr(twin, f.name) for f in fields(RunResult)},
        torque_nm=np.array(joints.torque_nm),
        firmware_state=np.array(joints.firmware_state, dtype=np.int64),
        sent=joints.sent,
        executed=joints.executed,
        refused=joints.refused,
        telemetry=joints.telemetry,
        firmware_counters=driver.counters(),
        host_bad_frames=dict(link.counters.bad_frames),
        uplink=lockstep.uplink.counters,
        downlink=lockstep.downlink.counters,
        cpu_s=time.process_time() - cpu0,
    )


def run_firmware_in_loop(
    robot: Robot,
    scenario: Scenario,
    seed: int = 0,
    radio: RadioModel | None = None,
    options: LockstepOptions | None = None,
    firmware: NativeFirmware | None = None,
) -> FirmwareRunResult:
    """Run the twin's closed loop with the native firmware computing the joint torques.

    Parameters
    ----------
    robot : Robot
        The robot; its joint gains k_p, k_d are sent to the firmware with SetGains.
    scenario : Scenario
        The task; its gait is sent with SetGait (slew rates 0: no limit).
    seed : int
        Seed of the twin's jitter and heading noise and of the radio's loss and corruption.
    radio : RadioModel, optional
        The link; ``None`` is ideal (bytes arrive when sent), as the twin assumes.
    options : LockstepOptions, optional
        Loop, host and firmware options.
    firmware : NativeFirmware, optional
        A firmware instance to use (booted at 0); by default a fresh one.

    Returns
    -------
    FirmwareRunResult
        The twin's result fields plus the firmware's torques, states, the commands it executed,
        its telemetry and counters, and what the radio did.

    Examples
    --------
    >>> from eelsim.robot import load_robot
    >>> from eelsim.scenario import load_scenario
    >>> from eelhost.xil.radio import RadioModel
    >>> res = run_firmware_in_loop(load_robot(), load_scenario("straight"), seed=1,
    ...                            radio=RadioModel.xbee())  # doctest: +SKIP
    """
    opts = options or LockstepOptions()
    fw = firmware or NativeFirmware(now_us=0, control_period_us=opts.firmware_control_period_us)
    if opts.joint_feedback:
        store_settings(fw, {"joint_feedback": 1.0})
    return run_lockstep(robot, scenario, NativeDriver(fw), seed, radio, opts)
