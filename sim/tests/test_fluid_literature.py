"""The laws from the literature (docs/model.md section 2): Lighthill's elongated-body law, the
resistive-force drag and the lift any law can carry; each against an independent computation or
an invariant: reduction to an existing law, momentum and energy shed at the tail, exact
integrals against quadrature, dissipation, lift that does no work.
"""

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from sim_helpers import random_state

from eelsim.dynamics import (
    fluid_link_forces,
    link_positions,
    link_velocities,
    state_derivative,
)
from eelsim.energy import power_balance
from eelsim.fluid import (
    FLUID_LAWS,
    GalileanCoefficients,
    LiftLaw,
    LighthillCoefficients,
    LinearQuadraticCoefficients,
    ResistiveCoefficients,
    get_fluid_law,
)
from eelsim.fluid.base import LinkMotion
from eelsim.model import SwimmerModel

CURRENT = np.array([0.03, -0.01])


def tail_tip(model, x, current=(0.0, 0.0)):
    """Tail link's tip: position, velocity relative to the water, t and n, from the state alone."""
    n = model.n_links
    theta, om = x[0], x[n + 2]
    t, nv = np.array([np.cos(theta), np.sin(theta)]), np.array([-np.sin(theta), np.cos(theta)])
    X, Y = link_positions(model, x)
    vx, vy = link_velocities(model, x)
    half = model.half_length_m[0]
    r = np.array([X[0], Y[0]]) - half * t
    v = np.array([vx[0], vy[0]]) - half * om * nv - np.asarray(current)
    return r, v, t, nv, half


def test_lighthill_is_the_galilean_law_but_for_the_tail_tips_shed_momentum(robot):
    rng = np.random.default_rng(11)
    light = SwimmerModel.from_robot(robot, LighthillCoefficients(C_f=0.01, C_d=0.8, C_a=0.9))
    gal = SwimmerModel.from_robot(robot, GalileanCoefficients(C_f=0.01, C_d=0.8, C_a=0.9,
                                                              C_m=0.3))
    for _ in range(5):
        x = random_state(rng, light.n_links)
        a, b = fluid_link_forces(light, x, CURRENT), fluid_link_forces(gal, x, CURRENT)
        for f, g in ((a.fx, b.fx), (a.fy, b.fy), (a.torque, b.torque)):
            assert np.allclose(f[1:], g[1:], rtol=1e-13, atol=1e-16)
        # the tail link: Lighthill's [m u w_n n - 1/2 m w_n^2 t] at the tip, m = mu_n / 2l
        r, v, t, nv, half = tail_tip(light, x, CURRENT)
        m = light.fluid.mu_n[0] / (2 * half)
        u, wn = v @ t, v @ nv
        force = -(m * u * wn * nv - 0.5 * m * wn**2 * t)
        assert np.allclose([a.fx[0] - b.fx[0], a.fy[0] - b.fy[0]], force, rtol=1e-12, atol=1e-16)
        arm = -half * t  # from the tail link's centre to its tip
        assert a.torque[0] - b.torque[0] == pytest.approx(arm[0] * force[1] - arm[1] * force[0],
                                                          rel=1e-12, abs=1e-16)


def test_lighthills_tail_sheds_energy_when_swimming_head_first(robot):
    # without drag, kinetic energy (bodies, added mass, added inertia) changes by the joints'
    # work and the tail term's power, F_tail . v_tip = -1/2 m u w_n^2: never positive for u > 0
    model = SwimmerModel.from_robot(robot, LighthillCoefficients(C_f=0.0, C_d=0.0, C_a=1.0))
    rng = np.random.default_rng(5)
    shed = []
    for _ in range(8):
        x = random_state(rng, model.n_links)
        balance = power_balance(model, x, np.zeros(model.n_links - 1))
        _, v, t, nv, half = tail_tip(model, x)
        m = model.fluid.mu_n[0] / (2 * half)
        expected = -0.5 * m * (v @ t) * (v @ nv) ** 2
        assert balance.fluid + balance.added_mass == pytest.approx(expected, rel=1e-10,
                                                                   abs=1e-15)
        if v @ t > 0:
            shed.append(expected)
    assert shed and max(shed) <= 0.0 and min(shed) < 0.0


