"""The planner: refuse what cannot be planned, search, swim the plan in the twin, repair or refuse.

docs/planning.md ("The planner") is the long form. :meth:`Planner.plan`:

1. **Refusals**, each with its reason (:class:`PlanRefused`; the CLI exits 2): the start pose
   puts the body into an obstacle or a wall (``blocked_start``); the current is at least the
   robot's own swimming speed, so no leg can be swum against it (``current_too_strong``); no
   corridor wide enough for the body joins start and goal (``unreachable``). A goal outside the
   tank is refused when the world is read (:class:`eelhost.planning.world.WorldError`).
2. **Search** (:class:`eelhost.planning.search.Search`): every leg swum in the twin from the state
   the previous one left, with the straight coefficients for straight legs and the turning ones
   for turns.
3. **Check**: the plan's waypoints are swum in the twin as the tank would give them to the robot
   (one task from the start), once per coefficient set of the uncertainty ensemble
   (:meth:`eelhost.planning.uncertainty.CoefficientModel.ensemble`: both fits, and each with one
   coefficient at +-2 standard deviations). Every run must enter the goal disc
   (:func:`eelhost.planning.search.in_goal`) without any contact.
4. **Repair**: a leg that failed a check run (the leg being swum at the first contact, or the last
   leg when the goal was missed) is banned and the search runs again (it keeps what it swam);
   after ``repairs`` attempts the plan is refused with the reason of the last failure.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from eelhost.errors import UserError
from eelhost.planning.body import body_points
from eelhost.planning.execute import Swim, swim
from eelhost.planning.field import ClearanceField, GoalDistance
from eelhost.planning.geometry import FloatArray
from eelhost.planning.search import Plan, Search, SearchSettings
from eelhost.planning.twin import Twin
from eelhost.planning.uncertainty import CoefficientModel
from eelhost.planning.world import World
from eelsim.closed_loop import LoopOptions
from eelsim.control import Gait
from eelsim.dynamics import straight_state
from eelsim.fluid import FluidCoefficients
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import PATH_GAIT

log = logging.getLogger(__name__)

SPEED_RUN_S = 20.0
"""Length of the twin run that measures the swimming speed, s."""

LEG_TIME_FACTOR = 1.6
"""A leg's time limit per metre, as a multiple of the time the robot needs against the current."""


