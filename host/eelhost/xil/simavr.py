"""Processor in the loop: the robot's real AVR image, emulated in simavr, drives the twin.

The ELF that would be flashed (``firmware/build/avr/eelbot.elf``) runs in simavr through
``firmware/build/tools/libeelavrsim.so`` (``firmware/tools/eel_avrsim.c`` built as a library, loaded
here with ctypes). One physics step ``[t_us, t_us + dt_us)`` of :func:`eelhost.xil.lockstep.run_lockstep`:

1. the joint torques for the step come from the :class:`ServoModel`: each joint's servo holds the
   angle of the last pulse it has received (width -> angle through the firmware's calibration,
   ``pulse_us = 1500 + 636.6 alpha``) and pulls the joint there with the robot file's PD gains,
   using the slope between its last two pulses as the rate reference;
2. the bytes the uplink delivers during the step enter the AVR's UART at their arrival times;
3. the AVR runs to ``t_us + dt_us``; every high pulse on D2..D6 (the servos) is timed from its pin
   edges, and D7 (high while a control update runs) gives the update times;
4. what the AVR's UART sent goes to the downlink with its times.

The AVR image does not read the joints (the hobby servos close their own loop), so the plant
never feeds back into the emulated processor except through the host's SetOffset frames.
One simulated second costs about 1-2 s of CPU (simavr interprets every AVR instruction).
"""

from __future__ import annotations

import ctypes
import logging
import math
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from eelhost.wire import protocol
from eelhost.xil.lockstep import FirmwareRunResult, LockstepOptions, run_lockstep
from eelhost.xil.native_firmware import FIRMWARE_DIR
from eelhost.xil.radio import RadioChannel, RadioModel
from eelsim.joints import pd_gains
from eelsim.robot import Robot
from eelsim.scenario import Scenario

log = logging.getLogger(__name__)

__all__ = [
    "AvrDriver",
    "AvrSimulator",
    "AvrSimulatorError",
    "PilRunResult",
    "ServoModel",
    "expected_pulse_widths_us",
    "run_processor_in_loop",
    "setup_eeprom",
]

ELF_PATH = FIRMWARE_DIR / "build" / "avr" / "eelbot.elf"
LIBRARY_PATH = FIRMWARE_DIR / "build" / "tools" / "libeelavrsim.so"
SERVO_PINS = ("D2", "D3", "D4", "D5", "D6")  # joint 1 (tail) .. joint 5 (head); README wiring
BUSY_PIN = "D7"
FloatArray = NDArray[np.float64]


EEPROM_BYTES = 1024  # the ATmega328P's


def setup_eeprom() -> bytes:
    """The EEPROM of a robot that has been set up: the default settings saved in slot 0.

    Taken from the native build of the same firmware sources, whose new instances hold exactly
    that (``eel_create``), so the image's layout is the firmware's own.
    """
    from eelhost.xil.native_firmware import NativeFirmware

    return NativeFirmware(now_us=0).eeprom_read(0, EEPROM_BYTES)


class AvrSimulatorError(RuntimeError):
    """The simavr harness library or the AVR image cannot be built or loaded."""


def build_avr(force: bool = False) -> None:
    """Build (or bring up to date) the AVR image and the simavr harness library with make.

    Parameters
    ----------
    force : bool
        Run make even when both files exist.

    Raises
    ------
    AvrSimulatorError
        When make fails (its output is in the message).
    """
    if not force and ELF_PATH.exists() and LIBRARY_PATH.exists():
        return
    log.debug("bringing %s and %s up to date (make avr tools)", ELF_PATH, LIBRARY_PATH)
    proc = subprocess.run(
        ["make", "-s", "-C", str(FIRMWARE_DIR), "avr", "tools"],
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0 or not (ELF_PATH.exists() and LIBRARY_PATH.exists()):
        raise AvrSimulatorError(
            f"building the AVR image and simavr harness failed (run scripts/setup.sh for "
            f"gcc-avr, avr-libc, libsimavr-dev):\n{proc.stdout}{proc.stderr}".rstrip()
        )


def _load_library(path: Path) -> ctypes.CDLL:
    lib = ctypes.CDLL(str(path))
    vp, d, sz = ctypes.c_void_p, ctypes.c_double, ctypes.c_size_t
    lib.eas_create.restype = vp
    lib.eas_create.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_ulong]
    lib.eas_destroy.argtypes = [vp]
    lib.eas_buffer_outputs.argtypes = [vp, ctypes.c_int]
    lib.eas_watch_pin.argtypes = [vp, ctypes.c_char_p]
    lib.eas_uart_push.argtypes = [vp, d, ctypes.c_uint8]
    lib.eas_run_until.argtypes = [vp, d]
    lib.eas_now_us.restype = d
    lib.eas_now_us.argtypes = [vp]
    lib.eas_take_uart.restype = sz
    lib.eas_take_uart.argtypes = [vp, ctypes.POINTER(d), ctypes.POINTER(ctypes.c_uint8), sz]
    lib.eas_eeprom.argtypes = [vp, ctypes.POINTER(ctypes.c_uint8), ctypes.c_uint32, ctypes.c_int]
    lib.eas_take_pulses.restype = sz
    lib.eas_take_pulses.argtypes = [
        vp,
        ctypes.POINTER(d),
        ctypes.POINTER(d),
        ctypes.POINTER(ctypes.c_int32),
        sz,
    ]
    return lib


