"""Our batched kernel against MuJoCo's rollout, each engine in a process of its own, windows paired.

Timed in one process, the two engines disturb each other: numba's OpenMP threads keep spinning
for a while after a batch (they wait actively for the next parallel region) while MuJoCo's
thread pool wants the same cores. Timed one after the other in separate processes, minutes
apart, each engine samples another moment of a shared machine's load, which changes from second
to second: one measurement of each gave ratios from 43 to 90 (issue 32), and five rounds of
process-isolated best-of-5 timings still moved by -20 % to +10 % about their median.

So each engine lives in a worker process of its own (:class:`EngineProcess`, running
``python -m eelhost.benchmarks.engine_rounds``), started once and warmed up once (the kernel
loads its compiled code and starts its threads; MuJoCo builds its model), and then times one
short *window* at a time when asked, while the other workers wait idle on their pipes (no
thread of theirs runs: MuJoCo's pool exists only inside its window, and a short pause before
each window lets the kernel's OpenMP threads go to sleep). A *round* is one window of each
engine, back to back, the order rotated from round to round so that no engine always runs
first; its ratios compare windows a second or two apart, which see nearly the same load, and
the report gives their median and spread over many rounds (:func:`engine_rounds`).
"""

from __future__ import annotations

import json
import os
import pickle
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import IO, Any

import numpy as np

from eelhost.machine import load_average
from eelhost.progress import Progress
from eelsim.batch import BatchSpec
from eelsim.closed_loop import LoopOptions
from eelsim.robot import Robot
from eelsim.scenario import TRAINING_CORNERS, grid_scenario

ENGINES = ("pd kernel", "servo kernel", "mujoco")
"""What a round times: the batched kernel with each joint model, and MuJoCo's rollout."""

MUJOCO_WINDOW_FRACTION = 50
"""A MuJoCo window runs this fraction of the batch's runs (12 of 600): about as long as the
kernel's window, a whole generation, on this kind of machine (MuJoCo is about 100 times
slower per step), so that the two windows of a round see the same moment of the load."""

