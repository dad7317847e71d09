"""A take as an MCAP file, on topics with Foxglove's well-known schemas (``eelbot export --mcap``).

Labs replay and inspect robot logs in Foxglove, and ROS 2 stores its bags as MCAP. One take
(``eelbot run``'s files, docs/data.md) becomes one ``.mcap`` file written with the maintained
``mcap`` package, every message JSON-encoded with a JSON schema (MCAP's ``jsonschema`` encoding,
which Foxglove reads).

The topics and their schemas are listed in docs/host.md ("Takes as MCAP, for Foxglove") and in
:data:`TOPICS`: the pose (``foxglove.PoseInFrame``) and frame transform
(``foxglove.FrameTransform``) of every frame with a pose, a frame ``link_i`` at each link's
centre along its axis (the centres from the centre of mass and the link angles through the robot's
geometry, docs/model.md; the robot file is the take's copy), the joint angles, every link event,
the robot's telemetry and other messages decoded from the byte log, every frame's localisation
status, and the camera frames (``foxglove.CompressedImage``, JPEG).

Times: a take's times are seconds since the gait started; in the MCAP file they are put at the
take's date (``source.run.date``) plus that time, in nanoseconds since the Unix epoch, so Foxglove
shows the wall-clock time the take was run. The received bytes are stamped with the link's clock;
they are put on the take's time by the robot's acknowledgement that ``<take>.commands.csv`` and the
byte log both hold (the first ``Ack`` in both, matched by sequence number). A take records no
camera images: the frames come from the video it was filmed from, the n-th frame of the video
stamped with the time of the n-th row of ``<take>.frames.csv``. The take's JSON metadata, robot
file and calibration are attachments; the MCAP metadata record ``eelbot.take`` names the take.
"""

from __future__ import annotations

import base64
import json
import logging
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from eelhost.data.experiments import read_experiment
from eelhost.errors import UserError
from eelhost.field.recorder import read_commands_csv
from eelhost.files import atomic_writer
from eelhost.link.replay_transport import read_rx_log
from eelhost.wire import protocol
from eelsim.dynamics import link_positions
from eelsim.model import SwimmerModel
from eelsim.robot import load_robot

__all__ = ["ExportError", "ExportSummary", "TOPICS", "export_take_mcap", "link_centres",
           "take_stem"]

log = logging.getLogger(__name__)

TANK_FRAME = "tank"
ROBOT_FRAME = "robot"
CAMERA_FRAME = "camera"
JPEG_QUALITY = 90


class ExportError(UserError, ValueError):
    """A take that cannot be exported; the message names the file."""


# --- JSON schemas: Foxglove's well-known ones, written from their published field lists ----------

_TIME = {
    "type": "object",
    "title": "time",
    "properties": {"sec": {"type": "integer", "minimum": 0},
                   "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}},
}
_VECTOR3 = {"type": "object", "properties": {k: {"type": "number"} for k in ("x", "y", "z")}}
_QUATERNION = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}


def _schema(title: str, description: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "description": description, "$comment": "eelbot export --mcap",
            "type": "object", "properties": properties}


SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.PoseInFrame": _schema(
        "foxglove.PoseInFrame", "A timestamped pose for an object in a reference frame",
        {"timestamp": _TIME, "frame_id": {"type": "string"},
         "pose": {"type": "object", "properties": {"position": _VECTOR3,
                                                    "orientation": _QUATERNION}}}),
    "foxglove.FrameTransform": _schema(
        "foxglove.FrameTransform", "A transform between two reference frames in 3D space",
        {"timestamp": _TIME, "parent_frame_id": {"type": "string"},
         "child_frame_id": {"type": "string"}, "translation": _VECTOR3, "rotation": _QUATERNION}),
    "foxglove.CompressedImage": _schema(
        "foxglove.CompressedImage", "A compressed image",
        {"timestamp": _TIME, "frame_id": {"type": "string"},
         "data": {"type": "string", "contentEncoding": "base64"},
         "format": {"type": "string"}}),
    "eelbot.JointAngles": _schema(
        "eelbot.JointAngles", "Link angles theta_i (tail first) and joint angles phi_j, rad",
        {"timestamp": _TIME, "theta_rad": {"type": "array", "items": {"type": "number"}},
         "phi_rad": {"type": "array", "items": {"type": "number"}},
         "heading_rad": {"type": "number"}}),
    "eelbot.LinkEvent": _schema(
        "eelbot.LinkEvent", "A message the host sent and what became of it (docs/host.md)",
        {"timestamp": _TIME, "seq": {"type": "integer"}, "message": {"type": "string"},
         "fields": {"type": "object"}, "event": {"type": "string"}}),
    "eelbot.Telemetry": _schema(
        "eelbot.Telemetry", "The robot's telemetry message (docs/firmware.md)",
        {"timestamp": _TIME, "seq": {"type": "integer"}, "time_us": {"type": "integer"},
         "state": {"type": "integer"}, "flags": {"type": "integer"},
         "alpha_rad": {"type": "array", "items": {"type": "number"}},
         "offset_rad": {"type": "number"}, "amplitude_rad": {"type": "number"},
         "frames_ok": {"type": "integer"}, "frames_bad": {"type": "integer"},
         "frames_lost": {"type": "integer"},
         "phi_mrad": {"type": "array", "items": {"type": "integer"}}}),
    "eelbot.Message": _schema(
        "eelbot.Message", "A message from the robot other than telemetry (docs/firmware.md)",
        {"timestamp": _TIME, "seq": {"type": "integer"}, "message": {"type": "string"},
         "fields": {"type": "object"}}),
    "eelbot.FrameStatus": _schema(
        "eelbot.FrameStatus", "A camera frame seen: the localisation's status, markers read",
        {"timestamp": _TIME, "status": {"type": "string"}, "markers": {"type": "integer"}}),
}

TOPICS: dict[str, str] = {
    "/robot/pose": "foxglove.PoseInFrame",
    "/tf": "foxglove.FrameTransform",
    "/robot/joints": "eelbot.JointAngles",
    "/robot/commands": "eelbot.LinkEvent",
    "/robot/telemetry": "eelbot.Telemetry",
    "/robot/received": "eelbot.Message",
    "/camera/frames": "eelbot.FrameStatus",
    "/camera/image": "foxglove.CompressedImage",
}


@dataclass(frozen=True)
class ExportSummary:
    """What an export wrote: the file and the messages per topic."""

    path: Path
    counts: dict[str, int]
    clock_offset_s: float | None  # link clock minus take time; None when no Ack matched

    def line(self) -> str:
        """``/robot/pose 120, /tf 120, ...``: the topics with their message counts."""
        return ", ".join(f"{topic} {n}" for topic, n in self.counts.items() if n)


def take_stem(take: str | Path) -> str:
    """The stem of a take given as its stem, ``.csv`` or ``.json``."""
    stem = str(take)
    for ext in (".csv", ".json"):
        stem = stem.removesuffix(ext)
    return stem