def test_lighthills_reactive_force_is_the_lateral_flows_momentum_change_plus_the_tails(robot):
    # bodies' momentum plus the lateral flow's impulse (P = mu_n w_n n per link, angular
    # lambda_1 omega with lambda_1 = mu_n l^2 / 3, the slender link's) changes only by the tail
    # term: its force, and its moment about the origin; this pins the sign and frame of the
    # reactive terms, the Munk moment, the added inertia and the tail term together
    model = SwimmerModel.from_robot(robot, LighthillCoefficients(C_f=0.0, C_d=0.0, C_a=0.9))
    n = model.n_links
    assert np.allclose(model.fluid.lambda_1, model.fluid.mu_n * model.fluid.half_length**2 / 3)

    def torques(t):
        return 0.05 * np.sin(3.5 * t + np.arange(n - 1))

    def momenta(x):
        theta, w = x[:n], x[n + 2 : 2 * n + 2]
        X, Y = link_positions(model, x)
        vx, vy = link_velocities(model, x)
        s, c = np.sin(theta), np.cos(theta)
        impulse = model.fluid.mu_n * (-s * vx + c * vy)
        px, py = model.mass_kg * vx - impulse * s, model.mass_kg * vy + impulse * c
        spin = (model.yaw_inertia_kg_m2 + model.fluid.lambda_1) * w
        return np.array([px.sum(), py.sum(), np.sum(X * py - Y * px) + spin.sum()])

    def tail_push(x):
        r, v, t, nv, half = tail_tip(model, x)
        m = model.fluid.mu_n[0] / (2 * half)
        f = -(m * (v @ t) * (v @ nv) * nv - 0.5 * m * (v @ nv) ** 2 * t)
        return np.array([f[0], f[1], r[0] * f[1] - r[1] * f[0]])

    def rhs(t, z):
        return np.concatenate([state_derivative(model, z[:-3], torques(t)), tail_push(z[:-3])])

    x0 = random_state(np.random.default_rng(2), n, rate=1.0, speed=0.05)
    sol = solve_ivp(rhs, (0, 2.0), np.concatenate([x0, np.zeros(3)]), method="DOP853",
                    rtol=1e-11, atol=1e-13)
    assert sol.success
    change = momenta(sol.y[:-3, -1]) - momenta(x0)
    assert np.abs(sol.y[-3:, -1]).max() > 1e-4  # the tail really pushed
    assert np.allclose(change, sol.y[-3:, -1], rtol=0, atol=1e-9)


def test_lighthills_tail_gives_thrust_to_a_wave_faster_than_the_body():
    # Lighthill's mean thrust 1/2 m (<h_t^2> - U^2 <h_x^2>) at the tail: positive when the
    # body's wave (h = H sin(k x + omega t), speed V = omega / k) runs backwards faster than
    # the body swims (U < V), negative when slower. The tail link lies along the wave's slope at
    # the tip (x = 0), which moves with (U, h_t); its centre is l ahead
    law = get_fluid_law("lighthill")
    half = 0.05
    fluid = law.link_coefficients(np.array([half]), np.array([0.025]), np.array([0.02]),
                                  [0.0, 0.0, 1.0], 1000.0)
    m = fluid.mu_n[0] / (2 * half)
    amplitude, k, omega = 0.005, 2 * np.pi / 0.6, 2 * np.pi * 1.5
    for swim, sign in ((0.5 * omega / k, 1.0), (1.5 * omega / k, -1.0)):
        thrust = []
        for time in np.linspace(0, 2 * np.pi / omega, 64, endpoint=False):
            slope = amplitude * k * np.cos(omega * time)
            theta = np.arctan(slope)
            rate = -amplitude * k * omega * np.sin(omega * time) / (1 + slope**2)
            h_t = amplitude * omega * np.cos(omega * time)
            # the centre's velocity: the tip's plus l omega n
            vx = swim - half * rate * np.sin(theta)
            vy = h_t + half * rate * np.cos(theta)
            f = law.forces(fluid, LinkMotion(np.array([np.sin(theta)]), np.array([np.cos(theta)]),
                                             np.array([rate]), np.array([vx]), np.array([vy])),
                           np.zeros(2))
            thrust.append(f.parts["tail"][0][0])
        expected = 0.5 * m * 0.5 * amplitude**2 * (omega**2 - swim**2 * k**2)
        assert np.sign(np.mean(thrust)) == sign
        assert np.mean(thrust) == pytest.approx(expected, rel=0.02)  # small-amplitude theory


def _resistive_by_quadrature(fluid, j, vt, vn, om):
    """f_t, f_n, torque of link j from the per-length force density, by adaptive quadrature."""
    h = fluid.half_length[j]

    def normal(sigma):
        wn = vn + sigma * om
        return -(fluid.k_n1[j] * wn + fluid.k_n2[j] * abs(wn) * wn)

    points = [-vn / om] if om != 0 and abs(vn / om) < h else None
    fn = quad(normal, -h, h, points=points, epsabs=1e-16, epsrel=1e-11)[0]
    torque = quad(lambda s: s * normal(s), -h, h, points=points, epsabs=1e-16, epsrel=1e-11)[0]
    ft = -2 * h * (fluid.k_t1[j] * vt + fluid.k_t2[j] * abs(vt) * vt)
    return ft, fn, torque


