"""The robot's firmware compiled for this PC, driven in lockstep from Python.

``firmware/build/native/libeelfw.so`` is the same C++ core as the Nano image with a native board
layer: the caller owns time, the UART is two byte queues and the servos are an array. This module
loads it with cffi in ABI mode and first runs ``make native`` (a no-op when the library is up to
date; skipped when make is not installed and the library exists). Typical use, one physics step
of the twin at a time::

    fw = NativeFirmware(control_period_us=0)
    fw.feed(protocol.encode_frame(protocol.Start(), seq=0))
    out = fw.tick(t_us, phi_rad, phi_dot_rad_s)   # references, PD torques, servo pulses
    frames = fw.read_frames()                     # Ack, Telemetry, ...
"""

from __future__ import annotations

import logging
import re
import shutil
import subprocess
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from cffi import FFI
from numpy.typing import ArrayLike, NDArray

from eelhost.wire import protocol

log = logging.getLogger(__name__)

FIRMWARE_DIR = Path(__file__).resolve().parents[3] / "firmware"
LIBRARY_PATH = FIRMWARE_DIR / "build" / "native" / "libeelfw.so"
HEADER_PATH = FIRMWARE_DIR / "hal" / "native" / "eel_native.h"


def _cdef_from_header(path: Path) -> tuple[str, int, int]:
    """The declarations of the C header for cffi, and its EEL_JOINTS and EEL_ABI_VERSION.

    The header is the one description of the ABI: reading it here, rather than keeping a copy,
    means a changed struct cannot silently disagree with the library.
    """
    text = path.read_text()
    defines = dict(re.findall(r"#define\s+(EEL_\w+)\s+(\d+)", text))
    body = text.split('extern "C" {', 1)[1].split("#ifdef __cplusplus", 1)[0]
    body = re.sub(r"/\*.*?\*/", "", body, flags=re.DOTALL)
    body = "\n".join(line for line in body.splitlines() if not line.lstrip().startswith("#"))
    for name, value in defines.items():
        body = re.sub(rf"\b{name}\b", value, body)
    return body, int(defines["EEL_JOINTS"]), int(defines["EEL_ABI_VERSION"])


_CDEF, N_JOINTS, ABI_VERSION = _cdef_from_header(HEADER_PATH)
#: The analog input of the battery divider (the joints' potentiometers are 0 .. N_JOINTS - 1).
BATTERY_INPUT = int(re.findall(r"#define\s+EEL_BATTERY_INPUT\s+(\d+)", HEADER_PATH.read_text())[0])

_ffi = FFI()
_ffi.cdef(_CDEF)
_lib = None
_lib_lock = threading.Lock()


class NativeFirmwareError(RuntimeError):
    """The native firmware library cannot be built, loaded, or does not match this module."""


def build_library() -> Path:
    """Build (or bring up to date) the native firmware library with ``make native``.

    Returns
    -------
    Path
        The library's path.

    Raises
    ------
    NativeFirmwareError
        When make fails (its output is in the message).
    """
    log.debug("bringing %s up to date (make native)", LIBRARY_PATH)
    try:
        proc = subprocess.run(
            ["make", "-s", "-C", str(FIRMWARE_DIR), "native"],
            capture_output=True,
            text=True,
            check=False,
        )
    except FileNotFoundError as err:
        raise NativeFirmwareError("`make` is not installed; run scripts/setup.sh") from err
    if proc.returncode != 0 or not LIBRARY_PATH.exists():
        raise NativeFirmwareError(
            f"building {LIBRARY_PATH} failed:\n{proc.stdout}{proc.stderr}".rstrip()
        )
    return LIBRARY_PATH


