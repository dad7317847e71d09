"""Generated worlds for the planning benchmark, and the worlds of issue 20.

docs/planning.md, "Benchmark", is the long form.

:func:`generate_world` draws a 3 m x 2 m tank with 5 to 8 obstacles, start and goal at least
1.5 m apart, and a current of 0 to 0.06 m/s in any direction, from a seed:

- in about one world in three the obstacles include a barrier across the tank, from wall to
  wall, with one gate of 0.35 to 0.6 m between start and goal (two obstacles);
- the others are discs (radius 0.08 to 0.2 m) and rectangles (0.08 to 0.25 m by 0.2 to 0.6 m,
  any orientation), placed so that every gap between two obstacles, or an obstacle and a wall,
  is at least 0.35 m, or 0 (touching);
- nothing comes within 0.45 m of the start (the robot's half length and some) or 0.1 m of the
  goal disc.

:func:`issue_worlds` are the cases issue 20 tried by hand, kept as tests and benchmark cases.
"""

from __future__ import annotations

import math

import numpy as np

from eelhost.planning.geometry import point_segment_distance, points_in_polygon
from eelhost.planning.world import World, parse_world

TANK_M = (3.0, 2.0)
MIN_GAP_M = 0.35


def _rectangle(centre, length, width, angle) -> list[list[float]]:
    c, s = math.cos(angle), math.sin(angle)
    corners = [(-length / 2, -width / 2), (length / 2, -width / 2),
               (length / 2, width / 2), (-length / 2, width / 2)]
    return [[centre[0] + x * c - y * s, centre[1] + x * s + y * c] for x, y in corners]


def _world(name, start, heading, goal, speed, direction, obstacles, clearance=0.03) -> World:
    return parse_world({
        "name": name,
        "clearance_m": clearance,
        "tank": {"size_m": list(TANK_M)},
        "start": {"position_m": list(start), "heading_deg": heading},
        "goal": {"position_m": list(goal), "radius_m": 0.2},
        "current": {"speed_m_s": speed, "direction_deg": direction},
        "obstacles": obstacles,
    }, name)


def _distance_to(o: dict, points: np.ndarray) -> np.ndarray:
    """Signed distance from points to one obstacle (negative inside)."""
    if o["kind"] == "circle":
        return np.hypot(*(points - np.asarray(o["centre_m"])).T) - o["radius_m"]
    poly = np.asarray(o["vertices_m"], dtype=float)
    d = point_segment_distance(points, poly, np.roll(poly, -1, axis=0)).min(axis=1)
    return np.where(points_in_polygon(points, poly), -d, d)


def _gap(a: dict, b: dict) -> float:
    """Distance between two obstacles, from their sampled outlines (0 when they overlap)."""
    return float(max(0.0, min(_distance_to(b, _outline(a)).min(),
                              _distance_to(a, _outline(b)).min())))


