"""Accuracy and speed of the vision on synthetic frames of a twin run: ``eelbot vision-bench``.

:func:`run_benchmark` renders N synthetic 1280 x 720 frames of a closed-loop run (evenly spread over it), localises them
and compares with the truth: centre-of-mass error (px and mm), heading error (deg), how often the
full pose was found, and frames per second on one core (localisation alone; render + localise).
:func:`vision_doc` is ``docs/vision.md``: the marker layout and the calibration how-to
(:data:`STATIC_DOC`) followed by the figures.
"""

from __future__ import annotations

import math
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from eelhost.machine import cpu_model
from eelhost.vision.localise import REFINE_METHODS, Localiser
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera, sample_run
from eelsim.closed_loop import simulate_closed_loop
from eelsim.control import wrap_angle
from eelsim.robot import Robot
from eelsim.scenario import load_scenario


@dataclass
class BenchResult:
    """Figures of one benchmark.

    Attributes
    ----------
    frames : int
        Frames rendered.
    found : int
        Frames with a full pose (all links seen or rebuilt).
    rebuilt : int
        Of those, frames where an interior link was rebuilt from its neighbours.
    markers_read : float
        Fraction of the robot's markers read.
    pos_rms_px, pos_rms_mm, pos_max_px : float
        Centre-of-mass error over the found frames.
    heading_rms_deg, heading_max_deg : float
        Heading error over the found frames.
    fps_localise, fps_total : float
        Frames per second: localisation alone; render plus localisation.
    refine_compare : dict
        Per corner-refinement method: (pos rms px, heading rms deg, found).
    pixel_mm : float
        Mean pixel size at the robot, mm.
    """

    frames: int
    found: int
    rebuilt: int
    markers_read: float
    pos_rms_px: float
    pos_rms_mm: float
    pos_max_px: float
    heading_rms_deg: float
    heading_max_deg: float
    fps_localise: float
    fps_total: float
    refine_compare: dict[str, tuple[float, float, int]]
    pixel_mm: float


