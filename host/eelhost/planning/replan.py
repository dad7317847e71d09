"""Closed-loop execution: follow the plan, replan from the observed state off the corridor.

docs/planning.md ("Execution and replanning") is the long form. The corridor is the centre-of-mass
path the search swam for the plan (its legs' ``com_m``), widened by ``corridor_m`` on each side.
While the robot's centre of mass stays inside it, the robot follows the plan's waypoints under its
own control stack; when it leaves, the planner runs again (re-running A* from the current state:
:meth:`eelhost.planning.planner.Planner.plan` with that state) and the robot is given the new
waypoints. The goal test is :func:`eelhost.planning.search.in_goal` throughout.

- :func:`execute_with_replanning` does this in the twin: the "true" robot is the twin with
  coefficients (and optionally a current) the planner does not know; replans start from the true
  state at the last control update before the robot left (the twin's restarts are exact there).
- :class:`PlanMonitor` does it at the tank, inside ``eelbot run --plan``: it sees only the
  filtered camera pose, so it replans from the straight robot at that pose, with the gait's phase
  at that time (docs/planning.md says what this approximation costs).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from eelhost.planning.execute import Swim, body_clearance_m, swim
from eelhost.planning.geometry import FloatArray, point_segment_distance
from eelhost.planning.planner import Outcome, Planner
from eelhost.planning.search import Plan, in_goal
from eelhost.planning.twin import Twin
from eelsim.dynamics import straight_state
from eelsim.fluid import FluidCoefficients

log = logging.getLogger(__name__)


def corridor_path(plan: Plan) -> FloatArray:
    """The centre-of-mass path the search swam for a plan, shape (P, 2)."""
    if not plan.legs:
        return np.zeros((0, 2))
    return np.concatenate([leg.com_m for leg in plan.legs], axis=0)


def distance_to_path(path: FloatArray, points: FloatArray) -> FloatArray:
    """Distance from each point to a polyline.

    Parameters
    ----------
    path : ndarray, shape (P, 2)
    points : ndarray, shape (K, 2)

    Returns
    -------
    ndarray, shape (K,)
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(path) == 1:
        return np.hypot(*(pts - path[0]).T)
    out = np.empty(len(pts))
    for k in range(0, len(pts), 512):  # bounded memory: points x segments
        out[k : k + 512] = point_segment_distance(pts[k : k + 512], path[:-1], path[1:]).min(axis=1)
    return out


@dataclass
class ReplanRun:
    """A run of the twin with closed-loop replanning.

    Attributes
    ----------
    reached : bool
        The goal test held.
    collision_free : bool
    replans : int
        Times the robot left the corridor and was replanned.
    min_clearance_m : float
    goal_time_s : float or None
    message : str
    states : ndarray, shape (K, 2 N + 4)
        Every step of the run, across replans.
    outcomes : list of Outcome
        The first plan and every replan.
    """

    reached: bool
    collision_free: bool
    replans: int
    min_clearance_m: float
    goal_time_s: float | None
    message: str
    states: FloatArray
    outcomes: list[Outcome] = field(default_factory=list)


