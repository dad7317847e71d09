import json

import cv2
import numpy as np
import pytest

from eelhost.vision.calibration import (
    CalibrationFileError,
    CharucoSpec,
    from_charuco,
    from_tank_corners,
    load_calibration,
    save_calibration,
)

CORNERS_PX = [(35.0, 689.0), (1245.0, 689.0), (1237.0, 31.0), (43.0, 31.0)]
TANK_M = (4.6, 2.5)
CORNERS_M = [(0.0, 0.0), (4.6, 0.0), (4.6, 2.5), (0.0, 2.5)]


def test_calibration_round_trip_recovers_known_tank_corners(tmp_path):
    cal = from_tank_corners(CORNERS_PX, (1280, 720), tank_size_m=TANK_M)
    path = save_calibration(cal, tmp_path / "cal.json")
    loaded = load_calibration(path)
    assert np.allclose(loaded.to_px(CORNERS_M), CORNERS_PX, atol=1e-6)
    assert np.allclose(loaded.to_m(CORNERS_PX), CORNERS_M, atol=1e-9)
    assert loaded.image_size_px == (1280, 720) and loaded.method == "tank_corners"
    assert loaded.rms_reprojection_px < 1e-6
    assert loaded.pixel_size_m((2.3, 1.25)) == pytest.approx(0.0038, rel=0.02)


def test_height_correction_scales_about_the_point_under_the_camera():
    plain = from_tank_corners(CORNERS_PX, (1280, 720), tank_size_m=TANK_M)
    nadir = np.array([2.3, 1.25])
    raised = from_tank_corners(CORNERS_PX, (1280, 720), tank_size_m=TANK_M, camera_height_m=2.0,
                               marker_height_m=0.2, nadir_m=nadir)
    # A marker 0.2 m nearer a camera 2 m up appears 2 / 1.8 times farther from the nadir.
    point = nadir + [1.0, -0.5]
    assert np.allclose(raised.to_px(point), plain.to_px(nadir + (point - nadir) * 2.0 / 1.8))
    assert np.allclose(raised.to_px(nadir), plain.to_px(nadir))


def test_charuco_board_seen_through_a_known_homography_gives_that_homography():
    spec = CharucoSpec()
    dpi = 254.0  # 10 px per mm... of the printed board image: 100 px per 10 mm -> 0.1 mm/px
    board = spec.image(dpi=dpi)
    m_per_board_px = 0.0254 / dpi
    truth = from_tank_corners(CORNERS_PX, (1280, 720), corners_m=[(-1.5, -1.0), (3.1, -1.0),
                                                                    (3.1, 1.5), (-1.5, 1.5)])
    origin, angle = np.array([0.4, 0.6]), np.radians(20.0)
    c, s = np.cos(angle), np.sin(angle)
    # Board image (column, row) -> world: columns along the board's x, rows down the page (-y).
    board_to_m = np.array([[c * m_per_board_px, s * m_per_board_px, origin[0]],
                           [s * m_per_board_px, -c * m_per_board_px, origin[1]], [0, 0, 1.0]])
    shift = np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1.0]])
    frame = cv2.warpPerspective(board, truth.homography_m_to_px @ board_to_m @ shift, (1280, 720),
                                flags=cv2.INTER_AREA, borderValue=200)
    cal = from_charuco(frame, spec, board_origin_m=tuple(origin), board_angle_rad=angle)
    probe = origin + np.array([[0.3, -0.2], [0.6, -0.4], [0.1, -0.5]]) @ np.array([[c, s], [-s, c]])
    assert cal.method == "charuco" and len(cal.points_m) >= 20
    assert np.max(np.linalg.norm(cal.to_px(probe) - truth.to_px(probe), axis=1)) < 0.3


def _write(tmp_path, data):
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    ("change", "key"),
    [
        (lambda d: d.pop("homography_m_to_px"), "homography_m_to_px"),
        (lambda d: d.update(homography_m_to_px=[[1, 0], [0, 1]]), "homography_m_to_px"),
        (lambda d: d.update(points_px=[[1, "x"]]), "points_px"),
        (lambda d: d.update(image_size_px=[1280]), "image_size_px"),
        (lambda d: d.update(version=7), "version"),
        (lambda d: d.update(method="guess"), "method"),
        (lambda d: d.update(colour="blue"), "colour"),
        (lambda d: d.update(rms_reprojection_px=-1), "rms_reprojection_px"),
        (lambda d: d.update(rms_reprojection_px=True), "rms_reprojection_px"),
        (lambda d: d["points_px"][0].__setitem__(0, "1.5"), "points_px"),
        (lambda d: d.update(image_size_px=[True, 720]), "image_size_px"),
    ],
)
def test_malformed_calibration_file_is_refused_naming_file_and_key(tmp_path, change, key):
    cal = from_tank_corners(CORNERS_PX, (1280, 720), tank_size_m=TANK_M)
    data = json.loads(save_calibration(cal, tmp_path / "good.json").read_text())
    change(data)
    path = _write(tmp_path, data)
    with pytest.raises(CalibrationFileError) as info:
        load_calibration(path)
    assert str(path) in str(info.value) and key in str(info.value)


def test_calibration_file_that_is_not_json_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "cal.json"
    path.write_text("{not json")
    with pytest.raises(CalibrationFileError, match="cal.json: not valid JSON"):
        load_calibration(path)


def test_missing_calibration_file_is_refused_naming_the_file(tmp_path):
    with pytest.raises(CalibrationFileError, match="nowhere.json"):
        load_calibration(tmp_path / "nowhere.json")
