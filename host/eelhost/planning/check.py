"""Swim a plan in drawn waters leg by leg, as the search swam it, and judge every run.

docs/planning.md ("The planner", step 3) is the long form. The search swims straight legs with
the straight coefficients and turns with the turning ones, each leg restarted from the state
the previous one left (:mod:`eelhost.planning.twin`); a water of the check
(:class:`eelhost.planning.uncertainty.WaterDraw`) has its own straight and turning sets and its
own current, so the check swims the plan the same way in each water: all waters' runs of leg k
in one batch, each from the state its own run of leg k - 1 left, taken at the last control
update a median-filter window before that run accepted its waypoint (the search's restart, exact
but for the first offset's median filter holding one frame). The last leg runs until the
centre of mass enters the goal disc (:func:`eelhost.planning.search.in_goal`).

Each run is then judged as :func:`eelhost.planning.execute.swim` judges one: the goal reached,
and the body clear of everything at every physics step (the exact link distances against the
body's half width, :func:`eelhost.planning.execute.body_clearance_m`, computed only at the
states where a verdict can depend on it: :func:`judged_clearance_m`). A leg whose waypoint a
run never accepts ends that run there (the goal missed, blamed on that leg). With a check margin
(``margin_m``, the planner's :data:`eelhost.planning.planner.CHECK_MARGIN_M`) a run whose body
comes within the margin of anything has its ``failed_leg`` set to the leg it came that close on,
so that a repair can ban it; whether it touched stays its own (``collision_free``).

Each swim records its wall time per run-step (:data:`CHECK_COST`); with a deadline, a leg's
batch predicted by it to end late is not started and the swim raises :class:`CheckOutOfTime`
(docs/planning.md, "The planning call's deadline").
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import SupportsFloat

import numpy as np
import numpy.typing as npt

from eelhost.planning.body import link_endpoints, reach_m
from eelhost.planning.execute import Swim, quarter_point_values
from eelhost.planning.field import ClearanceField
from eelhost.planning.geometry import FloatArray
from eelhost.planning.harbour import StopWindow, stop_states
from eelhost.planning.search import Guide, Plan, SwimCost, goal_mask, leg_start_guide
from eelhost.planning.twin import Twin
from eelhost.planning.uncertainty import WaterDraw
from eelhost.planning.world import World
from eelsim.dynamics import straight_state
from eelsim.model import SwimmerModel

ARRIVAL_STOP_STRIDE = 3
"""Physics steps between the judged samples of an arrival's stop (the harbour's stride: a body
drifting at under 0.1 m/s moves under 0.3 mm between them)."""

LEG_TIME_FACTOR = 3.0
"""A check run's time limit for a leg, as a multiple of the time the search's run took."""


class CheckOutOfTime(Exception):
    """The check stopped at its deadline before swimming every run (the plan is not checked)."""


CHECK_COST = SwimCost()
"""The process's measurement of the check's cost, shared by every planner (replans' too)."""

SCREEN_TOLERANCE_M = 1e-9
"""Taken off :func:`judged_clearance_m`'s bound, m: room for the interpolation's rounding."""


FIELD_LIPSCHITZ = 1.0 + math.sqrt(2.0)
"""How much the clearance field's interpolant (:class:`eelhost.planning.field.ClearanceField`)
changes at most per metre a point moves, anywhere: the bilinear interpolant of grid values of a
1-Lipschitz distance changes by at most 1 per metre along each axis of a cell (sqrt 2 in any
direction, :data:`GRID_LIPSCHITZ`), and outside the grid the distance beyond it (1) is taken off
the clipped point's value."""

GRID_LIPSCHITZ = math.sqrt(2.0)
"""The same within the field's grid (a convex rectangle: a point moving between two points in it
stays in it)."""

CARRY_STRIDE = 8
"""Every this many states of a check run (and its last) the judge measures the body at its quarter
points; the states between carry a bound from the two nearest of them (:func:`judged_clearance_m`;
docs/planning.md, "The check's judge: a bound carried from state to state")."""


def end_motion_bound_m(model: SwimmerModel, states: FloatArray, anchors: FloatArray) -> FloatArray:
    """A bound on how far any link end point moved from ``anchors`` to ``states``, m.

    A link end is the centre of mass plus a fixed combination of the links' unit directions
    (:func:`eelhost.planning.body.link_endpoints`), and a unit direction moves by at most the
    angle it turns, so an end moves by at most the centre of mass's move plus the combination's
    weights times the links' turns. Cheaper than the end points themselves (no sines or cosines),
    and as valid for any turn, however large.

    Parameters
    ----------
    model : SwimmerModel
    states, anchors : ndarray, shape (K, 2 N + 4)
        Pairs of states, row by row.

    Returns
    -------
    ndarray, shape (K,)
        For each pair, at least the largest distance between the same link end at both, m.
    """
    n = model.n_links
    g = np.abs(model.geometry)
    lh = np.asarray(model.half_length_m, dtype=float)
    weights = np.empty((n + 1, n))  # end j's weight on link k's direction, as link_endpoints
    weights[0] = g[0]
    weights[0, 0] = abs(model.geometry[0, 0] - lh[0])
    weights[1:] = g
    weights[1:][np.arange(n), np.arange(n)] = np.abs(np.diagonal(model.geometry) + lh)
    turn = np.abs(states[:, :n] - anchors[:, :n])
    moved = np.hypot(states[:, n] - anchors[:, n], states[:, n + 1] - anchors[:, n + 1])
    return np.asarray(moved + (turn @ weights.T).max(axis=1), dtype=float)


def judged_clearance_m(world: World, field: ClearanceField, model: SwimmerModel,
                       states: FloatArray, margin_m: float = 0.0) -> FloatArray:
    """The body's clearance at every state where a check run's verdict can depend on it.

    Where it matters (every state that :func:`eelhost.planning.execute.body_clearance_m` puts
    at or below ``margin_m``, at or below 0, or at its smallest value) the value is that
    function's, computed the same way; elsewhere a bound above all of those. So the smallest
    value, the first state at or below 0 and the first at or below the margin, all that the
    check reads, are the reference's (docs/planning.md, "The check's processor time" and "The
    check's judge: a bound carried from state to state"; a test compares the two).

    Why it is cheaper: the reference measures every state at its links' quarter points (25
    field look-ups per state for six links) before the exact geometry. Here only every
    :data:`CARRY_STRIDE`-th state (an anchor) and the run's last are measured so: the
    reference's lower bound there, ``L = min f - e - h / 4`` (``f`` the field at the quarter
    points, ``e`` its error, ``h`` half a link). A state between two anchors carries the larger
    of their bounds less the field's slope (:data:`GRID_LIPSCHITZ` where both states' bodies
    are inside the field's grid, else :data:`FIELD_LIPSCHITZ`) times how far any link end moved
    since (:func:`end_motion_bound_m`; a quarter point moves no further than its link's ends),
    which is never above its own ``L``. The smallest upper bound over the anchors (``min f + e``) is at
    least the reference's smallest, so a state whose carried bound is above it, above the
    contact distance and above the margin is none the reference computes exactly, flags, or
    takes its minimum from; every other state gets the reference's own value (its quarter
    points, then the exact geometry where the reference takes it).

    Parameters
    ----------
    world : World
    field : ClearanceField
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4)
    margin_m : float
        The check's margin, m.

    Returns
    -------
    ndarray, shape (K,)
    """
    half_link = float(model.half_length_m.max())
    half_width = float(model.half_axis_horizontal_m.max())
    if not len(states):
        return np.zeros(0)
    bound, ceiling = carried_lower_m(field, model, states)
    rows = np.flatnonzero(bound <= max(ceiling, half_width, margin_m + half_width))
    out = bound
    out[rows] = _exact_where_it_matters(world, field, link_endpoints(model, states[rows]),
                                        half_link, half_width, margin_m)
    return out - half_width


def carried_lower_m(field: ClearanceField, model: SwimmerModel,
                    states: FloatArray) -> tuple[FloatArray, float]:
    """A lower bound of the reference's quarter-point bound at every state, and a ceiling.

    :func:`judged_clearance_m`'s screen: the reference's lower bound ``L = min f - e - h / 4``
    measured at every :data:`CARRY_STRIDE`-th state and the last (the anchors), carried to the
    states between from the nearer-bounding of the two anchors either side, less the field's
    slope times how far a link end can have moved (:func:`end_motion_bound_m`).

    Parameters
    ----------
    field : ClearanceField
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4), K >= 1

    Returns
    -------
    ndarray, shape (K,)
        At most the reference's ``L`` at every state (equal to it at the anchors), m of the
        centre line's clearance.
    float
        The anchors' smallest upper bound ``min f + e``: at least the reference's smallest.
    """
    half_link = float(model.half_length_m.max())
    e = field.error_m
    k = len(states)
    anchors = np.unique(np.r_[np.arange(0, k, CARRY_STRIDE), k - 1])
    anchor_values = quarter_point_values(field, link_endpoints(model, states[anchors]))
    lower = anchor_values - e - half_link / 4.0
    # each state's anchor at or before it and the next one (the run's last for the tail)
    before = np.minimum(np.arange(k) // CARRY_STRIDE, len(anchors) - 1)
    after = np.minimum(before + 1, len(anchors) - 1)
    # a state whose every body point is inside the grid (its centre of mass more than the
    # body's reach from the grid's edges): between two such, the interpolant's own slope
    n = model.n_links
    reach = reach_m(model) + 1e-3
    x, y = states[:, n], states[:, n + 1]
    inside = ((x > reach) & (x < (field.nx - 1) * field.cell_m - reach)
              & (y > reach) & (y < (field.ny - 1) * field.cell_m - reach))
    within = inside[anchors]

    def slope(side: npt.NDArray[np.intp]) -> FloatArray:
        return np.where(inside & within[side], GRID_LIPSCHITZ, FIELD_LIPSCHITZ)

    from_before = lower[before] - slope(before) * end_motion_bound_m(
        model, states, states[anchors[before]])
    from_after = lower[after] - slope(after) * end_motion_bound_m(
        model, states, states[anchors[after]])
    bound = np.maximum(from_before, from_after) - SCREEN_TOLERANCE_M
    bound[anchors] = lower
    return bound, float(anchor_values.min()) + e


EXACT_CHUNK = 256
"""States measured exactly at once while :func:`_exact_where_it_matters` looks for the smallest
(each call of :meth:`eelhost.planning.world.World.body_clearance` costs a fixed part per obstacle:
64 at once took a fifth more of the judging's time on 45001's check runs than 256)."""


def _exact_where_it_matters(world: World, field: ClearanceField, ends: FloatArray,
                            half_link: float, half_width: float, margin_m: float) -> FloatArray:
    """The reference's clearance of the centre line where a verdict reads it, else its bound.

    :func:`eelhost.planning.execute._body_clearance` (its quarter points' lower bound
    ``L``, the exact geometry where ``L`` is at most the smallest upper bound ``U`` or the
    contact distance), except that of the states it measures exactly whose ``L`` is above the
    margin (so that neither contact nor the margin can be theirs) only those are measured that
    may still hold the smallest value: in order of ``L``, until ``L`` is above the smallest
    value measured. The others keep ``L``, above that smallest value and above the margin.

    Parameters
    ----------
    world : World
    field : ClearanceField
    ends : ndarray, shape (K, N + 1, 2)
        Link end points.
    half_link, half_width : float
        Half the longest link and the body's half width, m.
    margin_m : float
        The check's margin over the half width, m.

    Returns
    -------
    ndarray, shape (K,)
        The centre line's clearance (the half width not taken off).
    """
    values = quarter_point_values(field, ends)
    if not len(values):
        return values
    upper = values + field.error_m
    lower = values - field.error_m - half_link / 4.0
    out = lower.copy()
    need = lower <= max(float(upper.min()), half_width)
    must = np.flatnonzero(need & (lower <= margin_m + half_width))
    best = math.inf
    for lo in range(0, must.size, 500):
        part = must[lo : lo + 500]
        out[part] = world.body_clearance(ends[part], upper[part])
        best = min(best, float(out[part].min()))
    rest = np.flatnonzero(need & (lower > margin_m + half_width))
    rest = rest[np.argsort(lower[rest], kind="stable")]
    for lo in range(0, rest.size, EXACT_CHUNK):
        part = rest[lo : lo + EXACT_CHUNK]
        part = part[lower[part] <= best]
        if not part.size:
            break
        out[part] = world.body_clearance(ends[part], upper[part])
        best = min(best, float(out[part].min()))
    return out


def water_twin(twin: Twin, waters: Sequence[WaterDraw]
               ) -> tuple[Twin, list[tuple[float, float]]]:
    """A twin carrying every water's coefficient sets, and each water's current.

    Water i swims with coefficient index ``2 i`` (its straight set) or ``2 i + 1`` (its turning
    set), in the planner's current plus its own offset.

    Parameters
    ----------
    twin : Twin
        Robot, gait, loop options and the planner's current.
    waters : sequence of WaterDraw

    Returns
    -------
    Twin, list of (vx, vy)
    """
    sets = [c for w in waters for c in (w.straight, w.turning)]
    runner = Twin(twin.robot, sets, twin.gait, twin.options, twin.current_m_s,
                  twin.acceptance_radius_m, twin.threads, twin.model)
    vx, vy = twin.current_m_s
    return runner, [(vx + w.current_offset_m_s[0], vy + w.current_offset_m_s[1])
                    for w in waters]


def swim_legs(
    world: World,
    plan: Plan,
    twin: Twin,
    model: SwimmerModel,
    waters: Sequence[WaterDraw],
    leg_coefficients: Sequence[int],
    clearance: ClearanceField,
    state: FloatArray | None = None,
    start_step: int = 0,
    guide: Guide | None = None,
    deadline_s: SupportsFloat | None = None,
    clock: Callable[[], float] = time.monotonic,
    cost: SwimCost | None = None,
    margin_m: float = 0.0,
    arrival_stop: StopWindow | None = None,
) -> list[Swim]:
    """Swim a plan leg by leg in each water and judge each run (module docstring).

    Parameters
    ----------
    world : World
    plan : Plan
    twin : Twin
        Robot, gait, loop options and the planner's current (each water adds its offset).
    model : SwimmerModel
        The robot's model (body dimensions).
    waters : sequence of WaterDraw
    leg_coefficients : sequence of int
        Per leg, 0 (swum with the water's straight set) or 1 (its turning set), as the search.
    clearance : ClearanceField
    state : ndarray, optional
        Start state (default: the straight robot at rest at the world's start).
    start_step : int
        Step of the task at ``state``.
    guide : (x, y, I_x, I_y), optional
        The guidance's state at the start (default the plan's ``start_guide``, else the first
        leg from the start state's centre of mass with the integral zero, as the search).
        Each run's next leg starts with the state its previous leg left at the restart.
    deadline_s : float, optional
        A time on ``clock``: no leg's batch is started that ``cost`` predicts would end after
        it (or at all once it has passed); the swim then raises :class:`CheckOutOfTime`.
        Default: none.
    clock : callable
        The clock of ``deadline_s`` and of the cost's measurement (``time.monotonic``).
    cost : SwimCost, optional
        Where the swim's measured cost is recorded and the leg batches' time predicted from
        (default :data:`CHECK_COST`, the process's).
    margin_m : float
        The check's margin, m: a run that reaches the goal without contact but whose body comes
        within this of anything gets ``failed_leg``, the leg of its first such step (default 0:
        only contact and a missed goal).
    arrival_stop : StopWindow, optional
        The stop the tank makes on arriving (the final Stop's brake and the glide after it):
        each run that reaches the goal swims it on from its first state in the goal disc, in
        its own water (its straight set and current), and is judged through it as through its
        legs; its states are appended to the run's (every :data:`ARRIVAL_STOP_STRIDE` steps),
        and a stop that touches or comes within the margin fails the run on the last leg
        (docs/planning.md, "The arrival's stop in the check"). Default: none (the run ends in
        the goal disc).

    Returns
    -------
    list of Swim
        One per water, in order.

    Raises
    ------
    CheckOutOfTime
        ``deadline_s`` came before every leg was swum (no run is judged then).
    """
    cost = CHECK_COST if cost is None else cost
    started = clock()
    run_steps = 0
    r = len(waters)
    n = model.n_links
    if state is None:
        state = straight_state(model, math.radians(world.start.heading_deg),
                               world.start.position_m)
    runner, currents = water_twin(twin, waters)
    period = runner.restart_steps or 1
    warm = int(math.ceil(twin.options.camera.median_window / twin.options.camera.fps
                         / twin.dt_s - 1e-9))
    if guide is None:
        guide = plan.start_guide or leg_start_guide(np.asarray(state, dtype=float), n)
    guides: list[Guide] = [guide] * r
    states = np.repeat(np.asarray(state, dtype=float)[None], r, axis=0)
    steps = np.full(r, int(start_step), dtype=np.int64)
    pieces: list[list[FloatArray]] = [[] for _ in range(r)]
    leg_of: list[list[int]] = [[] for _ in range(r)]
    live = list(range(r))
    reached = np.zeros(r, dtype=bool)
    missed_leg: list[int | None] = [None] * r
    reasons = [""] * r
    arrived_at = np.zeros(r, dtype=np.int64)
    last = len(plan.legs) - 1
    for k, leg in enumerate(plan.legs):
        if not live:
            break
        wps = [leg.waypoint_m] if k == 0 else [plan.legs[k - 1].waypoint_m, leg.waypoint_m]
        took = max(leg.end_step - leg.start_step, period) * twin.dt_s
        if deadline_s is not None:
            # the leg's batch as the search swam it, in every live water (the last with the
            # arrival's stop after it)
            extra = (arrival_stop_s(arrival_stop) if k == last and arrival_stop is not None
                     else 0.0)
            need = cost.predict_s(len(live) * (took + extra) / twin.dt_s) or 0.0
            if clock() + need > float(deadline_s):
                raise CheckOutOfTime(
                    f"the check stopped at its deadline before leg {k + 1} of "
                    f"{len(plan.legs)} ({len(live)} of {r} runs still swimming)")
        runs = runner.run(
            [wps] * len(live), LEG_TIME_FACTOR * took + 10.0,
            states=states[live], start_steps=steps[live],
            coefficient_index=[2 * i + leg_coefficients[k] for i in live], stride=1,
            currents=[currents[i] for i in live],
            guidance=[guides[i] for i in live],
        )
        run_steps += int(np.sum(runs.final_step + 1))
        # at a restart the guidance steers to this leg's waypoint along the leg from the one
        # before (for the first leg, from the start's leg start)
        origin = plan.legs[k - 1].waypoint_m if k > 0 else (guide[0], guide[1])
        still = []
        for j, i in enumerate(live):
            end = int(runs.final_step[j])
            path = runs.states[j, : end + 1]
            if k == last:
                inside = np.flatnonzero(goal_mask(world, path[:, n : n + 2]))
                cut = int(inside[0]) + 1 if inside.size else end + 1
                reached[i] = bool(inside.size)
                arrived_at[i] = int(steps[i]) + cut - 1
            else:
                arrival = int(runs.arrival_step[j])
                restart = ((arrival - warm) // period) * period
                if runs.reasons[j] or arrival < 0:
                    cut = end + 1
                else:
                    cut = restart if restart > 0 else arrival
            if k != last and (runs.reasons[j] or runs.arrival_step[j] < 0):
                missed_leg[i], reasons[i] = k, runs.reasons[j] or "waypoint never accepted"
            elif k == last and not reached[i]:
                missed_leg[i], reasons[i] = k, runs.reasons[j]
            pieces[i].append(path[:cut])
            leg_of[i] += [k] * cut
            if k != last and missed_leg[i] is None:
                states[i] = path[cut]
                guides[i] = runs.guidance_state(j, cut, origin)
                steps[i] += cut
                still.append(i)
        live = still
    stop_steps: list[int] = []
    stops = _arrival_stops(runner, currents, pieces, reached, arrived_at, arrival_stop,
                           stop_steps)
    run_steps += sum(stop_steps)
    out = []
    goal = np.asarray(world.goal.position_m)
    t0 = start_step * twin.dt_s
    for i, w in enumerate(waters):
        run_states = np.concatenate(pieces[i])
        swum = len(run_states)
        times = t0 + np.arange(swum) * twin.dt_s
        if stops is not None and reached[i]:
            stop = stops[i]
            ended = not np.isfinite(stop[:, 0]).all()
            stop = stop[np.isfinite(stop[:, 0])]
            if ended:
                # the twin ended the stop early (a flag): nothing after it is judged
                missed_leg[i], reasons[i] = last, "the arrival's stop ended early in the twin"
                reached[i] = False
            run_states = np.concatenate([run_states, stop[1:]])
            times = np.concatenate([times, times[-1] + np.arange(1, len(stop))
                                    * ARRIVAL_STOP_STRIDE * twin.dt_s])
            leg_of[i] += [last] * (len(stop) - 1)
        com = run_states[:, n : n + 2]
        clear = judged_clearance_m(world, clearance, model, run_states, margin_m)
        touching = np.flatnonzero(clear <= 0.0)
        first = int(touching[0]) if touching.size else None
        failed = leg_of[i][first] if first is not None else missed_leg[i]
        if failed is None and margin_m > 0.0:
            near = np.flatnonzero(clear <= margin_m)
            failed = leg_of[i][int(near[0])] if near.size else None
        out.append(Swim(
            label=w.label,
            reached=bool(reached[i]),
            goal_time_s=t0 + (swum - 1) * twin.dt_s if reached[i] else None,
            collision_free=first is None,
            min_clearance_m=float(clear.min()),
            first_collision_s=None if first is None else float(times[first]),
            goal_distance_m=float(np.hypot(*(com - goal).T).min()),
            failed_leg=failed,
            reason=reasons[i],
            t_s=np.asarray(times, dtype=np.float64),
            states=run_states,
        ))
    cost.record(run_steps, clock() - started)
    return out


def arrival_stop_s(window: StopWindow) -> float:
    """How long an arrival's stop is swum: its brake and the glide after it, s."""
    return float(window.unbrake(0.0)) + float(window.after_s)


def _arrival_stops(runner: Twin, currents: Sequence[tuple[float, float]],
                   pieces: Sequence[Sequence[FloatArray]], reached: npt.NDArray[np.bool_],
                   arrived_at: npt.NDArray[np.int64], window: StopWindow | None,
                   swum: list[int]) -> FloatArray | None:
    """Every arriving run's stop from its first state in the goal disc, in its own water.

    The stop the tank's replanner judges before its final stop
    (:func:`eelhost.planning.harbour.stop_states`: the brake's frozen S, then the straight
    body), swum in one batch per part with each water's straight set and current; the
    run-steps swum are appended to ``swum`` (the check's cost).

    Returns
    -------
    ndarray, shape (R, S, 2 N + 4), or None
        Row i is NaN for a run that did not arrive; None without a window or an arrival.
    """
    rows = np.flatnonzero(reached)
    if window is None or not rows.size:
        return None
    starts = np.stack([pieces[int(i)][-1][-1] for i in rows])
    times = arrived_at[rows].astype(np.float64) * runner.dt_s
    # each water's straight set (:func:`water_twin`: index 2 i): a stopped body does not turn
    got = stop_states(runner, runner.gait, starts, times, window, ARRIVAL_STOP_STRIDE,
                      coefficient_index=[2 * int(i) for i in rows],
                      currents=[currents[int(i)] for i in rows], swum=swum)
    out = np.full((len(reached), *got.shape[1:]), np.nan)
    out[rows] = got
    return out
