"""Equations of motion of the N-link swimmer in water (docs/model.md section 2, compact per-link form).

State x = (theta, p, theta_dot, p_dot): N absolute link angles (from the global x axis, link 1 the
tail), the centre of mass p = (p_x, p_y), and their rates: 2 N + 4 numbers, SI units.

In the generalised coordinates q = (theta, p), with J_i the Jacobian of link centre i,

    M(q) q_ddot = Q(q, q_dot, u, v_c)
    M = sum_i J_i^T (m_i I + mu_i n_i n_i^T) J_i + diag(J_i + lambda_1,i ; 0, 0)
    Q = sum_i J_i^T [f_i - (m_i I + mu_i n_i n_i^T) Jdot_i q_dot]
        + (theta block) [tau_i - D^T u]

where f_i and tau_i are the force and torque of the water on link i given by the model's fluid law
(:mod:`eelsim.fluid`; the paper's Morison law: drag on the velocity relative to the current, the
added-mass current term and the fluid yaw damping), and u the joint torques (u_j acts +u_j on
link j+1 and -u_j on link j). M is symmetric positive definite.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelsim.fluid import LinkForces, LinkMotion
from eelsim.model import SwimmerModel

FloatArray = NDArray[np.float64]


def split_state(model: SwimmerModel, state: ArrayLike) -> tuple[FloatArray, ...]:
    """Split a state vector into (theta, p, theta_dot, p_dot).

    Parameters
    ----------
    model : SwimmerModel
    state : array_like, shape (2 N + 4,)

    Returns
    -------
    theta, p, theta_dot, p_dot : ndarray
    """
    x = np.asarray(state, dtype=float)
    n = model.n_links
    if x.shape != (2 * n + 4,):
        raise ValueError(f"state must have shape ({2 * n + 4},) for N = {n}, got {x.shape}")
    return x[:n], x[n : n + 2], x[n + 2 : 2 * n + 2], x[2 * n + 2 :]


def make_state(
    theta_rad: ArrayLike,
    position_m: ArrayLike = (0.0, 0.0),
    theta_dot_rad_s: ArrayLike | None = None,
    velocity_m_s: ArrayLike = (0.0, 0.0),
) -> FloatArray:
    """Assemble a state vector (theta, p, theta_dot, p_dot).

    Parameters
    ----------
    theta_rad : array_like, shape (N,)
        Absolute link angles.
    position_m : array_like, shape (2,)
        Centre of mass.
    theta_dot_rad_s : array_like, shape (N,), optional
        Link angular rates (zero when omitted).
    velocity_m_s : array_like, shape (2,)
        Centre-of-mass velocity.

    Returns
    -------
    ndarray, shape (2 N + 4,)
    """
    theta = np.asarray(theta_rad, dtype=float)
    rates = np.zeros_like(theta) if theta_dot_rad_s is None else np.asarray(theta_dot_rad_s, float)
    return np.concatenate(
        [theta, np.asarray(position_m, float), rates, np.asarray(velocity_m_s, float)]
    )


def straight_state(model: SwimmerModel, heading_rad: float = 0.0, position_m: ArrayLike = (0, 0)):
    """Return the state of a straight robot at rest, pointing along ``heading_rad``.

    Parameters
    ----------
    model : SwimmerModel
    heading_rad : float
        Direction the head points to.
    position_m : array_like, shape (2,)
        Centre of mass.

    Returns
    -------
    ndarray, shape (2 N + 4,)
    """
    return make_state(np.full(model.n_links, float(heading_rad)), position_m)


def link_positions(model: SwimmerModel, state: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Link centre positions (X, Y), each shape (N,), tail first."""
    theta, p, _, _ = split_state(model, state)
    g = model.geometry
    return p[0] + g @ np.cos(theta), p[1] + g @ np.sin(theta)


