"""The fluid laws beyond the paper's: Galilean consistency, the energy of the reactive added-mass
terms, the linear and quadratic drag's relation to the Galilean law, and each law from the robot
file to the batched kernel (docs/model.md section 2).
"""

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from sim_helpers import random_state
from test_physics_invariants import gait_torques

from eelsim.batch import BatchSpec, run_batch, run_spec
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.dynamics import (
    fluid_link_forces,
    link_positions,
    link_velocities,
    make_state,
    state_derivative,
)
from eelsim.energy import kinetic_energy, power_balance
from eelsim.fluid import (
    FLUID_LAWS,
    GalileanCoefficients,
    HydroCoefficients,
    LighthillCoefficients,
    LinearQuadraticCoefficients,
    ResistiveCoefficients,
    ReynoldsCoefficients,
    candidate_laws,
    get_fluid_law,
)
from eelsim.integrate import integrate_rk4
from eelsim.model import SwimmerModel
from eelsim.scenario import load_scenario

PAPER = dict(C_f=0.008, C_d=0.776, C_a=0.618, C_m=0.007)
CURRENT = (0.03, 0.0)  # the 0.03 m/s


def drifting_pair(duration_s=10.0):
    """The fastest gait without steering (k_theta = 0), in still water and in a 0.03 m/s current.

    Without steering nothing the camera sees feeds back, so a Galilean law must give the still
    water run carried along by the current, when the robot starts carried along too.
    """
    still = load_scenario("straight").model_copy(update={
        "k_theta": 0.0, "waypoints_m": [(50.0, 0.0)], "duration_s": duration_s})
    moving = still.model_copy(update={"current_speed_m_s": 0.03, "current_direction_deg": 0.0})
    return still, moving


def drift_residual(still, moving, t_s, n=6):
    """Largest |p_current - (p_still + v_c t)| and |p_dot_current - (p_dot_still + v_c)|, m, m/s."""
    vc = np.asarray(CURRENT)
    shift = np.zeros_like(still)
    shift[:, n : n + 2] = np.outer(t_s, vc)
    shift[:, -2:] = vc
    return np.abs(moving - (still + shift)).max()


def swim(robot, coefficients, current, duration_s=10.0):
    """The fastest gait through the PD joints, open loop (RK4, 0.01 s), from rest in the water."""
    model = SwimmerModel.from_robot(robot, coefficients)
    x0 = make_state(np.zeros(6), velocity_m_s=current)
    return integrate_rk4(model, x0, duration_s, torques=gait_torques(model, robot),
                         current_m_s=current)


GALILEAN_LAWS = [
    GalileanCoefficients(**PAPER),
    LinearQuadraticCoefficients(C_f_lin=0.008, C_d_lin=0.776, C_f_quad=0.02, C_d_quad=1.2,
                                C_a=0.618, C_m=0.007),
    ReynoldsCoefficients(C_f_lam=1.328, C_d_inf=1.0, C_d_visc=5.0, C_a=0.618, C_m=0.007),
    LighthillCoefficients(C_f=0.008, C_d=0.776, C_a=0.618),
    ResistiveCoefficients(C_t_lin=0.008, C_n_lin=0.776, C_t_quad=0.02, C_n_quad=1.2, C_a=0.618),
    FLUID_LAWS["galilean_lift"].coefficients(**PAPER, C_L=1.2, C_D_alpha=2.0, alpha_stall=0.3),
]


@pytest.mark.parametrize("coefficients", GALILEAN_LAWS, ids=lambda c: c.law_name)
def test_swimming_in_a_steady_current_is_still_water_plus_drift_for_galilean_laws(robot,
                                                                                   coefficients):
    still = swim(robot, coefficients, (0.0, 0.0))
    moving = swim(robot, coefficients, CURRENT)
    assert np.abs(still.states[-1, 6:8]).max() > 0.2  # it swam
    assert drift_residual(still.states, moving.states, still.t_s) < 1e-11


def test_the_papers_morison_law_is_not_galilean(robot):
    coefficients = HydroCoefficients(**PAPER)
    still, moving = swim(robot, coefficients, (0.0, 0.0)), swim(robot, coefficients, CURRENT)
    assert drift_residual(still.states, moving.states, still.t_s) > 1e-3  # millimetres in 10 s


def test_the_batched_kernel_keeps_the_galilean_laws_drift(robot):
    # the closed loop without steering, the robot starting with the water's velocity (the
    # spec's initial states, as the scenarios give them, plus v_c)
    still, moving = drifting_pair()
    galilean = robot.with_coefficients(GalileanCoefficients(**PAPER))
    spec = BatchSpec.build(galilean, [still, moving])
    x0 = spec.initial_state.copy()
    x0[1, -2:] = CURRENT
    steps = np.arange(0, 1001, 50)
    res = run_spec(replace(spec, initial_state=x0), sample_steps=steps, threads=1)
    assert np.abs(res.states[0, -1, 6:8]).max() > 0.2
    assert drift_residual(res.states[0], res.states[1], steps * 0.01) < 1e-11
    ref = simulate_closed_loop(galilean, still)
    assert np.allclose(res.states[0], ref.states[steps], rtol=0, atol=1e-9)