class AvrSimulator:
    """The robot's AVR image running in simavr: UART in and out, pulses timed on pins.

    Parameters
    ----------
    elf : Path, optional
        The image (default ``firmware/build/avr/eelbot.elf``, built with make when missing).
    pins : sequence of str
        Pins whose high pulses are timed, e.g. ``("D2", "D3")``; pulses report the pin's index here.
    freq_hz : int
        Clock of the AVR (the Nano's 16 MHz).
    eeprom : bytes, optional
        The EEPROM the AVR boots with (1024 bytes). By default that of a robot that has been set
        up: the default settings saved (:func:`setup_eeprom`); an erased EEPROM (1024 bytes
        0xFF) boots the defaults with Start refused until the host acknowledges them
        (docs/firmware.md, "Settings in the EEPROM").

    The harness feeds the UART at the true line rate (5760 bytes/s; simavr alone counts a parity
    bit, 5195), keeps an EEPROM byte programming for the chip's 3.4 ms, and holds the battery
    input at 7.4 V behind the default divider (``firmware/tools/eel_avrsim.c``).
    """

    _CAP = 4096

    def __init__(
        self,
        elf: Path | None = None,
        pins: tuple[str, ...] = (*SERVO_PINS, BUSY_PIN),
        freq_hz: int = 16_000_000,
        eeprom: bytes | None = None,
    ) -> None:
        if elf is None:
            # Bring the image and the harness up to date (fast when they are), as the native
            # binding does, so that a test never runs a stale build of edited sources.
            build_avr(force=shutil.which("make") is not None)
        self._lib = _load_library(LIBRARY_PATH)
        handle = self._lib.eas_create(str(elf or ELF_PATH).encode(), b"atmega328p", freq_hz)
        if not handle:
            raise AvrSimulatorError(f"simavr cannot load {elf or ELF_PATH}")
        self._h: ctypes.c_void_p | None = ctypes.c_void_p(handle)
        self._lib.eas_buffer_outputs(self._h, 1)
        self.write_eeprom(setup_eeprom() if eeprom is None else eeprom)
        for name in pins:
            if self._lib.eas_watch_pin(self._h, name.encode()) < 0:
                raise ValueError(f"bad pin {name!r}")
        self._t = (ctypes.c_double * self._CAP)()
        self._w = (ctypes.c_double * self._CAP)()
        self._b = (ctypes.c_uint8 * self._CAP)()
        self._p = (ctypes.c_int32 * self._CAP)()
        self.crashed = False

    def close(self) -> None:
        """Free the simulator (also done when the object is collected)."""
        if self._h:
            self._lib.eas_destroy(self._h)
            self._h = None

    def __del__(self) -> None:
        self.close()

    def write_eeprom(self, image: bytes) -> None:
        """Put ``image`` (1024 bytes) into the AVR's EEPROM (before it boots, or for its next)."""
        if len(image) != EEPROM_BYTES:
            raise ValueError(f"an EEPROM image is {EEPROM_BYTES} bytes, not {len(image)}")
        buf = (ctypes.c_uint8 * EEPROM_BYTES).from_buffer_copy(image)
        self._lib.eas_eeprom(self._h, buf, EEPROM_BYTES, 1)

    def read_eeprom(self) -> bytes:
        """The AVR's EEPROM now (1024 bytes)."""
        buf = (ctypes.c_uint8 * EEPROM_BYTES)()
        self._lib.eas_eeprom(self._h, buf, EEPROM_BYTES, 0)
        return bytes(buf)

    def push_uart(self, t_us: float, data: bytes) -> None:
        """Queue bytes for the AVR's UART receiver from ``t_us`` on (in order, at the UART's pace)."""
        for byte in data:
            self._lib.eas_uart_push(self._h, float(t_us), byte)

    def run_until(self, t_us: float) -> None:
        """Run the AVR until its simulated time reaches ``t_us`` microseconds."""
        if self._lib.eas_run_until(self._h, float(t_us)):
            self.crashed = True

    @property
    def now_us(self) -> float:
        """Simulated time since reset, microseconds."""
        return float(self._lib.eas_now_us(self._h))

    def take_uart(self) -> list[tuple[float, int]]:
        """Bytes the AVR sent since the last call, as (time_us, byte)."""
        out: list[tuple[float, int]] = []
        while True:
            n = self._lib.eas_take_uart(self._h, self._t, self._b, self._CAP)
            out.extend((self._t[i], self._b[i]) for i in range(n))
            if n < self._CAP:
                return out

    def take_pulses(self) -> list[tuple[float, int, float]]:
        """Pulses completed since the last call, as (rise_us, pin index, width_us)."""
        out: list[tuple[float, int, float]] = []
        while True:
            n = self._lib.eas_take_pulses(self._h, self._t, self._w, self._p, self._CAP)
            out.extend((self._t[i], self._p[i], self._w[i]) for i in range(n))
            if n < self._CAP:
                return out


