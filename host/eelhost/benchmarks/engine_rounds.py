"""Our batched kernel against MuJoCo's rollout, each engine timed in a process of its own.

Timed in one process, the two engines disturb each other: numba's OpenMP threads keep spinning
for a while after a batch (they wait actively for the next parallel region) while MuJoCo's
thread pool wants the same cores, and on a shared machine the load changes from minute to minute,
so one measurement of each gave ratios from 43 to 90 (issue 32). Here each measurement is a fresh
Python process that times one engine alone (:func:`time_engine`, run as
``python -m eelhost.benchmarks.engine_rounds``); a *round* times the PD kernel, the servo kernel
and MuJoCo one after the other, the order rotated from round to round so that no engine always
runs first; each round gives its own ratios (measured minutes apart at most), and the report
gives their median and range over the rounds (:func:`engine_rounds`).
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.machine import load_average
from eelhost.progress import Progress
from eelsim.batch import BatchSpec
from eelsim.closed_loop import LoopOptions
from eelsim.robot import Robot
from eelsim.scenario import TRAINING_CORNERS, grid_scenario

ENGINES = ("pd kernel", "servo kernel", "mujoco")
"""What a round times: the batched kernel with each joint model, and MuJoCo's rollout."""


@dataclass(frozen=True)
class EngineJob:
    """One engine's measurement, as sent to its process.

    Attributes
    ----------
    engine : str
        ``"kernel"`` or ``"mujoco"``.
    robot : Robot
        The robot (its joints decide the kernel's joint model; MuJoCo needs PD joints).
    runs, steps : int
        The batch: runs of ``steps`` RK4 steps (the GA generation of ``eelbot bench``).
    threads : int
    repeats : int
        Timed repetitions (the kernel's after one untimed run: cache load, thread start-up).
        MuJoCo's repetitions each run ``runs / repeats`` of the runs (it has nothing to warm):
        both engines are then timed as the best of ``repeats`` short windows.
    """

    engine: str
    robot: Robot
    runs: int
    steps: int
    threads: int
    repeats: int = 5


def generation_spec(robot: Robot, runs: int, steps: int) -> BatchSpec:
    """The batch ``eelbot bench`` times: the training corners' straight runs, coefficients x U(0.5, 1.5).

    Parameters
    ----------
    robot : Robot
    runs, steps : int

    Returns
    -------
    eelsim.batch.BatchSpec
    """
    opts = LoopOptions(stop_at_goal=False)
    corners = [grid_scenario("straight", a, w).model_copy(
        update={"duration_s": steps * opts.timing.dt_s}) for a, w in TRAINING_CORNERS]
    base = robot.hydrodynamics.as_array()
    candidates = base * np.random.default_rng(0).uniform(0.5, 1.5, size=(runs, base.size))
    return BatchSpec.build(robot, [corners[i % 4] for i in range(runs)], candidates, opts, 0)


def time_engine(job: EngineJob) -> tuple[float, list[float]]:
    """Time one engine in this process: RK4 or MuJoCo steps simulated, and each repeat's wall time.

    Parameters
    ----------
    job : EngineJob

    Returns
    -------
    (steps, walls) : float and list of float
        Steps of one repetition (over all runs), wall seconds of each timed repetition.
    """
    if job.engine == "mujoco":
        from eelhost.benchmarks import mujoco_compare

        chunk = max(job.threads, job.runs // job.repeats)
        timing = mujoco_compare.rollout_speed(job.robot, chunk, job.steps, job.threads,
                                              repeats=job.repeats)
        return float(chunk * job.steps), list(timing.walls_s)
    if job.engine != "kernel":
        raise ValueError(f"unknown engine {job.engine!r}; expected 'kernel' or 'mujoco'")
    from eelsim import batch

    spec = generation_spec(job.robot, job.runs, job.steps)
    res = batch.run_spec(spec, threads=job.threads)  # compile or load, start the threads
    walls = []
    for _ in range(job.repeats):
        start = time.perf_counter()
        res = batch.run_spec(spec, threads=job.threads)
        walls.append(time.perf_counter() - start)
    return float(res.final_step.sum()), walls


def time_engine_in_process(job: EngineJob) -> float:
    """Steps per second of ``job``'s engine, best of its repeats, timed in a fresh process.

    Parameters
    ----------
    job : EngineJob

    Returns
    -------
    float

    Raises
    ------
    RuntimeError
        When the process fails (its last lines of error output in the message).
    """
    out = subprocess.run([sys.executable, "-m", __name__], input=pickle.dumps(job),
                         capture_output=True, check=False, env=dict(os.environ))
    if out.returncode != 0:
        tail = out.stderr.decode(errors="replace").strip().splitlines()[-3:]
        raise RuntimeError(f"timing {job.engine} in its own process failed: {' | '.join(tail)}")
    result = json.loads(out.stdout.decode().strip().splitlines()[-1])
    return float(result["steps"]) / min(result["walls"])


@dataclass(frozen=True)
class Round:
    """One round: each engine's steps per second, timed alone, and the load around it.

    Attributes
    ----------
    threads : int
        Threads every engine used in this round.
    rates : dict
        Engine (:data:`ENGINES`) -> steps per second.
    load_before, load_after : str
        Load averages.
    """

    threads: int
    rates: dict[str, float]
    load_before: str
    load_after: str

    def ratio(self, engine: str, over: str = "mujoco") -> float:
        """``engine``'s rate over ``over``'s, in this round."""
        return self.rates[engine] / self.rates[over]


def engine_rounds(pd_robot: Robot, servo_robot: Robot, runs: int, steps: int,
                  thread_counts: Sequence[int], rounds: int) -> list[Round]:
    """Time the PD kernel, the servo kernel and MuJoCo, each in its own process, in rounds.

    Every round times the three engines with each thread count; the engines' order rotates
    from round to round. Each process reports its engine's best of five short windows (the
    kernel: five generations after an untimed one; MuJoCo: five rollouts of a fifth of the
    runs), the estimate of its speed least touched by the other processes' load.

    Parameters
    ----------
    pd_robot, servo_robot : Robot
        The same links with PD and with servo joints (MuJoCo runs the PD one).
    runs, steps : int
        The batch.
    thread_counts : sequence of int
        The threads every engine gets, one round per count and repetition.
    rounds : int
        Repetitions.

    Returns
    -------
    list of Round
        ``rounds`` x ``len(thread_counts)`` rounds, in the order measured.
    """
    out = []
    with Progress("bench: engines, each in its own process",
                  total=3 * rounds * len(thread_counts), unit="process") as progress:
        for r in range(rounds):
            for threads in thread_counts:
                jobs = {"pd kernel": EngineJob("kernel", pd_robot, runs, steps, threads),
                        "servo kernel": EngineJob("kernel", servo_robot, runs, steps, threads),
                        "mujoco": EngineJob("mujoco", pd_robot, runs, steps, threads)}
                order = ENGINES[r % 3:] + ENGINES[: r % 3]
                before = load_average()
                rates = {}
                for engine in order:
                    rates[engine] = time_engine_in_process(jobs[engine])
                    progress.update()
                out.append(Round(threads, rates, before, load_average()))
    return out


def spread(values: Sequence[float]) -> str:
    """``median (min-max)`` of ``values``, one decimal."""
    v = np.asarray(values, dtype=float)
    return f"{np.median(v):.1f} ({v.min():.1f}-{v.max():.1f})"


def _main() -> int:
    job = pickle.loads(sys.stdin.buffer.read())
    steps, walls = time_engine(job)
    print(json.dumps({"steps": steps, "walls": walls}))
    return 0


if __name__ == "__main__":
    sys.exit(_main())