def _outline(o: dict, count: int = 64) -> np.ndarray:
    if o["kind"] == "circle":
        a = np.linspace(0, 2 * math.pi, count, endpoint=False)
        return np.c_[o["centre_m"][0] + o["radius_m"] * np.cos(a),
                     o["centre_m"][1] + o["radius_m"] * np.sin(a)]
    v = np.asarray(o["vertices_m"], dtype=float)
    nxt = np.roll(v, -1, axis=0)
    f = np.linspace(0, 1, count // len(v), endpoint=False)
    return (v[:, None] + f[None, :, None] * (nxt - v)[:, None]).reshape(-1, 2)


def _wall_gap(o: dict) -> float:
    pts = _outline(o)
    w, h = TANK_M
    return float(np.min([pts[:, 0].min(), w - pts[:, 0].max(), pts[:, 1].min(),
                         h - pts[:, 1].max()]))


def generate_world(seed: int) -> World:
    """One benchmark world (module docstring).

    Parameters
    ----------
    seed : int

    Returns
    -------
    World
    """
    rng = np.random.default_rng(seed)
    w, h = TANK_M
    while True:
        start = np.array([rng.uniform(0.4, 0.8), rng.uniform(0.45, h - 0.45)])
        goal = np.array([rng.uniform(2.2, 2.7), rng.uniform(0.3, h - 0.3)])
        if rng.random() < 0.5:  # half the worlds run right to left, or diagonally
            start[0], goal[0] = w - start[0], w - goal[0]
        if np.hypot(*(goal - start)) >= 1.5:
            break
    towards = math.degrees(math.atan2(goal[1] - start[1], goal[0] - start[0]))
    heading = towards + rng.uniform(-45.0, 45.0)
    count = int(rng.integers(5, 9))
    obstacles: list[dict] = []
    if rng.random() < 1 / 3:
        x = float(np.clip((start[0] + goal[0]) / 2 + rng.uniform(-0.25, 0.25), 1.0, 2.0))
        gap = rng.uniform(MIN_GAP_M, 0.6)
        middle = rng.uniform(0.45, h - 0.45)
        thick = rng.uniform(0.08, 0.15)
        low, high = middle - gap / 2, middle + gap / 2
        obstacles.append({"kind": "polygon", "vertices_m": [
            [x - thick / 2, 0.0], [x + thick / 2, 0.0], [x + thick / 2, low], [x - thick / 2, low]]})
        obstacles.append({"kind": "polygon", "vertices_m": [
            [x - thick / 2, high], [x + thick / 2, high], [x + thick / 2, h], [x - thick / 2, h]]})
    tries = 0
    while len(obstacles) < count and tries < 2000:
        tries += 1
        centre = [rng.uniform(0.2, w - 0.2), rng.uniform(0.2, h - 0.2)]
        if rng.random() < 0.5:
            cand = {"kind": "circle", "centre_m": centre, "radius_m": rng.uniform(0.08, 0.2)}
        else:
            cand = {"kind": "polygon", "vertices_m": _rectangle(
                centre, rng.uniform(0.2, 0.6), rng.uniform(0.08, 0.25), rng.uniform(0, math.pi))}
        pts = _outline(cand)
        if np.hypot(*(pts - start).T).min() < 0.45:
            continue
        if np.hypot(*(pts - goal).T).min() < 0.2 + 0.1:
            continue
        wall = _wall_gap(cand)
        if wall < 0 or 0 < wall < MIN_GAP_M:
            continue
        if any(0 < _gap(cand, o) < MIN_GAP_M for o in obstacles):
            continue
        obstacles.append(cand)
    speed = float(rng.uniform(0.0, 0.06))
    direction = float(rng.uniform(0.0, 360.0))
    return _world(f"bench_{seed}", start.round(3).tolist(), round(heading, 1),
                  goal.round(3).tolist(), round(speed, 4), round(direction, 1), obstacles)


def issue_worlds() -> dict[str, World]:
    """The worlds issue 20 tried.

    A 0.35 m gap off the start-goal line, a 0.6 m gap, a 0.06 m/s current against the goal,
    and a goal behind a wall with no gate.

    Returns
    -------
    dict of str -> World
    """
    def barrier(x: float, low: float, high: float, thick: float = 0.1) -> list[dict]:
        h = TANK_M[1]
        return [
            {"kind": "polygon", "vertices_m": [[x - thick / 2, 0.0], [x + thick / 2, 0.0],
                                               [x + thick / 2, low], [x - thick / 2, low]]},
            {"kind": "polygon", "vertices_m": [[x - thick / 2, high], [x + thick / 2, high],
                                               [x + thick / 2, h], [x - thick / 2, h]]},
        ]

    blocks = [{"kind": "circle", "centre_m": [0.9, 1.55], "radius_m": 0.12},
              {"kind": "circle", "centre_m": [2.2, 0.45], "radius_m": 0.12}]
    return {
        "gap_0.35_off_line": _world("gap_0.35_off_line", (0.5, 1.0), 0.0, (2.5, 1.0), 0.0, 0.0,
                                    barrier(1.5, 1.25, 1.6) + blocks),
        "gap_0.6": _world("gap_0.6", (0.5, 1.0), 0.0, (2.5, 1.0), 0.0, 0.0,
                          barrier(1.5, 0.55, 1.15) + blocks),
        "current_0.06_against": _world("current_0.06_against", (0.5, 1.0), 0.0, (2.5, 1.0),
                                       0.06, 180.0, blocks),
        "walled_off_goal": _world("walled_off_goal", (0.5, 1.0), 0.0, (2.5, 1.0), 0.0, 0.0,
                                  [{"kind": "polygon", "vertices_m": [
                                      [1.8, 0.0], [2.0, 0.0], [2.0, 2.0], [1.8, 2.0]]}]),
    }
