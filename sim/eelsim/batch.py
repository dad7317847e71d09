"""Fast batched closed-loop rollouts: many runs of the twin in one call, on all cores.

This is the fast path of the physics and control stack whose readable reference is
:func:`eelsim.closed_loop.simulate_closed_loop`; the tests (``sim/tests/test_batch.py``) check that
both agree to 1e-9 (states at sample times, arrival times, flags, failure times).

Use
---
>>> from eelsim.batch import run_batch
>>> res = run_batch(robot, [scenario_a, scenario_b], coefficients=[[0.008, 0.776, 0.618, 0.007],
...                 [0.009, 0.978, 1.169, 0.001]], sample_times_s=[0.0, 5.0, 10.0])
>>> res.states.shape          # (runs, samples, 2 N + 4)
>>> res.arrival_time_s, res.failure, res.reason(0)

Every per-run input (robot, scenario, coefficients, seed) may be a single value, shared by all
runs, or a sequence with one entry per run. Robots may differ in gains, limits and per-link values
but must have the same number of links. Loop options (timing, camera, servo model, stopping rule)
are shared by the batch.

How it is fast
--------------
Runs are grouped in blocks of ``lanes`` runs that advance in lock step, with the per-run data laid
out as structure of arrays (one row of ``lanes`` numbers per quantity). The right-hand side of the
dynamics is generated as straight-line code for the robot's N (``eelsim._batch_codegen``) inside
one loop over the lanes, which LLVM vectorises (4 runs per AVX2 instruction); the accelerations
come from an O(N) articulated-body recursion rather than the dense mass matrix, and the RK4 sums,
the finiteness checks and the condition-number bound at control updates are generated code too.
Blocks are spread over the cores by numba's threads, each taking the next block from a shared
counter when it finishes one (longest blocks first, so that the cores end together). The kernel
module is generated once per (N, lanes) and compiled once: numba caches it on disk (next to the
package in ``__pycache__``, or in ``$EELSIM_KERNEL_CACHE``) for every later process.

The generated RK4 stage (about 85 % of a step) is by default translated to C and compiled by the
machine's C compiler (``eelsim._batch_c``), whose schedule of its long straight-line loops runs
about 15 % faster than LLVM's here; numba compiles the same generated text when there is no C
compiler, or when ``stage="numba"`` / ``$EELSIM_STAGE=numba`` asks for it
(:func:`stage_backend`). Both agree to rounding (tested).

Randomness follows the reference exactly: for each run, ``np.random.default_rng(seed)`` draws
first the control update schedule (:meth:`eelsim.timing.LoopTiming.update_steps`), then one heading
noise sample per camera frame when ``heading_noise_rad > 0``. These draws are made here in Python;
the kernel is deterministic.

Memory: per run, only the requested samples, the final state and the flags are kept; the full
state history is stored only with ``record_full=True``.
"""

from __future__ import annotations

import enum
import importlib.util
import math
import os
import sys
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelsim import _batch_c, _batch_codegen
from eelsim.closed_loop import LoopOptions
from eelsim.flags import DIVERGENCE_RATE, ILL_CONDITION_THRESHOLD, Failure, penalty
from eelsim.model import geometry_matrix
from eelsim.robot import HydroCoefficients, Robot
from eelsim.scenario import Scenario

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

DEFAULT_LANES = 16
"""Runs per block (4 AVX2 vectors). Measured on the 2-core machine (docs/kernel_history.md): 8
lanes spend more of each step in the per-block driver, 32 gain nothing measurable, and longer
blocks waste more work on runs that stopped early while others in the block continue."""


class Reason(enum.IntEnum):
    """Why a run was flagged; :meth:`BatchResult.reason` turns it into the reference's text."""

    NONE = 0
    TOO_SLOW = 1
    NOT_FINITE = 2
    NOT_POSITIVE_DEFINITE = 3
    CONDITION_NUMBER = 4
    JOINT_LIMIT = 5
    LINKS_INTERSECT = 6
    DIVERGED = 7


# ---------------------------------------------------------------------------------------------
# the compiled kernel


_KERNELS: dict[tuple[int, int, str], object] = {}

STAGE_ENV = "EELSIM_STAGE"
"""Environment variable choosing how the generated stage is compiled: ``c``, ``numba`` or ``auto``."""
STAGES = ("auto", "c", "numba")
_C_FUNCTIONS = ("_stage",)  # the generated functions compiled as C when the stage is "c"
_C_UNAVAILABLE: list[str] = []  # why "auto" fell back to numba (said once per process)


def stage_backend(stage: str | None = None) -> str:
    """Resolve how the generated RK4 stage is compiled: ``"c"`` or ``"numba"``.

    ``"c"``: translated to C and compiled by the machine's C compiler (``eelsim._batch_c``; about
    15 % faster here); ``"numba"``: by numba/LLVM like the rest of the kernel. ``"auto"`` (the
    default, or ``$EELSIM_STAGE``) takes C when a compiler is found.

    Parameters
    ----------
    stage : str, optional
        ``"auto"``, ``"c"`` or ``"numba"``; default ``$EELSIM_STAGE`` or ``"auto"``.

    Returns
    -------
    str
        ``"c"`` or ``"numba"``.

    Raises
    ------
    ValueError
        An unknown choice (naming where it came from).
    """
    stage = _requested_stage(stage)
    if stage == "auto":
        return "c" if _batch_c.find_compiler() is not None and not _C_UNAVAILABLE else "numba"
    return stage


