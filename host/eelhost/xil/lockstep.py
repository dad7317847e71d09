"""Firmware in the loop: the robot's firmware drives the twin, in lockstep, on one integer clock.

:func:`run_firmware_in_loop` runs the twin's closed loop (:func:`eelsim.closed_loop.
simulate_closed_loop`) with one change: the joint torques come from the robot's firmware, compiled
for this PC (:class:`eelhost.xil.native_firmware.NativeFirmware`, the same C++ sources as the AVR
image), instead of eelsim's PD law. Everything the host does goes to the firmware as real protocol
bytes through a radio model (:mod:`eelhost.xil.radio`), and everything the firmware sends comes back
the same way.

The loop itself (camera, waypoints, control updates and their delay, failure checks, recording,
stopping rules) is the twin's; :class:`LinkedJoints` is the :class:`eelsim.closed_loop.
JointController` that takes the joints' place. One physics step of ``dt_us`` (10,000 us) at
``t_us = k * dt_us``, in this order:

1. the host reads the bytes the downlink has delivered by ``t_us`` (Acks, Telemetry) and resends
   any configuration command not acknowledged after ``resend_after_us``; it sends Start again if
   the robot reports FAILSAFE while the host wants it running (``restart_on_failsafe``);
2. when the loop hands over a heading offset (computed at the twin's control updates from the
   filtered camera pose, exactly as in the twin, and due now that the extra delay has passed), the
   host sends it in a SetOffset frame (which also keeps the firmware's link watchdog fed);
3. the firmware is fed the bytes the uplink has delivered by ``t_us``, ticks once at ``t_us`` with
   the plant's joint angles and rates (float32), and returns its references and PD torques;
4. the loop records the state and checks it for failures as in the twin;
5. RK4 advances the plant by one step with those torques held constant (a zero-order hold, as a
   firmware that runs its PD once per control update applies them); camera frames falling in the
   step observe the interpolated pose, as in the twin.

At ``t_us = 0`` the host sends Hello, SetGains (the robot file's k_p, k_d), SetGait (the scenario's
gait with slew rates 0, so the firmware reproduces the twin's zero-order hold of the offset),
SetOffset and Start. Over an ideal link (``radio=None``) these arrive before the first tick, the
gait's phase starts at 0 with the twin's, and the only differences from the twin are float32
arithmetic and the torque hold; see ``hil_tests/README.md`` for the measured size of both.

There are no threads, sleeps or wall clocks: the same seed gives the same run, byte for byte.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from eelhost.wire import protocol
from eelhost.xil.native_firmware import N_JOINTS, NativeFirmware
from eelhost.xil.radio import ChannelCounters, RadioChannel, RadioModel
from eelsim.closed_loop import (
    JointDrive,
    LoopOptions,
    RunResult,
    plant_rhs,
    servo_limited,
    simulate_closed_loop,
)
from eelsim.control import Gait, gait_reference, joint_pd_torque
from eelsim.integrate import rk4_step
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import Scenario

__all__ = [
    "CosimOptions",
    "ExecutedCommand",
    "FirmwareRunResult",
    "HeldTwinDriver",
    "HostLink",
    "JointDriver",
    "LinkedJoints",
    "NativeDriver",
    "run_firmware_in_loop",
    "plant_step",
    "run_lockstep",
]

FloatArray = NDArray[np.float64]
# SetGains takes torque limits up to 10 N m; the twin's PD has no limit unless servo limits are on.
NO_TORQUE_LIMIT_NM = 10.0


@dataclass(frozen=True)
class CosimOptions:
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
        The host stops sending anything from this time on (a host that hangs), or never.
    """

    loop: LoopOptions = field(default_factory=LoopOptions)
    resend_after_us: int = 200_000
    restart_on_failsafe: bool = True
    firmware_control_period_us: int = 0
    host_silent_after_us: int | None = None


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
    firmware_counters: dict = field(default_factory=dict)
    host_bad_frames: dict = field(default_factory=dict)
    uplink: ChannelCounters = field(default_factory=ChannelCounters)
    downlink: ChannelCounters = field(default_factory=ChannelCounters)
    cpu_s: float = 0.0


