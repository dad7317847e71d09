"""The planning benchmark: plan in generated worlds, swim each plan with drawn coefficients.

docs/planning.md ("Benchmark") states what is measured. For each world of
:func:`eelhost.planning.worlds.generate_world`:

1. the planner runs (refusals, search, check over the uncertainty ensemble, repairs) and is timed
   (a warm-up plan first, so the batched kernel is loaded from its disk cache);
2. a returned plan is swum in the twin from the start over ``BENCH_DRAWS`` fresh draws of the
   water (:meth:`eelhost.planning.uncertainty.CoefficientModel.water_draws`, seeded per world
   and apart from the check's own draws: coefficients jointly within the fit's 95 % region, the
   unknown current at its bound in directions round the circle); a world counts as reached when
   every run enters the goal disc, and as a collision when the independent audit
   (:mod:`eelhost.planning.audit`, shapely's exact geometry) finds the body touching anything
   in any run.
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

from eelhost.planning.audit import body_gaps_m
from eelhost.planning.planner import (
    CHECK_MARGIN_M,
    GuidanceChoice,
    Outcome,
    Planner,
    laws_of,
    plan_with_laws,
)
from eelhost.planning.uncertainty import (
    DEFAULT_UNKNOWN_CURRENT_M_S,
    LATTICE,
    CoefficientModel,
)
from eelhost.planning.world import World
from eelhost.planning.worlds import generate_world
from eelsim.guidance import PURSUIT, GuidanceLaw
from eelsim.model import SwimmerModel
from eelsim.robot import Robot

BENCH_DRAWS = 8
"""Draws of the water each returned plan is swum in after planning (apart from the check's)."""

AUDIT_SEED_OFFSET = 1_000_003
"""Added to a world's seed for the bench's own draws, so they are not the check's."""


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
        Every drawn-water run entered the goal (None without a plan).
    collision : bool or None
        The audit found contact in a drawn-water run (None without a plan).
    min_clearance_m : float
        Smallest body gap over the drawn-water runs, by the audit (NaN without a plan).
    goal_distance_m : float
        Closest approach of the worse run to the goal centre (NaN without a plan).
    overshoot_s : float
        With a budget: the wall time from the planning call's deadline to its return, s
        (negative: returned before it; NaN without a budget).
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
    collision_upper: float = float("nan")
    arrival_spread_s: tuple[float, float, float] = (float("nan"),) * 3
    planned_arrival_s: float = float("nan")
    overshoot_s: float = float("nan")


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
            f"- collisions (independent audit, shapely) in {BENCH_DRAWS} fresh draws of the water "
            f"per planned world: {self.collisions} of {p} planned worlds",
            f"- goal reached in every drawn-water run: {self.reached} of {p} "
            f"({self.reached / max(p, 1):.1%})",
            f"- planning time (set-up, refusal checks, search, check runs, repairs): median "
            f"{statistics.median(times):.2f} s, 90th percentile {np.percentile(times, 90):.2f} s, "
            f"max {times[-1]:.2f} s; worlds with a plan: median {statistics.median(found_t):.2f} s",
            f"- search alone: median {statistics.median(search):.2f} s",
        ]
        budgeted = [r.overshoot_s for r in self.results if r.overshoot_s == r.overshoot_s]
        if budgeted:
            late = sorted(budgeted)
            out.append(f"- with the budget (a deadline on each planning call, its check "
                       f"included): returned after its deadline in "
                       f"{sum(o > 0 for o in late)} of {len(late)} worlds, by at most "
                       f"{max(late[-1], 0.0) * 1000:.0f} ms; median return "
                       f"{-statistics.median(late) * 1000:.0f} ms before the deadline")
        repaired = sum(r.repairs > 0 for r in self.planned)
        cpu = sorted(r.cpu_time_s for r in self.results)
        out.append(f"- processor time of the planning (the same span; what the wall-clock figures "
                   f"are when the machine is otherwise idle): median {statistics.median(cpu):.2f} s, "
                   f"90th percentile {np.percentile(cpu, 90):.2f} s")
        hit = sum(bool(r.collision) for r in self.planned if r.repairs > 0)
        out.append(f"- plans repaired after a failed check: {repaired} (worlds with contact in "
                   f"the fresh draws: {hit} of the {repaired} repaired plans, "
                   f"{self.collisions - hit} of the {p - repaired} plans that passed at once)")
        if p:
            upper = sorted(r.collision_upper for r in self.planned)
            late = sorted(r.arrival_spread_s[2] / r.planned_arrival_s for r in self.planned)
            out.append(f"- each plan's check: 0 failures in its draws, collision probability at "
                       f"most {statistics.median(upper):.1%} (upper end of its Clopper-Pearson "
                       f"interval, 95 % over every plan the repairs may check; median over the "
                       f"planned worlds)")
            out.append(f"- arrival: the 95th percentile of the check runs' arrival times over "
                       f"the search's planned time, median {statistics.median(late):.2f} (max "
                       f"{late[-1]:.2f})")
        return out


