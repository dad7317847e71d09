"""Replay of a recorded log of the bytes the host received, as a transport.

The log (``<out>.rx.bin`` of ``eelbot run``) is a sequence of records, each
``t_s:float64 | length:uint32 | bytes`` (little-endian), written by :class:`RxLogWriter` as the
bytes arrive and flushed at once, so a crash loses at most the record being written; a truncated
last record is ignored on reading.

:class:`ReplayTransport` gives the bytes back: with a clock, each record when the clock reaches
its time (relative to the first read); without one, a record per read. What the host writes is
counted and dropped. After the last record the transport reports itself disconnected, as a link
that went silent, and cannot be reopened.

Registers the ``replay:///path/run.rx.bin`` scheme. It lists no ports: a log is named, not found.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path

from eelhost.errors import UserError
from eelhost.link.base import Clock, Link, TransportError, WallClock
from eelhost.link.uri import LinkURI, Port, TransportScheme, register_transport
from eelsim.robot import Robot

__all__ = ["RECORD_HEADER", "ReplayLogError", "ReplayTransport", "RxLogWriter", "read_rx_log"]

RECORD_HEADER = struct.Struct("<dI")


class ReplayLogError(UserError, FileNotFoundError):
    """A replay log that is not there."""


class RxLogWriter:
    """Append received bytes to a log, one flushed record per chunk.

    Parameters
    ----------
    path : str or Path
        The log file (created or truncated).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.path, "wb")  # noqa: SIM115 (kept open for the whole run)

    def __call__(self, t_s: float, data: bytes) -> None:
        """Append one record (the signature :class:`eelhost.link.base.Link` calls)."""
        self._f.write(RECORD_HEADER.pack(float(t_s), len(data)) + bytes(data))
        self._f.flush()

    def close(self) -> None:
        """Close the file."""
        self._f.close()


def read_rx_log(path: str | Path) -> list[tuple[float, bytes]]:
    """Read every complete record of a log.

    Parameters
    ----------
    path : str or Path
        The log.

    Returns
    -------
    list of (float, bytes)
        ``(t_s, data)`` per record; a truncated last record is left out.

    Raises
    ------
    ReplayLogError
        When the file does not exist.
    """
    if not Path(path).is_file():
        raise ReplayLogError(f"{path}: no such replay log")
    raw = Path(path).read_bytes()
    out: list[tuple[float, bytes]] = []
    i = 0
    while i + RECORD_HEADER.size <= len(raw):
        t_s, n = RECORD_HEADER.unpack_from(raw, i)
        start = i + RECORD_HEADER.size
        if start + n > len(raw):
            break
        out.append((t_s, raw[start : start + n]))
        i = start + n
    return out


class ReplayTransport:
    """A recorded byte log played back as if the robot were sending it.

    Parameters
    ----------
    path : str or Path
        The log.
    clock : callable, optional
        Returns seconds; records come out when ``clock() - clock()_at_first_read`` reaches their
        time relative to the first record. Without a clock, one record per read.
    """

    def __init__(self, path: str | Path, clock: Callable[[], float] | None = None) -> None:
        self.path = Path(path)
        self.records = read_rx_log(self.path)
        self.clock = clock
        self.description = f"replay of {self.path}"
        self.bytes_written = 0
        self._next = 0
        self._open = False
        self._t0: float | None = None

    @property
    def finished(self) -> bool:
        """Whether every record has been read."""
        return self._next >= len(self.records)

    @property
    def is_connected(self) -> bool:
        """Open and not at the end of the log."""
        return self._open and not self.finished

    def open(self) -> None:
        """Start (or continue) the replay; fails once the log is exhausted."""
        if self.finished:
            raise TransportError(f"{self.path}: end of the replay log")
        self._open = True

    def close(self) -> None:
        """Pause the replay."""
        self._open = False

    def write(self, data: bytes) -> None:
        """Drop the bytes (nobody listens to a replay), counting them."""
        if not self.is_connected:
            raise TransportError(f"{self.path}: replay not open or finished")
        self.bytes_written += len(data)

    def read(self) -> bytes:
        """The records that are due."""
        if not self.is_connected:
            raise TransportError(f"{self.path}: replay not open or finished")
        if self.clock is None:
            data = self.records[self._next][1]
            self._next += 1
            return data
        now = self.clock()
        if self._t0 is None:
            self._t0 = now - self.records[0][0]
        out = bytearray()
        while not self.finished and self.records[self._next][0] <= now - self._t0:
            out += self.records[self._next][1]
            self._next += 1
        return bytes(out)


def _open_replay(u: LinkURI, robot: Robot | None, clock: Clock | None) -> Link:
    c = clock or WallClock()
    return Link(ReplayTransport(u.target, c.now), c)


def _list_replay_ports() -> list[Port]:
    return []


register_transport(
    TransportScheme(
        name="replay",
        parameters=(),
        target="log file path",
        open=_open_replay,
        list_ports=_list_replay_ports,
        example="replay:///path/run.rx.bin",
        description="a recorded run's received bytes played back",
    )
)
