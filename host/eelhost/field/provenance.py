"""Where a recording came from: software version, git commit, date, and the robot file's text.

Recorded in every take's metadata (``source.run``, docs/data.md), so a dataset says which code and
which robot made it.
"""

from __future__ import annotations

import datetime
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

from eelsim.robot import robot_file_text

__all__ = ["robot_file_text", "software"]

PACKAGE_DIR = Path(__file__).resolve().parent


def _git(*args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(PACKAGE_DIR), *args], capture_output=True,
                              text=True, timeout=5, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def software() -> dict[str, Any]:
    """What software made a recording, and when.

    Returns
    -------
    dict
        ``eelbot_version``, ``git_commit`` (None outside a clone), ``git_dirty`` (tracked files
        changed) and ``date`` (local time with its offset, ISO 8601).
    """
    try:
        version = metadata.version("eelbot")
    except metadata.PackageNotFoundError:
        version = None
    commit = _git("rev-parse", "HEAD")
    status = _git("status", "--porcelain", "--untracked-files=no") if commit else None
    return {
        "eelbot_version": version,
        "git_commit": commit,
        "git_dirty": bool(status) if status is not None else None,
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
    }