def execute_with_replanning(
    planner: Planner,
    coefficients: FluidCoefficients,
    current_m_s: tuple[float, float] | None = None,
    corridor_m: float = 0.10,
    max_replans: int = 6,
) -> ReplanRun:
    """Swim the planner's world in the twin as the true robot, replanning off the corridor.

    Parameters
    ----------
    planner : Planner
        Plans with its own coefficients and the world's current.
    coefficients : FluidCoefficients
        The true robot's coefficients.
    current_m_s : (float, float), optional
        The true current (default: the world's).
    corridor_m : float
        Half width of the corridor around the planned centre-of-mass path.
    max_replans : int

    Returns
    -------
    ReplanRun
    """
    world = planner.world
    truth = Twin(planner.robot, [coefficients], planner.gait, planner.options,
                 current_m_s if current_m_s is not None else world.current_m_s,
                 planner.twin.acceptance_radius_m, planner.twin.threads)
    n = planner.model.n_links
    period = truth.restart_steps or 1
    state: FloatArray | None = None
    step = 0
    pieces: list[FloatArray] = []
    outcomes: list[Outcome] = []
    replans = 0
    while True:
        outcome = planner.plan(state, step)
        outcomes.append(outcome)
        if not outcome.found:
            msg = f"no plan after {replans} replans: {outcome.message}"
            return _finish(planner, False, True, replans, None, msg, pieces, outcomes)
        plan = outcome.plan
        duration = 2.0 * (plan.cost_s - step * truth.dt_s) + 30.0
        (run,) = swim(world, plan.waypoints_m, truth, [("true", coefficients)], duration,
                      state=state, start_step=step, clearance=planner.clearance)
        off = np.flatnonzero(distance_to_path(corridor_path(plan),
                                              run.states[:, n : n + 2]) > corridor_m)
        left = int(off[0]) if off.size else None
        contact = (None if run.first_collision_s is None
                   else int(round(run.first_collision_s / truth.dt_s)) - step)
        if left is None or (contact is not None and contact <= left):
            pieces.append(run.states)
            return _finish(planner, run.reached, run.collision_free, replans, run.goal_time_s,
                           _message(run, replans), pieces, outcomes)
        if replans >= max_replans:
            pieces.append(run.states)
            msg = f"left the corridor again after {replans} replans; {_message(run, replans)}"
            return _finish(planner, run.reached, run.collision_free, replans, run.goal_time_s,
                           msg, pieces, outcomes)
        # replan from the last control update before the robot left (an exact restart)
        cut = max(((step + left) // period) * period - step, 1)
        pieces.append(run.states[:cut])
        state, step = run.states[cut].copy(), step + cut
        replans += 1
        log.info("left the corridor at t = %.1f s; replanning (%d)", step * truth.dt_s, replans)


def _message(run: Swim, replans: int) -> str:
    return f"{run.message}; {replans} replans"


def _finish(planner: Planner, reached: bool, free: bool, replans: int, goal_time: float | None,
            message: str, pieces: list[FloatArray], outcomes: list[Outcome]) -> ReplanRun:
    if not pieces:
        return ReplanRun(reached, free, replans, math.nan, goal_time, message, np.zeros((0, 0)),
                         outcomes)
    states = np.concatenate(pieces, axis=0)
    clear = body_clearance_m(planner.world, planner.clearance, planner.model, states)
    # a contact before a replan ends the run there, so the pieces hold no contact but the last's
    return ReplanRun(reached, free and bool(clear.min() > 0), replans, float(clear.min()),
                     goal_time, message, states, outcomes)


class PlanMonitor:
    """The tank's replanning: watch the filtered pose, replan off the corridor, stop in the goal.

    Called by the run loop (``eelbot run --plan``) with every filtered pose.

    Parameters
    ----------
    planner : Planner
    outcome : Outcome
        The plan being followed.
    corridor_m : float
    max_replans : int
    """

    def __init__(self, planner: Planner, outcome: Outcome, corridor_m: float = 0.10,
                 max_replans: int = 6) -> None:
        self.planner = planner
        self.outcome = outcome
        self.corridor_m = corridor_m
        self.max_replans = max_replans
        self.replans = 0
        self.path = corridor_path(outcome.plan)

    def __call__(self, t_s: float, pose: FloatArray) -> list[tuple[float, float]] | str | None:
        """Decide on one filtered pose.

        Parameters
        ----------
        t_s : float
            Time since the gait started.
        pose : ndarray, shape (3,)
            Filtered x, y, heading.

        Returns
        -------
        list of (x, y), str or None
            New waypoints after a replan; ``"arrived"`` when the goal test holds; None to go on.
        """
        world = self.planner.world
        xy = (float(pose[0]), float(pose[1]))
        if in_goal(world, xy):
            return "arrived"
        if self.replans >= self.max_replans:
            return None
        if float(distance_to_path(self.path, np.asarray([xy]))[0]) <= self.corridor_m:
            return None
        state = straight_state(self.planner.model, float(pose[2]), xy)
        step = int(round(t_s / self.planner.twin.dt_s))
        outcome = self.planner.plan(state, step)
        self.replans += 1
        if not outcome.found:
            log.warning("left the corridor at t = %.1f s and replanning failed: %s", t_s,
                        outcome.message)
            return None
        log.info("left the corridor at t = %.1f s; replanned: %s", t_s, outcome.message)
        self.outcome = outcome
        self.path = corridor_path(outcome.plan)
        return outcome.plan.waypoints_m