def _requested_stage(stage: str | None) -> str:
    """The choice as given (argument, else ``$EELSIM_STAGE``, else auto), checked."""
    where = "stage"
    if stage is None:
        stage, where = os.environ.get(STAGE_ENV, "auto"), f"${STAGE_ENV}"
    if stage not in STAGES:
        raise ValueError(f"{where} must be one of {', '.join(STAGES)}; got {stage!r}")
    return stage


def kernel_cache_dir() -> Path:
    """Directory holding the generated kernel sources and numba's on-disk cache of them.

    ``$EELSIM_KERNEL_CACHE`` when set, else ``__pycache__/batch_kernels`` beside this module (git
    ignores ``__pycache__``), else ``~/.cache/eelsim/batch_kernels`` if the package is read-only.

    Returns
    -------
    Path
    """
    env = os.environ.get("EELSIM_KERNEL_CACHE")
    if env:
        return Path(env)
    here = Path(__file__).resolve().parent / "__pycache__" / "batch_kernels"
    try:
        here.mkdir(parents=True, exist_ok=True)
        probe = here / ".writable"
        probe.touch()
        return here
    except OSError:
        return Path.home() / ".cache" / "eelsim" / "batch_kernels"


def _kernel_source(n_links: int, lanes: int, template: str | None = None,
                   generator: ModuleType | None = None, stage: str = "numba") -> str:
    """The kernel module's text: the driver template with the generated part appended.

    ``template`` (the text of ``_batch_kernel.py``) and ``generator`` (a module like
    ``_batch_codegen``) default to this package's; scripts/kernel_ab.py passes other versions.
    ``stage="c"`` compiles the generated stage as C (``eelsim._batch_c``, raising its
    ``CStageError``) and appends the binding that makes ``_stage`` call it.
    """
    if template is None:
        template = (Path(__file__).parent / "_batch_kernel.py").read_text()
    generator = _batch_codegen if generator is None else generator
    for name, value in (
        ("ILL_CONDITION_THRESHOLD = 1e10", ILL_CONDITION_THRESHOLD),
        ("DIVERGENCE_RATE = 1e3", DIVERGENCE_RATE),
    ):
        if name not in template:
            raise RuntimeError(f"kernel template lost its line {name!r}")
        template = template.replace(name, f"{name.split(' = ')[0]} = {value!r}")
    layout = generator.make_layout(n_links, lanes)
    generated = generator.generate_stage_source(layout)
    if stage == "numba":
        return template + generated
    library, symbols = _batch_c.build(generated, _C_FUNCTIONS, kernel_cache_dir())
    return template + generated + _batch_c.binding_source(library, symbols, generated)


def load_kernel_source(name: str, source: str) -> ModuleType:
    """Write a kernel module's text to :func:`kernel_cache_dir` and import it as ``name``.

    The file is rewritten only when the text changed, so numba's cache (keyed on the file's
    time stamp) stays valid across processes.

    Parameters
    ----------
    name : str
        Module name (also the file's stem).
    source : str
        The module's text.

    Returns
    -------
    module
    """
    folder = kernel_cache_dir()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.py"
    if not path.exists() or path.read_text() != source:
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(source)
        os.replace(tmp, path)  # atomic: concurrent processes never see half a file
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    # numba's cache re-imports the module by name when it loads compiled code
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def kernel_module(n_links: int, lanes: int = DEFAULT_LANES, stage: str | None = None):
    """Return the compiled-on-demand kernel module for N links and ``lanes`` runs per block.

    The module's source is written to :func:`kernel_cache_dir` (:func:`load_kernel_source`).

    Parameters
    ----------
    n_links : int
        N.
    lanes : int
        Runs per block (a multiple of 4, so that the lane loops vectorise).
    stage : str, optional
        How the generated stage is compiled (:func:`stage_backend`). With ``"auto"`` a C
        compiler that fails is reported once as a warning and numba compiles the stage instead;
        an explicit ``"c"`` raises the compiler's error.

    Returns
    -------
    module
    """
    requested = _requested_stage(stage)
    stage = stage_backend(requested)
    key = (n_links, lanes, stage)
    if key in _KERNELS:
        return _KERNELS[key]
    if lanes < 4 or lanes % 4:
        raise ValueError(f"lanes must be a positive multiple of 4 (vectors), got {lanes}")
    try:
        source = _kernel_source(n_links, lanes, stage=stage)
    except _batch_c.CStageError as exc:
        if requested != "auto":
            raise
        _C_UNAVAILABLE.append(str(exc))
        warnings.warn(f"the batched kernel's C stage is unavailable, numba compiles it: {exc}",
                      RuntimeWarning, stacklevel=2)
        return kernel_module(n_links, lanes, "numba")
    suffix = "_c" if stage == "c" else ""
    module = load_kernel_source(f"eelsim_batch_kernel_n{n_links}_l{lanes}{suffix}", source)
    _KERNELS[key] = module
    return module


def warm_up(n_links: int = 6, lanes: int = DEFAULT_LANES, stage: str | None = None) -> float:
    """Compile (or load from the disk cache) the kernel for N links; return the seconds it took.

    Parameters
    ----------
    n_links : int
        N.
    lanes : int
        Runs per block.
    stage : str, optional
        How the stage is compiled (:func:`stage_backend`).

    Returns
    -------
    float
        Wall time of loading or compiling, s.
    """
    from eelsim.robot import load_robot
    from eelsim.scenario import load_scenario

    start = time.perf_counter()
    robot = load_robot()
    if robot.n_links != n_links:
        robot = robot.model_copy(update={"n_links": n_links})
    scenario = load_scenario("straight").model_copy(update={"duration_s": 0.05})
    run_batch(robot, scenario, lanes=lanes, sample_steps=[0], stage=stage)
    return time.perf_counter() - start


