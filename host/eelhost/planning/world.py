"""The planning world: tank, start, goal, current and obstacles, read from a TOML file.

A world file looks like this (every key shown; ``clearance_m`` is optional)::

    name = "five obstacles"
    clearance_m = 0.05            # extra margin kept from obstacles and walls while planning

    [tank]
    size_m = [3.0, 2.0]           # the tank spans x in [0, 3] m and y in [0, 2] m

    [start]
    position_m = [0.35, 1.0]
    heading_deg = 0.0

    [goal]
    position_m = [2.6, 1.0]
    radius_m = 0.2

    [current]
    speed_m_s = 0.03
    direction_deg = 180.0         # the direction it flows towards

    [[obstacles]]
    kind = "circle"
    centre_m = [1.0, 1.0]
    radius_m = 0.15

    [[obstacles]]
    kind = "polygon"
    vertices_m = [[1.6, 0.0], [1.8, 0.0], [1.8, 0.8], [1.6, 0.8]]

Unknown keys are refused; errors name the file and the key.
"""

from __future__ import annotations

import math
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from eelhost.errors import UserError
from eelhost.planning.geometry import (
    FloatArray,
    inside_convex,
    point_segment_distance,
    points_in_polygon,
    segments_circle_distance,
    segments_cross,
    segments_polygon_distance,
)
from eelsim.tomlfile import read_toml, validation_message

Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]  # "1" or true refused
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False, strict=True)]
Point = tuple[Finite, Finite]

EXAMPLES = ("tank_5_obstacles",)

MIN_POLYGON_AREA_M2 = 1e-6
"""A polygon obstacle enclosing less (1 mm^2) is refused as degenerate."""

BOX_TOLERANCE_M = 1e-9
""":meth:`World.body_clearance` leaves an obstacle out of a step only when the step's bounding
box is further from it than this over the smallest distance so far, m: room for rounding, so
that no step's value differs from measuring every obstacle (docs/planning.md, "The planner's
processor time (session 24)")."""


class WorldError(UserError, ValueError):
    """An invalid or unreadable world file."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Tank(_Strict):
    """The tank: a rectangle from (0, 0) to ``size_m``."""

    size_m: tuple[Positive, Positive]


class Start(_Strict):
    """Start pose of the robot (straight, at rest)."""

    position_m: Point
    heading_deg: Finite = 0.0


class Goal(_Strict):
    """Goal region: a disc the robot's centre of mass must enter."""

    position_m: Point
    radius_m: Positive = 0.2


class Current(_Strict):
    """Uniform steady current: speed and the direction it flows towards."""

    speed_m_s: Annotated[float, Field(ge=0, allow_inf_nan=False, strict=True)] = 0.0
    direction_deg: Finite = 0.0


class CircleObstacle(_Strict):
    """A round obstacle."""

    kind: Literal["circle"]
    centre_m: Point
    radius_m: Positive


class PolygonObstacle(_Strict):
    """A simple polygon obstacle (vertices in order, not repeated, at least 3).

    Refused when read: a polygon whose edges cross or touch other than at shared corners
    (self-intersecting), or with no area (fewer than 3 distinct corners, all on one line): the
    inside test and the distances of the planner assume a simple polygon with an inside.
    """

    kind: Literal["polygon"]
    vertices_m: list[Point] = Field(min_length=3)

    @model_validator(mode="after")
    def _simple(self) -> PolygonObstacle:
        from shapely.geometry import Polygon
        from shapely.validation import explain_validity

        shape = Polygon(self.vertices_m)
        if shape.convex_hull.area < MIN_POLYGON_AREA_M2:
            raise ValueError(f"degenerate polygon: its vertices enclose no area "
                             f"({shape.area:.2g} m^2); give at least 3 corners not on one line")
        if not shape.is_valid or shape.area < MIN_POLYGON_AREA_M2:
            raise ValueError(f"self-intersecting polygon: {explain_validity(shape)} (its edges "
                             "may meet only at shared corners, in order round the outline)")
        return self


Obstacle = Annotated[CircleObstacle | PolygonObstacle, Field(discriminator="kind")]


