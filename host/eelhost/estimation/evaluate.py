"""Simulating experiments for many candidate parameter vectors, and scoring them.

An :class:`Evaluator` holds a set of experiments (training or test) prepared for simulation: the
task from each experiment's metadata, run for T_max = ``tmax_factor`` times the recorded span so that
a slightly slow candidate is not flagged too slow by the clock's noise (but ended at its goal once
the last state compared is simulated), with the sample times of the fitness, seen through the
camera the recording declares (frame rate, median filter causal or centred; docs/data.md). A
candidate is a vector of its :class:`~eelhost.estimation.parameters.ParameterSpace` (the fluid
law's coefficients, any fitted joint parameters and the ambient current if fitted, by name: each
run's scenario gets the candidate's current added to the one its experiment declares). ``simulate``
runs every
(candidate, experiment) pair through a backend:

- ``"reference"``: the readable closed loop (``eelsim.closed_loop``), spread over processes;
- ``"batch"``: the fast batched kernel (``eelsim.batch``), the default when it is available;
  with a ``map_function`` (a Dask cluster), the candidates in blocks, one task each.

Both return the centre of mass at the sample times, the failure flag and the path left.
"""

from __future__ import annotations

import copy
import dataclasses
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from eelhost.data.experiments import Experiment
from eelhost.errors import UserError
from eelhost.estimation.fitness import (
    N_SAMPLES_FIT,
    VELOCITY_WEIGHT,
    sample_times,
    sampled_velocity,
    trajectory_error,
)
from eelhost.estimation.parameters import ParameterSpace
from eelsim.camera import observation_steps, observed_positions
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.flags import Failure, penalty
from eelsim.robot import Robot
from eelsim.scenario import Scenario
from eelsim.timing import LoopTiming

if TYPE_CHECKING:  # imported when used: it loads the batched kernel
    from eelhost.estimation.batch_backend import RunLengths

TMAX_FACTOR = 1.5
# Default half-width of the clock-offset search: the paper's stated time-stamp uncertainty.
ALIGN_S = 0.1
ALIGN_STEP_S = 0.01


_ALL_RUNS = [0]  # closed-loop runs of every evaluator in this process, for progress
_ALL_RUNS_LOCK = threading.Lock()  # evaluators may run in several threads at once


def count_runs(runs: int) -> int:
    """Add ``runs`` closed-loop runs to the process-wide count (thread-safe); the new total.

    Evaluators count their own; work done in another process (the comparison's worker pool,
    :mod:`eelhost.estimation.selection`) is added here when its result comes back.
    """
    with _ALL_RUNS_LOCK:
        _ALL_RUNS[0] += int(runs)
        return _ALL_RUNS[0]


def simulations_counter() -> Callable[[], dict[str, int]]:
    """A status for :func:`eelhost.progress.phase`: the runs simulated since it was made.

    Every evaluator counts its own runs; a stage that makes several (a cross-validation's
    folds, a bootstrap's refits) is followed by this process-wide count (``sims=1200``).
    """
    start = _ALL_RUNS[0]

    def status() -> dict[str, int]:
        done = _ALL_RUNS[0] - start
        return {"sims": done} if done else {}  # one batch of runs counts only when it is back

    return status


class EstimationError(UserError, ValueError):
    """A fit or validation that cannot be set up from what was given."""


