"""``eelbot calibrate`` on synthetic frames: the board, the tank corners, the lens, ``--check``."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from eelhost.cli import main
from eelhost.vision.calibration import (
    CalibrationFileError,
    CharucoSpec,
    Lens,
    calibrate_lens,
    from_charuco,
    load_calibration,
)
from eelhost.vision.synthetic import SyntheticCamera
from eelhost.vision.synthetic_lens import lens_views
from eelsim.robot import load_robot

TRUTH = SyntheticCamera(load_robot()).calibration()
# Over the swimming area of the named scenarios.
AREA_M = np.stack(np.meshgrid(np.linspace(-0.5, 2.0, 6), np.linspace(-0.5, 1.0, 4)), -1).reshape(-1, 2)
TANK_CORNERS = "35,689;1245,689;1237,31;43,31"
TANK_CORNERS_M = "-1.5,-1;3.1,-1;3.1,1.5;-1.5,1.5"


def test_calibrating_on_the_synthetic_board_recovers_the_camera_and_checks_clean(tmp_path, capsys):
    cal_path, frame = tmp_path / "cal.json", tmp_path / "frame.png"
    assert main(["calibrate", "--camera", "synthetic", "--calibration", str(cal_path),
                 "--save-frame", str(frame)]) == 0
    out = capsys.readouterr().out
    assert "reprojection rms" in out and " px = " in out and " mm" in out
    cal = load_calibration(cal_path)
    assert cal.method == "charuco" and len(cal.points_m) == 24
    assert cal.rms_reprojection_px < 0.15 and cal.rms_reprojection_m < 0.0006
    # Pixels <-> metres as the camera really maps them, within a pixel over the swimming area.
    assert np.abs(cal.to_px(AREA_M) - TRUTH.to_px(AREA_M)).max() < 1.0
    # The saved frame, checked against the calibration: the same small error, exit 0.
    assert main(["calibrate", "--check", "--image", str(frame), "--calibration", str(cal_path),
                 "--board-origin", "0.2,0.6"]) == 0
    assert "on this frame: rms 0.0" in capsys.readouterr().out


def test_calibrating_from_a_camera_source_reads_its_frames(tmp_path, capsys):
    # A folder of images and a video stand for a camera: the same frames as the synthetic one.
    frame_png, folder = tmp_path / "frame.png", tmp_path / "camera"
    assert main(["calibrate", "--camera", "synthetic", "--calibration", str(tmp_path / "a.json"),
                 "--save-frame", str(frame_png)]) == 0
    frame = cv2.imread(str(frame_png))
    folder.mkdir()
    for i in range(12):
        cv2.imwrite(str(folder / f"{i:03d}.png"), frame)
    video = tmp_path / "camera.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30.0,
                             (frame.shape[1], frame.shape[0]))
    for _ in range(12):
        writer.write(frame)
    writer.release()
    for source in (folder, video):
        cal_path = tmp_path / f"{source.stem}.json"
        assert main(["calibrate", "--camera", str(source), "--board-origin", "0.2,0.6",
                     "--calibration", str(cal_path)]) == 0
        cal = load_calibration(cal_path)
        assert cal.method == "charuco" and cal.rms_reprojection_px < 0.3
        assert np.abs(cal.to_px(AREA_M) - TRUTH.to_px(AREA_M)).max() < 1.5
    # A camera that is not there is named, and nothing is written.
    assert main(["calibrate", "--camera", "7", "--calibration", str(tmp_path / "none.json")]) == 2
    assert "camera 7" in capsys.readouterr().err
    assert not (tmp_path / "none.json").exists()


def test_check_fails_when_the_board_is_not_where_the_calibration_says(tmp_path, capsys):
    cal_path, frame = tmp_path / "cal.json", tmp_path / "frame.png"
    assert main(["calibrate", "--camera", "synthetic", "--calibration", str(cal_path),
                 "--save-frame", str(frame)]) == 0
    # Told the board lies 2 cm further along x than it does: about 5 px of error.
    assert main(["calibrate", "--check", "--image", str(frame), "--calibration", str(cal_path),
                 "--board-origin", "0.22,0.6"]) == 1
    assert "recalibrate" in capsys.readouterr().out


def test_tank_corners_given_as_pixels_give_the_exact_homography(tmp_path):
    cal_path = tmp_path / "cal.json"
    assert main(["calibrate", "--camera", "synthetic", "--corners", TANK_CORNERS,
                 f"--corners-m={TANK_CORNERS_M}", "--calibration", str(cal_path)]) == 0
    cal = load_calibration(cal_path)
    assert cal.method == "tank_corners"
    assert np.abs(cal.to_px(AREA_M) - TRUTH.to_px(AREA_M)).max() < 1e-6


def test_bad_corners_are_refused_naming_the_option(capsys):
    assert main(["calibrate", "--camera", "synthetic", "--corners", "1,2;3,4"]) == 2
    assert "--corners: expected four x,y pairs" in capsys.readouterr().err


LENS = Lens(np.array([[950.0, 0, 642], [0, 950, 357], [0, 0, 1]]),
            np.array([-0.28, 0.09, 0.0005, -0.0003, 0.0]), 0.0, 1)


@pytest.fixture(scope="module")
def views():
    return lens_views(CharucoSpec(), LENS)


def test_lens_calibration_recovers_the_lens_and_straightens_the_board(views):
    lens = calibrate_lens(views)
    assert lens.views == len(views) and lens.rms_px < 0.2
    assert np.diag(lens.camera_matrix)[:2] == pytest.approx([950, 950], rel=0.005)
    assert lens.distortion[:2] == pytest.approx(LENS.distortion[:2], abs=0.01)
    board = CharucoSpec().board()
    detector = cv2.aruco.CharucoDetector(board)
    for view in views:
        corners, ids, _, _ = detector.detectBoard(view)
        obj = board.getChessboardCorners()[ids.ravel(), :2].astype(float)
        px = corners.reshape(-1, 2).astype(float)

        def plane_fit_rms(points, obj=obj):
            h, _ = cv2.findHomography(obj, points, 0)
            q = cv2.perspectiveTransform(obj.reshape(-1, 1, 2), h).reshape(-1, 2)
            return np.sqrt(np.mean(np.sum((q - points) ** 2, axis=1)))

        # Undistorted, the flat board's corners are one homography away from the board.
        assert plane_fit_rms(lens.undistort(px)) < 1.2 * plane_fit_rms(LENS.undistort(px)) + 0.02
        assert plane_fit_rms(lens.undistort(px)) < plane_fit_rms(px) / 3


def test_calibrate_with_lens_views_writes_the_lens_and_fits_the_plane_better(tmp_path, views, capsys):
    folder = tmp_path / "views"
    folder.mkdir()
    for i, v in enumerate(views):
        cv2.imwrite(str(folder / f"view{i}.png"), v)
    with_lens, without = tmp_path / "lens.json", tmp_path / "plain.json"
    assert main(["calibrate", "--image", str(folder / "view1.png"), "--lens", str(folder),
                 "--calibration", str(with_lens)]) == 0
    assert "lens: 8 views" in capsys.readouterr().out
    assert main(["calibrate", "--image", str(folder / "view1.png"), "--calibration", str(without)]) == 0
    cal, plain = load_calibration(with_lens), load_calibration(without)
    assert cal.lens is not None and plain.lens is None
    assert cal.rms_reprojection_px < plain.rms_reprojection_px / 3
    # to_px and to_m undo each other through the distortion.
    pts = cal.points_m[::3]
    assert np.allclose(cal.to_m(cal.to_px(pts)), pts, atol=1e-9)
    # A malformed lens section is named.
    data = json.loads(with_lens.read_text())
    data["lens"]["distortion"] = [0.1, 0.2]
    with_lens.write_text(json.dumps(data))
    with pytest.raises(CalibrationFileError, match="lens.distortion"):
        load_calibration(with_lens)


def test_charuco_fit_with_the_true_lens_matches_the_board_in_a_distorted_view(views):
    spec = CharucoSpec()
    cal = from_charuco(views[4], spec, lens=LENS)
    assert cal.rms_reprojection_px < 0.2


def _half_size_calibration(tmp_path):
    """A calibration made on the synthetic tank's frame scaled to 640x360 (its corners halved)."""
    big = tmp_path / "frame.png"
    assert main(["calibrate", "--camera", "synthetic", "--calibration", str(tmp_path / "big.json"),
                 "--save-frame", str(big)]) == 0
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), cv2.resize(cv2.imread(str(big)), (640, 360)))
    halved = ";".join(f"{float(u) / 2:g},{float(v) / 2:g}"
                      for u, v in (p.split(",") for p in TANK_CORNERS.split(";")))
    cal = tmp_path / "small.json"
    assert main(["calibrate", "--image", str(small), "--corners", halved,
                 f"--corners-m={TANK_CORNERS_M}", "--calibration", str(cal)]) == 0
    assert load_calibration(cal).image_size_px == (640, 360)
    return cal, big


