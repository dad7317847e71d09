"""The base of eelhost's user errors: input that cannot be used, as opposed to a bug.

Every module that rejects what a user gave it (a file, an option, a URI, a dataset) raises its own
subclass of :class:`UserError`, with a message that names what is wrong and where. The ``eelbot``
command line prints such a message on one line and exits with status 2 (as it does for eelsim's
``RobotFileError``, ``ScenarioError`` and ``TimingError``); any other exception is a bug and keeps
its traceback.

The subclasses also derive from ``ValueError`` (or ``ConnectionError`` for a transport), as they
did before this base existed, so callers that catch those still do.
"""

from __future__ import annotations

__all__ = ["UserError"]


class UserError(Exception):
    """Input that cannot be used; the message says what is wrong and where."""