@dataclass(frozen=True)
class ServoModel:
    """A hobby servo as the plant sees it: the pulse width sets the angle it holds.

    Attributes
    ----------
    centre_us : float
        Pulse width of a straight joint (``firmware/core/servo_map.h``).
    us_per_rad : float
        Calibration slope (636.6 us/rad: 2000 us over pi rad).
    rate_feedforward : bool
        Use the slope between the last two pulses as the rate reference of the PD law (as the
        firmware's own PD uses alpha_dot); otherwise the servo only damps (rate reference 0).
    """

    centre_us: float = 1500.0
    us_per_rad: float = 636.6
    rate_feedforward: bool = True

    def angle_rad(self, width_us: float | FloatArray) -> float | FloatArray:
        """Joint angle commanded by a pulse width."""
        return (np.asarray(width_us) - self.centre_us) / self.us_per_rad


class AvrDriver:
    """The emulated AVR as a :class:`eelhost.xil.drivers.JointDriver`.

    Parameters
    ----------
    sim : AvrSimulator
        A simulator watching the five servo pins (indices 0-4) and the busy pin (index 5).
    kp_nm_per_rad, kd_nms_per_rad : float
        Gains of the servo model's position loop (the robot file's).
    servo : ServoModel
        Pulse width to angle.
    """

    def __init__(
        self, sim: AvrSimulator, kp_nm_per_rad: float, kd_nms_per_rad: float, servo: ServoModel
    ) -> None:
        self.sim = sim
        self.servo = servo
        self._kp, self._kd = kp_nm_per_rad, kd_nms_per_rad
        n = len(SERVO_PINS)
        self._alpha = np.zeros(n)
        self._alpha_dot = np.zeros(n)
        self._last_rise = np.full(n, np.nan)
        self.pulses: list[tuple[float, int, float]] = []  # servo pulses (rise, joint index, width)
        self.updates: list[tuple[float, float]] = []  # control updates (rise, width)
        self.uart_in: list[tuple[float, int]] = []  # bytes as delivered to the AVR
        self._raw = protocol.FrameReader()
        self._last_telemetry: protocol.Telemetry | None = None

    def step(self, t_us, dt_us, uplink: RadioChannel, phi_rad, phi_dot_rad_s):  # noqa: D102
        torque = self._kp * (self._alpha - phi_rad) + self._kd * (self._alpha_dot - phi_dot_rad_s)
        alpha_now = self._alpha.copy()
        for arrival, byte in uplink.deliver(t_us + dt_us - 1):
            at = max(arrival, t_us)
            self.sim.push_uart(at, bytes([byte]))
            self.uart_in.append((float(at), byte))
        self.sim.run_until(t_us + dt_us)
        for rise, pin, width in sorted(self.sim.take_pulses(), key=lambda p: p[0] + p[2]):
            if pin == len(SERVO_PINS):
                self.updates.append((rise, width))
                continue
            self.pulses.append((rise, pin, width))
            angle = float(self.servo.angle_rad(width))
            if self.servo.rate_feedforward and np.isfinite(self._last_rise[pin]):
                self._alpha_dot[pin] = (angle - self._alpha[pin]) / (
                    (rise - self._last_rise[pin]) * 1e-6
                )
            self._alpha[pin] = angle
            self._last_rise[pin] = rise
        tx: list[tuple[int, bytes]] = []
        for t_byte, byte in self.sim.take_uart():
            tx.append((max(t_us, math.ceil(t_byte)), bytes([byte])))
            for _, msg in self._raw.feed(bytes([byte])):
                if isinstance(msg, protocol.Telemetry):
                    self._last_telemetry = msg
        return torque, alpha_now, tx

    def observe(self) -> tuple[int, float]:  # noqa: D102 (see JointDriver)
        t = self._last_telemetry
        return (-1, 0.0) if t is None else (int(t.state), float(t.offset_rad))

    def counters(self) -> dict:  # noqa: D102 (see JointDriver)
        t = self._last_telemetry
        if t is None:
            return {}
        return {
            "state": int(t.state),
            "frames_ok": t.frames_ok,
            "frames_bad": t.frames_bad,
            "lost": t.frames_lost,
        }