def link_velocities(model: SwimmerModel, state: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Link centre velocities (Xdot, Ydot), each shape (N,)."""
    theta, _, w, v = split_state(model, state)
    g = model.geometry
    return v[0] - g @ (np.sin(theta) * w), v[1] + g @ (np.cos(theta) * w)


def joint_angles(theta_rad: ArrayLike) -> FloatArray:
    """Joint angles phi_j = theta_{j+1} - theta_j (head-side minus tail-side), shape (N-1,)."""
    return np.diff(np.asarray(theta_rad, dtype=float))


def heading(theta_rad: ArrayLike) -> float:
    """The robot's heading theta_bar, the mean of the link angles."""
    return float(np.mean(np.asarray(theta_rad, dtype=float)))


@dataclass(frozen=True)
class _LinkKinematics:
    s: FloatArray
    c: FloatArray
    jx: FloatArray  # (N, N+2): d Xdot_i / d q_dot
    jy: FloatArray
    ax0: FloatArray  # Jdot q_dot, x components (centripetal part of the link acceleration)
    ay0: FloatArray
    vx: FloatArray  # link centre velocities
    vy: FloatArray


def _kinematics(model: SwimmerModel, theta: FloatArray, w: FloatArray, v: FloatArray):
    n = model.n_links
    g = model.geometry
    s, c = np.sin(theta), np.cos(theta)
    jx = np.zeros((n, n + 2))
    jy = np.zeros((n, n + 2))
    jx[:, :n] = -g * s[None, :]
    jx[:, n] = 1.0
    jy[:, :n] = g * c[None, :]
    jy[:, n + 1] = 1.0
    return _LinkKinematics(
        s=s,
        c=c,
        jx=jx,
        jy=jy,
        ax0=-g @ (c * w**2),
        ay0=-g @ (s * w**2),
        vx=v[0] - g @ (s * w),
        vy=v[1] + g @ (c * w),
    )


def fluid_link_forces(
    model: SwimmerModel, state: ArrayLike, current_m_s: ArrayLike = (0.0, 0.0)
) -> LinkForces:
    """The water's force and torque on each link, from the model's fluid law (docs/model.md section 2).

    Parameters
    ----------
    model : SwimmerModel
    state : array_like, shape (2 N + 4,)
    current_m_s : array_like, shape (2,)
        Uniform steady current velocity v_c.

    Returns
    -------
    LinkForces
        Force (global x, y) and torque per link, and the law's named parts (for the Morison law
        ``"drag"`` and ``"current"``).
    """
    theta, _, w, v = split_state(model, state)
    k = _kinematics(model, theta, w, v)
    return _fluid_forces(model, k, w, np.asarray(current_m_s, dtype=float))


def _fluid_forces(
    model: SwimmerModel, k: _LinkKinematics, w: FloatArray, vc: FloatArray
) -> LinkForces:
    motion = LinkMotion(sin=k.s, cos=k.c, omega=w, rel_vx=k.vx - vc[0], rel_vy=k.vy - vc[1])
    return model.fluid_law.forces(model.fluid, motion, vc)


def mass_matrix(model: SwimmerModel, state: ArrayLike) -> FloatArray:
    """The generalised mass matrix M(q), shape (N+2, N+2), including added mass and inertia."""
    theta, _, w, v = split_state(model, state)
    return _mass_matrix(model, _kinematics(model, theta, w, v))


def _mass_matrix(model: SwimmerModel, k: _LinkKinematics) -> FloatArray:
    m, mu = model.mass_kg, model.fluid.mu_n
    mxx = m + mu * k.s**2
    myy = m + mu * k.c**2
    mxy = -mu * k.s * k.c
    big = (
        k.jx.T @ (mxx[:, None] * k.jx)
        + k.jx.T @ (mxy[:, None] * k.jy)
        + k.jy.T @ (mxy[:, None] * k.jx)
        + k.jy.T @ (myy[:, None] * k.jy)
    )
    n = model.n_links
    big[np.arange(n), np.arange(n)] += model.yaw_inertia_kg_m2 + model.fluid.lambda_1
    return big


def joint_torques_on_links(torques_nm: ArrayLike) -> FloatArray:
    """Torque on each link from joint torques u: -D^T u (u_j: +u_j on link j+1, -u_j on link j)."""
    u = np.asarray(torques_nm, dtype=float)
    tau = np.zeros(u.size + 1)
    tau[1:] += u
    tau[:-1] -= u
    return tau


def accelerations(
    model: SwimmerModel,
    state: ArrayLike,
    torques_nm: ArrayLike,
    current_m_s: ArrayLike = (0.0, 0.0),
) -> tuple[FloatArray, FloatArray]:
    """Accelerations (theta_ddot, p_ddot) of the swimmer.

    Parameters
    ----------
    model : SwimmerModel
        The robot and its fluid coefficients.
    state : array_like, shape (2 N + 4,)
        (theta, p, theta_dot, p_dot).
    torques_nm : array_like, shape (N-1,)
        Joint torques u.
    current_m_s : array_like, shape (2,)
        Uniform steady current velocity v_c.

    Returns
    -------
    theta_ddot : ndarray, shape (N,)
    p_ddot : ndarray, shape (2,)
    """
    n = model.n_links
    u = np.asarray(torques_nm, dtype=float)
    if u.shape != (n - 1,):
        raise ValueError(f"torques must have shape ({n - 1},) for N = {n}, got {u.shape}")
    big_m, q, fluid_torque = _mass_matrix_and_forces(model, state, current_m_s)
    q[:n] += fluid_torque + joint_torques_on_links(u)
    chol = np.linalg.cholesky(big_m)
    qdd = np.linalg.solve(chol.T, np.linalg.solve(chol, q))
    return qdd[:n], qdd[n:]


def _mass_matrix_and_forces(
    model: SwimmerModel, state: ArrayLike, current_m_s: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """M, the generalised force without torques on the theta block, and the fluid torques."""
    theta, _, w, v = split_state(model, state)
    k = _kinematics(model, theta, w, v)
    big_m = _mass_matrix(model, k)
    water = _fluid_forces(model, k, w, np.asarray(current_m_s, float))
    m, mu = model.mass_kg, model.fluid.mu_n
    # Inertial forces of the centripetal link accelerations, (m I + mu n n^T) Jdot q_dot.
    inert_x = (m + mu * k.s**2) * k.ax0 - mu * k.s * k.c * k.ay0
    inert_y = -mu * k.s * k.c * k.ax0 + (m + mu * k.c**2) * k.ay0
    q = k.jx.T @ (water.fx - inert_x) + k.jy.T @ (water.fy - inert_y)
    return big_m, q, water.torque


def prescribed_shape_accelerations(
    model: SwimmerModel,
    state: ArrayLike,
    phi_ddot_rad_s2: ArrayLike,
    current_m_s: ArrayLike = (0.0, 0.0),
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Accelerations of a swimmer whose joint accelerations are given, and the joint torques.

    Prescribed-shape dynamics (docs/model.md section 4, "Joint models"): with the joint angles
    kinematic, the free coordinates are s = (theta_1, p_x, p_y); theta = e theta_1 + C phi
    (C[i, j] = 1 for j < i) gives q_ddot = T s_ddot + c with T = [[e, 0], [0, I2]] and
    c = [C phi_ddot; 0], and the 3 x 3 system (T^T M T) s_ddot = T^T (Q0 - M c) is the whole
    body's force and moment balance (the joint torques are internal: T^T [-D^T u; 0] = 0). The
    torques the joints must give follow from the theta rows, r = (M q_ddot - Q0)[theta] = -D^T u:
    u_1 = -r_1, u_j = u_(j-1) - r_j.

    Parameters
    ----------
    model : SwimmerModel
    state : array_like, shape (2 N + 4,)
    phi_ddot_rad_s2 : array_like, shape (N-1,)
        The joint accelerations.
    current_m_s : array_like, shape (2,)

    Returns
    -------
    theta_ddot : ndarray, shape (N,)
    p_ddot : ndarray, shape (2,)
    torques_nm : ndarray, shape (N-1,)
        Joint torques u (u_j acts +u_j on link j+1 and -u_j on link j).
    """
    n = model.n_links
    phi_ddot = np.asarray(phi_ddot_rad_s2, dtype=float)
    if phi_ddot.shape != (n - 1,):
        raise ValueError(f"joint accelerations must have shape ({n - 1},) for N = {n}, got "
                         f"{phi_ddot.shape}")
    big_m, q0, fluid_torque = _mass_matrix_and_forces(model, state, current_m_s)
    q0[:n] += fluid_torque
    t = np.zeros((n + 2, 3))
    t[:n, 0] = 1.0
    t[n:, 1:] = np.eye(2)
    c = np.zeros(n + 2)
    c[1:n] = np.cumsum(phi_ddot)
    reduced = t.T @ big_m @ t
    chol = np.linalg.cholesky(reduced)
    s_ddot = np.linalg.solve(chol.T, np.linalg.solve(chol, t.T @ (q0 - big_m @ c)))
    qdd = t @ s_ddot + c
    residual = (big_m @ qdd - q0)[:n]
    torques = -np.cumsum(residual[:-1])
    return qdd[:n], qdd[n:], torques


def prescribed_shape_derivative(
    model: SwimmerModel,
    state: ArrayLike,
    phi_ddot_rad_s2: ArrayLike,
    current_m_s: ArrayLike = (0.0, 0.0),
) -> tuple[FloatArray, FloatArray]:
    """Time derivative of the state with the joint accelerations given, and the joint torques.

    Parameters are those of :func:`prescribed_shape_accelerations`.

    Returns
    -------
    x_dot : ndarray, shape (2 N + 4,)
    torques_nm : ndarray, shape (N-1,)
    """
    x = np.asarray(state, dtype=float)
    n = model.n_links
    theta_ddot, p_ddot, torques = prescribed_shape_accelerations(model, x, phi_ddot_rad_s2,
                                                                 current_m_s)
    return np.concatenate([x[n + 2 :], theta_ddot, p_ddot]), torques


def state_derivative(
    model: SwimmerModel,
    state: ArrayLike,
    torques_nm: ArrayLike,
    current_m_s: ArrayLike = (0.0, 0.0),
) -> FloatArray:
    """Time derivative of the state, x_dot = (theta_dot, p_dot, theta_ddot, p_ddot).

    Parameters are those of :func:`accelerations`.

    Returns
    -------
    ndarray, shape (2 N + 4,)
    """
    x = np.asarray(state, dtype=float)
    n = model.n_links
    theta_ddot, p_ddot = accelerations(model, x, torques_nm, current_m_s)
    return np.concatenate([x[n + 2 :], theta_ddot, p_ddot])
