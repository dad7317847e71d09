"""The marker file: what was printed, for the localiser and the calibration to load.

``eelbot markers`` writes it beside the PDFs; ``eelbot calibrate``, ``run`` and ``campaign`` read it
with ``--markers`` (without it, the default layout and board). JSON::

    {"format": "eelbot-markers", "version": 1,
     "robot": {"dictionary": "DICT_4X4_50", "link_ids": [0, 1, 2, 3, 4, 5],
               "marker_size_m": 0.06, "margin_m": 0.005, "offsets_m": []},
     "board": {"squares": [7, 5], "square_m": 0.11, "marker_m": 0.08,
               "dictionary": "DICT_4X4_50", "first_id": 10}}

``robot`` is :class:`~eelhost.vision.markers.MarkerLayout` (link 1 = tail first), ``board`` the
ChArUco board (:class:`~eelhost.vision.calibration.CharucoSpec`). Loading checks every key and
names the file and the key of anything wrong, and refuses a board whose ids overlap the robot's
(the localiser would take a board marker for a link).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from eelhost.errors import UserError
from eelhost.files import atomic_write
from eelhost.vision.calibration import CharucoSpec
from eelhost.vision.markers import MarkerLayout, default_layout

__all__ = ["MarkerFile", "MarkerFileError", "load_marker_file", "save_marker_file"]

FORMAT = "eelbot-markers"
VERSION = 1


class MarkerFileError(UserError, ValueError):
    """A marker file that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class MarkerFile:
    """The robot's markers and the calibration board, as printed.

    Attributes
    ----------
    layout : MarkerLayout
        The markers on the links.
    board : CharucoSpec
        The ChArUco calibration board.
    """

    layout: MarkerLayout = field(default_factory=default_layout)
    board: CharucoSpec = field(default_factory=CharucoSpec)

    def __post_init__(self) -> None:
        n_board = self.board.squares[0] * self.board.squares[1] // 2
        board_ids = set(range(self.board.first_id, self.board.first_id + n_board))
        same_dictionary = self.board.dictionary_name == self.layout.dictionary_name
        clash = sorted(board_ids & set(self.layout.link_ids)) if same_dictionary else []
        if clash:
            raise MarkerFileError(f"the board's marker ids {clash} are also on the robot's links")

    def as_dict(self) -> dict[str, Any]:
        """The JSON content."""
        lay, b = self.layout, self.board
        return {
            "format": FORMAT,
            "version": VERSION,
            "robot": {
                "dictionary": lay.dictionary_name,
                "link_ids": list(lay.link_ids),
                "marker_size_m": lay.marker_size_m,
                "margin_m": lay.margin_m,
                "offsets_m": list(lay.offsets_m),
            },
            "board": {
                "squares": list(b.squares),
                "square_m": b.square_m,
                "marker_m": b.marker_m,
                "dictionary": b.dictionary_name,
                "first_id": b.first_id,
            },
        }


def save_marker_file(markers: MarkerFile, path: str | Path) -> Path:
    """Write the marker file (JSON); return its path."""
    return atomic_write(path, json.dumps(markers.as_dict(), indent=2) + "\n")


def _section(data: dict[str, Any], key: str, keys: set[str], source: str) -> dict[str, Any]:
    part = data.get(key)
    if not isinstance(part, dict):
        raise MarkerFileError(f"{source}: '{key}' must be an object")
    for k in part:
        if k not in keys:
            raise MarkerFileError(f"{source}: unknown key '{key}.{k}'")
    for k in keys:
        if k not in part:
            raise MarkerFileError(f"{source}: missing key '{key}.{k}'")
    return part


def load_marker_file(path: str | Path | None) -> MarkerFile:
    """Read a marker file; None gives the defaults (the paper robot's layout, the default board).

    Raises
    ------
    MarkerFileError
        When the file cannot be read or a key is missing, unknown or invalid (named).
    """
    if path is None:
        return MarkerFile()
    source = str(path)
    try:
        data = json.loads(Path(path).read_text())
    except OSError as err:
        raise MarkerFileError(f"{source}: cannot read marker file: {err.strerror}") from None
    except json.JSONDecodeError as err:
        raise MarkerFileError(f"{source}: not valid JSON: {err}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise MarkerFileError(f"{source}: 'format' must be {FORMAT!r}")
    if data.get("version") != VERSION:
        raise MarkerFileError(f"{source}: 'version' must be {VERSION}")
    for key in data:
        if key not in ("format", "version", "robot", "board"):
            raise MarkerFileError(f"{source}: unknown key '{key}'")
    r = _section(data, "robot", {"dictionary", "link_ids", "marker_size_m", "margin_m",
                                 "offsets_m"}, source)
    b = _section(data, "board", {"squares", "square_m", "marker_m", "dictionary", "first_id"},
                 source)
    try:
        layout = MarkerLayout(
            dictionary_name=str(r["dictionary"]),
            link_ids=tuple(int(i) for i in r["link_ids"]),
            marker_size_m=float(r["marker_size_m"]),
            margin_m=float(r["margin_m"]),
            offsets_m=tuple(float(v) for v in r["offsets_m"]),
        )
    except (TypeError, ValueError) as err:
        raise MarkerFileError(f"{source}: robot: {err}") from None
    try:
        sx, sy = (int(v) for v in b["squares"])
        board = CharucoSpec((sx, sy), float(b["square_m"]), float(b["marker_m"]),
                            str(b["dictionary"]), int(b["first_id"]))
    except (TypeError, ValueError) as err:
        raise MarkerFileError(f"{source}: board: {err}") from None
    try:
        return MarkerFile(layout, board)
    except MarkerFileError as err:
        raise MarkerFileError(f"{source}: {err}") from None