def _stamp(t0_ns: int, t_s: float) -> tuple[int, dict[str, int]]:
    ns = max(0, t0_ns + int(round(t_s * 1e9)))
    return ns, {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _yaw(heading_rad: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(heading_rad / 2), "w": math.cos(heading_rad / 2)}


def _plain(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def _message_fields(msg: Any) -> dict[str, Any]:
    return {name: _plain(getattr(msg, name)) for name in msg.__dataclass_fields__}


def received_messages(rx_path: Path) -> Iterator[tuple[float, int, Any]]:
    """Every message in a take's byte log, as ``(link time s, seq, message)``."""
    reader = protocol.FrameReader()
    for t_s, data in read_rx_log(rx_path):
        for seq, msg in reader.feed(data):
            yield t_s, seq, msg


def clock_offset_s(received: list[tuple[float, int, Any]],
                   commands: list[dict[str, Any]]) -> float | None:
    """Link clock minus take time, from an acknowledgement both records hold (None if none).

    The recorder writes an ``ack`` row at the time the Ack was decoded, less the gait's start;
    the byte log holds the same Ack at the link time it arrived.
    """
    acks = {int(row["seq"]): float(row["t_s"]) for row in commands if row["event"] == "ack"}
    for t_link, _seq, msg in received:
        if isinstance(msg, protocol.Ack) and msg.seq in acks:
            return t_link - acks[msg.seq]
    return None


def _take_time_zero_ns(meta: dict[str, Any]) -> int:
    date = meta.get("source", {}).get("run", {}).get("date")
    try:
        return int(datetime.fromisoformat(date).timestamp() * 1e9) if date else 0
    except (TypeError, ValueError):
        return 0


def _jpeg(frame: np.ndarray) -> bytes:
    import cv2

    ok, buf = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ExportError("a camera frame could not be encoded as JPEG")
    return buf.tobytes()


def export_take_mcap(
    take: str | Path,
    out: str | Path | None = None,
    frames: Iterable[np.ndarray] | None = None,
    progress: Any = None,
    frame_times_s: Sequence[float] | None = None,
    frames_note: str = "the video the take was filmed from",
) -> ExportSummary:
    """Write a take as an MCAP file (the topics of the module's table).

    Parameters
    ----------
    take : str or Path
        The take's stem (or its ``.csv`` / ``.json``).
    out : str or Path, optional
        The MCAP file (default ``<stem>.mcap``); written whole (atomically).
    frames : iterable of ndarray, optional
        The camera frames (BGR) of the video the take was filmed from, in order: the n-th is
        stamped with the n-th row of ``<take>.frames.csv``.
    progress : callable, optional
        ``progress(done, total)`` over the frames seen.
    frame_times_s : sequence of float, optional
        The times (take's clock) of ``frames``, when they are not the rows of
        ``<take>.frames.csv`` (frames re-rendered at the recorded poses).
    frames_note : str
        Where the frames came from, for the file's metadata.

    Returns
    -------
    ExportSummary

    Raises
    ------
    ExportError, DataError
        A take that cannot be read, naming the file.
    """
    from mcap.writer import CompressionType, Writer

    stem = take_stem(take)
    exp = read_experiment(stem, allow_incomplete=True)
    meta = json.loads(Path(stem + ".json").read_text())
    t0 = _take_time_zero_ns(meta)
    commands_path = Path(stem + ".commands.csv")
    commands = read_commands_csv(commands_path) if commands_path.exists() else []
    rx_path = Path(stem + ".rx.bin")
    received = list(received_messages(rx_path)) if rx_path.exists() else []
    offset = clock_offset_s(received, commands)
    if received and offset is None:
        log.warning("%s: no acknowledgement in both the byte log and the commands; the robot's "
                    "messages are put at their link times", rx_path)
    frame_rows = _frame_rows(Path(stem + ".frames.csv"))
    out_path = Path(out) if out is not None else Path(stem + ".mcap")
    counts = dict.fromkeys(TOPICS, 0)

    with atomic_writer(out_path, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD if _has_zstd() else CompressionType.NONE)
        writer.start(profile="", library="eelbot export --mcap")
        schema_ids = {name: writer.register_schema(name=name, encoding="jsonschema",
                                                   data=json.dumps(s).encode())
                      for name, s in SCHEMAS.items()}
        channels = {topic: writer.register_channel(topic=topic, message_encoding="json",
                                                   schema_id=schema_ids[schema])
                    for topic, schema in TOPICS.items()}

        def put(topic: str, t_s: float, body: dict[str, Any]) -> None:
            ns, stamp = _stamp(t0, t_s)
            data = json.dumps({"timestamp": stamp, **body}, separators=(",", ":")).encode()
            writer.add_message(channel_id=channels[topic], log_time=ns, publish_time=ns,
                               data=data, sequence=counts[topic])
            counts[topic] += 1

        messages: list[tuple[float, str, dict[str, Any]]] = []
        heading = exp.heading_rad if exp.heading_rad is not None else np.zeros(len(exp.t_s))
        model = _model_of(stem, exp.link_angles_rad)
        for k, t_s in enumerate(exp.t_s):
            x, y = (float(v) for v in exp.position_m[k])
            h = float(heading[k])
            position = {"x": x, "y": y, "z": 0.0}
            messages.append((t_s, "/robot/pose", {"frame_id": TANK_FRAME, "pose": {
                "position": position, "orientation": _yaw(h)}}))
            messages.append((t_s, "/tf", {"parent_frame_id": TANK_FRAME,
                                          "child_frame_id": ROBOT_FRAME,
                                          "translation": position, "rotation": _yaw(h)}))
            if exp.link_angles_rad is not None:
                theta = exp.link_angles_rad[k]
                if model is not None:
                    for i, (cx, cy) in enumerate(link_centres(model, exp.position_m[k], theta)):
                        messages.append((t_s, "/tf", {
                            "parent_frame_id": TANK_FRAME, "child_frame_id": f"link_{i + 1}",
                            "translation": {"x": float(cx), "y": float(cy), "z": 0.0},
                            "rotation": _yaw(float(theta[i]))}))
                messages.append((t_s, "/robot/joints", {
                    "theta_rad": _plain(list(theta)), "phi_rad": _plain(list(np.diff(theta))),
                    "heading_rad": h}))
        for row in commands:
            messages.append((float(row["t_s"]), "/robot/commands", {
                "seq": int(row["seq"]), "message": row["message"],
                "fields": row.get("fields") or {}, "event": row["event"]}))
        for t_link, seq, msg in received:
            t_s = t_link - (offset or 0.0)
            if isinstance(msg, protocol.Telemetry):
                messages.append((t_s, "/robot/telemetry", {"seq": seq, **_message_fields(msg)}))
            else:
                messages.append((t_s, "/robot/received", {
                    "seq": seq, "message": type(msg).__name__, "fields": _message_fields(msg)}))
        for t_s, status, markers in frame_rows:
            messages.append((t_s, "/camera/frames", {"status": status, "markers": markers}))
        messages.sort(key=lambda m: m[0])  # MCAP readers want log times in order within a chunk
        for t_s, topic, body in messages:
            put(topic, t_s, body)
        if frames is not None:
            times = (list(frame_times_s) if frame_times_s is not None
                     else [row[0] for row in frame_rows])
            for n, frame in enumerate(frames):
                if n >= len(times):
                    log.info("the video has more frames than the take saw; the rest are left out")
                    break
                put("/camera/image", times[n], {
                    "frame_id": CAMERA_FRAME, "format": "jpeg",
                    "data": base64.b64encode(_jpeg(frame)).decode("ascii")})
                if progress:
                    progress(n + 1, len(times))
        for suffix, media in ((".json", "application/json"), (".robot.toml", "application/toml"),
                              (".calibration.json", "application/json")):
            path = Path(stem + suffix)
            if path.exists():
                ns, _ = _stamp(t0, 0.0)
                writer.add_attachment(create_time=ns, log_time=ns, name=path.name,
                                      media_type=media, data=path.read_bytes())
        writer.add_metadata("eelbot.take", {
            "take": Path(stem).name, "format": str(meta.get("format", "")),
            "date": str(meta.get("source", {}).get("run", {}).get("date", "")),
            "time_zero": "the gait's start, at the take's date",
            "camera_frames": frames_note if frames is not None else "none",
            "clock_offset_s": "" if offset is None else f"{offset:.6f}"})
        writer.finish()
    return ExportSummary(out_path, counts, offset)


def link_centres(model: SwimmerModel, com_m: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
    """Centres of the links (N, 2), tail first, of a body at ``com_m`` with link angles ``theta``."""
    n = model.n_links
    state = np.concatenate([np.asarray(theta_rad, dtype=float), np.asarray(com_m, dtype=float),
                            np.zeros(n + 2)])
    x, y = link_positions(model, state)
    return np.column_stack([x, y])


def _model_of(stem: str, link_angles: np.ndarray | None) -> SwimmerModel | None:
    """The take's robot (its copy beside it, else the bundled one) if its links match the CSV."""
    copy = Path(stem + ".robot.toml")
    try:
        robot = load_robot(copy if copy.exists() else None)
    except (OSError, ValueError) as err:
        log.warning("%s: no link frames in the export: %s", copy, err)
        return None
    if link_angles is None or link_angles.shape[1] != robot.n_links:
        return None
    return SwimmerModel.from_robot(robot)


def _frame_rows(path: Path) -> list[tuple[float, str, int]]:
    """``(t_s, status, markers)`` of every frame the take saw (none without the file)."""
    if not path.exists():
        return []
    rows = []
    lines = path.read_text().splitlines()
    for number, line in enumerate(lines[1:], start=2):
        cells = line.split(",")
        if len(cells) != 3:
            if number == len(lines):  # a last line cut by a killed writer
                break
            raise ExportError(f"{path}:{number}: expected t_s,status,markers, got {line!r}")
        try:
            rows.append((float(cells[0]), cells[1], int(cells[2])))
        except ValueError:
            raise ExportError(f"{path}:{number}: expected t_s,status,markers, got {line!r}") \
                from None
    return rows


def _has_zstd() -> bool:
    try:
        import zstandard  # noqa: F401
    except ImportError:
        return False
    return True
