"""``eelbot ports``: the links the registered transports can open now, as URIs for ``--link``."""

from __future__ import annotations

import argparse

from eelhost.commands import COMMANDS
from eelhost.link import list_ports
from eelhost.link.uri import transport_schemes


@COMMANDS.add("ports", "list the links eelbot run can open (serial ports, the virtual robot)")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "ports",
        help=COMMANDS.description("ports"),
        description="List, transport by transport, the links that can be opened now, as URIs "
        "for `eelbot run --link`, and the URI schemes known.",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    for port in list_ports():
        print(f"{port.uri}\t{port.description}")
    schemes = ", ".join(s.example for s in transport_schemes().values())
    print(f"URI schemes: {schemes}")
    return 0