class World(_Strict):
    """Everything the planner needs to know about the task (SI units).

    Attributes
    ----------
    name : str
    tank : Tank
    start : Start
    goal : Goal
    current : Current
    obstacles : list of CircleObstacle or PolygonObstacle
    clearance_m : float
        Margin kept between a primitive's swept hull and obstacles or walls while planning,
        on top of the robot's half width (the hull is drawn through the link centre lines).
    """

    name: str = "world"
    tank: Tank
    start: Start
    goal: Goal
    current: Current = Current()
    obstacles: list[Obstacle] = Field(default_factory=list)
    clearance_m: Annotated[float, Field(ge=0, allow_inf_nan=False, strict=True)] = 0.03

    @model_validator(mode="after")
    def _start_and_goal_in_tank(self) -> World:
        w, h = self.tank.size_m
        for key, (x, y) in (("start.position_m", self.start.position_m),
                            ("goal.position_m", self.goal.position_m)):
            if not (0 < x < w and 0 < y < h):
                raise ValueError(f"{key} ({x}, {y}) is outside the tank [0, {w}] x [0, {h}] m")
        return self

    @property
    def current_m_s(self) -> tuple[float, float]:
        """The current velocity vector, m/s."""
        a = math.radians(self.current.direction_deg)
        return (self.current.speed_m_s * math.cos(a), self.current.speed_m_s * math.sin(a))

    @cached_property
    def _polygons(self) -> list[FloatArray]:
        return [
            np.asarray(o.vertices_m, dtype=float)
            for o in self.obstacles
            if isinstance(o, PolygonObstacle)
        ]

    @cached_property
    def _circles(self) -> list[tuple[FloatArray, float]]:
        return [
            (np.asarray(o.centre_m, dtype=float), float(o.radius_m))
            for o in self.obstacles
            if isinstance(o, CircleObstacle)
        ]

    @cached_property
    def obstacle_bounds(self) -> FloatArray:
        """Bounding circle (x, y, radius) of every obstacle, polygons first, shape (K, 3)."""
        rows = []
        for poly in self._polygons:
            c = poly.mean(axis=0)
            rows.append([c[0], c[1], np.linalg.norm(poly - c, axis=1).max()])
        for c, r in self._circles:
            rows.append([c[0], c[1], r])
        return np.asarray(rows, dtype=float).reshape(-1, 3)

    def inside_tank(self, points: FloatArray, margin_m: float) -> bool:
        """Whether every point keeps ``margin_m`` from the tank walls.

        Parameters
        ----------
        points : ndarray, shape (P, 2)
        margin_m : float

        Returns
        -------
        bool
        """
        w, h = self.tank.size_m
        x, y = points[:, 0], points[:, 1]
        return bool(
            np.all(x >= margin_m) & np.all(x <= w - margin_m)
            & np.all(y >= margin_m) & np.all(y <= h - margin_m)
        )

    def hulls_free(self, hulls: FloatArray, margin_m: float) -> NDArray[np.bool_]:
        """Which convex regions keep ``margin_m`` from every obstacle and wall.

        All regions are tested at once (the planner passes every child of a node together).

        Parameters
        ----------
        hulls : ndarray, shape (M, H, 2)
            Counter-clockwise vertices of each convex region in the world frame; repeated
            vertices (padding) are allowed.
        margin_m : float

        Returns
        -------
        ndarray of bool, shape (M,)
        """
        w, h = self.tank.size_m
        x, y = hulls[..., 0], hulls[..., 1]
        free = (
            (x.min(axis=1) >= margin_m) & (x.max(axis=1) <= w - margin_m)
            & (y.min(axis=1) >= margin_m) & (y.max(axis=1) <= h - margin_m)
        )
        if not np.any(free) or not self.obstacles:
            return free
        # bounding circles first: most hulls are far from most obstacles
        centres = hulls.mean(axis=1)
        reach = np.linalg.norm(hulls - centres[:, None], axis=2).max(axis=1)
        bounds = self.obstacle_bounds
        gap = np.linalg.norm(centres[:, None] - bounds[None, :, :2], axis=2)
        near = free[:, None] & (gap <= reach[:, None] + bounds[None, :, 2] + margin_m)
        if not np.any(near):
            return free
        pick = np.flatnonzero(near.any(axis=1))
        free[pick] &= self._hulls_clear(hulls[pick], np.flatnonzero(near.any(axis=0)), margin_m)
        return free

    def _hulls_clear(self, hulls: FloatArray, obstacles: NDArray[np.int64], margin_m: float):
        """Exact test of hulls against the obstacles numbered ``obstacles`` (polygons first)."""
        free = np.ones(len(hulls), dtype=bool)
        a, b = hulls, np.roll(hulls, -1, axis=1)
        n_poly = len(self._polygons)
        circles = [self._circles[k - n_poly] for k in obstacles if k >= n_poly]
        polygons = [self._polygons[k] for k in obstacles if k < n_poly]
        if circles:
            centres = np.stack([c for c, _ in circles])[None]  # (1, C, 2)
            radii = np.array([r for _, r in circles])
            near = point_segment_distance(centres, a, b).min(axis=2) - radii <= margin_m
            free &= ~np.any(near | inside_convex(centres, hulls), axis=1)
        if polygons:
            verts = np.concatenate(polygons)
            e2 = np.concatenate([np.roll(p, -1, axis=0) for p in polygons])
            starts = np.cumsum([0] + [len(p) for p in polygons[:-1]])
            e1b, e2b, vb = verts[None], e2[None], verts[None]
            hit = np.any(segments_cross(a, b, e1b, e2b), axis=(1, 2))
            hit |= np.any(inside_convex(vb, hulls), axis=1)
            hit |= point_segment_distance(hulls, e1b, e2b).min(axis=(1, 2)) <= margin_m
            hit |= point_segment_distance(vb, a, b).min(axis=(1, 2)) <= margin_m
            # a hull wholly inside a polygon meets none of its edges: even-odd test of one vertex
            px, py = hulls[:, 0, 0:1], hulls[:, 0, 1:2]
            e1 = verts
            straddle = (e1[None, :, 1] > py) != (e2[None, :, 1] > py)
            dy = e2[:, 1] - e1[:, 1]
            x_cross = e1[:, 0] + (py - e1[:, 1]) * (e2[:, 0] - e1[:, 0]) / np.where(dy == 0, 1, dy)
            crossings = np.add.reduceat((straddle & (px < x_cross)).astype(int), starts, axis=1)
            hit |= np.any(crossings % 2 == 1, axis=1)
            free &= ~hit
        return free

    def hull_is_free(self, hull: FloatArray, margin_m: float) -> bool:
        """Whether one convex region keeps ``margin_m`` from every obstacle and wall.

        Parameters
        ----------
        hull : ndarray, shape (H, 2)
            Counter-clockwise vertices in the world frame.
        margin_m : float

        Returns
        -------
        bool
        """
        return bool(self.hulls_free(np.asarray(hull, dtype=float)[None], margin_m)[0])

    def segments_clearance(self, a: FloatArray, b: FloatArray) -> float:
        """Smallest distance from segments to any obstacle or wall (0 if one touches).

        Parameters
        ----------
        a, b : ndarray, shape (S, 2)
            Segment end points (e.g. the links of the robot at every step).

        Returns
        -------
        float
        """
        w, h = self.tank.size_m
        pts = np.concatenate([a, b])
        wall = float(
            np.min([pts[:, 0].min(), w - pts[:, 0].max(), pts[:, 1].min(), h - pts[:, 1].max()])
        )
        best = max(0.0, wall)
        for poly in self._polygons:
            best = min(best, segments_polygon_distance(a, b, poly))
        for c, r in self._circles:
            best = min(best, segments_circle_distance(a, b, c, r))
        return best


    def body_clearance(self, polylines: FloatArray,
                       at_most: FloatArray | None = None) -> FloatArray:
        """Exact distance from each polyline to the nearest obstacle or wall (0 when touching).

        The executor's check of the robot's centre line at every step of a run.

        Parameters
        ----------
        polylines : ndarray, shape (K, P, 2)
            K polylines of P points (e.g. the link end points at K steps).
        at_most : ndarray, shape (K,), optional
            A bound each distance is known not to exceed (the check's field bound): an
            obstacle whose bounding box is further from a polyline's is not measured. Only the
            time depends on it, never a value.

        Returns
        -------
        ndarray, shape (K,)
        """
        pts = np.asarray(polylines, dtype=float)
        w, h = self.tank.size_m
        x, y = pts[..., 0], pts[..., 1]
        x_lo, x_hi, y_lo, y_hi = x.min(axis=1), x.max(axis=1), y.min(axis=1), y.max(axis=1)
        best = np.maximum(0.0, np.minimum.reduce([x_lo, w - x_hi, y_lo, h - y_hi]))
        a, b = pts[:, :-1], pts[:, 1:]

        def beyond(lo: FloatArray, hi: FloatArray) -> FloatArray:
            # how far each polyline's bounding box is from the box lo-hi: no point of the
            # polyline is nearer to anything in that box (a step whose obstacle is further
            # than its smallest distance so far is not measured: the same values)
            return np.hypot(np.maximum(np.maximum(lo[0] - x_hi, x_lo - hi[0]), 0.0),
                            np.maximum(np.maximum(lo[1] - y_hi, y_lo - hi[1]), 0.0))

        # a distance is never below 0 (a bound below it, inside an obstacle, bounds nothing)
        cap = math.inf if at_most is None else np.maximum(at_most, 0.0)
        for c, r in self._circles:
            rows = np.flatnonzero(beyond(c, c) - r <= np.minimum(best, cap) + BOX_TOLERANCE_M)
            if not rows.size:
                continue
            d = point_segment_distance(c[None, None], a[rows], b[rows])[:, 0].min(axis=1) - r
            best[rows] = np.minimum(best[rows], np.maximum(d, 0.0))
        for poly in self._polygons:
            # only steps that its bounding box and circle leave a chance to come closer than so
            # far
            near = np.flatnonzero(beyond(poly.min(axis=0), poly.max(axis=0))
                                  <= np.minimum(best, cap) + BOX_TOLERANCE_M)
            if not near.size:
                continue
            centre = poly.mean(axis=0)
            radius = float(np.hypot(*(poly - centre).T).max())
            gap = np.hypot(pts[near, :, 0] - centre[0], pts[near, :, 1] - centre[1]).min(axis=1)
            rows = near[gap - radius < best[near]]
            if not rows.size:
                continue
            pa, pb, pp = a[rows], b[rows], pts[rows]
            e1, e2 = poly[None], np.roll(poly, -1, axis=0)[None]
            touch = np.any(segments_cross(pa, pb, e1, e2), axis=(1, 2))
            touch |= points_in_polygon(pp[:, 0], poly)
            d = np.minimum(
                point_segment_distance(pp, e1, e2).min(axis=(1, 2)),
                point_segment_distance(poly[None], pa, pb).min(axis=(1, 2)),
            )
            best[rows] = np.minimum(best[rows], np.where(touch, 0.0, d))
        return best