def test_resistive_drag_is_the_exact_integral_of_the_force_density_along_each_link():
    law = get_fluid_law("resistive")
    halves = np.array([0.04, 0.05, 0.06])
    fluid = law.link_coefficients(halves, np.full(3, 0.025), np.full(3, 0.02),
                                  [0.01, 0.8, 0.02, 1.2, 0.0], 1000.0)
    rng = np.random.default_rng(3)
    crossings = 0
    for _ in range(40):
        vt, vn, om = rng.normal(0, 0.1, 3), rng.normal(0, 0.1, 3), rng.normal(0, 3.0, 3)
        om[rng.random(3) < 0.1] = 0.0
        got = law.drag(fluid, vt, vn, om)
        for j in range(3):
            crossings += abs(vn[j]) < halves[j] * abs(om[j])
            want = _resistive_by_quadrature(fluid, j, vt[j], vn[j], om[j])
            for g, w in zip(got, want, strict=True):
                assert g[j] == pytest.approx(w, rel=1e-9, abs=1e-15)
    assert crossings > 10  # both branches: the normal velocity changes sign along many links


def test_resistive_drag_without_rotation_is_the_linear_quadratic_law(robot):
    rng = np.random.default_rng(8)
    rft = SwimmerModel.from_robot(robot, ResistiveCoefficients(
        C_t_lin=0.008, C_n_lin=0.776, C_t_quad=0.02, C_n_quad=1.2, C_a=0.6))
    split = SwimmerModel.from_robot(robot, LinearQuadraticCoefficients(
        C_f_lin=0.008, C_d_lin=0.776, C_f_quad=0.02, C_d_quad=1.2, C_a=0.6, C_m=0.0))
    n = rft.n_links
    for _ in range(5):
        x = random_state(rng, n)
        x[n + 2 : 2 * n + 2] = 0.0  # no link turns
        a, b = fluid_link_forces(rft, x, CURRENT), fluid_link_forces(split, x, CURRENT)
        for f, g in ((a.fx, b.fx), (a.fy, b.fy), (a.torque, b.torque)):
            assert np.allclose(f, g, rtol=1e-12, atol=1e-16)
        spinning = random_state(rng, n)
        assert not np.allclose(fluid_link_forces(rft, spinning).torque,
                               fluid_link_forces(split, spinning).torque)


def test_pure_resistive_force_theory_only_dissipates(robot):
    model = SwimmerModel.from_robot(robot, ResistiveCoefficients(
        C_t_lin=0.01, C_n_lin=0.8, C_t_quad=0.02, C_n_quad=1.2, C_a=0.0))
    rng = np.random.default_rng(9)
    n = model.n_links
    for _ in range(20):
        x = random_state(rng, n)
        f = fluid_link_forces(model, x, CURRENT)
        vx, vy = link_velocities(model, x)
        power = (vx - CURRENT[0]) * f.fx + (vy - CURRENT[1]) * f.fy + x[n + 2 : 2 * n + 2] * f.torque
        assert np.all(power < 0.0)


@pytest.mark.parametrize("base", [law.base.name for law in FLUID_LAWS.values()
                                  if isinstance(law, LiftLaw)])
