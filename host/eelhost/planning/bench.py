"""The planning benchmark: plan in generated worlds, swim each plan with drawn coefficients.

docs/planning.md ("Benchmark") states what is measured. For each world of
:func:`eelhost.planning.worlds.generate_world`:

1. the planner runs (refusals, search, check over the uncertainty ensemble, repairs) and is timed
   (a warm-up plan first, so the batched kernel is loaded from its disk cache);
2. a returned plan is swum in the twin from the start, once with a straight and once with a
   turning coefficient set drawn within the reported uncertainty
   (:meth:`eelhost.planning.uncertainty.CoefficientModel.draw`, seeded per world); a world counts
   as reached when both runs enter the goal disc, and as a collision when either touches.
"""

from __future__ import annotations

import multiprocessing
import statistics
import time
from collections import Counter
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from eelhost.planning.execute import swim
from eelhost.planning.planner import Planner
from eelhost.planning.uncertainty import CoefficientModel
from eelhost.planning.world import World
from eelhost.planning.worlds import generate_world
from eelsim.robot import Robot


@dataclass
class WorldResult:
    """One world's outcome in the benchmark.

    Attributes
    ----------
    name : str
    status : str
        The planner's status (``found`` or why not).
    message : str
    planning_time_s : float
        Set-up (the world's clearance and goal maps), refusal checks, search, check runs and
        repairs.
    search_time_s : float
        The searches alone.
    cpu_time_s : float
        Processor time of this process over the same span as ``planning_time_s`` (the work,
        whatever else the machine is running).
    repairs : int
    reached : bool or None
        Both drawn-coefficient runs entered the goal (None without a plan).
    collision : bool or None
        Either drawn-coefficient run touched an obstacle or wall (None without a plan).
    min_clearance_m : float
        Smallest body clearance over the drawn-coefficient runs (NaN without a plan).
    goal_distance_m : float
        Closest approach of the worse run to the goal centre (NaN without a plan).
    """

    name: str
    status: str
    message: str
    planning_time_s: float
    search_time_s: float
    cpu_time_s: float
    repairs: int
    reached: bool | None = None
    collision: bool | None = None
    min_clearance_m: float = float("nan")
    goal_distance_m: float = float("nan")


@dataclass
class BenchSummary:
    """The benchmark's figures.

    Attributes
    ----------
    results : list of WorldResult
    statuses : Counter
        Worlds per planner status.
    """

    results: list[WorldResult] = field(default_factory=list)
    statuses: Counter = field(default_factory=Counter)

    @property
    def planned(self) -> list[WorldResult]:
        """Worlds with a returned plan."""
        return [r for r in self.results if r.status == "found"]

    @property
    def collisions(self) -> int:
        """Planned worlds where a drawn-coefficient run touched something."""
        return sum(bool(r.collision) for r in self.planned)

    @property
    def reached(self) -> int:
        """Planned worlds where both drawn-coefficient runs entered the goal."""
        return sum(bool(r.reached) for r in self.planned)

    @property
    def median_planning_time_s(self) -> float:
        """Median planning time over all worlds (refused ones included)."""
        return statistics.median(r.planning_time_s for r in self.results)

    def lines(self) -> list[str]:
        """The figures as markdown list items."""
        n = len(self.results)
        p = len(self.planned)
        times = sorted(r.planning_time_s for r in self.results)
        search = sorted(r.search_time_s for r in self.results)
        found_t = sorted(r.planning_time_s for r in self.planned) or [float("nan")]
        out = [
            f"- worlds: {n}; with a plan: {p} ({p / n:.0%})",
            "- outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(self.statuses.items())),
            f"- collisions in the drawn-coefficient runs: {self.collisions} of {p} planned worlds",
            f"- goal reached in both drawn-coefficient runs: {self.reached} of {p} "
            f"({self.reached / max(p, 1):.1%})",
            f"- planning time (set-up, refusal checks, search, check runs, repairs): median "
            f"{statistics.median(times):.2f} s, 90th percentile {np.percentile(times, 90):.2f} s, "
            f"max {times[-1]:.2f} s; worlds with a plan: median {statistics.median(found_t):.2f} s",
            f"- search alone: median {statistics.median(search):.2f} s",
        ]
        repaired = sum(r.repairs > 0 for r in self.planned)
        cpu = sorted(r.cpu_time_s for r in self.results)
        out.append(f"- processor time of the planning (the same span; what the wall-clock figures "
                   f"are when the machine is otherwise idle): median {statistics.median(cpu):.2f} s, "
                   f"90th percentile {np.percentile(cpu, 90):.2f} s")
        out.append(f"- plans repaired after a failed check: {repaired}")
        return out


