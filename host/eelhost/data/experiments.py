"""Recorded experiments and datasets on disk (see ``docs/data.md``).

One experiment is two files with the same stem:

- ``<name>.csv``: a header line, then one row per camera frame. Required columns ``t_s, x_m, y_m``
  (time since the gait started, centre of mass); optional ``heading_rad`` and the absolute link
  angles ``theta_1 .. theta_N`` (link 1 = tail). Every value a finite number; time strictly
  increasing.
- ``<name>.json``: metadata: format tag, the task (gait, gain, waypoints, acceptance radius, current,
  duration, start pose: the keys of :class:`eelsim.scenario.Scenario`), the motion type, the camera
  and timing facts, and where the data came from.

A dataset is a folder with ``manifest.toml`` naming the robot file, the training and testing
experiments of each motion type, and the multi-waypoint paths used for validation.

Every reader refuses malformed input with the file, line and column; writers write to a temporary
file and rename it, so a crash never leaves half an experiment behind.
"""

from __future__ import annotations

import csv
import json
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from eelhost.errors import UserError
from eelhost.files import atomic_write
from eelsim.camera import MEDIAN_PLACEMENTS, CameraModel
from eelsim.fluid import FluidCoefficients, get_fluid_law
from eelsim.robot import (
    BUNDLED_ROBOTS,
    HydroCoefficients,
    Robot,
    RobotFileError,
    load_robot,
    parse_robot,
)
from eelsim.scenario import Scenario
from eelsim.tomlfile import parse_toml

EXPERIMENT_FORMAT = "eelbot-experiment/1"
DATASET_FORMAT = "eelbot-dataset/1"
REQUIRED_COLUMNS = ("t_s", "x_m", "y_m")
COLUMN_ALIASES = {"t": "t_s", "time": "t_s", "x": "x_m", "y": "y_m", "heading": "heading_rad"}


# The repository's bundled virtual-tank dataset (this file is host/eelhost/data/experiments.py).
BUNDLED_DATASET = Path(__file__).resolve().parents[3] / "datasets" / "paper_virtual_tank"


class DataError(UserError, ValueError):
    """A malformed experiment, CSV or dataset; the message says where (file, line, column)."""


@dataclass
class Experiment:
    """One recorded run of the robot.

    Attributes
    ----------
    name : str
        Identifier (the file stem).
    t_s : ndarray, shape (K,)
        Frame times, s, strictly increasing.
    position_m : ndarray, shape (K, 2)
        Centre of mass per frame.
    heading_rad : ndarray or None, shape (K,)
        Heading per frame, if recorded.
    link_angles_rad : ndarray or None, shape (K, N)
        Absolute link angles per frame, if recorded.
    scenario : Scenario
        The task the robot was given (gait, gain, waypoints, current...).
    motion : str
        Motion type: "straight", "turning" or "path".
    camera : dict
        Camera facts (docs/data.md): ``fps`` (absent: measured from the frame times),
        ``pixel_m``, ``median_window``, ``median`` ("causal", the default, or "centred"),
        ``timestamp_jitter_s``; :meth:`recording_camera` reads them.
    timing : dict
        Loop facts: control_period_s, extra_delay_s, jitter_s.
    source : dict
        Where the data came from (a virtual tank records its truth and seed here).
    """

    name: str
    t_s: np.ndarray
    position_m: np.ndarray
    scenario: Scenario
    motion: str = "straight"
    heading_rad: np.ndarray | None = None
    link_angles_rad: np.ndarray | None = None
    camera: dict[str, Any] = field(default_factory=dict)
    timing: dict[str, Any] = field(default_factory=dict)
    source: dict[str, Any] = field(default_factory=dict)

    @property
    def span_s(self) -> tuple[float, float]:
        """First and last frame times."""
        return float(self.t_s[0]), float(self.t_s[-1])

    def recording_camera(self) -> CameraModel:
        """The camera that recorded the frames, as declared (docs/data.md).

        ``fps`` absent means a real camera's measured rate: one over the median frame interval.
        ``median`` absent reads as "causal" (what recordings made before the field did).

        Raises
        ------
        DataError
            For a declared value the camera model refuses, naming the experiment and the key.
        """
        cam = self.camera
        try:
            fps = float(cam["fps"]) if "fps" in cam else 1.0 / float(np.median(np.diff(self.t_s)))
            return CameraModel(
                fps=fps,
                pixel_m=float(cam.get("pixel_m", 0.0038)),
                median_window=int(cam.get("median_window", 5)),
                median=str(cam.get("median", "causal")),
            )
        except (TypeError, ValueError) as err:
            raise DataError(f"{self.name}: camera: {err}") from None

    @property
    def timestamp_jitter_s(self) -> float:
        """Half-width of the recording's clock offset (its time stamps' uncertainty)."""
        return float(self.camera.get("timestamp_jitter_s", 0.1))

    def position_at(self, times_s: np.ndarray) -> np.ndarray:
        """Centre of mass linearly interpolated at ``times_s`` (inside the recorded span)."""
        t = np.asarray(times_s, dtype=float)
        return np.column_stack(
            [
                np.interp(t, self.t_s, self.position_m[:, 0]),
                np.interp(t, self.t_s, self.position_m[:, 1]),
            ]
        )