@dataclass
class PilRunResult(FirmwareRunResult):
    """A run driven by the emulated AVR: :class:`eelhost.xil.lockstep.FirmwareRunResult` plus the pins.

    Attributes
    ----------
    pulses_us : ndarray, shape (P, 3)
        Servo pulses: rise time (us), joint index (0 = joint 1, tail), width (us).
    control_updates_us : ndarray, shape (U, 2)
        Control updates from the busy pin D7: rise time and duration (us).
    uart_in : list of (float, int)
        Bytes as they entered the AVR's UART: (time_us, byte).
    servo : ServoModel
        The servo model used.
    crashed : bool
        Whether the emulated AVR crashed.
    """

    pulses_us: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    control_updates_us: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    uart_in: list[tuple[float, int]] = field(default_factory=list)
    servo: ServoModel = field(default_factory=ServoModel)
    crashed: bool = False


def run_processor_in_loop(
    robot: Robot,
    scenario: Scenario,
    seed: int = 0,
    radio: RadioModel | None = None,
    options: LockstepOptions | None = None,
    servo: ServoModel | None = None,
    elf: Path | None = None,
) -> PilRunResult:
    """Run the twin's closed loop with the emulated AVR image driving the joints.

    Parameters
    ----------
    robot : Robot
        The robot; its k_p, k_d are the servo model's gains (and are sent with SetGains).
    scenario : Scenario
        The task (use a short ``duration_s``: the emulation costs 1-2 CPU s per simulated s).
    seed : int
        Seed of the twin's jitter and noise and of the radio.
    radio : RadioModel, optional
        The link; ``None`` is ideal (bytes enter the UART when sent; the UART itself still takes
        173.6 us a byte at 57600 baud).
    options : LockstepOptions, optional
        Loop and host options.
    servo : ServoModel, optional
        Pulse width to joint reference.
    elf : Path, optional
        Another AVR image.

    Returns
    -------
    PilRunResult
    """
    servo = servo or ServoModel()
    sim = AvrSimulator(elf)
    try:
        # the servo joint model takes the pulses' angles as its references: no torques needed
        kp, kd = pd_gains(robot.joints) or (0.0, 0.0)
        driver = AvrDriver(sim, kp, kd, servo)
        res = run_lockstep(robot, scenario, driver, seed, radio, options)
    finally:
        crashed = sim.crashed
        sim.close()
    fields = {k: getattr(res, k) for k in res.__dataclass_fields__}
    return PilRunResult(
        **fields,
        pulses_us=np.array(driver.pulses, dtype=float).reshape(-1, 3),
        control_updates_us=np.array(driver.updates, dtype=float).reshape(-1, 2),
        uart_in=driver.uart_in,
        servo=servo,
        crashed=crashed,
    )


