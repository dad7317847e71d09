"""The link to the robot: transports chosen by a URI, one framed session on top (see ``uri.py``).

Every module of this package named ``*_transport`` is imported here, and registers its URI
scheme with :func:`eelhost.link.uri.register_transport` when it is: adding a transport is adding
such a module (see docs/architecture.md).
"""

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
from eelsim.registry import import_package_modules

import_package_modules(__name__, __path__, suffix="_transport")

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
]
