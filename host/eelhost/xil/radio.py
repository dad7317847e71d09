"""A model of the serial radio link (XBee) between the host and the robot, byte by byte.

Used by the lockstep stepper (:mod:`eelhost.xil.lockstep`, behind both the firmware-in-the-loop runs
and the virtual robot of ``sim://``) and the processor-in-the-loop driver (:mod:`eelhost.xil.simavr`).
Each direction is a :class:`RadioChannel`: bytes handed to it at an integer microsecond time come
out later, in order, at the times the link delivers them.

What is modelled, per direction:

- **byte rate**: a UART at ``baud`` with ``bits_per_byte`` (10 for 8N1) sends one byte every
  ``bits_per_byte / baud`` s; bytes queue behind each other (57600 baud: 173.6 us a byte);
- **latency**: a fixed delay added to every byte (the radio's packetisation and air time);
- **loss**: each byte is dropped with probability ``loss_probability``;
- **corruption**: each byte that is not lost is replaced, with probability
  ``corruption_probability``, by itself XOR a random non-zero mask (so it always differs);
- **outages**: time windows ``[start_us, end_us)`` in which every byte sent is lost (a link that
  drops mid-run).

Randomness comes only from the ``numpy.random.Generator`` passed in, so a run is deterministic
for a seed. With ``baud=None``, zero latency and no loss the link is ideal: a byte arrives at the
time it was sent, which is what the twin assumes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from eelhost.wire import protocol

__all__ = ["ChannelCounters", "RadioChannel", "RadioModel"]


@dataclass(frozen=True)
class RadioModel:
    """Parameters of one radio link (the same for both directions).

    Attributes
    ----------
    baud : int or None
        UART bit rate; ``None`` for an infinitely fast link.
    bits_per_byte : int
        Bits on the wire per byte: start + 8 data + stop = 10 for 8N1.
    latency_us : int
        Fixed delay added to every byte, microseconds.
    loss_probability : float
        Probability that a byte is dropped.
    corruption_probability : float
        Probability that a delivered byte is altered (XOR a random non-zero mask).
    outages_us : tuple of (int, int)
        Windows ``[start_us, end_us)`` of send times in which every byte is lost.
    """

    baud: int | None = None
    bits_per_byte: int = 10
    latency_us: int = 0
    loss_probability: float = 0.0
    corruption_probability: float = 0.0
    outages_us: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        if self.baud is not None and self.baud <= 0:
            raise ValueError(f"baud must be positive or None, got {self.baud}")
        if self.bits_per_byte < 1:
            raise ValueError(f"bits_per_byte must be at least 1, got {self.bits_per_byte}")
        if self.latency_us < 0 or int(self.latency_us) != self.latency_us:
            raise ValueError(f"latency_us must be a non-negative integer, got {self.latency_us}")
        for name in ("loss_probability", "corruption_probability"):
            p = getattr(self, name)
            if not (math.isfinite(p) and 0.0 <= p <= 1.0):
                raise ValueError(f"{name} must be in [0, 1], got {p}")
        for start, end in self.outages_us:
            if not 0 <= start <= end:
                raise ValueError(f"outage ({start}, {end}) must have 0 <= start <= end")

    @classmethod
    def xbee(
        cls,
        baud: int = protocol.BAUD,
        latency_us: int = 5000,
        loss_probability: float = 0.0,
        corruption_probability: float = 0.0,
        outages_us: tuple[tuple[int, int], ...] = (),
    ) -> RadioModel:
        """The robot's XBee link: 57600 baud 8N1 and a few milliseconds of radio latency.

        Parameters
        ----------
        baud : int
            UART bit rate (the robot's is 57600).
        latency_us : int
            Fixed delay per byte (an XBee in transparent mode waits 3 character times before it
            sends a packet, then the air time and the far UART add a few milliseconds).
        loss_probability, corruption_probability : float
            Per-byte probabilities.
        outages_us : tuple of (int, int)
            Windows in which the link is down.

        Returns
        -------
        RadioModel
        """
        return cls(baud, 10, latency_us, loss_probability, corruption_probability, outages_us)

    @property
    def byte_time_us(self) -> float:
        """Time to send one byte, microseconds (0 for an infinitely fast link)."""
        return 0.0 if self.baud is None else self.bits_per_byte * 1e6 / self.baud

    @property
    def is_ideal(self) -> bool:
        """True when bytes arrive when sent, unchanged."""
        return (
            self.baud is None
            and self.latency_us == 0
            and self.loss_probability == 0.0
            and self.corruption_probability == 0.0
            and not self.outages_us
        )

    def with_outages(self, extra_us: tuple[tuple[int, int], ...]) -> RadioModel:
        """The same link with more outage windows (``[start_us, end_us)`` each).

        Parameters
        ----------
        extra_us : tuple of (int, int)
            Windows added to :attr:`outages_us`.

        Returns
        -------
        RadioModel
        """
        return replace(self, outages_us=tuple(self.outages_us) + tuple(extra_us))

    def channels(self, seed: int) -> tuple[RadioChannel, RadioChannel]:
        """Both directions of this link, each with its own random stream of ``seed``.

        Parameters
        ----------
        seed : int
            Seed of the loss and corruption; the uplink and the downlink draw from two streams
            spawned from it (``numpy.random.SeedSequence(seed).spawn(2)``).

        Returns
        -------
        uplink, downlink : RadioChannel
            Host -> robot and robot -> host.
        """
        up, down = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
        return self.channel(up), self.channel(down)

    def channel(self, rng: np.random.Generator) -> RadioChannel:
        """Create one direction of this link.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of loss and corruption for this direction.

        Returns
        -------
        RadioChannel
        """
        return RadioChannel(self, rng)


@dataclass
class ChannelCounters:
    """What one direction of the link did to the bytes it carried.

    Attributes
    ----------
    sent, delivered, lost, corrupted : int
        Bytes handed to the channel, delivered, dropped (loss or outage), delivered altered.
    """

    sent: int = 0
    delivered: int = 0
    lost: int = 0
    corrupted: int = 0


class RadioChannel:
    """One direction of a radio link: bytes in at a time, bytes out when the link delivers them.

    Parameters
    ----------
    model : RadioModel
        Link parameters.
    rng : numpy.random.Generator
        Source of loss and corruption.
    """

    def __init__(self, model: RadioModel, rng: np.random.Generator) -> None:
        self.model = model
        self._rng = rng
        self._line_free_us = 0.0  # when the UART finishes the byte in progress
        self._queue: list[tuple[int, int]] = []  # (arrival_us, byte), in order
        self._head = 0
        self.counters = ChannelCounters()

    def send(self, t_us: int, data: bytes) -> None:
        """Hand bytes to the link at time ``t_us``.

        Parameters
        ----------
        t_us : int
            Send time, microseconds; not earlier than any previous send.
        data : bytes
            The bytes, in order.
        """
        m = self.model
        byte_us = m.byte_time_us
        start = max(float(t_us), self._line_free_us)
        down = any(a <= t_us < b for a, b in m.outages_us)
        for k, byte in enumerate(data):
            self.counters.sent += 1
            done = start + (k + 1) * byte_us  # the byte's stop bit leaves the UART
            lost = down or (m.loss_probability > 0 and self._rng.random() < m.loss_probability)
            if lost:
                self.counters.lost += 1
                continue
            if m.corruption_probability > 0 and self._rng.random() < m.corruption_probability:
                byte ^= int(self._rng.integers(1, 256))
                self.counters.corrupted += 1
            self._queue.append((math.ceil(done - 1e-9) + m.latency_us, byte))
        self._line_free_us = start + len(data) * byte_us

    def deliver(self, until_us: int) -> list[tuple[int, int]]:
        """Take the bytes that have arrived by ``until_us`` (inclusive).

        Parameters
        ----------
        until_us : int
            Time up to which to deliver, microseconds.

        Returns
        -------
        list of (arrival_us, byte)
            In order of arrival.
        """
        q, i = self._queue, self._head
        while i < len(q) and q[i][0] <= until_us:
            i += 1
        out = q[self._head : i]
        self._head = i
        if i > 4096:  # drop what was delivered, now and then
            del q[:i]
            self._head = 0
        self.counters.delivered += len(out)
        return out

    def deliver_bytes(self, until_us: int) -> bytes:
        """Like :meth:`deliver`, but only the bytes.

        Parameters
        ----------
        until_us : int
            Time up to which to deliver, microseconds.

        Returns
        -------
        bytes
        """
        return bytes(b for _, b in self.deliver(until_us))

    @property
    def pending(self) -> int:
        """Bytes sent but not delivered yet."""
        return len(self._queue) - self._head
