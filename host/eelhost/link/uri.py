"""Open a link from a URI: one host code for the robot, the virtual robot and a replay.

Transports are chosen by a URI (docs/architecture.md, "transports chosen by a URI"). Each transport
module registers its scheme in :data:`TRANSPORTS` with :func:`register_transport` (its
parameters, how to open it, how to list the ports it can see, one line saying what it is), as
cflib's drivers do; :func:`open_link`, :func:`list_ports` and the CLI's help consult that
registry. Another package adds a transport through the ``eelbot.transports`` entry-point group
(docs/architecture.md, "Extension points"). The bundled ones:

- ``serial:///dev/ttyUSB0?baud=57600`` (``serial://COM3`` on Windows): the XBee on a serial port
  (:mod:`eelhost.link.serial_transport`);
- ``sim://?speed=10&seed=0``: the virtual robot, native firmware + twin
  (:mod:`eelhost.link.sim_transport`, which lists its parameters);
- ``replay:///path/log.bin``: the bytes of a recorded run (``<out>.rx.bin``) played back
  (:mod:`eelhost.link.replay_transport`).

Errors are :class:`LinkURIError` naming the part of the URI that is wrong.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from eelhost.errors import UserError
from eelhost.link.base import Clock, Link
from eelsim.registry import Registry
from eelsim.robot import Robot

__all__ = [
    "LinkURI",
    "TRANSPORTS",
    "LinkURIError",
    "Port",
    "TransportScheme",
    "list_ports",
    "open_link",
    "parse_link_uri",
    "register_transport",
    "transport_schemes",
]


class LinkURIError(UserError, ValueError):
    """A link URI that cannot be used; the message names the bad part."""


@dataclass(frozen=True)
class LinkURI:
    """A parsed link URI.

    Attributes
    ----------
    scheme : str
        A registered scheme (``serial``, ``sim``, ``replay``, ...).
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


@dataclass(frozen=True)
class Port:
    """A link a transport can open now.

    Attributes
    ----------
    uri : str
        The URI that opens it.
    description : str
        What it is (the adapter's name, ...).
    """

    uri: str
    description: str


@dataclass(frozen=True)
class TransportScheme:
    """A transport's entry in the registry of URI schemes.

    Attributes
    ----------
    name : str
        The scheme, lower case (``serial``).
    parameters : tuple of str
        The query parameters it accepts.
    target : str
        What must follow ``scheme://`` (``port``, ``log file path``), or "" when nothing may.
    open : callable
        ``open(uri, robot, clock) -> Link``: the link, not yet opened. ``robot`` is the robot a
        simulated transport simulates (None: the bundled paper robot); ``clock`` times a real
        transport (None: the wall clock).
    list_ports : callable
        ``list_ports() -> list of Port``: what it can open now.
    example : str
        A URI to show in messages.
    check : callable or None
        ``check(uri)``: refuses parameter values the transport cannot use (raising
        :class:`LinkURIError`), called by :func:`parse_link_uri`, so a bad value is said before
        anything is opened or recorded.
    description : str
        One line for help texts (``eelbot ports --help``); required by the registry.
    """

    name: str
    parameters: tuple[str, ...]
    target: str
    open: Callable[[LinkURI, Robot | None, Clock | None], Link]
    list_ports: Callable[[], list[Port]]
    example: str
    check: Callable[[LinkURI], object] | None = None
    description: str = ""


def _check_scheme(name: str, scheme: TransportScheme) -> None:
    """Refuse an entry that cannot be registered under ``name`` (:data:`TRANSPORTS`)."""
    if not isinstance(scheme, TransportScheme):
        raise ValueError(f"expected a TransportScheme, got {type(scheme).__name__}")
    if scheme.name.lower() != name:
        raise ValueError(f"the entry says its scheme is {scheme.name!r}")
    if not re.fullmatch(r"[a-z][a-z0-9+.-]*", name):
        raise ValueError("a URI scheme is a letter, then letters, digits, '+', '-' or '.'")
    if not scheme.description.strip():
        raise ValueError("give the TransportScheme a one-line description")


