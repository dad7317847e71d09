"""A* over robot poses, with the twin's motion primitives as edges (docs/model.md section 9).

A node is a pose (x, y, heading) and whether the robot is at rest (the start) or swimming. Its
children are the end poses of the primitives simulated for the current as the robot would feel it
there: the world current's direction relative to the node's heading, rounded to the nearest of the
library's directions (8 by default). A child is kept only if the primitive's swept hull, placed at
the node, keeps the robot's half width plus the world's clearance from every obstacle and wall.

Cost is time (the primitives' durations). The heuristic is the straight-line distance left to the
goal disc divided by the largest displacement per second any primitive of the library achieves
(:attr:`PrimitiveLibrary.max_progress_speed_m_s`): no sequence of primitives covers distance faster,
so it never overestimates the time left (admissible) and the first goal node popped is optimal for
this graph. Poses are merged on a grid (``cell_m``, ``heading_bins``) so the search is finite; a goal
that cannot be reached therefore exhausts the queue and is reported as such.
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from eelhost.planning.geometry import FloatArray
from eelhost.planning.primitives import KIND_NAMES, REST, SWIMMING, PrimitiveLibrary
from eelhost.planning.world import World
from eelsim.control import wrap_angle


@dataclass(frozen=True)
class PlanStep:
    """One primitive of a plan, placed in the world.

    Attributes
    ----------
    primitive : int
        Row of the library.
    kind : str
        "rest" or "swimming".
    current_rel_deg : float
        Nominal direction of the current relative to the heading the primitive was chosen for.
    distance_m, bearing_deg : float
        The primitive's nominal waypoint.
    start_pose, end_pose : tuple of float
        (x, y, heading) in the world, m and rad.
    waypoint_m : tuple of float
        The waypoint the robot steers to, world frame.
    duration_s : float
    hull : ndarray, shape (H, 2)
        Swept region in the world.
    """

    primitive: int
    kind: str
    current_rel_deg: float
    distance_m: float
    bearing_deg: float
    start_pose: tuple[float, float, float]
    end_pose: tuple[float, float, float]
    waypoint_m: tuple[float, float]
    duration_s: float
    hull: FloatArray


@dataclass
class Plan:
    """What the search found.

    Attributes
    ----------
    found : bool
    message : str
        One line: the outcome, and why when no path was found.
    steps : list of PlanStep
    cost_s : float
        Sum of the primitives' durations (planned time to the goal), NaN when not found.
    expansions : int
        Nodes expanded.
    planning_time_s : float
        Wall time of the search.
    tree : ndarray, shape (E, 4)
        Every collision-free edge generated, (x0, y0, x1, y1), for figures.
    heuristic_speed_m_s : float
        The speed the heuristic divides by.
    """

    found: bool
    message: str
    steps: list[PlanStep] = field(default_factory=list)
    cost_s: float = math.nan
    expansions: int = 0
    planning_time_s: float = 0.0
    tree: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    heuristic_speed_m_s: float = math.nan

    @property
    def waypoints_m(self) -> list[tuple[float, float]]:
        """The waypoints to give the robot, in order."""
        return [s.waypoint_m for s in self.steps]


def heuristic_s(
    world: World, library: PrimitiveLibrary, xy: Sequence[float] | FloatArray
) -> float:
    """Admissible estimate of the time from ``xy`` into the goal disc.

    Parameters
    ----------
    world : World
    library : PrimitiveLibrary
    xy : array_like, shape (2,)

    Returns
    -------
    float
        max(0, distance to the goal centre - goal radius) / fastest progress speed, s.
    """
    gx, gy = world.goal.position_m
    d = math.hypot(float(xy[0]) - gx, float(xy[1]) - gy) - world.goal.radius_m
    return max(0.0, d) / library.max_progress_speed_m_s


def place(pose: tuple[float, float, float], rel: FloatArray) -> FloatArray:
    """Transform points from a pose's frame into the world.

    Parameters
    ----------
    pose : (x, y, heading)
    rel : ndarray, shape (..., 2)

    Returns
    -------
    ndarray, shape (..., 2)
    """
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rot = np.array([[c, s], [-s, c]])  # row vectors: p_world = p_rel @ rot + origin
    return rel @ rot + np.array(pose[:2])


def current_index_at(
    world: World, library: PrimitiveLibrary, heading_rad: float, kind: int = SWIMMING
) -> int:
    """Which of the library's current directions the robot feels at this heading.

    Parameters
    ----------
    world : World
    library : PrimitiveLibrary
    heading_rad : float
    kind : int
        ``REST`` or ``SWIMMING``: directions without primitives of this kind are skipped.

    Returns
    -------
    int
    """
    rel = world.current.direction_deg - math.degrees(heading_rad)
    return library.nearest_current_index(rel, kind)


def plan_path(
    world: World,
    library: PrimitiveLibrary,
    cell_m: float = 0.1,
    heading_bins: int = 12,
    max_expansions: int = 200_000,
) -> Plan:
    """Find the fastest collision-free sequence of primitives from the start into the goal disc.

    Parameters
    ----------
    world : World
    library : PrimitiveLibrary
        Built for the world's current speed.
    cell_m : float
        Size of the position cells of the closed set.
    heading_bins : int
        Heading cells of the closed set.
    max_expansions : int
        Safety stop; hitting it is reported as such, not as unreachable.

    Returns
    -------
    Plan

    Raises
    ------
    ValueError
        When the library was built for another current speed.
    """
    if abs(library.current_speed_m_s - world.current.speed_m_s) > 1e-9:
        raise ValueError(
            f"primitive library built for a {library.current_speed_m_s} m/s current, the world "
            f"has {world.current.speed_m_s} m/s"
        )
    started = time.perf_counter()
    margin = world.clearance_m + library.body_half_width_m
    speed = library.max_progress_speed_m_s
    goal = np.asarray(world.goal.position_m, dtype=float)
    sx, sy = map(float, world.start.position_m)
    start = (sx, sy, math.radians(world.start.heading_deg))

    def cell(pose: tuple[float, float, float], kind: int) -> tuple[int, int, int, int]:
        hb = int(round(float(wrap_angle(pose[2])) / (2 * math.pi) * heading_bins)) % heading_bins
        return (int(pose[0] // cell_m), int(pose[1] // cell_m), hb, kind)

    # node records: pose, kind, g, parent node, primitive row
    nodes: list[tuple[tuple[float, float, float], int, float, int, int]] = []
    nodes.append((start, REST, 0.0, -1, -1))
    best_g = {cell(start, REST): 0.0}
    closed: set[tuple[int, int, int, int]] = set()
    open_heap = [(heuristic_s(world, library, start[:2]), 0, 0)]  # (f, tie, node)
    tie = 1
    tree: list[tuple[float, float, float, float]] = []
    expansions = 0
    found = -1
    while open_heap:
        _, _, ni = heapq.heappop(open_heap)
        pose, kind, g, _, _ = nodes[ni]
        key = cell(pose, kind)
        if key in closed:
            continue
        if math.hypot(pose[0] - goal[0], pose[1] - goal[1]) <= world.goal.radius_m:
            found = ni
            break
        closed.add(key)
        expansions += 1
        if expansions > max_expansions:
            break
        ci = current_index_at(world, library, pose[2], kind)
        rows = library.group(kind, ci)
        if ci < 0 or rows.size == 0:
            continue
        ends = library.end_pose[rows]
        child_xy = place(pose, ends[:, :2])
        child_h = np.asarray(wrap_angle(pose[2] + ends[:, 2]))
        hulls = place(pose, library.group_hulls(kind, ci)[0])
        free = world.hulls_free(hulls, margin)
        for j in np.flatnonzero(free):
            child = (float(child_xy[j, 0]), float(child_xy[j, 1]), float(child_h[j]))
            ckey = cell(child, SWIMMING)
            cg = g + float(library.duration_s[rows[j]])
            if ckey in closed or cg >= best_g.get(ckey, math.inf):
                continue
            best_g[ckey] = cg
            nodes.append((child, SWIMMING, cg, ni, int(rows[j])))
            tree.append((pose[0], pose[1], child[0], child[1]))
            f = cg + heuristic_s(world, library, child[:2])
            heapq.heappush(open_heap, (f, tie, len(nodes) - 1))
            tie += 1

    elapsed = time.perf_counter() - started
    tree_arr = np.asarray(tree, dtype=float).reshape(-1, 4)
    if found < 0:
        if expansions > max_expansions:
            msg = (f"no path found: search stopped at the limit of {max_expansions} expansions "
                   "(raise max_expansions)")
        else:
            msg = (f"goal unreachable: all {expansions} reachable poses were expanded and none "
                   f"enters the goal disc (radius {world.goal.radius_m} m at "
                   f"({goal[0]:.2f}, {goal[1]:.2f}) m) with a collision-free primitive")
        return Plan(False, msg, expansions=expansions, planning_time_s=elapsed, tree=tree_arr,
                    heuristic_speed_m_s=speed)

    chain = []
    ni = found
    while nodes[ni][3] >= 0:
        chain.append(ni)
        ni = nodes[ni][3]
    steps = []
    for ni in reversed(chain):
        pose, _, _, parent, row = nodes[ni]
        ppose = nodes[parent][0]
        waypoint = place(ppose, library.waypoint_rel[row])
        steps.append(
            PlanStep(
                primitive=row,
                kind=KIND_NAMES[int(library.kind[row])],
                current_rel_deg=float(
                    library.discretisation.current_directions_deg[int(library.current_index[row])]
                ),
                distance_m=float(library.distance_m[row]),
                bearing_deg=float(library.bearing_deg[row]),
                start_pose=ppose,
                end_pose=pose,
                waypoint_m=(float(waypoint[0]), float(waypoint[1])),
                duration_s=float(library.duration_s[row]),
                hull=place(ppose, library.hulls[row]),
            )
        )
    cost = nodes[found][2]
    msg = (f"path found: {len(steps)} primitives, {cost:.1f} s planned, "
           f"{expansions} expansions")
    return Plan(True, msg, steps, cost, expansions, elapsed, tree_arr, speed)
