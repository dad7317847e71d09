"""Test plants that test: each records something else than the bundled tank (issue 32)."""

from pathlib import Path

import numpy as np
import pytest

from eelhost.data.experiments import load_dataset
from eelhost.data.plant_laws import (
    FOIL,
    QUARTER_CHORD,
    STALL,
    FoilCoefficients,
    QuarterChordCoefficients,
    StallCoefficients,
)
from eelhost.data.plants import PLANTS, SMALL_SERVO_STALL_NM
from eelhost.data.virtual_tank import (
    TABLE3,
    TankSettings,
    paper_experiment_plan,
    record_experiment,
    true_robot,
)
from eelhost.estimation.coefficients_file import FittedModel
from eelhost.estimation.evaluate import Evaluator
from eelsim.fluid import candidate_laws
from eelsim.robot import SERVO_ROBOT, load_robot
from eelsim.scenario import load_scenario

REPO = Path(__file__).resolve().parents[2]
BUNDLED = REPO / "datasets" / "paper_virtual_tank"
FAST_GAIT = "straight_A0.87_w3.9"  # where the small servo's line binds hardest
PIXEL_M = 0.0038


@pytest.fixture(scope="module")
def bundled_fast():
    """The bundled dataset's fast straight experiment, its plan index (its seed) and task."""
    ds = load_dataset(BUNDLED)
    index, (motion, _split, task) = next(
        (i, p) for i, p in enumerate(paper_experiment_plan()) if p[2].name == FAST_GAIT)
    recorded = next(e for e in ds.train[motion] + ds.test[motion] if e.name == FAST_GAIT)
    # its first 6 s: the recording is causal, so a shorter run records the same frames
    return ds.robot, index, motion, task.model_copy(update={"duration_s": 6.0}), recorded


def _prefix_gap(exp, recorded):
    n = min(len(exp.t_s), len(recorded.t_s)) - 3  # a centred median's last frames differ
    return float(np.linalg.norm(exp.position_m[:n] - recorded.position_m[:n], axis=1).max())


def test_the_bundled_tanks_settings_record_the_bundled_dataset_again(bundled_fast):
    # what makes the test below meaningful: the same plan index and seed reproduce the file
    robot, index, motion, task, recorded = bundled_fast
    exp = record_experiment(robot, task, motion, TABLE3[motion], TankSettings(), seed=index)
    assert _prefix_gap(exp, recorded) == 0.0


@pytest.mark.parametrize("plant", sorted(PLANTS))
def test_every_plant_records_something_else_than_the_bundled_dataset(bundled_fast, plant):
    # issue 32: servo_limits recorded exactly the bundled figures (the paper's soft PD joints
    # ask 2.6 % of the robot file's servo's stall torque, so its line never bound)
    robot, index, motion, task, recorded = bundled_fast
    p = PLANTS[plant]
    exp = record_experiment(robot, task, motion, p.truths()[motion], p.settings, seed=index)
    assert _prefix_gap(exp, recorded) > 1.5 * PIXEL_M, plant


def test_the_servo_limits_plant_clips_its_joints_on_a_small_servos_line():
    p = PLANTS["servo_limits"]
    robot = load_robot()
    plant_robot = true_robot(robot, p.settings)
    assert p.settings.servo_limits
    assert plant_robot.joints.servo_max_torque_nm == SMALL_SERVO_STALL_NM
    assert plant_robot.joints.kp_nm_per_rad == robot.joints.kp_nm_per_rad  # the same PD loop


def test_plant_only_laws_are_no_candidate_and_two_plants_swim_in_them():
    assert FOIL.name not in candidate_laws() and STALL.name not in candidate_laws()
    foil_plants = {n for n, p in PLANTS.items() if p.law == FOIL.name}
    assert {"foil_lift", "no_added_mass"} <= foil_plants
    stalling = PLANTS["stalling_foil"]
    assert stalling.law == STALL.name and stalling.settings == PLANTS["foil_lift"].settings
    stall = stalling.truths()["straight"]
    assert stall.C_L > stall.C_D2  # the lift drops at the stall angle
    still = PLANTS["no_added_mass"].truths()
    assert still["straight"].C_a == 0.0 and still["turning"].C_m == 0.0
    lift = PLANTS["foil_lift"].truths()["straight"]
    assert lift.C_a == TABLE3["straight"].C_a and lift.C_L > 0


