"""Energy bookkeeping of the swimmer, for checking the dynamics and for reports.

Kinetic energy counts the bodies, the normal added mass and the added yaw inertia:

    T = sum_i 1/2 m_i |v_i|^2 + 1/2 (J_i + lambda_1,i) theta_dot_i^2 + 1/2 mu_i (n_i . v_i)^2

Along any solution, dT/dt = P_joint + P_fluid + P_added_mass, where P_joint is the power of the
joint torques, P_fluid the power of the fluid law's forces and torques (for the Morison law: drag,
fluid yaw damping and the current term; negative in still water: dissipation), and P_added_mass = -sum_i mu_i theta_dot_i v_n,i v_t,i is the power that the
Morison added-mass force -mu n (n . a) exchanges as a link turns while it moves (it is not the time
derivative of any energy; with C_a = 0 it vanishes and T changes only by joint work minus
dissipation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from eelsim.dynamics import fluid_link_forces, link_velocities, split_state
from eelsim.model import SwimmerModel


@dataclass(frozen=True)
class PowerBalance:
    """Instantaneous powers, W (see the module docstring).

    Attributes
    ----------
    joint : float
        Power delivered by the joint torques, sum_j u_j phi_dot_j.
    fluid : float
        Power of the fluid law's forces and torques (Morison: drag, fluid yaw damping and the
        added-mass current term).
    added_mass : float
        Power exchanged by the Morison added-mass force as links rotate.
    """

    joint: float
    fluid: float
    added_mass: float

    @property
    def total(self) -> float:
        """Sum of the three powers: the rate of change of kinetic energy."""
        return self.joint + self.fluid + self.added_mass


def kinetic_energy(model: SwimmerModel, state: ArrayLike) -> float:
    """Kinetic energy of the bodies plus added mass and added inertia, J.

    Parameters
    ----------
    model : SwimmerModel
    state : array_like, shape (2 N + 4,)

    Returns
    -------
    float
    """
    theta, _, w, _ = split_state(model, state)
    vx, vy = link_velocities(model, state)
    vn = -np.sin(theta) * vx + np.cos(theta) * vy
    return float(
        0.5 * np.sum(model.mass_kg * (vx**2 + vy**2))
        + 0.5 * np.sum((model.yaw_inertia_kg_m2 + model.fluid.lambda_1) * w**2)
        + 0.5 * np.sum(model.fluid.mu_n * vn**2)
    )


def power_balance(
    model: SwimmerModel,
    state: ArrayLike,
    torques_nm: ArrayLike,
    current_m_s: ArrayLike = (0.0, 0.0),
) -> PowerBalance:
    """Split the rate of change of kinetic energy into its sources.

    Parameters
    ----------
    model : SwimmerModel
    state : array_like, shape (2 N + 4,)
    torques_nm : array_like, shape (N-1,)
    current_m_s : array_like, shape (2,)

    Returns
    -------
    PowerBalance
    """
    theta, _, w, _ = split_state(model, state)
    u = np.asarray(torques_nm, dtype=float)
    vx, vy = link_velocities(model, state)
    water = fluid_link_forces(model, state, current_m_s)
    s, c = np.sin(theta), np.cos(theta)
    vt, vn = c * vx + s * vy, -s * vx + c * vy
    fluid = float(np.sum(vx * water.fx + vy * water.fy) + np.sum(w * water.torque))
    return PowerBalance(
        joint=float(np.dot(u, np.diff(w))),
        fluid=fluid,
        added_mass=float(-np.sum(model.fluid.mu_n * w * vn * vt)),
    )