@pytest.mark.slow
def test_galilean_added_mass_does_no_net_work_without_drag(robot):
    # the reactive terms and the Munk moment come from the links' fluid impulse: with the drag
    # and yaw damping off, kinetic energy (bodies, added mass, added inertia) changes only by
    # the joints' work, to the solver's accuracy
    coeffs = GalileanCoefficients(C_f=0.0, C_d=0.0, C_a=0.9, C_m=0.5)
    model = SwimmerModel.from_robot(robot, coeffs)
    n, size = model.n_links, model.state_size
    x0 = random_state(np.random.default_rng(2), n, rate=1.0, speed=0.05)

    def torques(t):
        return 0.05 * np.sin(3.5 * t + np.arange(n - 1))

    def rhs(t, z):
        u = torques(t)
        work = power_balance(model, z[:size], u)
        return np.concatenate([state_derivative(model, z[:size], u), [work.joint]])

    sol = solve_ivp(rhs, (0, 3.0), np.concatenate([x0, [0.0]]), method="DOP853", rtol=1e-11,
                    atol=1e-13)
    assert sol.success
    change = kinetic_energy(model, sol.y[:size, -1]) - kinetic_energy(model, x0)
    assert abs(change) > 1e-3  # the joints really did work
    assert change == pytest.approx(sol.y[size, -1], abs=1e-9 * abs(change))
    # and the terms are really there: the paper's law exchanges energy as links turn
    reactive = fluid_link_forces(model, x0).parts["reactive"]
    assert np.abs(reactive[0]).max() > 1e-4


def fluid_and_body_momenta(model, x):
    """Linear (x, y) and angular momentum about the origin of the bodies plus the water.

    Independent of the laws' code: each link's fluid impulse is P = mu_n (n . w) n at its centre
    and its angular impulse lambda_1 theta_dot (docs/model.md section 2, "Galilean-consistent
    laws"); in still water w = v.
    """
    n = model.n_links
    theta, w = x[:n], x[n + 2 : 2 * n + 2]
    X, Y = link_positions(model, x)
    vx, vy = link_velocities(model, x)
    s, c = np.sin(theta), np.cos(theta)
    impulse_n = model.fluid.mu_n * (-s * vx + c * vy)
    px = model.mass_kg * vx - impulse_n * s
    py = model.mass_kg * vy + impulse_n * c
    spin = (model.yaw_inertia_kg_m2 + model.fluid.lambda_1) * w
    return np.array([px.sum(), py.sum(), np.sum(X * py - Y * px) + spin.sum()])


WITHOUT_DRAG = [
    GalileanCoefficients(C_f=0.0, C_d=0.0, C_a=0.9, C_m=0.5),
    LinearQuadraticCoefficients(C_f_lin=0.0, C_d_lin=0.0, C_f_quad=0.0, C_d_quad=0.0, C_a=0.9,
                                C_m=0.5),
    ReynoldsCoefficients(C_f_lam=0.0, C_d_inf=0.0, C_d_visc=0.0, C_a=0.9, C_m=0.5),
    ResistiveCoefficients(C_t_lin=0.0, C_n_lin=0.0, C_t_quad=0.0, C_n_quad=0.0, C_a=0.9),
]


@pytest.mark.parametrize("coefficients", WITHOUT_DRAG, ids=lambda c: c.law_name)
def test_reactive_terms_conserve_the_momenta_of_bodies_and_water_without_drag(robot,
                                                                             coefficients):
    # Kirchhoff: the water pushes each link with -dP/dt and turns it with -(w x P) - dL/dt, so
    # with drag off and the joints' torques internal, the bodies' momentum plus the water's
    # impulse is constant, linear and angular. This pins the sign and frame of the reactive
    # terms and the Munk moment, which the energy balance alone does not (a force
    # mu_n theta_dot (w_n t - w_t n) does no work)
    model = SwimmerModel.from_robot(robot, coefficients)
    n = model.n_links
    x0 = random_state(np.random.default_rng(2), n, rate=1.0, speed=0.05)

    def torques(t):
        return 0.05 * np.sin(3.5 * t + np.arange(n - 1))

    sol = solve_ivp(lambda t, x: state_derivative(model, x, torques(t)), (0, 2.0), x0,
                    method="DOP853", rtol=1e-11, atol=1e-13, dense_output=True)
    assert sol.success
    momenta = np.array([fluid_and_body_momenta(model, sol.sol(t))
                        for t in np.linspace(0, 2.0, 21)])
    assert np.abs(momenta - momenta[0]).max() < 1e-9
    # not trivially: the bodies' own momentum does change (the water takes its share)
    bodies = [np.sum(model.mass_kg * link_velocities(model, sol.sol(t))[0])
              for t in np.linspace(0, 2.0, 21)]
    assert np.ptp(bodies) > 1e-3