def test_lift_is_perpendicular_to_the_relative_flow_with_the_sin_two_alpha_magnitude(base):
    law = FLUID_LAWS[f"{base}_lift"]
    assert law.coefficient_names == (*get_fluid_law(base).coefficient_names, "C_L", "C_D_alpha",
                                     "alpha_stall")
    rng = np.random.default_rng(1)
    n = 4
    coeffs = rng.uniform(law.bounds[:, 0], law.bounds[:, 1])
    coeffs[-2:] = 0.0, np.pi / 2  # the lift alone: no drag rise, no stall
    half, a, b = np.full(n, 0.05), np.full(n, 0.025), np.full(n, 0.02)
    lifted = law.link_coefficients(half, a, b, coeffs, 1000.0)
    plain = get_fluid_law(base).link_coefficients(half, a, b, coeffs[:-3], 1000.0)
    theta, om, rel = rng.uniform(-3, 3, n), rng.normal(0, 2, n), rng.normal(0, 0.1, (n, 2))
    rel[0] = 0.0  # a link at rest in the water feels no lift
    motion = LinkMotion(np.sin(theta), np.cos(theta), om, rel[:, 0], rel[:, 1])
    with_lift = law.forces(lifted, motion, CURRENT)
    without = get_fluid_law(base).forces(plain, motion, CURRENT)
    lx, ly = with_lift.parts["lift"]
    # the variant is its base law plus the lift (to rounding: the forces are ~0.3 N)
    assert np.allclose(with_lift.fx - without.fx, lx, rtol=0, atol=1e-15)
    assert np.allclose(with_lift.fy - without.fy, ly, rtol=0, atol=1e-15)
    assert np.allclose(with_lift.torque, without.torque, rtol=0, atol=0)
    # does no work (to rounding of the products, ~0.02 W)
    assert np.allclose(lx * rel[:, 0] + ly * rel[:, 1], 0.0, atol=1e-16)
    alpha = np.arctan2(-np.sin(theta) * rel[:, 0] + np.cos(theta) * rel[:, 1],
                       np.cos(theta) * rel[:, 0] + np.sin(theta) * rel[:, 1])
    area = 2 * a * 2 * half
    magnitude = 0.5 * 1000.0 * area * coeffs[-3] * np.abs(np.sin(2 * alpha)) * (rel**2).sum(1)
    assert np.allclose(np.hypot(lx, ly), magnitude, rtol=1e-12, atol=1e-18)
    assert lx[0] == 0.0 and ly[0] == 0.0
    normal = -np.sin(theta) * lx + np.cos(theta) * ly
    wn = -np.sin(theta) * rel[:, 0] + np.cos(theta) * rel[:, 1]
    assert np.all(normal * wn <= 0.0)  # its normal part opposes the sideways motion, as a plate's


@pytest.mark.parametrize("base", ["galilean", "morison", "resistive"])
def test_the_drag_rise_opposes_the_flow_with_the_sin_squared_magnitude_and_its_crossflow_moment(base):
    law = FLUID_LAWS[f"{base}_lift"]
    rng = np.random.default_rng(3)
    n = 5
    coeffs = rng.uniform(law.bounds[:, 0], law.bounds[:, 1])
    coeffs[-3] = 0.0  # the drag rise alone: no lift
    coeffs[-1] = np.pi / 2  # and no stall (a stalled plate's lift is the drag rise's k_D)
    half, a, b = rng.uniform(0.03, 0.06, n), rng.uniform(0.02, 0.03, n), np.full(n, 0.02)
    rho = 1000.0
    risen = law.link_coefficients(half, a, b, coeffs, rho)
    plain = get_fluid_law(base).link_coefficients(half, a, b, coeffs[:-3], rho)
    theta, om, rel = rng.uniform(-3, 3, n), rng.normal(0, 2, n), rng.normal(0, 0.1, (n, 2))
    rel[0] = 0.0
    motion = LinkMotion(np.sin(theta), np.cos(theta), om, rel[:, 0], rel[:, 1])
    with_rise = law.forces(risen, motion, CURRENT)
    without = get_fluid_law(base).forces(plain, motion, CURRENT)
    dx, dy = with_rise.fx - without.fx, with_rise.fy - without.fy
    # the variant is its base law plus the drag rise (to rounding)
    assert np.allclose((dx, dy), with_rise.parts["rise"], rtol=0, atol=1e-14)
    dx, dy = with_rise.parts["rise"]
    speed2 = (rel**2).sum(1)
    # along -w: no component across the flow, and it takes energy
    assert np.allclose(dx * rel[:, 1] - dy * rel[:, 0], 0.0, rtol=0, atol=1e-15)
    assert np.all(dx * rel[:, 0] + dy * rel[:, 1] <= 0.0)
    wn = -np.sin(theta) * rel[:, 0] + np.cos(theta) * rel[:, 1]
    sin2 = np.divide(wn**2, speed2, out=np.zeros(n), where=speed2 > 0)
    magnitude = 0.5 * rho * (2 * a) * (2 * half) * coeffs[-2] * sin2 * speed2
    assert np.allclose(np.hypot(dx, dy), magnitude, rtol=1e-12, atol=1e-18)
    assert dx[0] == 0.0 and dy[0] == 0.0
    # the moment: the cross-flow drag 1/2 rho 2a C_D_alpha |s w| s w integrated along the link
    # turning about its centre (quadrature, independent of the closed form)
    dtau = with_rise.torque - without.torque
    for i in range(n):
        per_length = 0.5 * rho * 2 * a[i] * coeffs[-2]
        moment = quad(lambda s, k=per_length, w=om[i]: -s * k * abs(s * w) * s * w,
                      -half[i], half[i])[0]
        assert np.isclose(dtau[i], moment, rtol=1e-10, atol=1e-18)