class HostLink:
    """The host's end of the link: numbers and sends frames, reads the robot's frames.

    Parameters
    ----------
    uplink : RadioChannel
        Host -> robot.
    resend_after_us : int
        Resend unacknowledged configuration commands after this long.
    """

    CONFIG = (protocol.MsgId.SET_GAINS, protocol.MsgId.SET_GAIT, protocol.MsgId.START)

    def __init__(self, uplink: RadioChannel, resend_after_us: int) -> None:
        self.uplink = uplink
        self.resend_after_us = resend_after_us
        self.sent: list[tuple[int, int, protocol.Message]] = []
        self.telemetry: list[tuple[int, protocol.Telemetry]] = []
        self.acked: set[int] = set()  # seq numbers acknowledged
        self._seq = 0
        self._waiting: dict[int, tuple[int, int, protocol.Message]] = {}  # msg_id -> (t, seq, msg)
        self._reader = protocol.FrameReader()
        self._now = 0
        self.silent_after_us: int | None = None

    def send(self, t_us: int, message: protocol.Message) -> int:
        """Send a message at ``t_us``; returns its sequence number (-1 when the host is silent)."""
        if self.silent_after_us is not None and t_us >= self.silent_after_us:
            return -1
        seq = self._seq
        self._seq = (self._seq + 1) % 256
        self.uplink.send(t_us, protocol.encode_frame(message, seq))
        self.sent.append((t_us, seq, message))
        if message.MSG_ID in self.CONFIG:
            self._waiting[message.MSG_ID] = (t_us, seq, message)
        return seq

    def receive(self, data: bytes) -> None:
        """Read bytes from the downlink (telemetry is stamped with the last ``service`` time)."""
        for _, msg in self._reader.feed(data):
            if isinstance(msg, protocol.Ack):
                self.acked.add(msg.seq)
                waiting = self._waiting.get(msg.msg_id)
                if waiting is not None and waiting[1] == msg.seq:
                    del self._waiting[msg.msg_id]
            elif isinstance(msg, protocol.Telemetry):
                self.telemetry.append((self._now, msg))

    def service(self, t_us: int, data: bytes, restart_on_failsafe: bool) -> None:
        """Read the downlink, then resend what needs it.

        Parameters
        ----------
        t_us : int
            Now.
        data : bytes
            Bytes the downlink delivered since the last call.
        restart_on_failsafe : bool
            Send Start when new telemetry reports FAILSAFE.
        """
        self._now = t_us
        before = len(self.telemetry)
        self.receive(data)
        for msg_id in self.CONFIG:  # in this order: gains and gait before Start
            waiting = self._waiting.get(msg_id)
            if waiting is not None and t_us - waiting[0] >= self.resend_after_us:
                self.send(t_us, waiting[2])
        if restart_on_failsafe and protocol.MsgId.START not in self._waiting:
            fresh = self.telemetry[before:]
            if fresh and fresh[-1][1].state == protocol.State.FAILSAFE:
                self.send(t_us, protocol.Start())

    @property
    def bad_frames(self) -> dict[str, int]:
        """Frames from the robot that failed to decode, by kind."""
        return dict(self._reader.bad)


class JointDriver(Protocol):
    """What turns link bytes and joint measurements into joint torques, one physics step at a time.

    Implemented by :class:`NativeDriver` (the native firmware) and :class:`eelhost.xil.simavr.AvrDriver`
    (the AVR image in simavr).
    """

    def step(
        self,
        t_us: int,
        dt_us: int,
        uplink: RadioChannel,
        phi_rad: FloatArray,
        phi_dot_rad_s: FloatArray,
    ) -> tuple[FloatArray, FloatArray, list[tuple[int, bytes]]]:
        """Advance the robot's side over ``[t_us, t_us + dt_us)``.

        Parameters
        ----------
        t_us, dt_us : int
            Start and length of the physics step.
        uplink : RadioChannel
            Bytes from the host; take what has arrived by the time the robot reads it.
        phi_rad, phi_dot_rad_s : ndarray, shape (N-1,)
            The plant's joint angles and rates at ``t_us``.

        Returns
        -------
        torque_nm : ndarray, shape (N-1,)
            Joint torques held over the step.
        alpha_rad : ndarray, shape (N-1,)
            The joint references in force at ``t_us``.
        tx : list of (int, bytes)
            What the robot transmitted during the step, with the times.
        """
        ...

    def observe(self) -> tuple[int, float]:
        """The robot's state after the step (-1 when unknown) and the offset it holds, rad."""
        ...

    def counters(self) -> dict:
        """The robot's link counters at the end of the run."""
        ...


