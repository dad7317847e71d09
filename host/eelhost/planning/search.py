"""A* over waypoint sequences, every manoeuvre swum in the twin from the state the last one left.

docs/planning.md ("The search") is the long form. In short:

- **Actions** (the motion primitives): from the waypoint the robot is steering to, the next
  waypoint at a distance d and a bearing b relative to the direction of the last leg (the first
  leg from the start pose's heading); d in ``distances_m``, b in ``bearings_deg``.
- **A node** is the robot's full twin state (links, speed, turn, gait phase: everything a
  primitive leaves) at a control update shortly before its guidance accepts a waypoint W, with W,
  the leg's direction psi and the time. Its children swim each action from that state, in the
  world's current, under the robot's own control stack (camera, median filter, 0.3 s offset
  updates; :mod:`eelhost.planning.twin`), until the next waypoint is accepted. The child's node
  is taken from that run at the last control update at least one median-filter window before the
  acceptance, so the next run starts with the same guidance as the uninterrupted run would.
- **A child is kept** when the twin raised no failure flag and every sampled body point keeps
  ``margin_m`` from every obstacle and wall (:class:`eelhost.planning.field.ClearanceField`);
  with ``robust_current_m_s`` also when the same plan, swum from the start in each of a few
  other currents (each node carries the robot's state in each), stays clear there.
- **The goal test** (:func:`in_goal`, the one used by execution and at the tank too): the centre
  of mass is inside the goal disc. A child whose run enters the disc shrunk by ``goal_margin_m``
  is a goal node; its cost is the time it enters.
- **Cost** is time, plus the soft margin's cost where the body comes closer to anything than
  ``preferred_clearance_m`` (:meth:`Search.soft_cost_s`), so plans take the middle of the gaps
  where that costs little time. The heuristic is the free-space path length to the goal disc
  (:class:`eelhost.planning.field.GoalDistance`, priced with the same soft margin) over the
  fastest ground speed (swimming speed plus current), weighted by ``weight`` (weighted A*: the
  plan costs at most ``weight`` times the optimum of this graph). Nodes are merged on a grid of waypoint cells x leg directions, so the
  search is finite; the B best open nodes are expanded together, their children swum in one batch.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import SupportsFloat

import numpy as np
from numpy.typing import NDArray

from eelhost.planning.body import body_points, point_spacing_m, reach_m
from eelhost.planning.field import ClearanceField, GoalDistance
from eelhost.planning.geometry import FloatArray
from eelhost.planning.twin import Runs, Twin
from eelhost.planning.world import World
from eelsim.control import wrap_angle

BATCHES_SEEN = 3
"""With a deadline, a batch's nodes are predicted to take the largest wall time per node of the
search's last this many batches (those that swam anything, in this call or the search's calls
before: a repair's first batch too)."""

CLEARANCE_CHUNK = 4096
"""Samples whose body points are measured against the clearance field at once (a piece that
stays in the cache; any size gives the same values)."""

COST_WINDOW = 32
"""A swim cost's rate is taken over its last this many measured swims (:class:`SwimCost`)."""

RAISE_INNER_M = 0.1
"""Within this distance of where a check run came too close, a raised margin counts whole
(:meth:`Search.raise_margin`), m."""

RAISE_OUTER_M = 0.25
"""A raised margin falls linearly to nothing at this distance, m."""

REST_KEY = -1
GOAL = -1
"""The action index of the leg to the goal's centre."""


def ramped_margin_m(t_s: NDArray[np.floating] | float, start_m: float, full_m: float, ramp_s: float) -> FloatArray:
    """A margin that grows linearly from ``start_m`` at time 0 to ``full_m`` at ``ramp_s``.

    The escape replan's rule (docs/planning.md, "An escape from inside the margin"): a plan from
    a start already inside the margin keeps what the start has, less a tolerance, and regains
    the full margin within ``ramp_s``.

    Parameters
    ----------
    t_s : array_like
        Times since the plan's start, s.
    start_m, full_m : float
        The margin at time 0 and from ``ramp_s`` on, m (``start_m`` above ``full_m`` is cut to it).
    ramp_s : float
        Seconds over which the margin grows (> 0).

    Returns
    -------
    ndarray
        The margin at each time, m.
    """
    start = min(start_m, full_m)
    frac = np.clip(np.asarray(t_s, dtype=float) / ramp_s, 0.0, 1.0)
    return np.asarray(start + (full_m - start) * frac, dtype=float)


def in_goal(world: World, xy: Sequence[float] | FloatArray, shrink_m: float = 0.0) -> bool:
    """The goal test of planning, the twin's execution and the tank's run loop.

    Parameters
    ----------
    world : World
    xy : array_like, shape (2,)
        The robot's centre of mass (at the tank: the filtered camera position).
    shrink_m : float
        Test against the disc shrunk by this much (the planner's margin).

    Returns
    -------
    bool
    """
    return bool(goal_mask(world, np.asarray(xy, dtype=float), shrink_m))


def goal_mask(world: World, xy: FloatArray, shrink_m: float = 0.0) -> NDArray[np.bool_]:
    """:func:`in_goal` for many positions at once.

    Parameters
    ----------
    world : World
    xy : ndarray, shape (..., 2)
    shrink_m : float

    Returns
    -------
    ndarray of bool, shape (...)
    """
    gx, gy = world.goal.position_m
    return np.hypot(xy[..., 0] - gx, xy[..., 1] - gy) <= world.goal.radius_m - shrink_m


class SwimCost:
    """Wall-clock cost per run-step of some swims in the twin, measured in this process.

    A run-step is one physics step of one run. Each measured swim records its wall time and the
    run-steps it swam; the rate is their sums' ratio over the last :data:`COST_WINDOW` swims, so
    it follows the machine's load and the robot's model. The check's
    (:data:`eelhost.planning.check.CHECK_COST`: its kernel, the restarts and the exact clearance
    of every state) is what the planner keeps free before a deadline; the search's own
    (:attr:`Search.swim_cost`) stands in for it, scaled, before the check has been measured
    (docs/planning.md, "The planning call's deadline").
    """

    def __init__(self, window: int = COST_WINDOW) -> None:
        self._walls: deque[float] = deque(maxlen=window)
        self._steps: deque[int] = deque(maxlen=window)

    def record(self, run_steps: int, wall_s: float) -> None:
        """Add one measured swim: ``run_steps`` run-steps in ``wall_s`` seconds."""
        if run_steps > 0 and wall_s >= 0:
            self._walls.append(float(wall_s))
            self._steps.append(int(run_steps))

    @property
    def rate_s(self) -> float | None:
        """Seconds per run-step over the recorded swims (None before any)."""
        steps = sum(self._steps)
        return sum(self._walls) / steps if steps else None

    def predict_s(self, run_steps: float) -> float | None:
        """Predicted wall time of ``run_steps`` run-steps, s (None before any measurement)."""
        rate = self.rate_s
        return None if rate is None else rate * run_steps


