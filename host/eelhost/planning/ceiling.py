"""A geometric ceiling on the plan share: how much room the widest route of a world leaves.

docs/planning_history.md, "Targets of issue 28 (the planner's)", "A geometric ceiling", is the long form.
Written apart from the planner (its own distance field, from shapely's exact geometry, and its
own route search), so that it says what any planner could reach, not what this one does.

For a world, the *bottleneck clearance* is the largest c such that some route of the body's
centre point from the start to the goal disc keeps at least c from every obstacle and wall
(the maximin, or widest, path over the distance field). If the body's centre line followed
that route exactly, every centre-line point would be on it, so no plan can keep the centre
line further than c from everything; a plan that must leave room X for how far the body strays
in water the planner does not know exists only where c >= half width + X.

The route is found on a square grid (cell ``cell_m``, 8-connected) by a bisection on the
clearance threshold with connected-component labelling: the bottleneck is the largest
threshold whose free cells join a start cell to a goal cell. Its error against the continuous
answer is at most one cell (a cell centre is within half a cell diagonal of the continuous
route, and a step between neighbouring centres passes within half a diagonal of a cell centre).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from scipy import ndimage

from eelhost.planning.geometry import FloatArray
from eelhost.planning.world import World

log = logging.getLogger(__name__)

CELL_M = 0.01
"""Grid cell of the distance field (m)."""

START_RADIUS_M = 0.2
"""A route may begin anywhere within this distance of the start's centre of mass (m): where the
body starts is given, not chosen, so its own neighbourhood is not the route's bottleneck (the
start's clearance is reported apart, :attr:`Ceiling.start_clearance_m`)."""

MARGINS_M = (0.050, 0.075, 0.100, 0.125, 0.150, 0.175, 0.200, 0.250, 0.300)
"""Room beyond the body's half width the ceiling table is given for (m)."""


@dataclass(frozen=True)
class Ceiling:
    """One world's room.

    Attributes
    ----------
    name : str
    bottleneck_m : float
        Largest clearance of the body's centre point a route from within
        :data:`START_RADIUS_M` of the start to the goal disc can keep from everything (m).
    start_clearance_m : float
        Clearance of the straight body's centre line at the start pose (m).
    """

    name: str
    bottleneck_m: float
    start_clearance_m: float

    def room_m(self) -> float:
        """The smaller of the route's bottleneck and the start's clearance (m)."""
        return min(self.bottleneck_m, self.start_clearance_m)


def _obstacles(world: World) -> shapely.Geometry:
    shapes = []
    for o in world.obstacles:
        if o.kind == "circle":
            shapes.append(shapely.Point(o.centre_m).buffer(o.radius_m, quad_segs=64))
        else:
            shapes.append(shapely.Polygon(o.vertices_m))
    return shapely.union_all(shapes) if shapes else shapely.Polygon()


