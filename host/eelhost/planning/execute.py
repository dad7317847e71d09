"""Run a plan in the twin and check that the robot reached the goal without touching anything.

The planned waypoints are given to the robot as one closed-loop scenario (the way the real robot
would get them: it steers to each in turn and switches within the acceptance radius), in the world's
current, from the start pose. Every physics step's link segments are checked against the obstacles
and the tank walls, with the links' half width as the clearance they need.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from eelhost.planning.geometry import FloatArray
from eelhost.planning.primitives import link_endpoints, simulate_manoeuvres
from eelhost.planning.search import Plan
from eelhost.planning.world import World
from eelsim.closed_loop import LoopOptions
from eelsim.control import Gait
from eelsim.fluid import FluidCoefficients
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import PATH_GAIT, Scenario


@dataclass
class Execution:
    """The outcome of running a plan in the twin.

    Attributes
    ----------
    reached : bool
        The centre of mass entered the goal disc.
    collision_free : bool
        No link came closer than its half width to an obstacle or a wall.
    min_clearance_m : float
        Smallest gap between the robot's body (link centre lines less the half width) and an
        obstacle or wall, over the run; negative in contact.
    first_collision_s : float or None
        Time of the first step in contact, None when collision-free.
    goal_time_s : float or None
        When the centre of mass entered the goal disc.
    goal_distance_m : float
        Closest approach of the centre of mass to the goal centre.
    reason : str
        Why the twin flagged the run ("" when it did not; a run that reaches the goal disc
        but not the last waypoint in time is flagged too slow).
    t_s : ndarray, shape (K,)
    states : ndarray, shape (K, 2 N + 4)
    scenario : Scenario
        What was simulated.
    """

    reached: bool
    collision_free: bool
    min_clearance_m: float
    first_collision_s: float | None
    goal_time_s: float | None
    goal_distance_m: float
    reason: str
    t_s: FloatArray
    states: FloatArray
    scenario: Scenario

    @property
    def message(self) -> str:
        """One line: reached or not, collision-free or not."""
        goal = (f"reached the goal at t = {self.goal_time_s:.1f} s" if self.reached
                else f"did not reach the goal (closest {self.goal_distance_m:.2f} m)")
        hit = ("collision-free" if self.collision_free
               else f"COLLISION at t = {self.first_collision_s:.1f} s")
        extra = f"; twin flag: {self.reason}" if self.reason else ""
        return f"{goal}; {hit} (min clearance {self.min_clearance_m * 1000:.0f} mm){extra}"


def plan_scenario(world: World, plan: Plan, gait: Gait = PATH_GAIT) -> Scenario:
    """The closed-loop scenario that executes a plan: its waypoints, the world's current.

    Parameters
    ----------
    world : World
    plan : Plan
        A found plan (at least one step).
    gait : Gait
        Must be the gait the library was built with.

    Returns
    -------
    Scenario
    """
    if not plan.steps:
        raise ValueError("the plan has no steps to execute")
    return Scenario(
        name=f"plan_{world.name}",
        amplitude_rad=gait.amplitude_rad,
        omega_rad_s=gait.omega_rad_s,
        beta_rad=gait.beta_rad,
        k_theta=gait.k_theta,
        waypoints_m=plan.waypoints_m,
        current_speed_m_s=world.current.speed_m_s,
        current_direction_deg=world.current.direction_deg,
        # twice the planned time plus slack: a plan that runs that late has failed anyway
        duration_s=2.0 * plan.cost_s + 30.0,
        start_position_m=world.start.position_m,
        start_heading_deg=world.start.heading_deg,
    )


def execute_plan(
    world: World,
    plan: Plan,
    robot: Robot,
    coefficients: FluidCoefficients,
    gait: Gait = PATH_GAIT,
    options: LoopOptions | None = None,
    backend: str = "auto",
    threads: int | None = 1,
) -> Execution:
    """Swim a plan in the twin and check every step for collisions and the goal.

    Parameters
    ----------
    world : World
    plan : Plan
    robot : Robot
    coefficients : FluidCoefficients
    gait : Gait
    options : LoopOptions, optional
    backend : {"auto", "batch", "reference"}
    threads : int or None

    Returns
    -------
    Execution
    """
    scenario = plan_scenario(world, plan, gait)
    opts = options or LoopOptions()
    (run,), _ = simulate_manoeuvres(robot, coefficients, [scenario], opts, backend, threads)
    model = SwimmerModel.from_robot(robot, coefficients)
    n = model.n_links
    p = run.states[:, n : n + 2]
    gap = np.hypot(*(p - np.asarray(world.goal.position_m)).T)
    inside = np.flatnonzero(gap <= world.goal.radius_m)
    goal_time = float(run.t_s[inside[0]]) if inside.size else None
    # stop checking once the goal is reached: what the robot does after it is not the plan's
    end = int(inside[0]) + 1 if inside.size else len(run.t_s)
    pts = link_endpoints(model, run.states[:end])
    half_width = float(model.half_axis_horizontal_m.max())
    clearance, first = math.inf, None
    chunk = 200  # steps per clearance evaluation: a few MB of segment pairs at most
    for k in range(0, end, chunk):
        block = pts[k : k + chunk]
        c = world.segments_clearance(block[:, :-1].reshape(-1, 2), block[:, 1:].reshape(-1, 2))
        clearance = min(clearance, c)
        if c <= half_width and first is None:
            for j in range(len(block)):  # the first step in contact within this block
                if world.segments_clearance(block[j, :-1], block[j, 1:]) <= half_width:
                    first = float(run.t_s[k + j])
                    break
    return Execution(
        reached=goal_time is not None,
        collision_free=first is None,
        min_clearance_m=float(clearance - half_width),
        first_collision_s=first,
        goal_time_s=goal_time,
        goal_distance_m=float(gap.min()),
        reason=run.reason,
        t_s=run.t_s[:end],
        states=run.states[:end],
        scenario=scenario,
    )