PAUSE_S = 0.1
"""Idle time before each window: the previous window's threads (numba's OpenMP workers spin
for a few milliseconds after a parallel region) are asleep by then."""


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
        The batch: runs of ``steps`` RK4 steps (the GA generation of ``eelbot bench``). The
        kernel's window is the whole batch; MuJoCo's runs ``runs / MUJOCO_WINDOW_FRACTION`` of
        the runs (at least two per thread).
    threads : int
    """

    engine: str
    robot: Robot
    runs: int
    steps: int
    threads: int


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


def mujoco_window_runs(runs: int, threads: int) -> int:
    """Runs in one MuJoCo window: a fraction of the batch, at least two per thread."""
    return max(2 * threads, runs // MUJOCO_WINDOW_FRACTION)


class Engine:
    """One engine, prepared in this process: :meth:`window` times one window.

    Parameters
    ----------
    job : EngineJob

    Raises
    ------
    ValueError
        For an unknown engine.
    """

    def __init__(self, job: EngineJob) -> None:
        self.job = job
        if job.engine == "mujoco":
            from eelhost.benchmarks import mujoco_compare

            self._mujoco = mujoco_compare.Rollouts(
                job.robot, mujoco_window_runs(job.runs, job.threads), job.steps, job.threads)
        elif job.engine == "kernel":
            from eelsim import batch

            self._batch = batch
            self._spec = generation_spec(job.robot, job.runs, job.steps)
        else:
            raise ValueError(f"unknown engine {job.engine!r}; expected 'kernel' or 'mujoco'")
        self.window()  # untimed: the kernel loads its code and starts its threads

    def window(self) -> tuple[float, float]:
        """Time one window: (steps simulated over all its runs, wall seconds)."""
        if self.job.engine == "mujoco":
            wall = self._mujoco.time_once()
            return float(self._mujoco.runs * self._mujoco.steps), wall
        start = time.perf_counter()
        res = self._batch.run_spec(self._spec, threads=self.job.threads)
        wall = time.perf_counter() - start
        return float(res.final_step.sum()), wall


def time_engine(job: EngineJob, windows: int) -> tuple[float, list[float]]:
    """Time ``windows`` windows of one engine in this process.

    Parameters
    ----------
    job : EngineJob
    windows : int

    Returns
    -------
    (steps, walls) : float and list of float
        Steps of one window (over all its runs), wall seconds of each window.
    """
    engine = Engine(job)
    timed = [engine.window() for _ in range(windows)]
    return timed[0][0], [wall for _, wall in timed]


class EngineProcess:
    """An engine in a worker process of its own, timing one window when asked.

    Parameters
    ----------
    job : EngineJob

    Raises
    ------
    RuntimeError
        When the process fails (its last lines of error output in the message).
    """

    def __init__(self, job: EngineJob) -> None:
        self.job = job
        # its error output goes to a file: a pipe nobody reads until the end could fill up
        self._errors = tempfile.TemporaryFile()
        self._proc = subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=self._errors,
                                      env=dict(os.environ))
        data = pickle.dumps(job)
        self._send(struct.pack("<Q", len(data)) + data)
        self._answer()  # prepared and warmed up

    def _send(self, data: bytes) -> None:
        stdin = self._stream(self._proc.stdin)
        try:
            stdin.write(data)
            stdin.flush()
        except BrokenPipeError:
            self._fail()

    def _answer(self) -> dict[str, Any]:
        text = self._stream(self._proc.stdout).readline()
        if not text:
            self._fail()
        answer: dict[str, Any] = json.loads(text)
        return answer

    @staticmethod
    def _stream(stream: IO[bytes] | None) -> IO[bytes]:
        if stream is None:  # pragma: no cover - Popen was given pipes
            raise RuntimeError("engine process without pipes")
        return stream

    def _fail(self) -> None:
        self._proc.wait()
        self._errors.seek(0)
        tail = self._errors.read().decode(errors="replace").strip()
        raise RuntimeError(f"timing {self.job.engine} in its own process failed: "
                           f"{' | '.join(tail.splitlines()[-3:])}")

    def rate(self) -> float:
        """Steps per second of one window, timed now (after :data:`PAUSE_S` idle)."""
        time.sleep(PAUSE_S)
        self._send(b"w\n")
        answer = self._answer()
        return float(answer["steps"]) / float(answer["wall"])

    def close(self) -> None:
        """End the worker."""
        if self._proc.poll() is None:
            try:
                self._send(b"q\n")
            except RuntimeError:
                pass
            self._proc.wait()
        for stream in (self._proc.stdin, self._proc.stdout):
            if stream is not None:
                stream.close()
        self._errors.close()


@dataclass(frozen=True)
class Round:
    """One round: each engine's steps per second in one window, back to back, and the load.

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

    For each thread count, the three engines' worker processes are started (and warmed up)
    once; each round then times one window of each, back to back, the order rotated from round
    to round.

    Parameters
    ----------
    pd_robot, servo_robot : Robot
        The same links with PD and with servo joints (MuJoCo runs the PD one).
    runs, steps : int
        The batch.
    thread_counts : sequence of int
        The threads every engine gets.
    rounds : int
        Rounds per thread count.

    Returns
    -------
    list of Round
        ``len(thread_counts)`` x ``rounds`` rounds, in the order measured.
    """
    out = []
    with Progress("bench: engines, each in its own process, windows in rounds",
                  total=len(thread_counts) * (3 + rounds), unit="step") as progress:
        for threads in thread_counts:
            jobs = {"pd kernel": EngineJob("kernel", pd_robot, runs, steps, threads),
                    "servo kernel": EngineJob("kernel", servo_robot, runs, steps, threads),
                    "mujoco": EngineJob("mujoco", pd_robot, runs, steps, threads)}
            workers: dict[str, EngineProcess] = {}
            try:
                for engine in ENGINES:
                    workers[engine] = EngineProcess(jobs[engine])
                    progress.update()
                for r in range(rounds):
                    order = ENGINES[r % 3:] + ENGINES[: r % 3]
                    before = load_average()
                    rates = {engine: workers[engine].rate() for engine in order}
                    out.append(Round(threads, rates, before, load_average()))
                    progress.update()
            finally:
                for worker in workers.values():
                    worker.close()
    return out


def spread(values: Sequence[float]) -> str:
    """``median (min-max)`` of ``values``, one decimal."""
    v = np.asarray(values, dtype=float)
    return f"{np.median(v):.1f} ({v.min():.1f}-{v.max():.1f})"


def quartiles(values: Sequence[float], digits: int = 1) -> str:
    """``median (lower quartile-upper quartile)`` of ``values``."""
    q1, q2, q3 = np.percentile(np.asarray(values, dtype=float), [25, 50, 75])
    return f"{q2:.{digits}f} ({q1:.{digits}f}-{q3:.{digits}f})"


def _serve() -> int:
    """The worker: read the job, prepare, then time a window per ``w`` line until ``q``."""
    # the answers go to the original stdout; anything else printed (by Python or by compiled
    # code) goes to stderr and cannot garble them
    answers = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    stdin = sys.stdin.buffer
    size = struct.unpack("<Q", stdin.read(8))[0]
    engine = Engine(pickle.loads(stdin.read(size)))
    print(json.dumps({"ready": True}), file=answers, flush=True)
    for command in stdin:
        if command.strip() != b"w":
            break
        steps, wall = engine.window()
        print(json.dumps({"steps": steps, "wall": wall}), file=answers, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_serve())
