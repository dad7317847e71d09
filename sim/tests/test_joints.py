"""Joint models (eelsim.joints): the registry, each model's readable and batched forms, the servo
model's prescribed-shape dynamics and its torques, RK4's step limits, and the stiff PD loop's
convergence to exact tracking (docs/model.md section 4, "Joint models").
"""

import math

import numpy as np
import pytest
from sim_helpers import random_state

from eelsim.batch import BatchSpec, codegen, run_batch
from eelsim.closed_loop import LoopOptions, servo_limited, simulate_closed_loop
from eelsim.control import Gait, gait_reference, joint_amplitudes, joint_pd_torque
from eelsim.dynamics import (
    accelerations,
    link_positions,
    link_velocities,
    make_state,
    prescribed_shape_accelerations,
    split_state,
)
from eelsim.flags import Failure
from eelsim.fluid import GalileanCoefficients, HydroCoefficients
from eelsim.integrate import integrate_reference, integrate_rk4
from eelsim.joints import (
    JOINT_MODELS,
    PD,
    SERVO,
    get_joint_model,
    largest_stable_step,
    register_joint_model,
)
from eelsim.model import SwimmerModel
from eelsim.robot import Robot, RobotFileError, load_robot, parse_robot
from eelsim.scenario import load_scenario
from eelsim.timing import LoopTiming

FAST = Gait(0.87, 3.9)


@pytest.fixture(scope="module")
def servo_robot():
    return load_robot("servo_robot.toml")


def servo(robot, **changes):
    return robot.with_joints(robot.joints.model_copy(update=changes))


def on_the_gait(n, gait=FAST):
    """The body bent to the gait's alpha(0), with its rates: a start on the reference."""
    alpha, alpha_dot = gait_reference(0.0, gait, 0.0, n)
    theta = np.concatenate([[0.0], np.cumsum(alpha)])
    rates = np.concatenate([[0.0], np.cumsum(alpha_dot)])
    return make_state(theta, (0.0, 0.0), rates)


def gait_acceleration(n, gait=FAST):
    """Exact tracking: phi_ddot = alpha_ddot(t)."""
    amp = joint_amplitudes(gait.amplitude_rad, n)

    def law(t, _x):
        return -amp * gait.omega_rad_s**2 * np.sin(gait.omega_rad_s * t
                                                   + np.arange(n - 1) * gait.beta_rad)

    return law


def servo_following(robot, n, gait=FAST):
    """The servo law tracking the gait (no offset), as the twin's joints do."""
    spec = robot.joints

    def law(t, x):
        alpha = np.clip(gait_reference(t, gait, 0.0, n)[0], -spec.command_limit_rad,
                        spec.command_limit_rad)
        return SERVO.drive(spec, alpha, 0.0 * alpha, np.diff(x[:n]), np.diff(x[n + 2:2 * n + 2]))

    return law


# ---- the registry and the robot file


def test_the_models_are_registered_and_an_unknown_one_is_refused_naming_the_known_ones():
    assert set(JOINT_MODELS) == {"pd", "pd_limited", "servo"}
    assert get_joint_model("pd") is PD and not PD.kinematic and SERVO.kinematic
    with pytest.raises(ValueError, match="unknown joint model 'stepper'; known models: pd, pd_limited, servo"):
        get_joint_model("stepper")


def test_a_second_model_under_a_taken_name_is_refused():
    class Other(type(SERVO)):
        pass

    with pytest.raises(ValueError, match="'servo' is already registered"):
        register_joint_model(Other())


