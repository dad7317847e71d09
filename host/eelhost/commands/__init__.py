"""Subcommands of the eelbot command line, one module each, in the registry :data:`COMMANDS`.

A subcommand's module registers its ``add_parser(subparsers)`` beside its definition, with the
one line ``eelbot --help`` shows (:mod:`eelsim.registry`)::

    @COMMANDS.add("ports", "list the links eelbot run can open")
    def add_parser(sub):
        p = sub.add_parser("ports", help=COMMANDS.description("ports"), ...)
        p.set_defaults(run=run)

Every module of this package is imported on the first lookup, so adding a subcommand is adding
its module: no list to edit. Another package adds its own through the ``eelbot.commands``
entry-point group, naming such an ``add_parser`` (docs/architecture.md, "Extension points").
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

from eelsim.registry import Registry, import_package_modules

AddParser = Callable[[argparse._SubParsersAction], None]
"""``add_parser(subparsers)``: adds the subcommand's parser, whose ``run`` default runs it."""


def _import_commands() -> None:
    """Import every module of this package: their definitions register the subcommands."""
    import_package_modules(__name__, __path__)


COMMANDS: Registry[AddParser] = Registry(
    "command", "eelbot.commands", builtins=_import_commands
)
"""The subcommands, by name: each one's ``add_parser`` and one-line help."""

__all__ = ["COMMANDS", "AddParser"]