def _atomic_write(path: Path, text: str) -> None:
    atomic_write(path, text)  # readable by the group as the umask says (eelhost.files)


def experiment_csv_text(exp: Experiment) -> str:
    """The CSV text of an experiment's frames."""
    cols = ["t_s", "x_m", "y_m"]
    data = [exp.t_s, exp.position_m[:, 0], exp.position_m[:, 1]]
    if exp.heading_rad is not None:
        cols.append("heading_rad")
        data.append(exp.heading_rad)
    if exp.link_angles_rad is not None:
        cols += [f"theta_{i + 1}" for i in range(exp.link_angles_rad.shape[1])]
        data += list(exp.link_angles_rad.T)
    table = np.column_stack(data)
    lines = [",".join(cols)] + [",".join(f"{v:.9g}" for v in row) for row in table]
    return "\n".join(lines) + "\n"


def write_experiment(exp: Experiment, folder: str | Path) -> tuple[Path, Path]:
    """Write ``<folder>/<name>.csv`` and ``.json`` atomically; return both paths."""
    folder = Path(folder)
    csv_path, json_path = folder / f"{exp.name}.csv", folder / f"{exp.name}.json"
    meta = {
        "format": EXPERIMENT_FORMAT,
        "name": exp.name,
        "motion": exp.motion,
        "scenario": exp.scenario.model_dump(),
        "camera": exp.camera,
        "timing": exp.timing,
        "source": exp.source,
    }
    _atomic_write(csv_path, experiment_csv_text(exp))
    _atomic_write(json_path, json.dumps(meta, indent=2) + "\n")
    return csv_path, json_path


@dataclass
class FrameTable:
    """Columns read from a tracker CSV."""

    t_s: np.ndarray
    position_m: np.ndarray
    heading_rad: np.ndarray | None
    link_angles_rad: np.ndarray | None