@pytest.mark.parametrize("base", ["linear_quadratic", "morison"])
def test_a_stalled_link_feels_a_flat_plates_normal_force_and_an_attached_one_the_full_lift(base):
    # flat plate past the stall (Hoerner; Dickinson et al.): lift and drag rise add up to a force
    # normal to the link of 1/2 rho S C_D_alpha sin(alpha) |w|^2; below the stall angle the
    # variant is the one that never stalls
    law = FLUID_LAWS[f"{base}_lift"]
    rng = np.random.default_rng(8)
    n = 400
    coeffs = rng.uniform(law.bounds[:, 0], law.bounds[:, 1])
    coeffs[-3:] = 2.5, 1.1, np.radians(20.0)
    never = coeffs.copy()
    never[-1] = np.pi / 2
    half, a, b = np.full(n, 0.05), np.full(n, 0.025), np.full(n, 0.02)
    stalls = law.link_coefficients(half, a, b, coeffs, 1000.0)
    attached = law.link_coefficients(half, a, b, never, 1000.0)
    theta = rng.uniform(-3, 3, n)
    alpha = rng.uniform(0.0, np.pi / 2, n) * rng.choice([-1, 1], n)  # either side, head or tail
    alpha[rng.random(n) < 0.5] += np.pi
    speed = rng.uniform(0.01, 0.2, n)
    wt, wn = speed * np.cos(alpha), speed * np.sin(alpha)
    vx, vy = np.cos(theta) * wt - np.sin(theta) * wn, np.sin(theta) * wt + np.cos(theta) * wn
    motion = LinkMotion(np.sin(theta), np.cos(theta), np.zeros(n), vx, vy)
    f_stall = law.forces(stalls, motion, np.zeros(2))
    f_never = law.forces(attached, motion, np.zeros(2))
    acute = np.arcsin(np.abs(np.sin(alpha)))
    below, past = acute < np.radians(20.0), acute > np.radians(24.0)
    assert below.sum() > 20 and past.sum() > 20
    np.testing.assert_array_equal(f_stall.fx[below], f_never.fx[below])
    lx, ly = f_stall.parts["lift"]
    rx, ry = f_stall.parts["rise"]
    fx, fy = lx + rx, ly + ry
    along = np.cos(theta) * fx + np.sin(theta) * fy
    across = -np.sin(theta) * fx + np.cos(theta) * fy
    plate = 0.5 * 1000.0 * (2 * a) * (2 * half) * 1.1 * np.abs(np.sin(alpha)) * speed**2
    scale = plate.max()
    np.testing.assert_allclose(along[past], 0.0, atol=1e-12 * scale)
    np.testing.assert_allclose(np.abs(across[past]), plate[past], rtol=1e-12)
    assert np.all(across[past] * wn[past] < 0.0)  # against the sideways flow
    # in the band between, the lift's coefficient lies between the attached and the plate's
    band = ~below & ~past
    k_never = np.hypot(*f_never.parts["lift"])
    k_stall = np.hypot(lx, ly)
    plate_lift = 0.5 * 1000.0 * (2 * a) * (2 * half) * 1.1 * np.abs(np.sin(2 * alpha)) / 2 * speed**2
    lo, hi = np.minimum(k_never, plate_lift), np.maximum(k_never, plate_lift)
    assert np.all((k_stall[band] >= lo[band] - 1e-15) & (k_stall[band] <= hi[band] + 1e-15))


def test_a_lift_variant_with_no_lift_is_its_base_law(robot):
    rng = np.random.default_rng(6)
    base = SwimmerModel.from_robot(robot, GalileanCoefficients(C_f=0.01, C_d=0.8, C_a=0.9,
                                                               C_m=0.1))
    record = FLUID_LAWS["galilean_lift"].coefficients
    lifted = SwimmerModel.from_robot(robot, record(C_f=0.01, C_d=0.8, C_a=0.9, C_m=0.1, C_L=0.0))
    x = random_state(rng, base.n_links)
    a, b = fluid_link_forces(base, x, CURRENT), fluid_link_forces(lifted, x, CURRENT)
    assert np.array_equal(a.fx, b.fx) and np.array_equal(a.torque, b.torque)
    assert np.array_equal(state_derivative(base, x, np.zeros(base.n_links - 1)),
                          state_derivative(lifted, x, np.zeros(base.n_links - 1)))