def expected_pulse_widths_us(
    result: PilRunResult,
    amplitude_rad: float,
    omega_rad_s: float,
    beta_rad: float,
    limit_rad: float = 1.2,
    margin_us: float = 2000.0,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The pulse width each measured servo pulse should have, from the gait and the link bytes.

    Each pulse carries the references of the last control update that ended before it rose
    (the Timer1 driver latches a width when its pulse starts). An update at time ``t_k`` (rise of
    D7) computes ``alpha_j = A_j sin(omega (t_k - t_0) + (j-1) beta) + gamma`` (0 before Start),
    where ``t_0`` is the time the firmware handled Start (it restarts the phase there) and
    ``gamma`` is the last SetOffset handled before the update (slew rates 0). Which frame an
    update saw is read from the times the frames' last bytes were queued for the UART.

    The run does not record when the AVR handled Start: after the frame has crossed the UART and
    any control update in progress has ended. ``t_0`` is taken as the first update at or after the
    frame was queued, which errs by that delay (about 1.5 ms in the ideal-link test, 2 us of pulse
    width at most).

    Parameters
    ----------
    result : PilRunResult
        A processor-in-the-loop run.
    amplitude_rad, omega_rad_s, beta_rad : float
        The gait sent with SetGait (rates 0).
    limit_rad : float
        The firmware's joint reference clamp.
    margin_us : float
        Updates this close to the arrival of a SetOffset or Start frame, and pulses this close
        (in us / 100) to the end of an update, are ambiguous and masked out.

    Returns
    -------
    expected_us : ndarray, shape (P,)
        Expected width of each pulse in ``result.pulses_us``.
    valid : ndarray of bool, shape (P,)
        False for pulses whose update or frame is ambiguous.
    """
    # Frames as the AVR received them: (time the delimiter entered the UART, message). The
    # harness's UART takes the queued bytes one after the other at the line rate, 10 bit times
    # each (8N1): 173.6 us at 57600 baud (protocol.BAUD).
    byte_us = 10 * 1e6 / protocol.BAUD
    reader = protocol.FrameReader()
    frames: list[tuple[float, protocol.Message]] = []
    entered = -np.inf
    for t, byte in result.uart_in:
        entered = max(t, entered + byte_us)
        frames.extend((entered, m) for _, m in reader.feed(bytes([byte])))
    upd = result.control_updates_us
    rise_u, end_u = upd[:, 0], upd[:, 0] + upd[:, 1]
    k_start = None
    ambiguous = np.zeros(len(upd), dtype=bool)
    offsets = np.zeros(len(upd))
    started = np.zeros(len(upd), dtype=bool)
    for t, msg in frames:
        near = np.abs(rise_u - t) < margin_us
        if isinstance(msg, protocol.SetOffset):
            ambiguous |= near
            offsets[rise_u > t] = np.float32(msg.offset_rad)
        elif isinstance(msg, protocol.Start) and k_start is None:
            ambiguous |= near
            k_start = int(np.searchsorted(rise_u, t))  # first update at or after the frame
            started[k_start:] = True
    amp = amplitude_rad * (5.0 - np.arange(5)) / 7.0
    expected_update = np.full((len(upd), 5), 1500.0)
    if k_start is not None and k_start < len(upd):
        dt_s = (rise_u - rise_u[k_start]) * 1e-6
        phase = omega_rad_s * dt_s[:, None] + beta_rad * np.arange(5)[None, :]
        alpha = np.clip(amp[None, :] * np.sin(phase) + offsets[:, None], -limit_rad, limit_rad)
        widths = np.clip(np.floor(1500.0 + 636.6 * alpha + 0.5), 700, 2300)
        expected_update[started] = widths[started]
    pulses = result.pulses_us
    k = np.searchsorted(end_u, pulses[:, 0]) - 1  # last update that ended before the rise
    valid = k >= 0
    kk = np.clip(k, 0, None)
    valid &= ~ambiguous[kk]
    # A pulse rising while an update writes its widths could carry either: mask those too.
    nxt = np.clip(k + 1, 0, len(upd) - 1)
    valid &= np.abs(pulses[:, 0] - end_u[nxt]) > margin_us / 100.0
    expected = expected_update[kk, pulses[:, 1].astype(int)]
    return expected, valid
