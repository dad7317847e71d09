"""How close the tank's body state estimate comes to the truth, with and without the telemetry.

The run loop of ``eelbot run`` (:class:`eelhost.field.runloop.RunLoop`) steers the virtual robot
of ``sim://`` (the native firmware and the twin's plant, docs/host.md "The virtual robot and
replays") along a scenario's waypoints, filmed by the synthetic camera. Its navigator only
estimates: one :class:`~eelhost.planning.state_estimate.BodyStateEstimator` is handed every
Telemetry (as :class:`eelhost.planning.replan.TankReplanner`'s is), one sees the camera alone.
Each frame's estimate is compared with the plant's true state at the frame's time: the RMS of the
joint angles' error (the body's shape) and of the link rates' error.

Command (docs/planning.md, "The robot's state at the tank", has its figures)::

    .venv/bin/python -m eelhost.benchmarks.state_estimate --scenario path1 --duration 15
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from eelhost.field.runloop import RunConfig, RunLoop
from eelhost.link import open_link
from eelhost.planning.geometry import FloatArray
from eelhost.planning.state_estimate import BodyStateEstimator
from eelhost.vision.localise import Localisation, Localiser
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera, TankView
from eelhost.wire import protocol
from eelhost.xil.virtual_robot import VirtualCamera, VirtualRobot
from eelsim.control import Gait
from eelsim.model import SwimmerModel
from eelsim.robot import Robot, load_robot
from eelsim.scenario import load_scenario

__all__ = ["EstimateErrors", "EstimatingNavigator", "main", "measure"]


@dataclass
class _Go:
    """The navigator's answer: go on (:class:`eelhost.field.runloop.Decision`)."""

    waypoints: list[tuple[float, float]] | None = None
    guide: tuple[float, float, float, float] | None = None
    stop: str | None = None
    detail: str = ""
    arrived: bool = False
    recorded: bool = False


class EstimatingNavigator:
    """A navigator that only estimates: one estimator given the Telemetry, one the camera alone.

    Parameters
    ----------
    model : SwimmerModel
    gait : Gait
    """

    replans = 0

    def __init__(self, model: SwimmerModel, gait: Gait) -> None:
        self.n_links = model.n_links
        self.with_telemetry = BodyStateEstimator(model, gait)
        self.camera_only = BodyStateEstimator(model, gait, use_reference=False)
        #: (t, state with telemetry, state camera only, joint source) of every estimated frame
        self.rows: list[tuple[float, FloatArray, FloatArray, str]] = []
        self.telemetry = 0

    def on_telemetry(self, t_received_s: float, msg: protocol.Telemetry,
                     t_polled_before_s: float | None = None) -> None:
        """Hand the Telemetry to the estimator that takes it."""
        self.telemetry += 1
        self.with_telemetry.add_telemetry(t_received_s, msg, t_polled_before_s)

    def on_frame(self, t_s: float, loc: Localisation, pose: FloatArray | None, target: int,
                 offset_rad: float, guide: tuple[float, float, float, float] | None = None) -> _Go:
        """Estimate with both; never switch, stop or arrive."""
        if loc.found and loc.com_m is not None:
            for est in (self.with_telemetry, self.camera_only):
                est.observe(t_s, loc.com_m, loc.link_angles_rad, offset_rad)
            a, b = self.with_telemetry.estimate(), self.camera_only.estimate()
            if a is not None and b is not None:
                self.rows.append((t_s, a.state, b.state, a.joint_source))
        return _Go()

    def pace(self, t_s: float) -> None:
        """Nothing runs beside the loop."""

    def close(self) -> None:
        """Nothing to stop."""

    def record(self) -> dict[str, Any]:
        """Nothing to record."""
        return {}


class _TruthKeepingFrames:
    """The virtual camera's frames, keeping the plant's true state at each frame's time."""

    def __init__(self, robot: VirtualRobot, camera: VirtualCamera) -> None:
        self.robot, self.camera = robot, camera
        self.truth: dict[float, FloatArray] = {}

    def __iter__(self) -> Iterator[tuple[float, NDArray[np.uint8]]]:
        for t, frame in self.camera:
            self.truth[round(t, 6)] = self.robot.state_at(t).copy()
            yield t, frame


@dataclass
class EstimateErrors:
    """RMS errors of the estimates against the plant (frames from ``after_s`` on).

    Attributes
    ----------
    frames : int
    telemetry : int
        Telemetry messages handed over.
    joint_rad : dict
        ``with_telemetry`` and ``camera``: RMS of the joint angles' error.
    link_rate_rad_s : dict
        The same for the link angles' rates.
    sources : dict
        Frames by the estimate's joint source.
    ignored : dict
        Telemetry ignored, by reason.
    outcome : str
        How the run ended.
    bend_rad : float
        The largest spread of the true link angles over the frames (a bent body: > 0).
    """

    frames: int
    telemetry: int
    joint_rad: dict[str, float] = field(default_factory=dict)
    link_rate_rad_s: dict[str, float] = field(default_factory=dict)
    sources: dict[str, int] = field(default_factory=dict)
    ignored: dict[str, int] = field(default_factory=dict)
    outcome: str = ""
    bend_rad: float = 0.0