def test_foil_lift_does_no_work_and_its_drag_only_dissipates():
    robot = load_robot()
    c = FoilCoefficients(C_D0=0.008, C_D2=1.0, C_L=1.0, C_a=0.6, C_m=0.0)
    fluid = FOIL.link_coefficients(robot.link.half_length_m, robot.link.half_axis_vertical_m,
                                   robot.link.half_axis_horizontal_m, c.as_array(), 1000.0)
    rng = np.random.default_rng(0)
    vt, vn, om = rng.normal(0, 0.1, (3, 1000))
    ft, fn, tq = FOIL.drag(fluid, vt, vn, om)
    power = ft * vt + fn * vn
    assert np.all(power <= 1e-15) and np.all(tq * om <= 0)
    no_lift = FoilCoefficients(C_D0=0.008, C_D2=1.0, C_L=0.0, C_a=0.6, C_m=0.0)
    f0 = FOIL.link_coefficients(robot.link.half_length_m, robot.link.half_axis_vertical_m,
                                robot.link.half_axis_horizontal_m, no_lift.as_array(), 1000.0)
    ft0, fn0, _ = FOIL.drag(f0, vt, vn, om)
    # the lift's power is zero: both laws dissipate the same
    np.testing.assert_allclose(power, ft0 * vt + fn0 * vn, rtol=1e-9, atol=1e-18)
    # and it is across the flow, against the normal flow at a small angle of attack
    lift = np.stack([ft - ft0, fn - fn0])
    np.testing.assert_allclose(lift[0] * vt + lift[1] * vn, 0.0, atol=1e-15)
    small = np.abs(vn) < 0.1 * np.abs(vt)
    assert np.all(lift[1][small] * vn[small] <= 0)
    # at rest relative to the water: no force, no division by zero
    assert FOIL.drag(fluid, np.zeros(1), np.zeros(1), np.zeros(1))[0][0] == 0.0


def _stalled_plate_forces(c, half_length, half_vertical, half_horizontal, rho, vt, vn):
    """The stall law in angle form, written from docs/estimation.md: drag along -w, lift across.

    D = q |w|^2 (S_t C_D0 + S_n C_D2 sin^2 a), L = q |w|^2 S_n C sin a cos a with C = C_L up to
    the stall angle and C_D2 beyond, turned against the normal flow.
    """
    q = rho / 2.0
    wetted = np.pi * (half_vertical + half_horizontal) * half_length
    lateral = 4.0 * half_vertical * half_length
    speed = np.hypot(vt, vn)
    ut, un = vt / speed, vn / speed  # the flow's direction in the link's frame
    sin_a, cos_a = np.abs(un), np.abs(ut)
    stalled = np.arcsin(sin_a) > c.alpha_stall
    lift_coefficient = np.where(stalled, c.C_D2, c.C_L)
    drag = q * speed**2 * (wetted * c.C_D0 + lateral * c.C_D2 * sin_a**2)
    lift = q * speed**2 * lateral * lift_coefficient * sin_a * cos_a
    # across the flow, the side whose normal component opposes w_n
    across_t, across_n = np.sign(ut * un) * un, -np.sign(ut * un) * ut
    return -drag * ut + lift * across_t, -drag * un + lift * across_n, stalled


