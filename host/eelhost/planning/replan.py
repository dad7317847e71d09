"""Closed-loop execution: follow the plan, replan from the robot's state off the corridor.

docs/planning.md ("Execution and replanning") is the long form. The corridor is the centre-of-mass
path the search swam for the plan (its legs' ``com_m``), widened by ``corridor_m`` on each side.
While the robot's centre of mass stays inside it, the robot follows the plan's waypoints under its
own control stack; when it leaves, the planner runs again (re-running A* from the robot's state:
:meth:`eelhost.planning.planner.Planner.plan` with that state) and the robot is given the new
waypoints. The goal test is :func:`eelhost.planning.search.in_goal` throughout.

- :func:`execute_with_replanning` does this in the twin: the "true" robot is the twin with
  coefficients (and optionally a current) the planner does not know; replans start from the true
  state at the last control update before the robot left (the twin's restarts are exact there).
- :class:`TankReplanner` does it at the tank, inside ``eelbot run --plan``, beside the control
  loop: the planner runs on a worker thread while the robot swims its present leg on; a replan
  starts from the whole body state (:mod:`eelhost.planning.state_estimate`) predicted by the twin
  for the moment the plan will be ready, in the current estimated from the camera track; failed
  replans back off, and the robot is stopped deliberately when no safe continuation exists or
  its estimated body touches an obstacle. The run loop's guidance state (the present leg's
  start, the ILOS integral) goes with the estimate into every twin run from it, and a replan is
  searched from the guidance state predicted for its start, which the loop then steers with.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections import Counter
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from typing import Any, NamedTuple, SupportsFloat, cast

import numpy as np

from eelhost.planning.check import water_twin
from eelhost.planning.deadline import Deadline
from eelhost.planning.execute import Swim, body_clearance_m, swim
from eelhost.planning.geometry import FloatArray, point_segment_distance
from eelhost.planning.harbour import (
    FINAL_GLIDE_S,
    HARBOUR_CUSHION_M,
    HARBOUR_REACH_M,
    Harbour,
    StopWindow,
    find_harbour,
    stop_gap_m,
)
from eelhost.planning.planner import SCREEN_DRAWS, Outcome, Planner
from eelhost.planning.restart import (
    BRAKE_HOLD_S,
    DRIFT_AFTER_S,
    REST_BUDGET_MAX_S,
    REST_BUDGET_S,
    REST_PAUSE_MAX_S,
    REST_RETRY_S,
    REST_SETTLE_S,
    REST_TRIES,
    backing_gait,
    drift,
    paused_drift,
    stopped_gait,
    stopped_twin,
    unbrake_time,
)
from eelhost.planning.search import (
    Guide,
    Leg,
    Plan,
    goal_mask,
    in_goal,
    leg_start_guide,
    ramped_margin_m,
)
from eelhost.planning.state_estimate import (
    BodyEstimate,
    BodyStateEstimator,
    CurrentEstimator,
    CurrentWindow,
)
from eelhost.planning.station import (
    LEAST_BAD_GAIN_M,
    LEAST_BAD_HORIZON_S,
    LEAST_BAD_MAX_S,
    LEAST_BAD_STEP_M,
    STATION_CHECK_S,
    STATION_MAX_S,
    STATION_REACH_M,
    LeastBad,
    Station,
    find_least_bad,
    find_station,
)
from eelhost.planning.twin import Twin
from eelhost.planning.world import World
from eelhost.vision.localise import Localisation
from eelhost.wire import protocol
from eelsim.control import Gait, braked_gait
from eelsim.fluid import FluidCoefficients
from eelsim.model import SwimmerModel

log = logging.getLogger(__name__)


def outline_clearance_m(world: World, model: SwimmerModel, states: FloatArray) -> FloatArray:
    """Gap between the body's own outline and the nearest obstacle or wall (negative: overlap).

    Each link i is the stadium its ellipse fits in: a core segment of half length
    ``l_i - b_i`` along the link through its centre, widened by its own half width ``b_i``
    (docs/model.md section 1), so the outline ends at the head and tail tips. The planner's
    check (:func:`eelhost.planning.execute.body_clearance_m`) instead widens the whole centre
    line by the largest half width, a capsule reaching that half width beyond both tips: the
    right margin for planning, but a look-ahead or contact test judged with it sees contacts the
    body never makes (docs/planning.md, "Execution and replanning"). A link can overlap by at
    most its half width here (:meth:`World.body_clearance` is 0 when touching).

    Parameters
    ----------
    world : World
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4)

    Returns
    -------
    ndarray, shape (K,)
    """
    states = np.asarray(states, dtype=float)
    k, n = len(states), model.n_links
    if k == 0:
        return np.zeros(0)
    theta = states[:, :n]
    c, s = np.cos(theta), np.sin(theta)
    xc = states[:, n : n + 1] + c @ model.geometry.T  # link centres (eelsim.dynamics)
    yc = states[:, n + 1 : n + 2] + s @ model.geometry.T
    b = np.asarray(model.half_axis_horizontal_m, dtype=float)
    core = np.maximum(np.asarray(model.half_length_m, dtype=float) - b, 0.0)
    ends = np.stack([np.stack([xc - core * c, yc - core * s], axis=-1),
                     np.stack([xc + core * c, yc + core * s], axis=-1)], axis=2)  # (K, N, 2, 2)
    gaps = world.body_clearance(ends.reshape(k * n, 2, 2)).reshape(k, n) - b[None]
    return np.asarray(gaps.min(axis=1))


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
                 planner.twin.acceptance_radius_m, planner.twin.threads, planner.model)
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



# -- at the tank -----------------------------------------------------------------------------------

GOAL_APPROACH_CLEARANCE_M = 0.01
"""The goal approach's search margin beyond the body's half width (docs/planning.md): its centre
line this far plus the half width from everything, so the true outline at least this far."""

REPLAN_BUDGET_S = 1.0
"""A replan's wall-clock budget from its request (docs/planning.md, "The replan's deadline"):
issue 28 asks for a new plan ready within 1 s of the robot leaving its corridor."""

CALM_REPLAN_BUDGET_S = 3.0
"""The calm budget (``TankReplanner(calm_budget_s=)``; ``eelbot run`` passes it by default since
session 12, when a more urgent replan could first cut a calm one short): the budget of a replan
asked for in a moved current estimate (``current_estimate``): the
robot is on its plan and the look-ahead swims the next ``replan_horizon_s`` (5 s) clear, so the
replan may take longer, starting from the state predicted this long ahead. On the idle machine
(seeds 13000-13099 and 14000-14099, pure pursuit) 10 of the 18 runs that missed their goal
failed first such a replan within 1 s (the search out of time, or a plan failing its check and
its repair's search starting no expansion), later replans coming from starts where every
manoeuvre swam into the obstacle (docs/planning.md, "Calm replans get more time")."""


EARLY_MARGIN_M = 0.03
"""The early margin developed (``TankReplanner(early_margin_m=)``; ``eelbot run --early-margin
0.03``; off by default: on unseen seeds 23050-23099 it reached 18 goals of 28 against 19 without
it, docs/planning_history.md, "Measured on seeds 23000-23099"): a
look-ahead that swims the planner's capsule within this much of an obstacle or wall (its bare
gap, without the drift allowance) within the early horizon (:data:`EARLY_HORIZON_S`), but not
within the look-ahead's own margin, asks for an early replan (``early_margin``) while the body
still has room to turn: a searched plan keeps its capsule 30 mm clear in its own water (the search's
50 mm centre line less the body's half width), so under this the plan has lost the margin a new
search from there would ask for. On development seeds 21000-21049 every run that missed its goal
was stopped after replans asked at 10 mm, from starts where every manoeuvre swam into the
obstacle (docs/planning.md, "An earlier replan")."""

EARLY_HORIZON_S = 8.0
"""How far ahead the look-ahead swims for the early margin (:data:`EARLY_MARGIN_M`), beyond the
replan horizon's 5 s: on development seeds 21010 and 21012 the capsule's gap fell from 78 to
13 mm and from 77 to 2 mm between two look-aheads 0.6 s apart, an obstacle coming into the 5 s
horizon at its far end (near at 4.9 s ahead), so no margin over 5 s could have asked earlier."""

EARLY_BUDGET_S = 2.0
"""An early replan's budget (``TankReplanner(early_budget_s=)``; ``eelbot run`` passes it): on
development seeds 21000-21024 10 of the first 14 early replans at 1 s ran out of time, 4 of them
with a plan found whose check the deadline stopped; asked 5-8 s before the capsule comes near,
an early replan can take 2 s and start from the state predicted for when they end (as a calm
replan) and still steer before the urgent replan would have been asked."""

EARLY_BACKOFF_S = 1.0
"""After an early replan (found or not; the present plan kept and no failure counted when not),
the next early one waits this long, doubled after each further one (at most four times this)
until a look-ahead swims the plan clear of the early margin."""

EARLY_REASONS = ("current_estimate", "early_margin")
"""Replans asked for while the look-ahead swims the present plan clear by its margin: a failure
of one keeps the present plan and counts no failure (docs/planning.md)."""


PLANNER_REBUILD_M_S = 0.005
"""A planner in the current estimate is built anew only when the estimate has moved this far from
the one it was built in (building one takes 0.4-0.9 s on a loaded machine; docs/planning.md)."""


def _time_left(deadline_s: SupportsFloat | None) -> bool:
    """Whether a ``time.monotonic()`` deadline (None: none) is still ahead."""
    return deadline_s is None or time.monotonic() < float(deadline_s)


CUT_RETURN_S = 0.5
"""Wall time a calm replan cut short has to come back before a predicted contact stops the
robot as for a late replan (the search stops at its next batch, 0.1-0.3 s on the loaded machine;
docs/planning.md, "Calm replans get more time")."""


def _was_cut(deadline_s: SupportsFloat | None) -> bool:
    """Whether a more urgent replan cut this one's deadline short (:class:`Deadline`)."""
    return isinstance(deadline_s, Deadline) and deadline_s.cut


SHIFT_RADII_M = (0.05, 0.10, 0.15)
"""How far the shift repair moves the present plan's waypoints (docs/planning.md, "The shift
repair")."""

SHIFT_DIRECTIONS = 8
"""The directions (evenly spread) each radius of :data:`SHIFT_RADII_M` is tried in."""

SHIFT_CHECKED = 3
"""The shifted plans (the clearest in the estimated water first) checked over the water."""

SHIFT_PREFERENCE_M = 0.01
"""A shift must swim the capsule this much clearer than the unshifted waypoints to rank first."""

SHIFT_GRACE_S = 0.5
"""How far past the replan's budget the shift repair may start a check (docs/planning.md)."""

STOP_BRAKE_S = 3.0
"""The run loop's brake before its final Stop with ``--plan`` (``eelhost.field.runloop.BRAKE_S``,
which ``eelbot run`` passes as ``stop_brake_s``): how the harbour swims a final stop."""

HARBOUR_GAIN_M = 0.02
"""Where no harbour keeps the margin, the clearest is still swum when the twin predicts it clear
and at least this much clearer than the stop where it was decided (docs/planning.md)."""

HARBOURS_PER_PLAN = 2
"""Harbour swims a plan's stops may take: at the end of one, the stop is judged again from where
the robot is, and a second swim may follow (docs/planning.md, "The harbour")."""

HOLD_CHECK_S = 0.5
"""While the robot holds on its present plan, the stop and the harbours are judged again this
often (on the frame's thread, as the harbour's first search): a harbour found then is swum, a
stop the twin swims clear is made (docs/planning.md, "The hold")."""

HOLD_RETRY_S = 0.5
"""While the robot holds, a failed replan is asked for again after this long."""

HOLD_MAX_S = 20.0
"""The longest a plan's hold lasts, from its first frame; then the stop it put off is made."""

STATION_RETRY_S = 0.5
"""While holding station, a replan is asked for again this long after the last was asked
(docs/planning.md, "Holding station (session 21)")."""

STOP_ALLOWANCE_S = 1.0
"""The robot's time kept ahead of a predicted contact for a stop when a replan then fails: the
brake (docs/planning.md, "The brake in the pause") stops a body swimming 0.05-0.12 m/s within
0.02-0.07 m in the twin, which it swims in under 1 s. A failed replan is retried, or a late one
waited for, only while the contact is this much further ahead than the replan needs; on seed
28056 a retry asked for 2.0 s before the contact failed and the stop that followed, 0.7 s before
it, braked into the obstacle (docs/planning.md, "Decided while the brake has room")."""

SHIFT_MARGIN_M = 0.01
"""The capsule's smallest gap a shifted (or kept) route must swim in the estimated water before
it is checked: the goal approach's and the look-ahead's 10 mm, so a repair never steers a route
the look-ahead would at once replan (docs/planning.md, "The shift repair")."""

ESCAPE_FLOOR_M = 0.01
"""The escape's hard floor, m: every run of its check keeps the capsule more than this from
everything, and a start whose capsule is not more than this clear gets no escape (the
look-ahead's margin: the twin's outline was 8-12 mm optimistic over 0.5-1 s in water it did not
know; docs/planning.md, "An escape from inside the margin")."""

ESCAPE_TOLERANCE_M = 0.01
"""How much closer than its start an escape's runs may come, m (the search's own rule for the
first leg from a start inside its margin: the body sways and turns before it moves away)."""

ESCAPE_RAMP_S = 4.0
"""Seconds within which an escape's runs must regain the check's full margin: the margin grows
linearly from the start's gap less the tolerance to the check's margin over this time."""


def escape_margin_m(t_s: FloatArray, start_gap_m: float, full_m: float) -> FloatArray:
    """The capsule's margin an escape's check runs keep at ``t_s`` after its start.

    It grows from the start's gap less :data:`ESCAPE_TOLERANCE_M` (never under
    :data:`ESCAPE_FLOOR_M`) to ``full_m`` (the check's margin) over :data:`ESCAPE_RAMP_S`
    (docs/planning.md, "An escape from inside the margin").

    Parameters
    ----------
    t_s : array_like
        Times since the escape's start, s.
    start_gap_m : float
        The capsule's gap at the start, m.
    full_m : float
        The check's margin, m.

    Returns
    -------
    ndarray
    """
    start = max(start_gap_m - ESCAPE_TOLERANCE_M, ESCAPE_FLOOR_M)
    return ramped_margin_m(t_s, start, full_m, ESCAPE_RAMP_S)


def shifted_waypoints(waypoints: list[tuple[float, float]], size_m: tuple[float, float]
                      ) -> list[list[tuple[float, float]]]:
    """The present plan's remaining waypoints moved a little, the goal's last one kept.

    Every shift of :data:`SHIFT_RADII_M` in :data:`SHIFT_DIRECTIONS` directions, applied to all
    the waypoints before the last and, separately, to the first one only (the next leg alone),
    each clipped 0.05 m inside the tank. The unshifted list is not among them.

    Parameters
    ----------
    waypoints : list of (x, y)
        The waypoints the robot has left, the last one the goal's.
    size_m : (width, height)
        The tank.

    Returns
    -------
    list of list of (x, y)
    """
    if len(waypoints) < 2:
        return []
    w, h = size_m
    out = []
    for r in SHIFT_RADII_M:
        for k in range(SHIFT_DIRECTIONS):
            a = 2.0 * math.pi * k / SHIFT_DIRECTIONS
            dx, dy = r * math.cos(a), r * math.sin(a)
            moved = [(min(max(x + dx, 0.05), w - 0.05), min(max(y + dy, 0.05), h - 0.05))
                     for x, y in waypoints[:-1]]
            out.append(moved + [waypoints[-1]])
            if len(waypoints) > 2:
                out.append([moved[0], *waypoints[1:]])
    return out


def shift_repair(planner: Planner, state: FloatArray, step: int, guide: Guide,
                 waypoints: list[tuple[float, float]], horizon_s: float,
                 deadline_s: float | None = None) -> Outcome | None:
    """The present plan's route from where the robot is, its waypoints shifted if that is clearer.

    The twin swims the remaining ``waypoints`` and every :func:`shifted_waypoints` of them from
    ``state`` to the goal test, in the planner's water (the world's current plus the estimate)
    with the straight fit, in one batch. The variants whose planner's capsule keeps
    :data:`SHIFT_MARGIN_M` from everything on the way are ranked by its smallest gap there (the
    unshifted waypoints with :data:`SHIFT_PREFERENCE_M` added; then by the time to the goal);
    the best :data:`SHIFT_CHECKED` are checked in turn over the planner's own waters (the fits
    as fitted and the draws of its check, the straight sets; the fits and the first
    :data:`eelhost.planning.planner.SCREEN_DRAWS` draws first, as the planner's check): a
    variant passes when every run enters the goal disc with the capsule more than the planner's
    ``check_margin_m`` (the check's rule, :func:`eelhost.planning.planner.run_failed`) clear of
    everything.
    The first that passes is the plan (docs/planning.md, "The shift repair").

    Parameters
    ----------
    planner : Planner
        In the water of the replan (its twin's current holds the estimate).
    state : ndarray, shape (2 N + 4,)
        The replan's predicted start.
    step : int
        Its step of the task.
    guide : (x, y, I_x, I_y)
        The guidance state a new leg from ``state`` starts with.
    waypoints : list of (x, y)
        The present plan's waypoints the robot has left.
    horizon_s : float
        The longest swim to the goal.
    deadline_s : float, optional
        A ``time.monotonic()`` time: no batch is started after it.

    Returns
    -------
    Outcome or None
        ``found``, message starting ``shift repair:``, or None (no variant passed).
    """
    t0 = time.perf_counter()
    if not waypoints:
        return None
    variants = [list(waypoints), *shifted_waypoints(list(waypoints), planner.world.tank.size_m)]
    twin, world, model = planner.twin, planner.world, planner.model
    n = model.n_links
    state = np.asarray(state, dtype=float)
    stride = 3

    def judged(runs: Any, j: int) -> tuple[float, int] | None:
        """(capsule's smallest gap, samples to the goal) of run j, None if it never gets there."""
        states = runs.states[j]
        states = states[np.isfinite(states[:, 0])]
        inside = np.flatnonzero(goal_mask(world, states[:, n : n + 2]))
        if not inside.size:
            return None
        states = states[: int(inside[0]) + 1]
        return float(body_clearance_m(world, planner.clearance, model, states).min()), len(states)

    runs = twin.run(variants, horizon_s, states=np.repeat(state[None], len(variants), axis=0),
                    start_steps=[step] * len(variants), stride=stride,
                    guidance=[guide] * len(variants))
    scored = [(judged(runs, j), j) for j in range(len(variants))]
    base = scored[0][0]
    # the present waypoints as they are come first unless a shift is 10 mm clearer: a robot
    # that left its corridor may still be on a route that holds from where it is
    # a margin of its own in the estimated water, as the searches keep theirs in the fits': the
    # check's runs need only be clear (> 0), and repairs checked 1-2 mm clear steered a run of
    # seeds 11000-11099 within 2 mm of an obstacle
    # and every check run must keep the planner's check margin, as a searched plan's check runs
    # (planner.run_failed); the fits' own run is the first of them, so a variant is not checked
    # unless it keeps it here already
    check_margin = planner.check_margin_m
    ranked = sorted(((g, j) for g, j in scored
                     if g is not None and g[0] >= SHIFT_MARGIN_M and g[0] > check_margin),
                    key=lambda e: (-(e[0][0] + (SHIFT_PREFERENCE_M if e[1] == 0 else 0.0)),
                                   e[0][1]))
    if not ranked:
        return None
    waters = planner.check_waters(planner.waters(0))
    runner, currents = water_twin(twin, waters)
    screen = 1 + SCREEN_DRAWS
    for (gap, samples), j in ranked[:SHIFT_CHECKED]:
        worst: list[tuple[float, int] | None] = []
        for part in (range(0, min(screen, len(waters))), range(screen, len(waters))):
            if not part or not _time_left(deadline_s):
                break
            checks = runner.run([variants[j]] * len(part), horizon_s,
                                states=np.repeat(state[None], len(part), axis=0),
                                start_steps=[step] * len(part),
                                coefficient_index=[2 * i for i in part], stride=stride,
                                currents=[currents[i] for i in part],
                                guidance=[guide] * len(part))
            worst += [judged(checks, k) for k in range(len(part))]
            if any(g is None or g[0] <= check_margin for g in worst):
                break
        if len(worst) < len(waters) or any(g is None or g[0] <= check_margin for g in worst):
            if not _time_left(deadline_s):
                return None
            continue
        path = runs.states[j][: samples][:, n : n + 2].copy()
        end_step = step + (samples - 1) * stride
        legs = [Leg(wp, 0.0, 0.0, step, end_step, path if i == 0 else np.zeros((0, 2)), gap,
                    goal=i == len(variants[j]) - 1) for i, wp in enumerate(variants[j])]
        least = min(g[0] for g in worst if g is not None)
        msg = (f"shift repair: the present plan's {len(variants[j])} waypoints "
               + ("kept as they are" if j == 0 else "shifted") + ", "
               f"the capsule {gap * 1000:.0f} mm clear in the estimated water (unshifted "
               + ("never reaches the goal" if base is None else f"{base[0] * 1000:.0f} mm")
               + f"), at least {least * 1000:.0f} mm over the {len(waters)} waters of the check;"
               f" goal at {end_step * twin.dt_s:.1f} s")
        plan = Plan(True, "found", msg, legs, end_step * twin.dt_s, 0, len(variants),
                    time.perf_counter() - t0, start_guide=guide)
        return Outcome(plan, "found", msg, [], 0, time.perf_counter() - t0, 0.0,
                       len(waters) - 1, 1)
    return None


class Ahead(NamedTuple):
    """What a look-ahead of the present waypoints predicts (:meth:`TankReplanner._look_ahead`).

    Attributes
    ----------
    outline_m : float
        The body's own outline's smallest gap over ``lookahead_s`` (<= 0: contact).
    capsule_m : float
        The planner's capsule's smallest gap over the replan horizon, less the drift allowance
        of the current estimate's uncertainty at each moment (:func:`drift_allowance_m`; 0
        without a measured uncertainty): below the look-ahead's margin, a replan is asked for.
    contact_s : float
        The robot's time of the outline's first contact within ``lookahead_s`` (inf: none).
    near_s : float
        The robot's time at which that capsule first comes within the look-ahead's margin plus
        the allowance (inf: never within the horizon): the back-off yields to a replan when it
        comes before a replan asked for after the back-off could steer (docs/planning.md,
        "The back-off yields to a predicted contact").
    bare_m : float
        The capsule's smallest gap without the drift allowance over the early horizon (the
        replan horizon without an early margin; nan: not swum, the early margin then reads
        ``capsule_m``): under the early margin, an early replan is asked for
        (docs/planning.md, "An earlier replan").
    stop_now_m, stop_later_m : float
        Where the capsule comes within the margin: the smallest gap of the stop decided at the
        estimate (the pause's while restarts are left, else the final stop's), and of the stop
        decided after swimming the present plan on for as long as a retried replan needs, as
        the harbour judges a stop (:func:`eelhost.planning.harbour.stop_gap_m`); nan: not
        judged (docs/planning.md, "Stopped while the stop keeps clear").
    """

    outline_m: float
    capsule_m: float
    contact_s: float = math.inf
    near_s: float = math.inf
    bare_m: float = math.nan
    stop_now_m: float = math.nan
    stop_later_m: float = math.nan


def early_gap_m(judged: tuple[float, ...]) -> float:
    """The capsule's gap a look-ahead's verdict gives the early margin (:attr:`Ahead.bare_m`).

    A verdict without it (a bare pair, as the tests' fakes give) gives its capsule's gap.
    """
    if len(judged) > 4 and not math.isnan(judged[4]):
        return float(judged[4])
    return float(judged[1])


def near_time_s(judged: tuple[float, ...], t_s: float, margin_m: float) -> float:
    """When a look-ahead's verdict puts the capsule first within ``margin_m`` (plus allowance).

    A verdict without that time (a bare pair or triple, as the tests' fakes give) whose capsule
    is within the margin is taken as within it now.
    """
    if len(judged) > 3:
        return float(judged[3])
    return -math.inf if judged[1] < margin_m else math.inf


LOOKAHEAD_DRIFT_MAX_M = 0.02
"""The largest drift allowance added to the look-ahead's margin (:func:`drift_allowance_m`): 10 mm
plus this is 30 mm, what a searched plan's capsule keeps in its own water (the search's 50 mm
centre line less the body's half width), so a plan that holds in the estimate is not replanned
for the allowance alone."""


def current_spread_m_s(history: list[dict], windows: int = 3) -> float:
    """How far the current estimate may be from the water, from its last windows (m/s).

    The root mean square distance of the last ``windows`` windows' own samples of the current
    (``sample_m_s`` in :attr:`CurrentEstimator.history`) from the present estimate: 0 before any
    window (nothing measured), the remaining innovation after one, and the scatter of the
    water's samples around the estimate later (docs/planning.md, "The look-ahead's margin grows
    with the current's uncertainty").

    Parameters
    ----------
    history : list of dict
        :attr:`CurrentEstimator.history` (``current_m_s`` and ``sample_m_s`` of every window).
    windows : int

    Returns
    -------
    float
    """
    if not history:
        return 0.0
    now = np.asarray(history[-1]["current_m_s"], dtype=float)
    samples = np.array([h["sample_m_s"] for h in history[-windows:]], dtype=float)
    return float(np.sqrt(np.mean(np.sum((samples - now) ** 2, axis=1))))


def drift_allowance_m(spread_m_s: float, ahead_s: FloatArray) -> FloatArray:
    """The drift a current error of ``spread_m_s`` gives over ``ahead_s`` (m), capped.

    In a uniform current the body drifts with the water, so a current known to within ``e``
    puts the swum body up to ``e`` t from the twin's after ``t``; capped at
    :data:`LOOKAHEAD_DRIFT_MAX_M`.
    """
    return np.minimum(spread_m_s * np.asarray(ahead_s, dtype=float), LOOKAHEAD_DRIFT_MAX_M)


def contact_time_s(judged: tuple[float, ...], t_s: float) -> float:
    """When a look-ahead's verdict puts the first contact; -inf when it says contact, not when.

    A verdict without a time (a bare (outline, capsule) pair) that swims into contact is taken
    as contact now, so the stops that rest on it stay as they were.
    """
    if len(judged) > 2:
        return float(judged[2])
    return -math.inf if judged[0] <= 0.0 else math.inf


REFUSED_FROM_STATE = ("blocked_start", "current_too_strong", "unreachable")
"""Planner statuses that refuse the start state itself: no safe continuation from it, so the
robot is stopped unless the look-ahead swims its present plan clear (then it keeps that plan)."""


@dataclass
class Decision:
    """What the tank's replanner makes of one frame (the run loop acts on it).

    Attributes
    ----------
    waypoints : list of (x, y) or None
        Steer to these from now on (a replan that is ready and due).
    guide : (x, y, I_x, I_y) or None
        With ``waypoints``: the guidance state the new plan was searched from
        (``Plan.start_guide``), to steer them with.
    stop : str or None
        End the run now: ``contact`` (the estimated body touches an obstacle or wall) or
        ``no_safe_continuation`` (replanning cannot give the robot a safe plan).
    detail : str
        Why, in one line.
    arrived : bool
        The goal test holds.
    recorded : bool
        The plan record changed (the loop rewrites it into the take).
    pause : bool
        Stop the gait (amplitude 0, offset 0) but keep the run: the robot drifts to rest while
        a restart is planned (docs/planning.md, "A restart from rest").
    restart : bool
        With ``waypoints``: swim again (the gait's amplitude and beta back) and steer to them.
    pause_gait : Gait or None
        With ``pause``: the gait to pause with (its amplitude and beta; offset 0), e.g. the
        reversed wave of ``TankReplanner(rest_backing_rad=)``; None or an amplitude of 0 in
        effect: amplitude 0.
    """

    waypoints: list[tuple[float, float]] | None = None
    guide: Guide | None = None
    stop: str | None = None
    detail: str = ""
    arrived: bool = False
    recorded: bool = False
    pause: bool = False
    restart: bool = False
    pause_gait: Gait | None = None


@dataclass
class _Pause:
    """A stopped robot drifting towards rest while its restart is planned."""

    t_halt_s: float
    detail: str  # the stop it stands for
    drift: Future | None = None  # the twin's drift of the stopped body (the side worker)
    drift_wall_s: float = 0.0
    drift_gap_m: float | None = None  # the drift's smallest outline gap less the allowance
    budget_s: float = 0.0  # the rest replan's budget: as long as the drift stays clear
    job: _Job | None = None  # the rest replan
    outcome: Outcome | None = None  # its plan, once found
    extra: FloatArray | None = None  # the extra current it was searched in
    pending: tuple[float, list[tuple[float, float]], Guide | None] | None = None
    clear_s: float = 0.0  # from the stop until the drift comes within the margin (its horizon: never)
    tries: int = 0  # rest replans asked for in this pause
    t_next_s: float = -math.inf  # the robot's time the next rest replan may be asked for
    braked: Gait | None = None  # the brake's frozen gait, while the pause brakes first
    t_unbrake_s: float = -math.inf  # when the brake ends (the joints straighten)
    unbraked: bool = False  # the brake's end was sent
    halt_event: dict[str, Any] = field(default_factory=dict)  # its record (the take's events)


@dataclass
class _Hold:
    """The robot swimming its present plan on instead of a stop predicted worse (:meth:`TankReplanner._hold_on`)."""

    t_start_s: float  # the robot's time of its first frame
    next_check_s: float  # when the stop and the harbours are judged again
    stop_gap_m: float  # the stop at once's gap at the last check
    event: dict[str, Any]  # its record


@dataclass
class _Station:
    """The robot holding station: swimming into the current instead of a stop (:meth:`TankReplanner._station_on`)."""

    t_start_s: float  # the robot's time of its first frame
    next_check_s: float  # when the stop and the station swim are judged again
    kind: str  # the stop it puts off: ``pause``, ``stop`` or ``arrived``
    detail: str  # that stop's reason
    waypoint_m: tuple[float, float]  # the upstream waypoint steered to
    event: dict[str, Any]  # its record
    t_asked_s: float = -math.inf  # when the latest replan was asked for while holding station
    in_reach: bool = False  # instead of a stop while it keeps clear (:meth:`TankReplanner._stop_slips_away`)
    least_bad: bool = False  # the least-bad swim, not a station (:meth:`TankReplanner._least_bad_on`)


class _HarbourSwim(NamedTuple):
    """A harbour swim under way (:meth:`TankReplanner._take_harbour`)."""

    t_end_s: float  # the robot's time its stop is due
    kind: str  # the stop it precedes: ``arrived``, ``pause`` or ``stop``
    detail: str  # that stop's reason
    event: dict[str, Any]  # its record
    gait: Gait  # the gait it swims (a braked pause's resumes from its frozen phase)


@dataclass
class _Job:
    """A replan running beside the loop."""

    future: Future
    t_request_s: float
    wall_request_s: float
    t_start_s: float
    reason: str
    due_s: float = math.inf  # the robot's time by which its budget and the repair's grace end
    budget_s: float | None = None  # its budget (a calm replan's is longer)
    deadline: Deadline | None = None  # its deadline, which a more urgent replan may cut short
    cut_for: str | None = None  # the urgent replan's reason, once cut short
    t_cut_s: float | None = None  # the robot's time of the cut


class TankReplanner:
    """The tank's replanning beside the control loop (docs/planning.md, "Execution and replanning").

    The run loop calls :meth:`on_frame` with every frame and :meth:`pace` after it. Replans run on
    a worker thread and the other twin runs (look-aheads, the current's windows) on a second, so
    the loop keeps reading the camera and sending offsets at the control rate while the planner
    thinks (the robot swims its present leg on), and a replan never queues behind a look-ahead.

    Parameters
    ----------
    planner_for : callable
        ``planner_for(extra_current_m_s)``: the planner in the world with that current added to
        the world's (the current estimate); called on the worker thread, cached by the caller or
        here (a new planner only when the estimate moved by ``replan_current_step_m_s``).
    planner : Planner
        The planner that made the first plan (no extra current).
    outcome : Outcome
        The first plan.
    gait : Gait
        The gait the robot swims (the estimator's reference for unseen links).
    corridor_m : float
        Half width of the corridor around the planned centre-of-mass path.
    max_failures : int
        Consecutive failed replans after which the robot is stopped (no safe continuation); it
        is stopped at once when a replan fails while the latest look-ahead swims the present
        waypoints into contact, or when a look-ahead does so after a failed replan;
        unless the latest look-ahead swam its present waypoints clear of contact: it then keeps
        them, and replanning is tried again every ``backoff_s`` 2^(max_failures - 1). A replan
        refused from its start state (:data:`REFUSED_FROM_STATE`) counts as the last failure.
    backoff_s : float
        Wait after the first failed replan; it doubles with each further failure.
    lead_s : float
        First guess of the planner's wall time: a replan starts from the state predicted for this
        long after the request (then 1.5 times the last replan's wall time, at least this and at
        most ``max_lead_s``), rounded up to the next control update and frame.
    max_lead_s : float
        The longest lead: with the rounding up to a restart period (0.3 s), a replan's plan
        steers at most ``max_lead_s`` plus a period after the estimate it starts from, when it
        is ready by then (issue 28's target: within 1 s of the request). A plan that comes back
        later is switched in when it comes, unless it is stale (:meth:`_stale`).
    contact_frames : int
        Consecutive frames whose estimated body touches something before the run is stopped.
    estimate_current : bool
        Estimate the current from the camera track against the twin and replan in it.
    lookahead_s : float
        Every ``lookahead_every_s`` the twin swims the robot on from its estimated state along
        its present waypoints, in the estimated current, for ``replan_horizon_s``; a body that
        comes within ``lookahead_margin_m`` of an obstacle or wall there is replanned
        (``predicted_contact``) even inside the corridor. The body's outline over the first
        ``lookahead_s`` of that run judges the stops and whether the present plan may be kept.
        0 turns the look-ahead off.
    lookahead_every_s, lookahead_margin_m : float
    goal_planner_for : callable, optional
        ``goal_planner_for(extra_current_m_s)``: a planner like ``planner_for``'s whose search
        keeps a smaller margin (the goal approach); a replan that finds no plan from a start
        within ``goal_approach_m`` of the goal disc's edge, or whose search ran out of poses
        (``exhausted``) anywhere, is tried again with it.
    goal_approach_m : float
    blocked_retries : int
        A replan whose predicted start is refused as blocked (the body within its half width of
        an obstacle) is tried again from the states the twin predicts one, two, ... restart
        periods later along the present waypoints, this many times.
    replan_horizon_s : float
        The look-ahead swims this long (at least ``lookahead_s``): a capsule within
        ``lookahead_margin_m`` of anything anywhere in it asks for a replan, while only the
        first ``lookahead_s`` of it judge stops and keeping the present plan. A replan asked for
        only when contact is under 3 s away started from a body that no manoeuvre could turn
        away in time (docs/planning.md, "Replanning before contact").
    recovery_planner_for : callable, optional
        ``recovery_planner_for(extra_current_m_s)``: the recovery's planner (docs/planning.md,
        "The recovery replan"): a richer action set (sharper turns) with the goal approach's
        margin and a bounded number of expansions. A replan that found no plan with the
        planner and the goal approach is tried once more with it, from the same start.
    replan_current_change_m_s : float
        When the current estimate has moved this far from the current the present plan was
        searched in, the twin swims the rest of the present plan in the estimate; when it comes
        out of the look-ahead's margin anywhere, the robot is replanned in the estimate
        (``current_estimate``) before the water it did not know pushes it off its plan. A
        failure of such a replan keeps the present plan and is not counted (0 turns it off;
        docs/planning.md, "Replanning in the estimated current").
    replan_budget_s : float or None
        Wall-clock budget of a replan from its request: the prediction of its start, the
        searches (the planner's and its repairs', then the goal approach's and the recovery's,
        each only within what is left) stop at it and the replan returns what it has (a plan,
        or none: ``out_of_time``), so that the robot steers a new plan within about this long
        of leaving its corridor (issue 28's 1 s; docs/planning.md, "The replan's deadline");
        the check stops at it too ("The planning call's deadline"). None (the default here): no deadline;
        ``eelbot run --plan`` and the closed-loop benchmark give :data:`REPLAN_BUDGET_S`
        (:func:`eelhost.planning.tank.plan_for_run`).
    shift_repair : bool
        When every search of a replan found nothing from its start (not refused), try the
        present plan's remaining waypoints shifted by 5-15 cm (:func:`shift_repair`): the
        variant the twin swims clearest in the estimated water, when it passes a check over the
        planner's waters, is the plan (docs/planning.md, "The shift repair").
    retry_before_contact : bool
        With a ``replan_budget_s``: when a replan has failed and the look-ahead swims the present
        waypoints into contact, replan again at once instead of stopping the robot while the
        contact is far enough ahead for another replan to steer before it
        (:meth:`_retry_need_s`); a replan in flight past its start is likewise waited for while
        it can still come back in time (docs/planning.md, "Retried before contact").
    stop_allowance_s : float
        The time kept beyond that for a stop, should the replan fail
        (:data:`STOP_ALLOWANCE_S`; 0: none, as before session 17).
    harbour : bool
        Before a stop whose drift the twin predicts within the look-ahead's margin (at the goal,
        or where no safe continuation exists, a pause or the final stop), swim to where the
        stop stays clear first: the nearest of the twin's harbour swims
        (:func:`eelhost.planning.harbour.find_harbour`) whose swim and stop keep the margin
        plus :data:`~eelhost.planning.harbour.HARBOUR_CUSHION_M`, and stop at its end
        (docs/planning.md, "The harbour"). On by default.
    hold_plan : bool
        Where no safe continuation exists and the stop would drift within the margin with no
        harbour found, keep swimming the present plan while the twin swims it clear where the
        stop touches, replanning and judging the stop and the harbours again until one is safe
        (:meth:`_hold_on`; docs/planning.md, "The hold"). On by default.
    station_keeping : bool
        Where the stop decided (``no_safe_continuation``: the pause or the final stop, before
        the hold; or the arrival's) would drift within the margin with no harbour found, swim
        into the current instead when the twin swims that clear over
        :data:`~eelhost.planning.station.STATION_HORIZON_S` (:meth:`_station_on`), replanning
        every :data:`STATION_RETRY_S` and judging the stop and the swim again every
        :data:`~eelhost.planning.station.STATION_CHECK_S`, until a plan, a stop the twin swims
        clear, no station swim, or :data:`~eelhost.planning.station.STATION_MAX_S`
        (docs/planning.md, "Holding station (session 21)"). Off by default: on development
        seeds 39000-39099 no stop that drifted in had a station swim either. Also where
        ``stop_in_reach`` would stop while the stop keeps clear: a station swim kept clear is
        held instead, replanning, until no swim keeps clear (then that stop), its time bound
        or a plan (held once on 39000-39049, no goal won).
    least_bad : bool
        Where the stop decided (``no_safe_continuation``: the pause or the final stop, after the
        harbour, the station and the hold; at a harbour's end; the final stop after a failed
        pause once its brake is over) would drift within the margin, swim the station candidate
        the twin keeps :data:`~eelhost.planning.station.LEAST_BAD_GAIN_M` clear over
        :data:`~eelhost.planning.station.LEAST_BAD_HORIZON_S` whose stops along it are
        clearest, when one of those beats the stop now by
        :data:`~eelhost.planning.station.LEAST_BAD_STEP_M`, instead of the stop
        (:meth:`_least_bad_on`): judged again every
        :data:`~eelhost.planning.station.STATION_CHECK_S` from the estimate, replanning as the
        station does, until a plan, a stop the twin swims clear (made then), no swim beating the
        stop, or :data:`~eelhost.planning.station.LEAST_BAD_MAX_S` (docs/planning.md, "The
        least-bad swim (session 24)"). On by default: on development seeds 45250-45299 it
        turned 45278's stop contact into a goal, and replayed, unseen 40082's stop contact into
        a clear stop three times of three, adding no contact while swimming.
    stop_in_reach : bool
        After a failed replan, where the look-ahead swims the present plan within the margin
        and the stop the twin swims clear now would come within it after the time another
        replan needs, stop now (docs/planning.md, "Stopped while the stop keeps clear"). On
        by default.
    stop_brake_s : float
        The run loop's brake before its final Stop (:data:`STOP_BRAKE_S`), as the harbour swims
        a final stop.
    calm_budget_s : float or None
        With a ``replan_budget_s``: the budget of a replan asked for in a moved current estimate
        (``current_estimate``, the look-ahead clear), when longer; it starts from the state
        predicted that long ahead (docs/planning.md, "Calm replans get more time";
        :data:`CALM_REPLAN_BUDGET_S`, which ``eelbot run`` passes). A replan on leaving the
        corridor or a predicted contact cuts a calm one short (its :class:`Deadline` brought
        forward: the worker stops at its next batch) and is asked for as soon as the worker is
        back. None (the default here): every replan gets ``replan_budget_s``.
    early_margin_m : float or None
        A look-ahead whose capsule's bare gap (no drift allowance) comes under this margin
        (more than ``lookahead_margin_m``) within ``early_horizon_s``, the capsule not within
        ``lookahead_margin_m`` over ``replan_horizon_s``, asks for an early replan
        (``early_margin``) with the replan budget and the short lead, when no replan runs and
        no failed replan's back-off is on. It finds a plan: switched in as
        any. It finds none: the robot keeps its present plan and no failure is counted. Either
        way the next early replan waits :data:`EARLY_BACKOFF_S` (doubled after each further one
        until a look-ahead swims the plan clear of the early margin). It tries the planner alone
        (no goal approach, recovery or shift repair, whose margins are the look-ahead's). A
        replan on leaving the corridor or a predicted contact cuts it short as a calm one, and
        an early need cuts a calm replan short (docs/planning.md, "An earlier replan";
        :data:`EARLY_MARGIN_M`, the value developed; ``eelbot run --early-margin``). None (the
        default, here and in ``eelbot run``): off.
    early_horizon_s : float
        With an ``early_margin_m``: the look-ahead swims this long (at least
        ``replan_horizon_s``), and the capsule's gap over the whole of it, without the drift
        allowance, is judged against the early margin (:data:`EARLY_HORIZON_S`).
    early_budget_s : float or None
        With a ``replan_budget_s``: an early replan's budget, when longer; it then starts from
        the state predicted that long ahead, as a calm replan (:data:`EARLY_BUDGET_S`, which
        ``eelbot run`` passes). None (the default here): the replan budget and the short lead.
    escape_planner_for : callable, optional
        The escape's planner (docs/planning.md, "An escape from inside the margin").
    max_restarts : int
        Where the robot would be stopped for ``no_safe_continuation``, it is instead paused (its
        gait's amplitude 0: it drifts towards rest, its joints straight) this many times per
        run: the twin swims the stopped body's drift, which must stay clear by
        ``lookahead_margin_m`` (less the current's drift allowance), ``rest_settle_s`` later a
        replan is searched from the stopped body predicted for the end of its budget
        (``rest_budget_s``), and the robot swims that plan from then; when the drift or the
        replan fails, the run ends with ``no_safe_continuation`` as without it. Each pause and
        restart is an event of the record (``kind`` ``halt`` and ``restart``; docs/planning.md,
        "A restart from rest"). 0 (the default here): off.
    rest_settle_s, rest_budget_s, rest_budget_max_s : float
        The pause before the rest replan is asked for, and its budget: the longest up to
        ``rest_budget_max_s`` whose restart the drift keeps clear (at least ``rest_budget_s``).
    rest_escape_planner_for : callable, optional
        The escape's planner for the rest replans only (without ``escape_planner_for``): a
        coasting body inside the check's margin plans its escape from there.
    rest_tries : int
        Rest replans a pause may ask for (:data:`eelhost.planning.restart.REST_TRIES`, 1): after
        a failed one, another ``rest_retry_s`` later from the body then, while the stop's drift
        stays clear for its least budget (docs/planning.md, "A restart from rest"). A rest
        replan not back :attr:`max_lead_s` after the state it starts from ends the pause.
    rest_retry_s : float
    rest_backing_rad : float or None
        Pause with the travelling wave reversed at this amplitude (offset 0), which brakes the
        coasting body or backs it out, instead of amplitude 0
        (:func:`eelhost.planning.restart.backing_gait`); the drift and the rest replan's start
        are swum with it. None (the default): amplitude 0. Developed, not on by default: on
        development seed 27215 a pause at 0.87 rad ended in a contact.
    rest_brake_s : float or None
        The pause first brakes (:func:`eelsim.control.braked_gait`: the body frozen in a deep S,
        omega 0) for at least this long, until a whole gait period
        (:func:`eelhost.planning.restart.unbrake_time`), and then straightens (amplitude 0);
        the drift and the rest replan's start are swum so (docs/planning.md, "The brake in the
        pause"). None: amplitude 0 at once. Ignored with ``rest_backing_rad``.
    """

    def __init__(
        self,
        planner_for: Callable[[FloatArray], Planner],
        planner: Planner,
        outcome: Outcome,
        gait: Gait,
        corridor_m: float = 0.10,
        max_failures: int = 3,
        backoff_s: float = 1.0,
        lead_s: float = 0.3,
        max_lead_s: float = 0.6,
        contact_frames: int = 2,
        estimate_current: bool = True,
        lookahead_s: float = 3.0,
        lookahead_every_s: float = 0.6,
        lookahead_margin_m: float = 0.01,
        goal_planner_for: Callable[[FloatArray], Planner] | None = None,
        goal_approach_m: float = 0.5,
        blocked_retries: int = 3,
        replan_horizon_s: float = 5.0,
        recovery_planner_for: Callable[[FloatArray], Planner] | None = None,
        replan_current_change_m_s: float = 0.005,
        replan_budget_s: float | None = None,
        shift_repair: bool = True,
        retry_before_contact: bool = True,
        stop_allowance_s: float = STOP_ALLOWANCE_S,
        harbour: bool = True,
        hold_plan: bool = True,
        station_keeping: bool = False,
        least_bad: bool = True,
        stop_in_reach: bool = True,
        stop_brake_s: float = STOP_BRAKE_S,
        calm_budget_s: float | None = None,
        early_margin_m: float | None = None,
        early_horizon_s: float = EARLY_HORIZON_S,
        early_budget_s: float | None = None,
        escape_planner_for: Callable[[FloatArray], Planner] | None = None,
        max_restarts: int = 0,
        rest_settle_s: float = REST_SETTLE_S,
        rest_budget_s: float = REST_BUDGET_S,
        rest_budget_max_s: float = REST_BUDGET_MAX_S,
        rest_escape_planner_for: Callable[[FloatArray], Planner] | None = None,
        rest_tries: int = REST_TRIES,
        rest_retry_s: float = REST_RETRY_S,
        rest_backing_rad: float | None = None,
        rest_brake_s: float | None = BRAKE_HOLD_S,
    ) -> None:
        self.gait = gait
        # the rest replans' escape: the swimming one's when there is one
        self.rest_escape_planner_for = escape_planner_for or rest_escape_planner_for
        self.max_restarts = max(int(max_restarts), 0)
        self.rest_settle_s = rest_settle_s
        self.rest_budget_s = rest_budget_s
        self.rest_budget_max_s = rest_budget_max_s
        self.rest_tries = max(int(rest_tries), 1)
        self.rest_retry_s = rest_retry_s
        self.rest_backing_rad = rest_backing_rad
        self.rest_brake_s = None if rest_backing_rad is not None else rest_brake_s
        self.restarts = 0  # restarts from rest made (docs/planning.md, "A restart from rest")
        self._pause: _Pause | None = None
        self.planner_for = planner_for
        self.planner = planner
        self.outcome = outcome
        self.world = planner.world
        self.model = planner.model
        self.corridor_m = corridor_m
        self.max_failures = max_failures
        self.backoff_s = backoff_s
        self.lead_s = lead_s
        self.max_lead_s = max(max_lead_s, lead_s)
        self.contact_frames = contact_frames
        self.estimate_current = estimate_current
        self.lookahead_s = lookahead_s
        self.lookahead_every_s = lookahead_every_s
        self.lookahead_margin_m = lookahead_margin_m
        self.goal_planner_for = goal_planner_for
        self.goal_approach_m = goal_approach_m
        self.blocked_retries = blocked_retries
        self.replan_horizon_s = max(replan_horizon_s, lookahead_s)
        self.recovery_planner_for = recovery_planner_for
        self.escape_planner_for = escape_planner_for
        self.replan_current_change_m_s = replan_current_change_m_s
        self.replan_budget_s = replan_budget_s
        self.calm_budget_s = calm_budget_s
        self.early_margin_m = (early_margin_m if early_margin_m is not None
                               and early_margin_m > lookahead_margin_m else None)
        self.early_horizon_s = early_horizon_s
        self.early_budget_s = early_budget_s
        self._next_early_s = -math.inf  # the robot's time the next early replan may be asked
        self._early_in_row = 0  # early replans since the plan was last swum clear of its margin
        self.shift_repair = shift_repair
        self.retry_before_contact = retry_before_contact
        self.stop_allowance_s = stop_allowance_s
        self.harbour = harbour
        self.stop_brake_s = stop_brake_s
        self._harbour: _HarbourSwim | None = None  # the harbour swum now
        self._harbours_swum = 0  # since the last plan: at HARBOURS_PER_PLAN the next stop stands
        self.hold_plan = hold_plan
        self.station_keeping = station_keeping
        self.least_bad = least_bad
        self._station: _Station | None = None  # the station held now
        self._stationed_s = 0.0  # the present plan's stations' time so far (STATION_MAX_S)
        self.stop_in_reach = stop_in_reach
        self._hold: _Hold | None = None  # the hold on the present plan, while it lasts
        self._held_s = 0.0  # the present plan's holds' time so far (HOLD_MAX_S bounds it)
        self._stop_judged: tuple[float, float] = (-math.inf, math.nan)  # (t, the stop's gap)
        # the latest look-ahead's stops: (its estimate's time, the stop then, after a retry)
        self._stops: tuple[float, float, float] = (-math.inf, math.nan, math.nan)
        self._in_reach: dict[str, Any] | None = None  # this frame's stop_in_reach event, if any
        self.retries_before_contact = 0  # replans asked for instead of a stop (the record's)
        # the robot's time of the first contact the latest look-ahead predicts (inf: none)
        self._contact_at_s = math.inf
        # the robot's time the latest look-ahead puts the capsule within the margin (inf: never)
        self._near_at_s = math.inf
        self.backoff_yields = 0  # replans asked for during a back-off (the record's)
        self._retry_now = False  # a failed replan asked for another at the next frame
        self._urgent_after_cut: str | None = None  # asked for once the cut calm replan is back
        self._last_tiers: dict[str, float] = {}  # the last replan's parts' wall times
        self._plan_current = np.zeros(2)  # the extra current the present plan was searched in
        # the rest of the present plan swum in a moved estimate: (future, that estimate)
        self._whole_job: tuple[Future, FloatArray] | None = None
        # the goal approach's and the recovery's planners, each with the extra current it has
        self._extra_planners: dict[str, tuple[Planner, FloatArray]] = {}
        self.half_width_m = float(self.model.half_axis_horizontal_m.max())
        self.estimator = BodyStateEstimator(self.model, gait)
        self.current = CurrentEstimator()
        self.waypoints = list(outcome.plan.waypoints_m)
        self.path = corridor_path(outcome.plan)
        self.replans = 0
        self.failures = 0
        self.events: list[dict[str, Any]] = [self._event(
            "plan", "start", 0.0, 0.0, 0.0, None, outcome, outcome.planning_time_s, math.nan,
            np.zeros(2))]
        self._job: _Job | None = None
        # (t_start, waypoints, the guidance state they were searched from)
        self._pending: tuple[float, list[tuple[float, float]], Guide | None] | None = None
        self._guide: Guide | None = None  # the run loop's guidance state at the latest frame
        self._next_try_s = -math.inf
        self._touching = 0
        # the current's windows being swum by the twin on the side worker, oldest first
        self._window_jobs: list[tuple[Future, CurrentWindow]] = []
        self._planner_current = np.zeros(2)
        self._prebuild: Future | None = None  # the planner in a moved estimate, being built
        # (planner, its extra current) swapped as one, read by the side worker
        self._planned: tuple[Planner, FloatArray] = (planner, np.zeros(2))
        self._last_wall_s = 0.0
        self._lookahead: Future | None = None
        self._lookahead_from_s = -math.inf  # the estimate's time the running look-ahead swims from
        # (the time of the estimate it swam from, the outline's smallest gap) of the newest verdict
        self._last_gap: tuple[float, float | None] = (-math.inf, None)
        self._next_lookahead_s = 0.0
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="eelbot-planner")
        # look-aheads and the current's windows on their own thread, so a replan never queues
        # behind them (the twin's kernel releases the interpreter: both run at once)
        self._side = ThreadPoolExecutor(max_workers=1, thread_name_prefix="eelbot-lookahead")
        if (goal_planner_for is not None or recovery_planner_for is not None
                or escape_planner_for is not None):
            # the fallback tiers' planners built while the robot starts swimming
            self._prebuild = self._worker.submit(self._prepare_planner, np.zeros(2))

    # -- the loop's calls ----------------------------------------------------------------------

    def on_telemetry(self, t_received_s: float, msg: protocol.Telemetry,
                     t_polled_before_s: float | None = None) -> None:
        """Take one Telemetry: the robot's joint angles and gait phase for the state estimate.

        Parameters
        ----------
        t_received_s : float
            The poll that read it, since the gait started.
        msg : protocol.Telemetry
        t_polled_before_s : float, optional
            The poll before (it arrived after that).
        """
        self.estimator.add_telemetry(t_received_s, msg, t_polled_before_s)

    def on_frame(self, t_s: float, loc: Localisation, pose: FloatArray | None, target: int,
                 offset_rad: float, guide: Guide | None = None) -> Decision:
        """Take one frame: estimate, check contact and goal, start, collect or switch replans.

        A stop for ``no_safe_continuation`` becomes a pause while restarts are left
        (:attr:`max_restarts`): the robot stops swimming and drifts, and a restart is planned
        from rest (:meth:`_paused_frame`; docs/planning.md, "A restart from rest").

        Parameters
        ----------
        t_s : float
            Frame time since the gait started.
        loc : Localisation
            The frame's localisation (link angles and centre of mass when found).
        pose : ndarray (3,) or None
            The guidance's filtered pose.
        target : int
            Index of the waypoint being steered to in the waypoints last handed over.
        offset_rad : float
            The offset the robot steers with.
        guide : (x, y, I_x, I_y), optional
            The run loop's guidance state (:meth:`eelsim.guidance.Guidance.state`): the twin's
            runs from this frame's estimate start with it (none: a leg from the estimate's
            centre of mass, no integral).

        Returns
        -------
        Decision
        """
        ended = self._observe(t_s, loc, pose, offset_rad)
        if self._harbour is not None:
            # the harbour's stop was judged with its swim: the goal waits for its end
            return ended if ended is not None and ended.stop is not None else (
                self._harbour_frame(t_s))
        if self._station is not None and self._station.kind == "arrived":
            # arrived, and holding station until the stop keeps clear: only contact ends it
            if ended is not None and ended.stop is not None:
                self._end_station(t_s, ended.stop)
                return ended
            return self._station_frame(t_s, guide)
        if ended is not None:
            self._end_hold(t_s, ended.stop or "arrived")
            self._end_station(t_s, ended.stop or "arrived")
            if ended.arrived and self._pause is None:
                return (self._stop_safely(t_s, "arrived", "arrived in the goal disc")
                        or self._station_on(t_s, "arrived", "arrived in the goal disc") or ended)
            return ended
        if self._pause is not None:
            return self._paused_frame(t_s, loc, pose, offset_rad)
        if self._station is not None:
            return self._station_frame(t_s, guide)
        self._in_reach = None
        d = self._swimming_frame(t_s, loc, pose, target, offset_rad, guide)
        if d.stop == "no_safe_continuation":
            pausing = self.restarts < self.max_restarts
            kind = "pause" if pausing else "stop"
            if self._held(t_s):
                return Decision()  # the hold goes on until its next check
            harbour = self._stop_safely(t_s, kind, d.detail)
            if harbour is not None:
                self._end_hold(t_s, "harbour")
                return harbour
            # a swim the twin keeps clear by the margin over the station's horizon before a
            # plan swum clear of contact over the look-ahead's (docs/planning.md, "Holding
            # station (session 21)")
            stationed = self._station_on(t_s, kind, d.detail)
            if stationed is None and self._in_reach is not None:
                # the stop keeps clear now and not after a retry: a station swim kept clear
                # keeps replanning instead (docs/planning.md, "Holding station (session 21)")
                stationed = self._station_on(t_s, kind, d.detail, in_reach=self._in_reach)
            if stationed is not None:
                self._end_hold(t_s, "station")
                return stationed
            held = self._hold_on(t_s, kind, d.detail)
            if held is not None:
                return held
            # no harbour, station or hold: a short swim towards a better stop, judged again each
            # check (docs/planning.md, "The least-bad swim (session 24)")
            least = self._least_bad_on(t_s, kind, d.detail)
            if least is not None:
                self._end_hold(t_s, "least_bad")
                return least
            self._end_hold(t_s, "stopped")
            if pausing:
                return self._halt(t_s, d)
        elif self._hold is not None and (d.waypoints is not None or self._present_plan_clear(t_s)):
            self._end_hold(t_s, "replanned" if d.waypoints is not None else "clear")
        if d.waypoints is not None:
            self._held_s = 0.0  # a new plan: it may hold as long again
            self._stationed_s = 0.0  # and hold station
        return d

    def _observe(self, t_s: float, loc: Localisation, pose: FloatArray | None,
                 offset_rad: float) -> Decision | None:
        """Feed the frame's body to the estimate; the decision when it ends the run, else None.

        Swimming or paused alike: a contact of the estimated body stops the run ("An honest
        outcome"), and the filtered pose in the goal disc arrives.
        """
        if loc.found and loc.com_m is not None:
            self.estimator.observe(t_s, loc.com_m, loc.link_angles_rad, offset_rad)
            stop = self._contact(t_s)
            if stop is not None:
                d = Decision()
                d.stop, d.detail = "contact", stop
                return d
        if pose is not None and in_goal(self.world, pose[:2]):
            d = Decision()
            d.arrived = True
            return d
        return None

    def _swimming_frame(self, t_s: float, loc: Localisation, pose: FloatArray | None,
                        target: int, offset_rad: float, guide: Guide | None = None) -> Decision:
        """Take one frame while the robot swims (:meth:`on_frame`, whose parameters these are)."""
        d = Decision()
        self._guide = guide
        d.recorded |= self._collect(t_s, d)
        if d.stop is not None:
            return d
        if self._switch_in(t_s, d):
            return d
        est = self.estimator.estimate()
        if est is None or pose is None:
            return d
        left = self.waypoints[min(target, len(self.waypoints) - 1):]
        d.recorded |= self._estimate_current(est, left, pose)
        busy = self._job is not None or self._pending is not None
        # an early replan in flight is cut short by any urgent need: the rules after a failure
        # (retry or stop) then act as if it did not run (docs/planning.md, "An earlier replan")
        early_job = self._job is not None and self._job.reason == "early_margin"
        idle = self._job is None or early_job
        predicted = False
        capsule = None
        judged: tuple[float, ...] | None = None
        if self._lookahead is not None and self._lookahead.done():
            judged = self._lookahead.result()
            self._lookahead = None
            self._adopt(judged, self._lookahead_from_s, t_s)
            capsule = None if judged is None else judged[1]
            # a new plan is asked for with the planner's capsule (the safer trigger); the robot is
            # stopped, or keeps its plan, on its own outline
            predicted = capsule is not None and capsule < self.lookahead_margin_m
        # within the early margin, clear of the look-ahead's own: the plan has lost the margin a
        # new search would keep, and the body still has room to turn (docs/planning.md, "An
        # earlier replan")
        early = (judged is not None and not predicted and self.early_margin_m is not None
                 and early_gap_m(judged) < self.early_margin_m)
        if judged is not None and not early and not predicted:
            self._early_in_row = 0  # clear of the early margin: the next early need is new
        if predicted and self.failures > 0 and self._stop_slips_away(t_s, d):
            return d
        gap = self._last_gap[1]
        retry = yielded = False
        # the outline within the margin counts as contact for the stops: the twin's outline
        # was 8 mm clear where the body touched 0.6 s later (seed 18036, docs/planning.md,
        # "The outline's margin")
        close = gap is not None and gap < self.lookahead_margin_m
        if (predicted and self.failures > 0 and close
                and idle and self._pending is None
                and self._may_retry(t_s)):
            # the present plan swims into something and the last replan found nothing better,
            # but the contact is far enough ahead for one more replan to steer before it: ask
            # for it now, whatever the back-off (docs/planning.md, "Retried before contact")
            retry = True
            log.info("contact predicted at t = %.2f s after a failed replan: replanning again "
                     "at t = %.2f s instead of stopping", self._danger_at_s(), t_s)
        elif (predicted and self.failures > 0 and close
                and idle and self._pending is None):
            # the present plan swims into something and the last replan found nothing better
            d.stop = "no_safe_continuation"
            d.detail = (f"at t = {t_s:.2f} s the twin swims the present plan "
                        f"{self._verdict_text(t_s)} and "
                        f"the last replan failed: {self._last_replan()['message']}")
            return d
        elif (predicted and self._backoff_yields(t_s, busy)
              and (self.failures < self.max_failures or not self._present_plan_safe(t_s))):
            # the back-off would let the capsule come within the margin before a replan asked
            # for after it could steer (docs/planning.md, "The back-off yields to a predicted
            # contact"): replan now while failures are left, else stop deliberately unless the
            # outline swims the present plan clear by the margin (kept, as after a last failure)
            if self.failures < self.max_failures:
                retry = yielded = True
                self.backoff_yields += 1
                log.info("the back-off yields at t = %.2f s: the capsule comes within the margin "
                         "at t = %.2f s, before a replan after the back-off (%.2f s) could "
                         "steer", t_s, self._near_at_s, self._next_try_s)
            else:
                d.stop = "no_safe_continuation"
                d.detail = (
                    f"at t = {t_s:.2f} s the twin swims the present plan's capsule within "
                    f"{self.lookahead_margin_m * 1000:.0f} mm of an obstacle or wall (with the "
                    f"current estimate's drift allowance) at t = {self._near_at_s:.2f} s, "
                    f"before a replan after the back-off could steer, and {self.failures} "
                    f"replans failed in a row: {self._last_replan()['message']}")
                return d
        job = self._job
        if job is not None and self._cuttable(job) and job.cut_for is None and (
                predicted or self._off_corridor(pose)):
            # a calm (or early) replan runs, and now a more urgent one is needed: cut it short
            # (the worker stops at its next batch) and ask for the urgent one when it is back
            # (docs/planning.md, "Calm replans get more time", "An earlier replan")
            self._cut(job, "predicted_contact" if predicted else "left_corridor", t_s)
        elif (job is not None and self._calm(job) and job.cut_for is None and early
              and self._early_allowed(t_s)):
            # a calm replan starts its budget (3 s) ahead: too late for a plan the look-ahead
            # already swims within the early margin; the early replan starts a lead ahead
            self._cut(job, "early_margin", t_s)
        if (predicted and close and job is not None
                and (self._early_held_up(job) if early_job
                     else t_s > job.t_start_s + 1e-9 or self._calm_holds_up(job, t_s))
                and not (t_s <= job.due_s
                         and self._danger_at_s() - max(job.due_s, t_s)
                         >= self.lead_s + self.stop_allowance_s)):
            # the replan is late (past its start) and the twin swims the present plan into
            # contact meanwhile: on a loaded machine replans took minutes of wall time, and the
            # robot swam on into an obstacle before they came back (it is waited for only while
            # within its budget and its plan could still steer a lead before the contact)
            d.stop = "no_safe_continuation"
            d.detail = (f"at t = {t_s:.2f} s the twin swims the present plan "
                        f"{self._verdict_text(t_s)} and the replan requested at "
                        f"t = {job.t_request_s:.2f} s has not come back "
                        f"({time.monotonic() - job.wall_request_s:.1f} s of wall time)")
            return d
        reason = None
        if self._off_corridor(pose):
            reason = "left_corridor"
        elif predicted:
            reason = "predicted_contact"
            log.info("the twin predicts the body's capsule within %.0f mm (less the drift "
                     "allowance) of an obstacle or wall within %.1f s", capsule * 1000,  # type: ignore[operator]
                     self.replan_horizon_s)
        elif self._retry_now:
            reason = "predicted_contact"  # a failed replan's look-ahead swam into contact
        elif self._urgent_after_cut is not None:
            reason = self._urgent_after_cut  # what cut the calm replan short
        elif early and self._early_allowed(t_s):
            reason = "early_margin"
            log.info("the twin predicts the body's capsule %.0f mm from an obstacle or wall "
                     "within %.1f s (under the early margin): an early replan",
                     early_gap_m(judged) * 1000, self.replan_horizon_s)  # type: ignore[arg-type]
        elif self._whole_plan_fails(est, left, busy):
            # the water the plan was searched in is not the one the camera sees, and the twin
            # swims the rest of the plan out of its margin in the estimate: replan in it while
            # the robot is still on its plan (docs/planning.md)
            reason = "current_estimate"
        if reason is not None and not busy and (t_s >= self._next_try_s or retry
                                                 or self._urgent_after_cut is not None):
            if (retry and not yielded) or self._retry_now:
                self.retries_before_contact += 1
            self._retry_now = False
            self._urgent_after_cut = None
            self._request(t_s, est, left, reason)
        elif (self._pending is None and self._lookahead is None and self.lookahead_s > 0
              and t_s >= self._next_lookahead_s):
            # also while a replan runs (on its own worker): a failure is then judged on it
            self._next_lookahead_s = t_s + self.lookahead_every_s
            self._lookahead_from_s = est.t_s
            self._lookahead = self._side.submit(self._look_ahead, est, list(left),
                                                  self.current.value_m_s.copy(), self._guide)
        return d

    def pace(self, t_s: float) -> None:
        """Keep the robot's clock from running ahead of the planner's wall time.

        While a replan runs, the robot's time since the request may not exceed the wall time
        since it: at the tank both are the same clock and this never waits; over ``sim://`` the
        virtual robot then runs in real time while the planner thinks, so the planner's wall time
        passes on the robot's clock (docs/planning.md).
        """
        pause = self._pause
        jobs = [self._job] if pause is None else [pause.job]
        for job in jobs:
            if job is None:
                continue
            lead = (t_s - job.t_request_s) - (time.monotonic() - job.wall_request_s)
            if lead > 0.0 and not job.future.done():
                wait([job.future], timeout=lead)  # wakes early when the plan is done
        if pause is not None and pause.drift is not None and not pause.drift.done():
            lead = (t_s - pause.t_halt_s) - (time.monotonic() - pause.drift_wall_s)
            if lead > 0.0:
                wait([pause.drift], timeout=lead)

    def close(self) -> None:
        """Stop the worker (a replan in progress is left to finish on its own thread)."""
        self._worker.shutdown(wait=False, cancel_futures=True)
        self._side.shutdown(wait=False, cancel_futures=True)

    def record(self) -> dict[str, Any]:
        """What the take keeps of the planning: plans, replans, the current and state estimates.

        ``state_estimate``: frames by the joint angles' source (telemetry, reference, camera) and
        the Telemetry taken and ignored (docs/planning.md, "The robot's state at the tank").
        """
        return {"plans": self.events, "replans": self.replans,
                "restarts": self.restarts, "max_restarts": self.max_restarts,
                "retries_before_contact": self.retries_before_contact,
                "backoff_yields": self.backoff_yields,
                "replan_budget_s": self.replan_budget_s,
                "early_margin_m": self.early_margin_m,
                "current_estimate": self.current.history,
                "state_estimate": self.estimator.summary()}

    def tally(self) -> str:
        """The take's planning in one line: replans switched in and failed, pauses, harbours, holds.

        A run that printed only the replans switched in said "0" after failed replans, a pause
        and a harbour swim; the user reads here what the replanner did.
        """
        replans = [e for e in self.events if e["kind"] == "replan"]
        failed = Counter(e["status"] for e in replans if e["status"] != "found")
        parts = [f"{len(replans) - sum(failed.values())} switched in"]
        if failed:
            parts.append(f"{sum(failed.values())} failed ("
                         + ", ".join(f"{n} {status}" for status, n in sorted(failed.items()))
                         + ")")
        pauses = sum(e["kind"] == "halt" for e in self.events)
        if pauses:
            parts.append(f"{pauses} pause{'s' if pauses > 1 else ''}, {self.restarts} of "
                         f"{self.max_restarts} restarts from rest made")
        harbours = sum(e["kind"] == "harbour" and e["status"] == "harbour" for e in self.events)
        if harbours:
            parts.append(f"{harbours} harbour swim{'s' if harbours > 1 else ''}")
        holds = [e for e in self.events if e["kind"] == "hold"]
        if holds:
            held = sum(e.get("t_end_s", e.get("t_last_s", e["t_s"])) - e["t_s"] for e in holds)
            parts.append(f"{len(holds)} hold{'s' if len(holds) > 1 else ''} on the plan "
                         f"({held:.1f} s)")
        stations = [e for e in self.events if e["kind"] == "station" and e["status"] == "held"]
        if stations:
            kept = sum(e.get("t_end_s", e.get("t_last_s", e["t_s"])) - e["t_s"] for e in stations)
            in_reach = sum(bool(e.get("stop_in_reach")) for e in stations)
            parts.append(f"{len(stations)} station{'s' if len(stations) > 1 else ''} held "
                         f"({kept:.1f} s" + (f", {in_reach} instead of a stop while clear"
                                             if in_reach else "") + ")")
        swims = [e for e in self.events if e["kind"] == "least_bad" and e["status"] == "swum"]
        if swims:
            kept = sum(e.get("t_end_s", e.get("t_last_s", e["t_s"])) - e["t_s"] for e in swims)
            parts.append(f"{len(swims)} least-bad swim{'s' if len(swims) > 1 else ''} "
                         f"({kept:.1f} s)")
        return ", ".join(parts)

    # -- a restart from rest (docs/planning.md, "A restart from rest") -----------------------------

    def _halt(self, t_s: float, d: Decision) -> Decision:
        """Turn a ``no_safe_continuation`` stop into a pause: stop swimming, drift, plan a restart.

        Any replan in flight is cut short; the twin swims the stopped body's drift on the side
        worker (:meth:`_drift_gap`), and the rest replan is asked for :attr:`rest_settle_s`
        later (:meth:`_paused_frame`). Without an estimate the stop stands.
        """
        est = self.estimator.estimate()
        if est is None:
            return d
        self._drop_work()
        pause = _Pause(t_s, d.detail)
        if self.rest_brake_s is not None:
            # the brake reaches the robot about when this frame's decision does: the phase it
            # freezes is the gait's then (the same latency delays its end, which cancels)
            pause.braked = braked_gait(self.gait, t_s)
            pause.t_unbrake_s = unbrake_time(self.gait, t_s, self.rest_brake_s)
        extra = self.current.value_m_s.copy() if self.estimate_current else np.zeros(2)
        pause.drift_wall_s = time.monotonic()
        pause.drift = self._side.submit(self._drift_gap, est, extra, pause)
        # frames without fresh telemetry take the paused gait's reference (the brake's S,
        # straight joints, or the reversed wave's)
        self.estimator.gait = pause.braked or self._paused_gait()
        self._pause = pause
        self.events.append({
            "kind": "halt", "reason": "no_safe_continuation", "t_s": round(t_s, 3),
            "restart": self.restarts + 1, "detail": d.detail,
            "start_state": [round(float(v), 5) for v in est.state]})
        pause.halt_event = self.events[-1]
        if pause.braked is not None:
            pause.halt_event["brake_until_s"] = round(pause.t_unbrake_s, 3)
        log.warning("no safe continuation at t = %.2f s: the robot stops swimming and drifts; "
                    "restart %d of %d from rest (%s)", t_s, self.restarts + 1,
                    self.max_restarts, d.detail)
        return Decision(pause=True, recorded=True, pause_gait=self.estimator.gait, detail=(
            f"stopped swimming at t = {t_s:.2f} s for restart {self.restarts + 1} from rest"))

    def _paused_gait(self) -> Gait:
        """The gait while paused after any brake: amplitude 0, or the reversed wave."""
        if self.rest_backing_rad is None:
            return stopped_gait(self.gait)
        return backing_gait(self.gait, self.rest_backing_rad)

    def _pause_drift(self, base: Twin, pause: _Pause, state: FloatArray, t_s: float,
                     duration_s: float, stride: int) -> FloatArray:
        """The paused body's states from ``state`` at ``t_s``: braked, then as :meth:`_paused_gait`."""
        after = stopped_twin(base, self._paused_gait())
        if pause.braked is None:
            return drift(after, state, t_s, duration_s, stride)
        return paused_drift(stopped_twin(base, pause.braked), after, state, t_s,
                            pause.t_unbrake_s, duration_s, stride)

    def _restart_floor_s(self, pause: _Pause) -> float:
        """The earliest restart a braked pause allows: its joints straight after the brake's end."""
        return (pause.t_unbrake_s + self.rest_settle_s if pause.braked is not None
                else -math.inf)

    def _drift_gap(self, est: BodyEstimate, extra: FloatArray, pause: _Pause
                   ) -> tuple[float, float, float]:
        """On the side worker: the stopped body's drift's gap, and how long the pause may last.

        The twin swims the stopped body (:func:`eelhost.planning.restart.stopped_twin`) from the
        estimate in the estimated current; its outline's gap at each moment is less the drift the
        current estimate's uncertainty allows by then, as the look-ahead's. Returns the smallest
        such gap until :data:`DRIFT_AFTER_S` after a restart with the least budget
        (``rest_budget_s``), and the rest replan's budget: the longest, up to
        ``rest_budget_max_s``, whose restart the drift keeps clear of the look-ahead's margin
        until :data:`DRIFT_AFTER_S` after it, and should the rest replan fail, through the final
        stop's brake and glide after it (``stop_brake_s`` and
        :data:`~eelhost.planning.harbour.FINAL_GLIDE_S`); and how long after the stop the
        drift stays clear (the horizon, at least :data:`REST_PAUSE_MAX_S` with retries, when it never comes near),
        which bounds the later tries (``rest_tries``). A braked pause's earliest restart is
        :attr:`rest_settle_s` after its brake's end (:meth:`_request_rest`).
        """
        base = self._twin_in(extra)
        stride = 3
        # a failed rest replan ends the run with the final stop then: the drift must stay clear
        # through it too (development seed 33033: a 5 s budget, the replan out of time, and the
        # final stop after it touched 20 mm deep; docs/planning.md, "The harbour")
        after = max(DRIFT_AFTER_S, self.stop_brake_s + FINAL_GLIDE_S)
        horizon = self.rest_settle_s + max(self.rest_budget_s, self.rest_budget_max_s) + after
        if self.rest_tries > 1:
            horizon = max(horizon, REST_PAUSE_MAX_S + DRIFT_AFTER_S)
        # the earliest restart, from now: the least budget's, or after a brake's end
        earliest = max(self.rest_settle_s + self.rest_budget_s,
                       self._restart_floor_s(pause) - est.t_s)
        horizon = max(horizon, earliest + DRIFT_AFTER_S)
        states = self._pause_drift(base, pause, est.state, est.t_s, horizon, stride)
        if not len(states):
            return -math.inf, self.rest_budget_s, 0.0
        outline = outline_clearance_m(self.world, self.model, states)
        ahead = np.arange(len(outline), dtype=np.float64) * (stride * base.dt_s)
        allowance = drift_allowance_m(current_spread_m_s(self.current.history), ahead)
        gap = np.subtract(outline, allowance)
        least = ahead <= earliest + DRIFT_AFTER_S + 1e-9
        near = np.flatnonzero(gap <= self.lookahead_margin_m)
        clear_s = float(ahead[near[0]]) if near.size else horizon
        budget = min(max(self.rest_budget_s, self.rest_budget_max_s),
                     clear_s - self.rest_settle_s - after)
        return float(np.min(gap[least])), max(budget, self.rest_budget_s), clear_s

    def _stop_window(self, kind: str) -> StopWindow:
        """How the twin swims a stop of ``kind`` (``pause``, else the run's final stop)."""
        if kind == "pause":
            # the pause's brake (a whole number of gait periods), then straight until a rest
            # replan with the least budget has had time to act (as :meth:`_drift_gap`'s)
            hold = self.rest_brake_s
            return StopWindow(
                (lambda t: t) if hold is None else (lambda t: unbrake_time(self.gait, t, hold)),
                self.rest_settle_s + self.rest_budget_s + DRIFT_AFTER_S)
        return StopWindow(lambda t: t + self.stop_brake_s, FINAL_GLIDE_S)

    def _stop_safely(self, t_s: float, kind: str, detail: str, gait: Gait | None = None
                     ) -> Decision | None:
        """A harbour swim before the stop of ``kind``, or None: the stop goes on as decided.

        The twin swims the stop decided now and the harbour candidates from the estimate in the
        estimated water (:func:`eelhost.planning.harbour.find_harbour`). When the stop at once
        keeps the look-ahead's margin, or no harbour keeps the margin and the cushion, the stop
        stands (docs/planning.md, "The harbour"). ``gait``: the gait the harbour swims (default
        the run's; a braked pause's resumes from its frozen phase).
        """
        gait = gait or self.gait
        if not self.harbour or self._harbours_swum >= HARBOURS_PER_PLAN:
            return None
        est = self.estimator.estimate()
        if est is None:
            return None
        extra = self.current.value_m_s.copy() if self.estimate_current else np.zeros(2)
        base = self._twin_in(extra, gait)
        wall = time.monotonic()
        at_once, harbour, clearest = find_harbour(base, gait, est.state, est.t_s,
                                                  self._stop_window(kind), self._stop_gaps(),
                                                  self.lookahead_margin_m + HARBOUR_CUSHION_M)
        wall = time.monotonic() - wall
        self._stop_judged = (t_s, at_once.gap_m)
        if at_once.gap_m > self.lookahead_margin_m:
            return None
        if (harbour is None and clearest is not None and clearest.gap_m > 0.0
                and clearest.gap_m >= at_once.gap_m + HARBOUR_GAIN_M):
            # none keeps the margin, but one is predicted clear where the stop here is not: the
            # lesser risk (development seed 33050: the stop here 37 mm deep in the twin)
            harbour = clearest
        if harbour is None:
            log.warning("at t = %.2f s the stop (%s) drifts within %.0f mm of an obstacle or "
                        "wall and no harbour swim keeps %.0f mm: stopping here", t_s, kind,
                        max(at_once.gap_m, 0.0) * 1000,
                        (self.lookahead_margin_m + HARBOUR_CUSHION_M) * 1000)
            self.events.append({"kind": "harbour", "reason": kind, "t_request_s": round(t_s, 3),
                                "status": "none", "stop_gap_m": _rounded(at_once.gap_m),
                                "wall_s": round(wall, 4)})
            return None
        self.estimator.gait = gait  # the harbour's frames swim it
        return self._take_harbour(t_s, est, extra, kind, detail, at_once, harbour, wall, gait)

    def _stop_slips_away(self, t_s: float, d: Decision) -> bool:
        """Stop now (``d``) if the latest look-ahead's stop keeps clear now and not after a retry.

        After a failed replan, with the present plan within the margin: the look-ahead, at most
        1.5 s old, swam the stop decided at its estimate clear by the margin and the cushion
        (:data:`~eelhost.planning.harbour.HARBOUR_CUSHION_M`), and the stop decided after the
        time another replan needs (:meth:`_retry_need_s`) within the margin. The robot then
        stops while the stop keeps clear, instead of retrying (docs/planning.md, "Stopped while
        the stop keeps clear").
        """
        from_s, now_m, later_m = self._stops
        if (not self.stop_in_reach or self._station is not None or t_s - from_s > 1.5
                or math.isnan(now_m)
                or now_m <= self.lookahead_margin_m + HARBOUR_CUSHION_M
                or later_m > self.lookahead_margin_m):
            return False
        d.stop = "no_safe_continuation"
        gap = self._last_gap[1]
        d.detail = (f"at t = {t_s:.2f} s the twin swims the present plan within the look-ahead's "
                    f"{self.lookahead_margin_m * 1000:.0f} mm margin"
                    + ("" if gap is None else f" (its outline {gap * 1000:.0f} mm)")
                    + " after a failed replan "
                    f"({self._last_replan()['message']}); a stop keeps {now_m * 1000:.0f} mm in "
                    f"the twin at t = {from_s:.2f} s, and "
                    + ("the goal comes first" if math.isnan(later_m)
                       else f"{later_m * 1000:.0f} mm after the {self._retry_need_s():.1f} s "
                       "another replan needs")
                    + ": stopped while it keeps clear")
        self._in_reach = {"kind": "stop_in_reach", "t_s": round(t_s, 3),
                          "t_judged_s": round(from_s, 3), "stop_now_m": _rounded(now_m),
                          "stop_later_m": _rounded(later_m)}
        self.events.append(self._in_reach)
        log.warning("%s", d.detail)
        return True

    def _last_replan(self) -> dict[str, Any]:
        """The latest replan's event (a hold's event may have come after it)."""
        return next((e for e in reversed(self.events) if e["kind"] == "replan"), self.events[-1])

    def _held(self, t_s: float) -> bool:
        """Within a hold, before its next check, with the present plan still the lesser risk.

        A stop decided then is put off without judging the harbours again (they are judged every
        :data:`HOLD_CHECK_S`); a failed replan is asked for again :data:`HOLD_RETRY_S` later.
        """
        hold = self._hold
        if hold is None or t_s >= hold.next_check_s - 1e-9 or not self._plan_beats_stop(
                t_s, hold.stop_gap_m):
            return False
        self._retry_while_holding(t_s)
        return True

    def _plan_beats_stop(self, t_s: float, stop_gap_m: float) -> bool:
        """The last look-ahead, at most 1.5 s old, swims the present plan clear where the stop touches.

        The plan's gap is the body's outline over the look-ahead's horizon, the stop's the
        outline less the current estimate's drift allowance over its brake and glide. Only
        contact against no contact: an outline overlaps by at most a link's half width, so
        depths read alike, and a plan swum into contact is never held on to (swum on in the
        twin past such a verdict, the present plans of the stops that touched on unseen seeds
        36000-36099 went 7-37 mm into something within 3-6 s; docs/planning.md, "The hold").
        """
        t_gap, gap = self._last_gap
        return gap is not None and t_s - t_gap <= 1.5 and gap > 0.0 >= stop_gap_m

    def _present_plan_clear(self, t_s: float) -> bool:
        """The last look-ahead, at most 1.5 s old, swims the present plan clear of the margin."""
        t_gap, gap = self._last_gap
        return gap is not None and t_s - t_gap <= 1.5 and gap >= self.lookahead_margin_m

    def _retry_while_holding(self, t_s: float) -> None:
        """Ask for a replan at the next idle frame, :data:`HOLD_RETRY_S` after the last ask."""
        if not self._retry_now:
            self._retry_now = True
            self._next_try_s = max(self._next_try_s, t_s + HOLD_RETRY_S)

    def _hold_on(self, t_s: float, kind: str, detail: str) -> Decision | None:
        """Swim the present plan on instead of a stop the twin swims into something, or None.

        The stop at once (``kind``: ``pause`` or ``stop``) is judged in the estimated water as
        the harbour judges it (:meth:`_stop_safely`; judged here when the harbours were not).
        When it comes within the look-ahead's margin, no harbour was found, and the last
        look-ahead swims the present plan clear of contact where the stop touches, the robot
        keeps swimming it, its gait and offsets at the control rate, replanning with a
        back-off of :data:`HOLD_RETRY_S`; the stop and the harbours are judged again every
        :data:`HOLD_CHECK_S`, and the hold ends with a plan, a harbour, a stop the twin swims
        clear, when the plan is no longer the lesser risk, or after :data:`HOLD_MAX_S`
        (docs/planning.md, "The hold").
        """
        if not self.hold_plan:
            return None
        if self._stop_judged[0] == t_s:
            stop_gap = self._stop_judged[1]
        else:  # the harbours were not judged (none left to this plan): the stop alone
            est = self.estimator.estimate()
            if est is None:
                return None
            extra = self.current.value_m_s.copy() if self.estimate_current else np.zeros(2)
            stop_gap = stop_gap_m(self._twin_in(extra), self.gait, est.state, est.t_s,
                                  self._stop_window(kind), self._stop_gaps())
            self._stop_judged = (t_s, stop_gap)
        hold = self._hold
        held_s = self._held_s + (0.0 if hold is None else t_s - hold.t_start_s)
        if (stop_gap > self.lookahead_margin_m or held_s >= HOLD_MAX_S
                or not self._plan_beats_stop(t_s, stop_gap)):
            return None
        plan_gap = self._last_gap[1]
        assert plan_gap is not None  # _plan_beats_stop holds
        if (self.events and self.events[-1]["kind"] == "harbour"
                and self.events[-1]["status"] == "none"
                and self.events[-1]["t_request_s"] == round(t_s, 3)):
            # while holding, a harbour that was not found is the hold's check, not a stop
            self.events.pop()
        if hold is None:
            event = {"kind": "hold", "reason": kind, "t_s": round(t_s, 3),
                     "stop_gap_m": _rounded(stop_gap), "plan_gap_m": _rounded(plan_gap),
                     "checks": 1, "detail": detail}
            self.events.append(event)
            self._hold = hold = _Hold(t_s, t_s + HOLD_CHECK_S, stop_gap, event)
            log.warning("at t = %.2f s the stop (%s) drifts within %.0f mm of an obstacle or wall "
                        "and no harbour keeps the margin; the twin swims the present plan %.0f mm "
                        "clear: holding on it and replanning (%s)", t_s, kind,
                        max(stop_gap, 0.0) * 1000, plan_gap * 1000, detail)
        else:
            hold.next_check_s = t_s + HOLD_CHECK_S
            hold.stop_gap_m = stop_gap
            hold.event["checks"] += 1
            hold.event["t_last_s"] = round(t_s, 3)
        self._retry_while_holding(t_s)
        return Decision(recorded=hold.event["checks"] == 1, detail=(
            f"holding on the present plan at t = {t_s:.2f} s: the stop drifts "
            f"{stop_gap * 1000:.0f} mm from an obstacle or wall in the twin, the plan "
            f"{plan_gap * 1000:.0f} mm"))

    def _end_hold(self, t_s: float, why: str) -> None:
        """End the hold, if one is on, recording how (``harbour``, ``stopped``, ...)."""
        hold = self._hold
        if hold is None:
            return
        self._hold = None
        self._held_s += t_s - hold.t_start_s
        hold.event["t_end_s"] = round(t_s, 3)
        hold.event["ended"] = why

    # -- holding station (docs/planning.md, "Holding station (session 21)") -------------------

    def _station_current(self, extra: FloatArray) -> tuple[float, float]:
        """The current the body swims in: the world's (the planner's) and the estimate ``extra``."""
        planner, planner_extra = self._planned
        current = np.add(planner.world.current_m_s, extra - planner_extra)
        return (float(current[0]), float(current[1]))

    def _stop_now(self, t_s: float, kind: str) -> tuple[
            BodyEstimate, FloatArray, Twin, Callable[[FloatArray, FloatArray], FloatArray],
            float] | None:
        """The estimate, the estimated current, its twin, the stop's judge and the stop's gap now.

        What the station and the least-bad swim judge their swims against: the stop at once
        (``kind``: ``pause`` or ``stop``) swum from the estimate as the harbour swims it, its gap
        reused when it was judged at ``t_s`` already. None without an estimate.
        """
        est = self.estimator.estimate()
        if est is None:
            return None
        extra = self.current.value_m_s.copy() if self.estimate_current else np.zeros(2)
        twin = self._twin_in(extra)
        gap_of = self._stop_gaps()
        if self._stop_judged[0] == t_s:
            stop_gap = self._stop_judged[1]
        else:
            stop_gap = stop_gap_m(twin, self.gait, est.state, est.t_s, self._stop_window(kind),
                                  gap_of)
            self._stop_judged = (t_s, stop_gap)
        return est, extra, twin, gap_of, stop_gap

    def _judge_station(self, t_s: float, kind: str, always: bool = False
                       ) -> tuple[float, Station | None, Station | None] | None:
        """The stop at once's gap and the station swims from the estimate, or None without one.

        The stop is judged as the harbour judges it (``kind``: ``pause`` or ``stop``; reused
        when the harbours were judged at ``t_s``), the swims by
        :func:`~eelhost.planning.station.find_station` with the same judgement, needing the
        look-ahead's margin and the harbour's cushion: only when the stop comes within the
        margin, or ``always`` (a station instead of a stop while it keeps clear).
        """
        judged = self._stop_now(t_s, kind)
        if judged is None:
            return None
        est, extra, twin, gap_of, stop_gap = judged
        if stop_gap > self.lookahead_margin_m and not always:
            return stop_gap, None, None
        best, clearest = find_station(twin, est.state, est.t_s, self._station_current(extra),
                                      gap_of, self.lookahead_margin_m + HARBOUR_CUSHION_M)
        return stop_gap, best, clearest

    def _station_on(self, t_s: float, kind: str, detail: str,
                    in_reach: dict[str, Any] | None = None) -> Decision | None:
        """Swim into the current instead of a stop the twin drifts into something, or None.

        A tier before a ``no_safe_continuation`` stop (``kind``: ``pause`` or ``stop``), after
        the harbour and before the hold, and before the arrival's stop (``arrived``) after the
        harbour: when the stop at once comes within the look-ahead's margin and a station swim
        keeps the margin and the cushion over its horizon, the robot steers to that swim's
        waypoint, its gait and offsets at the control rate; the frames after are
        :meth:`_station_frame`'s (an arrival's ask for no replan, and end in the arrival).

        ``in_reach``: the ``stop_in_reach`` event of a stop made while it keeps clear
        (:meth:`_stop_slips_away`): the station swims are judged whatever the stop's gap, and
        one keeping the margin and the cushion is held instead, replanning, until it no longer
        keeps clear, its time bound, or a plan (docs/planning.md, "Holding station (session 21)").
        """
        if not self.station_keeping or self._stationed_s >= STATION_MAX_S:
            return None
        judged = self._judge_station(t_s, kind, always=in_reach is not None)
        if judged is None:
            return None
        stop_gap, best, clearest = judged
        if stop_gap > self.lookahead_margin_m and in_reach is None:
            return None
        if best is None:
            if self._hold is not None:
                return None  # the hold's check: recorded with the hold, not at every check
            self.events.append({"kind": "station", "reason": kind, "t_s": round(t_s, 3),
                                "status": "none", "stop_gap_m": _rounded(stop_gap),
                                "clearest_gap_m": (None if clearest is None
                                                   else _rounded(clearest.gap_m)),
                                "stop_in_reach": in_reach is not None})
            return None
        if kind == "arrived":
            self._drop_work()  # arrived: no plan is wanted, only the stop's room
        # the look-ahead and the windows followed the old waypoints; a replan in flight goes on
        self._lookahead = None
        self._whole_job = None
        self.current.drop()
        self._retry_now = False
        event = {"kind": "station", "reason": kind, "t_s": round(t_s, 3), "status": "held",
                 "bearing_deg": best.bearing_deg, "from": best.frame, "gait": "the run's",
                 "waypoint_m": [round(best.waypoint_m[0], 4), round(best.waypoint_m[1], 4)],
                 "gap_m": _rounded(best.gap_m), "drift_m": _rounded(best.drift_m),
                 "stop_gap_m": _rounded(stop_gap), "checks": 1, "switches": 0, "detail": detail,
                 "stop_in_reach": in_reach is not None}
        self.events.append(event)
        self._station = _Station(t_s, t_s + STATION_CHECK_S, kind, detail, best.waypoint_m, event,
                                 in_reach=in_reach is not None)
        if in_reach is not None:
            in_reach["station"] = True  # put off: the station holds instead
            log.warning("at t = %.2f s a stop keeps clear and not after a retry: holding "
                        "station instead, %+.0f deg from %s, %.0f mm clear in the twin",
                        t_s, best.bearing_deg, best.frame, best.gap_m * 1000)
            return Decision(waypoints=[best.waypoint_m], guide=best.guide, recorded=True, detail=(
                f"holding station at t = {t_s:.2f} s instead of a stop while it keeps clear "
                f"({stop_gap * 1000:.0f} mm in the twin): the swim into the current "
                f"{best.gap_m * 1000:.0f} mm, replanning"))
        self.waypoints = [best.waypoint_m]
        log.warning("at t = %.2f s the stop (%s) drifts within %.0f mm of an obstacle or wall and "
                    "no harbour keeps the margin: holding station, %+.0f deg from %s, "
                    "%.0f mm clear in the twin (%s)", t_s, kind, max(stop_gap, 0.0) * 1000,
                    best.bearing_deg, best.frame, best.gap_m * 1000, detail)
        return Decision(waypoints=[best.waypoint_m], guide=best.guide, recorded=True, detail=(
            f"holding station at t = {t_s:.2f} s: the stop drifts {stop_gap * 1000:.0f} mm "
            f"from an obstacle or wall in the twin, the swim into the current "
            f"{best.gap_m * 1000:.0f} mm"))

    # -- the least-bad swim (docs/planning.md, "The least-bad swim (session 24)") ----------------

    def _judge_least_bad(self, t_s: float, kind: str
                         ) -> tuple[float, LeastBad | None] | None:
        """The stop at once's gap and the least-bad swim from the estimate, or None without one.

        The stop is judged as :meth:`_judge_station` judges it (reused when judged at ``t_s``);
        the swims by :func:`~eelhost.planning.station.find_least_bad` (each swim over its short
        horizon and the stops of ``kind`` decided along it) only when the stop comes within the
        look-ahead's margin.
        """
        judged = self._stop_now(t_s, kind)
        if judged is None:
            return None
        est, extra, twin, gap_of, stop_gap = judged
        if stop_gap > self.lookahead_margin_m:
            return stop_gap, None
        least = find_least_bad(twin, self.gait, est.state, est.t_s,
                               self._station_current(extra), gap_of, self._stop_window(kind))
        return stop_gap, least

    @staticmethod
    def _beats_stop(least: LeastBad | None, stop_gap_m: float) -> bool:
        """The swim's clearest stop beats ``stop_gap_m`` by :data:`~eelhost.planning.station.LEAST_BAD_STEP_M`.

        The swim itself keeps :data:`~eelhost.planning.station.LEAST_BAD_GAIN_M` over its
        horizon (:func:`~eelhost.planning.station.find_least_bad`): only a swim the twin keeps
        clear of contact is swum, and only towards a better stop.
        """
        return (least is not None and least.swim.gap_m > LEAST_BAD_GAIN_M
                and least.stop_gap_m > stop_gap_m + LEAST_BAD_STEP_M)

    def _least_bad_on(self, t_s: float, kind: str, detail: str) -> Decision | None:
        """Swim towards a better stop instead of a stop the twin drifts into something, or None.

        The last tier before a ``no_safe_continuation`` stop (``kind``: ``pause`` or ``stop``),
        after the harbour, the station and the hold: when the stop at once comes within the
        look-ahead's margin and the least-bad swim
        (:func:`~eelhost.planning.station.find_least_bad`: clear over
        :data:`~eelhost.planning.station.LEAST_BAD_HORIZON_S`, its stops along it the clearest)
        beats it (:meth:`_beats_stop`), the robot steers to that swim's waypoint, its gait and offsets at
        the control rate; the frames after are :meth:`_station_frame`'s, judged again every
        :data:`~eelhost.planning.station.STATION_CHECK_S` (docs/planning.md, "The least-bad swim
        (session 24)").
        """
        if not self.least_bad or kind == "arrived" or self._stationed_s >= LEAST_BAD_MAX_S:
            return None
        judged = self._judge_least_bad(t_s, kind)
        if judged is None:
            return None
        stop_gap, least = judged
        if stop_gap > self.lookahead_margin_m:
            return None
        if least is None or not self._beats_stop(least, stop_gap):
            self.events.append({
                "kind": "least_bad", "reason": kind, "t_s": round(t_s, 3), "status": "none",
                "stop_gap_m": _rounded(stop_gap),
                "swim_gap_m": None if least is None else _rounded(least.swim.gap_m),
                "swim_stop_gap_m": None if least is None else _rounded(least.stop_gap_m)})
            return None
        swim = least.swim
        # the look-ahead and the windows followed the old waypoints; a replan in flight goes on
        self._lookahead = None
        self._whole_job = None
        self.current.drop()
        self._retry_now = False
        event = {"kind": "least_bad", "reason": kind, "t_s": round(t_s, 3), "status": "swum",
                 "bearing_deg": swim.bearing_deg, "from": swim.frame,
                 "waypoint_m": [round(swim.waypoint_m[0], 4), round(swim.waypoint_m[1], 4)],
                 "gap_m": _rounded(swim.gap_m), "stop_gap_m": _rounded(stop_gap),
                 "swim_stop_gap_m": _rounded(least.stop_gap_m), "horizon_s": LEAST_BAD_HORIZON_S,
                 "checks": 1, "switches": 0, "detail": detail,
                 "judged": [[round(t_s, 3), _rounded(stop_gap), _rounded(swim.gap_m),
                             _rounded(least.stop_gap_m)]]}
        self.events.append(event)
        self._station = _Station(t_s, t_s + STATION_CHECK_S, kind, detail, swim.waypoint_m, event,
                                 least_bad=True)
        self.waypoints = [swim.waypoint_m]
        log.warning("at t = %.2f s the stop (%s) drifts %.0f mm from an obstacle or wall in the "
                    "twin with no harbour, station or hold: swimming %+.0f deg from %s, %.0f mm "
                    "clear over %.1f s in the twin, a stop along it %.0f mm (%s)", t_s, kind,
                    stop_gap * 1000, swim.bearing_deg, swim.frame, swim.gap_m * 1000,
                    LEAST_BAD_HORIZON_S, least.stop_gap_m * 1000, detail)
        return Decision(waypoints=[swim.waypoint_m], guide=swim.guide, recorded=True, detail=(
            f"the least-bad swim at t = {t_s:.2f} s: the stop drifts {stop_gap * 1000:.0f} mm "
            f"from an obstacle or wall in the twin, the swim {swim.gap_m * 1000:.0f} mm over "
            f"{LEAST_BAD_HORIZON_S:.1f} s and a stop along it {least.stop_gap_m * 1000:.0f} mm"))

    def _least_bad_check(self, t_s: float, st: _Station) -> tuple[float, Station | None] | None:
        """A least-bad swim's check: the stop's gap, and the swim to steer (None: no swim beats it).

        Each check's stop, swim and the swim's clearest stop are recorded in the event's ``judged``.
        """
        judged = self._judge_least_bad(t_s, st.kind)
        if judged is None:
            return None
        stop_gap, least = judged
        st.event["judged"].append([
            round(t_s, 3), _rounded(stop_gap),
            None if least is None else _rounded(least.swim.gap_m),
            None if least is None else _rounded(least.stop_gap_m)])
        if least is None or not self._beats_stop(least, stop_gap):
            return stop_gap, None  # no swim beats the stop any more: the stop
        return stop_gap, least.swim

    def _station_frame(self, t_s: float, guide: Guide | None) -> Decision:
        """Take one frame while holding station: replan, judge again, end in a plan or a stop.

        A replan is asked for :data:`STATION_RETRY_S` after the last was asked (a failure is
        not a stop here); a plan found is switched in. Every
        :data:`~eelhost.planning.station.STATION_CHECK_S` the stop at once is judged again (made
        when the twin swims it clear) and the station swims (the best one steered to when its
        waypoint moved); with none, or after :data:`~eelhost.planning.station.STATION_MAX_S`
        of the plan's stations, the stop is made.
        """
        st = self._station
        assert st is not None
        self._guide = guide
        d = Decision()
        if st.kind != "arrived":  # arrived: no replan
            d.recorded |= self._collect(t_s, d)
        d.stop = None  # a failed replan while holding station is asked for again, not a stop
        self._retry_now = False
        if self._switch_in(t_s, d):
            self._end_station(t_s, "replanned")
            self._stationed_s = 0.0  # a new plan: it may hold and hold station again
            self._held_s = 0.0
            return d
        if t_s >= st.next_check_s - 1e-9:
            st.next_check_s = t_s + STATION_CHECK_S
            st.event["checks"] += 1
            st.event["t_last_s"] = round(t_s, 3)
            judged: tuple[float, Station | None] | None
            if st.least_bad:
                judged = self._least_bad_check(t_s, st)
            else:
                station = self._judge_station(t_s, st.kind, always=st.in_reach)
                judged = None if station is None else station[:2]
            if judged is not None:
                stop_gap, best = judged
                over = self._stationed_s + t_s - st.t_start_s >= (
                    LEAST_BAD_MAX_S if st.least_bad else STATION_MAX_S)
                # instead of a stop while it keeps clear: the station holds while its swim keeps
                # clear, the stop made the moment it no longer does (never for the stop's room)
                stop_clear = not st.in_reach and stop_gap > self.lookahead_margin_m
                why = ("stopped" if stop_clear else "max_time" if over
                       else "none" if best is None else "")
                if why:
                    return self._station_stop(t_s, why, stop_gap)
                assert best is not None
                st.event["gap_m"] = _rounded(best.gap_m)
                if math.dist(best.waypoint_m, st.waypoint_m) > 0.1 * STATION_REACH_M:
                    # the water or the body turned: steer the swim judged now, from here
                    st.waypoint_m = best.waypoint_m
                    st.event["switches"] += 1
                    self.waypoints = [best.waypoint_m]
                    d.waypoints, d.guide = [best.waypoint_m], best.guide
        est = self.estimator.estimate()
        if (est is not None and st.kind != "arrived" and self._job is None
                and self._pending is None and t_s >= st.t_asked_s + STATION_RETRY_S - 1e-9):
            st.t_asked_s = t_s
            self._request(t_s, est, list(self.waypoints), "least_bad" if st.least_bad else "station")
        return d

    def _station_stop(self, t_s: float, why: str, stop_gap: float) -> Decision:
        """End the station with the stop it put off (``why``: how it ended), as decided then.

        An arrival's station ends in the arrival (the run loop's final stop).
        """
        st = self._station
        assert st is not None
        self._end_station(t_s, why)
        self._drop_work()
        held = "swam the least-bad swim" if st.least_bad else "held station"
        text = {"stopped": "the stop now keeps clear in the twin",
                "max_time": ("swum for the longest a plan may "
                             f"({LEAST_BAD_MAX_S if st.least_bad else STATION_MAX_S:.0f} s)"),
                "none": ("no swim beats the stop any longer" if st.least_bad
                         else "no station swim keeps clear any longer")}[why]
        d = Decision(stop="no_safe_continuation", recorded=True, detail=(
            f"{st.detail}; {held} {t_s - st.t_start_s:.1f} s, then stopped: {text} "
            f"(the stop {stop_gap * 1000:.0f} mm from an obstacle or wall in the twin)"))
        log.warning("station ended at t = %.2f s: %s", t_s, text)
        if st.kind == "arrived":
            return Decision(arrived=True, recorded=True, detail=(
                f"then held station {t_s - st.t_start_s:.1f} s: {text} (the stop "
                f"{stop_gap * 1000:.0f} mm from an obstacle or wall in the twin)"))
        if st.kind == "pause":
            return self._halt(t_s, d)
        return d

    def _end_station(self, t_s: float, why: str) -> None:
        """End the station, if one is held, recording how (``replanned``, ``stopped``, ...)."""
        st = self._station
        if st is None:
            return
        self._station = None
        self._stationed_s += t_s - st.t_start_s
        st.event["t_end_s"] = round(t_s, 3)
        st.event["ended"] = why

    def _take_harbour(self, t_s: float, est: BodyEstimate, extra: FloatArray, kind: str,
                      detail: str, at_once: Harbour, harbour: Harbour, wall_s: float,
                      gait: Gait) -> Decision:
        """Swim the harbour now: its waypoint, a one-leg plan of the twin's swim as its corridor.

        Replans and look-aheads stop: the harbour was judged with its stop, which comes at its
        end (:meth:`_harbour_frame`).
        """
        dt = self.planner.twin.dt_s
        self._drop_work()
        leg = Leg(harbour.waypoint_m, HARBOUR_REACH_M, harbour.bearing_deg, harbour.start_step,
                  harbour.start_step + int(round(harbour.swim_s / dt)), harbour.com_m,
                  harbour.gap_m)
        why = (f"stopping at once would drift within {max(at_once.gap_m, 0.0) * 1000:.0f} mm of "
               f"an obstacle or wall; a harbour {harbour.swim_s:.1f} s at "
               f"{harbour.bearing_deg:+.0f} deg from the heading, its swim and stop "
               f"{harbour.gap_m * 1000:.0f} mm clear in the twin")
        outcome = Outcome(Plan(True, "harbour", why, legs=[leg], start_guide=harbour.guide),
                          "harbour", why)
        event = self._event("harbour", kind, t_s, est.t_s, t_s, est.state, outcome, wall_s,
                            math.nan, extra)
        event.update({"waypoints_m": [[round(harbour.waypoint_m[0], 4),
                                       round(harbour.waypoint_m[1], 4)]],
                      "swim_s": round(harbour.swim_s, 3), "gap_m": round(harbour.gap_m, 4),
                      "swim_gap_m": _rounded(harbour.swim_gap_m),
                      "stop_gap_m": round(harbour.stop_gap_m, 4),
                      "at_once_gap_m": _rounded(at_once.gap_m),
                      "within_margin": bool(harbour.gap_m <= self.lookahead_margin_m
                                            + HARBOUR_CUSHION_M),
                      "t_switch_s": round(t_s, 3), "detail": detail})
        self.events.append(event)
        self._take_plan(outcome, extra)
        self.waypoints = [harbour.waypoint_m]
        self._harbour = _HarbourSwim(t_s + harbour.swim_s, kind, detail, event, gait)
        self._harbours_swum += 1
        log.warning("at t = %.2f s (%s): %s", t_s, kind, why)
        d = Decision(waypoints=[harbour.waypoint_m], guide=harbour.guide, recorded=True)
        d.detail = f"harbour at t = {t_s:.2f} s: {why}"
        return d

    def _harbour_frame(self, t_s: float) -> Decision:
        """Take one frame of a harbour swim: swim on, and at its end the stop it precedes."""
        swim = self._harbour
        assert swim is not None
        if t_s < swim.t_end_s - 1e-9:
            return Decision()
        self._harbour = None
        swim.event["t_end_s"] = round(t_s, 3)
        # judged again from where the robot is: the water it swam may not be the twin's (a
        # harbour's stop judged 143 mm clear was 5 mm clear at its end, development seed 33005)
        again = self._stop_safely(t_s, swim.kind, swim.detail, swim.gait)
        if again is not None:
            return again
        if swim.gait is self.gait:
            # the stop still drifts within the margin with no harbour left: hold station, as
            # where the stop was decided (docs/planning.md, "Holding station (session 21)"); not
            # on a braked pause's resumed phase, which the twin's station swims do not have
            stationed = (self._station_on(t_s, swim.kind, swim.detail)
                         or self._least_bad_on(t_s, swim.kind, swim.detail))
            if stationed is not None:
                return stationed
        if swim.kind == "arrived":
            return Decision(arrived=True, recorded=True,
                            detail=f"then a harbour swim of {swim.event['swim_s']:.1f} s")
        d = Decision(stop="no_safe_continuation", recorded=True, detail=(
            f"{swim.detail}; stopped after a harbour swim of {swim.event['swim_s']:.1f} s"))
        if swim.kind == "pause":
            return self._halt(t_s, d)
        return d

    def _switch_in(self, t_s: float, d: Decision) -> bool:
        """Switch in the replan that is ready by ``t_s`` into ``d``, if one is; True if so.

        The one switch of a found replan's waypoints, while swimming and while holding station.
        """
        if self._pending is None or t_s < self._pending[0] - 1e-9:
            return False
        d.waypoints, d.guide = self._pending[1], self._pending[2]
        self.waypoints = list(d.waypoints)
        self._pending = None
        self.current.drop()  # the prediction of a window spans no switch of waypoints
        self._lookahead = None  # it followed the old waypoints
        self._whole_job = None
        self._last_replan()["t_switch_s"] = round(t_s, 3)
        self.replans += 1
        d.recorded = True
        return True

    def _drop_work(self) -> None:
        """Cut any replan short and forget every verdict: the robot swims no plan of the search."""
        job = self._job
        if job is not None and job.deadline is not None:
            job.deadline.cut_to(time.monotonic())  # the worker comes back at its next batch
        self._job = None
        self._pending = None
        self._lookahead = None
        self._whole_job = None
        self._retry_now = False
        self._urgent_after_cut = None
        self.current.drop()

    def _paused_frame(self, t_s: float, loc: Localisation, pose: FloatArray | None,
                      offset_rad: float) -> Decision:
        """Take one frame while the stopped robot drifts (:meth:`on_frame`).

        After :meth:`_observe` (contact and goal, as while swimming): the drift's verdict, the
        rest replan's request and collection, and the restart.
        """
        d = Decision()
        pause = self._pause
        assert pause is not None
        if pause.braked is not None and not pause.unbraked and t_s >= pause.t_unbrake_s - 1e-9:
            # the brake ends a whole gait period on: amplitude 0 at the gait's omega, whose
            # phase runs on from the frozen one, which is the twin's omega t here
            pause.unbraked = True
            self.estimator.gait = self._paused_gait()
            d.pause, d.pause_gait, d.recorded = True, self.estimator.gait, True
            pause.halt_event["brake_ended_s"] = round(t_s, 3)
            log.info("the pause's brake ends at t = %.2f s", t_s)
        if pause.drift is not None:
            if not pause.drift.done():
                return d
            gap, pause.budget_s, pause.clear_s = pause.drift.result()
            pause.drift = None
            pause.drift_gap_m = gap
            self.events[-1]["drift_gap_m"] = round(gap, 4) if math.isfinite(gap) else None
            self.events[-1]["rest_budget_s"] = round(pause.budget_s, 3)
            d.recorded = True
            if not gap > self.lookahead_margin_m:
                return self._end_pause(t_s, d, (
                    f"the twin drifts the stopped body within {max(gap, 0.0) * 1000:.0f} mm of an "
                    f"obstacle or wall (its outline, less the current's drift allowance; "
                    f"limit {self.lookahead_margin_m * 1000:.0f} mm)"))
        if pause.drift_gap_m is None:
            return d
        job = pause.job
        if job is None and pause.pending is None:
            if t_s < max(pause.t_halt_s + self.rest_settle_s, pause.t_next_s) - 1e-9:
                return d
            est = self.estimator.estimate()
            if est is None:
                return d
            self._request_rest(t_s, est)
            return d
        if job is not None:
            late = t_s > job.t_start_s + self.max_lead_s + 1e-9
            if late and job.deadline is not None:
                # past the start it plans from: a plan would be stale, and the drift was judged
                # only until DRIFT_AFTER_S after it (a loaded machine's rest replan overran
                # its budget and the paused body drifted on into contact, development seed 27224)
                job.deadline.cut_to(time.monotonic())
            if not job.future.done() or t_s - job.t_request_s < (
                    job.future.result()[5] - job.wall_request_s) - 1e-9:
                # not back, or over sim:// the robot has not yet lived the planner's time
                if late:
                    pause.job = None
                    return self._end_pause(t_s, d, (
                        f"the replan from rest asked for at t = {job.t_request_s:.2f} s was not "
                        f"back by t = {t_s:.2f} s, {t_s - job.t_start_s:.2f} s after the state "
                        f"it starts from"))
                return d
            outcome, state, wall_s, cpu, extra, done, start_step = job.future.result()
            wall = done - job.wall_request_s
            pause.job = None
            job.t_start_s = start_step * self.planner.twin.dt_s
            self.events.append(self._event("restart", "rest", job.t_request_s, job.t_start_s,
                                           job.t_request_s + wall, state, outcome, wall, cpu,
                                           extra))
            self.events[-1]["budget_s"] = job.budget_s
            self.events[-1]["restart"] = self.restarts + 1
            self.events[-1]["t_halt_s"] = round(pause.t_halt_s, 3)
            d.recorded = True
            self.events[-1]["try"] = pause.tries
            if not outcome.found:
                if self._rest_retry(t_s, pause):
                    return d
                return self._end_pause(t_s, d, f"the replan from rest failed: {outcome.message}")
            if t_s > job.t_start_s + self.max_lead_s:
                self.events[-1]["status"] = "stale"
                return self._end_pause(t_s, d, (
                    f"the replan from rest was ready at t = {t_s:.2f} s, {t_s - job.t_start_s:.2f} "
                    f"s after the state it starts from ({outcome.message})"))
            pause.outcome, pause.extra = outcome, extra
            pause.pending = (job.t_start_s, list(outcome.plan.waypoints_m),
                             outcome.plan.start_guide)
        if pause.pending is not None and t_s >= pause.pending[0] - 1e-9:
            return self._restart(t_s, d)
        return d

    def _request_rest(self, t_s: float, est: BodyEstimate) -> None:
        """Submit the rest replan: from the stopped body's state predicted for its budget's end."""
        pause = self._pause
        assert pause is not None
        dt = self.planner.twin.dt_s
        period = self.planner.twin.restart_steps or 1
        now_step = int(round(est.t_s / dt))
        first = now_step + math.ceil(pause.budget_s / dt)
        floor = self._restart_floor_s(pause)
        if math.isfinite(floor):  # the joints straighten before the restart
            first = max(first, math.ceil(floor / dt - 1e-9))
        start_step = int(math.ceil(first / period)) * period
        extra = self.current.value_m_s.copy() if self.estimate_current else np.zeros(2)
        wall = time.monotonic()
        deadline = Deadline(wall + pause.budget_s)
        pause.tries += 1
        future = self._worker.submit(self._rest_replan, est, start_step, extra, deadline,
                                     pause.tries > 1, pause)
        pause.job = _Job(future, t_s, wall, start_step * dt, "rest", math.inf,
                         pause.budget_s, deadline)
        log.info("replanning from rest at t = %.2f s, from the stopped body predicted for "
                 "t = %.2f s", t_s, start_step * dt)

    def _rest_retry(self, t_s: float, pause: _Pause) -> bool:
        """After a failed rest replan: whether another is tried later in the same pause.

        While tries are left (``rest_tries``), the next is asked for ``rest_retry_s`` from now,
        from the body then (slower, elsewhere), with the longest budget whose restart the stop's
        drift keeps clear until :data:`DRIFT_AFTER_S` after it; at least ``rest_budget_s``, else
        none (docs/planning.md, "A restart from rest").
        """
        if pause.tries >= self.rest_tries:
            return False
        t_next = t_s + self.rest_retry_s
        budget = min(max(self.rest_budget_s, self.rest_budget_max_s),
                     pause.t_halt_s + pause.clear_s - DRIFT_AFTER_S - t_next)
        if budget < self.rest_budget_s - 1e-9:
            return False
        pause.t_next_s, pause.budget_s = t_next, budget
        log.info("the replan from rest failed at t = %.2f s; try %d of %d from t = %.2f s", t_s,
                 pause.tries + 1, self.rest_tries, t_next)
        return True

    def _rest_replan(self, est: BodyEstimate, start_step: int, extra: FloatArray,
                     deadline_s: SupportsFloat | None, recheck: bool, pause: _Pause
                     ) -> tuple[Outcome, FloatArray, float, float, FloatArray, float, int]:
        """On the worker: the stopped body's state at ``start_step``, and a plan from it.

        The planner first, then (its search exhausted or failed, time left) the goal approach's
        planner, the recovery's and, from a start by the check's margin, the escape's: the tiers
        of a replan, without the blocked-start retries (the body does not swim on) and the shift
        repair (no route is left to shift). A later try (``recheck``) first judges the drift
        from the estimate to the start: within the look-ahead's margin, it is refused.
        """
        wall0, cpu0 = time.perf_counter(), time.thread_time()
        self._prepare_planner(extra)
        planner = self.planner
        now = int(round(est.t_s / planner.twin.dt_s))
        states = self._pause_drift(planner.twin, pause, est.state, est.t_s,
                                   max(start_step - now, 0) * planner.twin.dt_s, 1)
        state = states[min(max(start_step - now, 0), len(states) - 1)].copy()
        if recheck and len(states):
            near = float(np.min(outline_clearance_m(self.world, self.model, states)))
            if not near > self.lookahead_margin_m:
                why = (f"the stopped body drifts within {max(near, 0.0) * 1000:.0f} mm before "
                       f"the restart")
                refused = Outcome(Plan(False, "blocked_start", why), "blocked_start", why)
                return (refused, state, time.perf_counter() - wall0,
                        time.thread_time() - cpu0, self._planner_current.copy(),
                        time.monotonic(), start_step)
        guide = leg_start_guide(state, self.model.n_links, (0.0, 0.0))
        make = self.rest_escape_planner_for
        gap = self._escape_gap(state, make)
        if gap is not None and gap <= planner.check_margin_m:
            # inside the check's margin: every plan's check fails at its first sample
            outcome = self._escape(state, start_step, (0.0, 0.0), extra, gap, deadline_s, make)
            return (outcome, state, time.perf_counter() - wall0, time.thread_time() - cpu0,
                    self._planner_current.copy(), time.monotonic(), start_step)
        outcome = planner.plan(state, start_step, guide=guide, deadline_s=deadline_s)
        tiers = [("goal approach", lambda: self._goal_planner_in(extra)),
                 ("recovery", lambda: self._planner_in("recovery", self.recovery_planner_for,
                                                       extra))]
        for name, build in tiers:
            if (outcome.found or outcome.status in (*REFUSED_FROM_STATE, "out_of_time")
                    or not _time_left(deadline_s)):
                break
            other = build()
            if other is None:
                continue
            tried = other.plan(state, start_step, guide=guide, deadline_s=deadline_s)
            if tried.found:
                tried.message = f"{name}: {tried.message}"
                outcome = tried
            else:
                outcome = dataclasses.replace(outcome, message=(
                    f"{outcome.message}; with the {name}'s planner: {tried.message}"))
        if (gap is not None and not outcome.found and outcome.status != "out_of_time"
                and _time_left(deadline_s)):
            escaped = self._escape(state, start_step, (0.0, 0.0), extra, gap, deadline_s, make)
            outcome = escaped if escaped.found else dataclasses.replace(
                outcome, message=f"{outcome.message}; {escaped.message}")
        return (outcome, state, time.perf_counter() - wall0, time.thread_time() - cpu0,
                self._planner_current.copy(), time.monotonic(), start_step)

    def _restart(self, t_s: float, d: Decision) -> Decision:
        """Swim again: the rest replan's waypoints, the gait back, the swimming rules afresh."""
        pause = self._pause
        assert pause is not None and pause.pending is not None and pause.outcome is not None
        _, waypoints, guide = pause.pending
        self.restarts += 1
        self._pause = None
        self._harbours_swum = 0  # a new plan: its stops may swim harbours again
        self._held_s = 0.0  # and hold again
        self._stationed_s = 0.0  # and hold station again
        self.estimator.gait = self.gait
        assert pause.extra is not None  # set with the outcome
        self._take_plan(pause.outcome, pause.extra)
        self.waypoints = list(waypoints)
        self._afresh(t_s)
        self.events[-1]["t_switch_s"] = round(t_s, 3)
        log.info("restart %d from rest at t = %.2f s: %d waypoints", self.restarts, t_s,
                 len(waypoints))
        d.waypoints, d.guide, d.restart, d.recorded = list(waypoints), guide, True, True
        d.pause, d.pause_gait = False, None  # the restart's gait supersedes a brake's end
        d.detail = f"restart {self.restarts} from rest at t = {t_s:.2f} s"
        return d

    def _afresh(self, t_s: float) -> None:
        """The swimming rules from the start: no try held back, no verdict, a look-ahead now."""
        self._next_try_s = -math.inf
        self._last_gap = (-math.inf, None)
        self._contact_at_s = math.inf
        self._near_at_s = math.inf
        self._next_lookahead_s = t_s
        self._next_early_s = -math.inf
        self._early_in_row = 0
        self.current.drop()

    def _take_plan(self, outcome: Outcome, extra: FloatArray) -> None:
        """A found replan becomes the present plan: its corridor and current; no failures yet."""
        self.failures = 0
        self._plan_current = extra
        self._urgent_after_cut = None  # it judged the old plan; the new one is judged anew
        self.outcome = outcome
        self.path = corridor_path(outcome.plan)

    def _end_pause(self, t_s: float, d: Decision, why: str) -> Decision:
        """No restart: the run ends with ``no_safe_continuation``, naming the tried restart.

        A final stop whose drift the twin predicts within the margin is made after a harbour
        swim, the gait swum again for it; during the brake the firmware's phase is frozen and
        resumes from there, so the harbour swims the gait with that phase (docs/planning.md,
        "The harbour"). With no harbour and the brake over, the robot holds station instead,
        the gait swum again (:meth:`_station_on`).
        """
        pause = self._pause
        assert pause is not None
        d.stop = "no_safe_continuation"
        d.detail = (f"{pause.detail}; restart {self.restarts + 1} of {self.max_restarts} from rest "
                    f"(stopped at t = {pause.t_halt_s:.2f} s) not made: {why}")
        d.recorded = True
        gait = self.gait
        if pause.braked is not None and not pause.unbraked:
            # the phase resumes where the brake froze it: omega (t - t_s) + frozen
            gait = dataclasses.replace(self.gait, phase_rad=pause.braked.phase_rad
                                       - self.gait.omega_rad_s * t_s)
        harbour = self._stop_safely(t_s, "stop", d.detail, gait)
        if harbour is None and gait is self.gait:
            # no harbour: hold station, the gait swum again (not on the brake's resumed phase,
            # which the station's swims do not have; docs/planning.md, "Holding station
            # (session 21)")
            harbour = (self._station_on(t_s, "stop", d.detail)
                       or self._least_bad_on(t_s, "stop", d.detail))
            if harbour is not None:
                self.estimator.gait = self.gait
        if harbour is None:
            return d
        if pause.job is not None and pause.job.deadline is not None:
            pause.job.deadline.cut_to(time.monotonic())
        self._pause = None
        harbour.restart = True
        return harbour

    # -- contact ---------------------------------------------------------------------------------

    def _contact(self, t_s: float) -> str | None:
        """Whether the measured body touches the world: its own outline, as the look-ahead's.

        Each link the stadium of its own length and width (:func:`outline_clearance_m`), the
        geometry the look-ahead judges the present plan with.
        """
        pose = self.estimator.latest_pose()
        assert pose is not None
        n = self.model.n_links
        state = np.concatenate([pose, np.zeros(n + 2)])
        gap = float(outline_clearance_m(self.world, self.model, state[None])[0])
        self._touching = self._touching + 1 if gap <= 0.0 else 0
        if self._touching >= self.contact_frames:
            return (f"the body touched an obstacle or wall at t = {t_s:.2f} s, at "
                    f"({pose[n]:.2f}, {pose[n + 1]:.2f}) m ({-gap * 1000:.0f} mm deep, from the "
                    "camera)")
        return None

    # -- replans -------------------------------------------------------------------------------

    def _may_retry(self, t_s: float) -> bool:
        """A failed replan may be followed at once by another instead of a stop.

        It may while failures are left and the predicted contact is far enough ahead for
        another replan to steer before it (:meth:`_retry_need_s`), with room left for a stop
        should that one fail too (:attr:`stop_allowance_s`).
        """
        return (self.failures < self.max_failures
                and self._danger_at_s() - t_s >= self._retry_need_s() + self.stop_allowance_s)

    def _backoff_yields(self, t_s: float, busy: bool) -> bool:
        """A back-off after a failed replan gives way to a replan (or a stop) now.

        It does when the latest look-ahead puts the capsule within the margin (with the current
        estimate's drift allowance) before a replan asked for when the back-off ends could
        steer: its end plus the replanner's own need (:meth:`_retry_need_s`; without a budget
        nothing bounds that, so it always does). Until session 9 the back-off asked for no
        replan whatever the look-ahead said (seed 12041's contact, docs/planning.md).
        """
        return (self.failures > 0 and not busy and t_s < self._next_try_s
                and self._near_at_s < (self._next_try_s + self._retry_need_s()
                                       + self.stop_allowance_s))

    def _retry_need_s(self) -> float:
        """The robot's time a replan asked for now may take before its plan steers, at most.

        Its budget, the shift repair's grace past it and a lead for the new plan to turn the
        robot (:attr:`lead_s`); inf without a budget or with ``retry_before_contact`` off (then
        a failed replan with contact ahead always stops the robot, as before).
        """
        if self.replan_budget_s is None or not self.retry_before_contact:
            return math.inf
        return (self.replan_budget_s + (SHIFT_GRACE_S if self.shift_repair else 0.0)
                + self.lead_s)

    def _budget_for(self, reason: str) -> float | None:
        """The budget of a replan asked for with ``reason`` (calm and early budgets)."""
        base = self.replan_budget_s
        if reason == "early_margin" and base is not None and self.early_budget_s is not None:
            return max(base, self.early_budget_s)
        if (base is None or self.calm_budget_s is None or reason != "current_estimate"
                or self.failures > 0):
            return base
        return max(base, self.calm_budget_s)

    def _calm(self, job: _Job) -> bool:
        """Whether ``job`` was given the calm budget (:attr:`calm_budget_s`).

        Its start is its budget away, so contact predicted before its plan could steer stops
        the robot without waiting for that start.
        """
        return (job.budget_s is not None and self.replan_budget_s is not None
                and job.budget_s > self.replan_budget_s and job.reason != "early_margin")

    def _cuttable(self, job: _Job) -> bool:
        """Whether an urgent replan cuts ``job`` short: a calm replan or an early one."""
        return job.deadline is not None and (self._calm(job) or job.reason == "early_margin")

    def _early_allowed(self, t_s: float) -> bool:
        """Whether an early replan may be asked for now (:attr:`early_margin_m`).

        Not within the back-off of a failed replan, nor within an early replan's own back-off.
        After a failed replan that kept the plan (its back-off over), it may: on development
        seed 21011 the robot swam 13 s on a plan kept after a failure, its capsule's gap
        falling from 150 to 28 mm before the next urgent replan.
        """
        return (self.early_margin_m is not None and t_s >= self._next_try_s
                and t_s >= self._next_early_s)

    def _early_held_up(self, job: _Job) -> bool:
        """Whether an early ``job``, cut short, is not back within :data:`CUT_RETURN_S`.

        Cut by any urgent need, it otherwise stops the robot only as the rules after a failure
        would without it; not back in time, the robot is stopped as for a late replan.
        """
        cut_at = None if job.deadline is None else job.deadline.cut_at_s
        return cut_at is not None and time.monotonic() > cut_at + CUT_RETURN_S

    def _calm_holds_up(self, job: _Job, t_s: float) -> bool:
        """Whether a calm ``job`` keeps the urgent replan a predicted contact needs waiting.

        Not once cut short (:meth:`_cut`) while the contact is far enough ahead for the urgent
        replan to steer before it, and the worker is back within :data:`CUT_RETURN_S`; else
        (uncut, the contact too near, or the worker not back) the robot is stopped as for a late
        replan.
        """
        if not self._calm(job):
            return False
        if job.cut_for is None or job.deadline is None or job.deadline.cut_at_s is None:
            return True
        back_by_s = job.deadline.cut_at_s + CUT_RETURN_S  # wall time, as the cut
        return time.monotonic() > back_by_s or not self._may_retry(t_s)

    def _cut(self, job: _Job, reason: str, t_s: float) -> None:
        """Cut a calm (or early) replan short for a ``reason`` replan asked for once it is back."""
        if job.deadline is None:
            return
        job.deadline.cut_to(time.monotonic())
        job.cut_for, job.t_cut_s = reason, t_s
        self._urgent_after_cut = reason
        log.info("a %s replan is needed at t = %.2f s: the %s replan asked for at t = %.2f s "
                 "is cut short", reason, t_s, job.reason, job.t_request_s)

    def _off_corridor(self, pose: FloatArray) -> bool:
        """Whether the pose's centre of mass is outside the present plan's corridor."""
        return float(distance_to_path(self.path, np.asarray([pose[:2]]))[0]) > self.corridor_m

    def _lead_steps(self) -> int:
        """Steps from a request to the predicted start: a whole number of restart periods."""
        period = self.planner.twin.restart_steps or 1
        lead = min(max(self.lead_s, 1.5 * self._last_wall_s), self.max_lead_s)
        steps = int(math.ceil(lead / self.planner.twin.dt_s / period)) * period
        return max(steps, period)

    def _request(self, t_s: float, est: BodyEstimate, left: list[tuple[float, float]],
                 reason: str) -> None:
        """Submit a replan from the state predicted a lead ahead."""
        dt = self.planner.twin.dt_s
        period = self.planner.twin.restart_steps or 1
        # the predicted start: the first restart point (control update and frame) after the lead
        now_step = int(round(est.t_s / dt))
        budget = self._budget_for(reason)
        lead = self._lead_steps()
        if budget is not None and self.replan_budget_s is not None and (
                budget > self.replan_budget_s):
            # a calm replan starts from the state predicted for when its budget ends
            lead = max(lead, int(math.ceil(budget / dt)))
        start_step = int(math.ceil((now_step + lead) / period)) * period
        extra = self.current.value_m_s.copy() if self.estimate_current else np.zeros(2)
        wall = time.monotonic()
        deadline = None if budget is None else Deadline(wall + budget)
        future = self._worker.submit(self._replan_and_judge, est, list(left), start_step, extra,
                                     self._guide, deadline, reason)
        due = (math.inf if budget is None or not self.retry_before_contact
               else t_s + budget + (SHIFT_GRACE_S if self.shift_repair else 0.0))
        self._job = _Job(future, t_s, wall, start_step * dt, reason, due, budget, deadline)
        log.info("%s at t = %.2f s; replanning from the state predicted for t = %.2f s",
                 reason, t_s, start_step * dt)

    def _replan(self, est: BodyEstimate, left: list[tuple[float, float]], start_step: int,
                extra: FloatArray, guide: Guide | None = None,
                deadline_s: SupportsFloat | None = None, fallbacks: bool = True
                ) -> tuple[Outcome, FloatArray, float, float, FloatArray, float, int]:
        """On the worker: predict the state at the start step with the twin, then plan from it.

        The prediction starts with the loop's guidance state ``guide``; the plan is searched from
        the guidance state predicted for its start: its first leg from the start's centre of mass
        (a new leg), with the integral the controller will hold then (:func:`predict_start`), so
        the integral is carried across the replan as across a waypoint (docs/model.md section 4).

        A start refused as blocked is tried again a restart period later along the present
        waypoints (``blocked_retries`` times): the moving body swims on, and its predicted
        state a moment later may be clear. A start near the goal that gives no plan is tried
        again with the goal approach's planner. Returns the start step actually used.

        ``deadline_s`` (a ``time.monotonic()`` time, :attr:`replan_budget_s` after the request)
        bounds every search; the retries, the goal approach and the recovery are tried only
        while time is left before it. With ``fallbacks`` False (an early replan) only the planner
        is tried: a plan at the world's margin or none, never the goal approach's, the
        recovery's or a shifted route, whose margins are the look-ahead's own 10 mm, to replace
        a plan the look-ahead still swims clear by that margin (docs/planning.md, "An earlier
        replan").
        """
        wall0, cpu0 = time.perf_counter(), time.thread_time()
        tiers: dict[str, float] = {}  # wall time of each part, recorded with the replan
        mark = [wall0]

        def took(name: str) -> None:
            now = time.perf_counter()
            tiers[name] = round(tiers.get(name, 0.0) + now - mark[0], 3)
            mark[0] = now

        self._prepare_planner(extra)
        took("planner_built")
        planner = self.planner
        period = planner.twin.restart_steps or 1
        predicted = predict_start(planner.twin, est, left, start_step, guide=guide)
        assert predicted is not None  # allow_end: the run's last state when it ends early
        state, integral = predicted
        took("prediction")
        # a start inside the check's margin (every plan's check fails at its first sample) goes
        # straight to the escape; one a little outside it gets the escape after the other tiers
        # (docs/planning.md, "An escape from inside the margin")
        gap = self._escape_gap(state) if fallbacks else None
        trapped = gap is not None and gap <= planner.check_margin_m
        if trapped:
            assert gap is not None
            outcome = self._escape(state, start_step, integral, extra, gap, deadline_s)
            took("escape")
        else:
            outcome = planner.plan(state, start_step, guide=leg_start_guide(
                state, self.model.n_links, integral), deadline_s=deadline_s)
        for _ in range(0 if trapped else self.blocked_retries):
            if outcome.status != "blocked_start" or not _time_left(deadline_s):
                break
            later = predict_start(planner.twin, est, left, start_step + period, allow_end=False,
                                  guide=guide)
            if later is None:
                break
            log.info("replan start blocked at t = %.2f s; trying %.2f s",
                     start_step * planner.twin.dt_s, (start_step + period) * planner.twin.dt_s)
            start_step, (state, integral) = start_step + period, later
            outcome = planner.plan(state, start_step, guide=leg_start_guide(
                state, self.model.n_links, integral), deadline_s=deadline_s)
        took("planner")
        # the tighter margin: near the goal after any failure of the search or check; anywhere
        # when the search ran out of poses (a start so close to an obstacle that every manoeuvre
        # from it breaks the world's margin: the predicted start of a robot the water pushed on)
        # (not after a search stopped by the budget: the planner keeps only its check's time
        # free before the deadline, no room for another search and check)
        if fallbacks and not trapped and not outcome.found and outcome.status not in (
                *REFUSED_FROM_STATE, "out_of_time") and (
                _time_left(deadline_s)) and (outcome.status == "exhausted"
                                             or self._near_goal(state)):
            goal_planner = self._goal_planner_in(extra)
            if goal_planner is not None and _time_left(deadline_s):
                approach = goal_planner.plan(state, start_step, guide=leg_start_guide(
                    state, self.model.n_links, integral), deadline_s=deadline_s)
                log.info("goal approach from t = %.2f s: %s", start_step * planner.twin.dt_s,
                         approach.message)
                took("goal_approach")
                if approach.found:
                    outcome = approach
                else:
                    outcome = dataclasses.replace(outcome, message=(
                        f"{outcome.message}; with the goal approach's margin: {approach.message}"))
        # the recovery: sharper turns, the goal approach's margin, a bounded search; only when
        # everything else found nothing (docs/planning.md, "The recovery replan")
        if (fallbacks and not trapped and not outcome.found
                and outcome.status not in (*REFUSED_FROM_STATE, "out_of_time")
                and _time_left(deadline_s)):
            recovery = self._planner_in("recovery", self.recovery_planner_for, extra)
            if recovery is not None and _time_left(deadline_s):
                rescue = recovery.plan(state, start_step, guide=leg_start_guide(
                    state, self.model.n_links, integral), deadline_s=deadline_s)
                log.info("recovery replan from t = %.2f s: %s", start_step * planner.twin.dt_s,
                         rescue.message)
                took("recovery")
                if rescue.found:
                    rescue.message = f"recovery: {rescue.message}"
                    outcome = rescue
                else:
                    outcome = dataclasses.replace(outcome, message=(
                        f"{outcome.message}; with the recovery's actions: {rescue.message}"))
        if (gap is not None and not trapped and not outcome.found
                and outcome.status not in (*REFUSED_FROM_STATE, "out_of_time")
                and _time_left(deadline_s)):
            escaped = self._escape(state, start_step, integral, extra, gap, deadline_s)
            took("escape")
            outcome = escaped if escaped.found else dataclasses.replace(
                outcome, message=f"{outcome.message}; {escaped.message}")
        # the shift repair: the present route, its waypoints moved against the water that pushes
        # it into something (docs/planning.md, "The shift repair"); not from inside the check's
        # margin, where every route's check fails at its first sample
        if (fallbacks and self.shift_repair and not trapped and not outcome.found
                and outcome.status not in REFUSED_FROM_STATE and not _was_cut(deadline_s)):
            # also when the searches used up the budget (a failing search often does): the
            # repair's swims may overrun it by SHIFT_GRACE_S, a plan a little late rather than none
            repair_deadline = (None if deadline_s is None
                               else max(float(deadline_s), time.monotonic()) + SHIFT_GRACE_S)
            remaining = (self.outcome.plan.cost_s - start_step * planner.twin.dt_s
                         if self.outcome.found else math.nan)
            horizon = (min(1.5 * remaining + 5.0, 90.0) if math.isfinite(remaining) else 60.0)
            repaired = shift_repair(planner, state, start_step, leg_start_guide(
                state, self.model.n_links, integral), left, max(horizon, self.replan_horizon_s),
                repair_deadline)
            took("shift_repair")
            log.info("shift repair from t = %.2f s: %s", start_step * planner.twin.dt_s,
                     "none passed" if repaired is None else repaired.message)
            if repaired is not None:
                outcome = repaired
            else:
                outcome = dataclasses.replace(outcome, message=(
                    f"{outcome.message}; no shift of the present waypoints passed"))
        self._last_tiers = tiers
        return (outcome, state, time.perf_counter() - wall0, time.thread_time() - cpu0,
                self._planner_current.copy(), time.monotonic(), start_step)

    def _escape_gap(self, state: FloatArray,
                    make: Callable[[FloatArray], Planner] | None = None) -> float | None:
        """The start's capsule gap when an escape may plan from it, else None.

        An escape is for a start inside the check's margin or within
        :data:`ESCAPE_TOLERANCE_M` of it, and more than :data:`ESCAPE_FLOOR_M` clear (docs/planning.md,
        "An escape from inside the margin").
        """
        if (make or self.escape_planner_for) is None:
            return None
        gap = float(body_clearance_m(self.world, self.planner.clearance, self.model,
                                     np.asarray(state, dtype=float)[None])[0])
        if not ESCAPE_FLOOR_M < gap < self.planner.check_margin_m + ESCAPE_TOLERANCE_M:
            return None
        return gap

    def _escape(self, state: FloatArray, start_step: int, integral: tuple[float, float],
                extra: FloatArray, gap: float, deadline_s: SupportsFloat | None,
                make: Callable[[FloatArray], Planner] | None = None) -> Outcome:
        """On the worker: the escape's plan from a start ``gap`` clear, judged with the ramp.

        The escape's planner (``escape_planner_for``: the recovery's actions and bounded search,
        the search's margin ramped from the start's to the world's over :data:`ESCAPE_RAMP_S`,
        its check's margin :data:`ESCAPE_FLOOR_M`) plans from ``state``; a plan it finds is kept
        only when every run of its check keeps the capsule more than
        :func:`escape_margin_m` from everything at every step (docs/planning.md, "An escape from
        inside the margin").
        """
        escape = self._planner_in("escape", make or self.escape_planner_for, extra)
        if escape is None or not _time_left(deadline_s):
            why = "no escape planner" if escape is None else "no time left"
            status = "exhausted" if escape is None else "out_of_time"
            return Outcome(Plan(False, status, f"no escape: {why}"), status, f"no escape: {why}")
        out = escape.plan(state, start_step, guide=leg_start_guide(
            state, self.model.n_links, integral), deadline_s=deadline_s)
        log.info("escape from t = %.2f s, the capsule %.0f mm clear: %s",
                 start_step * escape.twin.dt_s, gap * 1000, out.message)
        if not out.found:
            return dataclasses.replace(out, message=(
                f"escape from {gap * 1000:.0f} mm: {out.message}"))
        full = self.planner.check_margin_m
        least = math.inf
        for run in out.checks:
            clear = body_clearance_m(escape.world, escape.clearance, self.model, run.states)
            margin = escape_margin_m(run.t_s - run.t_s[0], gap, full)
            excess = clear - margin
            if not np.all(excess > 0.0):
                at = int(np.argmax(excess <= 0.0))
                msg = (f"escape from {gap * 1000:.0f} mm: {out.message}; but run {run.label} "
                       f"came within {max(clear[at], 0.0) * 1000:.0f} mm at "
                       f"{run.t_s[at] - run.t_s[0]:.1f} s, inside the escape's "
                       f"{margin[at] * 1000:.0f} mm")
                return Outcome(dataclasses.replace(out.plan, found=False, status="check_failed",
                                                   message=msg), "check_failed", msg, out.checks)
            least = min(least, float(excess.min()))
        out.message = (f"escape from {gap * 1000:.0f} mm (every check run above the margin "
                       f"ramped to {full * 1000:.0f} mm over {ESCAPE_RAMP_S:.0f} s, by at least "
                       f"{least * 1000:.0f} mm): {out.message}")
        return out

    def _prepare_planner(self, extra: FloatArray) -> None:
        """On the replan worker: the planner in the world's current plus ``extra``.

        A new one only when ``extra`` moved by 5 mm/s or more from the present planner's. Also
        run as soon as the current estimate moves that far (:meth:`_estimate_current`), so a
        replan that comes later finds it built: building one took 0.4-0.9 s of a replan's 1 s
        on the loaded machine (docs/planning.md, "The replan's deadline").
        """
        if float(np.hypot(*(extra - self._planner_current))) >= PLANNER_REBUILD_M_S:
            self.planner = self.planner_for(extra)
            self._planner_current = extra
            self._planned = (self.planner, extra)
        # the goal approach's and the recovery's planners in the same water, built here too
        # (ahead of the replans when called from the estimate's prebuild or at the start), not
        # inside a replan after its main search has used the budget
        self._goal_planner_in(self._planner_current)
        self._planner_in("recovery", self.recovery_planner_for, self._planner_current)
        self._planner_in("escape", self.escape_planner_for, self._planner_current)

    def _replan_and_judge(self, est: BodyEstimate, left: list[tuple[float, float]],
                          start_step: int, extra: FloatArray, guide: Guide | None = None,
                          deadline_s: SupportsFloat | None = None, reason: str = ""
                          ) -> tuple[tuple, Ahead | None]:
        """On the worker: the replan and, when it fails, a look-ahead of the present waypoints.

        The look-ahead from the same estimate decides whether the robot may keep its present
        plan (:meth:`_collect`), so a failure is never judged on a stale or missing one. Not
        swum for a replan of :data:`EARLY_REASONS` (its failure keeps the plan unjudged): the
        worker is then free at once for an urgent replan. An early replan (``reason``
        ``early_margin``) tries the planner alone (:meth:`_replan`'s ``fallbacks``).
        """
        result = (self._replan(est, left, start_step, extra, guide, deadline_s, fallbacks=False)
                  if reason == "early_margin"
                  else self._replan(est, left, start_step, extra, guide, deadline_s))
        if result[0].found or self.lookahead_s <= 0 or reason in EARLY_REASONS:
            return result, None
        return result, self._look_ahead(est, left, self.current.value_m_s.copy(), guide)

    def _stale(self, t_s: float, t_start_s: float, path: FloatArray) -> bool:
        """A plan ready more than a restart period after its start, the robot off its corridor."""
        period_s = (self.planner.twin.restart_steps or 1) * self.planner.twin.dt_s
        pose = self.estimator.latest_pose()
        if t_s - t_start_s <= period_s or pose is None:
            return False
        n = self.model.n_links
        return float(distance_to_path(path, np.asarray([pose[n : n + 2]]))[0]) > self.corridor_m

    def _near_goal(self, state: FloatArray) -> bool:
        """The state's centre of mass within ``goal_approach_m`` of the goal disc's edge."""
        n = self.model.n_links
        goal = self.world.goal
        d = math.hypot(state[n] - goal.position_m[0], state[n + 1] - goal.position_m[1])
        return d - goal.radius_m <= self.goal_approach_m

    def _goal_planner_in(self, extra: FloatArray) -> Planner | None:
        """The goal approach's planner in the world's current plus ``extra`` (cached)."""
        return self._planner_in("goal approach", self.goal_planner_for, extra)

    def _planner_in(self, name: str, make: Callable[[FloatArray], Planner] | None,
                    extra: FloatArray) -> Planner | None:
        """``make``'s planner in the world's current plus ``extra``, cached under ``name``.

        A new one only when the estimate moved by 5 mm/s or more since the cached one's.
        """
        if make is None:
            return None
        cached = self._extra_planners.get(name)
        if cached is None or float(np.hypot(*(extra - cached[1]))) >= PLANNER_REBUILD_M_S:
            cached = (make(extra), extra)
            self._extra_planners[name] = cached
        return cached[0]

    def _collect(self, t_s: float, d: Decision) -> bool:
        """Take a finished replan once the robot's clock has passed its wall time."""
        job = self._job
        if job is None or not job.future.done():
            return False
        result, judged = job.future.result()
        outcome, state, _, cpu, extra, done, start_step = result
        job.t_start_s = start_step * self.planner.twin.dt_s
        wall = done - job.wall_request_s  # from the request: queueing and prediction included
        if t_s - job.t_request_s < wall - 1e-9:
            return False  # over sim://: the robot has not yet lived the planner's time
        self._job = None
        self._last_wall_s = wall
        self.events.append(self._event("replan", job.reason, job.t_request_s, job.t_start_s,
                                       job.t_request_s + wall, state, outcome, wall, cpu, extra))
        if job.budget_s is not None:
            self.events[-1]["budget_s"] = job.budget_s
        if job.cut_for is not None:
            self.events[-1]["cut_for"] = job.cut_for
            self.events[-1]["t_cut_s"] = job.t_cut_s
        tiers, self._last_tiers = self._last_tiers, {}
        if tiers:
            self.events[-1]["parts_wall_s"] = tiers
        if outcome.found and self._stale(t_s, job.t_start_s, corridor_path(outcome.plan)):
            # ready long after the state it was planned from, and the robot is no longer in its
            # corridor: it would be left at once; the robot keeps its plan, and replans now
            self.events[-1]["status"] = "stale"
            self.events[-1]["message"] = (
                f"ready at t = {t_s:.2f} s, {t_s - job.t_start_s:.2f} s after its start, with the "
                f"robot outside its corridor: not used ({outcome.message})")
            log.warning("replan ready %.2f s late, robot off its corridor: not used",
                        t_s - job.t_start_s)
            if job.reason not in EARLY_REASONS:  # asked while the plan swam clear: none
                self.failures += 1  # a failure for the stops on contact ahead, but no back-off
            self._next_try_s = t_s
            return True
        if job.reason == "early_margin" and job.cut_for is None:
            # found or not, the next early replan waits (1, 2, then 4 s) until a look-ahead swims
            # the plan clear of the early margin: a plan found with a margin near the early one
            # would otherwise be replanned at every look-ahead (docs/planning.md, "An earlier
            # replan")
            self._next_early_s = t_s + EARLY_BACKOFF_S * 2 ** min(self._early_in_row, 2)
            self._early_in_row += 1
        if outcome.found:
            self._take_plan(outcome, extra)
            self._pending = (job.t_start_s, list(outcome.plan.waypoints_m),
                             outcome.plan.start_guide)
            log.info("replanned at t = %.2f s (%.2f s wall): %s", t_s, wall, outcome.message)
            return True
        if job.reason == "current_estimate":
            # asked for by the estimate alone, on a plan not known to go wrong: keep the plan,
            # and ask again only when the estimate moves on (the look-ahead still guards it);
            # one cut short for an urgent replan did not fail, and may be asked for again
            if job.cut_for is None:
                self._plan_current = extra
            log.info("replanning in the estimated current failed (%s); the robot keeps its plan",
                     outcome.status)
            return True
        if job.reason == "early_margin":
            # asked for while the look-ahead swam the present plan clear by its margin: keep the
            # plan, count no failure (the look-ahead still guards it: within its margin, the
            # urgent replan), and wait before the next early one (docs/planning.md, "An earlier
            # replan"); one cut short for an urgent replan leaves the back-off as it was
            log.info("the early replan found nothing (%s); the robot keeps its plan, next early "
                     "replan from t = %.2f s", outcome.status, self._next_early_s)
            return True
        self.failures += 1
        if judged is not None:
            self._adopt(judged, job.t_request_s, t_s)
        if self._present_plan_hits(t_s) and self._stop_slips_away(t_s, d):
            return True  # stopped while the stop keeps clear, instead of a retry
        if self._present_plan_hits(t_s) and self._may_retry(t_s):
            # the present plan swims into contact (or within the margin), but far enough ahead
            # for another replan to steer before it: replan again at once (docs/planning.md,
            # "Retried before contact")
            self._next_try_s = t_s
            self._retry_now = True
            log.warning("replanning failed at t = %.2f s (%s) with the twin swimming the "
                        "present plan %s: replanning again at once", t_s, outcome.status,
                        self._verdict_text(t_s))
            return True
        if self._present_plan_hits(t_s):
            d.stop = "no_safe_continuation"
            d.detail = (f"replanning at t = {job.t_request_s:.2f} s failed and the twin swims the "
                        f"present plan {self._verdict_text(t_s)}: {outcome.message}")
            return True
        final = self.failures >= self.max_failures or outcome.status in REFUSED_FROM_STATE
        if final and self._present_plan_safe(t_s):
            # no new plan (or none from this state), but the twin swims the present one on
            # without contact: keep it, and try again later from a state further on
            log.warning("replanning failed %d times (%s); the present plan is predicted clear, "
                        "so the robot keeps it", self.failures, outcome.status)
            self._next_try_s = t_s + self.backoff_s * 2 ** (min(self.failures, self.max_failures)
                                                            - 1)
            return True
        if outcome.status in REFUSED_FROM_STATE or self.failures >= self.max_failures:
            d.stop = "no_safe_continuation"
            d.detail = (f"replanning at t = {job.t_request_s:.2f} s found no safe continuation "
                        f"({self.failures} failed in a row): {outcome.message}")
            return True
        wait = self.backoff_s * 2 ** (self.failures - 1)
        self._next_try_s = t_s + wait
        log.warning("replanning failed at t = %.2f s (%s); next try in %.1f s", t_s,
                    outcome.message, wait)
        return True

    def _whole_plan_fails(self, est: BodyEstimate, left: list[tuple[float, float]],
                          busy: bool) -> bool:
        """Whether the rest of the present plan, swum in the moved current estimate, fails.

        When the estimate has moved ``replan_current_change_m_s`` from the current the present
        plan was searched in, the twin swims the rest of the plan in the estimate (on the side
        worker) to its goal; a capsule within ``lookahead_margin_m`` of anything on the way
        asks for a replan. A plan that the new water does not break is kept: a replan in the
        estimate would often pick another route, and with it new risks.
        """
        job = self._whole_job
        if job is not None:
            if not job[0].done():
                return False
            self._whole_job = None
            judged = job[0].result()
            self._plan_current = job[1]
            return judged is not None and judged[1] < self.lookahead_margin_m
        if (busy or not self.estimate_current or self.replan_current_change_m_s <= 0
                or float(np.hypot(*(self.current.value_m_s - self._plan_current)))
                < self.replan_current_change_m_s):
            return False
        extra = self.current.value_m_s.copy()
        remaining = self.outcome.plan.cost_s - est.t_s if self.outcome.found else math.nan
        horizon = min(1.5 * remaining + 5.0, 90.0) if math.isfinite(remaining) else 60.0
        self._whole_job = (self._side.submit(self._look_ahead, est, list(left), extra,
                                             self._guide, max(horizon, self.replan_horizon_s)),
                           extra)
        return False

    def _look_ahead(self, est: BodyEstimate, left: list[tuple[float, float]],
                    extra: FloatArray, guide: Guide | None = None,
                    horizon_s: float | None = None) -> Ahead | None:
        """On the worker: the smallest clearances the twin predicts ahead of the estimate.

        Returns the body's own outline's over ``lookahead_s`` with the time of its first
        contact there, and the planner's capsule's over ``horizon_s`` (default
        ``replan_horizon_s``) with the time it first comes within the look-ahead's margin, or
        None without a run. Without ``horizon_s`` (the look-ahead that guards the robot) the
        capsule's gap at each moment is less the drift the current estimate's uncertainty
        allows by then (:func:`drift_allowance_m`), and with an early margin the twin swims on
        to ``early_horizon_s`` for the capsule's bare gap (:attr:`Ahead.bare_m`).
        """
        twin = self._twin_in(extra)
        now = int(round(est.t_s / twin.dt_s))
        guard = horizon_s is None  # the look-ahead that guards the robot
        horizon = (horizon_s if horizon_s is not None else self.replan_horizon_s
                   if self.early_margin_m is None
                   else max(self.replan_horizon_s, self.early_horizon_s))
        steps = int(round(horizon / twin.dt_s))
        stride = 3
        runs = twin.run([left], steps * twin.dt_s, states=est.state[None], start_steps=[now],
                        stride=stride, guidance=_guidance_arg(twin, guide))
        states = runs.states[0]
        states = states[np.isfinite(states[:, 0])]
        # the run ends where the goal test first holds (the loop stops the robot there): a goal
        # by a wall is not a contact of the twin swimming on to accept its last waypoint
        n = self.model.n_links
        inside = np.flatnonzero(goal_mask(self.world, states[:, n : n + 2]))
        if inside.size:
            states = states[: int(inside[0]) + 1]
        if not len(states):
            return None
        # the body's own outline, as the run's contact test, judges stops and keeping the plan
        # over the near future; the planner's capsule (a half width beyond the tips) asks for
        # replans over the longer horizon: docs/planning.md
        near = states[: int(round(self.lookahead_s / twin.dt_s)) // stride + 1]
        planner = self._planned[0]
        outline = outline_clearance_m(self.world, self.model, near)
        touching = np.flatnonzero(outline <= 0.0)
        contact = (now + int(touching[0]) * stride) * twin.dt_s if touching.size else math.inf
        # exact wherever the gap may be within the margin and the largest allowance (the
        # capsule's gap is otherwise a lower bound away from its smallest value)
        capsule = body_clearance_m(planner.world, planner.clearance, planner.model, states,
                                   max(self.lookahead_margin_m + LOOKAHEAD_DRIFT_MAX_M,
                                       self.early_margin_m or 0.0))
        bare = float(capsule.min())  # the early margin's, over the early horizon
        if guard:
            # the look-ahead that guards the robot: its margin grows along the horizon with the
            # drift the current estimate's uncertainty allows (docs/planning.md); the urgent
            # replan is asked over the replan horizon only
            capsule = capsule[: int(round(self.replan_horizon_s / twin.dt_s)) // stride + 1]
            ahead_s = np.arange(len(capsule), dtype=np.float64) * (stride * twin.dt_s)
            capsule = np.subtract(capsule, drift_allowance_m(
                current_spread_m_s(self.current.history), ahead_s))
        within = np.flatnonzero(capsule < self.lookahead_margin_m)
        near_s = (now + int(within[0]) * stride) * twin.dt_s if within.size else math.inf
        stop_now = stop_later = math.nan
        if guard and within.size and self.stop_in_reach:
            stop_now, stop_later = self._stops_ahead(twin, est, states, stride)
        return Ahead(float(outline.min()), float(capsule.min()), contact, near_s, bare,
                     stop_now, stop_later)

    def _stops_ahead(self, twin: Twin, est: BodyEstimate, states: FloatArray, stride: int
                     ) -> tuple[float, float]:
        """The stop decided now and after a retried replan's need on the present plan: gaps.

        ``states``: the look-ahead's run of the present plan from ``est`` (every ``stride``
        steps). The stop is the pause's while restarts are left, else the final stop's, swum
        and judged as the harbour's (:meth:`_stop_safely`). The later one is nan when the run
        ends first (the goal).
        """
        kind = "pause" if self.restarts < self.max_restarts else "stop"
        gap_of = self._stop_gaps()
        window = self._stop_window(kind)
        now = stop_gap_m(twin, self.gait, est.state, est.t_s, window, gap_of, stride)
        reach = min(self._retry_need_s(), self.lookahead_s)
        k = int(round(reach / (stride * twin.dt_s)))
        if k >= len(states):
            return now, math.nan
        later = stop_gap_m(twin, self.gait, states[k], est.t_s + k * stride * twin.dt_s, window,
                           gap_of, stride)
        return now, later

    def _stop_gaps(self) -> Callable[[FloatArray, FloatArray], FloatArray]:
        """How a stop's samples are judged: the body outline's gap less the current's drift.

        The outline's gap to obstacles and walls, less the drift the current estimate's spread
        allows by each sample's time ahead (docs/planning.md, "The harbour"); the one judgement
        of the harbour's candidates, the hold's stop and the look-ahead's two stops.
        """
        spread = current_spread_m_s(self.current.history)

        def gap_of(states: FloatArray, ahead_s: FloatArray) -> FloatArray:
            return np.subtract(outline_clearance_m(self.world, self.model, states),
                               drift_allowance_m(spread, ahead_s))

        return gap_of

    def _twin_in(self, extra: FloatArray, gait: Gait | None = None) -> Twin:
        """The planner's twin in the world's current plus the estimate ``extra`` (and ``gait``)."""
        planner, planner_extra = self._planned  # one read: the replan thread may swap it
        twin = planner.twin
        current = np.add(planner.world.current_m_s, extra - planner_extra)
        return Twin(twin.robot, twin.coefficients, gait or twin.gait, twin.options,
                    (float(current[0]), float(current[1])), twin.acceptance_radius_m, twin.threads,
                    twin.model)

    def _danger_at_s(self) -> float:
        """When the latest look-ahead puts the body in danger on its present plan.

        The outline's first contact; without one (an outline within the margin but clear), when
        the capsule first comes within the margin (plus the drift allowance).
        """
        return self._contact_at_s if self._contact_at_s < math.inf else self._near_at_s

    def _verdict_text(self, t_s: float) -> str:
        """The latest look-ahead's verdict, for a stop's message."""
        gap = self._last_gap[1]
        if gap is None:
            return "with no look-ahead run"
        ahead = self._danger_at_s() - t_s
        first = f", first in {ahead:.1f} s" if math.isfinite(ahead) else ""
        if gap <= 0.0:
            return (f"into an obstacle or wall within {self.lookahead_s:g} s "
                    f"({-gap * 1000:.0f} mm deep{first})")
        return (f"within {gap * 1000:.0f} mm of an obstacle or wall within {self.lookahead_s:g} s "
                f"(under the look-ahead's {self.lookahead_margin_m * 1000:.0f} mm margin{first})")

    def _adopt(self, judged: tuple[float, ...] | None, from_s: float, t_s: float) -> None:
        """Take a look-ahead's verdict, swum from the estimate at ``from_s``, unless older.

        A failed replan's own look-ahead swims from the estimate of its request, which may be
        more than a second older than the look-aheads run on the side meanwhile: the newest
        estimate's verdict judges the present plan (on seed 18036 the replan's older verdict
        kept a plan the newer ones swam within millimetres of an obstacle, and the body touched).
        """
        if from_s < self._last_gap[0]:
            log.debug("look-ahead from t = %.2f s not taken: the one from t = %.2f s is newer",
                      from_s, self._last_gap[0])
            return
        self._last_gap = (from_s, None if judged is None else judged[0])
        self._stops = ((from_s, float(judged[5]), float(judged[6]))
                       if judged is not None and len(judged) > 6 else (from_s, math.nan, math.nan))
        self._contact_at_s = math.inf if judged is None else contact_time_s(judged, t_s)
        self._near_at_s = (math.inf if judged is None
                           else near_time_s(judged, t_s, self.lookahead_margin_m))
        if judged is not None:
            log.debug("look-ahead from t = %.2f s (taken at %.2f s): outline %.1f mm, capsule "
                      "%.1f mm (%.1f mm bare), contact at %.2f s, near at %.2f s", from_s, t_s,
                      judged[0] * 1000, judged[1] * 1000, early_gap_m(judged) * 1000,
                      self._contact_at_s, self._near_at_s)

    def _present_plan_hits(self, t_s: float) -> bool:
        """The last look-ahead, at most 1.5 s old, swam the present waypoints within the margin.

        Within ``lookahead_margin_m`` of an obstacle or wall counts as contact: the twin's outline
        is not exact in water it does not know (docs/planning.md, "The outline's margin").
        """
        t_gap, gap = self._last_gap
        return gap is not None and t_s - t_gap <= 1.5 and gap < self.lookahead_margin_m

    def _present_plan_safe(self, t_s: float) -> bool:
        """The last look-ahead, at most 1.5 s old, swam the present waypoints clear of contact.

        Clear by the look-ahead's margin, not merely positive: on the development seeds, keeping
        a plan the twin swam 3 mm from a wall ended in a contact stop 3 s later.
        """
        t_gap, gap = self._last_gap
        safe = gap is not None and t_s - t_gap <= 1.5 and gap >= self.lookahead_margin_m
        log.info("the present plan: look-ahead at t = %.2f s gave %s (now %.2f s): %s", t_gap,
                 "no run" if gap is None else f"{gap * 1000:.0f} mm", t_s,
                 "clear" if safe else "not known clear")
        return safe

    # -- the current -----------------------------------------------------------------------------

    def _estimate_current(self, est: BodyEstimate, left: list[tuple[float, float]],
                          pose: FloatArray) -> bool:
        """Take the windows the twin has swum into the estimate; hand it a window that closed.

        Windows (:meth:`CurrentEstimator.track`) cover frames steering to one waypoint the
        robot faces; each closed one is swum on the side worker, also while a replan runs (on
        the other worker): with replans every few seconds a window waiting for none to run was
        never swum, and the current never estimated.
        """
        if not self.estimate_current:
            return False
        changed = False
        while self._window_jobs and self._window_jobs[0][0].done():
            future, window = self._window_jobs.pop(0)
            predicted = future.result()
            if predicted is not None:
                n = self.model.n_links
                self.current.update(window.end.t_s, predicted, window.end.state[n : n + 2],
                                    window.span_s, window.assumed_m_s)
                changed = True
        if changed and self._job is None and (
                self._prebuild is None or self._prebuild.done()) and float(np.hypot(
                    *(self.current.value_m_s - self._planner_current))) >= PLANNER_REBUILD_M_S:
            # build the planner in the moved estimate now, on the replan worker (a replan asked
            # for meanwhile queues behind it and finds it built), not inside the next replan
            self._prebuild = self._worker.submit(self._prepare_planner,
                                                 self.current.value_m_s.copy())
        closed = self.current.track(est, pose, left[0] if left else None, self._guide)
        if closed is not None:
            self._window_jobs.append((self._side.submit(self._window_prediction, closed),
                                      closed))
        return changed

    def _window_prediction(self, window: CurrentWindow) -> FloatArray | None:
        """On the worker: where the twin puts the centre of mass at the window's end.

        The twin steers to the window's one waypoint; when it reaches it before the window's
        end, it swam another manoeuvre than the robot, and the window is not compared (None).
        """
        twin = self._twin_in(window.assumed_m_s)
        step = int(round(window.end.t_s / twin.dt_s))
        guide = None if window.guide is None else cast(Guide, tuple(window.guide))
        state = predict_state(twin, window.start, [window.waypoint_m], step, allow_end=False,
                              guide=guide)
        if state is None:
            return None
        n = self.model.n_links
        return state[n : n + 2]

    # -- the record ------------------------------------------------------------------------------

    def _event(self, kind: str, reason: str, t_request: float, t_start: float, t_used: float,
               state: FloatArray | None, outcome: Outcome, wall: float, cpu: float,
               extra: FloatArray) -> dict[str, Any]:
        world_current = self.world.current_m_s
        return {
            "kind": kind,
            "reason": reason,
            "t_request_s": round(t_request, 3),
            "t_start_s": round(t_start, 3),
            "t_ready_s": round(t_used, 3),
            "status": outcome.status,
            "message": outcome.message,
            "wall_s": round(wall, 3),
            "cpu_s": None if math.isnan(cpu) else round(cpu, 3),
            "budget_s": (None if kind == "plan" or self.replan_budget_s is None
                         else self.replan_budget_s),
            "start_state": None if state is None else [round(float(v), 5) for v in state],
            "waypoints_m": [[round(x, 4), round(y, 4)] for x, y in outcome.plan.waypoints_m]
            if outcome.found else [],
            "planned_goal_s": round(outcome.plan.cost_s, 2) if outcome.found else None,
            "start_guide": ([round(float(v), 5) for v in outcome.plan.start_guide]
                            if outcome.found and outcome.plan.start_guide is not None else None),
            "current_m_s": [round(float(world_current[0] + extra[0]), 4),
                            round(float(world_current[1] + extra[1]), 4)],
            # the law the plan was searched and checked with (the planner's; an outcome made
            # here, a harbour's or a shift repair's, swims the running plan's law)
            "guidance": outcome.guidance or self.planner.options.guidance.name,
            **({"laws_tried": outcome.laws_tried} if outcome.laws_tried else {}),
        }


def _rounded(value: float, digits: int = 4) -> float | None:
    """A figure for the record: rounded, None when not finite (JSON has no inf)."""
    return round(value, digits) if math.isfinite(value) else None


def _guidance_arg(twin: Twin, guide: Guide | None) -> list[Guide] | None:
    """``Twin.run``'s ``guidance`` for one run from ``guide``: only with an integral law.

    Pure pursuit has no state beyond its waypoints, so its runs are left as they were.
    """
    if guide is None or not twin.options.guidance.integral:
        return None
    return [tuple(float(v) for v in guide)]  # type: ignore[list-item]


def predict_state(twin: Twin, est: BodyEstimate, waypoints: list[tuple[float, float]],
                  step: int, allow_end: bool = True,
                  guide: Guide | None = None) -> FloatArray | None:
    """The twin's prediction of the robot's state at ``step``, from an estimate.

    The robot swims on after the estimate under its own control stack, steering to
    ``waypoints`` (those it has left), in the twin's current and with its first coefficient set.

    Parameters
    ----------
    twin : Twin
    est : BodyEstimate
    waypoints : list of (x, y)
    step : int
        Step of the task to predict (at or after the estimate's).
    allow_end : bool
        When the run ends before ``step`` (the last waypoint accepted), return its last state;
        else None.
    guide : (x, y, I_x, I_y), optional
        The guidance state at the estimate (where the leg to ``waypoints[0]`` starts, the ILOS
        integral); default a leg from the estimate's centre of mass.

    Returns
    -------
    ndarray, shape (2 N + 4,) or None
    """
    predicted = predict_start(twin, est, waypoints, step, allow_end, guide)
    return None if predicted is None else predicted[0]


def predict_start(twin: Twin, est: BodyEstimate, waypoints: list[tuple[float, float]],
                  step: int, allow_end: bool = True, guide: Guide | None = None
                  ) -> tuple[FloatArray, tuple[float, float]] | None:
    """The twin's prediction of the state at ``step`` and of the ILOS integral then.

    As :func:`predict_state`, with the guidance's integral vector at ``step`` (before that
    step's control update, as :meth:`Twin.run` restarts take it; zero with pure pursuit): what
    a replan starting there carries.

    Returns
    -------
    (ndarray (2 N + 4,), (I_x, I_y)) or None
    """
    integral0 = (0.0, 0.0) if guide is None else (float(guide[2]), float(guide[3]))
    now = int(round(est.t_s / twin.dt_s))
    steps = max(step - now, 0)
    if steps == 0 or not waypoints:
        return est.state.copy(), integral0
    runs = twin.run([waypoints], steps * twin.dt_s + 2 * twin.dt_s, states=est.state[None],
                    start_steps=[now], stride=1, guidance=_guidance_arg(twin, guide))
    states = runs.states[0]
    if steps < len(states) and np.all(np.isfinite(states[steps])):
        g = runs.integral_s[0, steps]
        return np.asarray(states[steps], dtype=float), (float(g[0]), float(g[1]))
    if not allow_end:
        return None
    finite = np.flatnonzero(np.isfinite(states[:, 0]))
    g = runs.integral_s[0, finite[-1]]
    return np.asarray(states[finite[-1]], dtype=float), (float(g[0]), float(g[1]))