def test_the_robot_file_chooses_the_joint_model_and_validates_its_keys(servo_robot):
    assert load_robot().joint_model is PD  # no model named: the paper's PD
    assert servo_robot.joint_model is SERVO
    assert servo_robot.joints.deadband_rad == 0.003
    dumped = servo_robot.model_dump()
    assert list(dumped["joints"])[:2] == ["model", "position_gain_1_s"]
    assert Robot.model_validate(dumped) == servo_robot  # round trip keeps the model
    assert "model" not in load_robot().model_dump()["joints"]  # the default is left out
    data = servo_robot.model_dump()
    for table, wrong in [
        ({"model": "stepper", "limit_rad": 1.4}, r"joints: .*model must name a joint model "
                                                 r"\(pd, pd_limited, servo\), got 'stepper'"),
        ({"model": "servo", "limit_rad": 1.4, "kp_nm_per_rad": 1.0}, r"joints.kp_nm_per_rad: "
                                                                     r"unknown key"),
        ({"model": "servo", "limit_rad": 1.4, "motor_time_constant_s": 0.0},
         r"joints.motor_time_constant_s: Input should be greater than 0"),
        ({"model": "servo", "limit_rad": 1.4, "deadband_rad": float("nan")},
         r"joints.deadband_rad"),
    ]:
        data["joints"], data["assumptions"] = table, {}
        with pytest.raises(RobotFileError, match=wrong):
            parse_robot(data, "mine.toml")


def test_fittable_parameters_round_trip_by_name_with_bounds_that_hold_the_defaults(servo_robot):
    robot = load_robot()
    for model, spec, names in [(PD, robot.joints, ("kp_nm_per_rad", "kd_nms_per_rad")),
                               (SERVO, servo_robot.joints, ("lag_s", "motor_time_constant_s"))]:
        assert model.fit_names == names
        values = model.fit_values(spec)
        bounds = model.fit_bounds
        assert np.all((bounds[:, 0] <= values) & (values <= bounds[:, 1]))
        again = model.with_fit_values(spec, values * 1.5)
        assert np.allclose(model.fit_values(again), values * 1.5)
        assert again.limit_rad == spec.limit_rad  # the rest kept
    assert SERVO.fit_values(servo_robot.joints)[0] == pytest.approx(1 / 30.0)
    with pytest.raises(ValueError, match="lag_s must be positive"):
        SERVO.with_fit_values(servo_robot.joints, [0.0, 0.01])


# ---- readable and batched forms


def _run_joint_code(model, plain, rows, al, ald, ph, phd):
    layout = codegen.make_layout(3, 4, joints=model)
    emitter = codegen._Emitter(layout)
    codegen.emit_joint_law(emitter, plain)
    program = compile("\n".join(t.strip() for t in emitter.lines), model.name, "exec")
    work = np.zeros((layout.work_rows + layout.out_rows) * 4)
    for name, value in rows.items():
        work[layout.work[name] * 4 : layout.work[name] * 4 + 4] = value
    local = {"work": work, "r": 0, "al": al, "ald": ald, "ph": ph, "phd": phd}
    exec(program, {"np": np}, local)
    return local["jout"]


@pytest.mark.parametrize("plain", [True, False])
@pytest.mark.parametrize("deadband", [0.0, 0.05])
def test_each_models_kernel_code_computes_its_numpy_law(servo_robot, plain, deadband):
    rng = np.random.default_rng(3)
    pd_spec = load_robot().joints.model_copy(update={"kp_nm_per_rad": 0.6})
    servo_spec = servo(servo_robot, deadband_rad=deadband).joints
    for al, ald, ph, phd in rng.normal(0, [0.5, 2.0, 0.5, 9.0], (200, 4)):
        want = PD.drive(pd_spec, *(np.array([v]) for v in (al, ald, ph, phd)))
        rows = PD.kernel_values(pd_spec, servo_limits=not plain)
        if not plain:  # the loop's option: the torque-speed clip
            want = servo_limited(want, np.array([phd]), 1.26, 8.0)
        got = _run_joint_code(PD, plain, rows, al, ald, ph, phd)
        assert got == pytest.approx(want[0], rel=1e-12, abs=1e-15)
        want = SERVO.drive(servo_spec, *(np.array([v]) for v in (al, ald, ph, phd)))
        got = _run_joint_code(SERVO, plain, SERVO.kernel_values(servo_spec, False), al, ald, ph,
                              phd)
        assert got == pytest.approx(want[0], rel=1e-12, abs=1e-12)


