"""A take exported as MCAP reads back whole: every pose, joint angle, command, telemetry and frame.

The take is a real one (``eelbot run`` with the virtual robot, 2 s); the camera frames come from an
image folder made here, as from the video a take was filmed from. The file is read back with the
``mcap`` package's reader, independently of the writer's code, and compared with the take's own
files, read by eelbot's readers.
"""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from eelhost import cli
from eelhost.data.experiments import read_experiment
from eelhost.field.mcap_export import TOPICS, received_messages
from eelhost.field.recorder import read_commands_csv
from eelhost.wire import protocol
from eelsim.robot import load_robot


@pytest.fixture(scope="module")
def take(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("take")
    stem = folder / "t"
    status = cli.main(["run", "--link", "sim://?speed=0", "--waypoints", "1,0", "--gait",
                       "0.87,3.9", "--duration", "2", "--no-view", "--out", str(stem)])
    assert status == 0
    return stem


def _video(folder: Path, n: int) -> Path:
    folder.mkdir()
    for i in range(n):
        img = np.zeros((48, 64, 3), np.uint8)
        img[:, : (i % 64) + 1] = (40, 160, 240)  # a bar that grows: each frame differs
        cv2.imwrite(str(folder / f"frame_{i:04d}.png"), img)
    return folder


def _read(path: Path) -> tuple[dict, dict[str, list[tuple[int, dict]]], list, dict]:
    topics: dict[str, list[tuple[int, dict]]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        for _schema, channel, message in reader.iter_messages(log_time_order=True):
            topics.setdefault(channel.topic, []).append((message.log_time,
                                                         json.loads(message.data)))
        f.seek(0)
        attachments = [a.name for a in make_reader(f).iter_attachments()]
        f.seek(0)
        metadata = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    return schemas, topics, attachments, metadata


def test_a_take_exported_as_mcap_reads_back_whole(take, tmp_path, capsys):
    frames_seen = len((take.parent / "t.frames.csv").read_text().splitlines()) - 1
    video = _video(tmp_path / "video", frames_seen + 5)  # a video runs on after the take
    out = tmp_path / "t.mcap"
    assert cli.main(["export", str(take), "--mcap", "--video", str(video), "--out", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    schemas, topics, attachments, metadata = _read(out)

    # every topic on its schema, JSON-schema encoded; Foxglove's well-known ones by their names
    assert {t: s.name for t, s in schemas.items()} == TOPICS
    assert all(s.encoding == "jsonschema" and json.loads(s.data)["title"] == s.name
               for s in schemas.values())
    t0 = topics["/robot/pose"][0][0]

    def seconds(log_time: int) -> float:
        return (log_time - t0) / 1e9

    exp = read_experiment(take)
    poses = topics["/robot/pose"]
    robot_tf = [m for m in topics["/tf"] if m[1]["child_frame_id"] == "robot"]
    assert len(poses) == len(exp.t_s) == len(robot_tf) == len(topics["/robot/joints"])
    _links_join_up(topics["/tf"], exp)
    for k, (log_time, msg) in enumerate(poses):
        assert seconds(log_time) == pytest.approx(exp.t_s[k] - exp.t_s[0], abs=1e-6)
        stamp = msg["timestamp"]["sec"] * 10**9 + msg["timestamp"]["nsec"]
        assert stamp == log_time and msg["frame_id"] == "tank"
        p, q = msg["pose"]["position"], msg["pose"]["orientation"]
        assert (p["x"], p["y"]) == pytest.approx(tuple(exp.position_m[k]), abs=1e-9)
        assert 2 * math.atan2(q["z"], q["w"]) == pytest.approx(exp.heading_rad[k], abs=1e-9)
        joints = topics["/robot/joints"][k][1]
        assert joints["theta_rad"] == pytest.approx(list(exp.link_angles_rad[k]), abs=1e-12)
        assert joints["phi_rad"] == pytest.approx(list(np.diff(exp.link_angles_rad[k])), abs=1e-12)
        tf = robot_tf[k][1]
        assert (tf["parent_frame_id"], tf["child_frame_id"]) == ("tank", "robot")

    commands = read_commands_csv(f"{take}.commands.csv")
    got = [(m["seq"], m["message"], m["event"]) for _, m in topics["/robot/commands"]]
    assert sorted(got) == sorted((c["seq"], c["message"], c["event"]) for c in commands)
    assert any(m["message"] == "Start" for _, m in topics["/robot/commands"])

    received = list(received_messages(Path(f"{take}.rx.bin")))
    telemetry = [m for _, _, m in received if isinstance(m, protocol.Telemetry)]
    assert len(topics["/robot/telemetry"]) == len(telemetry) > 10  # 10 Hz over 2 s
    assert [m["time_us"] for _, m in topics["/robot/telemetry"]] == [m.time_us for m in telemetry]
    # on the take's clock: the robot's 100 ms telemetry lies within the run, not seconds off
    times = [seconds(t) for t, _ in topics["/robot/telemetry"]]
    assert -0.5 < times[0] and times[-1] < exp.t_s[-1] + 0.5
    assert len(topics["/robot/received"]) == len(received) - len(telemetry)

    images = topics["/camera/image"]
    rows = (take.parent / "t.frames.csv").read_text().splitlines()[1:]
    assert len(images) == len(topics["/camera/frames"]) == frames_seen
    for n, (log_time, msg) in enumerate(images):
        assert seconds(log_time) == pytest.approx(float(rows[n].split(",")[0]), abs=1e-6)
        assert msg["format"] == "jpeg"
        decoded = cv2.imdecode(np.frombuffer(base64.b64decode(msg["data"]), np.uint8),
                               cv2.IMREAD_COLOR)
        original = cv2.imread(str(video / f"frame_{n:04d}.png"))
        assert np.abs(decoded.astype(int) - original).mean() < 3  # JPEG, not another frame

    assert {"t.json", "t.robot.toml", "t.calibration.json"} <= set(attachments)
    assert metadata["eelbot.take"]["take"] == "t"


def _links_join_up(transforms: list[tuple[int, dict]], exp) -> None:
    """Each link frame sits at its link's centre: neighbouring links meet at their joint."""
    half = np.array([link.half_length_m for link in load_robot().links()])
    by_time: dict[int, dict[str, dict]] = {}
    for log_time, msg in transforms:
        by_time.setdefault(log_time, {})[msg["child_frame_id"]] = msg
    n = len(half)
    assert len(by_time) == len(exp.t_s)
    for frames in by_time.values():
        links = [frames[f"link_{i + 1}"] for i in range(n)]
        centre = np.array([[m["translation"]["x"], m["translation"]["y"]] for m in links])
        angle = np.array([2 * math.atan2(m["rotation"]["z"], m["rotation"]["w"]) for m in links])
        u = np.column_stack([np.cos(angle), np.sin(angle)])
        head_end = centre[:-1] + half[:-1, None] * u[:-1]
        tail_end = centre[1:] - half[1:, None] * u[1:]
        assert np.abs(head_end - tail_end).max() < 1e-9


def test_export_keeps_an_existing_file_unless_forced(take, tmp_path, capsys):
    out = tmp_path / "t.mcap"
    out.write_bytes(b"earlier")
    assert cli.main(["export", str(take), "--mcap", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err and out.read_bytes() == b"earlier"
    assert cli.main(["export", str(take), "--mcap", "--out", str(out), "--force"]) == 0
    _schemas, topics, _a, _m = _read(out)
    assert len(topics["/robot/pose"]) > 30


def test_a_synthetic_cameras_take_exports_frames_drawn_again_at_its_poses(take, tmp_path,
                                                                          capsys):
    from eelhost.vision.calibration import load_calibration
    from eelhost.vision.localise import Localiser

    out = tmp_path / "t.mcap"
    assert cli.main(["export", str(take), "--mcap", "--out", str(out)]) == 0
    assert "drawn again by the synthetic camera" in capsys.readouterr().out
    _schemas, topics, _a, metadata = _read(out)
    exp = read_experiment(take)
    images = topics["/camera/image"]
    assert len(images) == len(exp.t_s)  # one per recorded pose, none invented for the others
    assert "drawn again" in metadata["eelbot.take"]["camera_frames"]
    # the frame, localised as eelbot run does, gives back the pose it was drawn at
    localiser = Localiser(load_calibration(f"{take}.calibration.json"), load_robot())
    for k in (0, len(images) // 2, len(images) - 1):
        frame = cv2.imdecode(np.frombuffer(base64.b64decode(images[k][1]["data"]), np.uint8),
                             cv2.IMREAD_COLOR)
        found = localiser.localise(exp.t_s[k], frame)
        assert found.found
        assert np.abs(found.com_m - exp.position_m[k]).max() < 0.003