def bench_world(world: World, robot: Robot, coefficients: CoefficientModel, seed: int,
                threads: int | None = 1) -> WorldResult:
    """Plan in one world and swim the plan with drawn coefficients (module docstring).

    Parameters
    ----------
    world : World
    robot : Robot
    coefficients : CoefficientModel
    seed : int
        Seed of the coefficient draws.
    threads : int or None

    Returns
    -------
    WorldResult
    """
    t0, c0 = time.perf_counter(), time.process_time()
    planner = Planner(world, robot, coefficients, threads=threads)
    outcome = planner.plan()
    elapsed = time.perf_counter() - t0  # the planner's set-up (clearance and goal maps) too
    result = WorldResult(world.name, outcome.status, outcome.message, elapsed,
                         outcome.search_time_s, time.process_time() - c0, outcome.repairs)
    if not outcome.found:
        return result
    rng = np.random.default_rng(seed)
    drawn = [(f"drawn {m}", coefficients.draw(rng, m, planner.sigmas))
             for m in ("straight", "turning")]
    duration = 2.0 * outcome.plan.cost_s + 30.0
    runs = swim(world, outcome.plan.waypoints_m, planner.twin, drawn, duration,
                clearance=planner.clearance)
    result.reached = all(r.reached for r in runs)
    result.collision = not all(r.collision_free for r in runs)
    result.min_clearance_m = min(r.min_clearance_m for r in runs)
    result.goal_distance_m = max(r.goal_distance_m for r in runs)
    return result


def _warm_up(robot: Robot, coefficients: CoefficientModel, seed: int,
             threads: int | None) -> None:
    """Load the batched kernel and measure the swimming speed once (not timed)."""
    bench_world(generate_world(seed), robot, coefficients, seed, threads)


def _one(robot: Robot, coefficients: CoefficientModel, seed: int,
         threads: int | None) -> WorldResult:
    return bench_world(generate_world(seed), robot, coefficients, seed, threads)


def run_bench(
    robot: Robot,
    coefficients: CoefficientModel,
    count: int = 100,
    seed: int = 0,
    threads: int | None = 1,
    progress: Callable[[int, WorldResult], None] | None = None,
    jobs: int = 1,
) -> BenchSummary:
    """Run the benchmark over ``count`` generated worlds (seeds ``seed`` .. ``seed + count - 1``).

    Parameters
    ----------
    robot : Robot
    coefficients : CoefficientModel
    count : int
    seed : int
    threads : int or None
    progress : callable, optional
        Called with (index, result) after each world, in order.
    jobs : int
        Worlds planned at once, each in its own process (one per core: every plan still runs
        on one core, so its time is what one plan takes on an otherwise idle core).

    Returns
    -------
    BenchSummary
    """
    seeds = list(range(seed, seed + count))
    summary = BenchSummary()
    if jobs <= 1:
        _warm_up(robot, coefficients, seed + count, threads)
        results: Iterable[WorldResult] = (_one(robot, coefficients, s, threads) for s in seeds)
        _collect(summary, results, progress)
        return summary
    # spawned, not forked: a fork after the kernel's OpenMP runtime started is unsafe
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"),
                             initializer=_warm_up,
                             initargs=(robot, coefficients, seed + count, threads)) as pool:
        results = pool.map(_one, *zip(*[(robot, coefficients, s, threads) for s in seeds],
                                       strict=True))
        _collect(summary, results, progress)
    return summary


def _collect(summary: BenchSummary, results: Iterable[WorldResult],
             progress: Callable[[int, WorldResult], None] | None) -> None:
    for k, r in enumerate(results):
        summary.results.append(r)
        summary.statuses[r.status] += 1
        if progress is not None:
            progress(k, r)