def test_the_servo_law_has_its_rate_limit_lag_and_dead_zone(servo_robot):
    spec = servo(servo_robot, deadband_rad=0.01).joints
    zero = np.zeros(3)
    big = SERVO.drive(spec, np.array([1.0, -1.0, 0.005]), zero, zero, zero)
    # far from the reference the command is the no-load speed; inside the dead zone nothing
    assert big.tolist() == pytest.approx([8.0 / 0.008, -8.0 / 0.008, 0.0])
    at_speed = SERVO.drive(spec, np.array([1.0]), zero[:1], zero[:1], np.array([8.0]))
    assert at_speed[0] == 0.0  # at the commanded speed: no acceleration
    small = SERVO.drive(spec, np.array([0.11]), zero[:1], np.array([0.1]), zero[:1])
    assert small[0] == pytest.approx(30.0 * (0.01 - 0.01) / 0.008, abs=1e-9)


# ---- prescribed-shape dynamics


@pytest.mark.parametrize("coefficients", [None, GalileanCoefficients(
    C_f=0.008, C_d=0.776, C_a=0.618, C_m=0.007)], ids=["morison", "galilean"])
def test_the_servo_torques_drive_the_free_joints_to_the_same_accelerations(robot, coefficients):
    # two formulations: the 3 x 3 reduced system with the joint accelerations given, and the
    # full N + 2 system driven by the torques the first one says the joints give
    model = SwimmerModel.from_robot(robot, coefficients)
    rng = np.random.default_rng(9)
    for _ in range(10):
        x = random_state(rng, 6)
        phi_ddot = rng.normal(0, 20.0, 5)
        th, p, u = prescribed_shape_accelerations(model, x, phi_ddot, (0.02, -0.01))
        assert np.allclose(np.diff(th), phi_ddot, rtol=0, atol=1e-12)
        th2, p2 = accelerations(model, x, u, (0.02, -0.01))
        assert np.allclose(th2, th, rtol=1e-10, atol=1e-10)
        assert np.allclose(p2, p, rtol=1e-10, atol=1e-12)


def angular_momentum(model, x):
    theta, _, w, _ = split_state(model, x)
    X, Y = link_positions(model, x)
    vx, vy = link_velocities(model, x)
    return float(np.sum(model.mass_kg * (X * vy - Y * vx) + model.yaw_inertia_kg_m2 * w))


def test_servo_joints_out_of_water_keep_the_centre_of_mass_and_zero_angular_momentum(
        servo_robot, vacuum_model):
    # the servo's torques are internal: out of water the body wriggles (and may turn, like a
    # falling cat) but its centre of mass stays put and its angular momentum stays zero
    # (RK4 keeps the linear invariants to rounding; the angular momentum, nonlinear in the
    # angles, to the adaptive solver's accuracy)
    x0 = make_state(np.zeros(6), (0.3, -0.2))
    law = servo_following(servo_robot, 6)
    traj = integrate_rk4(vacuum_model, x0, 3.0, joint_accelerations=law)
    assert np.ptp(np.diff(traj.states[:, :6], axis=1)) > 0.5  # the joints moved
    assert np.abs(traj.states[:, 6:8] - [0.3, -0.2]).max() < 1e-12
    assert np.abs(traj.states[:, -2:]).max() < 1e-12
    ref = integrate_reference(vacuum_model, x0, 1.0, joint_accelerations=law, rtol=1e-10)
    scale = max(np.abs(vacuum_model.yaw_inertia_kg_m2 * x[8:14]).sum() for x in ref.states)
    assert max(abs(angular_momentum(vacuum_model, x)) for x in ref.states) < 1e-9 * scale