@dataclass(frozen=True)
class Actions:
    """The action set: legs of ``distances_m`` at ``bearings_deg`` from the last leg's direction.

    ``coefficient_index`` says which coefficient set swims each bearing: 0 (straight motion) for
    bearing 0, 1 (turning) otherwise (docs/planning.md, "Coefficients").
    """

    distances_m: tuple[float, ...] = (0.3, 0.5)
    bearings_deg: tuple[float, ...] = (-60.0, -30.0, 0.0, 30.0, 60.0)

    @property
    def legs(self) -> list[tuple[float, float]]:
        """(distance m, bearing deg) of every action."""
        return [(d, b) for d in self.distances_m for b in self.bearings_deg]

    def coefficient_index(self, bearing_deg: float) -> int:
        """0 (the straight-motion coefficients) for a straight leg, 1 (turning) otherwise."""
        return 0 if abs(bearing_deg) < 1e-9 else 1


@dataclass(frozen=True)
class SearchSettings:
    """How the search runs.

    Attributes
    ----------
    actions : Actions
    margin_m : float
        Clearance every sampled body centre-line point keeps from obstacles and walls (the
        body's half width, the world's clearance and the uncertainty margin).
    goal_margin_m : float
        A goal node's centre of mass enters the goal disc shrunk by this much.
    weight : float
        Heuristic weight (1: plain A*).
    cell_m : float
        Waypoint cells of the closed set.
    heading_bins : int
        Leg-direction bins of the closed set.
    batch : int
        Open nodes expanded together.
    max_expansions : int
        The search gives up after this many expansions.
    stride : int
        Physics steps between the sampled states that are checked.
    per_link : int
        Body points per link (intervals; see :func:`eelhost.planning.body.body_points`).
    leg_time_s : float
        Time limit of one leg at the slowest expected ground speed, s (scaled by distance).
    robust_current_m_s : float
        Extra waters (0: none): the world's current plus this speed towards each of
        ``robust_directions`` directions of the tank. Every node also holds the robot's state
        in each extra water, the same legs swum there from the start; a leg kept by the nominal
        run is swum in each extra water from that state and must accept its waypoint (or enter
        the goal disc) with the body centre line ``robust_margin_m`` clear of everything.
    robust_directions : int
    robust_margin_m : float
        Clearance of the body centre line the extra runs keep (the body's half width and some).
    preferred_clearance_m : float
        The soft margin: clearance of the body centre line the search prefers (0 or at most
        ``margin_m``: none). A sample of a leg closer than this to anything adds to the leg's
        cost (``clearance_cost``), so plans use the middle of the gaps where the time allows;
        ``margin_m`` stays the hard limit.
    clearance_cost : float
        Cost of the soft margin, s per s swum, of a sample at the hard margin ``margin_m``; it
        falls quadratically to 0 at ``preferred_clearance_m``.
    start_ramp_s : float
        0: the first legs keep the start's own clearance less 10 mm (never less than the body's
        half width) and every later leg ``margin_m``. Above 0 (the escape replan,
        docs/planning.md "An escape from inside the margin"): every sample keeps a margin that
        grows linearly from the start's clearance less 10 mm (also under the half width) to
        ``margin_m`` over this many seconds of the plan from its start, on whatever leg it lies,
        so the plan may stay inside the margin for a bounded time but must regain it by then.
    start_actions : Actions or None
        The action set of the legs from the search's start (its root node); later legs take
        ``actions``. None: ``actions`` throughout (the planner's fallback from a cramped start
        sets wider turns here, docs/planning_history.md "A wider turn from a cramped start").
    """

    actions: Actions = Actions()
    margin_m: float = 0.05
    goal_margin_m: float = 0.03
    weight: float = 2.0
    cell_m: float = 0.1
    heading_bins: int = 12
    batch: int = 8
    max_expansions: int = 600
    stride: int = 3
    per_link: int = 2
    leg_time_s: float = 40.0
    robust_current_m_s: float = 0.0
    robust_directions: int = 4
    robust_margin_m: float = 0.03
    preferred_clearance_m: float = 0.0
    clearance_cost: float = 0.0
    start_ramp_s: float = 0.0
    start_actions: Actions | None = None


@dataclass
class Leg:
    """One leg of a plan: the waypoint steered to, and what the twin did on the way.

    Attributes
    ----------
    waypoint_m : (float, float)
    distance_m, bearing_deg : float
        The action.
    start_step : int
        Step of the task at which this leg's run started (its parent's node).
    end_step : int
        Step at which the waypoint was accepted (or the goal entered, for the last leg).
    com_m : ndarray, shape (S, 2)
        Sampled centre of mass over the leg's run.
    min_clearance_m : float
        Smallest clearance of the sampled body centre line over the leg.
    goal : bool
        The last leg, to the goal's centre.
    parent_key : tuple of int
        Closed-set key of the node the leg leaves (with ``action``: what the planner bans when
        the leg fails its check).
    action : int
        Index of the action in :attr:`Actions.legs` (``GOAL`` for the leg to the goal).
    """

    waypoint_m: tuple[float, float]
    distance_m: float
    bearing_deg: float
    start_step: int
    end_step: int
    com_m: FloatArray
    min_clearance_m: float
    goal: bool = False
    parent_key: tuple[int, int, int] = (REST_KEY, REST_KEY, REST_KEY)
    action: int = GOAL


