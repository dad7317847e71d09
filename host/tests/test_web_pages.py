"""The live view and the corner picker, opened in a real headless browser."""

from __future__ import annotations

import io
import subprocess
import sys
import threading

import numpy as np
import pytest
from browser import headless_chromium
from PIL import Image
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

from eelhost.field.runloop import FrameReport, RunConfig
from eelhost.vision.calibration import load_calibration
from eelhost.vision.localise import Localiser
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
from eelhost.web.liveview import LiveView
from eelhost.web.picker import pick_points
from eelsim.closed_loop import simulate_closed_loop
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

ROBOT = load_robot()
PATH1 = load_scenario("path1")


def _reports(n_frames: int):
    """Frames of the twin's path1 run, localised as the run loop does."""
    cam = SyntheticCamera(ROBOT, options=RenderOptions(noise_sigma=0.0, jpeg_quality=0))
    localiser = Localiser(cam.calibration(), ROBOT)
    run = simulate_closed_loop(ROBOT, PATH1.model_copy(update={"duration_s": 8.0}))
    out = []
    for k in np.linspace(0, len(run.t_s) - 1, n_frames).astype(int):
        frame, _ = cam.render(run.states[k], run.t_s[k])
        loc = localiser.localise(run.t_s[k], frame)
        pose = np.array([loc.com_m[0], loc.com_m[1], loc.heading_rad])
        out.append(FrameReport(run.t_s[k], frame, loc, pose, 0))
    return cam.calibration(), out


@pytest.mark.slow
def test_live_view_page_shows_the_frame_markers_track_waypoints_and_prediction():
    calibration, reports = _reports(6)
    view = LiveView(calibration, ROBOT, RunConfig(PATH1.gait, list(PATH1.waypoints_m)),
                    predict_every_s=0.05)
    try:
        for r in reports:
            view.update(r)
        with headless_chromium() as browser:
            browser.get(view.url)
            wait = WebDriverWait(browser, 30)
            wait.until(lambda b: b.execute_script(
                "const i = document.getElementById('frame'); return i.complete && i.naturalWidth > 0"))
            wait.until(lambda b: b.execute_script(
                "return document.getElementById('predicted').getAttribute('points').length > 0"))
            page = browser.execute_script("""
                const q = (s) => document.querySelectorAll(s);
                return {width: document.getElementById('frame').naturalWidth,
                        markers: q('polygon.marker').length,
                        ids: [...q('text.marker-id')].map((t) => t.textContent).sort(),
                        circles: q('polygon.acceptance').length,
                        waypoints: q('circle.waypoint').length,
                        track: document.getElementById('track').getAttribute('points').split(' ').length,
                        status: document.getElementById('status').textContent};""")
            shot = np.asarray(Image.open(io.BytesIO(browser.get_screenshot_as_png())).convert("RGB"))
            frame_box = browser.find_element(By.ID, "frame").rect
    finally:
        view.close()
    assert page["width"] == 1280
    assert page["markers"] == 6 and page["ids"] == ["0", "1", "2", "3", "4", "5"]
    assert page["circles"] == 3 and page["waypoints"] == 3
    assert page["track"] == 6
    assert "ok (6/6 markers)" in page["status"] and "waypoint 1/3" in page["status"]
    # The screenshot shows the frame (the tank floor's pale blue-grey) under the overlays: the
    # acceptance circles' magenta and the markers' cyan outlines are drawn on it.
    scale = frame_box["width"] / 1280
    top, left = int(frame_box["y"]), int(frame_box["x"])
    shown = shot[top: top + int(720 * scale), left: left + int(1280 * scale)].astype(int)
    floor = (abs(shown[..., 0] - 170) < 40) & (abs(shown[..., 2] - 205) < 40)
    magenta = (shown[..., 0] > 200) & (shown[..., 1] < 80) & (shown[..., 2] > 150)
    cyan = (shown[..., 0] < 80) & (shown[..., 1] > 180) & (shown[..., 2] > 200)
    assert floor.mean() > 0.3
    assert magenta.sum() > 200 and cyan.sum() > 100
    u, v = calibration.to_px(PATH1.waypoints_m[0]) * scale
    near = magenta[int(v) - 30: int(v) + 30, int(u) - 30: int(u) + 30]
    assert near.sum() > 20  # the first waypoint's circle is where the calibration puts it


def test_corner_picker_returns_the_pixels_clicked_in_order():
    frame = np.full((300, 400, 3), 200, np.uint8)
    clicks = [(20, 30), (350, 40), (340, 260), (30, 250)]
    result: dict = {}
    ready = threading.Event()

    def announce(url: str) -> None:
        result["url"] = url
        ready.set()

    picker = threading.Thread(target=lambda: result.update(
        points=pick_points(frame, 4, announce=announce, timeout_s=60)))
    picker.start()
    assert ready.wait(30)
    with headless_chromium() as browser:
        browser.get(result["url"])
        WebDriverWait(browser, 30).until(lambda b: b.execute_script(
            "return document.getElementById('frame').naturalWidth > 0"))
        img = browser.find_element(By.ID, "frame")
        for x, y in clicks:
            # Selenium offsets are from the element's centre.
            ActionChains(browser).move_to_element_with_offset(img, x - 200, y - 150).click().perform()
        browser.find_element(By.ID, "done").click()
        picker.join(30)
    assert not picker.is_alive()
    assert np.allclose(result["points"], np.array(clicks) - 0.5, atol=1.0)


