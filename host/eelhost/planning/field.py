"""Two maps of a world on a grid: clearance from obstacles and walls, and the distance to the goal.

- :class:`ClearanceField`: the signed distance from any point to the nearest obstacle or wall
  (negative inside one), computed exactly at the nodes of a square grid and interpolated
  bilinearly in between. Distance is 1-Lipschitz, so the interpolant is never more than
  ``error_m`` (half the cell diagonal) above the true value; the search subtracts that bound and so
  never calls a point clearer than it is. It lets the search check thousands of body points per
  manoeuvre in one vectorised lookup; the twin's final check uses the exact geometry
  (:meth:`eelhost.planning.world.World.segments_clearance`).
- :class:`GoalDistance`: the length of the shortest path from each node to the goal disc through
  nodes where the body fits (clearance at least the body's half width), by Dijkstra on the
  8-connected grid (scipy). It is the search's heuristic, and it tells at once when no corridor
  wide enough for the body joins start and goal.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import map_coordinates
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from eelhost.planning.geometry import FloatArray, point_segment_distance, points_in_polygon
from eelhost.planning.memo import BoundedCache
from eelhost.planning.world import CircleObstacle, World

BoolArray = NDArray[np.bool_]


def signed_clearance(world: World, points: FloatArray) -> FloatArray:
    """Exact signed distance from points to the nearest obstacle or wall (negative inside).

    Parameters
    ----------
    world : World
    points : ndarray, shape (P, 2)

    Returns
    -------
    ndarray, shape (P,)
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    w, h = world.tank.size_m
    best = np.minimum.reduce([pts[:, 0], w - pts[:, 0], pts[:, 1], h - pts[:, 1]])
    for o in world.obstacles:
        if isinstance(o, CircleObstacle):
            d = np.hypot(*(pts - np.asarray(o.centre_m)).T) - o.radius_m
        else:
            poly = np.asarray(o.vertices_m, dtype=float)
            d = np.empty(len(pts))
            for k in range(0, len(pts), 4096):  # bounded memory: points x edges
                chunk = pts[k : k + 4096]
                d[k : k + 4096] = point_segment_distance(
                    chunk, poly, np.roll(poly, -1, axis=0)
                ).min(axis=1)
            d[points_in_polygon(pts, poly)] *= -1.0
        best = np.minimum(best, d)
    return best


class ClearanceField:
    """Signed clearance of a world on a grid, interpolated bilinearly (module docstring).

    Parameters
    ----------
    world : World
    cell_m : float
        Grid spacing.
    """

    def __init__(self, world: World, cell_m: float = 0.01) -> None:
        w, h = world.tank.size_m
        self.cell_m = float(cell_m)
        self.nx = int(math.ceil(w / cell_m)) + 1
        self.ny = int(math.ceil(h / cell_m)) + 1
        xs = np.arange(self.nx) * cell_m
        ys = np.arange(self.ny) * cell_m
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        self.values = signed_clearance(world, np.c_[gx.ravel(), gy.ravel()]).reshape(
            self.nx, self.ny
        )
        self.error_m = self.cell_m * math.sqrt(2.0) / 2.0
        """Largest amount by which the interpolant can exceed the true clearance."""

    def __call__(self, points: FloatArray) -> FloatArray:
        """Interpolated clearance at points.

        Outside the grid: the nearest edge value, minus the distance beyond it.

        Parameters
        ----------
        points : ndarray, shape (..., 2)

        Returns
        -------
        ndarray, shape (...)
        """
        p = np.asarray(points, dtype=float)
        shape = p.shape[:-1]
        # the grid coordinates written straight into the rows map_coordinates reads (the same
        # values as dividing and clipping apart, without joining them afterwards)
        coords = np.empty((2, int(np.prod(shape))))
        np.divide(p[..., 0].reshape(-1), self.cell_m, out=coords[0])
        np.divide(p[..., 1].reshape(-1), self.cell_m, out=coords[1])
        beyond = ((coords[0] < 0.0) | (coords[0] > self.nx - 1.0)
                  | (coords[1] < 0.0) | (coords[1] > self.ny - 1.0))
        off = np.flatnonzero(beyond)
        u, v = coords[0, off], coords[1, off]  # copies: the points beyond the grid
        np.clip(coords[0], 0.0, self.nx - 1.0, out=coords[0])
        np.clip(coords[1], 0.0, self.ny - 1.0, out=coords[1])
        # bilinear (order 1, no prefilter) interpolation of the node values
        val = map_coordinates(self.values, coords, order=1, prefilter=False, mode="nearest")
        if off.size:
            # beyond the grid: the nearest edge value, less the distance beyond it (inside,
            # that distance is 0 and taking it off changes nothing)
            val[off] -= np.hypot(u - coords[0, off], v - coords[1, off]) * self.cell_m
        return val.reshape(shape)


FIELD_CACHE_SIZE = 16
"""Clearance fields :func:`clearance_field` keeps (the most recently used; 0.5 MB each for a
3 x 2 m tank at 10 mm)."""

_FIELDS: BoundedCache[ClearanceField] = BoundedCache(FIELD_CACHE_SIZE)