def measure(robot: Robot, scenario: str, feedback: bool, duration_s: float = 15.0,
            noisy: bool = False, seed: int = 0, after_s: float = 1.5,
            tank_m: tuple[float, float] | None = None) -> EstimateErrors:
    """Run the loop over ``sim://`` with the estimating navigator; compare with the plant.

    Parameters
    ----------
    robot : Robot
    scenario : str
        A named scenario (its gait and waypoints).
    feedback : bool
        Feedback servos (``sim://?feedback=1``: the firmware measures and sends its joints).
    duration_s : float
    noisy : bool
        The synthetic camera's noise and JPEG (default rendering); False: blur only.
    seed : int
        The radio's and the camera's seed.
    after_s : float
        Frames before this are left out (the gait starting).
    tank_m : (float, float), optional
        The camera films a tank this size whole (:meth:`TankView.covering`, as ``eelbot run
        --plan`` films a world's tank over ``sim://``); default: the paper's tank view.

    Returns
    -------
    EstimateErrors
    """
    sc = load_scenario(scenario)
    model = SwimmerModel.from_robot(robot)
    n = model.n_links
    link = open_link(f"sim://?speed=0&seed={seed}&feedback={int(feedback)}", robot=robot)
    virtual = getattr(link.transport, "robot", None)
    if not isinstance(virtual, VirtualRobot):
        raise TypeError("sim:// gave no virtual robot")
    options = RenderOptions() if noisy else RenderOptions(noise_sigma=0.0, jpeg_quality=0)
    view = TankView.covering(tank_m) if tank_m is not None else None
    cam = SyntheticCamera(robot, options=options, seed=seed, view=view)
    frames = _TruthKeepingFrames(virtual, VirtualCamera(virtual, cam, keep_truth=False))
    nav = EstimatingNavigator(model, sc.gait)
    out = RunLoop(link, frames, Localiser(cam.calibration(), robot), robot,
                  RunConfig(sc.gait, list(sc.waypoints_m), duration_s=duration_s), None,
                  navigator=nav).run()
    joint: dict[str, list[FloatArray]] = {"with_telemetry": [], "camera": []}
    rate: dict[str, list[FloatArray]] = {"with_telemetry": [], "camera": []}
    sources: dict[str, int] = {}
    bend = 0.0
    for t, a, b, source in nav.rows:
        if t < after_s:
            continue
        x = frames.truth[round(t, 6)]
        bend = max(bend, float(np.ptp(x[:n])))
        for key, s in (("with_telemetry", a), ("camera", b)):
            joint[key].append(np.diff(s[:n]) - np.diff(x[:n]))
            rate[key].append(s[n + 2 : 2 * n + 2] - x[n + 2 : 2 * n + 2])
        sources[source] = sources.get(source, 0) + 1

    def rms(v: list[FloatArray]) -> float:
        return float(np.sqrt(np.mean(np.square(v)))) if v else float("nan")

    return EstimateErrors(
        frames=len(joint["camera"]), telemetry=nav.telemetry,
        joint_rad={k: rms(v) for k, v in joint.items()},
        link_rate_rad_s={k: rms(v) for k, v in rate.items()}, sources=sources,
        ignored=dict(nav.with_telemetry.telemetry.ignored), outcome=out.reason, bend_rad=bend)


def main(argv: Sequence[str] | None = None) -> int:
    """Print one Markdown table row per case (the command in the module docstring).

    Returns
    -------
    int
        Exit status.
    """
    parser = argparse.ArgumentParser(prog="python -m eelhost.benchmarks.state_estimate",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", action="append", help="named scenario (repeat); path1")
    parser.add_argument("--robot", action="append", help="robot file (repeat); the bundled one")
    parser.add_argument("--feedback", action="append", type=int, choices=(0, 1),
                        help="feedback servos 1 or 0 (repeat); both")
    parser.add_argument("--duration", type=float, default=15.0, help="seconds of each run")
    parser.add_argument("--noisy", action="store_true", help="the camera's noise and JPEG on")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tank", help="W,H: the camera films a tank this size whole, m")
    args = parser.parse_args(argv)
    tank: tuple[float, float] | None = None
    if args.tank:
        try:
            w, h = (float(v) for v in args.tank.split(","))
        except ValueError:
            parser.error(f"--tank {args.tank!r}: expected W,H in metres")
        tank = (w, h)
    print("| scenario | robot | camera | feedback servos | frames | joint angles RMS, with the "
          "telemetry / camera alone (rad) | link rates RMS, with / alone (rad/s) | sources | "
          "ignored | run |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for scenario in args.scenario or ["path1"]:
        for robot_file in args.robot or [None]:
            robot = load_robot(robot_file) if robot_file else load_robot()
            for feedback in args.feedback or [1, 0]:
                e = measure(robot, scenario, bool(feedback), args.duration, args.noisy, args.seed,
                            tank_m=tank)
                camera = ("noisy" if args.noisy else "clean") + (f", {args.tank} m tank"
                                                                   if args.tank else "")
                print(f"| {scenario} | {robot_file or 'bundled'} | {camera} | {feedback} | "
                      f"{e.frames} | "
                      f"{e.joint_rad['with_telemetry']:.4f} / {e.joint_rad['camera']:.4f} | "
                      f"{e.link_rate_rad_s['with_telemetry']:.3f} / "
                      f"{e.link_rate_rad_s['camera']:.3f} | {e.sources} | {e.ignored} | "
                      f"{e.outcome} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