def test_a_turned_and_shifted_start_gives_the_turned_and_shifted_swim(servo_robot, model):
    # still water has no direction: the servo-driven swim from heading 40 degrees at (1, -2)
    # is the swim from heading 0 at the origin, turned and shifted
    law = servo_following(servo_robot, 6)
    a = integrate_rk4(model, make_state(np.zeros(6)), 3.0, joint_accelerations=law)
    turn = math.radians(40.0)
    b = integrate_rk4(model, make_state(np.full(6, turn), (1.0, -2.0)), 3.0,
                      joint_accelerations=law)
    rot = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    assert np.abs(b.states[:, :6] - (a.states[:, :6] + turn)).max() < 1e-12
    assert np.abs(b.states[:, 6:8] - (a.states[:, 6:8] @ rot.T + [1.0, -2.0])).max() < 1e-12
    assert np.abs(b.states[:, -2:] - a.states[:, -2:] @ rot.T).max() < 1e-12
    assert np.linalg.norm(a.states[-1, 6:8]) > 0.1  # it swam


def test_servo_swimming_in_a_current_is_still_water_plus_drift_with_the_galilean_law(
        servo_robot):
    model = SwimmerModel.from_robot(servo_robot, GalileanCoefficients(
        C_f=0.008, C_d=0.776, C_a=0.618, C_m=0.007))
    law = servo_following(servo_robot, 6)
    vc = np.array([0.0, 0.03])
    still = integrate_rk4(model, make_state(np.zeros(6)), 5.0, joint_accelerations=law)
    moving = integrate_rk4(model, make_state(np.zeros(6), velocity_m_s=vc), 5.0,
                           joint_accelerations=law, current_m_s=vc)
    drift = still.states.copy()
    drift[:, 6:8] += np.outer(still.t_s, vc)
    drift[:, -2:] += vc
    assert np.abs(moving.states - drift).max() < 1e-12


@pytest.mark.slow
def test_stiff_pd_joints_converge_to_exact_tracking_as_the_gains_grow(robot, model):
    # the prescribed-shape swimmer with phi = alpha(t) exactly is the limit of the PD loop as
    # k_p grows (k_d near critical for the median joint mode), started on the reference;
    # adaptive solvers (DOP853; Radau for the stiff PD), 4 s of the fastest gait. The centre
    # of mass differs by about 1/k_p (docs/model.md section 4, table there)
    n = 6
    x0 = on_the_gait(n)
    exact = integrate_reference(model, x0, 4.0, joint_accelerations=gait_acceleration(n),
                                t_eval=[4.0])
    inertia = 1.0 / np.median(_joint_mode_rates(model))
    gaps = []
    for kp in (2.0, 8.0, 32.0):
        kd = 2.0 * math.sqrt(kp * inertia)

        def u(t, x, kp=kp, kd=kd):
            alpha, alpha_dot = gait_reference(t, FAST, 0.0, n)
            return joint_pd_torque(alpha, alpha_dot, np.diff(x[:n]), np.diff(x[n + 2:2 * n + 2]),
                                   kp, kd)

        with np.errstate(over="ignore"):  # scipy's numerical Jacobian probes wide steps
            pd = integrate_reference(model, x0, 4.0, torques=u, t_eval=[4.0], method="Radau",
                                     rtol=1e-8, atol=1e-10)
        gaps.append(np.linalg.norm(pd.states[-1, n:n + 2] - exact.states[-1, n:n + 2]))
    assert np.linalg.norm(exact.states[-1, n:n + 2]) > 0.3  # it swam
    assert gaps[0] > gaps[1] > gaps[2]
    assert all(a / b > 2.5 for a, b in zip(gaps, gaps[1:], strict=False))  # about 4 per 4 x k_p
    assert gaps[2] < 2e-3


def _joint_mode_rates(model):
    from eelsim.dynamics import mass_matrix, straight_state

    big_m = mass_matrix(model, straight_state(model))
    d = np.diff(np.eye(model.n_links), axis=0)
    stiff = np.zeros_like(big_m)
    stiff[:6, :6] = d.T @ d
    inv = np.linalg.inv(np.linalg.cholesky(big_m))
    mu = np.linalg.eigvalsh(inv @ stiff @ inv.T)
    return mu[mu > 1e-9 * mu.max()]


