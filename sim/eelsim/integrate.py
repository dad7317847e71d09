"""Time integration of the swimmer: fixed-step RK4 and an adaptive reference solver.

RK4 at dt = 0.01 s is what the closed loop, estimation and planning use. The adaptive solver
(scipy's ``solve_ivp``, DOP853 with tight tolerances by default) exists to check RK4 and physics.

Joint torques are given as a function ``torques(t_s, state) -> u`` (so a PD law can act inside the
RK4 stages), as a constant array, or as ``None`` for no torque. Kinematic joints (the servo joint
model, docs/model.md section 4) are given instead as their accelerations
``joint_accelerations(t_s, state) -> phi_ddot``: the plant is then the prescribed-shape dynamics.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelsim.dynamics import prescribed_shape_derivative, state_derivative
from eelsim.model import SwimmerModel

FloatArray = NDArray[np.float64]
TorqueInput = Callable[[float, FloatArray], ArrayLike] | ArrayLike | None
JointAccelerations = Callable[[float, FloatArray], ArrayLike]


@dataclass(frozen=True)
class Trajectory:
    """Sampled states of a run.

    Attributes
    ----------
    t_s : ndarray, shape (K,)
        Sample times.
    states : ndarray, shape (K, 2 N + 4)
        States (theta, p, theta_dot, p_dot) at those times.
    """

    t_s: FloatArray
    states: FloatArray


def _torque_function(
    model: SwimmerModel, torques: TorqueInput
) -> Callable[[float, FloatArray], ArrayLike]:
    if torques is None:
        zero = np.zeros(model.n_links - 1)
        return lambda _t, _x: zero
    if callable(torques):
        return torques
    const = np.asarray(torques, dtype=float)
    return lambda _t, _x: const


def _right_hand_side(
    model: SwimmerModel,
    torques: TorqueInput,
    current_m_s: ArrayLike,
    joint_accelerations: JointAccelerations | None,
) -> Callable[[float, FloatArray], FloatArray]:
    """f(t, x): torque-driven joints, or kinematic ones (then ``torques`` must be None)."""
    vc = np.asarray(current_m_s, dtype=float)
    if joint_accelerations is not None:
        if torques is not None:
            raise ValueError("give joint torques or joint accelerations, not both")
        law = joint_accelerations

        def kinematic(t: float, x: FloatArray) -> FloatArray:
            return prescribed_shape_derivative(model, x, law(t, x), vc)[0]

        return kinematic
    u = _torque_function(model, torques)

    def f(t: float, x: FloatArray) -> FloatArray:
        return state_derivative(model, x, u(t, x), vc)

    return f


def rk4_step(
    f: Callable[[float, FloatArray], FloatArray],
    t_s: float,
    state: FloatArray,
    dt_s: float,
    first_stage: FloatArray | None = None,
) -> FloatArray:
    """Advance ``state`` by one classical fourth-order Runge-Kutta step.

    Parameters
    ----------
    f : callable
        Right-hand side f(t, x) -> x_dot.
    t_s : float
        Current time.
    state : ndarray
        Current state.
    dt_s : float
        Step.
    first_stage : ndarray, optional
        f(t_s, state) when the caller has it already (it is not evaluated again).

    Returns
    -------
    ndarray
        The state at t_s + dt_s.
    """
    k1 = f(t_s, state) if first_stage is None else first_stage
    k2 = f(t_s + 0.5 * dt_s, state + 0.5 * dt_s * k1)
    k3 = f(t_s + 0.5 * dt_s, state + 0.5 * dt_s * k2)
    k4 = f(t_s + dt_s, state + dt_s * k3)
    return state + dt_s / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def integrate_rk4(
    model: SwimmerModel,
    initial_state: ArrayLike,
    duration_s: float,
    dt_s: float = 0.01,
    torques: TorqueInput = None,
    current_m_s: ArrayLike = (0.0, 0.0),
    joint_accelerations: JointAccelerations | None = None,
) -> Trajectory:
    """Integrate the swimmer open loop with fixed-step RK4.

    Parameters
    ----------
    model : SwimmerModel
        The robot.
    initial_state : array_like, shape (2 N + 4,)
        State at t = 0.
    duration_s : float
        Length of the run; must be a whole number of steps.
    dt_s : float
        Step, 0.01 s by default.
    torques : callable, array_like or None
        Joint torques ``u(t, x)``, a constant, or none.
    current_m_s : array_like, shape (2,)
        Uniform current velocity.
    joint_accelerations : callable, optional
        ``phi_ddot(t, x)`` of kinematic joints (prescribed-shape dynamics) instead of torques.

    Returns
    -------
    Trajectory
        Every step, from t = 0 to ``duration_s`` inclusive.
    """
    steps = _whole_steps(duration_s, dt_s)
    f = _right_hand_side(model, torques, current_m_s, joint_accelerations)

    states = np.empty((steps + 1, model.state_size))
    states[0] = np.asarray(initial_state, dtype=float)
    for k in range(steps):
        states[k + 1] = rk4_step(f, k * dt_s, states[k], dt_s)
    return Trajectory(t_s=np.arange(steps + 1, dtype=float) * dt_s, states=states)


def integrate_reference(
    model: SwimmerModel,
    initial_state: ArrayLike,
    duration_s: float,
    torques: TorqueInput = None,
    current_m_s: ArrayLike = (0.0, 0.0),
    t_eval: ArrayLike | None = None,
    rtol: float = 1e-11,
    atol: float = 1e-13,
    method: str = "DOP853",
    joint_accelerations: JointAccelerations | None = None,
) -> Trajectory:
    """Integrate the swimmer with an adaptive solver (``scipy.integrate.solve_ivp``) for checking.

    Parameters
    ----------
    model, initial_state, duration_s, torques, current_m_s
        As for :func:`integrate_rk4`.
    t_eval : array_like, optional
        Times at which to report the state (default: 101 evenly spaced samples).
    rtol, atol : float
        Solver tolerances.
    method : str
        Any ``solve_ivp`` method (an implicit one, ``"Radau"``, for stiff joints).
    joint_accelerations : callable, optional
        As for :func:`integrate_rk4`.

    Returns
    -------
    Trajectory

    Raises
    ------
    RuntimeError
        When the solver fails.
    """
    # imported here: scipy.integrate takes 0.6 s to import and only this check needs it
    from scipy.integrate import solve_ivp

    f = _right_hand_side(model, torques, current_m_s, joint_accelerations)
    times = np.linspace(0.0, duration_s, 101) if t_eval is None else np.asarray(t_eval, float)
    sol = solve_ivp(
        f,
        (0.0, float(duration_s)),
        np.asarray(initial_state, dtype=float),
        method=method,
        t_eval=times,
        rtol=rtol,
        atol=atol,
    )
    if not sol.success:
        raise RuntimeError(f"reference solver failed: {sol.message}")
    return Trajectory(t_s=sol.t, states=sol.y.T.copy())


def _whole_steps(duration_s: float, dt_s: float) -> int:
    if not (dt_s > 0.0 and np.isfinite(dt_s)):
        raise ValueError(f"dt_s must be positive and finite, got {dt_s}")
    steps = round(duration_s / dt_s)
    if steps < 0 or abs(steps * dt_s - duration_s) > 1e-9 * max(1.0, duration_s):
        raise ValueError(
            f"duration_s = {duration_s} is not a whole number of steps of dt_s = {dt_s}"
        )
    return int(steps)