@dataclass(frozen=True)
class PreparedExperiment:
    """One experiment ready to simulate.

    Attributes
    ----------
    experiment : Experiment
    scenario : Scenario
        The task with duration T_max.
    options : LoopOptions
        Loop timing and camera as recorded (no jitter: its realisation is unknown).
    times_s : ndarray
        Sample times.
    exp_positions_m : ndarray, shape (n, 2)
        The experiment's centre of mass at the sample times.
    shifts_s : ndarray, shape (M,)
        Candidate clock offsets of the recording (just 0 without alignment).
    shifted_positions_m : ndarray, shape (M, n, 2)
        The experiment's centre of mass at ``times_s + shift`` for each shift.
    state_steps : ndarray of int
        The physics steps whose simulated states are needed.
    observe : bool
        Compare the simulation as the camera saw it (frames, median filter) rather than its true
        centre of mass.
    last_time_s : float
        The recording's last frame time (a centred median holds no frame after it).
    """

    experiment: Experiment
    scenario: Scenario
    options: LoopOptions
    times_s: np.ndarray
    exp_positions_m: np.ndarray
    shifts_s: np.ndarray
    shifted_positions_m: np.ndarray
    state_steps: np.ndarray
    observe: bool = True
    last_time_s: float | None = None

    def positions(self, states: np.ndarray, n_links: int) -> tuple[np.ndarray, np.ndarray]:
        """Simulated centre of mass and heading at the sample times from states at ``state_steps``.

        Parameters
        ----------
        states : ndarray, shape (C, S, 2 N + 4)
            NaN where a run had already ended.
        n_links : int

        Returns
        -------
        positions : ndarray, shape (C, n, 2)
        heading : ndarray, shape (C, n)
        """
        dt = self.options.timing.dt_s
        at = np.searchsorted(self.state_steps, np.round(self.times_s / dt).astype(np.int64))
        heading = states[:, at, :n_links].mean(axis=-1)
        if not self.observe:
            return states[:, at, n_links : n_links + 2], heading
        # The camera's frames and median filter, but not its pixel rounding: rounding would make the
        # objective piecewise constant (finite differences, the least-squares polish, the bootstrap
        # and the identifiability Jacobian would all see zero slopes); in the recording it is a
        # zero-mean +-half-pixel noise that needs no reproducing.
        smooth_camera = dataclasses.replace(self.options.camera, pixel_m=0.0)
        com = states[:, :, n_links : n_links + 2]
        pos = observed_positions(
            self.times_s, self.state_steps, com, states[:, :, -2:], smooth_camera, dt,
            self.last_time_s,
        )
        # a run that ended before the last state needed (its later rows are NaN) has no camera
        # view there
        pos[np.isnan(com).any(axis=(1, 2))] = np.nan
        return pos, heading

    def scenario_in(self, current_m_s: np.ndarray) -> Scenario:
        """The task in a tank with an ambient current ``current_m_s`` (v_x, v_y, m/s).

        It adds to the current the experiment declares.
        """
        return self.scenario.with_added_current((current_m_s[0], current_m_s[1]))


def prepare(
    exp: Experiment,
    n_samples: int,
    dt_s: float = 0.01,
    tmax_factor: float = TMAX_FACTOR,
    align_s: float = 0.0,
    observe: bool = True,
    servo_limits: bool = False,
) -> PreparedExperiment:
    """Prepare an experiment for simulation with ``n_samples`` sample times.

    With ``align_s`` > 0 the recording's unknown clock offset is treated as a nuisance parameter:
    the experiment is also sampled at ``times + shift`` for shifts in [-align_s, align_s] (0.01 s
    apart), and the error of a simulation is its smallest over the shifts. Only the densely recorded
    experiment is shifted, so this costs no extra simulation.

    With ``observe`` (the default) the simulation is compared as the experiment's camera would
    have seen it (:func:`eelsim.camera.observed_positions` with the camera the recording declares:
    the same frames and median filter, causal or centred), not by its true centre of mass, so that
    the camera's filter lag is not blamed on the coefficients.

    With ``servo_limits`` the PD joints' torques are clipped to the servos' torque-speed line
    (``LoopOptions.servo_limits``; docs/model.md section 4): a plant known to run on that line,
    such as a test plant's own robot swum as the floor of ``eelbot estimate-bench``.
    """
    t0, t1 = exp.span_s
    times = sample_times(t0, t1, n_samples, dt_s)
    tmax = float(np.ceil(tmax_factor * t1 / dt_s)) * dt_s
    half = int(round(align_s / ALIGN_STEP_S))
    shifts = np.arange(-half, half + 1) * ALIGN_STEP_S
    camera = exp.recording_camera()
    timing = LoopTiming(
        dt_s=dt_s,
        control_period_s=float(exp.timing.get("control_period_s", 0.3)),
        extra_delay_s=float(exp.timing.get("extra_delay_s", 0.0)),
    )
    state_steps = np.union1d(
        np.round(times / dt_s).astype(np.int64),
        observation_steps(times, camera, dt_s, t1) if observe else np.zeros(0, dtype=np.int64),
    )
    # A run ends at T_max, or at its goal once the last state compared has been reached: after
    # both, nothing it does can count (see Simulated.counted_failure), so it need not be run.
    last_s = float(state_steps[-1]) * dt_s
    return PreparedExperiment(
        experiment=exp,
        scenario=exp.scenario.model_copy(update={"duration_s": tmax, "min_duration_s": last_s}),
        options=LoopOptions(timing=timing, camera=camera, servo_limits=servo_limits,
                            stop_at_goal=True),
        times_s=times,
        exp_positions_m=exp.position_at(times),
        shifts_s=shifts,
        shifted_positions_m=np.stack([exp.position_at(times + d) for d in shifts]),
        state_steps=state_steps,
        observe=observe,
        last_time_s=t1,
    )