# ---------------------------------------------------------------------------------------------
# inputs


@dataclass(frozen=True)
class BatchSpec:
    """Everything the kernel needs, as arrays with one row per run (R runs, N links).

    Build it with :meth:`build`; :meth:`with_coefficients` swaps the hydrodynamic coefficients
    cheaply (what estimation does generation after generation).

    Attributes
    ----------
    n_links : int
        N, shared by the batch.
    params : ndarray, shape (R, P)
        Per-run constants in the kernel's row order (geometry, fluid coefficients, gait, gains,
        current; see ``eelsim._batch_codegen.make_layout``).
    initial_state : ndarray, shape (R, 2 N + 4)
        Straight robot at rest at the scenario's start pose.
    total_steps : ndarray of int, shape (R,)
        floor(T_max / dt).
    goal_steps : ndarray of int, shape (R,)
        With ``options.stop_at_goal``, the first step at which reaching the goal ends the run
        (``Scenario.goal_steps``).
    waypoints_m : ndarray, shape (R, W, 2)
        Waypoints, padded (repeating the last one) to the longest list.
    n_waypoints : ndarray of int, shape (R,)
    acceptance_radius_m, k_theta : ndarray, shape (R,)
    delay_steps : ndarray of int, shape (R,)
    update_steps : ndarray of int, shape (R, U)
        Control update schedule of each run (from its seed), padded with -1.
    update_count : ndarray of int, shape (R,)
    heading_noise_rad : ndarray, shape (R, F) or (R, 0)
        Heading noise of each camera frame (from the seed), empty without noise.
    frame_step, frame_fraction, frame_time_s : ndarray, shape (F,)
        Camera frames: the step k whose interval (t_k, t_k + dt] holds the frame, the fraction of
        the step, and the frame's time (frame 0 is seen at t = 0 before the first step).
    options : LoopOptions
        The shared loop options.
    half_length_m, half_axis_vertical_m, half_axis_horizontal_m, yaw_inertia_kg_m2 : ndarray
        Per-run, per-link geometry and inertia, kept to recompute the fluid coefficients.
    density_kg_m3 : ndarray, shape (R,)
    coefficients : ndarray, shape (R, 4)
        (C_f, C_d, C_a, C_m) of each run.
    duration_s : ndarray, shape (R,)
        T_max of each run (for messages).
    joint_limit_rad : ndarray, shape (R,)
    """

    n_links: int
    params: FloatArray
    initial_state: FloatArray
    total_steps: IntArray
    goal_steps: IntArray
    waypoints_m: FloatArray
    n_waypoints: IntArray
    acceptance_radius_m: FloatArray
    k_theta: FloatArray
    delay_steps: IntArray
    update_steps: IntArray
    update_count: IntArray
    heading_noise_rad: FloatArray
    frame_step: IntArray
    frame_fraction: FloatArray
    frame_time_s: FloatArray
    options: LoopOptions
    half_length_m: FloatArray
    half_axis_vertical_m: FloatArray
    half_axis_horizontal_m: FloatArray
    yaw_inertia_kg_m2: FloatArray
    density_kg_m3: FloatArray
    coefficients: FloatArray
    duration_s: FloatArray
    joint_limit_rad: FloatArray

    @property
    def n_runs(self) -> int:
        """Number of runs R."""
        return int(self.initial_state.shape[0])

    @classmethod
    def build(
        cls,
        robots: Robot | Sequence[Robot],
        scenarios: Scenario | Sequence[Scenario],
        coefficients: ArrayLike | HydroCoefficients | Sequence[HydroCoefficients] | None = None,
        options: LoopOptions | None = None,
        seeds: int | ArrayLike = 0,
    ) -> BatchSpec:
        """Lay out a batch of runs.

        Parameters
        ----------
        robots : Robot or sequence of Robot
            One robot for all runs, or one per run (same number of links).
        scenarios : Scenario or sequence of Scenario
            One scenario for all runs, or one per run.
        coefficients : array_like (R, 4) or (4,), HydroCoefficients or a sequence of them, optional
            (C_f, C_d, C_a, C_m) per run; default: each robot's own.
        options : LoopOptions, optional
            Shared by all runs.
        seeds : int or array_like of int
            Seed of each run's jitter and heading noise (as ``simulate_closed_loop``'s ``seed``).

        Returns
        -------
        BatchSpec

        Raises
        ------
        ValueError
            When per-run sequences have different lengths or robots differ in N.
        """
        opts = options or LoopOptions()
        robot_list = [robots] if isinstance(robots, Robot) else list(robots)
        scen_list = [scenarios] if isinstance(scenarios, Scenario) else list(scenarios)
        coeff_arr = _coefficient_array(coefficients)
        seed_arr = np.atleast_1d(np.asarray(seeds, dtype=np.int64))
        sizes = {len(robot_list), len(scen_list), seed_arr.shape[0]}
        if coeff_arr is not None:
            sizes.add(coeff_arr.shape[0])
        sizes.discard(1)
        if len(sizes) > 1:
            raise ValueError(f"per-run inputs have different lengths: {sorted(sizes)}")
        n_runs = sizes.pop() if sizes else 1
        if not robot_list or not scen_list:
            raise ValueError("a batch needs at least one robot and one scenario")
        n = robot_list[0].n_links
        if any(rb.n_links != n for rb in robot_list):
            raise ValueError("all robots of a batch must have the same number of links")

        # per-run inputs are often a few objects repeated (estimation: every candidate on the
        # same experiments): their arrays are computed once per distinct object
        robot_list, robot_idx = _distinct(robot_list, n_runs)
        scen_list, scen_idx = _distinct(scen_list, n_runs)
        seed_of = np.broadcast_to(seed_arr, (n_runs,))
        timing, camera = opts.timing, opts.camera
        dt = timing.dt_s

        # -- robots: per-link geometry, gains (computed once per distinct robot)
        rob = [_robot_arrays(rb, opts) for rb in robot_list]
        per_robot = {k: np.stack([r[k] for r in rob]) for k in rob[0]}
        rsel = {k: v[robot_idx] for k, v in per_robot.items()}
        if coeff_arr is None:
            coeff_arr = np.stack([rb.hydrodynamics.as_array() for rb in robot_list])[robot_idx]
        coeff_arr = np.broadcast_to(coeff_arr, (n_runs, 4)).astype(float)

        # -- scenarios
        sc = [_scenario_arrays(s, n, dt) for s in scen_list]
        n_wp_max = max(len(s.waypoints_m) for s in scen_list)
        wp = np.stack([_pad_waypoints(s.waypoints_m, n_wp_max) for s in scen_list])[scen_idx]
        ssel = {k: np.stack([d[k] for d in sc])[scen_idx] for k in sc[0]}
        total = ssel["total_steps"].astype(np.int64)

        # -- camera frames, shared by all runs (the same dt and fps), for the longest run
        frame_step, frame_fraction, frame_time = _frame_table(int(total.max()), dt, camera.fps)

        # -- random draws, per distinct (seed, total) as the reference makes them
        updates, counts, noise = _random_draws(seed_of, total, timing, camera, frame_time.size)

        layout = _batch_codegen.make_layout(n, DEFAULT_LANES)
        params = np.zeros((n_runs, layout.work_rows - layout.work["geometry"]))
        spec = cls(
            n_links=n,
            params=params,
            initial_state=ssel["initial_state"],
            total_steps=total,
            goal_steps=ssel["goal_steps"].astype(np.int64),
            waypoints_m=wp,
            n_waypoints=ssel["n_waypoints"].astype(np.int64),
            acceptance_radius_m=ssel["radius"],
            k_theta=ssel["k_theta"],
            delay_steps=np.full(n_runs, timing.delay_steps, dtype=np.int64),
            update_steps=updates,
            update_count=counts,
            heading_noise_rad=noise,
            frame_step=frame_step,
            frame_fraction=frame_fraction,
            frame_time_s=frame_time,
            options=opts,
            half_length_m=rsel["half"],
            half_axis_vertical_m=rsel["a"],
            half_axis_horizontal_m=rsel["b"],
            yaw_inertia_kg_m2=rsel["inertia"],
            density_kg_m3=rsel["rho"],
            coefficients=coeff_arr,
            duration_s=ssel["duration"],
            joint_limit_rad=rsel["limit"],
        )
        _fill_params(params, layout, rsel, ssel, n, dt)
        _fill_fluid(params, layout, spec, coeff_arr)
        return spec

    def with_coefficients(self, coefficients: ArrayLike) -> BatchSpec:
        """The same batch with other hydrodynamic coefficients (one row or one per run).

        Parameters
        ----------
        coefficients : array_like, shape (R, 4) or (4,)
            (C_f, C_d, C_a, C_m).

        Returns
        -------
        BatchSpec
        """
        c = np.broadcast_to(np.asarray(coefficients, dtype=float), (self.n_runs, 4)).copy()
        params = self.params.copy()
        out = replace(self, params=params, coefficients=c)
        _fill_fluid(params, _batch_codegen.make_layout(self.n_links, DEFAULT_LANES), out, c)
        return out