def _rms(values: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values else float("nan")


def run_benchmark(
    robot: Robot,
    scenario_name: str = "path1",
    n_frames: int = 300,
    seed: int = 0,
    options: RenderOptions | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> BenchResult:
    """Render ``n_frames`` frames of a run of ``scenario_name``, localise them, compare.

    Parameters
    ----------
    robot : Robot
        The robot.
    scenario_name : str
        A named scenario or a scenario file.
    n_frames : int
        Number of frames, spread evenly over the run's 30 fps frames.
    seed : int
        Seed of the camera noise.
    options : RenderOptions, optional
        Camera faults (default :class:`RenderOptions`).
    progress : callable, optional
        ``progress(done, total)`` after each frame.

    Returns
    -------
    BenchResult
    """
    cv2.setNumThreads(1)  # the target is one core
    result = simulate_closed_loop(robot, load_scenario(scenario_name))
    run = sample_run(result.t_s, result.states, 30.0)
    picks = np.unique(np.linspace(0, len(run.t_s) - 1, n_frames).round().astype(int))
    camera = SyntheticCamera(robot, options=options, seed=seed)
    cal = camera.calibration()
    localisers = {name: Localiser(cal, robot, refine=name) for name in REFINE_METHODS}
    main = localisers["contour"]
    errors: dict[str, tuple[list[float], list[float]]] = {n: ([], []) for n in localisers}
    pos_mm: list[float] = []
    t_render = t_loc = 0.0
    found = rebuilt = markers = 0
    for done, k in enumerate(picks, start=1):
        if progress is not None:
            progress(done - 1, len(picks))
        t0 = time.perf_counter()
        frame, truth = camera.render(run.states[k], float(run.t_s[k]))
        t1 = time.perf_counter()
        loc = main.localise(float(run.t_s[k]), frame)
        t_loc += time.perf_counter() - t1
        t_render += t1 - t0
        markers += sum(loc.seen)
        for name, localiser in localisers.items():
            r = loc if localiser is main else localiser.localise(float(run.t_s[k]), frame)
            if not r.found:
                continue
            assert r.com_m is not None and r.heading_rad is not None
            errors[name][0].append(float(np.linalg.norm(cal.to_px(r.com_m) - truth.com_px)))
            errors[name][1].append(
                math.degrees(abs(float(wrap_angle(r.heading_rad - truth.heading_rad))))
            )
            if localiser is main:
                found += 1
                rebuilt += r.status == "rebuilt"
                pos_mm.append(float(np.linalg.norm(r.com_m - truth.com_m)) * 1000.0)
    px, deg = errors["contour"]
    n = len(picks)
    centre = np.mean(run.states[:, robot.n_links : robot.n_links + 2], axis=0)
    return BenchResult(
        frames=n,
        found=found,
        rebuilt=rebuilt,
        markers_read=markers / (n * robot.n_links),
        pos_rms_px=_rms(px),
        pos_rms_mm=_rms(pos_mm),
        pos_max_px=max(px, default=float("nan")),
        heading_rms_deg=_rms(deg),
        heading_max_deg=max(deg, default=float("nan")),
        fps_localise=n / t_loc,
        fps_total=n / (t_render + t_loc),
        refine_compare={k: (_rms(v[0]), _rms(v[1]), len(v[0])) for k, v in errors.items()},
        pixel_mm=cal.pixel_size_m(centre) * 1000.0,
    )


def machine_description() -> str:
    """CPU model, Python and OpenCV versions, for the figures' provenance."""
    cpu = cpu_model()
    return (
        f"{cpu}, one core (cv2.setNumThreads(1)); Python {platform.python_version()}, "
        f"OpenCV {cv2.__version__}, {platform.system()} {platform.release()}"
    )


def figures_markdown(r: BenchResult, scenario: str, seed: int, machine: str) -> str:
    """The benchmark section of ``docs/vision.md``."""
    o = RenderOptions()
    rows = "\n".join(
        f"| {name} | {v[0]:.3f} | {v[1]:.2f} | {v[2]} / {r.frames} |"
        for name, v in r.refine_compare.items()
    )
    return f"""## Benchmark (synthetic frames)

`eelbot vision-bench --frames {r.frames} --scenario {scenario} --seed {seed}` rendered {r.frames}
frames of 1280 x 720 px, evenly spread over a closed-loop run of `{scenario}`, at
{r.pixel_mm:.2f} mm per pixel (the paper's camera), with a lighting gradient and vignette, a keystone
of 8 px, Gaussian blur (sigma {o.blur_sigma_px} px), Gaussian noise (sigma {o.noise_sigma} grey
levels) and JPEG re-encoding (quality {o.jpeg_quality}), and localised them with contour corner
refinement. Machine: {machine}.

| figure | measured | target |
|---|---|---|
| centre-of-mass error, rms | {r.pos_rms_px:.3f} px = {r.pos_rms_mm:.2f} mm | <= 0.5 px (2 mm) |
| centre-of-mass error, max | {r.pos_max_px:.3f} px | |
| heading error, rms | {r.heading_rms_deg:.2f} deg | <= 1 deg |
| heading error, max | {r.heading_max_deg:.2f} deg | |
| frames with a full pose | {r.found} / {r.frames} ({r.rebuilt} with a link rebuilt) | |
| markers read | {100 * r.markers_read:.1f} % | |
| localisation only | {r.fps_localise:.0f} frames/s | >= 60 frames/s |
| render + localise | {r.fps_total:.1f} frames/s | |

Corner refinement compared on the same frames (errors over the frames each found):

| refinement | position rms, px | heading rms, deg | full poses |
|---|---|---|---|
{rows}
"""


STATIC_DOC = """# Vision: localising the robot from printed markers

The host finds the robot in overhead camera frames from one printed ArUco marker per link
(`eelhost.vision`). Per frame it gives the time, the centre of mass (mean of the link centres),
the heading (mean link angle), the link angles it saw, and which markers it saw. A moving median
filter (the twin's `eelsim.camera.MedianFilter`, through `eelhost.vision.localise.filtered_poses`)
smooths the poses for the controller, as in the paper.

## Marker layout

| link | 1 (tail) | 2 | 3 | 4 | 5 | 6 (head) |
|---|---|---|---|---|---|---|
| ArUco id (`DICT_4X4_50`) | 0 | 1 | 2 | 3 | 4 | 5 |

- Black square 60 mm a side (6 x 6 cells of 10 mm: 4 x 4 data bits and a one-cell black border),
  on a white plate with a 5 mm quiet zone each side (plate 70 mm).
- Mount each plate flat and level, above the water, centred over its link, with the **right-hand
  edge of the printed marker towards the head**. A plate off-centre along the link is allowed: set
  `MarkerLayout.offsets_m` (positive towards the head).
- Why this size: at 3.8 mm per pixel the black square spans about 16 px (2.6 px a cell), about the
  smallest the detector reads reliably through blur, noise and JPEG; 70 mm plates on 107 mm links
  clear each other up to a joint angle of about 1 rad (the twin's path runs reach 0.99 rad). With a
  closer camera, larger plates are not needed; with a farther one, the markers fail first.
- All plates must be at one height: the calibration maps pixels to metres on that plane.

### Printing

```
.venv/bin/eelbot markers --out lab      # lab/markers.pdf, lab/charuco.pdf, lab/markers.json
```

The sheet (A4) holds the six plates with labels, an arrow to the head side and grey cut lines.
Each marker is drawn as its exact bit matrix over its printed extent (vector,
no resampling); `lab/markers.json` records the layout (dictionary, ids tail first, sizes, offsets)
and the board, and `calibrate`, `run` and `campaign` read it with `--markers`. Print at 100 %
("actual size", no fit to page) on matte paper (gloss reflects the lights), laminate
or seal it against water, and cut on the grey lines, keeping the white quiet zone. The printed size
does not enter the localisation (only each marker's centre and orientation do), so a small scaling
by the printer is harmless.

## Calibration (pixels to metres at the markers' height)

A calibration is a homography between the markers' plane and the image, optionally after undoing
the lens's distortion, saved as JSON (`eelhost.vision.calibration.save_calibration`;
`load_calibration` names the file and the key of anything malformed). `eelbot calibrate` makes one
from a frame of a camera (`--camera 0`, a video or an image folder) or an image (`--image`), prints
its reprojection error in pixels and millimetres and the pixel size, and `--check` measures an
existing one on a new frame. [host.md](host.md#4-calibration) gives the steps at the tank.

**From a ChArUco board (automatic).** The board of `eelbot markers` (`CharucoSpec`: 7 x 5 squares
of 110 mm, 80 mm markers, `DICT_4X4_50` ids 10 to 26, clear of the robot's; 770 x 550 mm, printed
on A1) lies flat at the markers' height at a known place: `--board-origin X,Y` is the outer corner
of its first square (the top-left of the printed board), `--board-angle` the direction of its
printed rows. The fit (`from_charuco`) is accurate over the board and less so far beyond it; use a
board covering much of the swimming area, or check it elsewhere.

**From the tank's corners.** Clicked on a local web page (`--click`) or given as pixels
(`--corners "U,V;U,V;U,V;U,V"`), in order: origin, along +x, opposite, along +y; `--tank-size`
or `--corners-m` their world coordinates (`from_tank_corners`). The corners are on the rim, not at
the markers' height: give the camera's height above the rim (`--camera-height`) and the markers'
height relative to it (`--marker-height`, negative when below), and the homography is corrected
exactly for a pinhole camera (scaling about the point under the camera: the point seen at the
image centre). Leave them out if the corners are at the markers' height.

**Lens distortion.** `--lens FOLDER` fits OpenCV's camera model (focal lengths, centre, radial
and tangential distortion) to views of the board at several poses (`calibrate_lens`); the
calibration then maps undistorted pixels, and the localiser undistorts the marker corners first.

## Localising

```python
from eelhost.vision.calibration import load_calibration
from eelhost.vision.localise import Localiser, filtered_poses, localise_frames
from eelhost.vision.sources import open_source
from eelsim.robot import load_robot

localiser = Localiser(load_calibration("calibration.json"), load_robot())
for t_s, pose in filtered_poses(localise_frames(localiser, open_source("run1/")), window=5):
    ...
```

`open_source` takes a camera index (`0`), a video file or a folder of images (natural order, times
index / `fps`); `SyntheticSource` renders twin states. A frame gives a pose (`status` `ok`) when
every marker is read; a single unread interior link is rebuilt from its neighbours' joints
(`rebuilt`); otherwise (tail or head unread, the robot partly out of view) there is no pose
(`partial` or `not_found`), and `message` names the missing links: the filter then holds the last
pose rather than use a biased one.

"""


def vision_doc(r: BenchResult, scenario: str, seed: int, machine: str) -> str:
    """The whole of ``docs/vision.md``: the static guide and the benchmark's figures."""
    return STATIC_DOC + figures_markdown(r, scenario, seed, machine)