@dataclass
class Simulated:
    """Simulations of C candidates on E experiments.

    Attributes
    ----------
    positions_m : ndarray, shape (C, E, n, 2)
        Centre of mass at the sample times (NaN where a run failed before them).
    heading_rad : ndarray, shape (C, E, n)
        Heading at the sample times (NaN likewise).
    failure : ndarray of int, shape (C, E)
        :class:`eelsim.flags.Failure` codes.
    distance_left_m : ndarray, shape (C, E)
    arrival_time_s : ndarray, shape (C, E)
        When the last waypoint was reached (NaN: never).
    failure_time_s : ndarray, shape (C, E)
        When the failure was detected (NaN: none).
    steps : ndarray of int, shape (C, E)
        RK4 steps each run took.
    """

    positions_m: np.ndarray
    heading_rad: np.ndarray
    failure: np.ndarray
    distance_left_m: np.ndarray
    arrival_time_s: np.ndarray
    failure_time_s: np.ndarray
    steps: np.ndarray

    def take(self, rows: slice) -> Simulated:
        """The simulations of some candidates (rows of every array)."""
        return Simulated(*(getattr(self, f.name)[rows] for f in dataclasses.fields(self)))

    def counted_failure(self, prepared: Sequence[PreparedExperiment]) -> np.ndarray:
        """Failure codes that count against a candidate, shape (C, E).

        A run continues past the recording so that a slightly slow candidate can still arrive;
        a failure after both its arrival and the last sample time (e.g. circling the last waypoint
        until a joint reaches its stop) happens where there is no data and does not count.
        """
        out = self.failure.copy()
        for j, p in enumerate(prepared):
            after_data = (self.failure_time_s[:, j] > p.times_s[-1]) & (
                self.arrival_time_s[:, j] <= self.failure_time_s[:, j]
            )
            late = after_data & (self.failure[:, j] != int(Failure.TOO_SLOW))
            out[late, j] = int(Failure.NONE)
        return out


def _reference_job(args: tuple) -> tuple[np.ndarray, int, float, float, float, int]:
    # the candidate's robot (joint parameters), coefficients and ambient current
    robot, prepared, coeffs, current = args
    run = simulate_closed_loop(
        robot, prepared.scenario_in(current), prepared.options, seed=0, coefficients=coeffs
    )
    states = np.full((prepared.state_steps.size, run.states.shape[1]), np.nan)
    ok = prepared.state_steps < len(run.t_s)
    states[ok] = run.states[prepared.state_steps[ok]]
    nan = float("nan")
    arrival = nan if run.arrival_time_s is None else float(run.arrival_time_s)
    failed = (
        nan if run.failure_time_s is None or int(run.failure) == 0 else float(run.failure_time_s)
    )
    return states, int(run.failure), float(run.distance_left_m), arrival, failed, len(run.t_s) - 1


