import cv2
import numpy as np
import pytest

from eelhost.vision.sources import (
    CameraSource,
    FolderSource,
    SyntheticSource,
    VideoFileSource,
    open_source,
)
from eelhost.vision.synthetic import SyntheticCamera, sample_run
from eelsim.dynamics import straight_state
from eelsim.model import SwimmerModel
from eelsim.robot import load_robot


def test_folder_source_reads_images_in_natural_order_with_times_from_fps(tmp_path):
    for value, name in [(10, "frame_10.png"), (2, "frame_2.png"), (1, "frame_1.png")]:
        cv2.imwrite(str(tmp_path / name), np.full((8, 8, 3), value, np.uint8))
    (tmp_path / "notes.txt").write_text("not an image")
    frames = list(FolderSource(tmp_path, fps=20.0))
    assert [f[0, 0, 0] for _, f in frames] == [1, 2, 10]
    assert [t for t, _ in frames] == pytest.approx([0.0, 0.05, 0.1])


def test_folder_without_images_is_refused(tmp_path):
    with pytest.raises(FileNotFoundError, match="no images"):
        FolderSource(tmp_path)


def test_open_source_picks_camera_folder_or_video(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((4, 4, 3), np.uint8))
    assert isinstance(open_source("0"), CameraSource)
    assert isinstance(open_source(str(tmp_path)), FolderSource)
    with pytest.raises(FileNotFoundError, match="no such video"):
        open_source(str(tmp_path / "missing.avi"))


def test_video_file_source_yields_every_frame_with_increasing_times(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 48))
    for i in range(5):
        writer.write(np.full((48, 64, 3), 40 * i, np.uint8))
    writer.release()
    frames = list(VideoFileSource(path))
    assert len(frames) == 5
    times = [t for t, _ in frames]
    assert times == pytest.approx([i / 25.0 for i in range(5)], abs=1e-3)


def test_synthetic_source_yields_frames_and_keeps_the_truth():
    robot = load_robot()
    model = SwimmerModel.from_robot(robot)
    states = [straight_state(model, 0.0, (x, 0.2)) for x in (0.0, 0.1)]
    run = sample_run([0.0, 1 / 30], states, 30.0)
    source = SyntheticSource(SyntheticCamera(robot, seed=1), run.t_s, run.states)
    frames = list(source)
    assert len(frames) == 2 and frames[0][1].shape == (720, 1280, 3)
    assert [p.com_m[0] for p in source.truth] == pytest.approx([0.0, 0.1])


def test_synthetic_camera_noise_is_reproducible_from_the_seed():
    robot = load_robot()
    state = straight_state(SwimmerModel.from_robot(robot), 0.0, (0.0, 0.0))
    a = SyntheticCamera(robot, seed=5).render(state)[0]
    b = SyntheticCamera(robot, seed=5).render(state)[0]
    c = SyntheticCamera(robot, seed=6).render(state)[0]
    assert np.array_equal(a, b) and not np.array_equal(a, c)
