"""Running a batch: :func:`run_batch` and :func:`run_spec`, and what they return.

See the package docstring (``eelsim.batch``) for what the batched kernel does and how it is fast;
:class:`BatchResult` decodes the kernel's answers into the reference's terms (flags, reasons,
times). The tests compare both paths to 1e-9.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelsim.batch.loading import DEFAULT_LANES, kernel_module
from eelsim.batch.packing import BatchSpec, block_order, plain_runs
from eelsim.batch.records import FrameTable, LoopSettings, Reason, RunInputs, RunOutputs
from eelsim.closed_loop import LoopOptions
from eelsim.flags import ILL_CONDITION_THRESHOLD, Failure, penalty
from eelsim.fluid import FluidCoefficients
from eelsim.robot import Robot
from eelsim.scenario import Scenario

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

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
    max_torque_ratio : ndarray, shape (R,)
        The largest |u| over the run's recorded steps and joints, as a fraction of the stall
        torque (``RunResult.max_torque_ratio``).
    saturated_steps : ndarray of int, shape (R,)
        Recorded steps outside the servo's torque-speed line (``RunResult.saturated_steps``).
    integral_s : ndarray, shape (R, S, 2) or None
        The guidance's ILOS integral vector at each sample step, before that step's control
        update (what a run restarted there starts from: ``BatchSpec.guidance_state``); zero
        with pure pursuit. NaN where the run had ended.
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
    max_torque_ratio: FloatArray
    saturated_steps: IntArray
    integral_s: FloatArray | None = None

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
        hint = self.spec.blow_up_hint(run)
        if code == Reason.NOT_FINITE:
            return "state is not finite (the integration blew up)" + hint
        if code == Reason.DIVERGED:
            return "rates beyond any physical motion (the integration diverged)" + hint
        if code == Reason.NOT_POSITIVE_DEFINITE:
            return "mass matrix is not positive definite" + hint
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
        ``eelbot bench``.
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
        kernel = kernel_module(n, lanes, stage, spec.fluid_law, spec.joint_model)
    elif kernel.N_LINKS != n:
        raise ValueError(f"the kernel given is for N = {kernel.N_LINKS}, the batch has N = {n}")
    elif getattr(kernel, "JOINT_MODEL", "pd") != spec.joint_model_name:
        raise ValueError(f"the kernel given is for the {kernel.JOINT_MODEL!r} joint model, the "
                         f"batch has {spec.joint_model_name!r}")
    timing = spec.options.timing
    cam = spec.options.camera
    runs_in = RunInputs(
        block_order(spec, expected_steps), spec.params, spec.initial_state, spec.total_steps,
        spec.goal_steps, spec.waypoints_m, spec.n_waypoints, spec.acceptance_radius_m,
        spec.k_theta, spec.delay_steps, spec.update_steps, spec.update_count,
        spec.heading_noise_rad, plain_runs(spec), spec.guidance_start())
    frames = FrameTable(spec.frame_step, spec.frame_fraction, spec.frame_time_s)
    loop = LoopSettings(
        dt=float(dt), pixel=float(cam.pixel_m), window=int(cam.median_window),
        stop_at_goal=bool(spec.options.stop_at_goal),
        pending_size=int(timing.delay_steps // max(1, timing.period_steps - timing.jitter_steps)
                         + 2),
        record_full=bool(record_full), sample_steps=unique,
        guidance=guidance_settings(spec.options))
    out = RunOutputs(
        states=np.full((runs, unique.size, ns), np.nan),
        full=(np.full((runs, int(spec.total_steps.max()) + 1, ns), np.nan) if record_full
              else np.zeros((0, 0, ns))),
        arrival=np.full(runs, np.nan),
        failure=np.zeros(runs, dtype=np.int64),
        failure_time=np.full(runs, np.nan),
        reason=np.zeros(runs, dtype=np.int64),
        reason_index=np.zeros((runs, 2), dtype=np.int64),
        reason_value=np.zeros(runs),
        final_state=np.zeros((runs, ns)),
        final_step=np.zeros(runs, dtype=np.int64),
        target=np.zeros(runs, dtype=np.int64),
        distance=np.zeros(runs),
        torque_ratio=np.zeros(runs),
        saturated=np.zeros(runs, dtype=np.int64),
        integral=np.full((runs, unique.size, 2), np.nan),
    )
    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(int(threads))
    try:
        kernel.run_blocks(runs_in, frames, loop, out, int(numba.get_num_threads()))
    finally:
        if threads is not None:
            numba.set_num_threads(previous)
    return BatchResult(
        sample_steps=steps,
        sample_times_s=steps.astype(np.float64) * dt,
        # (asked for sorted unique steps, as estimation does, the rows are already in order)
        states=(out.states if np.array_equal(unique, steps)
                else out.states[:, inverse.reshape(-1), :]),
        arrival_time_s=out.arrival,
        failure=out.failure,
        failure_time_s=out.failure_time,
        distance_left_m=out.distance,
        reason_code=out.reason,
        reason_index=out.reason_index,
        reason_value=out.reason_value,
        final_state=out.final_state,
        final_step=out.final_step,
        target_index=out.target,
        full_states=out.full if record_full else None,
        spec=spec,
        max_torque_ratio=out.torque_ratio,
        saturated_steps=out.saturated,
        integral_s=(out.integral if np.array_equal(unique, steps)
                    else out.integral[:, inverse.reshape(-1), :]),
    )


def guidance_settings(options: LoopOptions) -> FloatArray:
    """The kernel's guidance row (``records.LoopSettings.guidance``) for the loop's options.

    Parameters
    ----------
    options : LoopOptions

    Returns
    -------
    ndarray, shape (9,)
        Law (0 pure pursuit, 1 ILOS, 2 pure pursuit with the known current's feed-forward),
        look-ahead, integral gain, control period, the law's heading gain (0: each run's
        k_theta), and the feed-forward's current (x, y), m/s, speed U, m/s, and crab limit.

    Raises
    ------
    ValueError
        A feed-forward law with a current but no speed (``GuidanceLaw.with_water``).
    """
    law = options.guidance
    if law.needs_water and law.current_m_s != (0.0, 0.0):
        raise ValueError("pursuit_ff: the robot's speed is not given (GuidanceLaw.with_water)")
    code = 1.0 if law.integral else 2.0 if law.feed_forward else 0.0
    return np.array([code, law.lookahead_m, law.integral_gain,
                     options.timing.control_period_s,
                     0.0 if law.heading_gain is None else law.heading_gain,
                     float(law.current_m_s[0]), float(law.current_m_s[1]), law.speed_m_s,
                     law.crab_limit])


def run_batch(
    robots: Robot | Sequence[Robot],
    scenarios: Scenario | Sequence[Scenario],
    coefficients: ArrayLike | FluidCoefficients | Sequence[FluidCoefficients] | None = None,
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
    coefficients : array_like (R, k) or (k,), FluidCoefficients or sequence, optional
        The fluid law's coefficients per run, e.g. (C_f, C_d, C_a, C_m) (default: each robot's
        own).
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