def test_picker_gives_up_with_a_clear_error_when_nobody_clicks():
    from eelhost.web.picker import PickError

    with pytest.raises(PickError, match="no 4 points were clicked within 0.2 s"):
        pick_points(np.zeros((10, 10), np.uint8), 4, timeout_s=0.2)


@pytest.mark.slow
def test_calibrate_click_takes_the_corners_clicked_on_the_synthetic_tank(tmp_path):
    # The synthetic tank's corners are at these pixels (the exact camera puts them there).
    corners_px = [(35, 689), (1245, 689), (1237, 31), (43, 31)]
    corners_m = "-1.5,-1;3.1,-1;3.1,1.5;-1.5,1.5"
    cal_path = tmp_path / "cal.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "eelhost", "calibrate", "--camera", "synthetic", "--click",
         "--port", "0", f"--corners-m={corners_m}", "--calibration", str(cal_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("click the tank's four corners at http://127.0.0.1:"), line
        url = line.split(" at ", 1)[1].split()[0]
        with headless_chromium() as browser:
            browser.get(url)
            WebDriverWait(browser, 30).until(lambda b: b.execute_script(
                "return document.getElementById('frame').naturalWidth > 0"))
            img = browser.find_element(By.ID, "frame")
            for u, v in corners_px:
                ActionChains(browser).move_to_element_with_offset(img, u - 640, v - 360).click().perform()
            browser.find_element(By.ID, "done").click()
            out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "tank_corners, 4 points" in out
    cal = load_calibration(cal_path)
    truth = SyntheticCamera(ROBOT).calibration()
    area = np.stack(np.meshgrid(np.linspace(-0.5, 2.0, 6), np.linspace(-0.5, 1.0, 4)), -1)
    # Clicks land on whole CSS pixels: the map is within a pixel of the camera's.
    assert np.abs(cal.to_px(area.reshape(-1, 2)) - truth.to_px(area.reshape(-1, 2))).max() < 1.0


@pytest.mark.slow
def test_live_view_has_a_legend_a_scale_bar_a_visible_prediction_and_a_stop_that_stops():
    import urllib.error
    import urllib.request

    calibration, reports = _reports(4)
    view = LiveView(calibration, ROBOT, RunConfig(PATH1.gait, list(PATH1.waypoints_m)),
                    predict_every_s=0.05)
    stops: list[str] = []
    try:
        for r in reports:
            view.update(r)
        # a POST from elsewhere (no session token) stops nothing
        forged = urllib.request.Request(view.url.split("?")[0] + "stop", data=b"", method="POST")
        with pytest.raises(urllib.error.HTTPError):
            urllib.request.urlopen(forged, timeout=10)
        view.on_stop = stops.append
        with headless_chromium() as browser:
            browser.get(view.url)
            wait = WebDriverWait(browser, 30)
            wait.until(lambda b: b.execute_script(
                "return document.getElementById('predicted').getAttribute('points').length > 0"))
            page = browser.execute_script("""
                const q = (s) => document.querySelectorAll(s);
                const order = [...document.getElementById('overlay').children].map((e) => e.id);
                return {legend: document.getElementById('legend').textContent,
                        scale: document.getElementById('scale-label').textContent,
                        order: order};""")
            state = view.state()
            browser.find_element(By.ID, "stop").click()
            wait.until(lambda b: stops)
            wait.until(lambda b: "Stop sent" in b.find_element(By.ID, "status").text
                       or b.find_element(By.ID, "stop").text == "Stopping...")
    finally:
        view.close()
    for entry in ("twin's prediction, next 20 s", "track", "markers found", "acceptance",
                  "reached"):
        assert entry in page["legend"], page["legend"]
    # drawn over the markers, and from the head on: not hidden under the body
    assert page["order"].index("predicted") > page["order"].index("markers")
    origin_m = calibration.to_m(np.asarray(state["predicted_from"]))  # the pose it swam from
    first_m = calibration.to_m(np.asarray(state["predicted"][0]))
    assert np.linalg.norm(first_m - origin_m) > 0.45 * ROBOT.body_length_m()
    # the scale bar is as long on the frame as its label says
    (a, b), label = state["scale"]["ends"], state["scale"]["label"]
    assert page["scale"] == label
    length_m = float(label.split()[0])
    span = np.linalg.norm(calibration.to_m(np.asarray(b)) - calibration.to_m(np.asarray(a)))
    assert span == pytest.approx(length_m, rel=0.02) and 80 < np.linalg.norm(np.subtract(b, a)) < 300
    assert stops == ["Stop from the live view"]