@dataclass
class Plan:
    """What the search found.

    Attributes
    ----------
    found : bool
    status : str
        ``found``, ``exhausted`` (every node the actions reach, as merged on the closed-set
        grid, was expanded: no plan with these actions and this margin, which is not a proof
        that none exists), ``gave_up`` (expansion limit) or ``out_of_time`` (the caller's
        wall-clock deadline passed first); the planner adds its own.
    message : str
        One line: the outcome, and why when no plan was found.
    legs : list of Leg
    cost_s : float
        Time at which the planned run enters the goal (NaN when not found).
    expansions : int
    simulations : int
        Manoeuvres swum in the twin.
    planning_time_s : float
    tree : ndarray, shape (E, 4)
        Every collision-free leg generated, (x0, y0, x1, y1) from waypoint to waypoint.
    start_guide : (x, y, I_x, I_y) or None
        The guidance state the plan was searched from (where its first leg starts, the ILOS
        integral); the check swims it from the same.
    """

    found: bool
    status: str
    message: str
    legs: list[Leg] = field(default_factory=list)
    cost_s: float = math.nan
    expansions: int = 0
    simulations: int = 0
    planning_time_s: float = 0.0
    tree: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    start_guide: tuple[float, float, float, float] | None = None

    @property
    def waypoints_m(self) -> list[tuple[float, float]]:
        """The waypoints to give the robot, in order."""
        return [leg.waypoint_m for leg in self.legs]


Guide = tuple[float, float, float, float]
"""The guidance's state a run starts with: its first leg's start (x, y) and the ILOS integral."""


def leg_start_guide(state: FloatArray, n_links: int,
                    integral_s: tuple[float, float] = (0.0, 0.0)) -> Guide:
    """The guidance state of a plan's start: its first leg from the centre of mass of ``state``.

    Parameters
    ----------
    state : ndarray, shape (2 N + 4,)
    n_links : int
    integral_s : (I_x, I_y)
        The ILOS integral the robot's controller holds (zero for a robot at rest).

    Returns
    -------
    Guide
    """
    return (float(state[n_links]), float(state[n_links + 1]), float(integral_s[0]),
            float(integral_s[1]))


@dataclass(frozen=True)
class _Judged:
    """What a kept child's verdict was judged from, to judge it again without swimming it.

    A raised margin (:meth:`Search.raise_margin`) changes only the clearances of a leg's
    samples, not its run: the child is judged again from the same samples (docs/planning.md,
    "Swum once, judged again").

    Attributes
    ----------
    samples : ndarray, shape (S, 2 N + 4)
        The leg's samples the margin applies to: the child's own copy, of which its state and
        its leg's centre-of-mass track are views.
    margin_m : float or ndarray, shape (S,)
        The margin each sample keeps (:meth:`Search._margin`).
    soft_end : int
        The soft margin's cost is summed over the first this many samples.
    swum_s : float
        The time the child adds to its parent's cost besides the soft margin's, s.
    stride : int
        Physics steps between the samples.
    """

    samples: FloatArray
    margin_m: float | FloatArray
    soft_end: int
    swum_s: float
    stride: int


@dataclass
class _Node:
    waypoint: tuple[float, float] | None  # None: the start, at rest
    psi: float
    state: FloatArray
    step: int
    g: float
    parent: int
    leg: Leg | None
    key: tuple[int, int, int]
    goal: bool = False
    # (state, step, guidance state) of the robot in each extra water
    # (SearchSettings.robust_current_m_s), the same plan swum there from the start
    particles: list[tuple[FloatArray, int, Guide]] = field(default_factory=list)
    # the guidance's state at ``step``: where the leg to ``waypoint`` starts and the ILOS
    # integral (Twin.run's ``guidance``), so a child's run continues the uninterrupted one
    guide: Guide = (math.nan, math.nan, 0.0, 0.0)
    # what a kept child was judged from (raise_margin judges it again from the same samples)
    judged: _Judged | None = None