def _coefficient_array(coefficients) -> FloatArray | None:
    if coefficients is None:
        return None
    if isinstance(coefficients, HydroCoefficients):
        return coefficients.as_array()[None, :]
    if isinstance(coefficients, Sequence) and coefficients and isinstance(
        coefficients[0], HydroCoefficients
    ):
        return np.stack([c.as_array() for c in coefficients])
    arr = np.asarray(coefficients, dtype=float)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise ValueError(f"coefficients must have shape (R, 4) or (4,), got {arr.shape}")
    return arr


def _distinct(items: list, n_runs: int) -> tuple[list, IntArray]:
    """The distinct objects of ``items`` (by identity) and each run's index into them.

    A single item is shared by all ``n_runs`` runs.
    """
    if len(items) == 1:
        return items, np.zeros(n_runs, dtype=np.int64)
    slot: dict[int, int] = {}  # id -> position among the distinct objects
    distinct = []
    index = np.empty(len(items), dtype=np.int64)
    for i, item in enumerate(items):
        if id(item) not in slot:
            slot[id(item)] = len(distinct)
            distinct.append(item)
        index[i] = slot[id(item)]
    return distinct, index


def _robot_arrays(robot: Robot, opts: LoopOptions) -> dict[str, FloatArray]:
    links = robot.links()
    half = np.array([lk.half_length_m for lk in links])
    mass = np.array([lk.mass_kg for lk in links])
    inertia = np.array(
        [
            lk.yaw_inertia_kg_m2 if lk.yaw_inertia_kg_m2 is not None
            else lk.mass_kg * lk.half_length_m**2 / 3.0
            for lk in links
        ]
    )
    g = geometry_matrix(half, mass)
    j = robot.joints
    return {
        "half": half,
        "mass": mass,
        "inertia": inertia,
        "a": np.array([lk.half_axis_vertical_m for lk in links]),
        "b": np.array([lk.half_axis_horizontal_m for lk in links]),
        "rho": np.array(robot.water_density_kg_m3),
        "geometry": g,
        "kp": np.array(j.kp_nm_per_rad),
        "kd": np.array(j.kd_nms_per_rad),
        "limit": np.array(j.limit_rad),
        "clamp": np.array(j.command_limit_rad),
        # the servo line with infinite stall torque and speed leaves the torque unchanged
        "stall": np.array(j.servo_max_torque_nm if opts.servo_limits else np.inf),
        "inv_no_load": np.array(1.0 / j.servo_max_speed_rad_s if opts.servo_limits else 0.0),
    }


