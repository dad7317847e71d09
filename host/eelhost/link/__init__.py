"""The link to the robot: transports chosen by a URI, one framed session on top (see ``uri.py``).

Importing the package registers the bundled transports (serial, sim, replay); a new transport is
a module here that calls :func:`eelhost.link.uri.register_transport`, imported below.
"""

from eelhost.link import replay_transport, serial_transport, sim_transport  # register schemes
from eelhost.link.base import (
    Clock,
    Link,
    LinkCounters,
    LinkEvent,
    Transport,
    TransportError,
    WallClock,
)
from eelhost.link.uri import (
    LinkURIError,
    Port,
    list_ports,
    open_link,
    parse_link_uri,
    register_transport,
)

__all__ = [
    "Clock",
    "Link",
    "LinkCounters",
    "LinkEvent",
    "LinkURIError",
    "Port",
    "Transport",
    "TransportError",
    "WallClock",
    "list_ports",
    "open_link",
    "parse_link_uri",
    "register_transport",
    "replay_transport",
    "serial_transport",
    "sim_transport",
]
