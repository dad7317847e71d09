"""An independent audit of contact: the body against the world with shapely's exact geometry.

The planner judges contact with its own code (a clearance grid and the segment distances of
:mod:`eelhost.planning.geometry`); a safety figure checked by the code it checks proves little.
This module measures the same thing another way (docs/planning.md, "Benchmark"): the body's
centre line at a state is a shapely ``LineString`` through its joints and tips
(docs/model.md section 1: link i spans its centre +- l_i along theta_i, the centres from the
centre of mass and the geometry matrix), and its gap to the world is

- to a polygon obstacle: shapely's exact distance from the line to the polygon (0 when they
  meet or the line is inside);
- to a circle: the distance from the line to the centre, less the radius;
- to the tank: the distance from the line to the tank's outline, or 0 when any point is outside,

less the body's half width. Nothing here is shared with the planner's geometry but the state
layout and the robot's dimensions.
"""

from __future__ import annotations

import numpy as np
import shapely
from numpy.typing import NDArray

from eelhost.planning.world import CircleObstacle, World
from eelsim.model import SwimmerModel

FloatArray = NDArray[np.float64]


def centre_lines(model: SwimmerModel, states: FloatArray) -> FloatArray:
    """Joints and tips of the body at each state, head link last, shape (K, N + 1, 2).

    Written from docs/model.md section 1 (not from :mod:`eelhost.planning.body`): the centre of
    link i is p + sum_j G_ij (cos theta_j, sin theta_j); its ends are that +- l_i (cos, sin)
    theta_i, and neighbouring links share their joint.
    """
    n = model.n_links
    k = len(states)
    theta = states[:, :n]
    unit = np.stack([np.cos(theta), np.sin(theta)], axis=-1)  # (K, N, 2)
    centres = states[:, None, n : n + 2] + np.einsum("ij,kjd->kid", model.geometry, unit)
    half = model.half_length_m[None, :, None] * unit
    out = np.empty((k, n + 1, 2))
    out[:, 0] = centres[:, 0] - half[:, 0]
    out[:, 1:] = centres + half
    return out


def body_gaps_m(world: World, model: SwimmerModel, states: FloatArray) -> FloatArray:
    """Gap between the body and the nearest obstacle or wall at each state (<= 0: contact).

    Parameters
    ----------
    world : World
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4)

    Returns
    -------
    ndarray, shape (K,)
    """
    lines = shapely.linestrings(centre_lines(model, np.asarray(states, dtype=float)))
    w, h = world.tank.size_m
    tank = shapely.box(0.0, 0.0, w, h)
    inside = shapely.contains_properly(tank, lines)
    gap = np.where(inside, shapely.distance(lines, tank.exterior), 0.0)
    for o in world.obstacles:
        if isinstance(o, CircleObstacle):
            d = shapely.distance(lines, shapely.Point(o.centre_m)) - o.radius_m
        else:
            d = shapely.distance(lines, shapely.Polygon(o.vertices_m))
        gap = np.minimum(gap, np.maximum(d, 0.0))
    return gap - float(model.half_axis_horizontal_m.max())
