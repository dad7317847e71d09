"""The link to the robot: transports chosen by a URI, framed messages on top (see ``uri.py``)."""

from eelhost.link.base import (
    Clock,
    Link,
    LinkCounters,
    LinkEvent,
    Transport,
    TransportError,
    WallClock,
)
from eelhost.link.uri import LinkURIError, open_link, parse_link_uri

__all__ = [
    "Clock",
    "Link",
    "LinkCounters",
    "LinkEvent",
    "LinkURIError",
    "Transport",
    "TransportError",
    "WallClock",
    "open_link",
    "parse_link_uri",
]
