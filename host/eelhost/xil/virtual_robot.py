"""The virtual robot: the native firmware driving the twin, behind the link and in front of the camera.

:class:`VirtualRobot` owns a :class:`~eelhost.xil.lockstep.SimClock`: whenever the host loop waits
for a time, the robot steps there, one physics step (10 ms) at a time, with the one lockstep
stepper (:class:`eelhost.xil.lockstep.Lockstep`): the firmware (:class:`eelhost.xil.drivers.
NativeDriver`) reads the bytes the uplink has delivered, ticks with the plant's joint angles and
returns its torques and transmitted bytes; the plant takes one RK4 step with the torques held
(:func:`eelhost.xil.lockstep.plant_step`), or, for a robot with the servo joint model, with the
firmware's commanded angles as the servo references (:func:`eelhost.xil.lockstep.joint_drive`).
Bytes travel through the radio model
(:mod:`eelhost.xil.radio`, an XBee at 57600 baud by default).

- :meth:`VirtualRobot.transport` is the host's end of the radio (the
  :class:`~eelhost.link.sim_transport.SimTransport` of ``sim://``); a dropped link (``drops``)
  both loses the bytes sent in the window, as the radio model's outages do, and makes the
  transport report disconnected, like a serial port unplugged.
- :class:`VirtualCamera` renders the plant with the synthetic overhead camera at 30 fps, moving the
  clock to each frame's time first; it is the frame source of ``eelbot run`` for ``sim://``.

With ``speed`` 0 the clock runs as fast as the computer can; with ``speed`` X > 0 it waits on the
wall clock so that simulated time runs X times faster than real time.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from eelhost.link.sim_transport import SimTransport
from eelhost.vision.synthetic import SyntheticCamera, TruePose
from eelhost.xil.drivers import NativeDriver
from eelhost.xil.lockstep import DT_US, Lockstep, SimClock, joint_drive, plant_step
from eelhost.xil.native_firmware import BATTERY_INPUT, NativeFirmware, store_settings
from eelhost.xil.radio import RadioModel
from eelsim.dynamics import straight_state
from eelsim.model import SwimmerModel
from eelsim.robot import Robot

__all__ = ["VirtualCamera", "VirtualRobot"]

FloatArray = NDArray[np.float64]


#: Volts of battery per volt at the ADC pin of the virtual robot's divider (22k over 10k).
BATTERY_DIVIDER = 3.2
EEPROM_BYTES = 1024  # the ATmega328P's (EEL_EEPROM_BYTES)
#: The ADC's reference: readings 0..1023 over 0..ADC_REFERENCE_V.
ADC_REFERENCE_V = 5.0


def battery_counts(battery_v: float, divider: float) -> int:
    """The ADC reading of a battery voltage behind a divider (clamped to 0..1023)."""
    return int(min(max(round(battery_v / divider / ADC_REFERENCE_V * 1023), 0), 1023))


class VirtualRobot:
    """The native firmware and the twin's plant stepping in lockstep, with a radio between.

    Parameters
    ----------
    robot : Robot
        Geometry, coefficients, joint limits.
    start_position_m : (float, float)
        Initial centre of mass.
    start_heading_deg : float
        Initial heading of the straight robot.
    current_m_s : (float, float)
        Uniform current velocity.
    radio : RadioModel, optional
        The link (default: an XBee at 57600 baud, 5 ms latency).
    drops_s : list of (float, float)
        Windows ``[start, end)`` in which the link is down.
    seed : int
        Seed of the radio's loss and corruption.
    speed : float
        Speed of the clock (see :class:`SimClock`).
    joint_feedback : bool
        Analog-feedback servos: the firmware boots with the setting ``joint_feedback`` on (saved
        in its EEPROM), measures the plant's joint angles through its ADC and runs the PD itself.
    battery_v : float, optional
        A battery of this voltage behind the default divider (the firmware boots with
        ``battery_divider`` set and measures it); None: no divider fitted (``battery_divider``
        0 saved).
    eeprom_path : Path, optional
        A file that holds the firmware's EEPROM (1024 bytes) across runs: loaded at the start
        when it exists (its settings then stand; ``joint_feedback`` and ``battery_v``'s divider
        are saved only into a new file), written back by :meth:`save_eeprom` (the ``sim://``
        transport does when it closes), so a ``--save`` persists between invocations.
    """

    def __init__(
        self,
        robot: Robot,
        start_position_m: tuple[float, float] = (0.0, 0.0),
        start_heading_deg: float = 0.0,
        current_m_s: tuple[float, float] = (0.0, 0.0),
        radio: RadioModel | None = None,
        drops_s: list[tuple[float, float]] | None = None,
        seed: int = 0,
        speed: float = 0.0,
        joint_feedback: bool = False,
        battery_v: float | None = None,
        eeprom_path: Path | None = None,
    ) -> None:
        self.robot = robot
        self.model = SwimmerModel.from_robot(robot)
        self.current_m_s = (float(current_m_s[0]), float(current_m_s[1]))
        self.start_position_m = (float(start_position_m[0]), float(start_position_m[1]))
        self.start_heading_deg = float(start_heading_deg)
        self.drops_us = [(round(a * 1e6), round(b * 1e6)) for a, b in (drops_s or [])]
        link = (radio or RadioModel.xbee()).with_outages(tuple(self.drops_us))
        self.firmware = NativeFirmware(now_us=0, control_period_us=0)
        self.eeprom_path = eeprom_path
        if eeprom_path is not None and eeprom_path.exists():
            image = eeprom_path.read_bytes()
            if len(image) != EEPROM_BYTES:
                raise ValueError(f"{eeprom_path}: an EEPROM image is {EEPROM_BYTES} bytes, "
                                 f"not {len(image)}")
            self.firmware.eeprom_write(0, image)
            self.firmware.reset(0)  # a power cycle: the firmware boots what the file holds
        else:
            saved = {"battery_divider": BATTERY_DIVIDER if battery_v is not None else 0.0}
            if joint_feedback:
                saved["joint_feedback"] = 1.0
            store_settings(self.firmware, saved)
        if battery_v is not None:
            self.firmware.set_adc(BATTERY_INPUT, battery_counts(battery_v, BATTERY_DIVIDER))
        self.driver = NativeDriver(self.firmware)
        self.lockstep = Lockstep(self.driver, link, seed, self.model.n_links, DT_US)
        self.uplink, self.downlink = self.lockstep.uplink, self.lockstep.downlink
        self.clock = SimClock(self.advance_to, speed)
        self.failure = ""
        self.trace: list[FloatArray] | None = None
        """Set to a list to keep the plant's true state at every step (benchmarks)."""
        self._k = -1  # last physics step ticked
        self._x = straight_state(
            self.model, np.radians(self.start_heading_deg), self.start_position_m
        )
        self._x_next = self._x.copy()

    @property
    def now_us(self) -> int:
        """Time of the last firmware tick, us (-1 before the first)."""
        return self._k * DT_US if self._k >= 0 else -1

    def advance_to(self, t_us: int) -> None:
        """Run every physics step whose start time is at or before ``t_us``.

        After it, the state over ``[k dt, (k+1) dt]`` is known for the last step k, so
        :meth:`state_at` can interpolate anywhere up to ``t_us``.
        """
        while (self._k + 1) * DT_US <= t_us:
            self._k += 1
            if self._k > 0:
                self._x = self._x_next
            if self.trace is not None:
                self.trace.append(self._x)
            if self.failure:
                continue  # a blown-up plant stays where it was; the firmware is not ticked
            tick = self.lockstep.tick(self._k, self._x)
            try:
                self._x_next = plant_step(
                    self.model,
                    self._x,
                    joint_drive(self.robot, tick, 0.0, servo_limits=False),
                    tick.t_us * 1e-6,
                    DT_US * 1e-6,
                    self.current_m_s,
                )
            except FloatingPointError as err:
                self.failure = str(err)
                self._x_next = self._x

    def state_at(self, t_s: float) -> FloatArray:
        """The plant's state at ``t_s`` (linear between steps; ``t_s`` within the last step)."""
        t_k = max(self._k, 0) * DT_US * 1e-6
        s = float(np.clip((t_s - t_k) / (DT_US * 1e-6), 0.0, 1.0))
        return (1.0 - s) * self._x + s * self._x_next

    def save_eeprom(self) -> None:
        """Write the firmware's EEPROM to :attr:`eeprom_path` (nothing without one)."""
        if self.eeprom_path is not None:
            self.eeprom_path.write_bytes(self.firmware.eeprom_read(0, EEPROM_BYTES))

    def link_down(self, t_us: int) -> bool:
        """Whether ``t_us`` falls in a drop window."""
        return any(a <= t_us < b for a, b in self.drops_us)

    def status(self) -> dict[str, Any]:
        """The firmware's state and counters (``NativeFirmware.status()``)."""
        return self.driver.counters()

    def transport(self) -> SimTransport:
        """The host's end of the robot's radio (the transport of ``sim://``).

        Returns
        -------
        SimTransport
            Stamped by :attr:`clock`; down inside the drop windows; its ``robot`` is this robot.
        """
        return SimTransport(
            self.uplink, self.downlink, self.clock.now_us, self.link_down, robot=self
        )


