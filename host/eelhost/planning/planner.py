"""The planner: refuse what cannot be planned, search, swim the plan in the twin, repair or refuse.

docs/planning.md ("The planner") is the long form. :meth:`Planner.plan`:

1. **Refusals**, each with its reason (:class:`PlanRefused`; the CLI exits 2): the start pose
   puts the body into an obstacle or a wall (``blocked_start``); the current is at least the
   robot's own swimming speed, so no leg can be swum against it (``current_too_strong``); the
   goal's centre inside an obstacle or a wall, or closer to one than the body's half width
   (``goal_blocked``); no corridor wide enough for the body joins start and goal
   (``unreachable``). A goal outside the
   tank is refused when the world is read (:class:`eelhost.planning.world.WorldError`).
2. **Search** (:class:`eelhost.planning.search.Search`): every leg swum in the twin from the state
   the previous one left, with the straight coefficients for straight legs and the turning ones
   for turns. With ``cramped_start`` (off by default), when the first search from the world's
   start is ``exhausted`` (a cramped start), a second one offers its first legs turns of up to
   120 degrees (:data:`CRAMPED_ACTIONS`).
3. **Check**: the plan is swum in the twin leg by leg as the search swam it
   (:func:`eelhost.planning.check.swim_legs`), with the fits as fitted and in ``draws`` draws
   of the water (:meth:`eelhost.planning.uncertainty.CoefficientModel.water_draws`: every
   coefficient of both fits drawn jointly within its fit's 95 % region, the fitted current
   within its own, and an unknown current of ``unknown_current_m_s`` in directions round the
   circle), all waters of a leg in one batch. Every run must enter the goal disc (:func:`eelhost.planning.search.in_goal`) without
   any contact. A plan that passes carries an estimated collision probability of 0 in ``draws``
   with its Clopper-Pearson interval, and its arrival time is the check runs' (median and range).
   The first ``SCREEN_DRAWS`` draws are swum first: a plan most draws fail is repaired without
   swimming the rest.
4. **Repair**: the leg most check runs failed on (the leg being swum at the first contact, or
   the last leg when the goal was missed) is banned and the search runs again (it keeps what it
   swam), with its margin raised where the failing runs came too close (:meth:`Planner.failure_sites`,
   :meth:`eelhost.planning.search.Search.raise_margin`; docs/planning_history.md, "A repair with the
   margin raised where the check failed"); after ``repairs`` attempts the plan is refused with
   the reason of the last failure.
   Each searched plan is checked over its own draws, fresh and independent of the draws that
   failed the plans before it (:meth:`Planner.waters`), so a repaired plan is not one chosen to
   pass the very draws its predecessors failed; and a plan's interval is a simultaneous one over
   every plan a planning call may check (:data:`CHECK_LEVEL` split evenly over ``repairs + 1``
   plans, Bonferroni), so the stated bound holds for whichever plan the repairs return
   (docs/planning.md, "The planner", step 4).
5. **Deadline** (``deadline_s``, a replan's at the tank): the whole call, checks included,
   returns by it up to a small overshoot; every search keeps the check's predicted time free
   (its cost per run-step measured in this process) and the check starts no leg it predicts
   would end late, so a plan whose check did not finish comes back ``out_of_time``, never as
   checked (docs/planning.md, "The planning call's deadline").
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, SupportsFloat

import numpy as np

from eelhost.errors import UserError
from eelhost.planning.body import body_points
from eelhost.planning.check import ARRIVAL_STOP_STRIDE, CHECK_COST, CheckOutOfTime, swim_legs
from eelhost.planning.execute import Swim
from eelhost.planning.field import GoalDistance, clearance_field, signed_clearance
from eelhost.planning.geometry import FloatArray
from eelhost.planning.harbour import FINAL_GLIDE_S, StopWindow, stop_states
from eelhost.planning.memo import BoundedCache
from eelhost.planning.search import Actions, Guide, Plan, Search, SearchSettings, SwimCost
from eelhost.planning.twin import Twin
from eelhost.planning.uncertainty import (
    DEFAULT_UNKNOWN_CURRENT_M_S,
    CoefficientModel,
    WaterDraw,
    clopper_pearson,
)
from eelhost.planning.world import World
from eelsim.closed_loop import LoopOptions
from eelsim.control import Gait
from eelsim.dynamics import straight_state
from eelsim.fluid import FluidCoefficients
from eelsim.guidance import PURSUIT, GuidanceLaw
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import PATH_GAIT

log = logging.getLogger(__name__)

SPEED_RUN_S = 20.0
"""Length of the twin run that measures the swimming speed, s."""

CHECK_DRAWS = 60
"""Draws of the water a plan is checked over by default (0 failures in 60: collision probability
at most 6.0 %, the upper end of its two-sided 95 % Clopper-Pearson interval)."""

CHECK_LEVEL = 0.95
"""Confidence of the stated collision-probability interval over all the plans one planning call may
check (the first and its repairs): each plan's Clopper-Pearson interval is taken at
``1 - (1 - CHECK_LEVEL) / (repairs + 1)`` (Bonferroni), so that the chance that the planner
returns a plan whose failure probability lies above its stated interval is at most 5 % however
many repairs it took (docs/planning.md, "The planner", step 4)."""

CHECK_MARGIN_M = 0.03
"""The check's margin, m: every check run (the fits' and each draw's) must keep the body this far
from everything, not merely clear of it. A plan whose worst draw came within a few millimetres of
contact is one whose collision probability sits near its stated bound: on development seeds
12000-12299 (ILOS) 12 of the 28 plans that passed 0-30 mm clear touched in 60 further fresh
draws (24 of 1680 runs), and 3 of them in the benchmark's 8; of the 29 clearer ones 2, both
repaired plans (docs/planning_history.md, "Targets of issue 28 (the planner's)", "Session 8's
development figures"). Coming within the margin counts as the run failing; so 0 such runs in n draws
bound the probability of coming within the margin, and with it the (smaller) probability of
contact, by the same Clopper-Pearson interval."""

REPAIR_DRAWS_FACTOR = 3
"""A repaired plan is checked over this many times ``draws`` draws (180 by default). A repair is
the search's next plan round the leg the last one failed on, and most of them fail much as their
predecessor did: on development seeds 12000-12299 (ILOS) 2 of the 11 repaired plans that passed
their 60 draws more than 30 mm clear touched in 60 further fresh draws (by 9-20 mm, where their
other runs kept 27 mm or more: a few draws going wrong, not the tail the margin covers), none
of the 18 such first plans; with pure pursuit (12000-12099) 1 of 2 repaired plans. A plan that fails one draw in 30 passes 60 draws with
probability 13 %, 180 with 0.2 %; for each of the up to ``repairs`` plans the planner may try
that is the chance it is returned (docs/planning.md, "The planner", step 5)."""

DEADLINE_DRAWS_MIN = 20
"""Fewest draws a first plan's check is cut to when a planning call's deadline leaves no room for
its whole check (:meth:`Planner.draws_within`): 0 failures in 20 still bound the probability of
coming within the margin by about 17 % (95 %, two-sided Clopper-Pearson), stated as such in the
plan's message. A repaired plan's check is never cut below ``draws`` (the first plan's)."""

CHECK_SHARE_MAX = 0.5
"""Largest share of the time left at a planning call's start that the kept-free check may take;
beyond it the check's draws are cut (:meth:`Planner.draws_within`). Until session 9 the search
kept the whole check's predicted time free, and under load (a load average of 15-29) that alone
exceeded a replan's 1 s budget: the search started no expansion (docs/planning.md, "The planning
call's deadline")."""

SCREEN_DRAWS = 4
"""Draws swum first; a plan that fails one is repaired without swimming the others. The verdict
does not depend on it (every draw must pass), only what a failing plan costs: the plans that fail
their check fail about 40 % of the draws at the default bound (docs/planning_history.md,
"Targets of issue 28 (the planner's)"), so 4 draws catch most of them; 4 instead of 12 cut the median
processor time on development worlds by a tenth to a fifth with the same statuses (the leg a
repair bans is chosen among the failing runs swum, so it can differ)."""

BATCH_RUNS = 16
"""Check runs swum in one batch (each holds every physics step of its run)."""

ROBUST_MARGIN_M = 0.002
"""With ``robust_search``, the body's gap every extra water's run keeps (over its half width)."""

RAISE_SAFETY_M = 0.01
"""A repair raises the search's margin where the check failed by what the failing run lacked
plus this, m (:meth:`Planner.failure_sites`)."""

RAISE_MAX_M = 0.15
"""The most a repair raises the search's margin at one place, m."""

RAISE_NEAR_M = 0.1
"""The fits' run's room near a failure is its smallest over body points this near it, m."""

PLANNING_GUIDANCE = GuidanceLaw("ilos", lookahead_m=0.2, integral_gain=0.02, heading_gain=1.0)
"""The integral line-of-sight law a plan may be searched, checked and followed with
(``eelbot plan --guidance ilos``; docs/planning.md, "The guidance"): it holds each leg in a current
the planner does not know, where the paper's pure pursuit drifts off it. Not the default (the
tank's closed-loop A/B kept pure pursuit, docs/planning.md); the tank's run loop steers with either
(``eelbot run --plan WORLD --guidance ilos``)."""

AUTO_GUIDANCE = "auto"
"""The name of the guidance chosen per plan (``--guidance auto``): the laws of :data:`AUTO_LAWS`
in turn, the first whose plan passes its check kept (:func:`plan_with_laws`; docs/planning.md, "A
guidance law chosen per plan")."""

AUTO_LAWS: tuple[GuidanceLaw, ...] = (GuidanceLaw("pursuit_ff"), PURSUIT)
"""The laws ``auto`` tries, in order: pure pursuit aimed off by the known current, which planned
62 of 100 unseen worlds to pure pursuit's 48 (seeds 36000-36099, docs/planning_history.md, "The known
current fed forward into the pursuit"), then pure pursuit, which plans some worlds the first does
not (tank_5_obstacles among them)."""

GuidanceChoice = GuidanceLaw | tuple[GuidanceLaw, ...]
"""A planner's ``guidance`` as the commands hand it on: one law, or the laws to try in turn."""

LAW_FREE_REFUSALS = ("blocked_start", "current_too_strong", "goal_blocked", "unreachable")
"""Refusals no other law changes (the start's body, the still-water speed with pure pursuit, the
goal's and the free space's geometry): :func:`plan_with_laws` tries no further law after one."""


SOFT_MARGIN_BASE_M = 0.03
"""The soft margin's room over the hard margin for the coefficients' uncertainty alone, m."""

SOFT_MARGIN_DRIFT_S = 6.0
"""The soft margin's room per unit of unknown current, s (m per m/s): how far the robot strays
from the search's run in the check's currents (docs/planning.md, "The search")."""

SOFT_MARGIN_FLOOR_M = 0.06
"""The soft margin's least room over the hard margin, m, whatever the unknown current's bound:
the preferred clearance is the hard margin plus the larger of this and
``SOFT_MARGIN_BASE_M + SOFT_MARGIN_DRIFT_S * bound`` (it binds below 0.005 m/s, so the default
0.02 m/s keeps its 200 mm). With the coefficients alone (``eelbot run --bench
--check-unknown-current 0``) the check's draws came within its margin on legs the search had
swum a median 72 mm clear (centre line; development seeds 27000-27059), where 30 mm of preferred
room left most failing first plans short by a few millimetres (docs/planning_history.md, "Session 16's
development figures: plan share")."""

SOFT_MARGIN_COST = 3.0
"""The soft margin's cost, s per s swum, of a body point at the hard margin."""

CHECK_OVER_SEARCH = 4.0
"""Before the check's cost has been measured in this process, a run-step of the check is taken to
cost this many times a run-step of the search's swims, measured in the same call (the check
samples every physics step and measures the exact clearance of every state; docs/planning.md,
"The planning call's deadline")."""

CRAMPED_ACTIONS = Actions(distances_m=(0.3, 0.5),
                          bearings_deg=(-120.0, -90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0, 120.0))
"""The first plan's fallback from a cramped start (docs/planning_history.md, "A wider turn from a cramped
start"; ``Planner(cramped_start=True)``, off by default): when the search from the world's
start is ``exhausted``, a second search runs whose
first legs take this action set, the planner's legs plus turns of 90 and 120 degrees (the
recovery replan's, docs/planning.md "The recovery replan"), so that a robot started towards an
obstacle may turn away before its head, 0.3 m ahead of its centre of mass, comes near it; its
later legs take the planner's actions (wider turns there too planned one world more of 16 on
the development seeds, for a median processor time half a second higher). The margin, the
repairs and the check are the plain search's."""

CRAMPED_EXPANSIONS = 100
"""The fallback from a cramped start runs only when the plain search was exhausted within this
many expansions (a sixth of its 600): a start hemmed in, not a world searched through. On the
development seeds 28500-28799 the worlds it planned had been exhausted after 36-84 expansions;
the 10 of 54 exhausted after 109-529 took 1.3-9.0 s of processor time each with the fallback
and got no plan (docs/planning_history.md, "A wider turn from a cramped start")."""

LEG_TIME_FACTOR = 1.6
"""A leg's time limit per metre, as a multiple of the time the robot needs against the current."""


PLAN_LENGTH_WINDOW = 16
"""The expected plan length's ratio is the median over the process's last this many plans."""


class PlanLengths:
    """How long the plans found in this process were, over their free-space paths.

    Each ratio is a found plan's length (steps from its start to the goal's entry) over the
    free-space path of the body's centre from its start to the goal disc at the swimming speed
    (:meth:`Planner.expected_steps`): what a deadline expects of the next plan, measured, not
    assumed (docs/planning.md, "The planning call's deadline").
    """

    def __init__(self, window: int = PLAN_LENGTH_WINDOW) -> None:
        self._ratios: deque[float] = deque(maxlen=window)

    def record(self, ratio: float) -> None:
        """Add one found plan's ratio (ignored unless finite and above 0)."""
        if math.isfinite(ratio) and ratio > 0:
            self._ratios.append(float(ratio))

    def ratio(self, default: float) -> float:
        """The median of the recorded ratios, ``default`` before any."""
        return float(np.median(self._ratios)) if self._ratios else float(default)


PLAN_LENGTHS = PlanLengths()
"""The process's record of found plans' lengths, shared by every planner (replans' too)."""


ARRIVAL_BRAKE_S = 3.0
"""The brake before the run loop's final Stop with ``--plan`` and ``--bench``
(``eelhost.field.runloop.BRAKE_S``, the replanner's ``STOP_BRAKE_S``; a test holds them equal):
how the check swims the stop on arriving (docs/planning.md, "The arrival's stop in the check")."""


def _after_arrival_brake(t_s: float) -> float:
    """When the arrival's brake ends for a stop decided at ``t_s`` (:data:`ARRIVAL_BRAKE_S`)."""
    return t_s + ARRIVAL_BRAKE_S


ARRIVAL_STOP = StopWindow(_after_arrival_brake, FINAL_GLIDE_S)
"""The stop the tank makes on arriving, as the check and the search swim it: the brake, then
the straight body's glide (docs/planning.md, "The arrival's stop in the check")."""

ARRIVAL_STOPS_KEPT = 256
"""The search's arrival stops a planner keeps, by state and step (one per goal node popped)."""


def run_failed(run: Swim, margin_m: float = 0.0) -> bool:
    """A check run that fails: contact, the goal missed, or the body within ``margin_m``.

    Parameters
    ----------
    run : Swim
    margin_m : float
        The check's margin (:data:`CHECK_MARGIN_M`), m.

    Returns
    -------
    bool
    """
    return not run.ok or run.min_clearance_m <= margin_m


_WATERS: BoundedCache[tuple[CoefficientModel, list[WaterDraw]]] = BoundedCache(32)


def _water_draws(coefficients: CoefficientModel, seed: int | tuple[int, int], count: int,
                 unknown_current_m_s: float) -> list[WaterDraw]:
    """``coefficients.water_draws`` from the generator seeded with ``seed``, drawn once.

    The replanner builds a planner per current estimate with the same model, seed and draws:
    the draws (0.26 s on the slower processor) are the same, so they are kept (keyed by the
    model's identity; the entry holds the model, so its identity is never reused meanwhile).
    """
    def draw() -> tuple[CoefficientModel, list[WaterDraw]]:
        rng = np.random.default_rng(list(seed) if isinstance(seed, tuple) else seed)
        return coefficients, coefficients.water_draws(rng, count, unknown_current_m_s)

    return _WATERS.get((id(coefficients), seed, int(count), float(unknown_current_m_s)), draw)[1]


class PlanRefused(UserError, ValueError):
    """The planner refuses a world (the message says why; ``status`` names the case)."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


_SPEEDS: dict[tuple, float] = {}


def _swimming_speed(robot: Robot, coefficients: FluidCoefficients, gait: Gait,
                    options: LoopOptions, swimmer: SwimmerModel | None) -> float:
    twin = Twin(robot, [coefficients], gait, options, (0.0, 0.0), swimmer=swimmer)
    runs = twin.run([[(10.0, 0.0)]], SPEED_RUN_S, stride=10)
    n = robot.n_links
    com = runs.states[0, :, n : n + 2]
    com = com[np.isfinite(com[:, 0])]
    half = len(com) // 2  # the second half: past the start from rest
    t = (len(com) - 1 - half) * runs.stride * twin.dt_s
    return float(np.hypot(*(com[-1] - com[half])) / t)


def swimming_speed_m_s(robot: Robot, coefficients: FluidCoefficients, gait: Gait = PATH_GAIT,
                       options: LoopOptions | None = None,
                       swimmer: SwimmerModel | None = None) -> float:
    """The robot's steady straight swimming speed in still water, from a twin run.

    Parameters
    ----------
    robot : Robot
    coefficients : FluidCoefficients
    gait : Gait
    options : LoopOptions, optional
    swimmer : SwimmerModel, optional
        The robot's model, handed to the twin (:class:`eelhost.planning.twin.Twin`).

    Returns
    -------
    float
        Mean speed of the centre of mass over the second half of a 20 s straight run, m/s.
    """
    opts = options or LoopOptions()
    key = (robot.model_dump_json(), type(coefficients).__name__,
           coefficients.as_array().tobytes(), repr(gait), repr(opts))
    if key not in _SPEEDS:  # one twin run per robot, coefficients, gait and loop
        _SPEEDS[key] = _swimming_speed(robot, coefficients, gait, opts, swimmer)
    return _SPEEDS[key]


@dataclass
class Outcome:
    """What the planner did.

    Attributes
    ----------
    plan : Plan
        The last search's plan (``found`` False when refused).
    status : str
        ``found``, or why not: ``blocked_start``, ``current_too_strong``, ``unreachable``
        (refusals), ``exhausted``, ``gave_up`` (the search's), ``check_failed``,
        ``out_of_time`` (the deadline stopped a search or the check; a plan whose check it
        stopped is returned with ``found`` False and no check runs).
    message : str
        One line.
    checks : list of Swim
        The check runs of the returned plan (or of the last plan that failed them).
    repairs : int
        Searches re-run after a failed check.
    planning_time_s : float
        Search and check time, all attempts.
    search_time_s : float
        Search time alone, all attempts.
    draws : int
        Draws of the water the returned plan was checked over (the first check run, the fits
        as fitted, comes on top).
    family : int
        The plans the planning call may check (the first and ``repairs`` repairs): the
        returned plan's interval is taken at :attr:`level`, :data:`CHECK_LEVEL` split over them
        (Bonferroni), so it holds at :data:`CHECK_LEVEL` whichever plan the repairs return.
    margin_m : float
        The check's margin (:data:`CHECK_MARGIN_M`): a run whose body came within it of anything
        failed the check.
    guidance : str
        The name of the guidance law the plan was searched and checked with (set by
        :meth:`Planner.plan`; empty for an outcome made elsewhere).
    laws_tried : list of dict
        With the guidance chosen per plan (:func:`plan_with_laws`): the laws tried before this
        outcome's, each found no plan (``law``, ``status``, ``message``, ``planning_time_s``).
    """

    plan: Plan
    status: str
    message: str
    checks: list[Swim] = field(default_factory=list)
    repairs: int = 0
    planning_time_s: float = 0.0
    search_time_s: float = 0.0
    draws: int = 0
    family: int = 1
    margin_m: float = 0.0
    guidance: str = ""
    laws_tried: list[dict[str, Any]] = field(default_factory=list)

    def failed(self, run: Swim) -> bool:
        """A check run that failed: contact, the goal missed, or within :attr:`margin_m`."""
        return run_failed(run, self.margin_m)

    @property
    def drawn_checks(self) -> list[Swim]:
        """The check runs over the draws of the water (without the fits as fitted)."""
        return self.checks[len(self.checks) - self.draws:] if self.draws else []

    @property
    def collision_probability(self) -> tuple[float, float, float]:
        """Estimated probability that the plan fails in the check's water.

        A failure is contact, the goal missed, or the body within the check's margin
        (:attr:`margin_m`) of anything; the interval therefore also bounds the probability of
        contact alone.

        Returns
        -------
        (float, float, float)
            Failures over draws, and the two-sided Clopper-Pearson interval at ``level`` (95 %
            over every plan the planning call may check; NaNs when the plan was not checked
            over draws).
        """
        runs = self.drawn_checks
        if not runs:
            return (math.nan, math.nan, math.nan)
        bad = sum(self.failed(r) for r in runs)
        low, high = clopper_pearson(bad, len(runs), self.level)
        return (bad / len(runs), low, high)

    @property
    def arrival_s(self) -> tuple[float, float, float]:
        """Arrival time over the check runs that reached the goal: median, 5th and 95th percentile.

        NaNs without such runs.
        """
        times = [r.goal_time_s for r in self.checks if r.goal_time_s is not None]
        if not times:
            return (math.nan, math.nan, math.nan)
        return (float(np.median(times)), float(np.percentile(times, 5)),
                float(np.percentile(times, 95)))

    def confidence(self) -> str:
        """One line: the check's estimated collision probability and the arrival time's spread."""
        p, low, high = self.collision_probability
        if math.isnan(p):
            return "not checked over draws of the water"
        median, t5, t95 = self.arrival_s
        margin = (f", every run {self.margin_m * 1000:.0f} mm clear" if self.margin_m > 0
                  else "")
        return (f"collision probability {p:.1%} ({sum(self.failed(r) for r in self.drawn_checks)} "
                f"of {self.draws} draws of the water failed{margin}; 95 % interval {low:.1%}-{high:.1%}, "
                f"simultaneous over the {self.family} plan(s) the repairs may check); arrival "
                f"{median:.1f} s (90 % of the check runs {t5:.1f}-{t95:.1f} s)")

    @property
    def level(self) -> float:
        """Two-sided level of the returned plan's own interval (:data:`CHECK_LEVEL`, Bonferroni)."""
        return 1.0 - (1.0 - CHECK_LEVEL) / max(self.family, 1)

    @property
    def found(self) -> bool:
        """A plan that passed every check run."""
        return self.status == "found"


class Planner:
    """Plan in one world (module docstring); reusable for replanning in that world.

    Parameters
    ----------
    world : World
    robot : Robot
    coefficients : CoefficientModel
        Straight and turning fits with their standard deviations. A fitted model's robot
        (law and joints) replaces ``robot`` and its tank's current is added to the world's
        (:meth:`CoefficientModel.robot_for`, :meth:`CoefficientModel.in_tank`).
    gait : Gait
    options : LoopOptions, optional
        The loop's timing and camera (the tank's by default).
    settings : SearchSettings, optional
    draws : int
        Draws of the water the check swims (:data:`CHECK_DRAWS`).
    unknown_current_m_s : float
        Bound of the current the planner is not told of, checked in every draw at that speed in
        directions round the circle.
    seed : int
        Seed of the draws. Each plan a planning call checks (the first, then each repair) has
        its own draws (:meth:`waters`); every call (a replan) checks its first plan over the
        same draws, its first repair over the same second draws, and so on.
    robust_search : bool
        Also swim every leg of the search in the unknown current towards 4 directions
        (:class:`eelhost.planning.search.SearchSettings`, ``robust_current_m_s``): fewer plans
        fail the check, for about 4 times the search's time (docs/planning.md, "The search").
    repairs : int
        Re-searches after a failed check before refusing.
    check : bool
        Swim the plan over the ensemble before returning it (off only to measure the search).
    threads : int or None
        Threads of the batched twin.
    guidance : GuidanceLaw
        The robot's guidance law, for the search and the check (default the paper's pure
        pursuit; :data:`PLANNING_GUIDANCE` is the integral line-of-sight law). It replaces the
        one of ``options``. A feed-forward law (``pursuit_ff``) not yet given its water is
        given this world's known current and :attr:`swimming_speed_m_s`
        (``GuidanceLaw.with_water``); ``options.guidance`` is the law filled in, which the run
        loop and every replan's planner must use.
    soft_margin : bool
        Give the search a soft margin (``SearchSettings.preferred_clearance_m``), unless
        ``settings`` sets its own: the hard margin plus :data:`SOFT_MARGIN_BASE_M` plus
        :data:`SOFT_MARGIN_DRIFT_S` times the unknown current, at least
        :data:`SOFT_MARGIN_FLOOR_M`, at :data:`SOFT_MARGIN_COST`.
    swimmer : SwimmerModel, optional
        The model of the robot the planner swims, built once by the command
        (:meth:`eelhost.planning.uncertainty.CoefficientModel.swimmer_for`) and handed on to the
        twin, the search, the check and the executed swims, and to every replan's planner
        (docs/architecture.md, "The planning room"); built here when not given.
    check_margin_m : float
        Every check run must keep the body at least this far from everything
        (:data:`CHECK_MARGIN_M`; 0: merely clear).
    repair_draws : int, optional
        Draws a repaired plan is checked over (default :data:`REPAIR_DRAWS_FACTOR` times
        ``draws``).
    raise_on_repair : bool
        A repair also raises the search's margin where the failing check runs came too close
        (:meth:`failure_sites`, :meth:`Search.raise_margin`), besides banning the leg most of
        them failed on; False: the ban alone, as until session 14.
    cramped_start : bool
        When the first search from the world's start is ``exhausted`` within
        :data:`CRAMPED_EXPANSIONS` expansions, search again with wider turns on the first legs
        (:data:`CRAMPED_ACTIONS`). Off by default: on development seeds 28500-29499 it planned
        14 more worlds of 1000, and one of those 14 plans touched in the bench's fresh draws
        (docs/planning_history.md, "A wider turn from a cramped start").
    arrival_stop : bool
        Judge every check run that reaches the goal through the stop the tank makes on arriving
        (:data:`ARRIVAL_BRAKE_S` of brake, then the straight body's glide,
        :data:`eelhost.planning.harbour.FINAL_GLIDE_S`), in that run's own water, with the
        check's margin (docs/planning.md, "The arrival's stop in the check"); False: the run
        ends where it enters the goal disc, as until session 22.
    """

    def __init__(
        self,
        world: World,
        robot: Robot,
        coefficients: CoefficientModel,
        gait: Gait = PATH_GAIT,
        options: LoopOptions | None = None,
        settings: SearchSettings | None = None,
        draws: int = CHECK_DRAWS,
        unknown_current_m_s: float = DEFAULT_UNKNOWN_CURRENT_M_S,
        seed: int = 0,
        robust_search: bool = False,
        repairs: int = 4,
        check: bool = True,
        threads: int | None = 1,
        guidance: GuidanceLaw = PURSUIT,
        swimmer: SwimmerModel | None = None,
        soft_margin: bool = True,
        check_margin_m: float = CHECK_MARGIN_M,
        repair_draws: int | None = None,
        raise_on_repair: bool = True,
        cramped_start: bool = False,
        arrival_stop: bool = True,
    ) -> None:
        world = coefficients.in_tank(world)
        robot = coefficients.robot_for(robot)
        self.world = world
        self.robot = robot
        self.coefficients = coefficients
        self.gait = gait
        self.options = dataclasses.replace(options or LoopOptions(), guidance=guidance)
        self.unknown_current_m_s = float(unknown_current_m_s)
        self.seed = int(seed)
        self.draws = int(draws)
        self.repair_draws = int(REPAIR_DRAWS_FACTOR * self.draws if repair_draws is None
                                else repair_draws)
        if self.repair_draws < 1:
            raise ValueError(f"repair_draws: expected at least 1, got {repair_draws!r}")
        self.water = _water_draws(coefficients, seed, draws, self.unknown_current_m_s)
        self._waters: dict[int, list[WaterDraw]] = {0: self.water}
        self.repairs = repairs
        self.raise_on_repair = bool(raise_on_repair)
        self.check = check
        if not check_margin_m >= 0.0:
            raise ValueError(f"check_margin_m: expected at least 0 m, got {check_margin_m!r}")
        self.check_margin_m = float(check_margin_m)
        self.arrival_stop: StopWindow | None = ARRIVAL_STOP if arrival_stop else None
        """How the check swims each arriving run's stop (None: not swum)."""
        self._stops: BoundedCache[FloatArray] = BoundedCache(ARRIVAL_STOPS_KEPT)
        self.check_cost: SwimCost = CHECK_COST
        """The check's measured cost the deadline keeps free (:data:`check.CHECK_COST`, the
        process's, by default)."""
        self.plan_lengths: PlanLengths = PLAN_LENGTHS
        """The found plans' lengths over their free-space paths (:data:`PLAN_LENGTHS`, the
        process's, by default): :meth:`expected_steps`."""
        if swimmer is not None and swimmer.n_links != robot.n_links:
            raise ValueError(f"the robot's model has {swimmer.n_links} links, the robot "
                             f"{robot.n_links}")
        self.model = swimmer if swimmer is not None else coefficients.swimmer_for(robot)
        self.body_half_width_m = float(self.model.half_axis_horizontal_m.max())
        # the still-water speed with the pursuit a feed-forward law is in still water (a law
        # given its current would crab in the speed's still-water run)
        still = (dataclasses.replace(self.options, guidance=GuidanceLaw(
            heading_gain=guidance.heading_gain)) if guidance.feed_forward else self.options)
        speeds = [swimming_speed_m_s(robot, c, gait, still, self.model)
                  for c in coefficients.sets]
        self.swimming_speed_m_s = min(speeds)
        fastest = max(speeds)
        if guidance.needs_water:
            # the feed-forward's water: the current this planner knows (the world's and a fitted
            # tank's, never the unknown part) and the slowest fit's speed (docs/model.md section 4)
            self.options = dataclasses.replace(self.options, guidance=guidance.with_water(
                world.current_m_s, self.swimming_speed_m_s))
        base = settings or SearchSettings()
        # the body's half width and the world's clearance, never less than the settings ask
        margin = max(base.margin_m, self.body_half_width_m + world.clearance_m)
        # a leg may take LEG_TIME_FACTOR times as long as swimming it straight against the whole
        # current would: a run still going then is circling its waypoint and is cut short
        slowest = max(self.swimming_speed_m_s - world.current.speed_m_s, 1e-3)
        leg_time = min(base.leg_time_s, LEG_TIME_FACTOR / slowest)
        # robust_search: every leg is also swum in the unknown current (search module docstring),
        # its body kept off everything by its half width and some
        self.settings = dataclasses.replace(base, margin_m=margin, leg_time_s=leg_time)
        if soft_margin and base.clearance_cost <= 0:
            # the soft margin (docs/planning.md, "The search"): room for the robot to stray from
            # the searched run in the water the check draws, where the world leaves it
            self.settings = dataclasses.replace(
                self.settings, clearance_cost=SOFT_MARGIN_COST,
                preferred_clearance_m=margin + max(
                    SOFT_MARGIN_FLOOR_M,
                    SOFT_MARGIN_BASE_M + SOFT_MARGIN_DRIFT_S * self.unknown_current_m_s))
        if robust_search:
            self.settings = dataclasses.replace(
                self.settings, robust_current_m_s=self.unknown_current_m_s,
                robust_margin_m=self.body_half_width_m + ROBUST_MARGIN_M)
        self.twin = Twin(robot, coefficients.sets, gait, self.options, world.current_m_s,
                         threads=threads, swimmer=self.model)
        self.clearance = clearance_field(world)  # shared by the planners of this geometry
        self.goal_distance = GoalDistance(world, self.clearance, self.body_half_width_m)
        # the search's heuristic: the soft margin's cost along the cheapest free-space path
        route = (GoalDistance(world, self.clearance, self.body_half_width_m,
                              preferred_clearance_m=self.settings.preferred_clearance_m,
                              clearance_cost=self.settings.clearance_cost)
                 if self.settings.clearance_cost > 0 else self.goal_distance)
        # 1.3: the body's sway and a turn's cut corner let the centre of mass gain on the
        # straight-line speed; a heuristic speed too low only makes the search greedier
        self.search = Search(world, self.twin, self.settings, self.clearance, route,
                             1.3 * fastest + world.current.speed_m_s)
        if self.arrival_stop is not None:
            self.search.goal_stop = self.arrival_stop_states
            # the search's stop keeps the check's margin (its measure is the centre line's, so
            # the half width on top), in the known water: the check then judges it in the draws
            # (docs/planning.md, "The arrival's stop in the check")
            self.search.goal_stop_margin_m = max(self.settings.margin_m,
                                                 self.body_half_width_m + self.check_margin_m)
        self.cramped_start = bool(cramped_start)
        self._route = route
        self._ground_speed_m_s = 1.3 * fastest + world.current.speed_m_s
        self._cramped_search: Search | None = None

    def arrival_stop_states(self, state: FloatArray, step: int) -> FloatArray:
        """The arrival's stop from ``state`` at ``step`` in the known water, as the check swims it.

        The twin's straight fit in the world's current (the search's water), the stop of
        :attr:`arrival_stop` (:func:`eelhost.planning.harbour.stop_states`), sampled every
        :data:`eelhost.planning.check.ARRIVAL_STOP_STRIDE` steps; the search's goal test
        (:attr:`Search.goal_stop`). The same state and step give the same stop: kept per planner.

        Parameters
        ----------
        state : ndarray, shape (2 N + 4,)
        step : int

        Returns
        -------
        ndarray, shape (S, 2 N + 4)
        """
        body = np.asarray(state, dtype=float)
        return self._stops.get(
            (body.tobytes(), int(step)),
            lambda: stop_states(self.twin, self.twin.gait, body[None], step * self.twin.dt_s,
                                ARRIVAL_STOP, ARRIVAL_STOP_STRIDE)[0])

    def cramped_search(self) -> Search:
        """The search whose first legs take the cramped start's wider turns (:data:`CRAMPED_ACTIONS`).

        Its own search object (its memo is keyed by action index, which the two action sets
        number differently), sharing the twin, the maps and the clock; built when first needed.

        Returns
        -------
        Search
        """
        if self._cramped_search is None:
            settings = dataclasses.replace(self.settings, start_actions=CRAMPED_ACTIONS)
            self._cramped_search = Search(self.world, self.twin, settings, self.clearance,
                                          self._route, self._ground_speed_m_s)
        self._cramped_search.clock = self.search.clock
        self._cramped_search.goal_stop = self.search.goal_stop
        self._cramped_search.goal_stop_margin_m = self.search.goal_stop_margin_m
        return self._cramped_search

    @property
    def clock(self) -> Callable[[], float]:
        """The clock a deadline is read on (``time.monotonic``; a test's fake one)."""
        return self.search.clock

    @clock.setter
    def clock(self, clock: Callable[[], float]) -> None:
        self.search.clock = clock

    def check_time_s(self, plan_steps: float, draws: int | None = None) -> float:
        """The predicted wall time of a whole check of a plan ``plan_steps`` physics steps long.

        The fits as fitted and ``draws`` draws, each swum the plan's length, at the check's
        cost per run-step measured in this process (:attr:`check_cost`); before any check has
        been measured, :data:`CHECK_OVER_SEARCH` times the search's own (0 before either).

        Parameters
        ----------
        plan_steps : float
        draws : int, optional
            The draws the check swims (default the first plan's, :attr:`draws`; a repaired
            plan's are :attr:`repair_draws`).

        Returns
        -------
        float
            Seconds.
        """
        run_steps = (1 + (self.draws if draws is None else draws)) * max(plan_steps, 0.0)
        need = self.check_cost.predict_s(run_steps)
        if need is None:
            search = self.search.swim_cost.predict_s(run_steps)
            need = 0.0 if search is None else CHECK_OVER_SEARCH * search
        return need

    def draws_within(self, plan_steps: float, draws: int, deadline_s: SupportsFloat | None,
                     fewest: int = DEADLINE_DRAWS_MIN) -> int:
        """How many of ``draws`` draws a check may swim so the search keeps room before a deadline.

        All of them unless their check's predicted time (:meth:`check_time_s`) exceeds
        :data:`CHECK_SHARE_MAX` of the time left now; then as many as fit in that share, never
        fewer than ``fewest`` (nor more than ``draws``). Without a deadline, or before any cost
        is measured, all of them. The plan's stated interval is always over the draws swum.

        Parameters
        ----------
        plan_steps : float
            The plan's expected length, physics steps (:meth:`expected_steps`).
        draws : int
        deadline_s : float or None
            On :attr:`clock`.
        fewest : int

        Returns
        -------
        int
        """
        if deadline_s is None or draws <= fewest:
            return draws
        room = CHECK_SHARE_MAX * (float(deadline_s) - self.clock())
        if self.check_time_s(plan_steps, draws) <= room:
            return draws
        per_run = self.check_time_s(plan_steps, 0)  # the fits' one run at the measured cost
        if per_run <= 0.0:
            return draws
        return int(min(draws, max(fewest, math.floor(room / per_run) - 1)))

    def _free_path_steps(self, state: FloatArray | None) -> float:
        """The free-space path of the body's centre to the goal disc at the swimming speed, steps.

        0 when no path is open (:class:`eelhost.planning.field.GoalDistance`).
        """
        n = self.model.n_links
        if state is None:
            xy = np.asarray(self.world.start.position_m, dtype=float)
        else:
            xy = np.asarray(state, dtype=float)[n : n + 2]
        path = self.goal_distance(xy)
        if not math.isfinite(path):
            return 0.0
        return path / self.swimming_speed_m_s / self.twin.dt_s

    def expected_steps(self, state: FloatArray | None = None) -> float:
        """A plan's expected length from ``state`` (default the start), physics steps.

        The free-space path of the body's centre to the goal disc
        (:class:`eelhost.planning.field.GoalDistance`) at the swimming speed, times the median
        ratio of the plans found in this process to that path (:attr:`plan_lengths`); before
        any, the path at the slowest ground speed (the swimming speed against the world's whole
        current). What the deadline keeps the check's time for before a plan is found.

        Parameters
        ----------
        state : ndarray, optional

        Returns
        -------
        float
        """
        slowest = max(self.swimming_speed_m_s - self.world.current.speed_m_s, 1e-3)
        return self._free_path_steps(state) * self.plan_lengths.ratio(
            self.swimming_speed_m_s / slowest)

    # -- refusals --------------------------------------------------------------------------------

    def refusal(self, state: FloatArray | None = None) -> PlanRefused | None:
        """Why this world cannot be planned from ``state`` (default: the start), or None.

        Parameters
        ----------
        state : ndarray, optional

        Returns
        -------
        PlanRefused or None
        """
        world = self.world
        n = self.model.n_links
        if state is None:
            state = straight_state(self.model, math.radians(world.start.heading_deg),
                                   world.start.position_m)
        pts = body_points(self.model, np.asarray(state)[None], 4)[0]
        clear = float(np.min(self.clearance(pts))) - self.clearance.error_m
        if clear < self.body_half_width_m:
            xy = state[n : n + 2]
            return PlanRefused(
                "blocked_start",
                f"start blocked: at ({xy[0]:.2f}, {xy[1]:.2f}) m the body comes within "
                f"{max(clear, 0.0) * 1000:.0f} mm of an obstacle or wall (its half width is "
                f"{self.body_half_width_m * 1000:.0f} mm)",
            )
        current = world.current.speed_m_s
        if current >= self.swimming_speed_m_s:
            return PlanRefused(
                "current_too_strong",
                f"current too strong: {current:.3f} m/s is at least the robot's swimming speed "
                f"({self.swimming_speed_m_s:.3f} m/s with this gait in the twin), so no leg can "
                "be swum against it",
            )
        goal = np.asarray(world.goal.position_m, dtype=float)
        goal_clear = float(signed_clearance(world, goal[None])[0])
        if goal_clear < self.body_half_width_m:
            where = "inside an obstacle or wall" if goal_clear < 0 else (
                f"{goal_clear * 1000:.0f} mm from an obstacle or wall")
            return PlanRefused(
                "goal_blocked",
                f"goal blocked: its centre ({goal[0]:.2f}, {goal[1]:.2f}) m is {where}, closer "
                f"than the body's half width ({self.body_half_width_m * 1000:.0f} mm)",
            )
        if not math.isfinite(self.goal_distance(state[n : n + 2])):
            return PlanRefused(
                "unreachable",
                "goal unreachable: no corridor wide enough for the body "
                f"({2 * self.body_half_width_m * 1000:.0f} mm) joins the start and the goal disc",
            )
        return None

    # -- planning --------------------------------------------------------------------------------

    def plan(self, state: FloatArray | None = None, step: int = 0,
             guide: Guide | None = None, deadline_s: SupportsFloat | None = None) -> Outcome:
        """Plan from the start (or from ``state`` at ``step``), check the plan, repair it.

        Parameters
        ----------
        state : ndarray, shape (2 N + 4,), optional
            The robot's state (replanning); default the straight robot at rest at the start.
        step : int
            Step of the task at ``state``.
        guide : (x, y, I_x, I_y), optional
            The guidance's state at ``state``: where the first leg starts and the controller's
            ILOS integral (default: from the state's centre of mass, the integral zero). A
            replan at the tank passes the controller's integral.
        deadline_s : float, optional
            A time on :attr:`clock` (``time.monotonic()``) by which the whole call returns, its
            checks included, up to a small overshoot (docs/planning.md, "The planning call's
            deadline"): every search keeps the predicted time of a whole check free before it
            (:meth:`check_time_s` of :meth:`expected_steps`) and starts no batch that would
            still be in flight (:meth:`Search.plan`), ending ``out_of_time``; a check starts no
            leg it predicts would end after the deadline, and the call then ends ``out_of_time``
            with the plan not checked (``found`` False). Default: none (nothing changes).

        Returns
        -------
        Outcome
            Its ``guidance`` the name of the law it was searched and checked with.
        """
        outcome = self._plan(state, step, guide, deadline_s)
        outcome.guidance = self.options.guidance.name
        return outcome

    def _plan(self, state: FloatArray | None, step: int, guide: Guide | None,
              deadline_s: SupportsFloat | None) -> Outcome:
        """:meth:`plan` (its parameters), without the outcome's law."""
        refused = self.refusal(state)
        if refused is not None:
            return Outcome(Plan(False, refused.status, str(refused)), refused.status, str(refused))
        banned: set = set()
        total = searching = 0.0
        checks: list[Swim] = []
        bad: list[Swim] = []
        plan = Plan(False, "gave_up", "")
        # with a deadline, every search keeps the predicted time of a whole check of a plan of
        # the expected length free before it (docs/planning.md, "The planning call's deadline")
        expected = self.expected_steps(state)
        free_path = self._free_path_steps(state)
        self.search.clear_raised()  # a margin raised by an earlier call's repairs is not this one's
        search = self.search
        for attempt in range(self.repairs + 1):
            # a repaired plan's check swims its own, larger count of draws (REPAIR_DRAWS_FACTOR);
            # with a deadline, as many as its predicted time leaves the search room for
            count = (self.draws_within(expected, len(self.waters(attempt)), deadline_s,
                                       DEADLINE_DRAWS_MIN if attempt == 0 else self.draws)
                     if self.check else 0)
            reserve = ((lambda c=count: self.check_time_s(expected, c)) if self.check else None)
            plan = search.plan(banned, start_state=state, start_step=step, guide=guide,
                               deadline_s=deadline_s, reserve_s=reserve)
            total += plan.planning_time_s
            searching += plan.planning_time_s
            if (attempt == 0 and state is None and self.cramped_start
                    and plan.status == "exhausted" and plan.expansions <= CRAMPED_EXPANSIONS):
                # the first plan from a cramped start: search again, its first legs with turns
                # of up to 120 degrees (docs/planning_history.md, "A wider turn from a cramped start");
                # the repairs go on in that search, the margin and the check are the same
                search = self.cramped_search()
                search.clear_raised()
                first = plan
                plan = search.plan(banned, start_state=state, start_step=step, guide=guide,
                                   deadline_s=deadline_s, reserve_s=reserve)
                total += plan.planning_time_s
                searching += plan.planning_time_s
                log.info("cramped start, wider turns: %s", plan.message)
                if not plan.found:
                    plan = first
            if plan.found and free_path > 0:
                self.plan_lengths.record((plan.legs[-1].end_step - step) / free_path)
            if not plan.found and attempt > 0:
                msg = (f"check failed: {attempt} plans failed their check in the twin (last: "
                       f"{bad[0].label}: {self.verdict(bad[0])}) and the search found no other "
                       f"({plan.message})")
                return Outcome(Plan(False, "check_failed", msg, expansions=plan.expansions,
                                    simulations=plan.simulations,
                                    planning_time_s=plan.planning_time_s, tree=plan.tree),
                               "check_failed", msg, checks, attempt, total, searching)
            if not plan.found:
                return Outcome(plan, plan.status, plan.message, checks, attempt, total, searching)
            if not self.check:
                return Outcome(plan, "found", plan.message, [], attempt, total, searching)
            # each plan its own draws: a repaired plan is not chosen to pass the very draws its
            # predecessors failed (docs/planning.md, "The planner", step 4)
            waters = self.waters(attempt)
            if count < len(waters):  # cut to fit the deadline (draws_within)
                waters = waters[:count]
            t_check = time.perf_counter()
            try:
                checks, elapsed = self.check_plan(plan, state, step, waters, deadline_s)
            except CheckOutOfTime as stop:
                total += time.perf_counter() - t_check
                # never returned as checked: the plan's status says it was not
                msg = (f"out of time: {plan.message}, but {stop} (predicted "
                       f"{self.check_time_s(plan.legs[-1].end_step - step, len(waters)):.2f} s "
                       "for the whole check); the plan is not checked")
                return Outcome(Plan(False, "out_of_time", msg, plan.legs, plan.cost_s,
                                    plan.expansions, plan.simulations, plan.planning_time_s,
                                    plan.tree, plan.start_guide),
                               "out_of_time", msg, [], attempt, total, searching)
            total += elapsed
            bad = [c for c in checks if run_failed(c, self.check_margin_m)]
            if not bad:
                outcome = Outcome(plan, "found", "", checks, attempt, total, searching,
                                  len(waters), self.repairs + 1, self.check_margin_m)
                repaired = (f" (searched again after {attempt} failed check(s), swimming only "
                            "manoeuvres not swum before)" if attempt else "")
                outcome.message = (
                    f"{plan.message}{repaired}; checked in the twin with the fits and over "
                    f"{len(waters)} "
                    f"draws of the water (min clearance "
                    f"{min(c.min_clearance_m for c in checks) * 1000:.0f} mm): "
                    f"{outcome.confidence()}")
                return outcome
            # the leg most failing runs failed on
            blamed = Counter(c.failed_leg if c.failed_leg is not None else -1 for c in bad)
            index = blamed.most_common(1)[0][0]
            leg = plan.legs[index]
            banned.add((leg.parent_key, leg.action))
            if self.raise_on_repair:
                for xy, extra in self.failure_sites(checks, bad):
                    search.raise_margin(xy, extra)
            log.info("plan failed its check in %d runs (e.g. %s: %s); banning leg to (%.2f, %.2f)",
                     len(bad), bad[0].label, self.verdict(bad[0]), *leg.waypoint_m)
        msg = (f"check failed: after {self.repairs} repairs the plan still fails in the twin with "
               f"{len(bad)} of the {len(checks)} check runs swum (e.g. {bad[0].label}: "
               f"{self.verdict(bad[0])})")
        return Outcome(Plan(False, "check_failed", msg, plan.legs, plan.cost_s, plan.expansions,
                            plan.simulations, plan.planning_time_s, plan.tree),
                       "check_failed", msg, checks, self.repairs, total, searching)

    def failure_sites(self, runs: list[Swim], bad: list[Swim]) -> list[tuple[tuple[float, float], float]]:
        """Where each failing check run came too close, and how much more room the search must keep.

        For a run that touched or came within the check's margin (not one that only missed the
        goal or raised a twin flag): the body point at its smallest gap g, and the extra the
        search's margin is raised by there (:meth:`Search.raise_margin`): the room the fits'
        own run (the first of ``runs``) kept near that point, plus what the failing run lacked
        (the check's margin less g), plus :data:`RAISE_SAFETY_M`, less the search's hard margin;
        so the next plan must keep, near that point, what this one kept and what the failing
        draw lost there (docs/planning_history.md, "A repair with the margin raised where the check
        failed"). At most :data:`RAISE_MAX_M`.

        Parameters
        ----------
        runs : list of Swim
            The check's runs, the fits as fitted first.
        bad : list of Swim
            The failing ones among them.

        Returns
        -------
        list of ((x, y), extra m)
        """
        # the fits' own run's body points and their room, once for every failing run
        nominal_pts = nominal_clear = None
        if runs and len(runs[0].states):
            nominal_pts = body_points(self.model, np.asarray(runs[0].states),
                                      self.settings.per_link)
            nominal_clear = self.clearance(nominal_pts)
        sites = []
        for run in bad:
            if run.collision_free and run.min_clearance_m > self.check_margin_m:
                continue  # the goal missed or a twin flag: nowhere to keep away from
            states = np.asarray(run.states)
            if not len(states):
                continue
            pts = body_points(self.model, states, self.settings.per_link)
            clear = self.clearance(pts)
            k, i = np.unravel_index(int(np.nanargmin(clear)), clear.shape)
            xy = (float(pts[k, i, 0]), float(pts[k, i, 1]))
            kept = math.nan
            if nominal_pts is not None and nominal_clear is not None:
                close = (np.hypot(nominal_pts[..., 0] - xy[0], nominal_pts[..., 1] - xy[1])
                         < RAISE_NEAR_M)
                if np.any(close):
                    kept = float(np.min(nominal_clear[close]))
            if not math.isfinite(kept):
                kept = self.settings.margin_m
            lacked = self.check_margin_m - run.min_clearance_m
            extra = kept + lacked + RAISE_SAFETY_M - self.settings.margin_m
            sites.append((xy, float(min(max(extra, RAISE_SAFETY_M), RAISE_MAX_M))))
        return sites

    def verdict(self, run: Swim) -> str:
        """One line on a check run: its own message, or how close it came within the margin."""
        if run.ok and run.min_clearance_m <= self.check_margin_m:
            return (f"reached the goal, but the body came within "
                    f"{max(run.min_clearance_m, 0.0) * 1000:.0f} mm of an obstacle or wall, "
                    f"inside the check's {self.check_margin_m * 1000:.0f} mm margin")
        return run.message

    def check_waters(self, waters: list[WaterDraw] | None = None) -> list[WaterDraw]:
        """The waters a check swims: the fits as fitted, then ``waters``.

        ``waters`` defaults to the first plan's draws.

        Parameters
        ----------
        waters : list of WaterDraw, optional

        Returns
        -------
        list of WaterDraw
        """
        nominal = WaterDraw("the fits as fitted", self.coefficients.fits["straight"],
                            self.coefficients.fits["turning"], (0.0, 0.0))
        return [nominal, *(self.water if waters is None else waters)]

    def waters(self, attempt: int) -> list[WaterDraw]:
        """The draws of the water the ``attempt``-th plan of a planning call is checked over.

        Attempt 0 (the first plan) has ``draws`` draws seeded with ``seed``; each repair its own
        ``repair_draws`` (:data:`REPAIR_DRAWS_FACTOR` times ``draws``) seeded with
        ``(seed, attempt)``: independent of one another and of every other seed's.

        Parameters
        ----------
        attempt : int
            0 for the first plan, k for the k-th repair.

        Returns
        -------
        list of WaterDraw
        """
        if attempt not in self._waters:
            count = self.draws if attempt == 0 else self.repair_draws
            self._waters[attempt] = _water_draws(self.coefficients, (self.seed, attempt), count,
                                                 self.unknown_current_m_s)
        return self._waters[attempt]

    def swim_waters(self, plan: Plan, waters: list[WaterDraw], state: FloatArray | None = None,
                    step: int = 0, deadline_s: SupportsFloat | None = None,
                    through_stop: bool | None = None) -> list[Swim]:
        """Swim a plan leg by leg in each water, as the search swam it, and judge each run.

        Parameters
        ----------
        plan : Plan
        waters : list of WaterDraw
        state : ndarray, optional
            Start state (default: the world's start).
        step : int
        deadline_s : float, optional
            A time on :attr:`clock` (:func:`eelhost.planning.check.swim_legs`; it raises
            :class:`eelhost.planning.check.CheckOutOfTime` when it stops there).
        through_stop : bool, optional
            Swim each arriving run on through the arrival's stop (True), or end it in the goal
            disc (False); default the planner's :attr:`arrival_stop` (the bench's fresh draws
            swim it whatever the check did, so both arms are judged alike).

        Returns
        -------
        list of Swim
        """
        window = self.arrival_stop
        if through_stop is not None:
            window = ARRIVAL_STOP if through_stop else None
        legs = [self.search.leg_coefficients(leg.goal, leg.bearing_deg) for leg in plan.legs]
        return swim_legs(self.world, plan, self.twin, self.model, waters, legs, self.clearance,
                         state, step, deadline_s=deadline_s, clock=self.clock,
                         cost=self.check_cost, margin_m=self.check_margin_m,
                         arrival_stop=window)

    def check_plan(self, plan: Plan, state: FloatArray | None = None, step: int = 0,
                   waters: list[WaterDraw] | None = None, deadline_s: SupportsFloat | None = None
                   ) -> tuple[list[Swim], float]:
        """Swim a plan with the fits and over the draws of the water (module docstring).

        Leg by leg, as the search swam it (:func:`eelhost.planning.check.swim_legs`). The fits
        as fitted and the first :data:`SCREEN_DRAWS` draws are swum first; when one of them
        fails, the rest are not swum (the plan fails its check either way).

        Parameters
        ----------
        plan : Plan
        state : ndarray, optional
            Start state (default: the world's start).
        step : int
        waters : list of WaterDraw, optional
            The draws (default the first plan's, :meth:`waters` (0)).
        deadline_s : float, optional
            A time on :attr:`clock`: no leg's batch is started that would end after it
            (:func:`eelhost.planning.check.swim_legs`). Default: none.

        Returns
        -------
        list of Swim, float
            The runs (the fits as fitted first, then the draws in order) and the time they took,
            s.

        Raises
        ------
        CheckOutOfTime
            The deadline stopped the check before its verdict (a failing run found before it
            ends the check with its runs, as without a deadline).
        """
        t0 = time.perf_counter()
        todo = self.check_waters(waters)
        screen = 1 + SCREEN_DRAWS
        runs: list[Swim] = []
        for lo in [0, *range(screen, len(todo), BATCH_RUNS)]:
            part = todo[lo : screen if lo == 0 else lo + BATCH_RUNS]
            if not part:
                break
            runs += self.swim_waters(plan, part, state, step, deadline_s)
            if any(run_failed(r, self.check_margin_m) for r in runs):
                break
        return runs, time.perf_counter() - t0


def laws_of(choice: GuidanceChoice) -> tuple[GuidanceLaw, ...]:
    """The laws a planner's ``guidance`` option tries, in order.

    Parameters
    ----------
    choice : GuidanceLaw or tuple of GuidanceLaw

    Returns
    -------
    tuple of GuidanceLaw
    """
    return choice if isinstance(choice, tuple) else (choice,)


def plan_with_laws(make: Callable[[GuidanceLaw], Planner], laws: tuple[GuidanceLaw, ...],
                   call: Callable[[Planner], Outcome] | None = None,
                   ) -> tuple[Planner, Outcome]:
    """Plan with each law in turn until one finds a plan that passes its check.

    The guidance chosen per plan (docs/planning_history.md, "A guidance law chosen per plan"): a law is
    searched and checked only where the ones before it found no plan, so a world the first law
    plans costs what it did; a refusal no law changes (:data:`LAW_FREE_REFUSALS`) ends the
    tries. The plan carries the law it was searched and checked with (``Outcome.guidance``,
    the returned planner's ``options.guidance``), which the run loop and every replan use.

    Parameters
    ----------
    make : callable
        The planner for a law (the same world, robot, model and options otherwise).
    laws : tuple of GuidanceLaw
        At least one.
    call : callable, optional
        The planning call with a made planner (the planning benchmark's, with its deadline);
        default ``planner.plan()``.

    Returns
    -------
    Planner, Outcome
        The planner of the law whose plan was found and its outcome, with the laws tried
        before it in ``laws_tried`` and their time added to ``planning_time_s`` and
        ``search_time_s``; without a plan, the last law's, its message naming every law's
        failure.
    """
    if not laws:
        raise ValueError("laws: expected at least one guidance law")
    tried: list[dict[str, Any]] = []
    earlier_s = earlier_search_s = 0.0
    for k, law in enumerate(laws):
        planner = make(law)
        outcome = planner.plan() if call is None else call(planner)
        outcome.laws_tried = list(tried)
        outcome.planning_time_s += earlier_s
        outcome.search_time_s += earlier_search_s
        last = k == len(laws) - 1 or outcome.status in LAW_FREE_REFUSALS
        if outcome.found or last:
            if tried:
                before = "; ".join(f"{t['law']}: {t['status']}" for t in tried)
                outcome.message += (f" (guidance {law.name}, after {before})" if outcome.found
                                    else f" (with {law.name}; before it {before})")
            return planner, outcome
        log.info("no plan with guidance %s (%s): trying %s", law.name, outcome.message,
                 laws[k + 1].name)
        tried.append({"law": law.name, "status": outcome.status, "message": outcome.message,
                      "planning_time_s": round(outcome.planning_time_s, 3)})
        earlier_s = outcome.planning_time_s
        earlier_search_s = outcome.search_time_s
    raise AssertionError("unreachable: the last law returns")