class PlanRefused(UserError, ValueError):
    """The planner refuses a world (the message says why; ``status`` names the case)."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


_SPEEDS: dict[tuple, float] = {}


def _swimming_speed(robot: Robot, coefficients: FluidCoefficients, gait: Gait,
                    options: LoopOptions) -> float:
    twin = Twin(robot, [coefficients], gait, options, (0.0, 0.0))
    runs = twin.run([[(10.0, 0.0)]], SPEED_RUN_S, stride=10)
    n = robot.n_links
    com = runs.states[0, :, n : n + 2]
    com = com[np.isfinite(com[:, 0])]
    half = len(com) // 2  # the second half: past the start from rest
    t = (len(com) - 1 - half) * runs.stride * twin.dt_s
    return float(np.hypot(*(com[-1] - com[half])) / t)


def swimming_speed_m_s(robot: Robot, coefficients: FluidCoefficients, gait: Gait = PATH_GAIT,
                       options: LoopOptions | None = None) -> float:
    """The robot's steady straight swimming speed in still water, from a twin run.

    Parameters
    ----------
    robot : Robot
    coefficients : FluidCoefficients
    gait : Gait
    options : LoopOptions, optional

    Returns
    -------
    float
        Mean speed of the centre of mass over the second half of a 20 s straight run, m/s.
    """
    opts = options or LoopOptions()
    key = (robot.model_dump_json(), type(coefficients).__name__,
           coefficients.as_array().tobytes(), repr(gait), repr(opts))
    if key not in _SPEEDS:  # one twin run per robot, coefficients, gait and loop
        _SPEEDS[key] = _swimming_speed(robot, coefficients, gait, opts)
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
        (refusals), ``exhausted``, ``gave_up`` (the search's), ``check_failed``.
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
    """

    plan: Plan
    status: str
    message: str
    checks: list[Swim] = field(default_factory=list)
    repairs: int = 0
    planning_time_s: float = 0.0
    search_time_s: float = 0.0

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
    sigmas : float
        The check ensemble's coefficients at +-``sigmas`` standard deviations.
    repairs : int
        Re-searches after a failed check before refusing.
    check : bool
        Swim the plan over the ensemble before returning it (off only to measure the search).
    threads : int or None
        Threads of the batched twin.
    """

    def __init__(
        self,
        world: World,
        robot: Robot,
        coefficients: CoefficientModel,
        gait: Gait = PATH_GAIT,
        options: LoopOptions | None = None,
        settings: SearchSettings | None = None,
        sigmas: float = 2.0,
        repairs: int = 4,
        check: bool = True,
        threads: int | None = 1,
    ) -> None:
        world = coefficients.in_tank(world)
        robot = coefficients.robot_for(robot)
        self.world = world
        self.robot = robot
        self.coefficients = coefficients
        self.gait = gait
        self.options = options or LoopOptions()
        self.sigmas = sigmas
        self.repairs = repairs
        self.check = check
        straight = coefficients.fits["straight"]
        self.model = SwimmerModel.from_robot(robot, straight)
        self.body_half_width_m = float(self.model.half_axis_horizontal_m.max())
        self.swimming_speed_m_s = min(
            swimming_speed_m_s(robot, c, gait, self.options) for c in coefficients.sets
        )
        fastest = max(swimming_speed_m_s(robot, c, gait, self.options) for c in coefficients.sets)
        base = settings or SearchSettings()
        # the body's half width and the world's clearance, never less than the settings ask
        margin = max(base.margin_m, self.body_half_width_m + world.clearance_m)
        # a leg may take LEG_TIME_FACTOR times as long as swimming it straight against the whole
        # current would: a run still going then is circling its waypoint and is cut short
        slowest = max(self.swimming_speed_m_s - world.current.speed_m_s, 1e-3)
        leg_time = min(base.leg_time_s, LEG_TIME_FACTOR / slowest)
        self.settings = SearchSettings(**{**base.__dict__, "margin_m": margin,
                                          "leg_time_s": leg_time})
        self.twin = Twin(robot, coefficients.sets, gait, self.options, world.current_m_s,
                         threads=threads)
        self.clearance = ClearanceField(world)
        self.goal_distance = GoalDistance(world, self.clearance, self.body_half_width_m)
        # 1.3: the body's sway and a turn's cut corner let the centre of mass gain on the
        # straight-line speed; a heuristic speed too low only makes the search greedier
        self.search = Search(world, self.twin, self.settings, self.clearance, self.goal_distance,
                             1.3 * fastest + world.current.speed_m_s)

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
        if not math.isfinite(self.goal_distance(state[n : n + 2])):
            return PlanRefused(
                "unreachable",
                "goal unreachable: no corridor wide enough for the body "
                f"({2 * self.body_half_width_m * 1000:.0f} mm) joins the start and the goal disc",
            )
        return None

    # -- planning --------------------------------------------------------------------------------

    def plan(self, state: FloatArray | None = None, step: int = 0) -> Outcome:
        """Plan from the start (or from ``state`` at ``step``), check the plan, repair it.

        Parameters
        ----------
        state : ndarray, shape (2 N + 4,), optional
            The robot's state (replanning); default the straight robot at rest at the start.
        step : int
            Step of the task at ``state``.

        Returns
        -------
        Outcome
        """
        refused = self.refusal(state)
        if refused is not None:
            return Outcome(Plan(False, refused.status, str(refused)), refused.status, str(refused))
        banned: set = set()
        total = searching = 0.0
        checks: list[Swim] = []
        bad: list[Swim] = []
        plan = Plan(False, "gave_up", "")
        for attempt in range(self.repairs + 1):
            plan = self.search.plan(banned, start_state=state, start_step=step)
            total += plan.planning_time_s
            searching += plan.planning_time_s
            if not plan.found and attempt > 0:
                msg = (f"check failed: {attempt} plans failed their check in the twin (last: "
                       f"{bad[0].label}: {bad[0].message}) and the search found no other "
                       f"({plan.message})")
                return Outcome(Plan(False, "check_failed", msg, expansions=plan.expansions,
                                    simulations=plan.simulations,
                                    planning_time_s=plan.planning_time_s, tree=plan.tree),
                               "check_failed", msg, checks, attempt, total, searching)
            if not plan.found:
                return Outcome(plan, plan.status, plan.message, checks, attempt, total, searching)
            if not self.check:
                return Outcome(plan, "found", plan.message, [], attempt, total, searching)
            checks, elapsed = self.check_plan(plan, state, step)
            total += elapsed
            bad = [c for c in checks if not c.ok]
            if not bad:
                msg = (f"{plan.message}; checked in the twin over {len(checks)} coefficient sets"
                       f" (min clearance {min(c.min_clearance_m for c in checks) * 1000:.0f} mm)")
                return Outcome(plan, "found", msg, checks, attempt, total, searching)
            worst = bad[0]
            leg = plan.legs[worst.failed_leg if worst.failed_leg is not None else -1]
            banned.add((leg.parent_key, leg.action))
            log.info("plan failed its check with %s (%s); banning leg to (%.2f, %.2f)",
                     worst.label, worst.message, *leg.waypoint_m)
        msg = (f"check failed: after {self.repairs} repairs the plan still fails in the twin with "
               f"{len(bad)} of {len(checks)} coefficient sets (e.g. {bad[0].label}: "
               f"{bad[0].message})")
        return Outcome(Plan(False, "check_failed", msg, plan.legs, plan.cost_s, plan.expansions,
                            plan.simulations, plan.planning_time_s, plan.tree),
                       "check_failed", msg, checks, self.repairs, total, searching)

    def check_plan(self, plan: Plan, state: FloatArray | None = None,
                   step: int = 0) -> tuple[list[Swim], float]:
        """Swim a plan over the uncertainty ensemble.

        Parameters
        ----------
        plan : Plan
        state : ndarray, optional
            Start state (default: the world's start).
        step : int

        Returns
        -------
        list of Swim, float
            The runs and the time they took, s.
        """
        import time

        t0 = time.perf_counter()
        duration = 2.0 * (plan.cost_s - step * self.twin.dt_s) + 30.0
        runs = swim(self.world, plan.waypoints_m, self.twin,
                    self.coefficients.ensemble(self.sigmas), duration, state=state,
                    start_step=step, clearance=self.clearance)
        return runs, time.perf_counter() - t0
