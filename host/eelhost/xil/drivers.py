"""The robot's side of a lockstep step: what turns link bytes and joint measurements into torques.

A :class:`JointDriver` is ticked once per physics step by :class:`eelhost.xil.lockstep.Lockstep`:
it takes the bytes the uplink has delivered, computes the joint torques held over the step and
returns what the robot transmitted. Three drivers:

- :class:`NativeDriver`: the robot's firmware compiled for this PC;
- :class:`HeldTwinDriver`: the twin's own control laws in float64, evaluated once per step and held
  (a reference that separates the torque hold from float32 arithmetic);
- :class:`eelhost.xil.simavr.AvrDriver`: the real AVR image in simavr.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelhost.wire import protocol
from eelhost.xil.native_firmware import N_JOINTS, NativeFirmware
from eelhost.xil.radio import RadioChannel
from eelsim.control import Gait, gait_reference, joint_pd_torque

__all__ = ["HeldTwinDriver", "JointDriver", "NativeDriver", "Transmission", "servo_command_rad"]

#: Pulse width of a straight joint, us (docs/firmware.md, "Settings": trim_us).
SERVO_CENTRE_US = 1500.0


def servo_command_rad(pulse_us: ArrayLike) -> FloatArray:
    """The angle an ideal servo turns to for a pulse width (1500 us straight, untrimmed).

    Parameters
    ----------
    pulse_us : array_like
        Pulse widths, us.

    Returns
    -------
    ndarray
        Angles, rad, at the default ``servo_us_per_rad`` (docs/firmware.md, "Settings").
    """
    us_per_rad = protocol.SETTINGS["servo_us_per_rad"].default
    return (np.asarray(pulse_us, dtype=float) - SERVO_CENTRE_US) / us_per_rad

FloatArray = NDArray[np.float64]
#: What the robot transmitted during a step: (time, bytes) chunks.
Transmission = list[tuple[int, bytes]]


class JointDriver(Protocol):
    """What turns link bytes and joint measurements into joint torques, one physics step at a time.

    Implemented by :class:`NativeDriver` (the native firmware), :class:`HeldTwinDriver` (the twin's
    laws, held) and :class:`eelhost.xil.simavr.AvrDriver` (the AVR image in simavr).
    """

    def step(
        self,
        t_us: int,
        dt_us: int,
        uplink: RadioChannel,
        phi_rad: FloatArray,
        phi_dot_rad_s: FloatArray,
    ) -> tuple[FloatArray, FloatArray, Transmission]:
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

    def counters(self) -> dict[str, Any]:
        """The robot's link counters at the end of the run."""
        ...


class NativeDriver:
    """The native firmware as a :class:`JointDriver`: feed, tick at ``t_us``, take.

    The plant's joint angles also go to the firmware's feedback inputs (the potentiometers of
    analog-feedback servos, through the robot's calibration), which it reads when its setting
    ``joint_feedback`` is on. Then the firmware runs the PD itself and its pulses command each
    servo to phi + u / k_s; the servo, a spring of stiffness k_s about its commanded angle, gives
    the joint the torque k_s (command - phi), which is u plus what the ADC got wrong. Without
    feedback the torques are the firmware's PD law on the plant's angles (docs/firmware.md,
    "Joint loop").

    Parameters
    ----------
    firmware : NativeFirmware
        A firmware instance booted at ``t_us = 0``.
    torque_hook : callable, optional
        ``torque_hook(torque_nm, phi_dot_rad_s) -> torque_nm`` applied to the firmware's torques
        (the servo torque-speed limit).
    servo_stiffness_nm_per_rad : float
        k_s of the simulated servos (the setting's default, which the firmware assumes).

    Attributes
    ----------
    servo_command_rad : ndarray, shape (N-1,)
        The angle each servo is commanded to at the last tick, what a position servo follows:
        with joint feedback, the angle of its pulse (1500 us straight, the setting
        servo_us_per_rad's default per radian: the simulated servos are ideal, so a trim moves
        the joint); without, the reference alpha itself (the pulse less its 1 us rounding).
    """

    def __init__(
        self,
        firmware: NativeFirmware,
        torque_hook: Callable[[FloatArray, FloatArray], FloatArray] | None = None,
        servo_stiffness_nm_per_rad: float = protocol.SETTINGS["servo_stiffness_nm_per_rad"].default,
    ) -> None:
        self.firmware = firmware
        self._hook = torque_hook
        self._stiffness = servo_stiffness_nm_per_rad
        self.servo_command_rad = np.zeros(N_JOINTS)

    def step(
        self,
        t_us: int,
        dt_us: int,
        uplink: RadioChannel,
        phi_rad: FloatArray,
        phi_dot_rad_s: FloatArray,
    ) -> tuple[FloatArray, FloatArray, Transmission]:
        """See :meth:`JointDriver.step`."""
        data = uplink.deliver_bytes(t_us)
        if data:
            self.firmware.feed(data)
        self.firmware.set_joint_angles(phi_rad)
        out = self.firmware.tick(t_us, phi_rad, phi_dot_rad_s)
        alpha = out.alpha_rad.astype(np.float64)
        if out.measured:
            self.servo_command_rad = servo_command_rad(out.pulse_us)
            torque = self._stiffness * (self.servo_command_rad - np.asarray(phi_rad, dtype=float))
        else:
            self.servo_command_rad = alpha
            torque = out.torque_nm.astype(np.float64)
        if self._hook is not None:
            torque = self._hook(torque, phi_dot_rad_s)
        tx = self.firmware.take()
        return torque, alpha, [(t_us, tx)] if tx else []

    def observe(self) -> tuple[int, float]:
        """See :meth:`JointDriver.observe`."""
        s = self.firmware.status()
        return int(s["state"]), float(s["offset_rad"])

    def counters(self) -> dict[str, Any]:
        """See :meth:`JointDriver.counters`."""
        s: dict[str, Any] = dict(self.firmware.status())
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

    def step(
        self,
        t_us: int,
        dt_us: int,
        uplink: RadioChannel,
        phi_rad: FloatArray,
        phi_dot_rad_s: FloatArray,
    ) -> tuple[FloatArray, FloatArray, Transmission]:
        """See :meth:`JointDriver.step`."""
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

    def observe(self) -> tuple[int, float]:
        """See :meth:`JointDriver.observe`."""
        running = self._start_us is not None
        return int(protocol.State.RUNNING if running else protocol.State.IDLE), self._offset

    def counters(self) -> dict[str, Any]:
        """See :meth:`JointDriver.counters`."""
        return {}
