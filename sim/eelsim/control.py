"""The robot's control laws, written once as pure functions of time and state.

The twin runs them inside its closed loop, the host's real-time loop calls the same functions, and
the firmware's C++ core implements the gait and PD laws identically (its tests compare to these).
docs/model.md section 4:

- gait:  alpha_j(t) = A_j sin(omega t + phi_0 + beta_j) + gamma (phi_0: ``Gait.phase_rad``, 0 from
         the Start),
         A_j = A (N - j)/(N + 1),  beta_j = (j-1) beta
- PD:    u_j = k_p (alpha_j - phi_j) + k_d (alpha_dot_j - phi_dot_j)
- LOS:   theta_ref = atan2(y_g - p_y, x_g - p_x)
- offset: gamma = k_theta * wrap(theta_ref - theta_bar), wrap to (-pi, pi]

Joints are numbered j = 1..N-1 from the tail; joint j joins link j and link j+1 and its angle is
phi_j = theta_{j+1} - theta_j. Arrays here are 0-based: index 0 is joint 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Gait:
    """Gait parameters G_p = (A, omega, beta, k_theta) of the eel-like gait.

    Attributes
    ----------
    amplitude_rad : float
        A, the amplitude parameter; joint j swings with A (N - j)/(N + 1).
    omega_rad_s : float
        Angular frequency of the joint oscillation.
    beta_rad : float
        Phase shift between neighbouring joints.
    k_theta : float
        Gain of the proportional heading controller (rad of offset per rad of heading error).
    phase_rad : float
        The gait's phase at t = 0: 0 for a gait swum from the Start (the firmware restarts its
        phase there). A braked robot's gait (omega 0 at the firmware) holds the phase it froze
        at: docs/planning.md, "The brake in the pause".
    """

    amplitude_rad: float
    omega_rad_s: float
    beta_rad: float = 1.04
    k_theta: float = 0.1
    phase_rad: float = 0.0


BRAKE_AMPLITUDE_RAD = 1.5
"""The brake's gait amplitude (SetGait's largest): with omega 0 joint j is held at
A (N - j)/(N + 1) sin(phase + (j - 1) beta), at most 1.07 rad for six links, inside the references'
1.2 rad clamp; the deep S's drag stops a gliding body within a few seconds (docs/planning.md,
"The brake before the Stop")."""

FROZEN_OMEGA_RAD_S = 1e-9
"""A braked gait's omega in the twin: 0 in effect (the firmware is sent 0; a scenario's omega must
be positive)."""


def braked_gait(gait: Gait, t_s: float, amplitude_rad: float = BRAKE_AMPLITUDE_RAD) -> Gait:
    """The gait of a robot braked at ``t_s``: a deep S frozen at the phase it had then.

    SetGait with omega 0 stops the firmware's phase where it is (the phase is continuous when
    omega changes, docs/firmware.md) and ``amplitude_rad`` bends the body into that phase's S.
    The twin swims it as a gait of (nearly) zero omega whose ``phase_rad`` is the frozen phase.

    Parameters
    ----------
    gait : Gait
        The gait swum until the brake.
    t_s : float
        When the brake reaches the robot, s since the gait started.
    amplitude_rad : float

    Returns
    -------
    Gait
        Heading gain 0 (the offset is held at 0 while braked).
    """
    frozen = math.remainder(gait.omega_rad_s * t_s + gait.phase_rad, 2.0 * math.pi)
    return Gait(amplitude_rad, FROZEN_OMEGA_RAD_S, gait.beta_rad, 0.0, frozen)


def wrap_angle(angle_rad: ArrayLike) -> FloatArray | float:
    """Wrap an angle to the half-open interval (-pi, pi]: the twin's one convention.

    An angle already in (-pi, pi] comes back unchanged (to the bit); others as
    pi - mod(pi - a, 2 pi), and a result that rounds to -pi (from just above pi) as pi. The
    batched kernel's ``_wrap_angle`` is the same expression (tested against this one).

    Parameters
    ----------
    angle_rad : array_like
        Angle(s) in radians.

    Returns
    -------
    float or ndarray
        The equivalent angle(s) in (-pi, pi].
    """
    a = np.asarray(angle_rad, dtype=float)
    inside = (a > -np.pi) & (a <= np.pi)
    w = np.where(inside, a, np.pi - np.mod(np.pi - a, 2.0 * np.pi))  # in [-pi, pi]
    w = np.where(w <= -np.pi, np.pi, w)  # the float interval is (-pi, pi]
    return float(w) if w.ndim == 0 else w


def joint_amplitudes(amplitude_rad: float, n_links: int) -> FloatArray:
    """Per-joint amplitudes A_j = A (N - j)/(N + 1), j = 1..N-1 (largest at the tail joint).

    Parameters
    ----------
    amplitude_rad : float
        The gait's amplitude parameter A.
    n_links : int
        Number of links N.

    Returns
    -------
    ndarray, shape (N-1,)
    """
    j = np.arange(1, n_links, dtype=float)
    return amplitude_rad * (n_links - j) / (n_links + 1.0)


def gait_reference(
    t_s: float, gait: Gait, offset_rad: float, n_links: int
) -> tuple[FloatArray, FloatArray]:
    """Joint angle references alpha_j(t) and their time derivatives.

    Parameters
    ----------
    t_s : float
        Time since the gait started, s.
    gait : Gait
        Gait parameters.
    offset_rad : float
        Steering offset gamma added to every joint, rad (held constant between updates, so it
        contributes nothing to the derivative).
    n_links : int
        Number of links N.

    Returns
    -------
    alpha_rad : ndarray, shape (N-1,)
    alpha_dot_rad_s : ndarray, shape (N-1,)
    """
    amp = joint_amplitudes(gait.amplitude_rad, n_links)
    phase = gait.omega_rad_s * t_s + gait.phase_rad + np.arange(n_links - 1) * gait.beta_rad
    alpha = amp * np.sin(phase) + offset_rad
    alpha_dot = amp * gait.omega_rad_s * np.cos(phase)
    return alpha, alpha_dot


def joint_pd_torque(
    alpha_rad: ArrayLike,
    alpha_dot_rad_s: ArrayLike,
    phi_rad: ArrayLike,
    phi_dot_rad_s: ArrayLike,
    kp_nm_per_rad: float,
    kd_nms_per_rad: float,
) -> FloatArray:
    """Joint PD law u = k_p (alpha - phi) + k_d (alpha_dot - phi_dot).

    Parameters
    ----------
    alpha_rad, alpha_dot_rad_s : array_like, shape (N-1,)
        Joint references and their rates.
    phi_rad, phi_dot_rad_s : array_like, shape (N-1,)
        Measured joint angles phi_j = theta_{j+1} - theta_j and their rates.
    kp_nm_per_rad, kd_nms_per_rad : float
        Proportional and derivative gains.

    Returns
    -------
    ndarray, shape (N-1,)
        Joint torques, N m, positive acting +u on link j+1 and -u on link j.
    """
    return kp_nm_per_rad * (np.asarray(alpha_rad) - np.asarray(phi_rad)) + kd_nms_per_rad * (
        np.asarray(alpha_dot_rad_s) - np.asarray(phi_dot_rad_s)
    )


def los_heading(position_m: ArrayLike, waypoint_m: ArrayLike) -> float:
    """Line-of-sight reference heading theta_ref = atan2(y_g - p_y, x_g - p_x).

    Parameters
    ----------
    position_m : array_like, shape (2,)
        The robot's centre of mass.
    waypoint_m : array_like, shape (2,)
        The current target waypoint.

    Returns
    -------
    float
        Reference heading in (-pi, pi], rad.
    """
    p = np.asarray(position_m, dtype=float)
    g = np.asarray(waypoint_m, dtype=float)
    return math.atan2(g[1] - p[1], g[0] - p[0])


def heading_offset(
    position_m: ArrayLike, heading_rad: float, waypoint_m: ArrayLike, k_theta: float
) -> float:
    """Proportional heading controller gamma = k_theta * wrap(theta_ref - theta_bar).

    Parameters
    ----------
    position_m : array_like, shape (2,)
        The robot's (filtered) centre of mass.
    heading_rad : float
        The robot's (filtered) heading theta_bar, the mean of the link angles.
    waypoint_m : array_like, shape (2,)
        The current target waypoint.
    k_theta : float
        Controller gain.

    Returns
    -------
    float
        The offset gamma, rad.
    """
    error = wrap_angle(los_heading(position_m, waypoint_m) - heading_rad)
    return k_theta * float(error)
