"""The virtual tank: the paper's experiments recorded from the twin instead of a real robot.

Each experiment runs the closed-loop twin (the *plant*) with a chosen *true* coefficient set (of
any fluid law: the truth's law is the plant's) and records what an overhead camera would: the
pixel-quantised pose at 30 fps through a median filter (the controller's causal one, or centred
as a recording filtered afterwards), with the time stamps' uncertainty (about 0.1 s in the paper)
modelled as a per-experiment clock offset drawn uniformly from [-jitter, +jitter], and a jittered
control period. The experiment ends when the robot reaches its last waypoint, as in the tank.

The tank's settings (:class:`TankSettings`) make the data harder than the model that will be
fitted to it (the dataset's robot file keeps the paper's model); the named test plants that use
them are :mod:`eelhost.data.plants` (docs/estimation.md, "Test plants"):

- a truth of another fluid law (e.g. a law the estimator does not fit);
- ``head_tail``: the true robot has a bulkier head (battery, electronics) and a slim pointed tail,
  while the dataset's robot file, used for fitting, keeps identical links;
- ``servo_limits``: the true joints obey the servos' torque-speed line (with
  ``servo_stall_torque_nm``, of a smaller servo than the robot file's: the paper's soft PD joints
  ask at most 2.6 % of its 1.26 N m, so its line never binds);
- ``joints``: the true joints are another joint model (e.g. stiff servos with lag), given as the
  robot file's ``[joints]`` table;
- ``stray_current_m_s``: a weak current that the metadata does not mention, in a random (seeded)
  direction drawn anew for every experiment, or with ``stray_current_direction_deg`` one steady
  current of the whole tank (the residual current of a lab tank, which estimation can fit as a
  nuisance: docs/estimation.md, "Nuisance parameters");
- ``median``: the recording's median filter is centred (declared in the camera facts, as a lab
  would declare it);
- water of a plant-only law (:mod:`eelhost.data.plant_laws`: lift and angle-of-attack drag, with
  or without added mass), which no candidate model contains.

Everything is deterministic for a seed.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from eelhost.data.experiments import (
    Experiment,
    manifest_text,
    write_experiment,
    write_manifest,
)
from eelhost.files import atomic_write
from eelsim.camera import CameraModel, observation_steps, observed_positions
from eelsim.closed_loop import LoopOptions, RunResult, simulate_closed_loop
from eelsim.fluid import FluidCoefficients
from eelsim.robot import HydroCoefficients, Robot, load_robot
from eelsim.scenario import TRAINING_CORNERS, Scenario, named_scenarios, paper_grid
from eelsim.timing import LoopTiming

log = logging.getLogger(__name__)

TABLE3: dict[str, FluidCoefficients] = {
    "straight": HydroCoefficients(C_f=0.008, C_d=0.776, C_a=0.618, C_m=0.007),
    "turning": HydroCoefficients(C_f=0.009, C_d=0.978, C_a=1.169, C_m=0.001),
}

# The mismatched robot's head and tail (per-link overrides of the true robot only).

MISMATCH_HEAD = {"half_axis_vertical_m": 0.032, "half_axis_horizontal_m": 0.026, "mass_kg": 0.33}
MISMATCH_TAIL = {"half_axis_vertical_m": 0.014, "half_axis_horizontal_m": 0.008, "mass_kg": 0.15}


@dataclass(frozen=True)
class TankSettings:
    """How the virtual tank records.

    Attributes
    ----------
    timestamp_jitter_s : float
        Half-width of the per-experiment clock offset.
    control_jitter_s : float
        Control-period jitter (whole physics steps).
    head_tail, servo_limits : bool
        Mismatch knobs (see the module docstring).
    stray_current_m_s : float
        Speed of the unmodelled current (0: none).
    stray_current_direction_deg : float, optional
        The direction it flows towards, the same in every experiment (default: a random one per
        experiment).
    pixel_m : float
        The camera's pixel size on the water (0: no rounding).
    median : {"causal", "centred"}
        The recording's median filter (the controller's is causal either way).
    joints : dict, optional
        The plant's ``[joints]`` table (a robot file's; e.g. another joint model), replacing the
        dataset robot's.
    servo_stall_torque_nm : float, optional
        With ``servo_limits``: the stall torque of the plant's servos, replacing the robot
        file's (the no-load speed stays).
    """

    timestamp_jitter_s: float = 0.1
    control_jitter_s: float = 0.03
    head_tail: bool = False
    servo_limits: bool = False
    stray_current_m_s: float = 0.0
    stray_current_direction_deg: float | None = None
    pixel_m: float = 0.0038
    median: str = "causal"
    joints: dict | None = None
    servo_stall_torque_nm: float | None = None

    def describe(self) -> dict[str, object]:
        """The plant's knobs by name (the manifest's ``[plant]`` table)."""
        out: dict[str, object] = {
            "timestamp_jitter_s": self.timestamp_jitter_s,
            "control_jitter_s": self.control_jitter_s,
            "head_tail": self.head_tail,
            "servo_limits": self.servo_limits,
            "stray_current_m_s": self.stray_current_m_s,
            "pixel_m": self.pixel_m,
            "median": self.median,
        }
        if self.stray_current_direction_deg is not None:
            out["stray_current_direction_deg"] = self.stray_current_direction_deg
        if self.joints:
            out["joint_model"] = str(self.joints.get("model", "pd"))
        if self.servo_stall_torque_nm is not None:
            out["servo_stall_torque_nm"] = self.servo_stall_torque_nm
        return out


def true_robot(robot: Robot, settings: TankSettings) -> Robot:
    """The robot that generates the data (the fitted robot plus the plant's differences)."""
    small_servo = settings.servo_limits and settings.servo_stall_torque_nm is not None
    if not settings.head_tail and not settings.joints and not small_servo:
        return robot
    data = robot.model_dump()
    if settings.head_tail:
        data["head"] = MISMATCH_HEAD
        data["tail"] = MISMATCH_TAIL
    if settings.joints:
        data["joints"] = dict(settings.joints)
        # the fitted robot's reasons for its own joint values do not describe the plant's joints
        data["assumptions"] = {key: why for key, why in data.get("assumptions", {}).items()
                               if key.removeprefix("joints.") == key
                               or key.removeprefix("joints.") in settings.joints}
    if small_servo:
        data["joints"] = {**data["joints"], "servo_max_torque_nm": settings.servo_stall_torque_nm}
    return Robot.model_validate(data)


def paper_experiment_plan() -> list[tuple[str, str, Scenario]]:
    """(motion, split, scenario) for the paper's 32 experiments and its two paths."""
    plan = []
    for motion in ("straight", "turning"):
        for s in paper_grid(motion):
            corner = (s.amplitude_rad, s.omega_rad_s) in TRAINING_CORNERS
            plan.append((motion, "train" if corner else "test", s))
    names = named_scenarios()
    plan += [("path", "path", names["path1"]), ("path", "path", names["path2"])]
    return plan


def record_experiment(
    robot: Robot,
    scenario: Scenario,
    motion: str,
    truth: FluidCoefficients,
    settings: TankSettings,
    seed: int,
) -> Experiment:
    """Run one experiment in the virtual tank and return what the camera recorded.

    Parameters
    ----------
    robot : Robot
        The robot file of the dataset (the true robot adds the mismatch knobs).
    scenario : Scenario
        The task.
    motion : str
        "straight", "turning" or "path".
    truth : FluidCoefficients
        The true coefficients.
    settings : TankSettings
    seed : int
        Seeds the control jitter, the clock offset and the stray current.

    Returns
    -------
    Experiment
    """
    rng = np.random.default_rng(seed)
    offset_s = float(rng.uniform(-settings.timestamp_jitter_s, settings.timestamp_jitter_s))
    task = scenario
    if settings.stray_current_m_s > 0:
        a = rng.uniform(0, 2 * np.pi)  # drawn either way: the later draws stay the same
        if settings.stray_current_direction_deg is not None:
            a = np.radians(settings.stray_current_direction_deg)
        task = scenario.with_added_current(
            (settings.stray_current_m_s * np.cos(a), settings.stray_current_m_s * np.sin(a))
        )
    timing = LoopTiming(control_period_s=0.3, jitter_s=settings.control_jitter_s)
    camera = CameraModel(pixel_m=settings.pixel_m, median=settings.median)
    options = LoopOptions(timing=timing, camera=camera, servo_limits=settings.servo_limits)
    run = simulate_closed_loop(
        true_robot(robot, settings),
        task,
        options,
        seed=int(rng.integers(2**31)),
        coefficients=truth,
    )
    frames = run.camera_t_s <= (run.t_s[-1] + 1e-9)
    if camera.median == "centred":
        # filtered afterwards from the stored states: a frame between the run's last two steps
        # cannot be interpolated, and the recording ends before it
        frames &= run.camera_t_s <= run.t_s[-1] - timing.dt_s + 1e-9
    t_frames = run.camera_t_s[frames]
    position, heading = _recorded(run, t_frames, camera, timing.dt_s)
    return Experiment(
        name=scenario.name,
        t_s=t_frames + offset_s,
        position_m=position,
        heading_rad=heading,
        scenario=scenario,
        motion=motion,
        camera={
            "fps": camera.fps,
            "pixel_m": camera.pixel_m,
            "median_window": camera.median_window,
            "median": camera.median,
            "timestamp_jitter_s": settings.timestamp_jitter_s,
        },
        timing={
            "control_period_s": timing.control_period_s,
            "extra_delay_s": 0.0,
            "jitter_s": timing.jitter_s,
        },
        source={
            "virtual_tank": True,
            "truth": truth.model_dump(),
            "seed": seed,
            "clock_offset_s": offset_s,
            "outcome": run.failure.name,
            "plant": {"fluid_law": type(truth).law_name, **settings.describe()},
        },
    )


def _recorded(
    run: RunResult, t_frames: np.ndarray, camera: CameraModel, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """What the recording holds at each frame: the controller's causal view, or centred.

    A centred median is the recording filtered afterwards: the same pixel-rounded frames
    (:func:`eelsim.camera.observed_positions` reproduces the closed loop's camera), each the
    median of the frames around it, none after the last. The heading goes through the same
    filter (unrounded: the camera measures it as an angle).
    """
    if camera.median == "causal":
        return run.camera_pose[: t_frames.size, :2], run.camera_pose[: t_frames.size, 2]
    n = (run.states.shape[1] - 4) // 2
    last = float(t_frames[-1])
    steps = observation_steps(t_frames, camera, dt_s, last)
    steps = steps[steps < len(run.states)]
    st = run.states[steps]
    position = observed_positions(t_frames, steps, st[:, n : n + 2], st[:, -2:], camera, dt_s,
                                  last)
    # the heading as a 2-vector (heading, 0) through the same filter, without pixel rounding
    angle = np.column_stack([st[:, :n].mean(axis=1), np.zeros(len(st))])
    rate = np.column_stack([st[:, n + 2 : 2 * n + 2].mean(axis=1), np.zeros(len(st))])
    unrounded = dataclasses.replace(camera, pixel_m=0.0)
    heading = observed_positions(t_frames, steps, angle, rate, unrounded, dt_s, last)[:, 0]
    return position, heading


def _record_job(args: tuple) -> Experiment:
    return record_experiment(*args)


def generate_dataset(
    folder: str | Path,
    robot: Robot | None = None,
    truth: dict[str, FluidCoefficients] | None = None,
    settings: TankSettings | None = None,
    seed: int = 0,
    workers: int = 2,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Generate the paper's 32 experiments and two paths into a dataset folder.

    Parameters
    ----------
    folder : str or Path
        Output folder (created).
    robot : Robot, optional
        The dataset's robot (default: the bundled paper robot).
    truth : dict, optional
        True coefficients per motion type ("straight", "turning"; paths use "turning").
        Default: the paper's table 3.
    settings : TankSettings, optional
    seed : int
        Master seed; experiment i uses seed + i.
    workers : int
        Parallel processes.
    progress : callable, optional
        ``progress(done, total)``.

    Returns
    -------
    Path
        The manifest's path.
    """
    folder = Path(folder)
    robot = robot or load_robot()
    truths = truth or TABLE3
    settings = settings or TankSettings()
    plan = paper_experiment_plan()
    jobs = [
        (robot, s, motion, truths["turning" if motion == "path" else motion], settings, seed + i)
        for i, (motion, _split, s) in enumerate(plan)
    ]
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write(folder / "robot.toml", _robot_file_text(robot))
    done = 0
    log.info("recording %d virtual-tank experiments into %s", len(jobs), folder)
    with ProcessPoolExecutor(max_workers=max(1, workers)) as pool:
        for exp in pool.map(_record_job, jobs):
            write_experiment(exp, folder)
            done += 1
            if progress:
                progress(done, len(jobs))
    motions: dict[str, dict[str, list[str]]] = {}
    for motion, split, s in plan:
        if motion != "path":
            motions.setdefault(motion, {"train": [], "test": []})[split].append(s.name)
    plant = {"fluid_law": type(truths["straight"]).law_name, **settings.describe()}
    desc = f"virtual tank, seed {seed}, plant " + ", ".join(f"{k}={v}" for k, v in plant.items())
    return write_manifest(
        folder,
        manifest_text(
            "robot.toml",
            motions,
            ["path1", "path2"],
            {"straight": truths["straight"], "turning": truths["turning"]},
            desc,
            plant,
        ),
    )


def _robot_file_text(robot: Robot) -> str:
    """The robot as a TOML file (the bundled file when unchanged, so comments survive)."""
    bundled = resources.files("eelsim.data").joinpath("paper_robot.toml").read_text()
    if robot == load_robot():
        return bundled
    return _to_toml(robot.model_dump(exclude_none=True))


def _to_toml(data: dict, prefix: str = "") -> str:
    scalars = [(k, v) for k, v in data.items() if not isinstance(v, dict)]
    tables = [(k, v) for k, v in data.items() if isinstance(v, dict)]
    out = [f'"{k}" = {_toml_value(v)}' for k, v in scalars]
    for k, v in tables:
        out += ["", f"[{prefix}{k}]", _to_toml(v, f"{prefix}{k}.").strip()]
    return "\n".join(out) + "\n"


def _toml_value(v: object) -> str:
    if isinstance(v, str):
        return '"' + v.replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v)