# ---- RK4's step


def test_rk4_stability_limits_are_those_of_its_region():
    assert largest_stable_step([-1.0]) == pytest.approx(2.785293563, rel=1e-8)
    assert largest_stable_step([2j, -2j]) == pytest.approx(2.0 * math.sqrt(2) / 2, rel=1e-8)
    assert largest_stable_step([0.0]) == math.inf


def test_a_servo_too_fast_for_the_step_is_refused_naming_the_largest_stable_step(servo_robot):
    fast = servo(servo_robot, motor_time_constant_s=0.001)  # roots -1000 and -31 1/s
    stable = SERVO.largest_stable_step_s(fast.joints, SwimmerModel.from_robot(fast))
    assert stable == pytest.approx(2.785293563 / 968.5, rel=2e-3)
    s = load_scenario("straight").model_copy(update={"duration_s": 0.3})
    message = (r"motor_time_constant_s = 0.001 s: explicit RK4 at dt = 0.01 s is unstable on the "
               r"servo law; the largest stable step is 0.00287 s. Use dt = 1/360 s")
    with pytest.raises(ValueError, match=message):
        simulate_closed_loop(fast, s)
    with pytest.raises(ValueError, match=message):
        BatchSpec.build(fast, s)
    # the step offered keeps the loop's timing rules and runs
    offered = LoopOptions(timing=LoopTiming(dt_s=1 / 360))
    assert offered.timing.period_steps == 108  # 0.3 s control period, 12 steps a camera frame
    ref = simulate_closed_loop(fast, s, offered)
    assert ref.failure in (Failure.NONE, Failure.TOO_SLOW)
    assert SERVO.largest_stable_step_s(servo_robot.joints, None) > 0.01  # the default is fine


def test_the_default_pd_gains_are_inside_rk4s_limit_and_stiff_ones_are_not(robot, model):
    assert PD.largest_stable_step_s(robot.joints, model) > 0.01
    stiff = robot.joints.model_copy(update={"kp_nm_per_rad": 2.0, "kd_nms_per_rad": 0.5})
    assert PD.largest_stable_step_s(stiff, model) == pytest.approx(4e-4, rel=0.2)


@pytest.mark.slow
def test_stiff_pd_joints_are_flagged_with_a_reason_that_points_to_the_servo_model(robot):
    # the stiff joints: explicit RK4 at 0.01 s blows up at once (ill-conditioned at
    # t = 0.01 s); the reason says why and what to use instead, in the reference and the batch
    stiff = robot.with_joints(robot.joints.model_copy(
        update={"kp_nm_per_rad": 2.0, "kd_nms_per_rad": 0.5}))
    s = load_scenario("straight").model_copy(update={"duration_s": 1.0})
    ref = simulate_closed_loop(stiff, s)
    assert ref.failure == Failure.ILL_CONDITIONED and ref.failure_time_s <= 0.02
    assert "too stiff for explicit RK4 at dt = 0.01 s" in ref.reason
    assert '[joints] model = "servo"' in ref.reason
    res = run_batch(stiff, s, threads=1)
    assert res.reason(0) == ref.reason
    fine = simulate_closed_loop(stiff, s, LoopOptions(timing=LoopTiming(dt_s=0.0002)))
    assert fine.failure != Failure.ILL_CONDITIONED  # a small enough step integrates it


# ---- torques and saturation in the closed loop


def test_servo_torques_are_recorded_and_saturation_is_counted_not_failed(servo_robot):
    s = load_scenario("straight").model_copy(update={"duration_s": 2.0})
    run = simulate_closed_loop(servo_robot, s)
    assert run.joint_torque_nm.shape == (len(run.t_s), 5)
    assert np.all(np.isfinite(run.joint_torque_nm))
    # from rest the servos accelerate at w_max / tau_m = 1000 rad/s^2: more than 1.26 N m
    assert run.saturated_steps > 0 and run.max_torque_ratio > 1.0
    assert run.failure == Failure.TOO_SLOW  # a warning, not a failure
    # after the start the steady gait needs far less than the stall torque
    assert np.abs(run.joint_torque_nm[50:]).max() < 0.5 * 1.26


