"""The live view of a run: a web page on localhost showing what the host sees and plans.

:class:`LiveView` observes the run loop (each frame's :class:`~eelhost.field.runloop.FrameReport`)
and serves at ``http://127.0.0.1:<port>/``:

- ``/``: the page: the latest camera frame with an SVG overlay (the markers found, outlined and
  labelled with their ids; the track of filtered positions; each waypoint with its acceptance
  circle, drawn through the calibration so perspective bends it as the camera does; the twin's
  predicted path from the present pose, drawn from the robot's head on, over everything else,
  with its end marked), a legend of what is drawn, a scale bar of a round length in metres
  (drawn through the calibration at the frame's lower left), a status line and a Stop button.
  The page polls ``/state.json`` five times a second and reloads the frame when it changed.
- ``/frame.jpg``: the latest frame (encoded only when asked for);
- ``/state.json``: the overlay in image pixels;
- ``POST /stop``: the Stop button: calls :attr:`LiveView.on_stop` (``eelbot run`` stops the robot
  as on Ctrl-C: Stop sent, the record closed). Like every POST it needs the session's token
  (:mod:`eelhost.web.server`), which only the page's own script sends.

The prediction is the twin's closed loop over the next ``horizon_s`` from the latest filtered pose,
straight and at rest there (the camera gives no joint rates), steering to the waypoints not yet
reached: those the run loop steers to now (:attr:`FrameReport.waypoints_m`, so a replan's new
waypoints are drawn and predicted as soon as the robot steers to them). It is swum by the model
the run plans with (``eelbot run --plan --coefficients-file``: the fitted law, joints and straight
set, in the world's current plus the tank's fitted one; docs/planning.md, "The live view of a
planned run"), else by the robot file's robot in the current the operator declared. It runs in a background thread at most once per ``predict_every_s`` of wall time. It is
swum by the batched kernel (:func:`eelsim.batch.run_spec`, one run on one thread), which agrees
with the reference closed loop to rounding and runs without Python's global lock: the reference
loop took about 5 s of processor time per prediction, held the lock the run loop needs, and
slowed a run with the view to a third of its speed (docs/host.md, "5. One take by hand"). The
kernel is loaded (compiled on first use) when the view opens, before the robot is started.

It is a :class:`eelhost.field.take.LiveDisplay`: ``eelbot run`` and ``eelbot campaign`` hand
:func:`eelhost.field.take.run_take` the way to open it, so the dependency goes one way, this
package on the run loop (docs/architecture.md).
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections.abc import Callable

import cv2
import numpy as np
from numpy.typing import NDArray

from eelhost.field.runloop import FrameReport, RunConfig
from eelhost.vision.calibration import Calibration
from eelhost.web.server import LocalServer
from eelsim.batch import BatchSpec, run_spec
from eelsim.closed_loop import LoopOptions
from eelsim.robot import Robot
from eelsim.scenario import Scenario

log = logging.getLogger(__name__)

__all__ = ["LiveView"]

FloatArray = NDArray[np.float64]
TRACK_POINTS = 3000  # the oldest positions are dropped beyond this


PREDICTION_SAMPLE_S = 0.1
"""Spacing of the predicted path's points, s."""