TRANSPORTS: Registry[TransportScheme] = Registry(
    "transport", "eelbot.transports", check=_check_scheme, normalise=str.lower, plural="schemes"
)
"""The registered transports, by URI scheme (:mod:`eelsim.registry`; plug-ins: group
``eelbot.transports``, each entry point a :class:`TransportScheme`)."""


def register_transport(scheme: TransportScheme) -> TransportScheme:
    """Make a transport available under its URI scheme (beside the transport's definition).

    Parameters
    ----------
    scheme : TransportScheme
        The entry, with its one-line ``description``.

    Returns
    -------
    TransportScheme
        The entry itself.

    Raises
    ------
    eelsim.registry.RegistryError
        When another transport has the scheme, or the entry has no description.
    """
    TRANSPORTS.add(scheme.name, scheme, scheme.description)
    return scheme


def transport_schemes() -> dict[str, TransportScheme]:
    """The registered schemes, by name (plug-ins included)."""
    return dict(TRANSPORTS.items())


def list_ports() -> list[Port]:
    """Every link the registered transports can open now, transport by transport.

    Returns
    -------
    list of Port
    """
    return [port for scheme in TRANSPORTS.values() for port in scheme.list_ports()]


def parse_link_uri(uri: str) -> LinkURI:
    """Split and check a link URI against the registered transports.

    Parameters
    ----------
    uri : str
        ``serial://PORT?baud=N``, ``sim://?...``, ``replay://PATH`` or another registered scheme.

    Returns
    -------
    LinkURI

    Raises
    ------
    LinkURIError
        Unknown scheme, missing port or path, unknown parameter, or a value the transport
        refuses (``sim://?seed=-3``).
    """
    text = str(uri).strip()
    examples = ", ".join(s.example.split("?")[0] for s in TRANSPORTS.values())
    if "://" not in text:
        raise LinkURIError(f"{text!r}: not a link URI (expected {examples})")
    parts = urlsplit(text)
    scheme = TRANSPORTS.get(parts.scheme)
    if scheme is None:
        raise LinkURIError(
            f"{text!r}: unknown scheme {parts.scheme!r} (expected {', '.join(TRANSPORTS)})"
        )
    target = parts.netloc + parts.path
    if scheme.target and not target:
        raise LinkURIError(f"{text!r}: no {scheme.target} after {scheme.name}://")
    if not scheme.target and target.strip("/"):
        raise LinkURIError(
            f"{text!r}: {scheme.name}:// takes no path ({target!r}); use parameters"
        )
    try:
        params = parse_qs(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError:
        raise LinkURIError(f"{text!r}: malformed parameters {parts.query!r}") from None
    for name in params:
        if name not in scheme.parameters:
            known = ", ".join(scheme.parameters) or "none"
            raise LinkURIError(
                f"{text!r}: unknown parameter {name!r} for {scheme.name}:// (known: {known})"
            )
    parsed = LinkURI(scheme.name, target, params, text)
    if scheme.check is not None:
        scheme.check(parsed)
    return parsed


def open_link(uri: str, robot: Robot | None = None, clock: Clock | None = None) -> Link:
    """Open the link a URI names, with the transport registered for its scheme.

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
        Opened. For ``sim://``, ``link.transport.robot`` is the virtual robot
        (:class:`eelhost.xil.virtual_robot.VirtualRobot`).

    Raises
    ------
    LinkURIError
        For a malformed URI.
    eelhost.link.base.TransportError
        When the port cannot be opened.
    eelhost.link.replay_transport.ReplayLogError
        For a missing replay log.
    """
    u = parse_link_uri(uri)
    link = TRANSPORTS[u.scheme].open(u, robot, clock)
    link.open()
    return link