class VirtualCamera:
    """The synthetic overhead camera looking at the virtual robot, at ``fps``.

    Iterating moves the robot's clock to each frame time, renders the plant there and yields
    ``(t_s, frame)``; :attr:`truth` keeps the true pose of every frame.

    Parameters
    ----------
    robot : VirtualRobot
        What is filmed; its clock is advanced.
    camera : SyntheticCamera, optional
        The renderer (default: the paper's tank view, seeded with ``seed``).
    fps : float
        Frame rate.
    seed : int
        Seed of the image noise.
    keep_truth : bool
        Keep the true pose of every frame.
    """

    def __init__(
        self,
        robot: VirtualRobot,
        camera: SyntheticCamera | None = None,
        fps: float = 30.0,
        seed: int = 0,
        keep_truth: bool = True,
    ) -> None:
        self.robot = robot
        self.camera = camera or SyntheticCamera(robot.robot, seed=seed)
        self.fps = fps
        self.keep_truth = keep_truth
        self.truth: list[TruePose] = []

    def __iter__(self) -> Iterator[tuple[float, NDArray[np.uint8]]]:
        """Frames at k / fps, k = 0, 1, ... (endless: the host loop decides when to stop)."""
        k = 0
        while True:
            t = k / self.fps
            self.robot.clock.wait_until(t)
            frame, pose = self.camera.render(self.robot.state_at(t), t)
            if self.keep_truth:
                self.truth.append(pose)
            yield t, frame
            k += 1
