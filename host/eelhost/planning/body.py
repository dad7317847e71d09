"""Where the robot's body is: the link end points and points along the links, from twin states.

The planner checks the body against obstacles at every sampled state of every manoeuvre, so these
are vectorised over states (docs/model.md section 1: link centres X = p_x + G cos(theta),
Y = p_y + G sin(theta), link i from its centre -l_i to +l_i along theta_i).
"""

from __future__ import annotations

import numpy as np

from eelhost.planning.geometry import FloatArray
from eelsim.model import SwimmerModel


def link_endpoints(model: SwimmerModel, states: FloatArray) -> FloatArray:
    """Joint and tip positions of the robot at many states, tail tip first.

    Parameters
    ----------
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4)

    Returns
    -------
    ndarray, shape (K, N + 1, 2)
    """
    n = model.n_links
    if len(states) == 1:
        # a single state through the matrix product's many-row path, as among others: a
        # one-row product takes another path whose last bits can differ, and a state's points
        # must not depend on what it is computed with (docs/planning.md, "Swum once, judged
        # again")
        return link_endpoints(model, np.repeat(states, 2, axis=0))[:1]
    theta = states[:, :n]
    c, s = np.cos(theta), np.sin(theta)
    g = model.geometry
    xc = states[:, n : n + 1] + c @ g.T  # link centres, as eelsim.dynamics.link_positions
    yc = states[:, n + 1 : n + 2] + s @ g.T
    lh = model.half_length_m
    # written in place rather than joined and stacked: the same sums, without the temporaries
    out = np.empty((len(states), n + 1, 2))
    out[:, 0, 0] = xc[:, 0] - lh[0] * c[:, 0]
    out[:, 0, 1] = yc[:, 0] - lh[0] * s[:, 0]
    out[:, 1:, 0] = xc + lh * c
    out[:, 1:, 1] = yc + lh * s
    return out


def body_points(model: SwimmerModel, states: FloatArray, per_link: int = 2) -> FloatArray:
    """Points along the body's centre line.

    Every joint and tip, and ``per_link - 1`` evenly spaced points inside each link.

    Parameters
    ----------
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4)
    per_link : int
        Intervals per link (1: joints and tips only).

    Returns
    -------
    ndarray, shape (K, N per_link + 1, 2)
    """
    ends = link_endpoints(model, states)
    if per_link <= 1:
        return ends
    k, links = len(states), ends.shape[1] - 1
    a = ends[:, :-1]
    step = ends[:, 1:] - a
    # point j of a link is a + (j / per_link) (b - a), as np.arange(per_link) / per_link gives
    # it, written into its place: the same values in half the processor time of broadcasting
    # and joining them (the search's inner loop; docs/planning.md, "The check's processor time")
    out = np.empty((k, links * per_link + 1, 2))
    inner = out[:, :-1].reshape(k, links, per_link, 2)
    inner[:, :, 0] = a
    for j in range(1, per_link):
        np.multiply(step, j / per_link, out=inner[:, :, j])
        inner[:, :, j] += a
    out[:, -1] = ends[:, -1]
    return out


def point_spacing_m(model: SwimmerModel, per_link: int = 2) -> float:
    """Largest distance between neighbouring points of :func:`body_points`."""
    return float(2.0 * model.half_length_m.max() / max(per_link, 1))


def reach_m(model: SwimmerModel) -> float:
    """Largest distance from the centre of mass to any point of the body, whatever its shape.

    A link centre is p + sum_j G_ij (cos, sin)(theta_j) (docs/model.md section 1), so it is at
    most sum_j |G_ij| from the centre of mass p, and the link's points at most l_i further.
    """
    return float((np.abs(model.geometry).sum(axis=1) + model.half_length_m).max())