def test_the_stall_law_is_the_foil_law_below_the_stall_angle_and_a_stalled_plate_above():
    robot = load_robot()
    geometry = (robot.link.half_length_m, robot.link.half_axis_vertical_m,
                robot.link.half_axis_horizontal_m)
    stall = StallCoefficients(C_D0=0.008, C_D2=1.0, C_L=2.0, C_a=0.6, C_m=0.01,
                              alpha_stall=np.radians(16.0))
    foil = FoilCoefficients(**{k: v for k, v in stall.model_dump().items() if k != "alpha_stall"})
    s_fluid = STALL.link_coefficients(*geometry, stall.as_array(), 1000.0)
    f_fluid = FOIL.link_coefficients(*geometry, foil.as_array(), 1000.0)
    rng = np.random.default_rng(3)
    vt, vn, om = rng.normal(0, 0.1, (3, 2000))
    st_t, st_n, st_q = STALL.drag(s_fluid, vt, vn, om)
    fo_t, fo_n, fo_q = FOIL.drag(f_fluid, vt, vn, om)
    want_t, want_n, stalled = _stalled_plate_forces(stall, *geometry, 1000.0, vt, vn)
    assert 200 < stalled.sum() < 1800  # both sides of the stall angle are tried
    attached = ~stalled
    # below the stall angle: the foil law, force for force; the same added mass and damping
    np.testing.assert_allclose(st_t[attached], fo_t[attached], rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(st_n[attached], fo_n[attached], rtol=1e-12, atol=1e-18)
    np.testing.assert_array_equal(st_q, fo_q)
    np.testing.assert_array_equal(s_fluid.mu_n, f_fluid.mu_n)
    # everywhere: the angle form; above the stall angle the lift is smaller than the foil's
    np.testing.assert_allclose(st_t, want_t, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(st_n, want_n, rtol=1e-9, atol=1e-15)
    # (the two lifts vanish together only where the flow is across the link, alpha = 90 deg)
    beyond = stalled & (np.abs(vt) > 0.1 * np.hypot(vt, vn))
    gap = np.hypot(fo_t - st_t, fo_n - st_n)[beyond]
    assert np.all(gap > 0.05 * np.hypot(fo_t, fo_n)[beyond])
    # the stalled plate's force is normal to it, besides the skin friction along it
    k_0 = s_fluid.k_0
    np.testing.assert_allclose(st_t[stalled], -(k_0 * np.hypot(vt, vn) * vt)[stalled],
                               rtol=1e-9, atol=1e-18)
    # at rest relative to the water: no force, no division by zero
    assert STALL.drag(s_fluid, np.zeros(1), np.zeros(1), np.zeros(1))[0][0] == 0.0


@pytest.mark.parametrize("plant", sorted(n for n, p in PLANTS.items()
                                         if p.law in (FOIL.name, STALL.name, QUARTER_CHORD.name)))
def test_the_batched_kernel_swims_the_foil_plants_as_the_reference_twin_does(plant):
    # the virtual tank records with the readable closed loop; the evaluator swims the batched
    # kernel's generated foil law: the truth must score 0 on a recording without noise
    p = PLANTS[plant]
    servo = load_robot(SERVO_ROBOT)
    clean = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0,
                         joints=p.settings.joints)
    task = load_scenario(FAST_GAIT).model_copy(update={"waypoints_m": [(0.3, 0.0)]})
    truth = p.truths()["straight"]
    exp = record_experiment(servo, task, "straight", truth, clean, seed=1)
    model = FittedModel.of_coefficients(truth, servo)
    ev = Evaluator(servo, [exp], backend="batch", space=model.space)
    assert ev.errors(model.values[None])[0, 0] < 1e-9


def test_the_pitching_foil_swims_in_a_plant_only_law_on_the_foil_plants_joints():
    assert QUARTER_CHORD.name not in candidate_laws()
    pitching = PLANTS["pitching_foil"]
    assert pitching.law == QUARTER_CHORD.name
    assert pitching.settings == PLANTS["foil_lift"].settings
    truth = pitching.truths()["turning"]
    assert truth.C_a == TABLE3["turning"].C_a and truth.C_L > 0


def _quarter_chord_by_hand(c, half_length, half_vertical, half_horizontal, rho, vt, vn, om):
    """The quarter_chord law written from docs/estimation.md, in angle form, as a force on a point.

    The drag along -w at the centre; the lift of a flat plate in the flow seen at the
    three-quarter-chord point, across that flow, applied at the quarter-chord point.
    Returns the force (t, n), the torque about the centre and the lift's force and point.
    """
    q = rho / 2.0
    wetted = np.pi * (half_vertical + half_horizontal) * half_length
    lateral = 4.0 * half_vertical * half_length
    speed = np.hypot(vt, vn)
    drag = q * speed**2 * (wetted * c.C_D0 + lateral * c.C_D2 * (vn / speed) ** 2)
    lead = np.where(vt >= 0, 1.0, -1.0)  # +1: the link's head end leads
    quarter = lead * half_length / 2.0  # the quarter chord's place along t from the centre
    vn3 = vn - quarter * om  # the point a quarter chord behind the centre
    speed3 = np.hypot(vt, vn3)
    ut, un = vt / speed3, vn3 / speed3
    lift = q * speed3**2 * lateral * c.C_L * np.abs(un) * np.abs(ut)
    across_t, across_n = np.sign(ut * un) * un, -np.sign(ut * un) * ut
    lift_t, lift_n = lift * across_t, lift * across_n
    force_t = -drag * vt / speed + lift_t
    force_n = -drag * vn / speed + lift_n
    torque = -rho * half_vertical * c.C_D2 * half_length**4 / 2.0 * np.abs(om) * om \
        + quarter * lift_n
    return force_t, force_n, torque, (lift_t, lift_n), quarter


def test_the_quarter_chord_law_lifts_from_the_three_quarter_chord_flow_at_the_quarter_chord():
    robot = load_robot()
    geometry = (robot.link.half_length_m, robot.link.half_axis_vertical_m,
                robot.link.half_axis_horizontal_m)
    c = QuarterChordCoefficients(C_D0=0.008, C_D2=1.0, C_L=0.73, C_a=0.6, C_m=0.01)
    fluid = QUARTER_CHORD.link_coefficients(*geometry, c.as_array(), 1000.0)
    rng = np.random.default_rng(4)
    vt, vn = rng.normal(0, 0.1, (2, 2000))
    om = rng.normal(0, 2.0, 2000)
    ft, fn, tq = QUARTER_CHORD.drag(fluid, vt, vn, om)
    want_t, want_n, want_q, (lift_t, lift_n), quarter = _quarter_chord_by_hand(
        c, *geometry, 1000.0, vt, vn, om)
    np.testing.assert_allclose(ft, want_t, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(fn, want_n, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(tq, want_q, rtol=1e-9, atol=1e-15)
    # the drag only dissipates: on the link, its power and its yaw damping's are never positive
    drag_power = (ft - lift_t) * vt + (fn - lift_n) * vn + (tq - quarter * lift_n) * om
    assert np.all(drag_power <= 1e-15)
    # the lift is across the flow at the three-quarter chord; on the link it works only through
    # the pitch rate: its power is l theta_dot f_n^L (the sign of w_t's), zero without turning
    lift_power = lift_t * vt + lift_n * vn + quarter * lift_n * om
    np.testing.assert_allclose(lift_power, 2.0 * quarter * om * lift_n, rtol=1e-9, atol=1e-18)
    assert np.any(lift_power > 1e-6)  # a pitching foil can feed its wake's thrust
    # a link that does not turn feels the foil law's forces, with the lift's moment about the
    # centre besides the yaw damping's
    foil = FoilCoefficients(**c.model_dump())
    f_fluid = FOIL.link_coefficients(*geometry, foil.as_array(), 1000.0)
    still = np.zeros_like(om)
    qt, qn, qq = QUARTER_CHORD.drag(fluid, vt, vn, still)
    fo_t, fo_n, fo_q = FOIL.drag(f_fluid, vt, vn, still)
    np.testing.assert_allclose(qt, fo_t, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(qn, fo_n, rtol=1e-12, atol=1e-18)
    _, _, _, (_, still_lift_n), _ = _quarter_chord_by_hand(c, *geometry, 1000.0, vt, vn, still)
    np.testing.assert_allclose(qq, fo_q + quarter * still_lift_n, rtol=1e-9, atol=1e-18)
    assert np.all(np.abs(qq - fo_q) > 0)  # the foil law has no such moment
    # at a small angle the pitch rate adds Sane and Dickinson's rotational lift,
    # C_rot rho U c^2 theta_dot on the span 2a, C_rot = C_L / 8, against the three-quarter flow
    u, rate = 0.1, 0.2
    _, fn_rate, _ = QUARTER_CHORD.drag(fluid, np.full(1, u), np.zeros(1), np.full(1, rate))
    chord, span = 2.0 * robot.link.half_length_m, 2.0 * robot.link.half_axis_vertical_m
    rotational = c.C_L / 8.0 * 1000.0 * u * chord**2 * rate * span
    np.testing.assert_allclose(fn_rate[0], rotational, rtol=0.01)
    # another law's link coefficients are refused by name
    with pytest.raises(TypeError, match="the quarter_chord law needs its own"):
        QUARTER_CHORD.drag(f_fluid, vt, vn, om)
    # at rest relative to the water: no force, no division by zero
    rest = QUARTER_CHORD.drag(fluid, np.zeros(1), np.zeros(1), np.zeros(1))
    assert rest[0][0] == 0.0 and rest[1][0] == 0.0 and rest[2][0] == 0.0
