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
    theta = states[:, :n]
    c, s = np.cos(theta), np.sin(theta)
    g = model.geometry
    xc = states[:, n : n + 1] + c @ g.T  # link centres, as eelsim.dynamics.link_positions
    yc = states[:, n + 1 : n + 2] + s @ g.T
    lh = model.half_length_m
    x = np.concatenate([xc[:, :1] - lh[0] * c[:, :1], xc + lh * c], axis=1)
    y = np.concatenate([yc[:, :1] - lh[0] * s[:, :1], yc + lh * s], axis=1)
    return np.stack([x, y], axis=-1)


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
    a, b = ends[:, :-1], ends[:, 1:]
    f = np.arange(per_link) / per_link
    inner = a[:, :, None, :] + f[None, None, :, None] * (b - a)[:, :, None, :]
    k = len(states)
    return np.concatenate([inner.reshape(k, -1, 2), ends[:, -1:]], axis=1)


def point_spacing_m(model: SwimmerModel, per_link: int = 2) -> float:
    """Largest distance between neighbouring points of :func:`body_points`."""
    return float(2.0 * model.half_length_m.max() / max(per_link, 1))


def reach_m(model: SwimmerModel) -> float:
    """Largest distance from the centre of mass to any point of the body, whatever its shape.

    A link centre is p + sum_j G_ij (cos, sin)(theta_j) (docs/model.md section 1), so it is at
    most sum_j |G_ij| from the centre of mass p, and the link's points at most l_i further.
    """
    return float((np.abs(model.geometry).sum(axis=1) + model.half_length_m).max())