def bench_world(world: World, robot: Robot, coefficients: CoefficientModel, seed: int,
                threads: int | None = 1,
                unknown_current_m_s: float = DEFAULT_UNKNOWN_CURRENT_M_S,
                guidance: GuidanceChoice = PURSUIT,
                swimmer: SwimmerModel | None = None,
                budget_s: float | None = None,
                check_margin_m: float = CHECK_MARGIN_M,
                arrival_stop: bool = True) -> WorldResult:
    """Plan in one world and swim the plan in fresh draws of the water (module docstring).

    Parameters
    ----------
    world : World
    robot : Robot
    coefficients : CoefficientModel
    seed : int
        Seed of the planner's check draws; the bench's own draws use ``seed +
        AUDIT_SEED_OFFSET``.
    threads : int or None
    unknown_current_m_s : float
        The unknown current's bound, for the check and the bench's draws.
    guidance : GuidanceLaw or tuple of GuidanceLaw
        The robot's guidance law (the planner's, and the bench's runs'); a tuple: the laws
        tried in turn (``planner.plan_with_laws``), the bench's runs steering with the plan's.
    swimmer : SwimmerModel, optional
        The model of the robot the planner swims, built once by the command
        (:meth:`CoefficientModel.swimmer_for`; built here when not given).
    budget_s : float, optional
        A deadline this long after the planning call starts (the planner built already, as a
        replan's is): ``Planner.plan(deadline_s=)``, its check included. Default: none.
    check_margin_m : float
        The check's margin (:data:`eelhost.planning.planner.CHECK_MARGIN_M`); the fresh draws
        are judged by contact alone, whatever it is.
    arrival_stop : bool
        The planner's check judges the arrival's stop (:class:`Planner`'s ``arrival_stop``); the
        fresh draws swim it either way.

    Returns
    -------
    WorldResult
    """
    t0, c0 = time.perf_counter(), time.process_time()
    deadline: float | None = None

    def make(law: GuidanceLaw) -> Planner:
        nonlocal deadline
        made = Planner(world, robot, coefficients, threads=threads, seed=seed,
                       unknown_current_m_s=unknown_current_m_s, guidance=law,
                       swimmer=swimmer, check_margin_m=check_margin_m,
                       arrival_stop=arrival_stop)
        if deadline is None and budget_s is not None:  # one deadline for every law tried
            deadline = time.monotonic() + budget_s
        return made

    def call(made: Planner) -> Outcome:
        return made.plan(deadline_s=deadline)

    planner, outcome = plan_with_laws(make, laws_of(guidance), call)
    done = time.monotonic()
    elapsed = time.perf_counter() - t0  # the planner's set-up (clearance and goal maps) too
    result = WorldResult(world.name, outcome.status, outcome.message, elapsed,
                         outcome.search_time_s, time.process_time() - c0, outcome.repairs)
    if deadline is not None:
        result.overshoot_s = done - deadline
    if not outcome.found:
        return result
    # the fresh draws keep the lattice of directions the benchmark has always judged with
    draws = coefficients.water_draws(np.random.default_rng(seed + AUDIT_SEED_OFFSET),
                                     BENCH_DRAWS, unknown_current_m_s, LATTICE)
    # judged through the arrival's stop whether or not the check was (docs/planning.md, "The
    # arrival's stop in the check")
    runs = planner.swim_waters(outcome.plan, draws, through_stop=True)
    gaps = [float(body_gaps_m(planner.world, planner.model, r.states).min()) for r in runs]
    result.reached = all(r.reached for r in runs)
    result.collision = min(gaps) <= 0.0
    result.min_clearance_m = min(gaps)
    result.goal_distance_m = max(r.goal_distance_m for r in runs)
    result.collision_upper = outcome.collision_probability[2]
    result.arrival_spread_s = outcome.arrival_s
    result.planned_arrival_s = outcome.plan.cost_s
    return result


