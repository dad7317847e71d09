"""Planar collision geometry: segments against circles, polygons and the tank walls.

The planner checks a primitive's swept region (a convex hull, given by its edges) and the executor
checks the robot's link segments; both reduce to "how close do these segments come to this
obstacle". Everything is vectorised over segments with numpy, because the planner calls it for
every child of every expanded node. Polygons may be non-convex (simple polygons, either winding).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def _cross(u: FloatArray, v: FloatArray) -> FloatArray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def point_segment_distance(points: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance from each point to each segment (leading dimensions broadcast).

    Parameters
    ----------
    points : ndarray, shape (..., P, 2)
    a, b : ndarray, shape (..., S, 2)
        Segment end points.

    Returns
    -------
    ndarray, shape (..., P, S)
    """
    # by components: x x' + y y' is what summing the products over the last axis of two gives,
    # bit for bit, without the reductions over a length-2 axis (half the processor time of the
    # clearance field's build; docs/planning.md, "The check's processor time")
    points, a, b = np.asarray(points), np.asarray(a), np.asarray(b)
    abx, aby = (b - a)[..., 0], (b - a)[..., 1]
    apx = points[..., :, None, 0] - a[..., None, :, 0]
    apy = points[..., :, None, 1] - a[..., None, :, 1]
    denom = (abx * abx + aby * aby)[..., None, :]
    # degenerate segments (a == b, e.g. hull padding) fall back to the distance to a
    safe = np.where(denom > 0, denom, 1.0)
    abx, aby = abx[..., None, :], aby[..., None, :]
    t = np.clip((apx * abx + apy * aby) / safe, 0.0, 1.0)
    t = np.where(denom > 0, t, 0.0)
    gx = apx - t * abx
    gy = apy - t * aby
    return np.sqrt(gx * gx + gy * gy)


def segments_cross(a1: FloatArray, a2: FloatArray, b1: FloatArray, b2: FloatArray) -> FloatArray:
    """Whether segment i of set A meets segment j of set B (leading dimensions broadcast).

    The vectorised form of :func:`eelsim.flags.segments_intersect` (the twin's self-collision
    test), which the planner cannot call pair by pair in its inner loop; a test checks that the
    two agree.

    Parameters
    ----------
    a1, a2 : ndarray, shape (..., S, 2)
    b1, b2 : ndarray, shape (..., E, 2)

    Returns
    -------
    ndarray of bool, shape (..., S, E)
        Touching counts as meeting. Collinear overlaps are left to the callers' distance tests
        (their distance is 0), so only the general-position test is needed here.
    """
    a1e, a2e = a1[..., :, None, :], a2[..., :, None, :]
    b1e, b2e = b1[..., None, :, :], b2[..., None, :, :]
    da, db = a2e - a1e, b2e - b1e
    d1 = _cross(db, a1e - b1e)
    d2 = _cross(db, a2e - b1e)
    d3 = _cross(da, b1e - a1e)
    d4 = _cross(da, b2e - a1e)
    return (d1 * d2 <= 0) & (d3 * d4 <= 0) & ~((d1 == 0) & (d2 == 0))


def inside_convex(points: FloatArray, hull: FloatArray) -> FloatArray:
    """Which points lie inside (or on) a counter-clockwise convex polygon (dimensions broadcast).

    Parameters
    ----------
    points : ndarray, shape (..., P, 2)
    hull : ndarray, shape (..., H, 2)
        Counter-clockwise vertices; repeated vertices (padding) are allowed.

    Returns
    -------
    ndarray of bool, shape (..., P)
    """
    edges = np.roll(hull, -1, axis=-2) - hull
    rel = points[..., :, None, :] - hull[..., None, :, :]
    return np.all(_cross(edges[..., None, :, :], rel) >= 0, axis=-1)


def points_in_polygon(points: FloatArray, polygon: FloatArray) -> NDArray[np.bool_]:
    """Even-odd rule: which points lie strictly inside a simple polygon.

    Parameters
    ----------
    points : ndarray, shape (P, 2)
    polygon : ndarray, shape (V, 2)
        Vertices in order (not repeated at the end), either winding.

    Returns
    -------
    ndarray of bool, shape (P,)
    """
    x, y = points[:, 0:1], points[:, 1:2]
    v0 = polygon
    v1 = np.roll(polygon, -1, axis=0)
    straddle = (v0[None, :, 1] > y) != (v1[None, :, 1] > y)
    dy = v1[:, 1] - v0[:, 1]
    safe = np.where(dy == 0, 1.0, dy)
    x_cross = v0[None, :, 0] + (y - v0[None, :, 1]) * (v1[:, 0] - v0[:, 0])[None] / safe[None]
    hits = straddle & (x < x_cross)
    return (hits.sum(axis=1) % 2) == 1


def polygon_edges(polygon: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The closed polygon's edges as (start points, end points), each shape (V, 2)."""
    return polygon, np.roll(polygon, -1, axis=0)


def segments_polygon_distance(a: FloatArray, b: FloatArray, polygon: FloatArray) -> float:
    """Smallest distance from a set of segments to a polygon's area (0 if they overlap).

    Parameters
    ----------
    a, b : ndarray, shape (S, 2)
        Segment end points.
    polygon : ndarray, shape (V, 2)

    Returns
    -------
    float
    """
    e1, e2 = polygon_edges(polygon)
    if np.any(segments_cross(a, b, e1, e2)) or np.any(points_in_polygon(a, polygon)):
        return 0.0
    d_ends = point_segment_distance(np.concatenate([a, b]), e1, e2).min()
    d_verts = point_segment_distance(polygon, a, b).min()
    return float(min(d_ends, d_verts))


def segments_circle_distance(
    a: FloatArray, b: FloatArray, centre: FloatArray, radius: float
) -> float:
    """Smallest distance from a set of segments to a disc (0 if they touch or overlap).

    Parameters
    ----------
    a, b : ndarray, shape (S, 2)
    centre : ndarray, shape (2,)
    radius : float

    Returns
    -------
    float
    """
    d = point_segment_distance(np.asarray(centre, dtype=float)[None], a, b).min()
    return float(max(0.0, d - radius))