def clearance_field(world: World, cell_m: float = 0.01) -> ClearanceField:
    """The world's :class:`ClearanceField`, built once per tank and obstacles in this process.

    The field depends on the tank and the obstacles alone, not on the current or the
    clearance the world asks for, so the planners of one world share it: the replanner's, one
    per current estimate, and the goal approach's and the recovery's. Building it took 0.9 s of a
    replan's 1 s budget on a slower processor (docs/planning.md, "The replan's deadline").
    The field is read only; callers must not change its values.

    Parameters
    ----------
    world : World
    cell_m : float
        Grid spacing.

    Returns
    -------
    ClearanceField
    """
    def build() -> ClearanceField:
        field = ClearanceField(world, cell_m)
        field.values.setflags(write=False)
        return field

    return _FIELDS.get((world.model_dump_json(include={"tank", "obstacles"}), float(cell_m)),
                       build)


class GoalDistance:
    """Shortest free-space path length from grid nodes to the goal disc (module docstring).

    Parameters
    ----------
    world : World
    clearance : ClearanceField
        Only its values at nodes every ``stride`` cells are used.
    body_half_width_m : float
        Nodes with less clearance than this are blocked.
    cell_m : float
        Grid spacing of the map (a multiple of the clearance field's).
    preferred_clearance_m, clearance_cost : float
        The search's soft margin (:class:`eelhost.planning.search.SearchSettings`): a step
        between nodes whose mean clearance c is under the preferred clearance p costs its
        length times 1 + clearance_cost ((p - c) / (p - body_half_width_m))^2, so the map is
        the soft margin's cost of the cheapest path, in metres at the swimming speed
        (0: plain path length).
    """

    def __init__(
        self,
        world: World,
        clearance: ClearanceField,
        body_half_width_m: float,
        cell_m: float = 0.05,
        preferred_clearance_m: float = 0.0,
        clearance_cost: float = 0.0,
    ) -> None:
        stride = max(1, int(round(cell_m / clearance.cell_m)))
        self.cell_m = clearance.cell_m * stride
        free = clearance.values[::stride, ::stride] >= body_half_width_m
        near = clearance.values[::stride, ::stride].ravel()
        nx, ny = free.shape
        self.shape = (nx, ny)
        xs = np.arange(nx) * self.cell_m
        ys = np.arange(ny) * self.cell_m
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        gxy = np.c_[gx.ravel(), gy.ravel()]
        goal = np.asarray(world.goal.position_m)
        in_goal = (np.hypot(*(gxy - goal).T) <= world.goal.radius_m) & free.ravel()
        ids = np.arange(nx * ny).reshape(nx, ny)
        rows, cols, lens = [], [], []
        for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
            a = ids[max(0, -di) : nx - max(0, di), max(0, -dj) : ny - max(0, dj)]
            b = ids[max(0, di) : max(0, di) + a.shape[0], max(0, dj) : max(0, dj) + a.shape[1]]
            ok = free.ravel()[a.ravel()] & free.ravel()[b.ravel()]
            rows.append(a.ravel()[ok])
            cols.append(b.ravel()[ok])
            length = np.full(int(ok.sum()), math.hypot(di, dj) * self.cell_m)
            if clearance_cost > 0 and preferred_clearance_m > body_half_width_m:
                mid = 0.5 * (near[a.ravel()[ok]] + near[b.ravel()[ok]])
                short = np.clip((preferred_clearance_m - mid)
                                / (preferred_clearance_m - body_half_width_m), 0.0, 1.0)
                length = length * (1.0 + clearance_cost * short ** 2)
            lens.append(length)
        r, c, ln = np.concatenate(rows), np.concatenate(cols), np.concatenate(lens)
        graph = coo_matrix((np.r_[ln, ln], (np.r_[r, c], np.r_[c, r])), shape=(nx * ny,) * 2)
        sources = np.flatnonzero(in_goal)
        if sources.size:
            dist = dijkstra(graph.tocsr(), directed=False, indices=sources, min_only=True)
        else:
            dist = np.full(nx * ny, np.inf)
        # a node inside the goal disc is at distance 0; elsewhere the path ends on the disc's
        # nodes, so subtracting nothing keeps the map a lower bound up to one cell
        self.values = np.asarray(dist, dtype=float).reshape(nx, ny)
        self.free = free

    def __call__(self, xy: FloatArray) -> float:
        """Path length from a point to the goal.

        The smallest over the four surrounding nodes of their distance plus the straight
        distance to them (inf when none is connected).

        Parameters
        ----------
        xy : array_like, shape (2,)

        Returns
        -------
        float
        """
        u, v = float(xy[0]) / self.cell_m, float(xy[1]) / self.cell_m
        i0 = min(max(int(math.floor(u)), 0), self.shape[0] - 2)
        j0 = min(max(int(math.floor(v)), 0), self.shape[1] - 2)
        best = math.inf
        for i in (i0, i0 + 1):
            for j in (j0, j0 + 1):
                d = self.values[i, j]
                if math.isfinite(d):
                    best = min(best, d + math.hypot(u - i, v - j) * self.cell_m)
        return best