def load_library(path: Path | None = None):
    """Load the library once per process, building or updating it first with make.

    Parameters
    ----------
    path : Path, optional
        Another build of the library (default: ``firmware/build/native/libeelfw.so``).

    Returns
    -------
    cffi library object

    Raises
    ------
    NativeFirmwareError
        When the library's ABI version or schema hash differ from this module's.
    """
    global _lib
    with _lib_lock:
        if _lib is not None and path is None:
            return _lib
        target = path or LIBRARY_PATH
        # Bring the default library up to date (a no-op of ~20 ms when it is), so that Python
        # never runs a stale build of edited C++; without make, use what is there.
        if path is None and (shutil.which("make") or not target.exists()):
            build_library()
        lib = _ffi.dlopen(str(target))
        if lib.eel_abi_version() != ABI_VERSION:
            raise NativeFirmwareError(
                f"{target}: ABI version {lib.eel_abi_version()}, this module needs {ABI_VERSION}"
            )
        if lib.eel_schema_hash() != protocol.SCHEMA_HASH:
            raise NativeFirmwareError(
                f"{target}: schema 0x{lib.eel_schema_hash():04X}, eelhost.wire.protocol has "
                f"0x{protocol.SCHEMA_HASH:04X}; rebuild with `make -C firmware native`"
            )
        if path is None:
            _lib = lib
        return lib


@dataclass(frozen=True)
class TickOutputs:
    """What one tick of the firmware produced.

    Attributes
    ----------
    alpha_rad : ndarray, shape (5,)
        Joint references, joint 1 (tail) first, clamped to the joint limit.
    alpha_dot_rad_s : ndarray, shape (5,)
        Their rates.
    torque_nm : ndarray, shape (5,)
        Joint PD torques for the angles and rates passed to the tick.
    pulse_us : ndarray, shape (5,)
        Servo pulse widths the Nano would output.
    control_ran : bool
        Whether this tick ran a control update (else the references are held).
    measured : bool
        Whether the update measured the joint angles (joint feedback on): the robot then runs the
        PD itself and its pulses command phi + u / k_s (docs/firmware.md, "Joint loop").
    phi_measured_rad : ndarray, shape (5,)
        The angles it measured through the ADC (zeros without feedback).
    """

    alpha_rad: NDArray[np.float32]
    alpha_dot_rad_s: NDArray[np.float32]
    torque_nm: NDArray[np.float32]
    pulse_us: NDArray[np.uint16]
    control_ran: bool
    measured: bool = False
    phi_measured_rad: NDArray[np.float32] = field(
        default_factory=lambda: np.zeros(N_JOINTS, dtype=np.float32)
    )


