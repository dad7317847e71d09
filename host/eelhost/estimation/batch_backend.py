"""The Evaluator's fast backend: every (candidate, experiment) pair in one batched-kernel call.

The kernel samples all runs at one shared set of steps, so the union of every experiment's sample
steps is requested and each run's own are picked from it. Experiments whose loop options differ go
in separate calls (the options are shared by a batch).

The kernel runs LANES runs side by side in a block until the last of them ends; a run that ends
early leaves its lane idle. Estimation asks again and again about candidates near the earlier
ones (a GA's children, CMA-ES's samples), so :class:`RunLengths` guesses each run's length from
the nearest earlier candidate on the same experiment and the kernel packs runs of about the same
length together: on the paper's GA this took the kernel's lane-steps from 243 M to about 197 M
(lanes busy 75 % -> 93 % of the time). The guess changes the speed only, never a result.

:class:`BatchBackend` is the backend an :class:`~eelhost.estimation.evaluate.Evaluator` holds: it
keeps the run lengths of its evaluator's candidates, and with a ``map_function`` (a Dask
cluster's :class:`~eelhost.estimation.cluster.ClusterMap`) spreads each call in blocks
(:func:`simulate_batch_spread`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree

from eelhost.estimation.runs import PreparedExperiment, Simulated
from eelhost.estimation.space import ParameterSpace
from eelsim.batch import run_batch
from eelsim.closed_loop import LoopOptions
from eelsim.robot import Robot


class RunLengths:
    """Each (candidate, experiment) run's length guessed from the runs done before.

    The guess for a candidate is what the nearest earlier candidate (Euclidean distance of the
    logarithms of its parameters' magnitudes over 1e-4, signed) took on each experiment.

    Parameters
    ----------
    experiments : int
        E, the experiments every call simulates.
    memory : int
        How many earlier candidates are kept (the most recent).
    """

    def __init__(self, experiments: int, memory: int = 3000) -> None:
        self.memory = memory
        self._keys: np.ndarray | None = None
        self._steps = np.zeros((0, experiments))

    @staticmethod
    def _key(coefficients: np.ndarray) -> np.ndarray:
        # a symmetric logarithm: the coefficients' logarithms (above 1e-4), and parameters of
        # either sign (the ambient current) kept apart by their sign
        x = np.asarray(coefficients, dtype=float)
        return np.sign(x) * np.log1p(np.abs(x) / 1e-4)

    def predict(self, coefficients: np.ndarray) -> np.ndarray | None:
        """Expected steps of each candidate on each experiment, shape (C, E); None before any.

        Parameters
        ----------
        coefficients : ndarray, shape (C, K)
            Candidates' parameters.

        Returns
        -------
        ndarray or None
        """
        if self._keys is None or not len(self._keys):
            return None
        _, nearest = cKDTree(self._keys).query(self._key(coefficients))
        return self._steps[nearest]

    def record(self, coefficients: np.ndarray, steps: np.ndarray) -> None:
        """Remember the candidates' run lengths.

        Parameters
        ----------
        coefficients : ndarray, shape (C, K)
        steps : ndarray, shape (C, E)
            Steps each run lasted.
        """
        keys = self._key(coefficients)
        before = np.zeros((0, keys.shape[1])) if self._keys is None else self._keys
        self._keys = np.concatenate([before, keys])[-self.memory :]
        self._steps = np.concatenate([self._steps, steps])[-self.memory :]


def simulate_batch(
    robots: Sequence[Robot],
    prepared: Sequence[PreparedExperiment],
    parameters: np.ndarray,
    space: ParameterSpace,
    lengths: RunLengths | None = None,
    expected: np.ndarray | None = None,
) -> Simulated:
    """Simulate every prepared experiment for every candidate with ``eelsim.batch``.

    Parameters
    ----------
    robots, prepared, parameters, space
        As for :meth:`eelhost.estimation.runs.SimulationBackend.simulate`.
    lengths : RunLengths, optional
        Guesses the runs' lengths for the kernel's packing, and learns them from this call.
    expected : ndarray, shape (C, E), optional
        The guesses themselves, when there is no ``lengths`` (a block run on a worker).

    Returns
    -------
    Simulated
    """
    c, e = parameters.shape[0], len(prepared)
    coefficients = space.coefficient_array(parameters)
    currents = space.current_array(parameters)  # (C, 2), added to each experiment's own
    n = prepared[0].times_s.size
    n_links = robots[0].n_links
    pos = np.full((c, e, n, 2), np.nan)
    heading = np.full((c, e, n), np.nan)
    failure = np.zeros((c, e), dtype=int)
    left = np.zeros((c, e))
    arrival = np.full((c, e), np.nan)
    failed = np.full((c, e), np.nan)
    if lengths is not None:
        expected = lengths.predict(parameters)
    steps = np.zeros((c, e), dtype=np.int64)
    groups: dict[LoopOptions, list[int]] = {}
    for j, p in enumerate(prepared):
        groups.setdefault(p.options, []).append(j)
    for options, members in groups.items():
        union = np.unique(np.concatenate([prepared[j].state_steps for j in members]))
        scenarios = [prepared[j].scenario_in(v) for v in currents for j in members]
        coeffs = np.repeat(coefficients, len(members), axis=0)
        run_robots = [rb for rb in robots for _ in members]
        hint = None if expected is None else expected[:, members].reshape(-1)
        res = run_batch(run_robots, scenarios, coeffs, options, seeds=0, sample_steps=union,
                        expected_steps=hint)
        states = res.states.reshape(c, len(members), union.size, -1)
        for k, j in enumerate(members):
            picked = states[:, k, np.searchsorted(union, prepared[j].state_steps)]
            pos[:, j], heading[:, j] = prepared[j].positions(picked, n_links)
        shape = (c, len(members))  # the batch's runs are candidate-major
        steps[:, members] = res.final_step.reshape(shape)
        failure[:, members] = codes = res.failure.reshape(shape)
        left[:, members] = res.distance_left_m.reshape(shape)
        arrival[:, members] = res.arrival_time_s.reshape(shape)
        failed[:, members] = np.where(codes != 0, res.failure_time_s.reshape(shape), np.nan)
    if lengths is not None:
        lengths.record(parameters, steps)
    return Simulated(pos, heading, failure, left, arrival, failed, steps)


def _block_job(args: tuple) -> Simulated:
    """One block of candidates simulated on a worker (its process keeps the kernel loaded)."""
    robots, prepared, parameters, space, expected = args
    return simulate_batch(robots, prepared, parameters, space, expected=expected)


def simulate_batch_spread(
    map_function: Callable,
    robots: Sequence[Robot],
    prepared: Sequence[PreparedExperiment],
    parameters: np.ndarray,
    space: ParameterSpace,
    lengths: RunLengths | None = None,
) -> Simulated:
    """:func:`simulate_batch` with the candidates cut into blocks, each a task of ``map_function``.

    On a Dask cluster (:class:`~eelhost.estimation.cluster.ClusterMap`) each block is one task on
    a worker, whose kernel runs its runs on all the worker's cores; the worker's process compiles
    or loads the kernel once and keeps it. The blocks interleave the candidates by their guessed
    run lengths (longest first, dealt round), so that they last about as long as each other; the
    experiments are sent to every worker once (``map_function.share``). Results are those of
    :func:`simulate_batch` on all the candidates at once (each run is independent).

    Parameters
    ----------
    map_function : callable
        ``map(function, jobs) -> results``; its ``blocks`` attribute, when it has one, says how
        many blocks to cut (default 2).
    robots, prepared, parameters, space, lengths
        As for :func:`simulate_batch`.

    Returns
    -------
    Simulated
    """
    c = parameters.shape[0]
    blocks = max(1, min(c, int(getattr(map_function, "blocks", 2))))
    expected = lengths.predict(parameters) if lengths is not None else None
    order = (np.arange(c) if expected is None
             else np.argsort(-expected.sum(axis=1), kind="stable"))
    parts = [np.sort(order[b::blocks]) for b in range(blocks)]
    share = getattr(map_function, "share", None)
    sent = share(prepared) if share is not None else list(prepared)
    jobs = [([robots[i] for i in idx], sent, parameters[idx], space,
             None if expected is None else expected[idx]) for idx in parts]
    results = map_function(_block_job, jobs)
    merged = {}
    for f in dataclasses.fields(Simulated):
        first = getattr(results[0], f.name)
        merged[f.name] = np.empty((c, *first.shape[1:]), dtype=first.dtype)
        for idx, part in zip(parts, results, strict=True):
            merged[f.name][idx] = getattr(part, f.name)
    sim = Simulated(**merged)
    if lengths is not None:
        lengths.record(parameters, sim.steps)
    return sim


class BatchBackend:
    """The batched kernel as an evaluator's backend (a ``SimulationBackend``).

    Parameters
    ----------
    map_function : callable, optional
        Spreads each call's candidates in blocks, one task each (:func:`simulate_batch_spread`;
        a Dask cluster's :class:`~eelhost.estimation.cluster.ClusterMap`); None: this machine's
        kernel on all its cores.
    """

    def __init__(self, map_function: Callable | None = None) -> None:
        self.map_function = map_function
        self.lengths: RunLengths | None = None  # learned from the calls, for the kernel's packing

    def fresh(self) -> BatchBackend:
        """A backend on the same machines that has learned no run lengths yet."""
        return BatchBackend(self.map_function)

    def simulate(
        self,
        robots: Sequence[Robot],
        prepared: Sequence[PreparedExperiment],
        parameters: np.ndarray,
        space: ParameterSpace,
    ) -> Simulated:
        """Every (candidate, experiment) run through the kernel (``SimulationBackend.simulate``)."""
        if self.lengths is None:
            self.lengths = RunLengths(len(prepared))
        if self.map_function is not None:  # blocks of runs as tasks on the cluster
            return simulate_batch_spread(self.map_function, robots, prepared, parameters, space,
                                         self.lengths)
        return simulate_batch(robots, prepared, parameters, space, self.lengths)