def test_equal_linear_and_quadratic_coefficients_give_the_galilean_law(robot):
    rng = np.random.default_rng(4)
    galilean = SwimmerModel.from_robot(robot, GalileanCoefficients(**PAPER))
    split = SwimmerModel.from_robot(robot, LinearQuadraticCoefficients(
        C_f_lin=0.008, C_d_lin=0.776, C_f_quad=0.008, C_d_quad=0.776, C_a=0.618, C_m=0.007))
    for _ in range(5):
        x = random_state(rng, 6)
        a, b = fluid_link_forces(galilean, x, CURRENT), fluid_link_forces(split, x, CURRENT)
        for f, g in ((a.fx, b.fx), (a.fy, b.fy), (a.torque, b.torque)):
            assert np.allclose(f, g, rtol=1e-13, atol=1e-15)


def test_the_linear_drag_scale_is_one_metre_per_second():
    # the paper's linear term c v (c in kg/m) reads as c U_0 v with U_0 = 1 m/s
    law = get_fluid_law("linear_quadratic")
    lin = law.link_coefficients(0.05, 0.025, 0.02, [0.01, 0.5, 0.0, 0.0, 0.6, 0.0], 1000.0)
    paper = get_fluid_law("morison").link_coefficients(0.05, 0.025, 0.02, [0.01, 0.5, 0.6, 0.0],
                                                       1000.0)
    assert lin.c_t1 == pytest.approx(paper.c_t * 1.0) and lin.c_t2 == 0.0
    assert lin.c_n1 == pytest.approx(paper.c_n * 1.0) and lin.c_n2 == 0.0


def test_the_reynolds_law_drags_as_speed_to_the_power_one_and_a_half(robot):
    coeffs = ReynoldsCoefficients(C_f_lam=1.328, C_d_inf=0.0, C_d_visc=5.0, C_a=0.6, C_m=0.0)
    model = SwimmerModel.from_robot(robot, coeffs)
    forces = []
    for speed in (0.02, 0.08):  # straight body gliding head first, then sideways
        along = make_state(np.zeros(6), velocity_m_s=(speed, 0.0))
        across = make_state(np.zeros(6), velocity_m_s=(0.0, speed))
        forces.append((fluid_link_forces(model, along).fx.sum(),
                       fluid_link_forces(model, across).fy.sum()))
    ratios = np.array(forces[1]) / np.array(forces[0])
    assert np.allclose(ratios, 4.0**1.5, rtol=1e-12)  # four times the speed, 8 times the force
    assert forces[0][0] < 0 and forces[0][1] < 0  # against the motion


def test_the_candidates_are_the_laws_that_declare_themselves_so_and_their_lift_variants():
    bases = ("morison", "galilean", "linear_quadratic", "lighthill", "resistive")
    assert candidate_laws(lift_variants=False) == bases
    assert candidate_laws() == (*bases, *(f"{name}_lift" for name in bases))
    assert not get_fluid_law("reynolds").candidate and not FLUID_LAWS["reynolds_lift"].candidate
    for name in candidate_laws():
        assert "candidate" in vars(type(FLUID_LAWS[name]))  # declared by the law, not inherited
    for name in FLUID_LAWS:
        law = get_fluid_law(name)
        assert law.bounds.shape == (len(law.coefficient_names), 2)
        assert np.all(law.bounds[:, 0] <= law.bounds[:, 1])


@pytest.mark.parametrize("coefficients", [
    LinearQuadraticCoefficients(C_f_lin=0.008, C_d_lin=0.776, C_f_quad=0.02, C_d_quad=1.2,
                                C_a=0.618, C_m=0.007),
    ReynoldsCoefficients(C_f_lam=1.328, C_d_inf=1.0, C_d_visc=5.0, C_a=0.618, C_m=0.007),
    LighthillCoefficients(C_f=0.008, C_d=0.776, C_a=0.618),
    ResistiveCoefficients(C_t_lin=0.008, C_n_lin=0.776, C_t_quad=0.02, C_n_quad=1.2, C_a=0.618),
    FLUID_LAWS["lighthill_lift"].coefficients(C_f=0.008, C_d=0.776, C_a=0.618, C_L=1.2,
                                              C_D_alpha=2.0, alpha_stall=0.35),
], ids=lambda c: c.law_name)
def test_each_new_law_runs_in_the_batched_kernel_as_in_the_reference(robot, coefficients):
    # from the robot file's [hydrodynamics] table: law name and its coefficients
    data = robot.model_dump()
    data["hydrodynamics"] = {"law": coefficients.law_name, **coefficients.model_dump()}
    plant = type(robot).model_validate(data)
    s = load_scenario("path2").model_copy(update={"duration_s": 4.0})  # with a current
    ref = simulate_closed_loop(plant, s)
    res = run_batch(plant, s, sample_steps=np.arange(len(ref.t_s)), threads=1)
    assert np.allclose(res.states[0], ref.states, rtol=0, atol=1e-9)
    assert res.failure[0] == ref.failure
    # the water differs from the paper's: the same run ends elsewhere
    paper = simulate_closed_loop(robot, s, LoopOptions(), coefficients=HydroCoefficients(**PAPER))
    assert np.abs(paper.states[-1, 6:8] - ref.states[-1, 6:8]).max() > 1e-3
