"""Scoring candidate parameter vectors on a set of experiments, through a simulation backend.

An :class:`Evaluator` holds a set of experiments (training or test) prepared for simulation
(:func:`eelhost.estimation.runs.prepare`: the task, T_max, the sample times, the recording's
camera). A candidate is a vector of its :class:`~eelhost.estimation.space.ParameterSpace` (the
fluid law's coefficients, any fitted joint parameters and the ambient current if fitted, by name:
each run's scenario gets the candidate's current added to the one its experiment declares).
``simulate`` hands every (candidate, experiment) pair to the evaluator's backend
(:class:`~eelhost.estimation.runs.SimulationBackend`), given by name or as an object:

- ``"reference"``: the readable closed loop (``eelsim.closed_loop``), spread over processes
  (:class:`~eelhost.estimation.reference_backend.ReferenceBackend`);
- ``"batch"``: the fast batched kernel (``eelsim.batch``), the default when it is available;
  with a ``map_function`` (a Dask cluster), the candidates in blocks, one task each
  (:class:`~eelhost.estimation.batch_backend.BatchBackend`).

Both return the centre of mass at the sample times, the failure flag and the path left; the
evaluator turns them into errors, fitness and residuals. The backends import nothing of this
module. The names are a registry, :data:`BACKENDS` (docs/architecture.md, "Extension points"):
``--backend`` offers what it holds, and a package adds its own backend through the
``eelbot.backends`` entry points (a factory ``make(workers, map_function) -> SimulationBackend``);
``"auto"`` is not a backend but the choice of ``"batch"`` when its kernel loads, else
``"reference"``.
"""

from __future__ import annotations

import copy
import dataclasses
import threading
from collections.abc import Callable, Sequence

import numpy as np

