"""Record a run as it happens, so that a crash at any moment leaves a readable experiment.

Three files share the stem ``<out>``:

- ``<out>.json``: the experiment metadata (``docs/data.md``), written atomically (temporary file +
  rename) before the first frame, again when the start pose is known and at the end with the
  outcome. ``source.recording.complete`` is false until the end.
- ``<out>.csv``: the experiment's frames (``t_s, x_m, y_m, heading_rad, theta_1..theta_N``), one
  line per frame that gave a pose, each appended in one write, flushed and fsynced. A writer
  killed mid-line leaves a last line without its newline;
  ``read_experiment(stem, allow_incomplete=True)`` drops it and keeps every complete row.
- ``<out>.frames.csv``: every camera frame, pose or not: ``t_s, status, markers`` (the
  localisation's status and how many markers it read), appended the same way; the measured frame
  rate and intervals go into the metadata's ``camera`` at the end.
- ``<out>.commands.csv``: the link's events, appended and flushed the same way:
  ``t_s, seq, message, fields, event`` where ``event`` is ``sent``, ``resent``, ``not_sent``,
  ``ack``, ``refused:<reason>``, ``lost``, ``disconnected`` or ``reconnected``; ``fields`` is the
  message's fields as JSON. Read it back with :func:`read_commands_csv`.

Times are seconds since the gait was started (the Start command), as the experiment format wants.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelhost.data.experiments import EXPERIMENT_FORMAT, _atomic_write
from eelhost.link.base import LinkEvent
from eelsim.scenario import Scenario

__all__ = ["COMMAND_COLUMNS", "FRAME_COLUMNS", "MOTIONS", "Recorder", "read_commands_csv",
           "take_paths"]

COMMAND_COLUMNS = ("t_s", "seq", "message", "fields", "event")
FRAME_COLUMNS = ("t_s", "status", "markers")
MOTIONS = ("auto", "straight", "turning", "path")
STRAIGHT_WITHIN_DEG = 10.0  # a lone waypoint this close to the start heading is a straight run


def take_paths(stem: str | Path) -> list[Path]:
    """Every file a take writes (the recorder's, the byte log and the copies beside them)."""
    suffixes = (".json", ".csv", ".frames.csv", ".commands.csv", ".rx.bin", ".robot.toml",
                ".calibration.json")
    return [Path(f"{stem}{suffix}") for suffix in suffixes]


def infer_motion(waypoints_m: list[tuple[float, float]], start_m: tuple[float, float],
                 heading_rad: float) -> str:
    """``path`` for several waypoints; for one, ``straight`` when it lies ahead, else ``turning``."""
    if len(waypoints_m) > 1:
        return "path"
    dx, dy = waypoints_m[0][0] - start_m[0], waypoints_m[0][1] - start_m[1]
    off = (np.arctan2(dy, dx) - heading_rad + np.pi) % (2 * np.pi) - np.pi
    return "straight" if abs(np.degrees(off)) <= STRAIGHT_WITHIN_DEG else "turning"


class Recorder:
    """Incremental writer of an experiment and its commands log.

    Parameters
    ----------
    stem : str or Path
        Output path without extension.
    scenario : Scenario
        The task (gait, gain, waypoints...); its start pose is replaced by the first pose seen.
    n_links : int
        Number of links (columns ``theta_1..theta_N``).
    camera, timing, source : dict
        Experiment metadata (``docs/data.md``).
    fsync : bool
        fsync every line (on by default: a power cut then loses at most the line being written).
    motion : str
        ``straight``, ``turning``, ``path``, or ``auto`` (decided at the first pose by
        :func:`infer_motion`).
    pixel_size_m : callable, optional
        ``pixel_size_m((x, y))``: the camera's pixel size there; at the end it is taken at the
        mean recorded position and written as ``camera.pixel_m``.
    """

    def __init__(
        self,
        stem: str | Path,
        scenario: Scenario,
        n_links: int,
        camera: dict[str, Any] | None = None,
        timing: dict[str, Any] | None = None,
        source: dict[str, Any] | None = None,
        fsync: bool = True,
        motion: str = "auto",
        pixel_size_m: Callable[[NDArray[np.float64]], float] | None = None,
    ) -> None:
        if motion not in MOTIONS:
            raise ValueError(f"motion must be one of {MOTIONS}, got {motion!r}")
        self.stem = Path(stem)
        self.csv_path = Path(f"{self.stem}.csv")
        self.json_path = Path(f"{self.stem}.json")
        self.commands_path = Path(f"{self.stem}.commands.csv")
        self.frames_path = Path(f"{self.stem}.frames.csv")
        self.n_links = n_links
        self.fsync = fsync
        self.frames = 0
        self.last_t_s = -float("inf")
        self._auto_motion = motion == "auto"
        self._waypoints = [(float(x), float(y)) for x, y in scenario.waypoints_m]
        self._pixel_size_m = pixel_size_m
        self._position_sum = np.zeros(2)
        self._frame_times: list[float] = []
        self._meta: dict[str, Any] = {
            "format": EXPERIMENT_FORMAT,
            "name": self.stem.name,
            "motion": ("path" if len(self._waypoints) > 1 else "turning") if self._auto_motion
            else motion,
            "scenario": scenario.model_dump(mode="json"),
            "camera": dict(camera or {}),
            "timing": dict(timing or {}),
            "source": {**(source or {}), "recording": {"complete": False}},
        }
        self._start_known = False
        _atomic_write(self.json_path, json.dumps(self._meta, indent=2) + "\n")
        self._csv = self._open_append(self.csv_path)
        header = ["t_s", "x_m", "y_m", "heading_rad"] + [f"theta_{i + 1}" for i in range(n_links)]
        self._append(self._csv, ",".join(header) + "\n")
        self._cmd = self._open_append(self.commands_path)
        self._append(self._cmd, ",".join(COMMAND_COLUMNS) + "\n")
        self._seen = self._open_append(self.frames_path)
        self._append(self._seen, ",".join(FRAME_COLUMNS) + "\n")

    @staticmethod
    def _open_append(path: Path) -> TextIO:
        path.parent.mkdir(parents=True, exist_ok=True)
        return open(path, "w", encoding="utf-8", newline="")  # noqa: SIM115 (open for the run)

    def _append(self, f: TextIO, line: str) -> None:
        # One write per line: a kill leaves at most one incomplete line, at the end.
        try:
            f.write(line)
            f.flush()
            if self.fsync:
                os.fsync(f.fileno())
        except OSError as err:  # a full disk: name the file (the command line says it in a line)
            if err.filename is None:
                raise OSError(err.errno, err.strerror, f.name) from err
            raise

    def frame(
        self, t_s: float, com_m: ArrayLike, heading_rad: float, link_angles_rad: ArrayLike
    ) -> bool:
        """Append one frame's pose.

        Parameters
        ----------
        t_s : float
            Time since the gait started, s.
        com_m : (float, float)
            Centre of mass.
        heading_rad : float
            Mean link angle.
        link_angles_rad : sequence of N floats
            Absolute link angles, tail first.

        Returns
        -------
        bool
            False (nothing written) when the row would break the format: a time not after the
            last one, or a value that is not finite.
        """
        com = np.asarray(com_m, dtype=float)
        values = [float(t_s), float(com[0]), float(com[1]), float(heading_rad)]
        values += [float(a) for a in np.asarray(link_angles_rad, dtype=float)]
        if len(values) != 4 + self.n_links:
            raise ValueError(f"expected {self.n_links} link angles, got {len(values) - 4}")
        if t_s <= self.last_t_s or not all(np.isfinite(values)):
            return False
        if not self._start_known:
            self._start_known = True
            if self._auto_motion:
                self._meta["motion"] = infer_motion(self._waypoints, (values[1], values[2]),
                                                    values[3])
            self.update_metadata(
                scenario={
                    "start_position_m": [values[1], values[2]],
                    "start_heading_deg": float(np.degrees(values[3])),
                }
            )
        self._append(self._csv, ",".join(f"{v:.9g}" for v in values) + "\n")
        self.last_t_s = float(t_s)
        self.frames += 1
        self._position_sum += values[1:3]
        return True

    def frame_seen(self, t_s: float, status: str, markers: int) -> None:
        """Append one camera frame's time and what the localisation made of it (every frame)."""
        self._frame_times.append(float(t_s))
        self._append(self._seen, f"{t_s:.6f},{status},{int(markers)}\n")

    def camera_timing(self) -> dict[str, Any]:
        """The frame rate and intervals measured from the frame times so far."""
        t = np.asarray(self._frame_times)
        if len(t) < 2 or not t[-1] > t[0]:
            return {"frames": int(len(t))}
        dt = np.diff(t)
        return {
            "frames": int(len(t)),
            "fps": float((len(t) - 1) / (t[-1] - t[0])),
            "frame_interval_s": {"mean": float(dt.mean()), "std": float(dt.std()),
                                 "max": float(dt.max())},
        }

    def command(self, t_s: float, event: LinkEvent) -> None:
        """Append one link event (``t_s`` since the gait started; the event's own time is not)."""
        msg = event.message
        fields = "" if msg is None else json.dumps(_fields(msg), separators=(",", ":"))
        name = "" if msg is None else type(msg).__name__
        kind = event.kind if event.kind != "refused" else f"refused:{event.detail}"
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow(
            [f"{t_s:.6f}", event.seq, name, fields, kind]
        )
        self._append(self._cmd, buf.getvalue())

    def update_metadata(self, **sections: dict[str, Any]) -> None:
        """Merge keys into top-level sections of the JSON and rewrite it atomically."""
        for key, upd in sections.items():
            if isinstance(self._meta.get(key), dict):
                self._meta[key].update(upd)
            else:
                self._meta[key] = upd
        _atomic_write(self.json_path, json.dumps(self._meta, indent=2) + "\n")

    def close(self, outcome: dict[str, Any] | None = None) -> None:
        """Write the outcome and the measured facts into the metadata and close the files.

        ``source.recording`` gets the outcome and ``complete: true``; ``camera`` the measured frame
        rate (``fps``, from the frame times; the nominal one stays as ``fps_nominal``) and the pixel
        size at the mean recorded position; ``scenario.duration_s`` becomes the time the run
        lasted (the last frame's).
        """
        rec = {**self._meta["source"]["recording"], "complete": True, "frames": self.frames}
        rec.update(outcome or {})
        timing = self.camera_timing()
        camera: dict[str, Any] = {}
        if "fps" in timing:
            nominal = self._meta["camera"].get("fps")
            if nominal is not None and "fps_nominal" not in self._meta["camera"]:
                camera["fps_nominal"] = nominal
            camera["fps"] = timing["fps"]
            camera["frame_interval_s"] = timing["frame_interval_s"]
        camera["frames"] = timing["frames"]
        if self._pixel_size_m is not None and self.frames:
            camera["pixel_m"] = float(self._pixel_size_m(self._position_sum / self.frames))
        scenario = {}
        if self._frame_times and self._frame_times[-1] > 0:
            scenario["duration_s"] = float(self._frame_times[-1])
        self.update_metadata(source={"recording": rec}, camera=camera, scenario=scenario)
        for f in (self._csv, self._cmd, self._seen):
            if not f.closed:
                f.close()


def _fields(msg: Any) -> dict[str, Any]:
    out = {}
    for f in dataclasses.fields(msg):
        v = getattr(msg, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def read_commands_csv(path: str | Path) -> list[dict[str, Any]]:
    """Read a commands log, tolerating a last line cut by a crash.

    Parameters
    ----------
    path : str or Path
        ``<out>.commands.csv``.

    Returns
    -------
    list of dict
        One per complete row: ``t_s`` (float), ``seq`` (int), ``message`` (str), ``fields``
        (dict, empty when none) and ``event`` (str).
    """
    text = Path(path).read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # the line being written when the writer died
    rows = list(csv.reader(io.StringIO(text)))
    out = []
    for row in rows[1:]:
        if len(row) != len(COMMAND_COLUMNS):
            continue
        out.append(
            {
                "t_s": float(row[0]),
                "seq": int(row[1]),
                "message": row[2],
                "fields": json.loads(row[3]) if row[3] else {},
                "event": row[4],
            }
        )
    return out
