"""Swim a plan in the twin as the tank would, and check it: no contact, and the goal reached.

The planned waypoints go to the robot as one closed-loop task from the world's start (the control
stack of docs/model.md section 4: camera, median filter, offset updates every 0.3 s, waypoint
switches in the acceptance circle), in the world's current, with one or more coefficient sets at
once (the batched twin). For each run:

- the goal test is :func:`eelhost.planning.search.in_goal` on the centre of mass, the one the
  search and the tank's run loop use; the run is judged up to the step it first holds (the robot
  stops there);
- contact is the exact distance from the link centre lines to every obstacle and wall at every
  physics step, against the body's half width and nothing else (no planning margin);
- a failure is blamed on the leg being swum at the time (for a goal never reached, the last leg),
  which is what the planner repairs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.planning.body import link_endpoints
from eelhost.planning.field import ClearanceField
from eelhost.planning.geometry import FloatArray
from eelhost.planning.search import goal_mask
from eelhost.planning.twin import IntArray, Twin
from eelhost.planning.world import World
from eelsim.fluid import FluidCoefficients
from eelsim.model import SwimmerModel


@dataclass
class Swim:
    """One coefficient set's run of a plan in the twin.

    Attributes
    ----------
    label : str
        Which coefficient set.
    reached : bool
        The goal test held at some step.
    goal_time_s : float or None
    collision_free : bool
        No link centre line came within the body's half width of an obstacle or wall.
    min_clearance_m : float
        Smallest gap between the body and an obstacle or wall (negative: overlap).
    first_collision_s : float or None
    goal_distance_m : float
        Closest approach of the centre of mass to the goal centre.
    failed_leg : int or None
        Index of the leg being swum at the first failure (None when the run passed).
    reason : str
        The twin's failure flag ("" when none); a twin flag before the goal fails the run.
    t_s : ndarray, shape (K,)
    states : ndarray, shape (K, 2 N + 4)
        Every step up to the goal (or the end of the run).
    """

    label: str
    reached: bool
    goal_time_s: float | None
    collision_free: bool
    min_clearance_m: float
    first_collision_s: float | None
    goal_distance_m: float
    failed_leg: int | None
    reason: str
    t_s: FloatArray
    states: FloatArray

    @property
    def ok(self) -> bool:
        """Reached the goal without contact."""
        return self.reached and self.collision_free

    @property
    def message(self) -> str:
        """One line: reached or not, collision-free or not."""
        goal = (f"reached the goal at t = {self.goal_time_s:.1f} s" if self.reached
                else f"did not reach the goal (closest {self.goal_distance_m:.2f} m from its "
                     "centre)")
        hit = ("collision-free" if self.collision_free
               else f"COLLISION at t = {self.first_collision_s:.1f} s")
        extra = f"; twin flag: {self.reason}" if self.reason else ""
        return f"{goal}; {hit} (min clearance {self.min_clearance_m * 1000:.0f} mm){extra}"


def leg_in_progress(com: FloatArray, waypoints: FloatArray, radius_m: float) -> IntArray:
    """Index of the waypoint being steered to at each step.

    From the centre of mass entering each acceptance circle in turn (the guidance switches on
    the filtered position, a few milliseconds later).

    Parameters
    ----------
    com : ndarray, shape (K, 2)
    waypoints : ndarray, shape (W, 2)
    radius_m : float

    Returns
    -------
    ndarray of int, shape (K,)
    """
    out = np.full(len(com), len(waypoints), dtype=np.int64)
    k0 = 0
    for i, w in enumerate(waypoints):
        inside = np.flatnonzero(np.hypot(*(com[k0:] - w).T) < radius_m)
        if not inside.size:
            out[k0:] = i
            return out
        out[k0 : k0 + int(inside[0]) + 1] = i
        k0 += int(inside[0]) + 1
    return out


def swim(
    world: World,
    waypoints: Sequence[tuple[float, float]],
    twin: Twin,
    coefficient_sets: Sequence[tuple[str, FluidCoefficients]],
    duration_s: float,
    state: FloatArray | None = None,
    start_step: int = 0,
    clearance: ClearanceField | None = None,
    currents: Sequence[tuple[float, float]] | None = None,
) -> list[Swim]:
    """Swim waypoints in the twin with each coefficient set and check every step.

    Parameters
    ----------
    world : World
    waypoints : sequence of (x, y)
    twin : Twin
        Robot and its model, gait, loop options, current (its own coefficient sets are not
        used).
    coefficient_sets : sequence of (label, FluidCoefficients)
    duration_s : float
        Time limit of the runs.
    state : ndarray, optional
        Start state (default: straight at rest at the world's start).
    start_step : int
        Step of the task at which the runs start (the gait's phase; see
        :meth:`eelhost.planning.twin.Twin.run`).
    clearance : ClearanceField, optional
        The world's clearance field (built when not given); it only decides which steps need
        the exact distance.
    currents : sequence of (vx, vy), optional
        The current of each run, one per coefficient set (default: the twin's for all); the
        planner's check swims its draws of the water (coefficients and current) in one batch.

    Returns
    -------
    list of Swim
        In the order of ``coefficient_sets``.
    """
    if not waypoints:
        raise ValueError("the plan has no waypoints to swim")
    sets = list(coefficient_sets)
    runner = Twin(twin.robot, [c for _, c in sets], twin.gait, twin.options, twin.current_m_s,
                  twin.acceptance_radius_m, twin.threads, twin.model)
    start = (*world.start.position_m, math.radians(world.start.heading_deg))
    r = len(sets)
    runs = runner.run(
        [list(waypoints)] * r,
        duration_s,
        states=None if state is None else np.repeat(np.asarray(state)[None], r, axis=0),
        start_steps=None if state is None else [start_step] * r,
        coefficient_index=list(range(r)),
        stride=1,
        starts=[start] * r,
        currents=currents,
    )
    model = twin.model  # the body: its dimensions, whatever the water
    n = model.n_links
    field = clearance if clearance is not None else ClearanceField(world)
    wps = np.asarray(waypoints, dtype=float)
    dt = twin.dt_s
    out = []
    for i, (label, _) in enumerate(sets):
        end = int(runs.final_step[i])
        states = runs.states[i, : end + 1]
        com = states[:, n : n + 2]
        gap = np.hypot(*(com - np.asarray(world.goal.position_m)).T)
        inside = np.flatnonzero(goal_mask(world, com))
        stop = int(inside[0]) if inside.size else end
        states = states[: stop + 1]
        clear = body_clearance_m(world, field, model, states)
        touching = np.flatnonzero(clear <= 0.0)
        first = int(touching[0]) if touching.size else None
        reason = runs.reasons[i] if not inside.size else ""
        failed_leg = None
        legs = leg_in_progress(com[: stop + 1], wps, twin.acceptance_radius_m)
        if first is not None:
            failed_leg = int(min(legs[first], len(wps) - 1))
        elif not inside.size:
            failed_leg = int(min(legs[-1], len(wps) - 1))
        t0 = start_step * dt
        out.append(Swim(
            label=label,
            reached=bool(inside.size),
            goal_time_s=t0 + stop * dt if inside.size else None,
            collision_free=first is None,
            min_clearance_m=float(clear.min()),
            first_collision_s=None if first is None else t0 + first * dt,
            goal_distance_m=float(gap.min()),
            failed_leg=failed_leg,
            reason=reason,
            t_s=np.asarray(t0 + np.arange(stop + 1) * dt, dtype=np.float64),
            states=states,
        ))
    return out


def body_clearance_m(
    world: World, field: ClearanceField, model: SwimmerModel, states: FloatArray,
    exact_within_m: float = 0.0,
) -> FloatArray:
    """Gap between the body and the nearest obstacle or wall at each state (negative: overlap).

    The link centre lines' exact distance less the body's half width, wherever it can be the
    smallest, near contact, or within ``exact_within_m`` of it (see :func:`_body_clearance`);
    elsewhere a lower bound.

    Parameters
    ----------
    world : World
    field : ClearanceField
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4)
    exact_within_m : float
        Gaps up to this are exact (a caller that compares them with a margin gives it).

    Returns
    -------
    ndarray, shape (K,)
    """
    half_link = float(model.half_length_m.max())
    half_width = float(model.half_axis_horizontal_m.max())
    ends = link_endpoints(model, states)
    return _body_clearance(world, field, ends, half_link, half_width + exact_within_m) - half_width


def quarter_point_values(field: ClearanceField, ends: FloatArray) -> FloatArray:
    """The field's smallest value over every link's quarter points, per state.

    A link is never closer than its nearest quarter point less an eighth of its length, so
    this less the field's error and a quarter of a half link bounds the centre line's clearance
    from below (:func:`_body_clearance`; the check's judge, :mod:`eelhost.planning.check`).

    Parameters
    ----------
    field : ClearanceField
    ends : ndarray, shape (K, N + 1, 2)
        Link end points.

    Returns
    -------
    ndarray, shape (K,)
    """
    a, b = ends[:, :-1], ends[:, 1:]
    f = np.arange(4)[None, None, :, None] / 4.0
    pts = np.concatenate([(a[:, :, None] + f * (b - a)[:, :, None]).reshape(len(ends), -1, 2),
                          ends[:, -1:]], axis=1)
    return np.asarray(field(pts).min(axis=1), dtype=float)


def _body_clearance(
    world: World, field: ClearanceField, ends: FloatArray, half_link_m: float, contact_m: float
) -> FloatArray:
    """Exact clearance of the centre line at every step, where it can matter.

    Computed exactly at steps near contact, and at those that may hold the smallest value.

    At the link end points the field is within ``field.error_m`` of the truth, and a link is
    never closer than its nearer end less half its length; steps whose lower bound exceeds both
    the body's reach of contact and the smallest upper bound keep that lower bound, which is
    then not the smallest value and changes no verdict.
    """
    values = quarter_point_values(field, ends)
    upper = values + field.error_m
    lower = values - field.error_m - half_link_m / 4.0
    need = lower <= max(float(upper.min()), contact_m)
    out = lower.copy()
    pick = np.flatnonzero(need)
    for k in range(0, pick.size, 500):
        rows = pick[k : k + 500]
        out[rows] = world.body_clearance(ends[rows])
    return out
