"""Physics invariants of the swimmer model, checked through the integrators."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from sim_helpers import random_state

from eelsim.control import Gait, gait_reference, joint_pd_torque
from eelsim.dynamics import (
    link_positions,
    link_velocities,
    make_state,
    split_state,
    state_derivative,
)
from eelsim.energy import kinetic_energy, power_balance
from eelsim.integrate import integrate_reference, integrate_rk4
from eelsim.model import SwimmerModel
from eelsim.robot import HydroCoefficients


def wave_torques(n_joints, amp=0.15, omega=3.5, beta=1.0):
    phases = np.arange(n_joints) * beta
    return lambda t, _x: amp * np.sin(omega * t + phases)


FAST_GAIT = Gait(0.87, 3.9)


def gait_torques(model, robot, gait=FAST_GAIT):
    """The gait tracked by the joint PD loop, as the robot does (smooth, bounded motion)."""
    n = model.n_links

    def u(t, x):
        alpha, alpha_dot = gait_reference(t, gait, 0.0, n)
        w = x[n + 2 : 2 * n + 2]
        return joint_pd_torque(
            alpha,
            alpha_dot,
            np.diff(x[:n]),
            np.diff(w),
            robot.joints.kp_nm_per_rad,
            robot.joints.kd_nms_per_rad,
        )

    return u


def angular_momentum(model, x):
    theta, _, w, _ = split_state(model, x)
    X, Y = link_positions(model, x)
    vx, vy = link_velocities(model, x)
    return float(np.sum(model.mass_kg * (X * vy - Y * vx) + model.yaw_inertia_kg_m2 * w))


def at_rest_with_spin(model, rng):
    x = random_state(rng, model.n_links, rate=1.5)
    x[-2:] = 0.0  # centre of mass initially at rest
    return x


def test_vacuum_without_torques_conserves_centre_of_mass_momenta_and_energy(vacuum_model):
    model = vacuum_model
    x0 = at_rest_with_spin(model, np.random.default_rng(5))
    n = model.n_links
    drifts = []
    for dt in (0.004, 0.002):
        traj = integrate_rk4(model, x0, 3.0, dt_s=dt)
        p = traj.states[:, n : n + 2]
        assert np.abs(p - p[0]).max() < 1e-12  # linear invariants: exact up to rounding
        assert np.abs(traj.states[:, -2:]).max() < 1e-12
        h = np.array([angular_momentum(model, x) for x in traj.states])
        e = np.array([kinetic_energy(model, x) for x in traj.states])
        drifts.append((np.ptp(h) / abs(h[0]), np.ptp(e) / e[0]))
    (h1, e1), (h2, e2) = drifts
    assert h1 < 1e-6 and e1 < 1e-6  # quadratic invariants: to RK4's accuracy ...
    assert h1 / h2 > 10 and e1 / e2 > 10  # ... which shrinks at (nearly) fourth order


def test_vacuum_internal_joint_torques_do_not_move_the_centre_of_mass(robot, vacuum_model):
    model = vacuum_model
    x0 = make_state(np.zeros(model.n_links), (0.3, -0.2))
    traj = integrate_rk4(model, x0, 4.0, dt_s=0.002, torques=gait_torques(model, robot))
    n = model.n_links
    theta = traj.states[:, :n]
    assert np.ptp(np.diff(theta, axis=1)) > 0.1  # the body really moved
    assert np.abs(traj.states[:, n : n + 2] - [0.3, -0.2]).max() < 1e-12
    h = [angular_momentum(model, x) for x in traj.states]
    assert np.abs(h).max() < 1e-9  # started at zero: internal torques cannot create any


def _energy_run(model, x0, torque_fn, duration, current=(0.0, 0.0)):
    """Integrate the state with the work integrals of each power, tightly."""
    size = model.state_size

    def rhs(t, z):
        x = z[:size]
        u = torque_fn(t, x)
        pb = power_balance(model, x, u, current)
        return np.concatenate(
            [state_derivative(model, x, u, current), [pb.joint, pb.fluid, pb.added_mass]]
        )

    sol = solve_ivp(
        rhs,
        (0, duration),
        np.concatenate([x0, np.zeros(3)]),
        method="DOP853",
        rtol=1e-11,
        atol=1e-13,
    )
    assert sol.success
    z = sol.y[:, -1]
    return kinetic_energy(model, x0), kinetic_energy(model, z[:size]), z[size:]


@pytest.mark.slow
def test_kinetic_energy_change_equals_joint_work_minus_dissipation_when_added_mass_is_off(robot):
    model = SwimmerModel.from_robot(
        robot, HydroCoefficients(C_f=0.008, C_d=0.776, C_a=0.0, C_m=0.007)
    )
    x0 = make_state(np.zeros(model.n_links))
    t0, t1, (w_joint, w_fluid, w_am) = _energy_run(model, x0, wave_torques(model.n_links - 1), 4.0)
    assert w_am == 0.0
    assert w_joint > 0 and w_fluid < 0  # the joints drive, the water dissipates
    assert t1 - t0 == pytest.approx(w_joint + w_fluid, abs=1e-9 * w_joint)


@pytest.mark.slow
def test_energy_balance_with_added_mass_accounts_for_morison_exchange_term(model):
    x0 = make_state(np.zeros(model.n_links))
    t0, t1, (w_joint, w_fluid, w_am) = _energy_run(model, x0, wave_torques(model.n_links - 1), 4.0)
    assert t1 - t0 == pytest.approx(w_joint + w_fluid + w_am, abs=1e-9 * w_joint)
    assert abs(w_am) < 0.5 * w_joint  # a correction, not the main term


def test_robot_at_rest_in_a_current_is_carried_towards_the_current_velocity(model):
    current = np.array([-0.03, 0.02])
    x0 = make_state(np.full(model.n_links, 0.4))
    traj = integrate_rk4(model, x0, 60.0, current_m_s=current)
    v = traj.states[:, -2:]
    along = v @ current / np.linalg.norm(current)
    assert np.all(np.diff(along) > -1e-12)  # never slows down relative to the current
    assert np.linalg.norm(v[-1] - current) < 0.05 * np.linalg.norm(current)
    moved = (
        traj.states[-1, model.n_links : model.n_links + 2]
        - traj.states[0, model.n_links : model.n_links + 2]
    )
    assert moved @ current > 0


def test_mirrored_initial_state_and_torques_give_mirrored_trajectory(model):
    rng = np.random.default_rng(7)
    n = model.n_links
    x0 = random_state(rng, n, rate=0.5, speed=0.05)
    fn = wave_torques(n - 1)
    current = np.array([0.02, 0.015])
    mirror = np.ones(model.state_size)
    mirror[:n] = -1  # theta -> -theta
    mirror[n + 1] = -1  # p_y -> -p_y
    mirror[n + 2 : 2 * n + 2] = -1
    mirror[-1] = -1
    a = integrate_rk4(model, x0, 3.0, torques=fn, current_m_s=current)
    b = integrate_rk4(
        model, mirror * x0, 3.0, torques=lambda t, x: -fn(t, x), current_m_s=current * [1, -1]
    )
    assert np.abs(a.states * mirror - b.states).max() < 1e-12


def test_rk4_converges_at_fourth_order_against_adaptive_solver(robot, model):
    x0 = make_state(np.zeros(model.n_links))
    fn = gait_torques(model, robot)
    ref = integrate_reference(model, x0, 1.0, torques=fn, t_eval=[1.0], current_m_s=(0.01, 0.0))
    errors = []
    for dt in (0.01, 0.005, 0.0025):
        traj = integrate_rk4(model, x0, 1.0, dt_s=dt, torques=fn, current_m_s=(0.01, 0.0))
        errors.append(np.abs(traj.states[-1] - ref.states[-1]).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 3.6), (errors, orders)
    assert errors[0] < 1e-4  # at the default step, 1 s of swimming