def _scenario_arrays(s: Scenario, n: int, dt: float) -> dict[str, FloatArray]:
    heading = np.radians(s.start_heading_deg)
    x0 = np.concatenate(
        [np.full(n, float(heading)), np.asarray(s.start_position_m, float), np.zeros(n + 2)]
    )
    j = np.arange(1, n, dtype=float)
    return {
        "initial_state": x0,
        "total_steps": np.array(s.total_steps(dt)),
        "goal_steps": np.array(s.goal_steps(dt)),
        "n_waypoints": np.array(len(s.waypoints_m)),
        "radius": np.array(s.acceptance_radius_m),
        "k_theta": np.array(s.k_theta),
        "duration": np.array(s.duration_s),
        # control.joint_amplitudes and gait_reference's phase offsets (j - 1) beta
        "amp": s.amplitude_rad * (n - j) / (n + 1.0),
        "cos_beta": np.cos(np.arange(n - 1) * s.beta_rad),
        "sin_beta": np.sin(np.arange(n - 1) * s.beta_rad),
        "omega": np.array(s.omega_rad_s),
        "vcx": np.array(s.current_m_s[0]),
        "vcy": np.array(s.current_m_s[1]),
    }


def _pad_waypoints(waypoints: list[tuple[float, float]], size: int) -> FloatArray:
    wp = np.asarray(waypoints, dtype=float)
    return np.concatenate([wp, np.repeat(wp[-1:], size - len(wp), axis=0)])


def _frame_table(max_total: int, dt: float, fps: float) -> tuple[IntArray, FloatArray, FloatArray]:
    """Camera frames as closed_loop assigns them to physics steps.

    Frame f is seen in the first step k with f / fps <= k dt + dt + 1e-12, at the fraction
    (f / fps - k dt) / dt of the step (the same float expressions as the reference).
    """
    count = int(np.floor(max_total * dt * fps + 1e-9)) + 1
    times = np.arange(count) / fps
    t_step = np.arange(max_total) * dt
    step = np.searchsorted(t_step + dt + 1e-12, times, side="left").astype(np.int64)
    step[0] = -1  # frame 0 is seen at t = 0, before the loop
    keep = step < max_total
    step, times = step[keep], times[keep]
    frac = np.zeros_like(times)
    frac[1:] = (times[1:] - t_step[step[1:]]) / dt
    return step, frac, times


def _random_draws(seeds, total, timing, camera, n_frames):
    """Update schedules and heading noise per run, drawn like simulate_closed_loop.

    Drawn once per distinct (seed, length): a generation of the GA has hundreds of runs but a
    handful of lengths, and without jitter or heading noise the seed does not matter.
    """
    random = timing.jitter_steps > 0 or camera.heading_noise_rad > 0
    keys = np.stack([seeds if random else np.zeros_like(seeds), total], axis=1)
    distinct, inverse = np.unique(keys, axis=0, return_inverse=True)
    schedules, noises = [], []
    for seed, tot in distinct.tolist():
        rng = np.random.default_rng(seed)
        schedules.append(timing.update_steps(tot, rng))
        if camera.heading_noise_rad:
            noises.append(rng.normal(0.0, camera.heading_noise_rad, size=n_frames))
    width = max(s.size for s in schedules)
    updates = np.full((len(schedules), width), -1, dtype=np.int64)
    counts = np.zeros(len(schedules), dtype=np.int64)
    for i, s in enumerate(schedules):
        updates[i, : s.size] = s
        counts[i] = s.size
    noise = np.stack(noises) if noises else np.zeros((len(schedules), 0))
    inverse = inverse.reshape(-1)
    return updates[inverse], counts[inverse], noise[inverse]


def _rows(params: FloatArray, layout: _batch_codegen.Layout, name: str, size: int) -> FloatArray:
    start = layout.work[name] - layout.work["geometry"]
    return params[:, start : start + size]


def plain_runs(spec: BatchSpec) -> NDArray[np.bool_]:
    """Which runs have no servo line and no current.

    A block whose runs all have neither takes the kernel's backward sweep without those terms
    (``eelsim._batch_codegen``): same numbers, about 12 % less work in that loop.

    Parameters
    ----------
    spec : BatchSpec

    Returns
    -------
    ndarray of bool, shape (R,)
    """
    layout = _batch_codegen.make_layout(spec.n_links, DEFAULT_LANES)
    params = spec.params
    return (
        np.isinf(_rows(params, layout, "stall", 1)[:, 0])
        & (_rows(params, layout, "stall_slope", 1)[:, 0] == 0.0)
        & (_rows(params, layout, "vcx", 1)[:, 0] == 0.0)
        & (_rows(params, layout, "vcy", 1)[:, 0] == 0.0)
    )


