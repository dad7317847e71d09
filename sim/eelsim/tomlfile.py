"""Reading validated TOML files with errors that name the file and the key.

Robot files, scenario files and planning worlds are all TOML validated by pydantic; they share the
way they fail: ``<file>: cannot read ...``, ``<file>: not valid TOML: ...`` or
``<file>: invalid <what>:`` followed by one line per wrong key, dotted (``link.mass_kg``).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError


def read_toml(path: str | Path, error: type[Exception], what: str) -> dict[str, Any]:
    """Read a TOML file, raising ``error`` that names the file when it cannot be read or parsed.

    Parameters
    ----------
    path : str or Path
    error : exception class
        Raised with the message.
    what : str
        What the file is ("robot file", "scenario file", ...).

    Returns
    -------
    dict
    """
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as err:
        raise error(f"{p}: cannot read {what}: {err.strerror}") from None
    return parse_toml(text, str(p), error)


def parse_toml(text: str, source: str, error: type[Exception]) -> dict[str, Any]:
    """Parse TOML text, raising ``error`` naming ``source`` when it is not valid TOML."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise error(f"{source}: not valid TOML: {err}") from None


def validation_message(
    source: str, err: ValidationError, what: str, show_values: bool = True
) -> str:
    """A pydantic error as ``<source>: invalid <what>:`` and one line per key.

    Parameters
    ----------
    source : str
        The file (or other origin).
    err : ValidationError
    what : str
        What was being validated ("robot description", "scenario", "world").
    show_values : bool
        Append the offending value to each line.

    Returns
    -------
    str
    """
    lines = [f"{source}: invalid {what}:"]
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(top level)"
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = f"unknown key (not part of the {what})"
        value = e.get("input")
        shown = (
            f" (got {value!r})"
            if show_values and not isinstance(value, dict) and e["type"] != "missing"
            else ""
        )
        lines.append(f"  {loc}: {msg}{shown}")
    return "\n".join(lines)
