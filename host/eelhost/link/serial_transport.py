"""A serial port (the XBee on a USB adapter) as a transport, reopened when it comes back.

A USB serial adapter that is unplugged, or that the kernel resets, makes reads and writes fail
with ``serial.SerialException`` (or ``OSError``); the transport then closes the port and reports
itself disconnected, and :class:`eelhost.link.base.Link` calls :meth:`SerialTransport.open` every
``reconnect_every_s`` until the device node is back.

Registers the ``serial://PORT?baud=N`` scheme (``serial:///dev/ttyUSB0``, ``serial://COM3``); its
ports are the serial ports pyserial sees (``serial.tools.list_ports``).
"""

from __future__ import annotations

import serial
from serial.tools import list_ports as serial_ports

from eelhost.link.base import Clock, Link, TransportError, WallClock
from eelhost.link.uri import LinkURI, LinkURIError, Port, TransportScheme, register_transport
from eelhost.wire import protocol
from eelsim.robot import Robot

__all__ = ["SerialTransport"]


class SerialTransport:
    """A pyserial port, 8N1, non-blocking reads.

    Parameters
    ----------
    port : str
        Device (``/dev/ttyUSB0``, ``COM3``) or a pyserial URL (``loop://`` for tests).
    baud : int
        Bit rate (the robot's is 57600).
    """

    def __init__(self, port: str, baud: int = protocol.BAUD) -> None:
        if baud <= 0:
            raise ValueError(f"baud must be positive, got {baud}")
        self.port = port
        self.baud = baud
        self.description = f"serial port {port} at {baud} baud"
        self._serial: serial.SerialBase | None = None

    @property
    def is_connected(self) -> bool:
        """Whether the port is open."""
        return self._serial is not None and self._serial.is_open

    def open(self) -> None:
        """Open the port; :class:`TransportError` when it is not there (yet)."""
        self.close()
        try:
            # timeout=0: reads return what is buffered, the host loop never blocks on the radio.
            self._serial = serial.serial_for_url(
                self.port, baudrate=self.baud, bytesize=8, parity="N", stopbits=1, timeout=0,
                write_timeout=0.5,
            )
        except (serial.SerialException, OSError, ValueError) as err:
            self._serial = None
            hint = " (a file or device that is not a serial port)" if "ioctl" in str(err) else ""
            raise TransportError(f"{self.port}: cannot open: {err}{hint}") from None

    def close(self) -> None:
        """Close the port if open."""
        if self._serial is not None:
            try:
                self._serial.close()
            except (serial.SerialException, OSError):
                pass  # closing a vanished device can fail; it is closed either way
            self._serial = None

    def write(self, data: bytes) -> None:
        """Write bytes; a failure closes the port and raises :class:`TransportError`."""
        if self._serial is None:
            raise TransportError(f"{self.port}: not open")
        try:
            self._serial.write(data)
        except (serial.SerialException, OSError) as err:
            self.close()
            raise TransportError(f"{self.port}: write failed: {err}") from None

    def read(self) -> bytes:
        """Bytes waiting in the port's buffer; a failure closes the port."""
        if self._serial is None:
            raise TransportError(f"{self.port}: not open")
        try:
            n = self._serial.in_waiting
            return self._serial.read(n) if n else b""
        except (serial.SerialException, OSError) as err:
            self.close()
            raise TransportError(f"{self.port}: read failed: {err}") from None


def _open_serial(u: LinkURI, robot: Robot | None, clock: Clock | None) -> Link:
    if "/" in u.target and not u.target.startswith("/"):
        # serial://dev/ttyUSB0 has two slashes, so the URI names the relative path dev/ttyUSB0
        raise LinkURIError(
            f"{u.text!r}: port {u.target!r} is a relative path; a device path needs three "
            f"slashes: serial:///{u.target}"
        )
    baud = int(u.number("baud", protocol.BAUD, int))
    if baud <= 0:
        raise LinkURIError(f"{u.text!r}: baud={baud} must be positive")
    return Link(SerialTransport(u.target, baud), clock or WallClock())


def _list_serial_ports() -> list[Port]:
    return [
        Port(f"serial://{p.device}", p.description if p.description not in ("", "n/a") else "serial port")
        for p in sorted(serial_ports.comports(), key=lambda p: p.device)
    ]


register_transport(
    TransportScheme(
        name="serial",
        parameters=("baud",),
        target="port",
        open=_open_serial,
        list_ports=_list_serial_ports,
        example="serial:///dev/ttyUSB0?baud=57600",
        description="the XBee radio (or any serial link) on a serial port",
    )
)
