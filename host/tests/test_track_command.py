"""``eelbot track``: a video filmed without eelbot becomes an experiment that validate accepts.

The video is made here: a 3 s twin run rendered by the synthetic camera (clean, 640 x 360) and
written as an MJPG AVI, with five frames in the middle replaced by an empty tank (the robot lost
from view), and the same frames as an image folder. Tracking must give back the rendered truth
to within millimetres, take its frame times from the container, report the five lost frames
instead of inventing poses, and write an experiment that the dataset reader and validate accept.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from eelhost import cli
from eelhost.data.experiments import load_dataset, read_experiment
from eelhost.vision.calibration import save_calibration
from eelhost.vision.markerfile import load_marker_file, save_marker_file
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera, TankView, sample_run
from eelsim.closed_loop import simulate_closed_loop
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

FPS = 30.0
LOST = range(40, 45)  # frames without the robot
GAIT = "0.87,3.9,1.04"
SCENARIO = "straight"  # k_theta 0.1, waypoint (1.4, 0)


@pytest.fixture(scope="module")
def filmed(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("filmed")
    robot = load_robot()
    scenario = load_scenario(SCENARIO).model_copy(update={"duration_s": 3.0})
    result = simulate_closed_loop(robot, scenario)
    run = sample_run(result.t_s, result.states, FPS)
    view = TankView((640, 360), ((-0.5, -0.3), (1.0, -0.3), (1.0, 0.45), (-0.5, 0.45)),
                    ((10.0, 350.0), (630.0, 350.0), (626.0, 40.0), (14.0, 40.0)))  # 2.4 mm/px
    camera = SyntheticCamera(robot, view=view,
                             options=RenderOptions(noise_sigma=0.0, jpeg_quality=0))
    calibration = save_calibration(camera.calibration(), folder / "calibration.json")
    markers = save_marker_file(load_marker_file(None), folder / "markers.json")
    empty = np.clip(camera._background, 0, 255).astype(np.uint8)  # the tank without the robot
    video = folder / "take.avi"
    images = folder / "images"
    images.mkdir()
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), FPS,
                             camera.view.image_size_px)
    truth = []
    for k, state in enumerate(run.states):
        frame, pose = camera.render(state, run.t_s[k])
        if k in LOST:
            frame = empty
        truth.append(pose)
        writer.write(frame)
        cv2.imwrite(str(images / f"img_{k}.png"), frame)
    writer.release()
    return {"folder": folder, "video": video, "images": images, "truth": truth,
            "calibration": calibration, "markers": markers, "t_s": run.t_s}


def _track(filmed: dict, source: Path, out: Path, *extra: str) -> list[str]:
    return ["track", str(source), "--calibration", str(filmed["calibration"]), "--markers",
            str(filmed["markers"]), "--gait", GAIT, "--k-theta", "0.1", "--waypoints", "1.4,0",
            "--out", str(out), *extra]


@pytest.mark.parametrize("kind", ["video", "images"])
def test_a_video_becomes_the_experiment_it_filmed_and_lost_frames_are_reported(filmed, kind,
                                                                              tmp_path, capsys):
    out = tmp_path / "tracked" / "straight_tracked"
    assert cli.main(_track(filmed, filmed[kind], out)) == 0
    printed = capsys.readouterr().out
    n = len(filmed["truth"])
    assert f"{n - len(LOST)}/{n} frames with a pose" in printed
    t_lost = filmed["t_s"][LOST.start] - filmed["t_s"][0]
    assert f"{t_lost:.2f}-" in printed and f"({len(LOST)} frames, not_found" in printed

    exp = read_experiment(out)
    found = [k for k in range(n) if k not in LOST]
    assert len(exp.t_s) == len(found)  # no pose invented for a lost frame
    # frame times: the container's (or index / fps for a folder), the first frame at 0
    assert exp.t_s == pytest.approx([k / FPS for k in found], abs=1.5e-3)
    com = np.array([filmed["truth"][k].com_m for k in found])
    assert np.abs(exp.position_m - com).max() < 0.004  # the localisation of eelbot run
    angles = np.array([filmed["truth"][k].link_angles_rad for k in found])
    assert np.abs(exp.link_angles_rad - angles).max() < 0.05
    meta = json.loads(out.with_suffix(".json").read_text())
    tracked = meta["source"]["tracked"]
    assert tracked["video"] == str(filmed[kind].resolve())
    assert tracked["frames"] == n and tracked["frames_without_pose"] == len(LOST)
    assert tracked["lost"][0]["frames"] == len(LOST)
    assert ("container" in tracked["frame_times"]) == (kind == "video")
    assert meta["camera"]["median_window"] == 5 and exp.scenario.k_theta == 0.1
    rows = out.with_name(out.name + ".frames.csv").read_text().splitlines()[1:]
    assert len(rows) == n and sum(",not_found," in r for r in rows) == len(LOST)


def test_the_tracked_experiment_is_a_dataset_validate_accepts(filmed, tmp_path, capsys):
    dataset = tmp_path / "tank"
    for name in ("train_take", "test_take"):
        assert cli.main(_track(filmed, filmed["video"], dataset / name)) == 0
    (dataset / "robot.toml").write_text((dataset / "train_take.robot.toml").read_text())
    (dataset / "manifest.toml").write_text(
        'format = "eelbot-dataset/1"\nrobot = "robot.toml"\n\n[motions.straight]\n'
        'train = ["train_take"]\ntest = ["test_take"]\n')
    assert [e.name for e in load_dataset(dataset).held_out] == ["test_take"]
    capsys.readouterr()
    # the robot file's own coefficients: the twin that was filmed, so the errors are small
    coefficients = "0.008,0.776,0.618,0.007"
    status = cli.main(["validate", coefficients, str(dataset), "--backend", "reference",
                       "--out", str(tmp_path / "validate")])
    assert status == 0
    table = (tmp_path / "validate" / "table4.csv").read_text().splitlines()
    header, row = table[0].split(","), table[1].split(",")
    assert row[header.index("name")] == "test_take"  # (TOO_SLOW: 3 s do not reach the waypoint)
    ex = float(row[header.index("Ex_mean_BL")])
    assert ex < 0.1  # body lengths: the track follows the filmed run


def test_a_calibration_for_other_frames_is_refused(filmed, tmp_path, capsys):
    small = tmp_path / "small"
    small.mkdir()
    frame = cv2.imread(str(next(filmed["images"].iterdir())))
    cv2.imwrite(str(small / "a.png"), cv2.resize(frame, (320, 180)))
    assert cli.main(_track(filmed, small, tmp_path / "x")) == 2
    err = capsys.readouterr().err
    assert "640x360" in err and "320x180" in err
    assert not list(tmp_path.glob("x.*"))


def test_a_tracked_video_exports_with_its_own_frames_from_its_start(filmed, tmp_path, capsys):
    from mcap.reader import make_reader

    out = tmp_path / "late"
    start = 10 / FPS  # the gait started at the 11th frame
    assert cli.main(_track(filmed, filmed["video"], out, "--start", f"{start:.6f}")) == 0
    assert "10 frames before --start not used" in capsys.readouterr().out
    assert cli.main(["export", str(out), "--mcap"]) == 0  # the video named in the experiment
    with open(f"{out}.mcap", "rb") as f:
        images = [json.loads(m.data) for _s, c, m in make_reader(f).iter_messages()
                  if c.topic == "/camera/image"]
    n = len(filmed["truth"])
    assert len(images) == n - 10
    first = cv2.imdecode(np.frombuffer(base64.b64decode(images[0]["data"]), np.uint8),
                         cv2.IMREAD_COLOR).astype(int)

    def distance(k: int) -> float:
        return float(np.abs(first - cv2.imread(str(filmed["images"] / f"img_{k}.png"))).mean())

    assert distance(10) < min(distance(0), distance(9), distance(11))  # the 11th, as tracked