def distance_field(world: World, cell_m: float = CELL_M) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Distance from each grid cell centre to the nearest obstacle or wall (0 inside either).

    Parameters
    ----------
    world : World
    cell_m : float
        Grid cell (m).

    Returns
    -------
    xs : ndarray, shape (nx,)
        Cell centres along x (m).
    ys : ndarray, shape (ny,)
        Cell centres along y (m).
    clearance : ndarray, shape (ny, nx)
        Distance (m); circles are exact to the buffer's 256-gon (under 0.01 mm for the
        worlds' radii), polygons exact.
    """
    w, h = world.tank.size_m
    xs = np.arange(cell_m / 2, w, cell_m)
    ys = np.arange(cell_m / 2, h, cell_m)
    gx, gy = np.meshgrid(xs, ys)
    walls = np.minimum.reduce([gx, w - gx, gy, h - gy])
    obstacles = _obstacles(world)
    if obstacles.is_empty:
        return xs, ys, walls
    shapely.prepare(obstacles)
    d = shapely.distance(shapely.points(gx.ravel(), gy.ravel()), obstacles).reshape(gx.shape)
    return xs, ys, np.minimum(walls, d)


def bottleneck_m(
    xs: FloatArray,
    ys: FloatArray,
    clearance: FloatArray,
    source: np.ndarray,
    target: np.ndarray,
    tolerance_m: float = 1e-4,
) -> float:
    """Largest threshold t whose cells with clearance >= t join ``source`` to ``target``.

    Parameters
    ----------
    xs, ys : ndarray
        Cell centres (unused but for the shape check).
    clearance : ndarray, shape (ny, nx)
    source, target : ndarray of bool, shape (ny, nx)
        Cells a route may begin in, and cells it may end in. Source cells count as free
        whatever their clearance.
    tolerance_m : float
        Bisection's stopping width (m).

    Returns
    -------
    float
        The bottleneck (m); 0 when no route exists at any positive threshold.
    """
    if clearance.shape != (len(ys), len(xs)):
        raise ValueError(f"clearance shape {clearance.shape} is not (len(ys), len(xs))")
    if not source.any() or not target.any():
        raise ValueError("the route's source or target has no cell")
    structure = np.ones((3, 3), dtype=bool)

    def joined(t: float) -> bool:
        labels, _ = ndimage.label((clearance >= t) | source, structure=structure)
        start = np.unique(labels[source])
        end = labels[target & (clearance >= t)]
        return bool(np.isin(end, start[start > 0]).any())

    lo, hi = 0.0, float(clearance[target].max())
    if not joined(lo + 1e-12):
        return 0.0
    if joined(hi):
        return hi
    while hi - lo > tolerance_m:
        mid = 0.5 * (lo + hi)
        if joined(mid):
            lo = mid
        else:
            hi = mid
    return lo


def start_clearance_m(world: World, body_length_m: float) -> float:
    """Clearance of the straight body's centre line at the start pose (m).

    Parameters
    ----------
    world : World
    body_length_m : float
        Tip to tip (m); the centre of mass is taken at the middle.
    """
    heading = math.radians(world.start.heading_deg)
    half = 0.5 * body_length_m * np.array([math.cos(heading), math.sin(heading)])
    p = np.asarray(world.start.position_m, dtype=float)
    line = shapely.LineString([p - half, p + half])
    w, h = world.tank.size_m
    walls = shapely.box(0.0, 0.0, w, h).exterior
    d = shapely.distance(line, walls)
    obstacles = _obstacles(world)
    if not obstacles.is_empty:
        d = min(d, shapely.distance(line, obstacles))
    inside = shapely.box(0.0, 0.0, w, h).contains(line)
    return float(d) if inside else 0.0


def world_ceiling(world: World, body_length_m: float, cell_m: float = CELL_M,
                  start_radius_m: float = START_RADIUS_M) -> Ceiling:
    """The bottleneck of a world's widest route and the start's clearance (module docstring).

    Parameters
    ----------
    world : World
    body_length_m : float
        Tip to tip (m), for the start's clearance.
    cell_m : float
    start_radius_m : float

    Returns
    -------
    Ceiling
    """
    xs, ys, clearance = distance_field(world, cell_m)
    gx, gy = np.meshgrid(xs, ys)
    sx, sy = world.start.position_m
    source = np.hypot(gx - sx, gy - sy) <= max(start_radius_m, cell_m)
    qx, qy = world.goal.position_m
    target = np.hypot(gx - qx, gy - qy) <= max(world.goal.radius_m, cell_m)
    return Ceiling(world.name, bottleneck_m(xs, ys, clearance, source, target),
                   start_clearance_m(world, body_length_m))


def share_at_least(values_m: Sequence[float], thresholds_m: Sequence[float]) -> list[float]:
    """Share of ``values_m`` at least each threshold (0 to 1)."""
    v = np.asarray(values_m, dtype=float)
    return [float(np.mean(v >= t)) if v.size else math.nan for t in thresholds_m]


def main(argv: Sequence[str] | None = None) -> int:
    """Print the ceiling table for a range of generated worlds (``python -m eelhost.planning.ceiling``)."""
    import argparse

    from eelhost.planning.worlds import generate_world
    from eelsim.model import SwimmerModel
    from eelsim.robot import load_robot

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=8000, help="first world's seed")
    parser.add_argument("--worlds", type=int, default=100, help="number of worlds")
    args = parser.parse_args(argv)
    robot = load_robot()
    model = SwimmerModel.from_robot(robot)
    half_width = float(model.half_axis_horizontal_m.max())
    length = float(2.0 * model.half_length_m.sum())
    rows = [world_ceiling(generate_world(s), length)
            for s in range(args.seed, args.seed + args.worlds)]
    route = [c.bottleneck_m - half_width for c in rows]
    both = [c.room_m() - half_width for c in rows]
    print(f"worlds {args.seed}-{args.seed + args.worlds - 1}, body half width "
          f"{half_width * 1000:.1f} mm, length {length * 1000:.0f} mm")
    print("X (mm) | route keeps half width + X | and the start's body too")
    for x, a, b in zip(MARGINS_M, share_at_least(route, MARGINS_M),
                       share_at_least(both, MARGINS_M), strict=True):
        print(f"{x * 1000:6.0f} | {a * 100:5.0f} % | {b * 100:5.0f} %")
    q = np.percentile(route, [10, 25, 50, 75, 90])
    print("route room beyond half width, percentiles 10/25/50/75/90 (mm): "
          + " ".join(f"{v * 1000:.0f}" for v in q))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