class Search:
    """A* over the world with the twin (module docstring); reusable across searches of one world.

    Parameters
    ----------
    world : World
    twin : Twin
        Its coefficient sets 0 and 1 are the straight and turning ones.
    settings : SearchSettings
    clearance : ClearanceField, optional
    goal_distance : GoalDistance, optional
    ground_speed_m_s : float
        Fastest ground speed the heuristic divides by (swimming speed plus current).
    """

    def __init__(
        self,
        world: World,
        twin: Twin,
        settings: SearchSettings,
        clearance: ClearanceField,
        goal_distance: GoalDistance,
        ground_speed_m_s: float,
    ) -> None:
        self.world = world
        self.twin = twin
        self.settings = settings
        self.clearance = clearance
        self.goal_distance = goal_distance
        self.ground_speed_m_s = float(ground_speed_m_s)
        self.model = twin.model  # the robot's, built once and handed on
        self.n = twin.n_links
        self.warm_steps = int(math.ceil(
            twin.options.camera.median_window / twin.options.camera.fps / twin.dt_s - 1e-9
        ))
        self._slack_m = clearance.error_m + point_spacing_m(self.model, settings.per_link) / 4
        self.body_half_width_m = float(self.model.half_axis_horizontal_m.max())
        self.reach_m = reach_m(self.model)
        self._start_margin_m = settings.margin_m
        self._start_step = 0  # the search's start step: the margin ramp's origin
        self._soft_max_m = settings.preferred_clearance_m if settings.clearance_cost > 0 else 0.0
        self._memo: dict[tuple, list] = {}
        self.simulations = 0
        self.swim_cost = SwimCost()
        """Wall time per run-step of this search's batches (measured even without a deadline)."""
        # wall time per node of the last few batches that swam anything, over this search's
        # calls (a repair's or a replan's first batch is predicted from the ones before)
        self._node_walls: deque[float] = deque(maxlen=BATCHES_SEEN)
        self.clock: Callable[[], float] = time.monotonic
        """The clock ``deadline_s`` is read on (a test's fake one in place of the default)."""
        # the margin raised where plans failed their check (raise_margin): rows of (x, y,
        # extra m); the memo keys of the children swum while some were set (clear_raised)
        self._raised = np.zeros((0, 3))
        self._memo_raised: set[tuple] = set()
        # memo keys whose children a raise came near: judged again when next expanded
        self._stale: set[tuple] = set()
        self.rejudge = True
        """After :meth:`raise_margin`, judge the memo's children near it again from their
        samples (True), or swim them again (False, as until session 24): the same children
        either way (docs/planning.md, "Swum once, judged again")."""
        self.goal_stop: Callable[[FloatArray, int], FloatArray] | None = None
        """The arrival's stop from a goal node's state and step: its samples, shape (S, 2 N + 4)
        (the planner's, :meth:`eelhost.planning.planner.Planner.arrival_stop_states`); a goal
        node whose stop comes within the margin is passed over. None: the goal test ends in the
        disc."""
        self.goal_stop_margin_m: float | None = None
        """The clearance (the search's measure) the arrival's stop must keep; None: the hard
        margin, as the legs."""

    # -- pieces ----------------------------------------------------------------------------------

    def _key(self, waypoint: tuple[float, float], psi: float) -> tuple[int, int, int]:
        s = self.settings
        hb = int(round(psi / (2 * math.pi) * s.heading_bins)) % s.heading_bins
        return (int(waypoint[0] // s.cell_m), int(waypoint[1] // s.cell_m), hb)

    def heuristic_s(self, xy: FloatArray) -> float:
        """Time to the goal disc at the fastest ground speed along the free-space path, s."""
        return self.goal_distance(xy) / self.ground_speed_m_s

    def _jobs(self, nodes: list[_Node]) -> list[tuple[int, int, tuple[float, float], float]]:
        """(node position, action, waypoint, leg direction) of every leg to swim.

        Action ``GOAL`` is the leg to the goal's centre, offered within reach of it.
        """
        s = self.settings
        w, h = self.world.tank.size_m
        goal = self.world.goal.position_m
        reach = max(s.actions.distances_m) + self.world.goal.radius_m
        jobs = []
        for pos, node in enumerate(nodes):
            origin = (node.waypoint if node.waypoint is not None
                      else (float(node.state[self.n]), float(node.state[self.n + 1])))
            actions = (s.start_actions if node.waypoint is None and s.start_actions is not None
                       else s.actions)
            for a, (d, b) in enumerate(actions.legs):
                psi = node.psi + math.radians(b)
                wp = (origin[0] + d * math.cos(psi), origin[1] + d * math.sin(psi))
                if 0 < wp[0] < w and 0 < wp[1] < h:
                    jobs.append((pos, a, wp, psi))
            to_goal = math.hypot(goal[0] - origin[0], goal[1] - origin[1])
            if 1e-9 < to_goal <= reach:
                psi = math.atan2(goal[1] - origin[1], goal[0] - origin[0])
                jobs.append((pos, GOAL, (float(goal[0]), float(goal[1])), psi))
        return jobs

    def leg_coefficients(self, goal: bool, bearing_deg: float) -> int:
        """The coefficient set a leg is swum with: 0 straight, 1 turning (Actions).

        The leg to the goal's centre counts as straight within 15 degrees of the last leg.
        """
        if goal and abs(bearing_deg) < 15:
            return 0
        return self.settings.actions.coefficient_index(bearing_deg)

    def _bearing_deg(self, node: _Node, psi: float) -> float:
        return math.degrees(float(wrap_angle(psi - node.psi)))

    def _children(self, nodes: list[_Node]) -> list[list[tuple[int, _Node | None]]]:
        """Swim every leg from every node in one batch.

        Per node: (action, child or None for a leg that failed).
        """
        s = self.settings
        out: list[list[tuple[int, _Node | None]]] = [[] for _ in nodes]
        jobs = self._jobs(nodes)
        if not jobs:
            return out
        waypoints, durations, index = [], [], []
        for pos, a, wp, psi in jobs:
            node = nodes[pos]
            waypoints.append([wp] if node.waypoint is None else [node.waypoint, wp])
            index.append(self.leg_coefficients(a == GOAL, self._bearing_deg(node, psi)))
            origin = node.state[self.n : self.n + 2]
            durations.append(s.leg_time_s * (math.hypot(wp[0] - origin[0], wp[1] - origin[1])
                                             + 0.3))
        t0 = self.clock()
        runs = self.twin.run(
            waypoints,
            durations,
            states=np.stack([nodes[pos].state for pos, _, _, _ in jobs]),
            start_steps=[nodes[pos].step for pos, _, _, _ in jobs],
            coefficient_index=index,
            stride=s.stride,
            guidance=[nodes[pos].guide for pos, _, _, _ in jobs],
        )
        self.simulations += len(jobs)
        clear = self._clearances(runs)
        kids = [self._child(nodes[pos], a, wp, psi, runs, j, clear[j])
                for j, (pos, a, wp, psi) in enumerate(jobs)]
        self.swim_cost.record(int(np.sum(runs.final_step + 1)), self.clock() - t0)
        if s.robust_current_m_s > 0:
            self._swim_particles(jobs, kids, waypoints, durations, index, nodes)
        for j, (pos, a, _, _) in enumerate(jobs):
            out[pos].append((a, kids[j]))
        return out

    def _particle_currents(self) -> list[tuple[float, float]]:
        """The extra waters' currents: the twin's plus the robust current round the circle."""
        s = self.settings
        if s.robust_current_m_s <= 0:
            return []
        vx, vy = self.twin.current_m_s
        return [(vx + s.robust_current_m_s * math.cos(2 * math.pi * q / s.robust_directions),
                 vy + s.robust_current_m_s * math.sin(2 * math.pi * q / s.robust_directions))
                for q in range(s.robust_directions)]

    def _swim_particles(self, jobs: list, kids: list, waypoints: list, durations: list,
                        index: list[int], nodes: list[_Node]) -> None:
        """Swim each kept leg in every extra water from the parent's state there (settings).

        A leg whose run in some extra water raises a flag, misses its waypoint (or the goal
        disc) or comes closer than ``robust_margin_m`` to anything is dropped (its entry in
        ``kids`` set to None); a kept child gets its state in each water, taken at the last
        control update a median-filter window before that run accepted the waypoint.
        """
        s = self.settings
        waters = self._particle_currents()
        kept = [j for j, kid in enumerate(kids) if kid is not None]
        if not kept:
            return
        rows = [(j, q) for j in kept for q in range(len(waters))]
        parent = [nodes[jobs[j][0]] for j, _ in rows]
        runs = self.twin.run(
            [waypoints[j] for j, _ in rows],
            [durations[j] for j, _ in rows],
            states=np.stack([p.particles[q][0] for p, (_, q) in zip(parent, rows, strict=True)]),
            start_steps=[p.particles[q][1] for p, (_, q) in zip(parent, rows, strict=True)],
            coefficient_index=[index[j] for j, _ in rows],
            stride=s.stride,
            currents=[waters[q] for _, q in rows],
            guidance=[p.particles[q][2] for p, (_, q) in zip(parent, rows, strict=True)],
        )
        self.simulations += len(rows)
        clear = self._clearances(runs)
        period = self.twin.restart_steps or s.stride
        states: dict[int, list[tuple[FloatArray, int, Guide]]] = {j: [] for j in kept}
        for r, (j, q) in enumerate(rows):
            if kids[j] is None:
                continue
            end = int(runs.final_step[r]) // runs.stride
            start_step = parent[r].particles[q][1]
            if jobs[j][1] == GOAL:
                com = runs.states[r, : end + 1, self.n : self.n + 2]
                inside = np.flatnonzero(goal_mask(self.world, com))
                at = int(inside[0]) if inside.size else -1
                sample = at
                step = start_step + at * runs.stride
            else:
                arrival = int(runs.arrival_step[r])
                restart = ((arrival - self.warm_steps) // period) * period
                at = end if not runs.reasons[r] and arrival >= 0 and restart > 0 else -1
                sample = restart // runs.stride
                step = start_step + restart
            if at < 0 or not np.nanmin(clear[r, : at + 1]) >= s.robust_margin_m:
                kids[j] = None
                continue
            origin = _leg_origin(parent[r], parent[r].particles[q][2])
            states[j].append((runs.states[r, sample].copy(), step,
                              runs.guidance_state(r, sample, origin)))
        for j in kept:
            kid = kids[j]
            if kid is not None:
                kid.particles = states[j]

    def _clearances(self, runs: Runs) -> FloatArray:
        """Clearance of the body centre line at every sample of every run, shape (R, S).

        NaN after a run's end; less the field's and the point sampling's error.
        """
        r, k, _ = runs.states.shape
        return self.state_clearances(runs.states.reshape(r * k, -1)).reshape(r, k)

    def state_clearances(self, flat: FloatArray) -> FloatArray:
        """:meth:`_clearances` of states, shape (K, 2 N + 4) to (K,); NaN where a state is NaN.

        The measure the search's margin applies to (the arrival's stop in the goal test too,
        :attr:`goal_stop`).
        """
        n = self.n
        live = np.flatnonzero(np.isfinite(flat[:, 0]))
        out = np.full(len(flat), np.nan)
        if not live.size:
            return out
        # every body point is within reach_m of the centre of mass: where the centre of mass is
        # far enough from everything, that bound is all the search needs (and is what it keeps)
        far = self.clearance(flat[live, n : n + 2]) - self.clearance.error_m - self.reach_m
        out[live] = far
        # a raised margin (raise_margin) lowers no point's clearance by more than its largest
        raised = float(self._raised[:, 2].max()) if len(self._raised) else 0.0
        near = live[far < max(self.settings.margin_m, self._soft_max_m) + self._slack_m + raised]
        # in pieces whose body points stay in the processor's cache: the same values, in a
        # quarter to a third of the processor time of one pass over a batch's tens of thousands
        # of samples (docs/planning.md, "The planner", "Processor time")
        for lo in range(0, near.size, CLEARANCE_CHUNK):
            part = near[lo : lo + CLEARANCE_CHUNK]
            pts = body_points(self.model, flat[part], self.settings.per_link)
            value = self.clearance(pts)
            if len(self._raised):
                value -= self._raised_near(flat[part, n : n + 2], pts)
            out[part] = value.min(axis=1) - self._slack_m
        return out

    def _raised_near(self, com: FloatArray, points: FloatArray) -> FloatArray:
        """:meth:`raised_m` of each state's body points, computed only where it can be above 0.

        A state whose centre of mass is beyond :data:`RAISE_OUTER_M` plus the body's reach of a
        raise's site has every point beyond :data:`RAISE_OUTER_M` of it, where the raise is 0:
        the same values as :meth:`raised_m`, without measuring every point against every site.

        Parameters
        ----------
        com : ndarray, shape (K, 2)
            The states' centres of mass.
        points : ndarray, shape (K, P, 2)
            Their body points.

        Returns
        -------
        ndarray, shape (K, P)
        """
        out = np.zeros(points.shape[:-1])
        # a millimetre over the reach: no rounding puts a point of a state left out inside
        reach = RAISE_OUTER_M + self.reach_m + 1e-3
        for x, y, extra in self._raised:
            rows = np.flatnonzero(np.hypot(com[:, 0] - x, com[:, 1] - y) < reach)
            if not rows.size:
                continue
            near = points[rows]
            d = np.hypot(near[..., 0] - x, near[..., 1] - y)
            ramp = np.clip((RAISE_OUTER_M - d) / (RAISE_OUTER_M - RAISE_INNER_M), 0.0, 1.0)
            out[rows] = np.maximum(out[rows], extra * ramp)
        return out

    def raised_m(self, points: FloatArray) -> FloatArray:
        """How much the margin is raised at ``points`` (:meth:`raise_margin`), m; shape (...)."""
        out = np.zeros(np.shape(points)[:-1])
        for x, y, extra in self._raised:
            d = np.hypot(points[..., 0] - x, points[..., 1] - y)
            ramp = np.clip((RAISE_OUTER_M - d) / (RAISE_OUTER_M - RAISE_INNER_M), 0.0, 1.0)
            np.maximum(out, extra * ramp, out=out)
        return out

    def raise_margin(self, xy: tuple[float, float], extra_m: float) -> None:
        """Keep every body point near ``xy`` ``extra_m`` further from everything, from now on.

        The planner's repair after a failed check (docs/planning_history.md, "Targets of issue 28 (the
        planner's)", "A repair with the margin raised where the check failed"): within
        :data:`RAISE_INNER_M` of ``xy`` the body's clearance counts ``extra_m`` less (the hard
        margin and the soft margin's cost alike), falling linearly to nothing at
        :data:`RAISE_OUTER_M`; where several raises overlap, the largest counts. Children
        swum before whose legs came near are swum again when next reached; the rest of the
        memo stands (a raised margin only refuses more). :meth:`clear_raised` undoes it.

        Parameters
        ----------
        xy : (float, float)
            Where a check run came too close, m.
        extra_m : float
            How much further, m (> 0).
        """
        if not extra_m > 0:
            return
        self._raised = np.vstack([self._raised, [float(xy[0]), float(xy[1]), float(extra_m)]])
        near = RAISE_OUTER_M + self.reach_m
        for key in [k for k, kids in self._memo.items()
                    if any(c is not None and c.leg is not None and np.min(np.hypot(
                        c.leg.com_m[:, 0] - xy[0], c.leg.com_m[:, 1] - xy[1])) < near
                        for _, c in kids)]:
            if self.rejudge and not self.settings.robust_current_m_s > 0 and all(
                    c is None or c.judged is not None for _, c in self._memo[key]):
                # judged again from the same samples when next reached (_expand), not swum
                # again: the same children (docs/planning.md, "Swum once, judged again")
                self._stale.add(key)
            else:
                # the robust search's extra waters are judged with the raised margin too
                del self._memo[key]
                self._stale.discard(key)

    def clear_raised(self) -> None:
        """Undo every :meth:`raise_margin` (a new planning call starts without them)."""
        # an entry waiting to be judged again was judged without the raises since (the ones
        # judged with some are in _memo_raised): as it is, it holds without any
        self._stale.clear()
        if not len(self._raised):
            return
        self._raised = np.zeros((0, 3))
        for key in self._memo_raised:
            self._memo.pop(key, None)
        self._memo_raised.clear()

    def soft_cost_s(self, clear: FloatArray, stride: int) -> float:
        """The soft margin's cost of a run's samples (``SearchSettings.preferred_clearance_m``).

        Parameters
        ----------
        clear : ndarray, shape (S,)
            Clearance of the body centre line at each sample (NaN after the run's end).
        stride : int
            Physics steps between samples.

        Returns
        -------
        float
            Extra cost, s: the time integral of ``clearance_cost`` times the squared shortfall
            of the clearance under the preferred one, over the preferred one less the hard
            margin (1 at the hard margin).
        """
        s = self.settings
        if s.clearance_cost <= 0 or s.preferred_clearance_m <= s.margin_m or not clear.size:
            return 0.0
        span = s.preferred_clearance_m - s.margin_m
        short = np.clip((s.preferred_clearance_m - np.nan_to_num(clear, nan=np.inf)) / span,
                        0.0, None)
        return float(s.clearance_cost * stride * self.twin.dt_s * np.sum(short ** 2))

    def _child(self, parent: _Node, action: int, wp, psi, runs: Runs, j: int,
               clear: FloatArray) -> _Node | None:
        s = self.settings
        stride = runs.stride
        end = int(runs.final_step[j])
        last = end // stride
        samples = runs.states[j, : last + 1]
        com = samples[:, self.n : self.n + 2]
        margin = self._margin(parent, len(clear), stride)
        bearing = self._bearing_deg(parent, psi)
        origin = parent.waypoint if parent.waypoint is not None else (com[0, 0], com[0, 1])
        d = math.hypot(wp[0] - origin[0], wp[1] - origin[1])
        if action == GOAL:
            inside = np.flatnonzero(goal_mask(self.world, com, s.goal_margin_m))
            if not inside.size:
                return None
            at = int(inside[0])
            c = float(np.min(clear[: at + 1]))
            if np.any(clear[: at + 1] < margin[: at + 1]):
                return None
            step = parent.step + at * stride
            # the child's own copy of its samples: a view would keep the whole batch's buffer
            # (every run, sized for the longest time limit) alive as long as the memo
            own = samples[: at + 1].copy()
            leg = Leg(wp, d, bearing, parent.step, step, own[:, self.n : self.n + 2], c, True,
                      parent.key, action)
            soft = self.soft_cost_s(clear[: at + 1], stride)
            swum = (step - parent.step) * self.twin.dt_s
            return _Node(wp, psi, own[at], step, parent.g + swum + soft, -1, leg,
                         self._key(wp, psi), goal=True,
                         judged=_Judged(own, self._kept_margin(margin, at + 1), at + 1, swum,
                                        stride))
        if runs.reasons[j] or runs.arrival_step[j] < 0:
            return None
        c = float(np.min(clear[: last + 1]))
        if np.any(clear[: last + 1] < margin[: last + 1]):
            return None
        arrival = int(runs.arrival_step[j])
        period = self.twin.restart_steps or stride
        restart = ((arrival - self.warm_steps) // period) * period
        if restart <= 0 or restart % stride:
            return None
        if parent.waypoint is not None:
            # the guidance must already steer to wp at the restart: the previous waypoint was
            # accepted before it (the true centre of mass well inside its circle)
            r = self.twin.acceptance_radius_m - 0.01
            near = np.hypot(*(com[: restart // stride + 1] - np.asarray(parent.waypoint)).T)
            if not np.any(near < r):
                return None
        step = parent.step + restart
        own = samples.copy()  # not a view of the batch's buffer (above)
        leg = Leg(wp, d, bearing, parent.step, parent.step + arrival, own[:, self.n : self.n + 2],
                  c, False, parent.key, action)
        guide = runs.guidance_state(j, restart // stride, _leg_origin(parent, parent.guide))
        soft = self.soft_cost_s(clear[: restart // stride + 1], stride)
        swum = restart * self.twin.dt_s
        return _Node(wp, psi, own[restart // stride], step, parent.g + swum + soft, -1, leg,
                     self._key(wp, psi), guide=guide,
                     judged=_Judged(own, self._kept_margin(margin, last + 1),
                                    restart // stride + 1, swum, stride))

    def _kept_margin(self, margin: FloatArray, samples: int) -> float | FloatArray:
        """A child's margin as :class:`_Judged` keeps it: one number when it is flat."""
        if self.settings.start_ramp_s <= 0:
            return float(margin[0])
        return margin[:samples].copy()

    def _judged_again(self, parent: _Node, child: _Node | None) -> _Node | None:
        """A kept child of ``parent`` judged again from its samples with the margin raised now.

        What swimming its leg again from ``parent`` would give (the twin's run is the same;
        only the clearances change): None when a sample is now inside the margin, else the
        child with its leg's smallest clearance, its soft margin's cost and its cost from the
        parent's as it is now recomputed (docs/planning.md, "Swum once, judged again").
        """
        if child is None or child.judged is None or child.leg is None:
            return None
        info = child.judged
        clear = self.state_clearances(info.samples)
        if np.any(clear < info.margin_m):
            return None
        leg = dataclasses.replace(child.leg, min_clearance_m=float(np.min(clear)))
        soft = self.soft_cost_s(clear[: info.soft_end], info.stride)
        return _Node(child.waypoint, child.psi, child.state, child.step,
                     parent.g + info.swum_s + soft, -1, leg, child.key, child.goal,
                     child.particles, child.guide, info)

    def _stop_clear(self, node: _Node) -> bool:
        """The arrival's stop from a goal node keeps the search's margin (:attr:`goal_stop`).

        True without :attr:`goal_stop`; False for a stop the twin ended early. Judged with the
        search's own measure and margin, as its legs (docs/planning.md, "The arrival's stop in
        the check").
        """
        if self.goal_stop is None:
            return True
        stop = self.goal_stop(node.state, node.step)
        if not np.isfinite(stop[:, 0]).all():
            return False
        floor = self.settings.margin_m if self.goal_stop_margin_m is None else self.goal_stop_margin_m
        return bool(np.all(self.state_clearances(stop) >= floor))

    def _margin(self, parent: _Node, samples: int, stride: int) -> FloatArray:
        """The margin each of a leg's ``samples`` keeps (:attr:`SearchSettings.start_ramp_s`)."""
        s = self.settings
        if s.start_ramp_s <= 0:
            flat = s.margin_m if parent.waypoint is not None else self._start_margin_m
            return np.full(samples, flat)
        t = (parent.step - self._start_step + stride * np.arange(samples)) * self.twin.dt_s
        return ramped_margin_m(t, self._start_margin_m, s.margin_m, s.start_ramp_s)

    # -- the search ------------------------------------------------------------------------------

    def plan(
        self,
        banned: set | None = None,
        start_state: FloatArray | None = None,
        start_step: int = 0,
        heading_rad: float | None = None,
        guide: Guide | None = None,
        deadline_s: SupportsFloat | None = None,
        reserve_s: Callable[[], float] | None = None,
    ) -> Plan:
        """Search from the world's start, or from any state (see the module docstring).

        Parameters
        ----------
        banned : set of (node key, action index), optional
            Legs not to take (the planner bans legs that failed its check in the twin).
        start_state : ndarray, shape (2 N + 4,), optional
            The robot's state to plan from (default: straight at rest at the world's start);
            replanning passes the state it observes.
        start_step : int
            Step of the task at ``start_state`` (its gait phase).
        heading_rad : float, optional
            Direction the first legs' bearings are measured from (default: the world's start
            heading when planning from the start, else the head link's direction).
        guide : (x, y, I_x, I_y), optional
            The guidance's state at the start: where the first leg starts and the ILOS integral
            (default :func:`leg_start_guide` of the start state: from its centre of mass, the
            integral zero). A replan passes the controller's own.
        deadline_s : float or Deadline, optional
            A time on :attr:`clock`, read before every batch (a
            :class:`~eelhost.planning.deadline.Deadline` may come earlier meanwhile) (``time.monotonic()`` by default): no batch is started that
            would still be in flight then (near it, the batch shrinks to the nodes predicted to
            fit, each at the largest wall time per node of the last :data:`BATCHES_SEEN`
            batches), and the search ends ``out_of_time`` unless it has found the goal (docs/planning.md, "The planning call's deadline"). Default: none.
        reserve_s : callable, optional
            With ``deadline_s``: the time to keep free before it, s, asked before every batch
            (the planner's prediction of its check, which improves as the search measures its
            own swims). Default: none kept.

        Returns
        -------
        Plan
        """
        banned = banned or set()
        started = time.perf_counter()
        sims0 = self.simulations
        s = self.settings
        world = self.world
        if start_state is None:
            start_state = self.twin_start_state()
            start_step = 0
            if heading_rad is None:
                heading_rad = math.radians(world.start.heading_deg)
        start_state = np.asarray(start_state, dtype=float)
        if heading_rad is None:
            # the body's mean direction: the head swings with the gait
            heading_rad = float(np.angle(np.exp(1j * start_state[: self.n]).mean()))
        start_xy = start_state[self.n : self.n + 2].copy()
        # the first legs leave the start, which may be closer to a wall than the margin: they
        # keep what the start has (never less than the body's half width)
        start_clear = float(self.clearance(body_points(self.model, start_state[None],
                                                       s.per_link)).min()) - self._slack_m
        self._start_margin_m = min(s.margin_m, max(start_clear - 0.01, self.body_half_width_m))
        if s.start_ramp_s > 0:
            # the escape: the start's own clearance less 10 mm, also under the half width (the
            # centre line of a thin tail may be nearer than the widest link's half width); the
            # escape's check judges the body's own gap (docs/planning.md, "An escape from
            # inside the margin")
            self._start_margin_m = min(s.margin_m, start_clear - 0.01)
        self._start_step = int(start_step)
        if guide is None:
            guide = leg_start_guide(start_state, self.n)
        root = _Node(None, heading_rad, start_state, start_step, start_step * self.twin.dt_s, -1,
                     None, (REST_KEY, REST_KEY, REST_KEY),
                     particles=[(start_state, start_step, guide)]
                     * len(self._particle_currents()), guide=guide)
        nodes = [root]
        best_g: dict = {root.key: root.g}
        closed: set = set()
        heap = [(s.weight * self.heuristic_s(start_xy), 0, 0)]
        tie = 1
        tree: list[tuple[float, float, float, float]] = []
        expansions = 0
        found = -1
        late = False
        node_walls = self._node_walls
        while heap and found < 0 and expansions < s.max_expansions:
            size = s.batch
            if deadline_s is not None:
                # no batch is started that would still be in flight at the deadline (less the
                # time kept for the check): near it, the batch shrinks to the nodes that fit,
                # each predicted to take the largest wall time per node of the last few batches
                # (docs/planning.md, "The planning call's deadline")
                left = float(deadline_s) - self.clock() - (reserve_s() if reserve_s else 0.0)
                per_node = max(node_walls, default=0.0)
                if left <= 0:
                    late = True
                    break
                if per_node > 0:
                    size = min(size, int(left / per_node))
                    if size < 1:
                        late = True
                        break
            batch: list[int] = []
            while heap and len(batch) < size:
                _, _, ni = heapq.heappop(heap)
                node = nodes[ni]
                if node.goal:
                    if batch:
                        heapq.heappush(heap, (node.g, -1, ni))  # pop it after this batch
                    elif self._stop_clear(node):
                        found = ni
                    else:
                        continue  # its arrival's stop comes within the margin: search on
                    break
                if node.key in closed:
                    continue
                closed.add(node.key)
                batch.append(ni)
            if found >= 0 or not batch:
                continue
            expansions += len(batch)
            t_batch, sims_before = self.clock(), self.simulations
            expanded = self._expand([nodes[i] for i in batch], batch, banned)
            if self.simulations > sims_before:
                node_walls.append((self.clock() - t_batch) / len(batch))
            for ni, kids in zip(batch, expanded, strict=True):
                parent = nodes[ni]
                for child in kids:
                    if child is None:
                        continue
                    if not child.goal and (child.key in closed
                                           or child.g >= best_g.get(child.key, math.inf)):
                        continue
                    child.parent = ni
                    nodes.append(child)
                    if not child.goal:
                        best_g[child.key] = child.g
                    origin = (parent.waypoint if parent.waypoint is not None
                              else tuple(start_xy))
                    tree.append((origin[0], origin[1], child.waypoint[0], child.waypoint[1]))
                    xy = child.state[self.n : self.n + 2]
                    f = child.g if child.goal else child.g + s.weight * self.heuristic_s(xy)
                    heapq.heappush(heap, (f, tie, len(nodes) - 1))
                    tie += 1
        elapsed = time.perf_counter() - started
        tree_arr = np.asarray(tree, dtype=float).reshape(-1, 4)
        sims = self.simulations - sims0
        if found < 0:
            if late:
                status = "out_of_time"
                msg = (f"no plan: the search ran out of time after {expansions} expansions "
                       f"({sims} manoeuvres swum in the twin, {elapsed:.2f} s) without reaching "
                       "the goal")
            elif expansions >= s.max_expansions:
                status = "gave_up"
                msg = (f"no plan: the search gave up after {expansions} expansions "
                       f"({sims} manoeuvres swum in the twin) without reaching the goal")
            else:
                status = "exhausted"
                msg = (f"no plan: every pose the actions reach ({expansions} expanded, {sims} "
                       f"manoeuvres swum) was tried and none enters the goal disc (radius "
                       f"{world.goal.radius_m} m at ({world.goal.position_m[0]:.2f}, "
                       f"{world.goal.position_m[1]:.2f}) m) without coming closer than "
                       f"{s.margin_m * 1000:.0f} mm to an obstacle or wall")
            return Plan(False, status, msg, expansions=expansions, simulations=sims,
                        planning_time_s=elapsed, tree=tree_arr)
        legs = []
        ni = found
        while nodes[ni].parent >= 0:
            leg = nodes[ni].leg
            assert leg is not None
            legs.append(leg)
            ni = nodes[ni].parent
        legs.reverse()
        # the time the goal is entered (a node's g also holds the soft margin's cost)
        cost = nodes[found].step * self.twin.dt_s
        msg = (f"plan found: {len(legs)} legs, goal entered at {cost:.1f} s, "
               f"{expansions} expansions, {sims} manoeuvres swum")
        return Plan(True, "found", msg, legs, cost, expansions, sims, elapsed, tree_arr, guide)

    def twin_start_state(self) -> FloatArray:
        """The straight robot at rest at the world's start pose."""
        from eelsim.dynamics import straight_state

        return straight_state(self.model, math.radians(self.world.start.heading_deg),
                              self.world.start.position_m)

    def _expand(self, batch_nodes: list[_Node], ids: list[int], banned: set) -> list[list]:
        """Children of the nodes, from the memo where this search has swum them before."""
        todo = [k for k, ni in enumerate(ids) if self._path_key(ni, batch_nodes[k]) not in self._memo]
        if todo:
            fresh = self._children([batch_nodes[k] for k in todo])
            for k, kids in zip(todo, fresh, strict=True):
                self._memo[self._path_key(ids[k], batch_nodes[k])] = kids
                if len(self._raised):  # swum with a raised margin: not kept past clear_raised
                    self._memo_raised.add(self._path_key(ids[k], batch_nodes[k]))
        for k, ni in enumerate(ids):
            key = self._path_key(ni, batch_nodes[k])
            if key in self._stale:
                self._memo[key] = [(a, self._judged_again(batch_nodes[k], c))
                                   for a, c in self._memo[key]]
                self._stale.discard(key)
                self._memo_raised.add(key)  # judged with a raised margin: not past clear_raised
        out = []
        for k, ni in enumerate(ids):
            kids = self._memo[self._path_key(ni, batch_nodes[k])]
            out.append([None if (batch_nodes[k].key, a) in banned or c is None
                        else _copy(c) for a, c in kids])
        return out

    @staticmethod
    def _path_key(ni: int, node: _Node) -> tuple:
        return (node.step, node.state.tobytes(), node.guide)


def _leg_origin(node: _Node, guide: Guide) -> tuple[float, float]:
    """Where the leg from ``node`` to a child's waypoint starts, for the child's guidance state.

    At a child's restart the guidance steers to the child's waypoint along the leg from the
    node's waypoint (from the start: the leg start of ``guide``, the node's own).
    """
    if node.waypoint is not None:
        return (float(node.waypoint[0]), float(node.waypoint[1]))
    return (guide[0], guide[1])


def _copy(node: _Node) -> _Node:
    return _Node(node.waypoint, node.psi, node.state, node.step, node.g, -1, node.leg, node.key,
                 node.goal, node.particles, node.guide, node.judged)
