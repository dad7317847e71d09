"""Open a link from a URI: one host code for the robot, the virtual robot and a replay (rule 8).

- ``serial:///dev/ttyUSB0?baud=57600`` (``serial://COM3`` on Windows): the XBee on a serial port.
- ``sim://?speed=10&seed=0``: the virtual robot (native firmware + twin). Parameters:
  ``speed`` (simulated seconds per wall second, 0 = as fast as possible; default 1),
  ``seed``, ``radio`` (``xbee`` or ``ideal``), ``loss`` (byte loss probability),
  ``drop=START:END`` (the link is down over that window, s; repeat or separate with commas),
  ``start=x,y,heading_deg`` (where the robot starts in the virtual tank),
  ``current=speed,direction_deg``.
- ``replay:///path/log.bin``: the bytes of a recorded run (``<out>.rx.bin``) played back.

Errors are :class:`LinkURIError` naming the part of the URI that is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from eelhost.link.base import Clock, Link, WallClock
from eelhost.link.replay_transport import ReplayTransport
from eelhost.link.serial_transport import SerialTransport
from eelhost.link.sim_transport import SimTransport, VirtualRobot
from eelhost.wire import protocol
from eelhost.xil.radio import RadioModel
from eelsim.robot import Robot, load_robot

__all__ = ["LinkURI", "LinkURIError", "open_link", "parse_link_uri"]

SCHEMES = ("serial", "sim", "replay")
PARAMETERS = {
    "serial": ("baud",),
    "sim": ("speed", "seed", "radio", "loss", "drop", "start", "current"),
    "replay": (),
}


class LinkURIError(ValueError):
    """A link URI that cannot be used; the message names the bad part."""


@dataclass(frozen=True)
class LinkURI:
    """A parsed link URI.

    Attributes
    ----------
    scheme : str
        ``serial``, ``sim`` or ``replay``.
    target : str
        The port or the log path ("" for ``sim``).
    params : dict of str to list of str
        Query parameters (a parameter may repeat).
    text : str
        The URI as given.
    """

    scheme: str
    target: str
    params: dict[str, list[str]]
    text: str

    def one(self, name: str, default: str | None = None) -> str | None:
        """The value of a parameter given at most once."""
        values = self.params.get(name)
        if not values:
            return default
        if len(values) > 1:
            raise LinkURIError(f"{self.text!r}: parameter {name!r} given {len(values)} times")
        return values[0]

    def number(self, name: str, default: float, kind: type = float) -> float:
        """A numeric parameter (``kind`` int or float), checked finite."""
        raw = self.one(name)
        if raw is None:
            return default
        try:
            value = kind(raw)
        except ValueError:
            raise LinkURIError(
                f"{self.text!r}: {name}={raw!r} is not {'an integer' if kind is int else 'a number'}"
            ) from None
        if not math.isfinite(value):
            raise LinkURIError(f"{self.text!r}: {name}={raw!r} is not finite")
        return value

    def numbers(self, name: str, raw: str, count: int | None) -> list[float]:
        """Comma- or colon-separated numbers of one parameter value."""
        parts = [p for p in raw.replace(":", ",").split(",") if p.strip()]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise LinkURIError(f"{self.text!r}: {name}={raw!r}: expected numbers") from None
        if count is not None and len(values) != count:
            raise LinkURIError(f"{self.text!r}: {name}={raw!r}: expected {count} numbers")
        if not all(math.isfinite(v) for v in values):
            raise LinkURIError(f"{self.text!r}: {name}={raw!r}: numbers must be finite")
        return values


def parse_link_uri(uri: str) -> LinkURI:
    """Split and check a link URI.

    Parameters
    ----------
    uri : str
        ``serial://PORT?baud=N``, ``sim://?...`` or ``replay://PATH``.

    Returns
    -------
    LinkURI

    Raises
    ------
    LinkURIError
        Unknown scheme, missing port or path, unknown parameter.
    """
    text = str(uri).strip()
    if "://" not in text:
        raise LinkURIError(
            f"{text!r}: not a link URI (expected serial:///dev/ttyUSB0, sim:// or replay:///log.bin)"
        )
    parts = urlsplit(text)
    scheme = parts.scheme.lower()
    if scheme not in SCHEMES:
        raise LinkURIError(
            f"{text!r}: unknown scheme {parts.scheme!r} (expected {', '.join(SCHEMES)})"
        )
    target = parts.netloc + parts.path
    if scheme in ("serial", "replay") and not target:
        what = "port" if scheme == "serial" else "log file path"
        raise LinkURIError(f"{text!r}: no {what} after {scheme}://")
    if scheme == "sim" and target.strip("/"):
        raise LinkURIError(f"{text!r}: sim:// takes no path ({target!r}); use parameters")
    try:
        params = parse_qs(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError:
        raise LinkURIError(f"{text!r}: malformed parameters {parts.query!r}") from None
    for name in params:
        if name not in PARAMETERS[scheme]:
            known = ", ".join(PARAMETERS[scheme]) or "none"
            raise LinkURIError(
                f"{text!r}: unknown parameter {name!r} for {scheme}:// (known: {known})"
            )
    return LinkURI(scheme, target, params, text)


def open_link(uri: str, robot: Robot | None = None, clock: Clock | None = None) -> Link:
    """Open the link a URI names.

    Parameters
    ----------
    uri : str
        See the module docstring.
    robot : Robot, optional
        The robot the virtual robot simulates (default: the bundled paper robot); unused
        otherwise.
    clock : Clock, optional
        Time for serial and replay links (default: the wall clock). A ``sim://`` link always
        uses its virtual robot's clock (``link.clock``), which the host loop then drives.

    Returns
    -------
    Link
        Opened. For ``sim://``, ``link.transport.robot`` is the :class:`VirtualRobot`.

    Raises
    ------
    LinkURIError
        For a malformed URI.
    eelhost.link.base.TransportError
        When the port cannot be opened.
    FileNotFoundError
        For a missing replay log.
    """
    u = parse_link_uri(uri)
    if u.scheme == "serial":
        baud = int(u.number("baud", protocol.BAUD, int))
        if baud <= 0:
            raise LinkURIError(f"{u.text!r}: baud={baud} must be positive")
        link = Link(SerialTransport(u.target, baud), clock or WallClock())
    elif u.scheme == "replay":
        c = clock or WallClock()
        link = Link(ReplayTransport(u.target, c.now), c)
    else:
        vr = _virtual_robot(u, robot or load_robot())
        link = Link(SimTransport(vr), vr.clock)
    link.open()
    return link


def _virtual_robot(u: LinkURI, robot: Robot) -> VirtualRobot:
    speed = u.number("speed", 1.0)
    if speed < 0:
        raise LinkURIError(f"{u.text!r}: speed={speed:g} must be >= 0 (0 = as fast as possible)")
    seed = int(u.number("seed", 0, int))
    radio_name = u.one("radio", "xbee")
    loss = u.number("loss", 0.0)
    if not 0.0 <= loss <= 1.0:
        raise LinkURIError(f"{u.text!r}: loss={loss:g} must be in [0, 1]")
    if radio_name == "xbee":
        radio = RadioModel.xbee(loss_probability=loss)
    elif radio_name == "ideal":
        radio = RadioModel(loss_probability=loss)
    else:
        raise LinkURIError(f"{u.text!r}: radio={radio_name!r} (expected xbee or ideal)")
    drops = []
    for raw in u.params.get("drop", []):
        for window in raw.split(","):
            a, b = u.numbers("drop", window, 2)
            if not 0 <= a < b:
                raise LinkURIError(f"{u.text!r}: drop={window!r} needs 0 <= start < end")
            drops.append((a, b))
    start = u.one("start")
    x, y, heading = u.numbers("start", start, 3) if start else (0.0, 0.0, 0.0)
    current = u.one("current")
    c_speed, c_dir = u.numbers("current", current, 2) if current else (0.0, 0.0)
    if c_speed < 0:
        raise LinkURIError(f"{u.text!r}: current speed {c_speed:g} must be >= 0")
    c = math.radians(c_dir)
    return VirtualRobot(
        robot,
        start_position_m=(x, y),
        start_heading_deg=heading,
        current_m_s=(c_speed * math.cos(c), c_speed * math.sin(c)),
        radio=radio,
        drops_s=drops,
        seed=seed,
        speed=speed,
    )