class NativeFirmware:
    """One instance of the robot's firmware, running natively, with time set by the caller.

    Parameters
    ----------
    now_us : int
        The firmware's clock at boot (any non-negative integer; taken modulo 2^32 like micros()).
    control_period_us : int
        Period of the control update: 10000 as on the robot; 0 runs one on every tick (lockstep
        with a plant that calls :meth:`tick` at its own step).
    library : Path, optional
        Another build of the library (for example a sanitizer build).
    """

    def __init__(
        self,
        now_us: int = 0,
        control_period_us: int = protocol.CONTROL_PERIOD_US,
        library: Path | None = None,
    ) -> None:
        self._lib = load_library(library)
        handle = self._lib.eel_create(_u32(now_us))
        if handle == _ffi.NULL:
            raise MemoryError("eel_create failed")
        self._fw = _ffi.gc(handle, self._lib.eel_destroy)
        self._out = _ffi.new("EelOutputs*")
        self._status = _ffi.new("EelStatus*")
        self._phi = _ffi.new("float[5]")
        self._phi_dot = _ffi.new("float[5]")
        self._reader = protocol.FrameReader()
        self._period = control_period_us
        self._lib.eel_set_control_period_us(self._fw, _u32(control_period_us))

    def reset(self, now_us: int = 0) -> None:
        """Return to the boot state (as after a power cycle), keeping the control period.

        Parameters
        ----------
        now_us : int
            The clock at the new boot.
        """
        self._lib.eel_reset(self._fw, _u32(now_us))
        self._lib.eel_set_control_period_us(self._fw, _u32(self._period))
        self._reader = protocol.FrameReader()

    def reboot(self, now_us: int, reset_flags: int) -> None:
        """Reset without a power cycle (watchdog, brown-out, reset pin): the reset count goes up.

        Parameters
        ----------
        now_us : int
            The clock at the new boot.
        reset_flags : int
            :class:`eelhost.wire.protocol.ResetFlags` bits the robot finds at boot.
        """
        self._lib.eel_reboot(self._fw, _u32(now_us), int(reset_flags) & 0xFF)
        self._lib.eel_set_control_period_us(self._fw, _u32(self._period))
        self._reader = protocol.FrameReader()

    def set_adc(self, analog_input: int, counts: int) -> None:
        """Hold an analog input at a reading (0..1023 over 0..5 V) from now on.

        Parameters
        ----------
        analog_input : int
            0 .. N_JOINTS - 1: a joint's feedback potentiometer; ``BATTERY_INPUT``: the battery.
        counts : int
            The reading.

        Raises
        ------
        ValueError
            For an input or a reading the ADC does not have.
        """
        if self._lib.eel_set_adc(self._fw, int(analog_input), int(counts)) != 0:
            raise ValueError(f"no analog input {analog_input} with reading {counts} (0..1023)")

    def set_joint_angles(self, phi_rad: ArrayLike) -> None:
        """Set the joints' feedback inputs to what their potentiometers read at these angles.

        Parameters
        ----------
        phi_rad : array_like, shape (5,)
            Joint angles, joint 1 first (through the robot's feedback calibration settings).
        """
        self._lib.eel_set_joint_angles(self._fw, self._fill(self._phi, phi_rad, "phi_rad"))

    def eeprom_write(self, address: int, data: bytes) -> None:
        """Write bytes into the emulated EEPROM (as a programmer would, not through the robot).

        Raises
        ------
        ValueError
            When they do not fit in the EEPROM from ``address``.
        """
        n = self._lib.eel_eeprom_write(self._fw, int(address), data, len(data))
        if n != len(data):
            raise ValueError(f"{len(data)} bytes at {address} do not fit in the EEPROM")

    def eeprom_read(self, address: int, n: int) -> bytes:
        """Read ``n`` bytes of the emulated EEPROM from ``address`` (fewer at its end)."""
        buf = _ffi.new(f"uint8_t[{max(int(n), 1)}]")
        got = self._lib.eel_eeprom_read(self._fw, int(address), buf, int(n))
        return bytes(_ffi.buffer(buf, got))

    def set_uart_tx_stalled(self, stalled: bool) -> None:
        """Stop (or restart) the UART's transmitter: the robot's queue fills and frames drop."""
        self._lib.eel_set_uart_tx_stalled(self._fw, 1 if stalled else 0)

    def feed(self, data: bytes) -> None:
        """Deliver bytes to the firmware's UART, as if they came from the radio.

        Parameters
        ----------
        data : bytes
            Received bytes (frames, garbage, anything).

        Raises
        ------
        BufferError
            When the receive queue (4096 bytes) overflows: call :meth:`tick` more often.
        """
        n = self._lib.eel_feed(self._fw, data, len(data))
        if n != len(data):
            raise BufferError(f"UART receive queue full: {len(data) - n} of {len(data)} bytes lost")

    def send(self, message: protocol.Message, seq: int) -> None:
        """Encode a message as the host would and feed it.

        Parameters
        ----------
        message : protocol.Message
            Any message of :mod:`eelhost.wire.protocol`.
        seq : int
            Its sequence number, 0..255.
        """
        self.feed(protocol.encode_frame(message, seq))

    def take(self) -> bytes:
        """Return every byte the firmware has transmitted since the last call."""
        chunks: list[bytes] = []
        buf = _ffi.new("uint8_t[4096]")
        while True:
            n = self._lib.eel_take(self._fw, buf, 4096)
            if n == 0:
                return b"".join(chunks)
            chunks.append(bytes(_ffi.buffer(buf, n)))

    def read_frames(self) -> list[tuple[int, protocol.Message]]:
        """Decode what the firmware has transmitted since the last call.

        Returns
        -------
        list of (seq, message)
            In the order sent; frames that fail to decode are counted in ``host_bad_frames``.
        """
        return self._reader.feed(self.take())

    @property
    def host_bad_frames(self) -> dict[str, int]:
        """Frames from the firmware that this side could not decode, by kind (should stay empty)."""
        return dict(self._reader.bad)

    def tick(
        self,
        now_us: int,
        phi_rad: ArrayLike | None = None,
        phi_dot_rad_s: ArrayLike | None = None,
    ) -> TickOutputs:
        """Run one pass of the firmware's main loop at ``now_us``.

        Parameters
        ----------
        now_us : int
            The firmware's clock, microseconds (taken modulo 2^32: pass the plant's time in whole
            microseconds and the wrap of micros() happens as on the robot).
        phi_rad, phi_dot_rad_s : array_like, shape (5,), optional
            Measured joint angles phi_j = theta_{j+1} - theta_j and their rates (default zeros).

        Returns
        -------
        TickOutputs
            References, PD torques, servo pulses.
        """
        phi = _ffi.NULL if phi_rad is None else self._fill(self._phi, phi_rad, "phi_rad")
        phid = (
            _ffi.NULL
            if phi_dot_rad_s is None
            else self._fill(self._phi_dot, phi_dot_rad_s, "phi_dot_rad_s")
        )
        self._lib.eel_tick(self._fw, _u32(now_us), phi, phid, self._out)
        o = self._out
        return TickOutputs(
            alpha_rad=np.frombuffer(_ffi.buffer(o.alpha_rad), dtype=np.float32).copy(),
            alpha_dot_rad_s=np.frombuffer(_ffi.buffer(o.alpha_dot_rad_s), dtype=np.float32).copy(),
            torque_nm=np.frombuffer(_ffi.buffer(o.torque_nm), dtype=np.float32).copy(),
            pulse_us=np.frombuffer(_ffi.buffer(o.pulse_us), dtype=np.uint16).copy(),
            control_ran=bool(o.control_ran),
            measured=bool(o.measured),
            phi_measured_rad=np.frombuffer(_ffi.buffer(o.phi_measured_rad), dtype=np.float32).copy(),
        )

    def status(self) -> dict[str, float | int]:
        """Read the firmware's state, gait, gains and link counters.

        Returns
        -------
        dict
            Keys as in ``EelStatus`` of ``firmware/hal/native/eel_native.h``; ``state`` is a
            :class:`eelhost.wire.protocol.State`.
        """
        self._lib.eel_status(self._fw, self._status)
        s = self._status
        out = {name: getattr(s, name) for name, _ in _ffi.typeof("EelStatus").fields}
        out["state"] = protocol.State(s.state)
        return out

    @staticmethod
    def _fill(dest, values: ArrayLike, name: str):
        a = np.asarray(values, dtype=np.float32)
        if a.shape != (N_JOINTS,):
            raise ValueError(f"{name} must have shape ({N_JOINTS},), got {a.shape}")
        _ffi.memmove(dest, a.tobytes(), 4 * N_JOINTS)
        return dest


def store_settings(firmware: NativeFirmware, values: dict[str, float]) -> None:
    """Save settings into the firmware's EEPROM through its own commands, then power-cycle it.

    The firmware boots with them, as a robot configured with ``eelbot robot config --save`` does.

    Parameters
    ----------
    firmware : NativeFirmware
        Booted, idle.
    values : dict
        Setting name to value (every joint's element for a per-joint setting).

    Raises
    ------
    RuntimeError
        When the firmware refuses one of them.
    """
    seq = 0
    for name, value in values.items():
        info = protocol.SETTINGS[name]
        for index in range(info.count):
            firmware.send(protocol.SetSetting(info.key, index, value), seq)
            seq += 1
    firmware.send(protocol.SaveSettings(), seq)
    firmware.tick(0)
    refused = [m for _, m in firmware.read_frames() if isinstance(m, protocol.Refuse)]
    if refused:
        raise RuntimeError(f"the firmware refused settings {values}: {refused}")
    firmware.reset(0)


def _u32(now_us: int) -> int:
    if now_us < 0:
        raise ValueError(f"times are non-negative microseconds, got {now_us}")
    return int(now_us) & 0xFFFFFFFF
