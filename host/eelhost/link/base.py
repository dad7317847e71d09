"""The host's link to the robot: a byte transport behind one interface, and the framed link on top.

A :class:`Transport` moves bytes (a serial port, the virtual robot, a replayed log). A
:class:`Link` turns messages of :mod:`eelhost.wire.protocol` into frames and back: it numbers what it
sends, tracks the robot's Acks and Refuses, resends unacknowledged commands, counts bad frames,
notices a dropped transport and reopens it, and tells listeners (the recorder) about every event.

One :class:`Link` serves every transport: the serial port at the tank, the virtual robot of
``sim://``, a replayed log, and the firmware-in-the-loop runs of :mod:`eelhost.xil.lockstep`.

Time comes from a :class:`Clock` owned by the caller (docs/architecture.md, "one clock owner"):
the wall clock for a real robot, the simulated clock for the virtual one and for lockstep runs,
so nothing here sleeps or reads the time on its own.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from eelhost.errors import UserError
from eelhost.wire import protocol

log = logging.getLogger(__name__)

__all__ = [
    "Clock",
    "Link",
    "LinkCounters",
    "LinkEvent",
    "Transport",
    "TransportError",
    "WallClock",
]


class TransportError(UserError, ConnectionError):
    """The transport cannot carry bytes right now (a port that went away, a finished replay).

    Inside a run the :class:`Link` handles it (it reconnects); when a link cannot be opened at
    all it reaches the user, whose port it names.
    """


class Clock(Protocol):
    """Time for the host loop, in seconds from an arbitrary origin."""

    def now(self) -> float:
        """The present time, s."""
        ...

    def wait_until(self, t_s: float) -> None:
        """Return once the time is ``t_s`` or later."""
        ...


class WallClock:
    """The real time (``time.monotonic``), from the moment the clock is made."""

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        """Seconds since the clock was made."""
        return time.monotonic() - self._t0

    def wait_until(self, t_s: float) -> None:
        """Sleep until ``t_s`` (a real run has nothing better to do)."""
        delay = t_s - self.now()
        if delay > 0:
            time.sleep(delay)


class Transport(Protocol):
    """Bytes to and from the robot.

    ``open`` raises :class:`TransportError` when the other end is not there; ``write`` and
    ``read`` raise it when the transport dropped (after which ``is_connected`` is False until an
    ``open`` succeeds). ``read`` never blocks: it returns the bytes that have arrived.
    """

    description: str

    def open(self) -> None:
        """Connect (again)."""
        ...

    def close(self) -> None:
        """Disconnect; harmless when not connected."""
        ...

    def write(self, data: bytes) -> None:
        """Send bytes."""
        ...

    def read(self) -> bytes:
        """Bytes received since the last read (possibly none)."""
        ...

    @property
    def is_connected(self) -> bool:
        """Whether bytes can flow now."""
        ...


@dataclass(frozen=True)
class LinkEvent:
    """Something that happened on the link.

    Attributes
    ----------
    t_s : float
        Clock time.
    kind : str
        ``sent``, ``not_sent`` (the transport was down), ``resent``, ``ack``, ``refused``,
        ``lost`` (no Ack after every attempt), ``disconnected``, ``reconnected``.
    seq : int
        Sequence number of the frame concerned (-1 when none).
    message : protocol.Message or None
        The command concerned (for ``ack``/``refused``: the one sent under ``seq``).
    detail : str
        Free text (the refuse reason, the transport's error).
    """

    t_s: float
    kind: str
    seq: int = -1
    message: protocol.Message | None = None
    detail: str = ""


@dataclass
class LinkCounters:
    """What the link did, for reports and tests.

    Attributes
    ----------
    frames_sent, frames_received : int
        Frames written and frames decoded.
    bad_frames : dict
        Received frames dropped, by :class:`eelhost.wire.protocol.FrameError` kind.
    acks, refuses, resends, lost : int
        Acks and Refuses received, commands sent again, commands given up on.
    not_sent : int
        Frames that could not be written (the transport was down).
    disconnects, reconnects : int
        Times the transport dropped and came back.
    """

    frames_sent: int = 0
    frames_received: int = 0
    bad_frames: dict[str, int] = field(default_factory=dict)
    acks: int = 0
    refuses: int = 0
    resends: int = 0
    lost: int = 0
    not_sent: int = 0
    disconnects: int = 0
    reconnects: int = 0


@dataclass
class _Pending:
    message: protocol.Message
    seq: int
    sent_s: float
    attempts: int


class Link:
    """Framed messages over a transport, with sequence numbers, acknowledgements and reconnection.

    Parameters
    ----------
    transport : Transport
        The bytes; opened by the caller or by the first :meth:`poll`.
    clock : Clock
        Time of every event.
    resend_after_s : float
        A command sent with ``want_ack`` and not acknowledged this long is sent again, under a
        new sequence number (the firmware counts a repeated number as a duplicate).
    max_attempts : int or None
        Attempts before such a command is reported ``lost``; None: resend until acknowledged.
    reconnect_every_s : float
        How often to try reopening a dropped transport.
    rx_log : callable, optional
        ``rx_log(t_s, data)`` gets every chunk of received bytes (see
        :class:`eelhost.link.replay_transport.RxLogWriter`).
    """

    def __init__(
        self,
        transport: Transport,
        clock: Clock,
        resend_after_s: float = 0.2,
        max_attempts: int | None = 5,
        reconnect_every_s: float = 0.25,
        rx_log: Callable[[float, bytes], None] | None = None,
    ) -> None:
        self.transport = transport
        self.clock = clock
        self.resend_after_s = resend_after_s
        self.max_attempts = max_attempts
        self.reconnect_every_s = reconnect_every_s
        self.rx_log = rx_log
        self.counters = LinkCounters()
        self.listeners: list[Callable[[LinkEvent], None]] = []
        self.last_rx_s: float | None = None
        self.telemetry: protocol.Telemetry | None = None
        self.version: protocol.Version | None = None
        self.status: protocol.Status | None = None
        self._refusals: dict[int, int] = {}
        self._flags: int | None = None
        self._reader = protocol.FrameReader()
        self._seq = 0
        self._by_seq: dict[int, protocol.Message] = {}
        self._pending: dict[int, _Pending] = {}
        self._answered: dict[int, str] = {}
        self._last_attempt_s = -float("inf")
        self._was_connected = False

    # -- sending ---------------------------------------------------------------------------
    def send(self, message: protocol.Message, want_ack: bool = False) -> int:
        """Frame and write a message now.

        Parameters
        ----------
        message : protocol.Message
            A message to the robot (validated first: the robot would refuse it anyway).
        want_ack : bool
            Resend until acknowledged (up to ``max_attempts``); see :meth:`outcome`.

        Returns
        -------
        int
            The sequence number used (a ``want_ack`` command keeps its first number in
            :meth:`outcome` even when resent).
        """
        message.validate()
        seq = self._write(message, "sent")
        if want_ack:
            self._pending[seq] = _Pending(message, seq, self.clock.now(), 1)
        return seq

    def _write(self, message: protocol.Message, kind: str) -> int:
        seq = self._seq
        self._seq = (self._seq + 1) % 256
        self._by_seq[seq] = message
        self._answered.pop(seq, None)
        now = self.clock.now()
        try:
            if not self.transport.is_connected:
                raise TransportError("not connected")
            self.transport.write(protocol.encode_frame(message, seq))
        except TransportError as err:
            self._dropped(now, err)
            self.counters.not_sent += 1
            self._emit(LinkEvent(now, "not_sent", seq, message, str(err)))
            return seq
        self.counters.frames_sent += 1
        self._emit(LinkEvent(now, kind, seq, message))
        return seq

    def outcome(self, seq: int) -> str:
        """What became of the command sent under ``seq``.

        Returns
        -------
        str
            ``"ack"``, ``"refused"``, ``"lost"``, ``"pending"`` (still being resent) or
            ``"unknown"`` (sent without ``want_ack`` and not answered).
        """
        if seq in self._answered:
            return self._answered[seq]
        return "pending" if seq in self._pending else "unknown"

    def refusal(self, seq: int) -> protocol.RefuseReason | None:
        """Why the robot refused the command sent under ``seq`` (None if it did not)."""
        reason = self._refusals.get(seq) if self.outcome(seq) == "refused" else None
        if reason is None:
            return None
        try:
            return protocol.RefuseReason(reason)
        except ValueError:
            return None

    @property
    def joint_feedback(self) -> bool | None:
        """Whether the robot has joint feedback (analog-feedback servos, the PD on the robot).

        From the flags of its last Telemetry or Status; None before either arrived.
        """
        if self._flags is None:
            return None
        return bool(self._flags & protocol.Flags.JOINT_FEEDBACK)

    def pending(self) -> list[protocol.Message]:
        """The commands sent with ``want_ack`` that are still being resent, oldest first."""
        return [p.message for p in self._pending.values()]

    def sent_under(self, seq: int) -> protocol.Message | None:
        """The message last written under a sequence number (None if none was)."""
        return self._by_seq.get(seq)

    # -- receiving -------------------------------------------------------------------------
    def poll(self) -> list[protocol.Message]:
        """Reconnect if needed, read what has arrived, handle Acks, resend what is due.

        Returns
        -------
        list of protocol.Message
            Every message decoded from the robot, in order.
        """
        now = self.clock.now()
        if not self.transport.is_connected:
            self._try_reconnect(now)
        data = b""
        if self.transport.is_connected:
            try:
                data = self.transport.read()
            except TransportError as err:
                self._dropped(now, err)
        out: list[protocol.Message] = []
        if data:
            if self.rx_log is not None:
                self.rx_log(now, data)
            bad_before = sum(self._reader.bad.values())
            frames = self._reader.feed(data)
            if frames or sum(self._reader.bad.values()) != bad_before:
                self.counters.bad_frames = dict(self._reader.bad)
            for _, msg in frames:
                self.counters.frames_received += 1
                self.last_rx_s = now
                self._handle(now, msg)
                out.append(msg)
        self._resend_due(now)
        return out

    def _handle(self, now: float, msg: protocol.Message) -> None:
        if isinstance(msg, protocol.Telemetry):
            self.telemetry = msg
            self._flags = msg.flags
        elif isinstance(msg, protocol.Status):
            self.status = msg
            self._flags = msg.flags
        elif isinstance(msg, protocol.Version):
            self.version = msg
        elif isinstance(msg, protocol.Ack | protocol.Refuse):
            kind = "ack" if isinstance(msg, protocol.Ack) else "refused"
            if kind == "ack":
                self.counters.acks += 1
            else:
                self.counters.refuses += 1
            sent = self._by_seq.get(msg.seq)
            first = self._first_seq(msg.seq)
            self._answered[first] = kind
            self._answered[msg.seq] = kind
            self._pending.pop(first, None)
            detail = ""
            if isinstance(msg, protocol.Refuse):
                self._refusals[first] = self._refusals[msg.seq] = msg.reason
                detail = _refuse_reason(msg.reason)
                log.warning("the robot refused %s: %s", type(sent).__name__, detail)
            self._emit(LinkEvent(now, kind, msg.seq, sent, detail))

    def _first_seq(self, seq: int) -> int:
        """The number a resent command was first sent under (its key in ``_pending``)."""
        for first, p in self._pending.items():
            if p.seq == seq:
                return first
        return seq

    def _resend_due(self, now: float) -> None:
        for first, p in list(self._pending.items()):
            if now - p.sent_s < self.resend_after_s:
                continue
            if self.max_attempts is not None and p.attempts >= self.max_attempts:
                del self._pending[first]
                self._answered[first] = "lost"
                self.counters.lost += 1
                log.warning("%s lost after %d attempts", type(p.message).__name__, p.attempts)
                self._emit(LinkEvent(now, "lost", first, p.message, f"{p.attempts} attempts"))
                continue
            p.seq = self._write(p.message, "resent")
            log.debug("%s resent (attempt %d)", type(p.message).__name__, p.attempts + 1)
            p.sent_s, p.attempts = now, p.attempts + 1
            self.counters.resends += 1

    # -- connection ------------------------------------------------------------------------
    def open(self) -> None:
        """Open the transport (raises :class:`TransportError` when the robot's end is absent)."""
        self.transport.open()
        self._was_connected = True
        self.last_rx_s = None

    def close(self) -> None:
        """Close the transport."""
        self.transport.close()

    def _dropped(self, now: float, err: Exception) -> None:
        if self._was_connected:
            self._was_connected = False
            self.counters.disconnects += 1
            log.warning("link dropped: %s", err)
            self._emit(LinkEvent(now, "disconnected", detail=str(err)))

    def _try_reconnect(self, now: float) -> None:
        if self._was_connected:
            # The transport noticed the drop by itself (is_connected went False).
            self._dropped(now, TransportError("transport reports disconnected"))
        if now - self._last_attempt_s < self.reconnect_every_s:
            return
        self._last_attempt_s = now
        try:
            self.transport.open()
        except TransportError:
            return
        self._was_connected = True
        self.counters.reconnects += 1
        log.info("link back: %s", self.transport.description)
        self._emit(LinkEvent(now, "reconnected", detail=self.transport.description))
        # Hello resynchronises the robot's sequence check after the frames lost in the gap.
        self._write(protocol.Hello(), "sent")

    def silent_for_s(self, since_s: float) -> float:
        """Time since the last frame from the robot (or since ``since_s`` if none came after it)."""
        last = since_s if self.last_rx_s is None else max(self.last_rx_s, since_s)
        return self.clock.now() - last

    def _emit(self, event: LinkEvent) -> None:
        for listener in self.listeners:
            listener(event)


def _refuse_reason(code: int) -> str:
    try:
        return protocol.RefuseReason(code).name
    except ValueError:
        return f"reason {code}"
