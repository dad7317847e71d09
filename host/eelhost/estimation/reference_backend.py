"""The Evaluator's readable backend: one ``eelsim.closed_loop`` run per (candidate, experiment).

The reference the batched kernel is checked against (docs/model.md); slow, so its runs are spread
over local processes, or over any ``map_function`` (a Dask cluster,
:class:`~eelhost.estimation.cluster.ClusterMap`), one run per task.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from eelhost.estimation.runs import PreparedExperiment, Simulated
from eelhost.estimation.space import ParameterSpace
from eelsim.closed_loop import simulate_closed_loop
from eelsim.robot import Robot


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


class ReferenceBackend:
    """The closed loop of ``eelsim.closed_loop``, run by run (a ``SimulationBackend``).

    Parameters
    ----------
    workers : int
        Local processes (1: in this process).
    map_function : callable, optional
        ``map(function, jobs) -> results`` in place of the local processes (one run per job).
    """

    def __init__(self, workers: int = 2, map_function: Callable | None = None) -> None:
        self.workers = workers
        self.map_function = map_function

    def fresh(self) -> ReferenceBackend:
        """The same object: it learns nothing from its calls."""
        return self

    def simulate(
        self,
        robots: Sequence[Robot],
        prepared: Sequence[PreparedExperiment],
        parameters: np.ndarray,
        space: ParameterSpace,
    ) -> Simulated:
        """One readable closed-loop run per (candidate, experiment) (``SimulationBackend.simulate``)."""
        x = parameters
        jobs = [
            (rb, p, space.coefficients(c), space.current_array(c))
            for rb, c in zip(robots, x, strict=True)
            for p in prepared
        ]
        if self.map_function is not None:
            results = list(self.map_function(_reference_job, jobs))
        elif self.workers > 1 and len(jobs) > 1:
            with ProcessPoolExecutor(max_workers=self.workers) as pool:
                results = list(pool.map(_reference_job, jobs))
        else:
            results = [_reference_job(j) for j in jobs]
        c, e = x.shape[0], len(prepared)
        n = prepared[0].times_s.size
        n_links = robots[0].n_links
        pos = np.empty((c, e, n, 2))
        heading = np.empty((c, e, n))
        for j, p in enumerate(prepared):
            states = np.array([results[i * e + j][0] for i in range(c)])
            pos[:, j], heading[:, j] = p.positions(states, n_links)
        fail = np.array([r[1] for r in results], dtype=int).reshape(c, e)
        left = np.array([r[2] for r in results]).reshape(c, e)
        arrival = np.array([r[3] for r in results]).reshape(c, e)
        failed = np.array([r[4] for r in results]).reshape(c, e)
        steps = np.array([r[5] for r in results]).reshape(c, e)
        return Simulated(pos, heading, fail, left, arrival, failed, steps)