def _warm_up(robot: Robot, coefficients: CoefficientModel, seed: int,
             threads: int | None, unknown_current_m_s: float, guidance: GuidanceChoice,
             swimmer: SwimmerModel | None = None,
             check_margin_m: float = CHECK_MARGIN_M, arrival_stop: bool = True) -> None:
    """Load the batched kernel, measure the swimming speed and the check's cost (not timed)."""
    bench_world(generate_world(seed), robot, coefficients, seed, threads, unknown_current_m_s,
                guidance, swimmer, check_margin_m=check_margin_m, arrival_stop=arrival_stop)


def _one(robot: Robot, coefficients: CoefficientModel, seed: int,
         threads: int | None, unknown_current_m_s: float, guidance: GuidanceChoice,
         swimmer: SwimmerModel | None = None, budget_s: float | None = None,
         check_margin_m: float = CHECK_MARGIN_M, arrival_stop: bool = True) -> WorldResult:
    return bench_world(generate_world(seed), robot, coefficients, seed, threads,
                       unknown_current_m_s, guidance, swimmer, budget_s, check_margin_m,
                       arrival_stop)


def run_bench(
    robot: Robot,
    coefficients: CoefficientModel,
    count: int = 100,
    seed: int = 0,
    threads: int | None = 1,
    progress: Callable[[int, WorldResult], None] | None = None,
    jobs: int = 1,
    unknown_current_m_s: float = DEFAULT_UNKNOWN_CURRENT_M_S,
    guidance: GuidanceChoice = PURSUIT,
    swimmer: SwimmerModel | None = None,
    budget_s: float | None = None,
    check_margin_m: float = CHECK_MARGIN_M,
    arrival_stop: bool = True,
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
    unknown_current_m_s : float
        The unknown current's bound (the check's and the bench's draws).
    guidance : GuidanceLaw or tuple of GuidanceLaw
        The robot's guidance law, or the laws tried in turn (:func:`bench_world`).
    swimmer : SwimmerModel, optional
        The model of the robot the planner swims, built once by the command and handed to
        every world's planner (built here once when not given; each process has its copy).
    budget_s : float, optional
        Each world's planning call gets a deadline this long after it starts
        (:func:`bench_world`). Default: none.
    check_margin_m : float
        The check's margin (:func:`bench_world`).
    arrival_stop : bool
        The planner's check judges the arrival's stop (:class:`Planner`'s ``arrival_stop``).

    Returns
    -------
    BenchSummary
    """
    seeds = list(range(seed, seed + count))
    summary = BenchSummary()
    if swimmer is None:
        swimmer = coefficients.swimmer_for(robot)
    if jobs <= 1:
        _warm_up(robot, coefficients, seed + count, threads, unknown_current_m_s, guidance,
                 swimmer, check_margin_m, arrival_stop)
        results: Iterable[WorldResult] = (_one(robot, coefficients, s, threads,
                                               unknown_current_m_s, guidance, swimmer,
                                               budget_s, check_margin_m, arrival_stop)
                                          for s in seeds)
        _collect(summary, results, progress)
        return summary
    # spawned, not forked: a fork after the kernel's OpenMP runtime started is unsafe
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"),
                             initializer=_warm_up,
                             initargs=(robot, coefficients, seed + count, threads,
                                       unknown_current_m_s, guidance, swimmer,
                                       check_margin_m, arrival_stop)) as pool:
        results = pool.map(_one, *zip(*[(robot, coefficients, s, threads, unknown_current_m_s,
                                         guidance, swimmer, budget_s, check_margin_m,
                                         arrival_stop)
                                        for s in seeds],
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