def example_path(name: str = "tank_5_obstacles") -> Path:
    """Path of a bundled example world file.

    Parameters
    ----------
    name : str
        One of :data:`EXAMPLES`.

    Returns
    -------
    Path
    """
    if name not in EXAMPLES:
        raise WorldError(f"unknown example world {name!r}; bundled: {', '.join(EXAMPLES)}")
    return Path(str(resources.files("eelhost.planning") / "examples" / f"{name}.toml"))


def parse_world(data: dict, source: str = "<world>") -> World:
    """Validate a world from a dict (as read from TOML).

    Parameters
    ----------
    data : dict
    source : str
        Named in error messages.

    Returns
    -------
    World

    Raises
    ------
    WorldError
        Naming ``source`` and each offending key.
    """
    try:
        return World.model_validate(data)
    except ValidationError as err:
        raise WorldError(validation_message(source, err, "world", show_values=False)) from None


def load_world(path_or_name: str | Path) -> World:
    """Read a world TOML file, or a bundled example by name.

    Parameters
    ----------
    path_or_name : str or Path
        A ``.toml`` file, or the name of a bundled example (:data:`EXAMPLES`).

    Returns
    -------
    World

    Raises
    ------
    WorldError
        For an unreadable file, invalid TOML or invalid contents (naming file and key).
    """
    key = str(path_or_name)
    path = example_path(key) if key in EXAMPLES else Path(key)
    data = read_toml(path, WorldError, "world file")
    data.setdefault("name", path.stem)
    return parse_world(data, str(path))