def _fill_params(params, layout, rsel, ssel, n, dt) -> None:
    g = rsel["geometry"]  # (R, N, N), G[j, i]
    mass = rsel["mass"]
    _rows(params, layout, "geometry", n * n)[:] = g.reshape(len(g), n * n)
    _rows(params, layout, "mass", n)[:] = mass
    _rows(params, layout, "mass_weight", n)[:] = mass / mass.sum(axis=1, keepdims=True)
    gmg = np.einsum("rj,rji,rjk->rik", mass, g, g)
    _rows(params, layout, "gmg", n * n)[:] = gmg.reshape(len(g), n * n)
    _rows(params, layout, "sm", n)[:] = np.einsum("rj,rji->ri", mass, g)
    _rows(params, layout, "mass_sum", 1)[:, 0] = mass.sum(axis=1)
    _rows(params, layout, "half_length", n)[:] = rsel["half"]
    _rows(params, layout, "four_h2", n)[:] = (2.0 * rsel["half"]) ** 2
    reach = _batch_codegen.screen_reach(rsel["half"])
    _rows(params, layout, "reach", reach.shape[1])[:] = reach
    for name in ("kp", "kd", "limit", "clamp", "stall"):
        _rows(params, layout, name, 1)[:, 0] = rsel[name]
    # stall / no_load, 0 when the servo model is off (stall = inf, 1 / no_load = 0)
    on = rsel["inv_no_load"] > 0.0
    slope = np.zeros(len(on))
    slope[on] = rsel["stall"][on] * rsel["inv_no_load"][on]
    _rows(params, layout, "stall_slope", 1)[:, 0] = slope
    for name in ("amp", "cos_beta", "sin_beta"):
        _rows(params, layout, name, n - 1)[:] = ssel[name]
    for name in ("omega", "vcx", "vcy"):
        _rows(params, layout, name, 1)[:, 0] = ssel[name]
    _rows(params, layout, "amp_omega", n - 1)[:] = ssel["amp"] * ssel["omega"][:, None]
    # the gait phase advanced by half a step (angle addition in stages 2 and 4)
    omega = ssel["omega"]
    _rows(params, layout, "cos_whalf", 1)[:, 0] = np.cos(omega * 0.5 * dt)
    _rows(params, layout, "sin_whalf", 1)[:, 0] = np.sin(omega * 0.5 * dt)


def _fill_fluid(params, layout, spec: BatchSpec, coeffs: FloatArray) -> None:
    """model.link_coefficients for every run at once (same expressions, broadcast over runs)."""
    n = spec.n_links
    l_, a, b = spec.half_length_m, spec.half_axis_vertical_m, spec.half_axis_horizontal_m
    rho = spec.density_kg_m3[:, None]
    c_f, c_d, c_a, c_m = (coeffs[:, i : i + 1] for i in range(4))
    _rows(params, layout, "ct", n)[:] = 0.5 * rho * np.pi * c_f * (a + b) / 2.0 * 2.0 * l_
    _rows(params, layout, "cn", n)[:] = 0.5 * rho * c_d * 2.0 * a * 2.0 * l_
    _rows(params, layout, "mu", n)[:] = rho * np.pi * c_a * a**2 * 2.0 * l_
    lambda_1 = rho * np.pi * c_m * (a**2 - b**2) ** 2 * l_**3 / 12.0
    _rows(params, layout, "lambda2", n)[:] = rho * np.pi * c_f * (a + b) * l_**3 / 6.0
    _rows(params, layout, "lambda3", n)[:] = rho * np.pi * c_f * (a + b) * l_**4 / 8.0
    # the diagonal term J_i + lambda_1,i of dynamics.mass_matrix
    inertia = spec.yaw_inertia_kg_m2 + lambda_1
    _rows(params, layout, "inertia", n)[:] = inertia
    # the articulated-body recursion's per-link constants (eelsim._batch_codegen)
    mu = _rows(params, layout, "mu", n)
    hm = l_ * (_rows(params, layout, "mass", n) + mu)
    _rows(params, layout, "hm", n)[:] = hm
    _rows(params, layout, "dd0", n)[:] = inertia + l_ * hm


# ---------------------------------------------------------------------------------------------
# outputs