class Evaluator:
    """Scores candidate parameter vectors on a set of experiments (the paper's protocol).

    Parameters
    ----------
    robot : Robot
        The robot model to fit (its coefficients, and joint parameters when fitted, are
        replaced by each candidate's).
    experiments : sequence of Experiment
    n_samples : int
        Samples per experiment (7 for fitting, 35 for validation).
    weight : float
        Velocity weight w.
    align_s : float
        Half-width of the clock-offset search per experiment (0: the paper's protocol).
    observe : bool
        Compare the simulation through the experiment's camera model (default) or by its true
        centre of mass.
    backend : {"auto", "batch", "reference"}
    workers : int
        Processes for the reference backend.
    map_function : callable, optional
        Spreads the runs (e.g. :class:`~eelhost.estimation.cluster.ClusterMap` on a Dask
        cluster): the batch backend's candidates in blocks, each block one task
        (:func:`~eelhost.estimation.batch_backend.simulate_batch_spread`); the reference backend's
        runs one task each, in place of the local process pool.
    space : ParameterSpace, optional
        What a candidate vector holds (default: the robot's fluid law and joint model).
    servo_limits : bool
        Clip the PD joints' torques to the servos' torque-speed line in every run (the loop's
        option, :func:`prepare`); default off, as the estimator's models assume. A joint model
        with the line in its own law (``pd_limited``) has it either way.
    """

    def __init__(
        self,
        robot: Robot,
        experiments: Sequence[Experiment],
        n_samples: int = N_SAMPLES_FIT,
        weight: float = VELOCITY_WEIGHT,
        align_s: float = 0.0,
        observe: bool = True,
        backend: str = "auto",
        workers: int = 2,
        map_function: Callable | None = None,
        space: ParameterSpace | None = None,
        servo_limits: bool = False,
    ) -> None:
        if not experiments:
            raise EstimationError("no experiments to evaluate on")
        self.space = space or ParameterSpace.for_robot(robot)
        self.robot = self.space.model_robot(robot)
        self.n_samples, self.align_s, self.observe = n_samples, align_s, observe
        self.servo_limits = servo_limits
        self.prepared = self.prepare_like(experiments)
        self.weight = weight
        self.backend = _choose_backend(backend)
        self.workers = workers
        self.map_function = map_function
        self.simulations = 0  # closed-loop runs done so far
        self.steps = 0  # and the RK4 steps they took
        self._lengths: RunLengths | None = None  # the batch backend's guesses of run lengths

    def with_space(self, space: ParameterSpace) -> Evaluator:
        """The same experiments and settings, for candidates of another space of the same robot.

        Its counts of simulations and steps start at 0.
        """
        other = copy.copy(self)
        other.space, other.robot = space, space.model_robot(self.robot)
        other.simulations, other.steps, other._lengths = 0, 0, None
        return other

    def prepare_like(self, experiments: Sequence[Experiment]) -> list[PreparedExperiment]:
        """Experiments prepared as this evaluator prepares its own (samples, clock search)."""
        return [prepare(e, self.n_samples, align_s=self.align_s, observe=self.observe,
                        servo_limits=self.servo_limits)
                for e in experiments]

    def simulate(self, parameters: np.ndarray) -> Simulated:
        """Simulate every experiment for every candidate.

        Parameters
        ----------
        parameters : ndarray, shape (C, K)
            Candidates, vectors of :attr:`space` (Morison alone: C_f, C_d, C_a, C_m).

        Returns
        -------
        Simulated
        """
        x = np.atleast_2d(np.asarray(parameters, dtype=float))
        if x.shape[1] != self.space.size:
            raise EstimationError(
                f"candidates have {x.shape[1]} parameters; model {self.space.model_name} has "
                f"{self.space.size} ({', '.join(self.space.names)})"
            )
        robots = self.space.robots(self.robot, x)
        stable = self._integrable(robots)
        if not stable.all():
            return self._failing_unstable(x, stable)
        if self.backend == "batch":
            from eelhost.estimation.batch_backend import (
                RunLengths,
                simulate_batch,
                simulate_batch_spread,
            )

            if self._lengths is None:
                self._lengths = RunLengths(len(self.prepared))
            if self.map_function is not None:  # blocks of runs as tasks on the cluster
                sim = simulate_batch_spread(self.map_function, robots, self.prepared, x,
                                            self.space, self._lengths)
            else:
                sim = simulate_batch(robots, self.prepared, x, self.space, self._lengths)
        else:
            sim = self._simulate_reference(robots, x)
        self.simulations += x.shape[0] * len(self.prepared)
        count_runs(x.shape[0] * len(self.prepared))
        self.steps += int(sim.steps.sum())
        return sim

    def _integrable(self, robots: list[Robot]) -> np.ndarray:
        """Whether explicit RK4 at every experiment's step is stable on each robot's joints (C,).

        A fitted joint model's bounds hold parameters the step cannot integrate (the servo's
        lag and motor time constant together; docs/model.md section 4, "Joint models"): such a
        candidate is a failed run, as an ill-conditioned one is, not an error.
        """
        from eelsim.model import SwimmerModel

        steps = sorted({p.options.timing.dt_s for p in self.prepared})
        verdict: dict[int, bool] = {}
        out = np.ones(len(robots), dtype=bool)
        for i, rb in enumerate(robots):
            if id(rb) not in verdict:
                model = SwimmerModel.from_robot(rb)
                try:
                    for dt in steps:
                        rb.joint_model.check_step(rb.joints, model, dt)
                    verdict[id(rb)] = True
                except ValueError:
                    verdict[id(rb)] = False
            out[i] = verdict[id(rb)]
        return out

    def _failing_unstable(self, x: np.ndarray, stable: np.ndarray) -> Simulated:
        """Simulate the integrable candidates; the others fail as ill-conditioned (no run)."""
        c, e = x.shape[0], len(self.prepared)
        n = self.prepared[0].times_s.size
        nan = np.full((c, e), np.nan)
        sim = Simulated(np.full((c, e, n, 2), np.nan), np.full((c, e, n), np.nan),
                        np.full((c, e), int(Failure.ILL_CONDITIONED)), nan.copy(), nan.copy(),
                        np.zeros((c, e)), np.zeros((c, e), dtype=int))
        if stable.any():
            part = self.simulate(x[stable])
            for f in dataclasses.fields(Simulated):
                getattr(sim, f.name)[stable] = getattr(part, f.name)
        return sim

    def _simulate_reference(self, robots: list[Robot], x: np.ndarray) -> Simulated:
        """The reference backend: one readable closed-loop run per (candidate, experiment)."""
        jobs = [
            (rb, p, self.space.coefficients(c), self.space.current_array(c))
            for rb, c in zip(robots, x, strict=True)
            for p in self.prepared
        ]
        if self.map_function is not None:
            results = list(self.map_function(_reference_job, jobs))
        elif self.workers > 1 and len(jobs) > 1:
            with ProcessPoolExecutor(max_workers=self.workers) as pool:
                results = list(pool.map(_reference_job, jobs))
        else:
            results = [_reference_job(j) for j in jobs]
        c, e = x.shape[0], len(self.prepared)
        n = self.prepared[0].times_s.size
        pos = np.empty((c, e, n, 2))
        heading = np.empty((c, e, n))
        for j, p in enumerate(self.prepared):
            states = np.array([results[i * e + j][0] for i in range(c)])
            pos[:, j], heading[:, j] = p.positions(states, self.robot.n_links)
        fail = np.array([r[1] for r in results], dtype=int).reshape(c, e)
        left = np.array([r[2] for r in results]).reshape(c, e)
        arrival = np.array([r[3] for r in results]).reshape(c, e)
        failed = np.array([r[4] for r in results]).reshape(c, e)
        steps = np.array([r[5] for r in results]).reshape(c, e)
        return Simulated(pos, heading, fail, left, arrival, failed, steps)

    def errors(self, parameters: np.ndarray) -> np.ndarray:
        """Per-experiment error (with the failure penalties), shape (C, E)."""
        sim = self.simulate(parameters)
        return self.errors_of(sim)

    def errors_of(
        self, sim: Simulated, prepared: Sequence[PreparedExperiment] | None = None
    ) -> np.ndarray:
        """Per-experiment error of already simulated candidates, shape (C, E).

        ``prepared`` compares them with other recordings of the same tasks (the parametric
        bootstrap's regenerated data: same frame times, other positions); default: this
        evaluator's.
        """
        prepared = self.prepared if prepared is None else prepared
        c, e = sim.failure.shape
        counted = sim.counted_failure(prepared)
        out = np.empty((c, e))
        for j, p in enumerate(prepared):
            err = self.aligned_errors(p, sim.positions_m[:, j]).min(axis=1)
            for i in range(c):
                f = Failure(int(counted[i, j]))
                out[i, j] = (
                    err[i] if f == Failure.NONE else penalty(f, float(sim.distance_left_m[i, j]))
                )
        # a run whose numbers went NaN without a flag (or a too-slow run without its distance
        # left) failed numerically: it scores the ill-conditioned penalty, never NaN, which an
        # optimiser's argmin would pick and CMA-ES could not rank (docs/model.md section 5)
        out[~np.isfinite(out)] = penalty(Failure.ILL_CONDITIONED)
        return out

    def aligned_errors(self, p: PreparedExperiment, sim_positions_m: np.ndarray) -> np.ndarray:
        """Error of each simulation against each shifted recording, shape (C, M)."""
        return trajectory_error(
            p.times_s, p.shifted_positions_m, sim_positions_m[:, None], self.weight
        )

    def best_shift(self, p: PreparedExperiment, sim_positions_m: np.ndarray) -> np.ndarray:
        """The clock offset that fits each simulation best, shape (C,)."""
        return p.shifts_s[np.argmin(self.aligned_errors(p, sim_positions_m), axis=1)]

    def fitness(self, parameters: np.ndarray) -> np.ndarray:
        """Minimax fitness max_j error_j of each candidate, shape (C,)."""
        return self.errors(parameters).max(axis=1)

    def residual_vectors_of(
        self, sim: Simulated, prepared: Sequence[PreparedExperiment] | None = None
    ) -> np.ndarray:
        """The 2-vectors whose norms the errors sum, shape (C, E, 2 n, 2).

        Per experiment: the position differences at the n samples, then ``weight`` times the
        velocity differences, each against the recording at the candidate's best clock offset
        (error_j is the sum of their norms). NaN where a run failed (it scores its penalty).
        """
        prepared = self.prepared if prepared is None else prepared
        counted = sim.counted_failure(prepared)
        blocks = []
        for j, p in enumerate(prepared):
            simp = sim.positions_m[:, j]
            # each candidate is compared with the recording at its own best clock offset
            idx = np.argmin(np.nan_to_num(self.aligned_errors(p, simp), nan=np.inf), axis=1)
            exp = p.shifted_positions_m[idx]
            dv = sampled_velocity(p.times_s, simp) - sampled_velocity(p.times_s, exp)
            block = np.concatenate([simp - exp, self.weight * dv], axis=1)
            block[counted[:, j] != int(Failure.NONE)] = np.nan
            blocks.append(block)
        return np.stack(blocks, axis=1)

    def evaluate(
        self, parameters: np.ndarray, prepared: Sequence[PreparedExperiment] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Errors (C, E) and residual vectors (C, E, 2 n, 2) of candidates (one simulation)."""
        sim = self.simulate(parameters)
        return self.errors_of(sim, prepared), self.residual_vectors_of(sim, prepared)

    def residuals(self, parameters: np.ndarray) -> np.ndarray:
        """Stacked position and weighted velocity differences, shape (C, E * n * 4).

        The least-squares form of the same data (failed runs give large constant residuals).
        """
        vectors = self.residual_vectors_of(self.simulate(parameters))
        return np.nan_to_num(vectors.reshape(len(vectors), -1), nan=10.0)  # 10 m: far worse


def _choose_backend(backend: str) -> str:
    if backend not in ("auto", "batch", "reference"):
        raise EstimationError(f"backend must be auto, batch or reference, got {backend!r}")
    if backend != "auto":
        return backend
    try:
        import eelhost.estimation.batch_backend  # noqa: F401

        return "batch"
    except ImportError:
        return "reference"
