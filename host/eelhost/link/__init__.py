"""The link to the robot: transports chosen by a URI, one framed session on top (see ``uri.py``).

Every module of this package named ``*_transport`` is imported here, and registers its URI
scheme with :func:`eelhost.link.uri.register_transport` when it is: adding a transport is adding
such a module (see docs/architecture.md).
"""

import importlib
import pkgutil

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

for _module in pkgutil.iter_modules(__path__):
    if _module.name.endswith("_transport"):
        importlib.import_module(f"{__name__}.{_module.name}")

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
