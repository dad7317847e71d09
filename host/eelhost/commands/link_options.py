"""``--link URI`` and ``--robot FILE``: how the commands that talk to a robot name it and its file.

Every command spells the robot file ``--robot FILE``; ``eelbot run``, ``campaign`` and ``robot``
name the link to the robot (a URI: ``serial://``, ``sim://``, ``replay://``) with ``--link URI``.

Until this release these three commands spelled the link ``--robot URI`` and the robot file
``--robot-file FILE``. Both old spellings are still accepted in this release and go in the next,
each with a deprecation message on stderr: a ``--robot`` value that is a link URI (it contains ``://``, which
no robot file's path does) is taken as ``--link``, and ``--robot-file FILE`` as ``--robot FILE``
(docs/cli.md, "Deprecated spellings").
"""

from __future__ import annotations

import argparse

from eelhost import progress
from eelhost.commands.common import OptionError
from eelhost.link.uri import transport_schemes

__all__ = ["add_link_options", "add_robot_file_option", "is_link_uri", "link_examples",
           "resolve_link_options", "resolve_robot_file_option"]

ROBOT_FILE_HELP = "robot TOML file (default: the bundled paper robot)"


def link_examples() -> str:
    """An example URI of every registered transport, for help texts and messages.

    Read from the transport registry (:func:`eelhost.link.uri.transport_schemes`) when asked, so
    a transport added later is shown too; docs/host.md lists every scheme's parameters.
    """
    return ", ".join(scheme.example for scheme in transport_schemes().values())


def is_link_uri(value: str) -> bool:
    """Whether an option's value is a link URI (``scheme://...``) rather than a file's path."""
    scheme, sep, _rest = value.partition("://")
    return bool(sep) and scheme.isidentifier()


def add_robot_file_option(p: argparse.ArgumentParser, help_text: str = ROBOT_FILE_HELP) -> None:
    """``--robot FILE``, with the deprecated ``--robot-file FILE`` still accepted (not shown)."""
    p.add_argument("--robot", metavar="FILE", dest="robot_file", help=help_text)
    p.add_argument("--robot-file", metavar="FILE", dest="robot_file_deprecated",
                   help=argparse.SUPPRESS)


def add_link_options(p: argparse.ArgumentParser, link_note: str = "",
                     robot_help: str = ROBOT_FILE_HELP) -> None:
    """``--link URI`` and ``--robot FILE`` (:func:`resolve_link_options` reads the old spellings).

    ``link_note`` is added to the link's help, after the registered transports' examples.
    """
    note = f"; {link_note}" if link_note else ""
    p.add_argument("--link", metavar="URI", help="the link to the robot, a URI such as "
                   f"{link_examples()}; eelbot ports lists the links that can be opened now{note}")
    add_robot_file_option(p, robot_help
                          + "; the old spelling --robot URI still names the link (deprecated)")


def _warn(args: argparse.Namespace, text: str) -> None:
    command = getattr(args, "command", None)
    progress.message(f"eelbot{' ' + command if command else ''}: warning: {text}")


def resolve_robot_file_option(args: argparse.Namespace) -> None:
    """Fold the deprecated ``--robot-file`` into ``args.robot_file`` (saying so on stderr).

    Raises
    ------
    OptionError
        When the robot file is given both ways.
    """
    old = getattr(args, "robot_file_deprecated", None)
    if old is None:
        return
    if args.robot_file is not None:
        raise OptionError(f"--robot-file {old}: the robot file is given twice (--robot "
                          f"{args.robot_file} too); give it once, as --robot FILE")
    _warn(args, f"--robot-file is deprecated and goes in the next release: write --robot {old}")
    args.robot_file = old


def resolve_link_options(args: argparse.Namespace, required: str | None = None) -> None:
    """Read the new and the deprecated spellings into ``args.link`` and ``args.robot_file``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed with :func:`add_link_options`; changed in place.
    required : str, optional
        When given, a missing link is an error, and this ends its message (what needs it).

    Raises
    ------
    OptionError
        When the link is given both ways, or is missing and required.
    """
    value = args.robot_file
    if value is not None and is_link_uri(value):
        if args.link is not None:
            raise OptionError(f"--robot {value}: a link URI, but --link {args.link} is given too; "
                              "give the link once, as --link URI (--robot names the robot file)")
        _warn(args, f"--robot URI is deprecated and goes in the next release: write --link "
              f"{value} (--robot now names the robot file, as in every other command)")
        args.link, args.robot_file = value, None
    resolve_robot_file_option(args)
    if args.link is None and required is not None:
        raise OptionError(f"--link: required {required} (a URI: {link_examples()})")
