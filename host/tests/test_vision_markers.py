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


@pytest.mark.parametrize("suffix", [".png", ".pdf"])
def test_marker_sheet_is_written_as_png_or_pdf(tmp_path, suffix):
    path = save_marker_sheet(tmp_path / f"markers{suffix}", default_layout(), dpi=100)
    head = path.read_bytes()[:8]
    assert head.startswith(b"\x89PNG" if suffix == ".png" else b"%PDF")


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