class NativeDriver:
    """The native firmware as a :class:`JointDriver`: feed, tick at ``t_us``, take.

    Parameters
    ----------
    firmware : NativeFirmware
        A firmware instance booted at ``t_us = 0``.
    torque_hook : callable, optional
        ``torque_hook(torque_nm, phi_dot_rad_s) -> torque_nm`` applied to the firmware's torques
        (the servo torque-speed limit).
    """

    def __init__(self, firmware: NativeFirmware, torque_hook=None) -> None:
        self.firmware = firmware
        self._hook = torque_hook

    def step(self, t_us, dt_us, uplink, phi_rad, phi_dot_rad_s):  # noqa: D102 (see JointDriver)
        data = uplink.deliver_bytes(t_us)
        if data:
            self.firmware.feed(data)
        out = self.firmware.tick(t_us, phi_rad, phi_dot_rad_s)
        torque = out.torque_nm.astype(np.float64)
        if self._hook is not None:
            torque = self._hook(torque, phi_dot_rad_s)
        tx = self.firmware.take()
        return torque, out.alpha_rad.astype(np.float64), [(t_us, tx)] if tx else []

    def observe(self) -> tuple[int, float]:  # noqa: D102 (see JointDriver)
        s = self.firmware.status()
        return int(s["state"]), float(s["offset_rad"])

    def counters(self) -> dict:  # noqa: D102 (see JointDriver)
        s = self.firmware.status()
        s["state"] = int(s["state"])
        return s


class HeldTwinDriver:
    """The twin's own control laws in float64, evaluated once per step and held (a reference).

    It reads the same frames as the firmware (SetGains, SetGait, SetOffset, Start, Stop; no slew
    limits, no failsafe) and computes :func:`eelsim.control.gait_reference` and
    :func:`eelsim.control.joint_pd_torque` in float64 at the start of each step. Comparing the twin
    with this driver isolates the effect of the torque hold; comparing this driver with the
    firmware isolates float32.

    Parameters
    ----------
    n_links : int
        Number of links N.
    limit_rad : float
        Clamp of the joint references.
    """

    def __init__(self, n_links: int, limit_rad: float) -> None:
        self._n = n_links
        self._limit = limit_rad
        self._reader = protocol.FrameReader()
        self._gait = Gait(0.0, 0.0, 0.0)
        self._kp = self._kd = 0.0
        self._offset = 0.0
        self._start_us: int | None = None

    def step(self, t_us, dt_us, uplink, phi_rad, phi_dot_rad_s):  # noqa: D102 (see JointDriver)
        for _, msg in self._reader.feed(uplink.deliver_bytes(t_us)):
            if isinstance(msg, protocol.SetGains):
                self._kp, self._kd = msg.kp_nm_per_rad, msg.kd_nms_per_rad
            elif isinstance(msg, protocol.SetGait):
                self._gait = Gait(msg.amplitude_rad, msg.omega_rad_s, msg.beta_rad)
            elif isinstance(msg, protocol.SetOffset):
                self._offset = msg.offset_rad
            elif isinstance(msg, protocol.Start) and self._start_us is None:
                self._start_us = t_us
            elif isinstance(msg, protocol.Stop):
                self._start_us = None
        if self._start_us is None:
            alpha = alpha_dot = np.zeros(self._n - 1)
        else:
            t_s = (t_us - self._start_us) * 1e-6
            alpha, alpha_dot = gait_reference(t_s, self._gait, self._offset, self._n)
            alpha = np.clip(alpha, -self._limit, self._limit)
        u = joint_pd_torque(alpha, alpha_dot, phi_rad, phi_dot_rad_s, self._kp, self._kd)
        return u, alpha, []

    def observe(self) -> tuple[int, float]:  # noqa: D102 (see JointDriver)
        running = self._start_us is not None
        return int(protocol.State.RUNNING if running else protocol.State.IDLE), self._offset

    def counters(self) -> dict:  # noqa: D102 (see JointDriver)
        return {}