def test_pd_torques_clipped_to_the_servo_line_never_count_as_saturated(robot):
    s = load_scenario("straight").model_copy(update={"duration_s": 2.0})
    strong = robot.with_joints(robot.joints.model_copy(update={"servo_max_torque_nm": 0.03}))
    free = simulate_closed_loop(strong, s)
    clipped = simulate_closed_loop(strong, s, LoopOptions(servo_limits=True))
    assert free.saturated_steps > 0
    assert clipped.saturated_steps == 0 and clipped.max_torque_ratio <= 1.0 + 1e-9


@pytest.mark.parametrize("n_links", [3, 6, 8])
def test_servo_batch_agrees_with_the_reference(servo_robot, n_links):
    from test_batch import assert_agrees

    # a weaker servo (it changes no motion, only what counts as saturated): some steps saturate
    robot = servo(servo_robot, servo_max_torque_nm=0.3).model_copy(update={"n_links": n_links})
    s = load_scenario("path2").model_copy(update={  # a current, waypoints switching
        "waypoints_m": [(0.16, 0.0), (0.3, 0.15)], "duration_s": 3.0 if n_links != 6 else 6.0,
        "current_speed_m_s": 0.03, "current_direction_deg": 45.0})
    still = s.model_copy(update={"current_speed_m_s": 0.0})
    for scenario in (s, still):
        ref = simulate_closed_loop(robot, scenario)
        res = run_batch(robot, scenario, sample_steps=np.arange(len(ref.t_s) + 5), threads=1)
        assert_agrees(ref, res)
        assert res.max_torque_ratio[0] == pytest.approx(ref.max_torque_ratio, rel=1e-9)
        assert res.saturated_steps[0] == ref.saturated_steps
    assert 0 < ref.saturated_steps < len(ref.t_s)


def test_a_servo_batch_of_other_coefficients_agrees_run_by_run(servo_robot):
    from test_batch import assert_agrees

    s = load_scenario("turning").model_copy(update={"duration_s": 4.0})
    coeffs = [HydroCoefficients(C_f=0.009, C_d=0.978, C_a=1.169, C_m=0.001),
              HydroCoefficients(C_f=0.02, C_d=0.5, C_a=0.3, C_m=0.01)]
    res = run_batch(servo_robot, [s, s], coeffs, sample_steps=np.arange(410), threads=1)
    for i, c in enumerate(coeffs):
        ref = simulate_closed_loop(servo_robot, s, coefficients=c)
        assert_agrees(ref, res, run=i)
        assert res.saturated_steps[i] == ref.saturated_steps


def test_servo_runs_at_a_step_that_divides_the_camera_period_and_the_batch_agrees(servo_robot):
    from test_batch import assert_agrees

    # dt = 1/120 s: four steps a camera frame (frames fall on steps), 36 a control period; the
    # batch agrees with the reference, and the swim is the one at dt = 0.01 s to RK4's accuracy
    opts = LoopOptions(timing=LoopTiming(dt_s=1 / 120))
    assert opts.timing.period_steps == 36
    s = load_scenario("turning").model_copy(update={"duration_s": 5.0})
    ref = simulate_closed_loop(servo_robot, s, opts)
    res = run_batch(servo_robot, s, None, opts, sample_steps=np.arange(len(ref.t_s) + 5),
                    threads=1)
    assert_agrees(ref, res)
    assert res.saturated_steps[0] == ref.saturated_steps > 0
    coarse = simulate_closed_loop(servo_robot, s)
    assert np.linalg.norm(ref.states[-1, 6:8] - coarse.states[-1, 6:8]) < 1e-3
    assert np.linalg.norm(ref.states[-1, 6:8] - ref.states[0, 6:8]) > 0.2  # it swam