from eelhost.data.experiments import Experiment
from eelhost.errors import UserError
from eelhost.estimation.clock_prior import FIT_CLOCK_PRIOR, centred_offsets, shifted_recording
from eelhost.estimation.fitness import (
    N_SAMPLES_FIT,
    VELOCITY_WEIGHT,
    sampled_velocity,
    trajectory_error,
)
from eelhost.estimation.reference_backend import ReferenceBackend
from eelhost.estimation.runs import (
    PreparedExperiment,
    Simulated,
    SimulationBackend,
    declared_clock_bound_s,
    prepare,
)
from eelhost.estimation.space import ParameterSpace
from eelsim.flags import Failure, penalty
from eelsim.registry import Registry
from eelsim.robot import Robot

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
    backend : str or SimulationBackend
        What runs the simulations: a backend by name (of :data:`BACKENDS`; "auto": the batched
        kernel when it can be loaded), or a backend object
        (:class:`~eelhost.estimation.runs.SimulationBackend`), which ``workers`` and
        ``map_function`` then do not change.
    workers : int
        Processes for the reference backend named.
    map_function : callable, optional
        Spreads the runs of a backend named (e.g. :class:`~eelhost.estimation.cluster.ClusterMap`
        on a Dask cluster): the batch backend's candidates in blocks, each block one task
        (:func:`~eelhost.estimation.batch_backend.simulate_batch_spread`); the reference backend's
        runs one task each, in place of the local process pool.
    space : ParameterSpace, optional
        What a candidate vector holds (default: the robot's fluid law and joint model).
    servo_limits : bool
        Clip the PD joints' torques to the servos' torque-speed line in every run (the loop's
        option, :func:`prepare`); default off, as the estimator's models assume. A joint model
        with the line in its own law (``pd_limited``) has it either way.
    clock_prior : bool or None
        Where ``align_s`` is 0: compare each recording at its clock offset profiled within the
        bound it declares, the offsets' mean held at 0 (the zero-mean prior,
        :func:`eelhost.estimation.clock_prior.centred_offsets`; docs/estimation.md, "The training
        clocks: a zero-mean prior"). None: ``clock_prior.FIT_CLOCK_PRIOR``. With ``align_s`` > 0
        the offsets are profiled each on its own, as before.
    """

    def __init__(
        self,
        robot: Robot,
        experiments: Sequence[Experiment],
        n_samples: int = N_SAMPLES_FIT,
        weight: float = VELOCITY_WEIGHT,
        align_s: float = 0.0,
        observe: bool = True,
        backend: str | SimulationBackend = "auto",
        workers: int = 2,
        map_function: Callable | None = None,
        space: ParameterSpace | None = None,
        servo_limits: bool = False,
        clock_prior: bool | None = None,
    ) -> None:

        if not experiments:
            raise EstimationError("no experiments to evaluate on")
        self.space = space or ParameterSpace.for_robot(robot)
        self.robot = self.space.model_robot(robot)
        self.n_samples, self.align_s, self.observe = n_samples, align_s, observe
        prior = FIT_CLOCK_PRIOR if clock_prior is None else clock_prior
        self.clock_prior = bool(prior) and align_s <= 0.0
        self.servo_limits = servo_limits
        self.prepared = self.prepare_like(experiments)
        self.weight = weight
        self.backend = (backend_named(backend, workers, map_function) if isinstance(backend, str)
                        else backend)
        self.simulations = 0  # closed-loop runs done so far
        self.steps = 0  # and the RK4 steps they took

    def with_space(self, space: ParameterSpace) -> Evaluator:
        """The same experiments and settings, for candidates of another space of the same robot.

        Its counts of simulations and steps start at 0.
        """
        other = copy.copy(self)
        other.space, other.robot = space, space.model_robot(self.robot)
        other.simulations, other.steps = 0, 0
        other.backend = self.backend.fresh()  # the run lengths it learned were of this space
        return other

    def count_from(self, other: Evaluator) -> None:
        """Add the simulations and steps of ``other`` (a :meth:`with_space` of this one) here."""
        self.simulations += other.simulations
        self.steps += other.steps

    def prepare_like(self, experiments: Sequence[Experiment]) -> list[PreparedExperiment]:
        """Experiments prepared as this evaluator prepares its own (samples, clock search)."""
        return [prepare(e, self.n_samples,
                        align_s=declared_clock_bound_s(e) if self.clock_prior else self.align_s,
                        observe=self.observe, servo_limits=self.servo_limits)
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
        sim = self.backend.simulate(robots, self.prepared, x, self.space)
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
        held = self._prior_recordings(sim, prepared)
        for j, p in enumerate(prepared):
            if held is None:
                err = self.aligned_errors(p, sim.positions_m[:, j]).min(axis=1)
            else:
                err = trajectory_error(p.times_s, held[j], sim.positions_m[:, j], self.weight)
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

    def _prior_recordings(
        self, sim: Simulated, prepared: Sequence[PreparedExperiment]
    ) -> list[np.ndarray] | None:
        """Each recording at each candidate's offsets under the clock prior, (C, n, 2) each.

        None without the prior: each candidate is then compared at each recording's own best
        offset (a flat profile within ``align_s``; just the recorded clock for 0).
        """
        if not self.clock_prior:
            return None

        grids = [self.aligned_errors(p, sim.positions_m[:, j]) for j, p in enumerate(prepared)]
        offsets = centred_offsets(grids, [p.shifts_s for p in prepared])
        return [shifted_recording(p.shifted_positions_m, p.shifts_s, offsets[:, j])
                for j, p in enumerate(prepared)]

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
        held = self._prior_recordings(sim, prepared)
        for j, p in enumerate(prepared):
            simp = sim.positions_m[:, j]
            if held is None:
                # each candidate is compared with the recording at its own best clock offset
                idx = np.argmin(np.nan_to_num(self.aligned_errors(p, simp), nan=np.inf), axis=1)
                exp = p.shifted_positions_m[idx]
            else:
                exp = held[j]
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


BackendFactory = Callable[[int, Callable | None], SimulationBackend]
"""``make(workers, map_function)``: a backend that uses ``workers`` local processes or spreads its
work through ``map_function`` (a Dask cluster's), whichever it can."""

BACKENDS: Registry[BackendFactory] = Registry("simulation backend", "eelbot.backends",
                                              plural="backends")
"""The simulation backends by name (:mod:`eelsim.registry`; plug-ins: group ``eelbot.backends``)."""

AUTO_BACKEND = "auto"
"""Not a backend: ``"batch"`` when its kernel loads, else ``"reference"``."""


def many_problems(ev: Evaluator, drop: Sequence[int | None] = ()) -> Callable:
    """A ManyEvaluate (:mod:`eelhost.estimation.local`) over one evaluator's experiments.

    Problem b leaves out experiment ``drop[b]`` (none where ``drop`` is shorter or says None).
    The candidates of every problem are simulated as one batch (all experiments: a left-out
    one is simulated too and ignored, which costs less than a batch per problem).
    """

    def evaluate(xs: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        sizes = [len(x) for x in xs]
        if not sum(sizes):
            return [(np.zeros((0, len(ev.prepared))), np.zeros((0,)))] * len(xs)
        errors, vectors = ev.evaluate(np.concatenate([x for x in xs if len(x)]))
        out, at = [], 0
        for b, n in enumerate(sizes):
            e, v = errors[at:at + n], vectors[at:at + n]
            j = drop[b] if b < len(drop) else None
            if j is not None:
                keep = [i for i in range(e.shape[1]) if i != j]
                e, v = e[:, keep], v[:, keep]
            out.append((e, v))
            at += n
        return out

    return evaluate


@BACKENDS.add("batch", "the compiled batched kernel (with a cluster: the candidates in blocks, "
              "one task each)")
def _batch_backend(workers: int, map_function: Callable | None) -> SimulationBackend:
    # imported when chosen, not with the registry: it loads the batched kernel
    from eelhost.estimation.batch_backend import BatchBackend

    return BatchBackend(map_function)


@BACKENDS.add("reference", "the readable closed-loop twin, one run per candidate and experiment "
              "(slow, for cross-checks)")
def _reference_backend(workers: int, map_function: Callable | None) -> SimulationBackend:
    return ReferenceBackend(workers, map_function)


def backend_named(
    backend: str, workers: int = 2, map_function: Callable | None = None
) -> SimulationBackend:
    """The backend called ``backend`` in :data:`BACKENDS`, or "auto" (batch when it loads).

    Parameters
    ----------
    backend : str
        A registered name ("batch", "reference", a plug-in's) or "auto".
    workers : int
        Local processes of the reference backend.
    map_function : callable, optional
        Where either spreads its work (a Dask cluster's :class:`~eelhost.estimation.cluster.
        ClusterMap`).

    Raises
    ------
    EstimationError
        Another name (the message lists the known ones).
    """
    if backend == AUTO_BACKEND:
        try:
            return BACKENDS["batch"](workers, map_function)
        except ImportError:
            return BACKENDS["reference"](workers, map_function)
    if backend not in BACKENDS:
        raise EstimationError(f"{BACKENDS.unknown_message(backend)}, or {AUTO_BACKEND}")
    return BACKENDS[backend](workers, map_function)