def read_frames_csv(path: str | Path, allow_truncated_tail: bool = False) -> FrameTable:
    """Read and check a frames CSV (``t_s, x_m, y_m`` [, ``heading_rad``, ``theta_i``...]).

    Column names may also be ``t``, ``time``, ``x``, ``y``, ``heading``. Unknown columns are refused.

    Parameters
    ----------
    path : str or Path
    allow_truncated_tail : bool
        Read a file whose writer was killed mid-line (``eelhost.field.recorder`` appends a line per
        frame): a last line without its newline is incomplete, whatever it looks like, and is
        dropped; every complete row is kept. Off by default: a finished file must end cleanly.

    Returns
    -------
    FrameTable

    Raises
    ------
    DataError
        Naming the file, line and column of the first problem found.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise DataError(f"{path}: cannot read: {err.strerror}") from None
    if text and not text.endswith("\n"):
        if not allow_truncated_tail:  # a finished file ends with a newline; this one may be cut
            raise DataError(
                f"{path}:{text.count(chr(10)) + 1}: the last line has no newline, so the file "
                "may be cut mid-number (a writer stopped); if the line is whole, end it with a "
                "newline"
            )
        text = text[: text.rfind("\n") + 1]
    rows = list(csv.reader(text.splitlines()))
    if not rows or not any(c.strip() for c in rows[0]):
        raise DataError(f"{path}:1: empty file: expected a header line with t_s,x_m,y_m")
    header = [COLUMN_ALIASES.get(c.strip(), c.strip()) for c in rows[0]]
    for col, name in enumerate(header, start=1):
        known = name in (*REQUIRED_COLUMNS, "heading_rad") or (
            name.startswith("theta_") and name[6:].isdigit()
        )
        if not known:
            raise DataError(
                f"{path}:1:{col}: unknown column {name!r} (expected t_s, x_m, y_m, heading_rad, theta_1..)"
            )
    for req in REQUIRED_COLUMNS:
        if req not in header:
            raise DataError(f"{path}:1: missing required column {req!r}")
    if len(set(header)) != len(header):
        raise DataError(f"{path}:1: a column name appears twice")
    values = np.empty((len(rows) - 1, len(header)))
    for i, row in enumerate(rows[1:]):
        line = i + 2
        if len(row) != len(header):
            raise DataError(f"{path}:{line}: expected {len(header)} fields, found {len(row)}")
        for col, cell in enumerate(row):
            try:
                v = float(cell)
            except ValueError:
                raise DataError(
                    f"{path}:{line}:{col + 1}: {header[col]} is not a number: {cell!r}"
                ) from None
            if not math.isfinite(v):
                raise DataError(f"{path}:{line}:{col + 1}: {header[col]} is not finite: {cell!r}")
            values[i, col] = v
    if values.shape[0] < 2:
        raise DataError(f"{path}: needs at least two frames, found {values.shape[0]}")
    t = values[:, header.index("t_s")]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        line = int(bad[0]) + 3
        raise DataError(
            f"{path}:{line}:{header.index('t_s') + 1}: time does not increase ({t[bad[0] + 1]:g} after {t[bad[0]]:g})"
        )
    theta_cols = sorted((c for c in header if c.startswith("theta_")), key=lambda c: int(c[6:]))
    return FrameTable(
        t_s=t,
        position_m=values[:, [header.index("x_m"), header.index("y_m")]],
        heading_rad=values[:, header.index("heading_rad")] if "heading_rad" in header else None,
        link_angles_rad=values[:, [header.index(c) for c in theta_cols]] if theta_cols else None,
    )


def read_experiment(csv_or_stem: str | Path, allow_incomplete: bool = False) -> Experiment:
    """Read an experiment from ``<stem>.csv`` and ``<stem>.json``.

    A recording made by ``eelbot run`` says in ``source.recording.complete`` whether it was closed
    (docs/data.md): one still false was cut short (the recorder was killed, the power went) and is
    refused unless ``allow_incomplete``, which also drops the line its writer may have left
    half-written (:func:`read_frames_csv`'s ``allow_truncated_tail``).

    Parameters
    ----------
    csv_or_stem : str or Path
        ``<stem>``, ``<stem>.csv`` or ``<stem>.json``.
    allow_incomplete : bool
        Read a recording that was never closed, keeping every complete row.

    Raises
    ------
    DataError
        For a missing, malformed or inconsistent file, naming it (and the line and column), and
        for an incomplete recording without ``allow_incomplete``.
    """
    # Names may contain dots (straight_A0.61_w2.7), so suffixes are added, never replaced.
    stem = str(csv_or_stem)
    for ext in (".csv", ".json"):
        stem = stem.removesuffix(ext)
    json_path = Path(stem + ".json")
    try:
        meta = json.loads(json_path.read_text())
    except OSError as err:
        raise DataError(f"{json_path}: cannot read: {err.strerror}") from None
    except json.JSONDecodeError as err:
        raise DataError(
            f"{json_path}:{err.lineno}:{err.colno}: not valid JSON: {err.msg}"
        ) from None
    if not isinstance(meta, dict) or meta.get("format") != EXPERIMENT_FORMAT:
        raise DataError(f"{json_path}: format: expected {EXPERIMENT_FORMAT!r}")
    if not allow_incomplete and not recording_complete(meta):
        raise DataError(
            f"{json_path}: incomplete recording (source.recording.complete is false: the "
            "recorder did not close it, it was killed or lost power); re-record it, or use it "
            "as it is with --allow-incomplete"
        )
    frames = read_frames_csv(Path(stem + ".csv"), allow_truncated_tail=allow_incomplete)
    try:
        scenario = Scenario.model_validate(meta.get("scenario"))
    except ValidationError as err:
        e = err.errors()[0]
        loc = ".".join(str(p) for p in e["loc"])
        raise DataError(f"{json_path}: scenario.{loc}: {e['msg']}") from None
    motion = meta.get("motion", "straight")
    if motion not in ("straight", "turning", "path"):
        raise DataError(f"{json_path}: motion: expected straight, turning or path, got {motion!r}")
    _check_camera(meta.get("camera", {}), json_path)
    return Experiment(
        name=meta.get("name", Path(stem).name),
        t_s=frames.t_s,
        position_m=frames.position_m,
        heading_rad=frames.heading_rad,
        link_angles_rad=frames.link_angles_rad,
        scenario=scenario,
        motion=motion,
        camera=dict(meta.get("camera", {})),
        timing=dict(meta.get("timing", {})),
        source=dict(meta.get("source", {})),
    )


def recording_complete(meta: dict[str, Any]) -> bool:
    """Whether an experiment's metadata says it is whole.

    Only a recording of ``eelbot run`` carries ``source.recording``; anything else (a virtual tank,
    an imported tracker file) is whole by construction.
    """
    source = meta.get("source")
    recording = source.get("recording") if isinstance(source, dict) else None
    if not isinstance(recording, dict):
        return True
    return recording.get("complete") is True


# The camera declaration's fields and what each must be (other keys are kept, unread).
_CAMERA_NUMBERS = {"fps": "> 0", "pixel_m": ">= 0", "timestamp_jitter_s": ">= 0"}


def _check_camera(camera: Any, where: Path) -> None:
    """Refuse a camera declaration the estimator cannot use, naming the key."""
    if not isinstance(camera, dict):
        raise DataError(f"{where}: camera: expected a table of camera facts")
    for key, rule in _CAMERA_NUMBERS.items():
        if key not in camera:
            continue
        v = camera[key]
        ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        if not ok or (v <= 0 if rule == "> 0" else v < 0):
            raise DataError(f"{where}: camera.{key}: expected a number {rule}, got {v!r}")
    window = camera.get("median_window", 5)
    if not isinstance(window, int) or isinstance(window, bool) or window < 1:
        raise DataError(f"{where}: camera.median_window: expected a whole number >= 1, got {window!r}")
    median = camera.get("median", "causal")
    if median not in MEDIAN_PLACEMENTS:
        raise DataError(
            f"{where}: camera.median: expected one of {', '.join(MEDIAN_PLACEMENTS)}, got {median!r}"
        )


def import_tracker_csv(
    csv_path: str | Path,
    scenario: Scenario,
    motion: str,
    out_folder: str | Path,
    name: str | None = None,
    camera: dict[str, Any] | None = None,
    timing: dict[str, Any] | None = None,
) -> Experiment:
    """Import a user's tracker CSV as an experiment (all checked before anything is written).

    Parameters
    ----------
    csv_path : str or Path
        Tracker output with columns t_s, x_m, y_m (or t, x, y) and optional heading and link angles.
    scenario : Scenario
        The task the robot was given in that run.
    motion : str
        "straight", "turning" or "path".
    out_folder : str or Path
        Where to write the experiment.
    name : str, optional
        Experiment name (default: the CSV's stem).
    camera, timing : dict, optional
        Camera and loop facts to record.

    Returns
    -------
    Experiment
    """
    frames = read_frames_csv(csv_path)
    exp = Experiment(
        name=name or Path(csv_path).stem,
        t_s=frames.t_s,
        position_m=frames.position_m,
        heading_rad=frames.heading_rad,
        link_angles_rad=frames.link_angles_rad,
        scenario=scenario,
        motion=motion,
        camera=camera or {},
        timing=timing or {},
        source={"imported_from": str(csv_path)},
    )
    write_experiment(exp, out_folder)
    return exp


@dataclass
class Dataset:
    """A folder of experiments with a manifest.

    Attributes
    ----------
    folder : Path
    robot : Robot
        The robot the experiments were run with.
    train, test : dict[str, list[Experiment]]
        Per motion type ("straight", "turning").
    paths : list[Experiment]
        Multi-waypoint validation runs.
    truth : dict[str, FluidCoefficients]
        For virtual tanks: the coefficients the data was generated with, per motion type.
    manifest : dict
        The manifest as read.
    plant : dict
        For virtual tanks: what their physics were (fluid law, joints, mismatch knobs).
    """

    folder: Path
    robot: Robot
    train: dict[str, list[Experiment]]
    test: dict[str, list[Experiment]]
    paths: list[Experiment]
    truth: dict[str, FluidCoefficients]
    manifest: dict[str, Any]
    plant: dict[str, Any] = field(default_factory=dict)

    @property
    def held_out(self) -> list[Experiment]:
        """Every experiment validation predicts: the test experiments of each motion, then the paths."""
        return [e for exps in self.test.values() for e in exps] + list(self.paths)


def manifest_text(
    robot_file: str,
    motions: dict[str, dict[str, list[str]]],
    paths: list[str],
    truth: dict[str, FluidCoefficients] | None = None,
    description: str = "",
    plant: dict[str, Any] | None = None,
) -> str:
    """Render a dataset manifest (TOML; docs/data.md).

    ``truth`` (a virtual tank's coefficients per motion type) is written by name with its law;
    ``plant`` (what the virtual tank's physics were: numbers, strings and booleans by name)
    as its own table.
    """

    def names(xs: list[str]) -> str:
        return "[" + ", ".join(f'"{x}"' for x in xs) + "]"

    lines = [
        f'format = "{DATASET_FORMAT}"',
        f'description = "{description}"',
        f'robot = "{robot_file}"',
        "",
    ]
    for motion, split in motions.items():
        lines += [
            f"[motions.{motion}]",
            f"train = {names(split['train'])}",
            f"test = {names(split['test'])}",
            "",
        ]
    lines += ["[validation]", f"paths = {names(paths)}", ""]
    for motion, c in (truth or {}).items():
        lines.append(f"[truth.{motion}]  # the coefficients the data was generated with")
        lines.append(f'law = "{type(c).law_name}"')
        lines += [f"{n} = {v!r}" for n, v in zip(c.names(), c.as_array().tolist(), strict=True)]
        lines.append("")
    if plant:
        lines.append("[plant]  # the virtual tank's physics (what the fitted model may not contain)")
        lines += [f"{k} = {_toml_scalar(v)}" for k, v in plant.items()]
        lines.append("")
    return "\n".join(lines).rstrip("\n") + "\n"


def _toml_scalar(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    return repr(float(v)) if isinstance(v, float) else repr(v)


def write_manifest(folder: str | Path, text: str) -> Path:
    """Write ``manifest.toml`` atomically."""
    path = Path(folder) / "manifest.toml"
    _atomic_write(path, text)
    return path


def _dataset_robot(folder: Path, robot_ref: Any, mpath: Path) -> Robot:
    """The dataset's robot: a file in its folder, or a bundled robot it names.

    Never the working folder's robot.toml: a dataset validated silently against another robot's
    file gave wrong figures with no error (docs/data.md, "A dataset").
    """
    bundled = ", ".join(BUNDLED_ROBOTS)
    if robot_ref is None:
        if not (folder / "robot.toml").exists():
            raise DataError(
                f"{mpath}: robot: the manifest names no robot file and {folder} holds no "
                f"robot.toml; name one (a file in the dataset folder, or bundled: {bundled})"
            )
        robot_ref = "robot.toml"
    if not isinstance(robot_ref, str) or not robot_ref:
        raise DataError(f"{mpath}: robot: expected a file name, got {robot_ref!r}")
    robot_path = folder / robot_ref
    if robot_path.exists():
        return load_robot(robot_path.resolve())
    if robot_ref in BUNDLED_ROBOTS:  # bundled with eelsim, whatever the working folder holds
        text = resources.files("eelsim.data").joinpath(robot_ref).read_text()
        return parse_robot(parse_toml(text, f"<bundled {robot_ref}>", RobotFileError),
                           f"<bundled {robot_ref}>")
    raise DataError(
        f"{mpath}: robot: {robot_path} does not exist (the robot file is looked for in the "
        f"dataset folder only; bundled robots: {bundled})"
    )


def load_dataset(folder: str | Path, allow_incomplete: bool = False) -> Dataset:
    """Load a dataset folder: its manifest, robot and every experiment it names.

    Parameters
    ----------
    folder : str or Path
        The dataset folder (with ``manifest.toml``).
    allow_incomplete : bool
        Accept recordings that were never closed (see :func:`read_experiment`).

    Raises
    ------
    DataError
        For a missing or malformed manifest or experiment (naming the file and the key or line),
        and for an incomplete recording without ``allow_incomplete``.
    """
    folder = Path(folder)
    mpath = folder / "manifest.toml"
    try:
        manifest = tomllib.loads(mpath.read_text())
    except OSError as err:
        raise DataError(f"{mpath}: cannot read dataset manifest: {err.strerror}") from None
    except tomllib.TOMLDecodeError as err:
        raise DataError(f"{mpath}: not valid TOML: {err}") from None
    if manifest.get("format") != DATASET_FORMAT:
        raise DataError(f"{mpath}: format: expected {DATASET_FORMAT!r}")
    allowed = {"format", "description", "robot", "motions", "validation", "truth", "plant"}
    for key in manifest:
        if key not in allowed:
            raise DataError(f"{mpath}: {key}: unknown key")
    robot = _dataset_robot(folder, manifest.get("robot"), mpath)
    train: dict[str, list[Experiment]] = {}
    test: dict[str, list[Experiment]] = {}
    _refuse_reused_experiments(manifest, mpath)
    for motion, split in manifest.get("motions", {}).items():
        if not isinstance(split, dict) or set(split) - {"train", "test"}:
            raise DataError(f"{mpath}: motions.{motion}: expected only 'train' and 'test' lists")
        train[motion] = [
            _load_named(folder, n, mpath, f"motions.{motion}.train", allow_incomplete)
            for n in split.get("train", [])
        ]
        test[motion] = [
            _load_named(folder, n, mpath, f"motions.{motion}.test", allow_incomplete)
            for n in split.get("test", [])
        ]
    paths = [
        _load_named(folder, n, mpath, "validation.paths", allow_incomplete)
        for n in manifest.get("validation", {}).get("paths", [])
    ]
    truth = {m: _truth(v, f"{mpath}: truth.{m}") for m, v in manifest.get("truth", {}).items()}
    plant = manifest.get("plant", {})
    if not isinstance(plant, dict):
        raise DataError(f"{mpath}: plant: expected a table")
    return Dataset(folder, robot, train, test, paths, truth, manifest, plant)


def _truth(value: Any, where: str) -> FluidCoefficients:
    """A truth entry: a table (``law`` and the coefficients by name) or a list.

    A list is how datasets made before coefficients were named wrote the Morison law's four.
    """
    try:
        if isinstance(value, dict):
            fields = dict(value)
            law = get_fluid_law(str(fields.pop("law", "morison")))
            return law.coefficients.model_validate(fields)
        return HydroCoefficients.from_array(value)
    except (TypeError, ValueError) as err:  # pydantic's ValidationError is a ValueError
        raise DataError(
            f"{where}: expected a table with law and its coefficients by name, or the Morison "
            f"law's four non-negative numbers ({str(err).splitlines()[0]})"
        ) from None


def _refuse_reused_experiments(manifest: dict[str, Any], mpath: Path) -> None:
    """An experiment named twice (train and test, two motions, a path) would be tested on itself."""
    seen: dict[str, str] = {}
    lists = [
        (f"motions.{motion}.{part}", split.get(part, []))
        for motion, split in manifest.get("motions", {}).items()
        if isinstance(split, dict)
        for part in ("train", "test")
    ]
    lists.append(("validation.paths", manifest.get("validation", {}).get("paths", [])))
    for key, names in lists:
        for name in names:
            if name in seen:
                raise DataError(
                    f"{mpath}: {key}: experiment {name!r} is already in {seen[name]}; an "
                    "experiment is used once (fitting on a test experiment hides the error)"
                )
            seen[name] = key


def _load_named(
    folder: Path, name: str, mpath: Path, key: str, allow_incomplete: bool = False
) -> Experiment:
    if not (folder / f"{name}.csv").exists():
        raise DataError(
            f"{mpath}: {key}: experiment {name!r} has no file {folder / (name + '.csv')}"
        )
    return read_experiment(folder / name, allow_incomplete)