@dataclass(frozen=True)
class BatchResult:
    """What a batch produced, one entry per run (R runs, S samples, N links).

    Attributes
    ----------
    sample_steps : ndarray of int, shape (S,)
        Requested sample steps (k, at t = k dt), in the order asked.
    sample_times_s : ndarray, shape (S,)
    states : ndarray, shape (R, S, 2 N + 4)
        State at each sample; NaN after the run ended (stopped at the goal, failed, or past
        T_max).
    arrival_time_s : ndarray, shape (R,)
        Camera frame time at which the last waypoint was reached, NaN if never.
    failure : ndarray of int, shape (R,)
        :class:`eelsim.flags.Failure` values.
    failure_time_s : ndarray, shape (R,)
        When the failure was detected, NaN if none.
    distance_left_m : ndarray, shape (R,)
        Path length left to the last waypoint at the end of the run.
    reason_code : ndarray of int, shape (R,)
        :class:`Reason` values; :meth:`reason` gives the text.
    final_state : ndarray, shape (R, 2 N + 4)
        State at the last recorded step.
    final_step : ndarray of int, shape (R,)
        Index of that step.
    target_index : ndarray of int, shape (R,)
        Waypoints reached.
    full_states : ndarray, shape (R, K + 1, 2 N + 4), or None
        Every step (NaN after the end), only with ``record_full=True``.
    spec : BatchSpec
        The inputs.
    """

    sample_steps: IntArray
    sample_times_s: FloatArray
    states: FloatArray
    arrival_time_s: FloatArray
    failure: IntArray
    failure_time_s: FloatArray
    distance_left_m: FloatArray
    reason_code: IntArray
    reason_index: IntArray
    reason_value: FloatArray
    final_state: FloatArray
    final_step: IntArray
    target_index: IntArray
    full_states: FloatArray | None
    spec: BatchSpec

    def reason(self, run: int) -> str:
        """Human-readable reason of run ``run``'s flag, worded as ``RunResult.reason``.

        Parameters
        ----------
        run : int

        Returns
        -------
        str
            Empty when the run did not fail.
        """
        code = Reason(int(self.reason_code[run]))
        i, k = (int(v) for v in self.reason_index[run])
        value = float(self.reason_value[run])
        if code == Reason.TOO_SLOW:
            return (
                f"reached {i} of {int(self.spec.n_waypoints[run])} waypoints by "
                f"T_max = {float(self.spec.duration_s[run]):g} s"
            )
        if code == Reason.NOT_FINITE:
            return "state is not finite (the integration blew up)"
        if code == Reason.DIVERGED:
            return "rates beyond any physical motion (the integration diverged)"
        if code == Reason.NOT_POSITIVE_DEFINITE:
            return "mass matrix is not positive definite"
        if code == Reason.CONDITION_NUMBER:
            return (
                f"mass matrix condition number {value:.3g} is above {ILL_CONDITION_THRESHOLD:.0e}"
            )
        if code == Reason.JOINT_LIMIT:
            limit = float(self.spec.joint_limit_rad[run])
            return f"joint {i + 1} at {value:+.3f} rad is beyond its limit of {limit:.3f} rad"
        if code == Reason.LINKS_INTERSECT:
            return f"links {i + 1} and {k + 1} intersect"
        return ""

    def penalties(self) -> FloatArray:
        """The paper's fitness value of each run's failure (0 if none), as ``flags.penalty``."""
        return np.array(
            [penalty(Failure(int(f)), float(d))
             for f, d in zip(self.failure, self.distance_left_m, strict=True)]
        )


def _sample_steps(
    sample_steps: ArrayLike | None, sample_times_s: ArrayLike | None, dt: float
) -> IntArray:
    if sample_steps is not None and sample_times_s is not None:
        raise ValueError("give sample_steps or sample_times_s, not both")
    if sample_times_s is not None:
        times = np.atleast_1d(np.asarray(sample_times_s, dtype=float))
        steps = np.round(times / dt)
        off = np.abs(steps * dt - times) > 1e-9 * np.maximum(1.0, np.abs(times))
        if np.any(off):
            raise ValueError(
                f"sample time {times[off][0]} s is not a whole number of physics steps "
                f"(dt = {dt} s); the batch samples the state at steps"
            )
        return steps.astype(np.int64)
    if sample_steps is None:
        return np.zeros(0, dtype=np.int64)
    steps = np.atleast_1d(np.asarray(sample_steps))
    if steps.size and (steps.dtype.kind not in "iu" or steps.min() < 0):
        raise ValueError("sample_steps must be non-negative integers")
    return steps.astype(np.int64)


def run_spec(
    spec: BatchSpec,
    sample_steps: ArrayLike | None = None,
    sample_times_s: ArrayLike | None = None,
    record_full: bool = False,
    lanes: int = DEFAULT_LANES,
    threads: int | None = None,
    stage: str | None = None,
    *,
    kernel: ModuleType | None = None,
    expected_steps: ArrayLike | None = None,
) -> BatchResult:
    """Run a prepared batch.

    Parameters
    ----------
    spec : BatchSpec
        The runs.
    sample_steps : array_like of int, optional
        Steps k (t = k dt) at which to return the state.
    sample_times_s : array_like, optional
        The same as times; each must be a whole number of steps.
    record_full : bool
        Also return every step's state (memory R x (K+1) x (2N+4)).
    lanes : int
        Runs per block (a multiple of 4).
    threads : int, optional
        Number of threads (default: numba's, i.e. all cores).
    stage : str, optional
        How the generated RK4 stage is compiled: ``"auto"``, ``"c"`` or ``"numba"``
        (:func:`stage_backend`; the results agree to rounding).
    kernel : module, optional
        A kernel module to run instead of :func:`kernel_module`'s (``lanes`` and ``stage`` are
        then its own): for tools that time or compare versions of the kernel, e.g.
        ``eelbot bench`` and scripts/kernel_ab.py.
    expected_steps : array_like, shape (R,), optional
        How many steps each run is expected to last: runs of about the same length share a
        block (:func:`block_order`). Only the speed depends on it, never a result.

    Returns
    -------
    BatchResult
    """
    import numba

    n = spec.n_links
    ns = 2 * n + 4
    runs = spec.n_runs
    dt = spec.options.timing.dt_s
    steps = _sample_steps(sample_steps, sample_times_s, dt)
    unique, inverse = np.unique(steps, return_inverse=True)
    if kernel is None:
        kernel = kernel_module(n, lanes, stage)
    elif kernel.N_LINKS != n:
        raise ValueError(f"the kernel given is for N = {kernel.N_LINKS}, the batch has N = {n}")
    timing = spec.options.timing
    pending = timing.delay_steps // max(1, timing.period_steps - timing.jitter_steps) + 2
    states = np.full((runs, unique.size, ns), np.nan)
    full = (
        np.full((runs, int(spec.total_steps.max()) + 1, ns), np.nan)
        if record_full
        else np.zeros((0, 0, ns))
    )
    out = {
        "arrival": np.full(runs, np.nan),
        "failure": np.zeros(runs, dtype=np.int64),
        "failure_time": np.full(runs, np.nan),
        "reason": np.zeros(runs, dtype=np.int64),
        "reason_index": np.zeros((runs, 2), dtype=np.int64),
        "reason_value": np.zeros(runs),
        "final_state": np.zeros((runs, ns)),
        "final_step": np.zeros(runs, dtype=np.int64),
        "target": np.zeros(runs, dtype=np.int64),
        "distance": np.zeros(runs),
    }
    cam = spec.options.camera
    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(int(threads))
    try:
        kernel.run_blocks(
            block_order(spec, expected_steps), spec.params, spec.initial_state, spec.total_steps,
            spec.goal_steps, float(dt), spec.waypoints_m,
            spec.n_waypoints, spec.acceptance_radius_m, spec.k_theta, spec.delay_steps,
            spec.update_steps, spec.update_count, spec.frame_step, spec.frame_fraction,
            spec.frame_time_s, spec.heading_noise_rad, plain_runs(spec), float(cam.pixel_m),
            int(cam.median_window), bool(spec.options.stop_at_goal), int(pending), unique, states, bool(record_full), full,
            out["arrival"], out["failure"], out["failure_time"], out["reason"],
            out["reason_index"], out["reason_value"], out["final_state"], out["final_step"],
            out["target"], out["distance"], int(numba.get_num_threads()),
        )
    finally:
        if threads is not None:
            numba.set_num_threads(previous)
    return BatchResult(
        sample_steps=steps,
        sample_times_s=steps * dt,
        # (asked for sorted unique steps, as estimation does, the rows are already in order)
        states=states if np.array_equal(unique, steps) else states[:, inverse.reshape(-1), :],
        arrival_time_s=out["arrival"],
        failure=out["failure"],
        failure_time_s=out["failure_time"],
        distance_left_m=out["distance"],
        reason_code=out["reason"],
        reason_index=out["reason_index"],
        reason_value=out["reason_value"],
        final_state=out["final_state"],
        final_step=out["final_step"],
        target_index=out["target"],
        full_states=full if record_full else None,
        spec=spec,
    )


