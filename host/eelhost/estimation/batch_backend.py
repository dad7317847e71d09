"""The Evaluator's fast backend: every (candidate, experiment) pair in one batched-kernel call.

The kernel samples all runs at one shared set of steps, so the union of every experiment's sample
steps is requested and each run's own are picked from it. Experiments whose loop options differ go
in separate calls (the options are shared by a batch).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from eelsim.batch import run_batch
from eelsim.robot import Robot


def simulate_batch(robot: Robot, prepared: Sequence, coefficients: np.ndarray):
    """Simulate every prepared experiment for every candidate with ``eelsim.batch``.

    Parameters
    ----------
    robot : Robot
    prepared : sequence of PreparedExperiment
    coefficients : ndarray, shape (C, 4)

    Returns
    -------
    Simulated
    """
    from eelhost.estimation.evaluate import Simulated

    c, e = coefficients.shape[0], len(prepared)
    n = prepared[0].times_s.size
    n_links = robot.n_links
    pos = np.full((c, e, n, 2), np.nan)
    heading = np.full((c, e, n), np.nan)
    failure = np.zeros((c, e), dtype=int)
    left = np.zeros((c, e))
    arrival = np.full((c, e), np.nan)
    failed = np.full((c, e), np.nan)
    groups: dict[object, list[int]] = {}
    for j, p in enumerate(prepared):
        groups.setdefault(p.options, []).append(j)
    for options, members in groups.items():
        union = np.unique(np.concatenate([prepared[j].state_steps for j in members]))
        scenarios = [prepared[j].scenario for _ in range(c) for j in members]
        coeffs = np.repeat(coefficients, len(members), axis=0)
        res = run_batch(robot, scenarios, coeffs, options, seeds=0, sample_steps=union)
        states = res.states.reshape(c, len(members), union.size, -1)
        for k, j in enumerate(members):
            picked = states[:, k, np.searchsorted(union, prepared[j].state_steps)]
            pos[:, j], heading[:, j] = prepared[j].positions(picked, n_links)
        failure[:, members] = np.asarray(res.failure, dtype=int).reshape(c, len(members))
        left[:, members] = np.asarray(res.distance_left_m).reshape(c, len(members))
        arrival[:, members] = np.asarray(res.arrival_time_s, dtype=float).reshape(c, len(members))
        codes = np.asarray(res.failure, dtype=int).reshape(c, len(members))
        times = np.asarray(res.failure_time_s, dtype=float).reshape(c, len(members))
        failed[:, members] = np.where(codes != 0, times, np.nan)
    return Simulated(pos, heading, failure, left, arrival, failed)