def plant_step(
    model: SwimmerModel,
    x: FloatArray,
    torque_nm: FloatArray,
    t_s: float,
    dt_s: float,
    current_m_s: tuple[float, float] = (0.0, 0.0),
) -> FloatArray:
    """Advance the twin's plant by one RK4 step with the joint torques held (a zero-order hold).

    The step :func:`run_lockstep` takes, for callers that own their loop (the virtual robot of
    ``eelhost.link.sim_transport``).

    Parameters
    ----------
    model : SwimmerModel
        The plant.
    x : ndarray, shape (2 N + 4,)
        State at ``t_s``.
    torque_nm : ndarray, shape (N-1,)
        Joint torques held over the step.
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
    rhs = plant_rhs(model, np.asarray(torque_nm, dtype=float), np.asarray(current_m_s, dtype=float))
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
        raise ValueError(f"physics step {options.timing.dt_s} s is not a whole number of us")
    return dt_us


class LinkedJoints:
    """A robot-side driver behind the host and a radio link, as the twin loop's joints.

    The :class:`eelsim.closed_loop.JointController` of :func:`run_lockstep`: each physics step the
    host services the link and sends its frames (configuration at step 0, then every offset the
    loop hands over as a SetOffset), the driver ticks once with the plant's joint angles, and its
    torques are held over the step. It keeps what the run needs besides the twin's records: the
    torques, the robot's state, the commands the robot executed or refused.

    Parameters
    ----------
    robot : Robot
        Its k_p, k_d go out with SetGains; its servo figures limit the torques when asked.
    scenario : Scenario
        Its gait goes out with SetGait (slew rates 0).
    driver : JointDriver
        The robot's side.
    host : HostLink
        The host's end of the link (its uplink carries the frames to the driver).
    downlink : RadioChannel
        Robot -> host.
    dt_us : int
        Physics step, us (step k starts at ``k * dt_us``).
    options : CosimOptions
        Host options and the loop's servo-limit switch.
    """

    def __init__(
        self,
        robot: Robot,
        scenario: Scenario,
        driver: JointDriver,
        host: HostLink,
        downlink: RadioChannel,
        dt_us: int,
        options: CosimOptions,
    ) -> None:
        self.driver = driver
        self.host = host
        self.downlink = downlink
        self.dt_us = dt_us
        self._robot = robot
        self._gait = scenario.gait
        self._restart_on_failsafe = options.restart_on_failsafe
        self._servo_limits = options.loop.servo_limits
        self.torque_nm: list[FloatArray] = []
        self.firmware_state: list[int] = []
        self.executed: list[ExecutedCommand] = []
        self.refused: list[tuple[int, protocol.Refuse]] = []
        self._raw_reader = protocol.FrameReader()  # the robot's UART before the radio
        self._last_by_seq: dict[int, protocol.Message] = {}
        self._n_sent = 0

    def _send_configuration(self) -> None:
        joints = self._robot.joints
        torque_limit = joints.servo_max_torque_nm if self._servo_limits else NO_TORQUE_LIMIT_NM
        gait = self._gait
        self.host.send(0, protocol.Hello())
        self.host.send(
            0, protocol.SetGains(joints.kp_nm_per_rad, joints.kd_nms_per_rad, torque_limit)
        )
        self.host.send(
            0, protocol.SetGait(gait.amplitude_rad, gait.omega_rad_s, gait.beta_rad, 0, 0, 0)
        )

    def on_step(
        self, step: int, t_s: float, state: FloatArray, offset_command: float | None
    ) -> JointDrive:
        """See :meth:`eelsim.closed_loop.JointController.on_step`."""
        t_us = step * self.dt_us
        host = self.host
        host.service(t_us, self.downlink.deliver_bytes(t_us), self._restart_on_failsafe)
        if step == 0:
            self._send_configuration()
        if offset_command is not None:
            # SetOffset takes [-1, 1] rad; the twin's k_theta * pi stays inside for k < 0.32.
            host.send(t_us, protocol.SetOffset(float(np.clip(offset_command, -1.0, 1.0))))
        if step == 0:
            host.send(0, protocol.Start())  # after the first offset, so it starts with it
        for _, seq, msg in host.sent[self._n_sent :]:
            self._last_by_seq[seq] = msg
        self._n_sent = len(host.sent)

        n = self._robot.n_links
        phi = np.diff(state[:n])
        phi_dot = np.diff(state[n + 2 : 2 * n + 2])
        torque, alpha, tx = self.driver.step(t_us, self.dt_us, host.uplink, phi, phi_dot)
        for t_tx, data in tx:
            self.downlink.send(t_tx, data)
            for _, msg in self._raw_reader.feed(data):
                if isinstance(msg, protocol.Ack):
                    sent = self._last_by_seq.get(msg.seq)
                    self.executed.append(ExecutedCommand(t_tx, msg.seq, msg.msg_id, sent))
                elif isinstance(msg, protocol.Refuse):
                    self.refused.append((t_tx, msg))
        robot_state, offset = self.driver.observe()
        self.torque_nm.append(torque)
        self.firmware_state.append(robot_state)

        held = np.asarray(torque, dtype=float)
        if self._servo_limits:
            joints = self._robot.joints
            held = servo_limited(
                held, phi_dot, joints.servo_max_torque_nm, joints.servo_max_speed_rad_s
            )
        return JointDrive(held, alpha, offset)


def run_lockstep(
    robot: Robot,
    scenario: Scenario,
    driver: JointDriver,
    seed: int = 0,
    radio: RadioModel | None = None,
    options: CosimOptions | None = None,
) -> FirmwareRunResult:
    """Run the twin's closed loop with the joint torques from ``driver`` (any robot-side model).

    Parameters
    ----------
    robot : Robot
        The robot (geometry, gains, limits).
    scenario : Scenario
        Gait, waypoints, current, duration, start pose.
    driver : JointDriver
        The robot's side: native firmware, emulated AVR.
    seed : int
        Seed of the twin's period jitter and heading noise (drawn exactly as the twin draws them)
        and, through separate streams, of the radio's loss and corruption.
    radio : RadioModel, optional
        The link, both directions; ``None`` is an ideal link.
    options : CosimOptions, optional
        Loop, host and firmware options.

    Returns
    -------
    FirmwareRunResult
        Never raises for a run that goes wrong: failures come back as flags, as in the twin.
    """
    cpu0 = time.process_time()
    opts = options or CosimOptions()
    dt_us = _dt_us(opts.loop)
    if robot.n_links - 1 != N_JOINTS:
        raise ValueError(
            f"the firmware drives {N_JOINTS} joints; this robot has {robot.n_links - 1}"
        )
    link = radio or RadioModel()
    up_rng, down_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    uplink, downlink = link.channel(up_rng), link.channel(down_rng)
    host = HostLink(uplink, opts.resend_after_us)
    host.silent_after_us = opts.host_silent_after_us
    joints = LinkedJoints(robot, scenario, driver, host, downlink, dt_us, opts)

    twin = simulate_closed_loop(robot, scenario, opts.loop, seed, joints=joints)

    return FirmwareRunResult(
        **{f.name: getattr(twin, f.name) for f in fields(RunResult)},
        torque_nm=np.array(joints.torque_nm),
        firmware_state=np.array(joints.firmware_state, dtype=np.int64),
        sent=list(host.sent),
        executed=joints.executed,
        refused=joints.refused,
        telemetry=list(host.telemetry),
        firmware_counters=driver.counters(),
        host_bad_frames=host.bad_frames,
        uplink=uplink.counters,
        downlink=downlink.counters,
        cpu_s=time.process_time() - cpu0,
    )


def run_firmware_in_loop(
    robot: Robot,
    scenario: Scenario,
    seed: int = 0,
    radio: RadioModel | None = None,
    options: CosimOptions | None = None,
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
    options : CosimOptions, optional
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
    opts = options or CosimOptions()
    fw = firmware or NativeFirmware(now_us=0, control_period_us=opts.firmware_control_period_us)
    return run_lockstep(robot, scenario, NativeDriver(fw), seed, radio, opts)
