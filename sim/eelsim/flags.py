"""Failure conditions of a simulated run (docs/model.md section 5, paper eq. 34 and table 2).

A run is flagged, never crashed, when it is too slow (not at its last waypoint by T_max), when the
mass matrix is ill-conditioned or the state is not finite (the integration blew up), or when the
robot collides with itself (two non-adjacent links intersect, or a joint passes its limit).
"""

from __future__ import annotations

import enum

import numpy as np

# Condition number of M above which a run is flagged ill-conditioned. A physical M of this robot
# has a condition number of about 1e3 to 1e4; 1e10 leaves room for odd robots yet catches
# degenerate parameters long before the Cholesky solve loses all accuracy.
ILL_CONDITION_THRESHOLD = 1e10

# A state whose rates exceed this (rad/s or m/s) has diverged, even if still finite: the robot's
# links turn at a few rad/s and it swims at a few cm/s. Catching it early keeps a blown-up run
# from being misreported as a self-collision a step before it overflows.
DIVERGENCE_RATE = 1e3

# The paper's fitness values for failed runs (any H2 > H3 > H1 works).
PENALTY_TOO_SLOW = 1e6
PENALTY_ILL_CONDITIONED = 1e16
PENALTY_SELF_COLLISION = 1e14


class Failure(enum.IntEnum):
    """Why a run failed (0: it did not)."""

    NONE = 0
    TOO_SLOW = 1
    ILL_CONDITIONED = 2
    SELF_COLLISION = 3


def penalty(failure: Failure, distance_left_m: float = 0.0) -> float:
    """The paper's fitness value for a failed run.

    Parameters
    ----------
    failure : Failure
        The flag.
    distance_left_m : float
        Distance from the robot to its last waypoint at T_max (too-slow runs are ranked by it:
        we read the paper's "H_1 L" as H_1 times that distance).

    Returns
    -------
    float
        0 for a successful run.
    """
    if failure == Failure.TOO_SLOW:
        return PENALTY_TOO_SLOW * distance_left_m
    if failure == Failure.ILL_CONDITIONED:
        return PENALTY_ILL_CONDITIONED
    if failure == Failure.SELF_COLLISION:
        return PENALTY_SELF_COLLISION
    return 0.0


def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


def segments_intersect(p1: np.ndarray, p2: np.ndarray, q1: np.ndarray, q2: np.ndarray) -> bool:
    """True when the closed segments p1-p2 and q1-q2 share a point (touching counts)."""
    d1 = _cross(*(q2 - q1), *(p1 - q1))
    d2 = _cross(*(q2 - q1), *(p2 - q1))
    d3 = _cross(*(p2 - p1), *(q1 - p1))
    d4 = _cross(*(p2 - p1), *(q2 - p1))
    if ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4)):
        return True

    def on(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: float) -> bool:
        return (
            d == 0
            and min(a[0], b[0]) <= c[0] <= max(a[0], b[0])
            and min(a[1], b[1]) <= c[1] <= max(a[1], b[1])
        )

    return on(q1, q2, p1, d1) or on(q1, q2, p2, d2) or on(p1, p2, q1, d3) or on(p1, p2, q2, d4)


def self_collision(
    x_m: np.ndarray,
    y_m: np.ndarray,
    theta_rad: np.ndarray,
    half_length_m: np.ndarray,
    joint_limit_rad: float,
) -> str | None:
    """Describe a self-collision, or return None.

    Parameters
    ----------
    x_m, y_m, theta_rad, half_length_m : ndarray, shape (N,)
        Link centres, angles and half-lengths.
    joint_limit_rad : float
        Largest allowed |phi_j|.

    Returns
    -------
    str or None
        A human-readable reason, e.g. ``"links 1 and 3 intersect"`` (1-based, tail = 1).
    """
    phi = np.diff(theta_rad)
    over = np.flatnonzero(np.abs(phi) > joint_limit_rad)
    if over.size:
        j = int(over[0])
        return (
            f"joint {j + 1} at {phi[j]:+.3f} rad is beyond its limit of {joint_limit_rad:.3f} rad"
        )
    tx, ty = half_length_m * np.cos(theta_rad), half_length_m * np.sin(theta_rad)
    ends_a = np.stack([x_m - tx, y_m - ty], axis=1)
    ends_b = np.stack([x_m + tx, y_m + ty], axis=1)
    n = theta_rad.size
    for i in range(n):
        for k in range(i + 2, n):
            if segments_intersect(ends_a[i], ends_b[i], ends_a[k], ends_b[k]):
                return f"links {i + 1} and {k + 1} intersect"
    return None