def block_order(spec: BatchSpec, expected_steps: ArrayLike | None = None) -> IntArray:
    """The order in which runs fill the kernel's blocks: longest expected run first.

    A lane whose run has ended idles until the last run of its block ends, so runs of about
    the same length belong together: a batch mixing experiments of different spans (every
    estimation generation) otherwise runs each block as long as its longest run. Without a
    hint a run is expected to last until T_max (runs with the same T_max then by their minimum
    duration). np.lexsort is stable: a batch of equal runs keeps its order.

    Parameters
    ----------
    spec : BatchSpec
    expected_steps : array_like, shape (R,), optional
        Each run's expected number of steps (a caller's prediction, e.g. from similar runs).

    Returns
    -------
    ndarray of int, shape (R,)
        Run indices; block b takes entries b * lanes to (b + 1) * lanes - 1.
    """
    expected = spec.total_steps
    if expected_steps is not None:
        hint = np.asarray(expected_steps, dtype=float)
        if hint.shape != expected.shape:
            raise ValueError(
                f"expected_steps has shape {hint.shape}, the batch has {expected.shape[0]} runs"
            )
        expected = np.minimum(np.nan_to_num(hint, nan=np.inf), expected)
    return np.lexsort((-spec.goal_steps, -spec.total_steps, -expected)).astype(np.int64)


def run_batch(
    robots: Robot | Sequence[Robot],
    scenarios: Scenario | Sequence[Scenario],
    coefficients: ArrayLike | HydroCoefficients | Sequence[HydroCoefficients] | None = None,
    options: LoopOptions | None = None,
    seeds: int | ArrayLike = 0,
    sample_steps: ArrayLike | None = None,
    sample_times_s: ArrayLike | None = None,
    record_full: bool = False,
    lanes: int = DEFAULT_LANES,
    threads: int | None = None,
    stage: str | None = None,
    expected_steps: ArrayLike | None = None,
) -> BatchResult:
    """Run many closed-loop runs of the twin at once (see the module docstring).

    Parameters
    ----------
    robots : Robot or sequence of Robot
        One robot, or one per run (same N).
    scenarios : Scenario or sequence of Scenario
        One scenario, or one per run.
    coefficients : array_like (R, 4) or (4,), HydroCoefficients or sequence, optional
        (C_f, C_d, C_a, C_m) per run (default: each robot's own).
    options : LoopOptions, optional
        Shared loop options (timing, camera, servo limits, stop at goal).
    seeds : int or array_like of int
        Seed per run, as ``simulate_closed_loop``'s.
    sample_steps, sample_times_s : array_like, optional
        Where to sample the state (steps, or times on the step grid).
    record_full : bool
        Also keep every step's state.
    lanes : int
        Runs per block.
    threads : int, optional
        Threads to use (default all cores).
    stage : str, optional
        How the generated RK4 stage is compiled (:func:`stage_backend`).
    expected_steps : array_like, shape (R,), optional
        Each run's expected length in steps, a hint for packing the blocks (:func:`run_spec`).

    Returns
    -------
    BatchResult
    """
    spec = BatchSpec.build(robots, scenarios, coefficients, options, seeds)
    return run_spec(spec, sample_steps, sample_times_s, record_full, lanes, threads, stage,
                    expected_steps=expected_steps)


def steps_per_second(result: BatchResult, wall_s: float) -> float:
    """RK4 steps per wall second of a finished batch (sum of the runs' steps / wall time).

    Parameters
    ----------
    result : BatchResult
    wall_s : float

    Returns
    -------
    float
    """
    return float(result.final_step.sum()) / wall_s if wall_s > 0 else math.inf