class LiveView:
    """Serve the live view of a run (see the module docstring).

    Parameters
    ----------
    calibration : Calibration
        Metres <-> pixels, to draw world things on the frame.
    robot : Robot
        The robot file's robot (its body length places the path's start at the head).
    config : RunConfig
        The gait, the first waypoints and the acceptance radius.
    port : int
        Port on 127.0.0.1 (0: any free one).
    horizon_s, predict_every_s : float
        Length of the predicted path, and how often it is recomputed (wall time). 20 s by
        default: the robot swims about a body length in 6 s, so a shorter path would lie under
        its own body.
    twin : Robot, optional
        The robot the prediction swims, when it is not ``robot``: the fitted model's robot
        (law, joint model, fitted joint parameters, straight set) of a planned run.
    current_m_s : (float, float)
        The current the prediction swims in, m/s (what the run knows of the water).

    Attributes
    ----------
    on_stop : callable or None
        ``on_stop(why)``: what the page's Stop button does (set by the run once it can stop).
    """

    def __init__(self, calibration: Calibration, robot: Robot, config: RunConfig, port: int = 0,
                 horizon_s: float = 20.0, predict_every_s: float = 1.0,
                 twin: Robot | None = None,
                 current_m_s: tuple[float, float] = (0.0, 0.0)) -> None:
        self.calibration = calibration
        self.robot = twin if twin is not None else robot
        self.current_m_s = (float(current_m_s[0]), float(current_m_s[1]))
        self.config = config
        self.horizon_s = horizon_s
        self.predict_every_s = predict_every_s
        self._lock = threading.Lock()
        self._report: FrameReport | None = None
        self._frame_id = 0
        self._track: list[tuple[float, float]] = []
        self._predicted_m: FloatArray = np.zeros((0, 2))
        self._closed = threading.Event()
        self._wake = threading.Event()
        # the waypoints steered to now (a replan changes them)
        self._waypoints_m = [(float(x), float(y)) for x, y in config.waypoints_m]
        self._circles = [self._circle_px(w) for w in self._waypoints_m]
        self._head_m = robot.body_length_m() / 2.0  # the path is drawn from about the head on
        self._scale = self._scale_bar()
        self.on_stop: Callable[[str], None] | None = None
        self.stop_requests = 0
        # load (or compile) the twin's kernel now, before the robot is started, not in the run
        log.info("live view: loading the twin's kernel for the prediction")
        self.predict(np.zeros(3), 0, self._waypoints_m)
        self.server = LocalServer(
            {"/": self._page, "/state.json": self._state, "/frame.jpg": self._frame},
            post={"/stop": self._stop}, port=port,
        )
        self._predictor = threading.Thread(target=self._predict_loop, name="eelbot-predict",
                                           daemon=True)
        self._predictor.start()

    @property
    def waypoints_m(self) -> list[tuple[float, float]]:
        """The waypoints drawn and predicted: those the run loop steers to now."""
        with self._lock:
            return list(self._waypoints_m)

    @property
    def url(self) -> str:
        """Where to point the browser."""
        return self.server.url

    def update(self, report: FrameReport) -> None:
        """Take one frame's report (called by the run loop for every frame; cheap)."""
        with self._lock:
            self._report = report
            steered = (None if report.waypoints_m is None
                       else [(float(x), float(y)) for x, y in report.waypoints_m])
            if steered is not None and steered != self._waypoints_m:
                # a replan's waypoints: drawn (and predicted) from this frame on
                self._waypoints_m = steered
                self._circles = [self._circle_px(w) for w in self._waypoints_m]
            self._frame_id += 1
            if report.filtered_pose is not None:
                x, y = float(report.filtered_pose[0]), float(report.filtered_pose[1])
                if not self._track or self._track[-1] != (x, y):
                    self._track.append((x, y))
                    del self._track[:-TRACK_POINTS]
        self._wake.set()

    def close(self) -> None:
        """Stop the prediction and the server."""
        self._closed.set()
        self._wake.set()
        self._predictor.join(timeout=10)
        self.server.close()

    # -- what is served ------------------------------------------------------------------
    def _circle_px(self, centre: tuple[float, float]) -> list[list[float]]:
        a = np.linspace(0.0, 2 * math.pi, 48, endpoint=False)
        r = self.config.acceptance_radius_m
        ring = np.c_[centre[0] + r * np.cos(a), centre[1] + r * np.sin(a)]
        return np.round(self.calibration.to_px(ring), 1).tolist()

    def _scale_bar(self) -> dict:
        """A bar of a round length (0.1, 0.2, 0.5, 1, 2 m) about 150 px long at the lower left."""
        width, height = self.calibration.image_size_px
        start_m = self.calibration.to_m(np.array([0.06 * width, 0.93 * height]))
        per_m = 1.0 / max(self.calibration.pixel_size_m(start_m), 1e-9)  # px per metre there
        length = min((0.1, 0.2, 0.5, 1.0, 2.0, 5.0), key=lambda m: abs(m * per_m - 150.0))
        ends = self._px([tuple(start_m), (start_m[0] + length, start_m[1])])
        return {"ends": ends, "label": f"{length:g} m"}

    def _ahead(self, predicted: FloatArray) -> FloatArray:
        """The predicted path from where it leaves the body: the points beyond the head."""
        if len(predicted) < 2:
            return predicted
        far = np.linalg.norm(predicted - predicted[0], axis=1) > self._head_m
        return predicted[np.argmax(far):] if far.any() else predicted[-1:]

    def _stop(self, _body: bytes) -> tuple[str, bytes]:
        self.stop_requests += 1
        if self.on_stop is None:
            answer = {"stopping": False, "why": "the run has not started or has ended"}
        else:
            self.on_stop("Stop from the live view")
            answer = {"stopping": True, "why": "Stop sent; the run ends and its record is closed"}
        return "application/json", json.dumps(answer).encode()

    def _px(self, points_m: FloatArray | list[tuple[float, float]]) -> list[list[float]]:
        pts = np.asarray(points_m, dtype=float).reshape(-1, 2)
        return np.round(self.calibration.to_px(pts), 1).tolist() if len(pts) else []

    def state(self) -> dict:
        """The overlay in image pixels (what ``/state.json`` serves)."""
        with self._lock:
            report, frame_id = self._report, self._frame_id
            track, predicted = list(self._track), self._predicted_m
            points, circles = self._waypoints_m, self._circles
        width, height = self.calibration.image_size_px
        target = report.target_index if report else 0
        waypoints = [
            {"centre": self._px([w])[0], "circle": circle, "reached": i < target}
            for i, (w, circle) in enumerate(zip(points, circles, strict=True))
        ]
        markers = []
        status = "waiting for the first frame"
        if report is not None:
            loc = report.localisation
            markers = [{"id": s.marker_id, "link": s.link + 1,
                        "corners": np.round(s.corners_px, 1).tolist()} for s in loc.sightings]
            pose = report.filtered_pose
            where = (f"x {pose[0]:.2f} m, y {pose[1]:.2f} m, heading "
                     f"{math.degrees(pose[2]):.0f} deg" if pose is not None else "no pose yet")
            status = (f"t {report.t_s:.1f} s | {loc.status} ({sum(loc.seen)}/{len(loc.seen)} "
                      f"markers) | {where} | waypoint {min(target + 1, len(waypoints))}/"
                      f"{len(waypoints)}")
            height, width = report.frame.shape[:2]
        ahead = self._px(self._ahead(predicted))
        origin = self._px(predicted[:1])
        return {"t_s": report.t_s if report else None, "frame_id": frame_id,
                "size": [width, height], "markers": markers, "track": self._px(track),
                "waypoints": waypoints, "predicted": ahead,
                "predicted_end": ahead[-1] if ahead else None,
                "predicted_from": origin[0] if origin else None,  # the pose it started from
                "horizon_s": self.horizon_s, "scale": self._scale, "status": status}

    def _state(self) -> tuple[str, bytes]:
        return "application/json", json.dumps(self.state()).encode()

    def _frame(self) -> tuple[str, bytes]:
        with self._lock:
            frame = None if self._report is None else self._report.frame
        if frame is None:
            width, height = self.calibration.image_size_px
            frame = np.full((height, width, 3), 40, np.uint8)
        ok, jpeg = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 75])
        return "image/jpeg", jpeg.tobytes()

    def _page(self) -> tuple[str, bytes]:
        return "text/html; charset=utf-8", PAGE.encode()

    # -- the twin's prediction -------------------------------------------------------------
    def _predict_loop(self) -> None:
        last = -math.inf
        while not self._closed.is_set():
            self._wake.wait(timeout=self.predict_every_s)
            self._wake.clear()
            if self._closed.is_set() or time.monotonic() - last < self.predict_every_s:
                continue
            with self._lock:
                report, points = self._report, self._waypoints_m
            if report is None or report.filtered_pose is None:
                continue
            last = time.monotonic()
            try:
                self._predicted_m = self.predict(report.filtered_pose, report.target_index,
                                                 points)
            except Exception:  # noqa: BLE001 (a failed prediction must not end the run)
                log.exception("the live view's prediction failed")

    def predict(self, pose: FloatArray, target_index: int,
                waypoints_m: list[tuple[float, float]] | None = None) -> FloatArray:
        """The twin's centre-of-mass path over the horizon from ``pose`` (x, y, heading).

        Parameters
        ----------
        pose : ndarray (3,)
            Filtered x, y (m) and heading (rad) the path starts from.
        target_index : int
            The waypoint being steered to.
        waypoints_m : list of (float, float), optional
            The waypoints steered to now (default: the run's first ones).

        Returns
        -------
        ndarray, shape (K, 2)
            Positions every ``PREDICTION_SAMPLE_S`` (0.1 s), from the pose on, until the twin
            reaches the last waypoint or the horizon ends.
        """
        points = list(self.config.waypoints_m if waypoints_m is None else waypoints_m)
        remaining = points[target_index:] or points[-1:]
        g = self.config.gait
        vx, vy = self.current_m_s
        scenario = Scenario.swimming(
            g, name="live-view prediction", waypoints_m=list(remaining),
            current_speed_m_s=math.hypot(vx, vy),
            current_direction_deg=math.degrees(math.atan2(vy, vx)),
            acceptance_radius_m=self.config.acceptance_radius_m, duration_s=self.horizon_s,
            start_position_m=(float(pose[0]), float(pose[1])),
            start_heading_deg=math.degrees(float(pose[2])),
        )
        # the run loop's own guidance law (a plan's, e.g. pursuit_ff with the planner's known
        # current): the path drawn is the one the robot is steered along (docs/planning.md, "The
        # live view of a planned run")
        options = LoopOptions(stop_at_goal=True, guidance=self.config.guidance)
        spec = BatchSpec.build(self.robot, [scenario], None, options)
        every = max(1, round(PREDICTION_SAMPLE_S / options.timing.dt_s))
        steps = np.arange(0, int(spec.total_steps.max()) + 1, every)
        result = run_spec(spec, sample_steps=steps, threads=1)
        n = self.robot.n_links
        path = result.states[0, :, n : n + 2]
        return np.asarray(path[~np.isnan(path).any(axis=1)], dtype=float)  # NaN: after the end


PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>eelbot live view</title>
<style>
 body { margin: 0; background: #222; color: #eee; font: 14px sans-serif; }
 #bar { display: flex; align-items: center; gap: 12px; padding: 6px 10px; }
 #status { flex: 1; }
 #stop { background: #d32f2f; color: #fff; border: 0; border-radius: 4px; padding: 8px 18px;
         font: bold 16px sans-serif; cursor: pointer; }
 #stop:disabled { background: #777; cursor: default; }
 #view { position: relative; display: inline-block; }
 #frame { display: block; max-width: 100vw; }
 #overlay { position: absolute; left: 0; top: 0; width: 100%; height: 100%; }
 .marker { fill: none; stroke: #00e5ff; stroke-width: 2; }
 .marker-id { fill: #00e5ff; font: bold 14px sans-serif; }
 #track { fill: none; stroke: #ffd400; stroke-width: 2; }
 .acceptance { fill: rgba(255, 0, 200, 0.12); stroke: #ff00c8; stroke-width: 2; }
 .acceptance.reached { stroke: #3ddc84; fill: rgba(61, 220, 132, 0.12); }
 .waypoint { fill: #ff00c8; }
 #predicted-under { fill: none; stroke: #000; stroke-width: 7; stroke-opacity: 0.6; }
 #predicted { fill: none; stroke: #ff7a00; stroke-width: 4; stroke-dasharray: 10 6; }
 #predicted-end { fill: #ff7a00; stroke: #000; stroke-width: 2; }
 #scale line { stroke: #fff; stroke-width: 4; }
 #scale .tick { stroke-width: 3; }
 #scale text { fill: #fff; font: bold 16px sans-serif; paint-order: stroke; stroke: #000;
               stroke-width: 3; }
 #legend { position: absolute; right: 8px; top: 8px; background: rgba(0, 0, 0, 0.65);
           padding: 6px 10px; border-radius: 4px; font-size: 13px; line-height: 1.6; }
 #legend svg { vertical-align: middle; margin-right: 6px; }
</style></head>
<body>
<div id="bar"><div id="status">connecting...</div>
 <button id="stop" type="button" title="stop the robot now (as Ctrl-C does)">Stop</button></div>
<div id="view">
 <img id="frame" alt="camera frame">
 <svg id="overlay" xmlns="http://www.w3.org/2000/svg">
  <g id="waypoints"></g><polyline id="track" points=""></polyline><g id="markers"></g>
  <polyline id="predicted-under" points=""></polyline><polyline id="predicted" points="">
  </polyline><circle id="predicted-end" r="0" cx="0" cy="0"></circle>
  <g id="scale"><line id="scale-bar"></line><line class="tick" id="scale-tick0"></line>
   <line class="tick" id="scale-tick1"></line><text id="scale-label"></text></g>
 </svg>
 <div id="legend">
  <div class="entry"><svg width="26" height="10"><line x1="0" y1="5" x2="26" y2="5"
   stroke="#ff7a00" stroke-width="4" stroke-dasharray="8 4"/></svg><span
   id="legend-predicted">twin's prediction</span></div>
  <div class="entry"><svg width="26" height="10"><line x1="0" y1="5" x2="26" y2="5"
   stroke="#ffd400" stroke-width="2"/></svg>track (filtered positions)</div>
  <div class="entry"><svg width="26" height="12"><rect x="6" y="1" width="10" height="10"
   fill="none" stroke="#00e5ff" stroke-width="2"/></svg>markers found (id)</div>
  <div class="entry"><svg width="26" height="14"><circle cx="13" cy="7" r="6"
   fill="rgba(255,0,200,0.12)" stroke="#ff00c8" stroke-width="2"/></svg>waypoint, acceptance
   radius</div>
  <div class="entry"><svg width="26" height="14"><circle cx="13" cy="7" r="6"
   fill="rgba(61,220,132,0.12)" stroke="#3ddc84" stroke-width="2"/></svg>waypoint reached</div>
 </div>
</div>
<script>
const NS = "http://www.w3.org/2000/svg";
let shown = -1;
const pts = (list) => list.map((p) => p[0] + "," + p[1]).join(" ");
const byId = (id) => document.getElementById(id);
function el(name, attrs, text) {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}
function set(id, attrs) { for (const [k, v] of Object.entries(attrs)) byId(id).setAttribute(k, v); }
function drawScale(scale) {
  const [a, b] = scale.ends;
  set("scale-bar", {x1: a[0], y1: a[1], x2: b[0], y2: b[1]});
  set("scale-tick0", {x1: a[0], y1: a[1] - 8, x2: a[0], y2: a[1] + 8});
  set("scale-tick1", {x1: b[0], y1: b[1] - 8, x2: b[0], y2: b[1] + 8});
  set("scale-label", {x: (a[0] + b[0]) / 2, y: Math.min(a[1], b[1]) - 12, "text-anchor": "middle"});
  byId("scale-label").textContent = scale.label;
}
byId("stop").addEventListener("click", async () => {
  byId("stop").disabled = true;
  try {
    const answer = await (await fetch("/stop", {method: "POST"})).json();
    byId("stop").textContent = answer.stopping ? "Stopping..." : "Stop";
    byId("stop").disabled = answer.stopping;
    byId("status").textContent = answer.why;
  } catch (e) {
    byId("stop").disabled = false;
    byId("status").textContent = "Stop not sent: the run is not reachable";
  }
});
async function tick() {
  try {
    const s = await (await fetch("/state.json", {cache: "no-store"})).json();
    byId("status").textContent = s.status;
    byId("overlay").setAttribute("viewBox", "0 0 " + s.size[0] + " " + s.size[1]);
    if (s.frame_id !== shown) {
      shown = s.frame_id;
      byId("frame").src = "/frame.jpg?k=" + s.frame_id;
    }
    byId("waypoints").replaceChildren(...s.waypoints.flatMap((w) => [
      el("polygon", {class: "acceptance" + (w.reached ? " reached" : ""), points: pts(w.circle)}),
      el("circle", {class: "waypoint", cx: w.centre[0], cy: w.centre[1], r: 4}),
    ]));
    byId("track").setAttribute("points", pts(s.track));
    byId("predicted-under").setAttribute("points", pts(s.predicted));
    byId("predicted").setAttribute("points", pts(s.predicted));
    if (s.predicted_end) set("predicted-end", {cx: s.predicted_end[0], cy: s.predicted_end[1], r: 6});
    byId("legend-predicted").textContent = "twin's prediction, next " + s.horizon_s + " s";
    byId("markers").replaceChildren(...s.markers.flatMap((m) => [
      el("polygon", {class: "marker", points: pts(m.corners)}),
      el("text", {class: "marker-id", x: m.corners[0][0], y: m.corners[0][1] - 4}, String(m.id)),
    ]));
    drawScale(s.scale);
  } catch (e) {
    byId("status").textContent = "run ended or not reachable";
  }
  setTimeout(tick, 200);
}
tick();
</script>
</body></html>
"""
