import json

import cv2
import numpy as np
import pytest

from eelhost.vision.markers import MarkerLayout, default_layout, marker_sheet, save_marker_sheet


def test_marker_sheet_renders_every_link_marker_readably():
    layout = default_layout()
    sheet, printed_m = marker_sheet(layout, dpi=150)
    assert sheet.shape == (round(0.297 / 0.0254 * 150), round(0.210 / 0.0254 * 150))
    assert printed_m == pytest.approx(layout.marker_size_m, abs=0.0015)
    corners, ids, _ = cv2.aruco.ArucoDetector(layout.dictionary()).detectMarkers(sheet)
    assert sorted(np.asarray(ids).ravel().tolist()) == [0, 1, 2, 3, 4, 5]


def test_marker_sheet_image_is_a_png_and_a_pdf_is_left_to_the_printable_writer(tmp_path):
    path = save_marker_sheet(tmp_path / "markers.png", default_layout(), dpi=100)
    assert path.read_bytes()[:8].startswith(b"\x89PNG")
    with pytest.raises(ValueError, match="eelbot markers"):
        save_marker_sheet(tmp_path / "markers.pdf", default_layout())


def test_marker_layout_maps_ids_to_links_and_refuses_bad_layouts():
    layout = default_layout()
    assert layout.link_of(0) == 0 and layout.link_of(5) == 5 and layout.link_of(17) is None
    assert layout.plate_size_m == pytest.approx(0.070)
    with pytest.raises(ValueError, match="distinct"):
        MarkerLayout(link_ids=(0, 0, 1, 2, 3, 4))
    with pytest.raises(ValueError, match="0..49"):
        MarkerLayout(link_ids=(0, 1, 2, 3, 4, 60))
    with pytest.raises(ValueError, match="unknown ArUco dictionary"):
        MarkerLayout(dictionary_name="DICT_NOPE")


POINTS_PER_MM = 72 / 25.4


def _rasterise(path, dpi):
    import pypdfium2 as pdfium

    pdf = pdfium.PdfDocument(str(path))
    assert len(pdf) == 1
    page = pdf[0]
    size_mm = tuple(v / POINTS_PER_MM for v in page.get_size())
    grey = np.asarray(page.render(scale=dpi / 72).to_pil().convert("L"))
    pdf.close()
    return size_mm, grey


def test_eelbot_markers_writes_both_pdfs_at_true_size_and_the_layout_file(tmp_path, capsys):
    from eelhost.cli import main
    from eelhost.vision.markerfile import load_marker_file

    assert main(["markers", "--out", str(tmp_path), "--ids", "0,1,2,3,4,7"]) == 0
    # The sheet: A4, and each marker 60 mm a side once rasterised at 200 dpi.
    dpi = 200
    size_mm, sheet = _rasterise(tmp_path / "markers.pdf", dpi)
    assert size_mm == pytest.approx((210.0, 297.0), abs=0.1)
    corners, ids, _ = cv2.aruco.ArucoDetector(default_layout().dictionary()).detectMarkers(sheet)
    assert sorted(np.asarray(ids).ravel().tolist()) == [0, 1, 2, 3, 4, 7]
    for c in corners:
        sides_mm = np.linalg.norm(np.diff(np.vstack([c[0], c[0][:1]]), axis=0), axis=1) / dpi * 25.4
        assert sides_mm == pytest.approx(np.full(4, 60.0), abs=0.3)
    # The board: 770 x 550 mm on A1 landscape, its corners 110 mm apart.
    markers = load_marker_file(tmp_path / "markers.json")
    assert markers.layout.link_ids == (0, 1, 2, 3, 4, 7)
    dpi = 50
    size_mm, board = _rasterise(tmp_path / "charuco.pdf", dpi)
    assert size_mm == pytest.approx((841.0, 594.0), abs=0.1)
    detector = cv2.aruco.CharucoDetector(markers.board.board())
    found, found_ids, _, _ = detector.detectBoard(board)
    assert len(found_ids) == 24  # every interior corner of 7 x 5 squares
    pts = np.asarray(found).reshape(-1, 2)[np.argsort(np.asarray(found_ids).ravel())]
    grid = pts.reshape(4, 6, 2) / dpi * 25.4
    assert np.linalg.norm(np.diff(grid, axis=1), axis=2) == pytest.approx(np.full((4, 5), 110.0), abs=0.6)
    assert np.linalg.norm(np.diff(grid, axis=0), axis=2) == pytest.approx(np.full((3, 6), 110.0), abs=0.6)
    assert "markers.json" in capsys.readouterr().out


def test_marker_file_round_trips_and_names_what_is_wrong(tmp_path):
    from eelhost.vision.calibration import CharucoSpec
    from eelhost.vision.markerfile import (
        MarkerFile,
        MarkerFileError,
        load_marker_file,
        save_marker_file,
    )

    original = MarkerFile(MarkerLayout(link_ids=(5, 4, 3, 2, 1, 0), offsets_m=(0.01,) * 6),
                          CharucoSpec(squares=(5, 4), square_m=0.1, marker_m=0.07, first_id=20))
    path = save_marker_file(original, tmp_path / "m.json")
    assert load_marker_file(path) == original
    assert load_marker_file(None) == MarkerFile()
    data = json.loads(path.read_text())
    data["robot"]["colour"] = "red"
    path.write_text(json.dumps(data))
    with pytest.raises(MarkerFileError, match=r"m\.json: unknown key 'robot.colour'"):
        load_marker_file(path)
    with pytest.raises(MarkerFileError, match=r"ids \[10, 11\] are also on the robot"):
        MarkerFile(MarkerLayout(link_ids=(6, 7, 8, 9, 10, 11)))


def test_the_localiser_reads_the_robot_as_the_marker_file_says_it_was_printed(tmp_path):
    from eelhost.cli import main
    from eelhost.vision.localise import Localiser
    from eelhost.vision.markerfile import load_marker_file
    from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
    from eelsim.dynamics import straight_state
    from eelsim.model import SwimmerModel
    from eelsim.robot import load_robot

    # Printed head first (ids 5..0 from the tail) with the plates 1 cm towards the head.
    assert main(["markers", "--out", str(tmp_path), "--ids", "5,4,3,2,1,0",
                 "--offsets", "0.01,0.01,0.01,0.01,0.01,0.01"]) == 0
    printed = load_marker_file(tmp_path / "markers.json").layout
    robot = load_robot()
    camera = SyntheticCamera(robot, layout=printed,
                             options=RenderOptions(noise_sigma=0.0, jpeg_quality=0))
    frame, truth = camera.render(straight_state(SwimmerModel.from_robot(robot), 0.4, (0.6, 0.2)))
    loc = Localiser(camera.calibration(), robot, printed).localise(0.0, frame)
    assert loc.found
    assert np.hypot(*(np.asarray(loc.com_m) - truth.com_m)) < 0.002
    assert abs(np.angle(np.exp(1j * (loc.heading_rad - truth.heading_rad)))) < np.radians(1.0)
    # Read with the default layout (plates centred on their links), the same robot is placed
    # the plates' offset away from where it is.
    wrong = Localiser(camera.calibration(), robot).localise(0.0, frame)
    assert np.hypot(*(np.asarray(wrong.com_m) - truth.com_m)) > 0.008