def test_check_on_a_frame_of_another_size_names_both_sizes(tmp_path, capsys):
    cal, big = _half_size_calibration(tmp_path)
    capsys.readouterr()
    assert main(["calibrate", "--check", "--image", str(big), "--calibration", str(cal),
                 "--board-origin", "0.2,0.6"]) == 2
    err = capsys.readouterr().err
    assert str(cal) in err and "640x360" in err and "1280x720" in err
    assert "moved" not in err  # the size, not a guess about the camera


def test_run_refuses_frames_of_another_size_than_its_calibration(tmp_path, capsys):
    cal, _ = _half_size_calibration(tmp_path)
    capsys.readouterr()
    status = main(["run", "--link", "sim://", "--calibration", str(cal), "--waypoints", "1,0",
                   "--gait", "0.87,3.9", "--duration", "2", "--no-view", "--out",
                   str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert status == 2, err
    assert "640x360" in err and "1280x720" in err and str(cal) in err


def test_the_localiser_makes_no_pose_from_a_frame_of_another_size():
    from eelhost.vision.calibration import FrameSizeError
    from eelhost.vision.localise import Localiser

    localiser = Localiser(TRUTH, load_robot())
    with pytest.raises(FrameSizeError, match="made for 1280x720 px frames.*gives 640x360"):
        localiser.localise(0.0, np.zeros((360, 640, 3), np.uint8))
