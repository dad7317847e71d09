"""The batched kernel (eelsim.batch) against the readable reference (closed_loop.simulate_closed_loop).

Agreement is asked to 1e-9 on every recorded step (relative to max(1, |x|), which only matters for
the state of a run that is blowing up), on arrival and failure times, flags, reasons and the
distance left. The tests run on one thread (threads=1) except the one that checks threads agree.
The kernel is generated for the robot's N: the comparisons run at N = 3, 6 and 8 (the paper's
robot has 6 links; the others run shorter, to keep the suite quick).
"""

import numpy as np
import pytest

from eelsim.batch import BatchSpec, Reason, block_order, run_batch, run_spec
from eelsim.camera import CameraModel
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.flags import Failure
from eelsim.robot import HydroCoefficients, Robot
from eelsim.scenario import load_scenario
from eelsim.timing import LoopTiming

TOL = 1e-9
# the generated stage compiled as C and by numba: both are tested (eelsim.batch.stage_backend)
STAGES = ["c", "numba"]
LINK_COUNTS = [3, 6, 8]


@pytest.fixture(params=LINK_COUNTS, ids=lambda n: f"N{n}")
def sized_robot(request, robot):
    """The paper's robot, and the same links in chains of 3 and 8."""
    n = request.param
    return robot if n == robot.n_links else robot.model_copy(update={"n_links": n})


def for_size(robot, scenario, short_s=3.0):
    """The scenario, cut to ``short_s`` seconds for the robots other than the paper's."""
    if robot.n_links == 6:
        return scenario
    return scenario.model_copy(update={"duration_s": min(scenario.duration_s, short_s)})


def with_joints(robot, **changes):
    return robot.model_copy(update={"joints": robot.joints.model_copy(update=changes)})


def assert_agrees(ref, res, run=0):
    """Batch run ``run`` (sampled at every step and a few beyond) equals the reference run."""
    k = len(ref.t_s)
    states = res.states[run]
    scale = np.maximum(1.0, np.abs(ref.states))
    assert np.all(np.abs(states[:k] - ref.states) <= TOL * scale)
    assert np.all(np.isnan(states[k:]))  # nothing after the run ended
    assert res.failure[run] == ref.failure
    assert res.reason(run) == ref.reason
    if ref.failure_time_s is None:
        assert np.isnan(res.failure_time_s[run])
    else:
        assert res.failure_time_s[run] == pytest.approx(ref.failure_time_s, abs=TOL)
    if ref.arrival_time_s is None:
        assert np.isnan(res.arrival_time_s[run])
    else:
        assert res.arrival_time_s[run] == pytest.approx(ref.arrival_time_s, abs=TOL)
    assert res.distance_left_m[run] == pytest.approx(ref.distance_left_m, abs=TOL)
    assert res.final_step[run] == k - 1


def compare(robot, scenario, options=None, seed=0, coefficients=None):
    ref = simulate_closed_loop(robot, scenario, options, seed=seed, coefficients=coefficients)
    res = run_batch(robot, scenario, coefficients, options, seed,
                    sample_steps=np.arange(len(ref.t_s) + 5), threads=1)
    assert_agrees(ref, res)
    return ref, res


def test_batch_agrees_with_reference_on_a_straight_grid_gait(sized_robot):
    s = load_scenario("straight_A0.61_w2.7").model_copy(update={"duration_s": 8.0})
    ref, _ = compare(sized_robot, for_size(sized_robot, s))
    assert ref.failure == Failure.TOO_SLOW  # 8 s is too short to arrive: the flag is compared too


def test_batch_agrees_with_reference_on_a_turning_gait_up_to_arrival(robot):
    ref, res = compare(robot, load_scenario("turning"))
    assert ref.failure == Failure.NONE and res.arrival_time_s[0] > 0


def test_batch_agrees_on_path2_with_current_and_waypoint_switching(robot):
    ref, res = compare(robot, load_scenario("path2"))
    assert ref.failure == Failure.NONE and res.target_index[0] == 3


def test_batch_agrees_on_close_waypoints_in_a_current_for_other_link_counts(sized_robot):
    # waypoint switching, arrival and the current's terms at every N, in a few seconds: the
    # waypoints lie just outside the acceptance circle ahead and to the side
    s = load_scenario("path2").model_copy(update={
        "waypoints_m": [(0.16, 0.0), (0.22, 0.12)], "duration_s": 3.0,
        "current_speed_m_s": 0.03, "current_direction_deg": 45.0})
    ref, res = compare(sized_robot, s)
    assert res.target_index[0] >= 1  # the first waypoint was reached


def test_batch_agrees_with_jitter_delay_heading_noise_and_seed(sized_robot):
    opts = LoopOptions(
        timing=LoopTiming(extra_delay_s=0.05, jitter_s=0.05),
        camera=CameraModel(heading_noise_rad=0.02),
    )
    s = load_scenario("turning").model_copy(update={"duration_s": 10.0})
    compare(sized_robot, for_size(sized_robot, s), opts, seed=7)


@pytest.mark.parametrize("window", [1, 4, 7])
def test_batch_agrees_with_median_windows_other_than_five(robot, window):
    # five frames take a min/max network; other windows (even ones: the mean of the middle two)
    # and the filling of any window take the rank method
    opts = LoopOptions(camera=CameraModel(median_window=window, heading_noise_rad=0.02))
    s = load_scenario("turning").model_copy(update={"duration_s": 6.0})
    compare(robot, s, opts, seed=3)


def test_batch_agrees_with_servo_limits_and_other_coefficients(sized_robot):
    s = load_scenario("straight").model_copy(update={"duration_s": 6.0})
    compare(sized_robot, for_size(sized_robot, s), LoopOptions(servo_limits=True),
            coefficients=HydroCoefficients(C_f=0.009, C_d=0.978, C_a=1.169, C_m=0.001))


def test_batch_agrees_on_links_that_differ_head_and_tail_overrides(sized_robot):
    data = sized_robot.model_dump()
    data["head"] = {"half_length_m": 0.07, "mass_kg": 0.3, "half_axis_vertical_m": 0.03}
    data["tail"] = {"half_length_m": 0.04, "mass_kg": 0.15, "yaw_inertia_kg_m2": 1e-4}
    odd = Robot.model_validate(data)
    compare(odd, for_size(odd, load_scenario("turning").model_copy(update={"duration_s": 6.0})))


def test_batch_flags_too_slow_like_the_reference(robot):
    s = load_scenario("straight").model_copy(update={"amplitude_rad": 0.05, "duration_s": 6.0})
    _, res = compare(robot, s)
    assert res.failure[0] == Failure.TOO_SLOW and res.reason_code[0] == Reason.TOO_SLOW
    assert res.penalties()[0] == pytest.approx(1e6 * res.distance_left_m[0])


def test_batch_flags_a_blow_up_from_a_huge_kd_like_the_reference(robot):
    _, res = compare(with_joints(robot, kd_nms_per_rad=1.0), load_scenario("straight"))
    assert res.failure[0] == Failure.ILL_CONDITIONED


def test_batch_flags_an_ill_conditioned_mass_matrix_like_the_reference(robot):
    # a head of almost no mass or inertia and no added mass: cond(M) about 4e12 from the start
    data = robot.model_dump()
    data["head"] = {"mass_kg": 1e-10, "yaw_inertia_kg_m2": 1e-15}
    _, res = compare(Robot.model_validate(data), load_scenario("straight"),
                     coefficients=HydroCoefficients(C_f=0.008, C_d=0.776, C_a=0.0, C_m=0.0))
    assert res.reason_code[0] == Reason.CONDITION_NUMBER


def test_batch_flags_self_collision_when_links_cross_like_the_reference(robot):
    curl = load_scenario("straight").model_copy(update={"k_theta": 6.0, "waypoints_m": [(-1, 0.1)]})
    _, res = compare(with_joints(robot, limit_rad=3.0), curl)
    assert res.reason_code[0] == Reason.LINKS_INTERSECT


def test_batch_flags_a_joint_beyond_its_limit_like_the_reference(robot):
    curl = load_scenario("straight").model_copy(update={"k_theta": 6.0, "waypoints_m": [(-1, 0.1)]})
    _, res = compare(with_joints(robot, limit_rad=0.5, reference_limit_rad=0.5), curl)
    assert res.reason_code[0] == Reason.JOINT_LIMIT


def test_mixed_batch_gives_the_same_answers_as_separate_calls(robot):
    stiff = with_joints(robot, kp_nm_per_rad=0.12)
    robots = [robot, stiff, robot, robot, stiff]
    scenarios = [
        load_scenario("straight_A0.61_w2.7"),
        load_scenario("turning"),
        load_scenario("path2"),
        load_scenario("path1").model_copy(update={"current_speed_m_s": 0.05,
                                                  "current_direction_deg": 90.0}),
        load_scenario("turning_A0.87_w2.7"),
    ]
    scenarios = [s.model_copy(update={"duration_s": 5.0}) for s in scenarios]
    coeffs = np.array([[0.008, 0.776, 0.618, 0.007], [0.009, 0.978, 1.169, 0.001],
                       [0.02, 0.5, 0.3, 0.01], [0.008, 0.776, 0.618, 0.007],
                       [0.005, 1.5, 0.9, 0.0]])
    opts = LoopOptions(timing=LoopTiming(jitter_s=0.03), stop_at_goal=False)
    seeds = [1, 2, 3, 4, 5]
    steps = [0, 100, 250, 500]
    together = run_batch(robots, scenarios, coeffs, opts, seeds, sample_steps=steps, threads=1)
    for i in range(5):
        alone = run_batch(robots[i], scenarios[i], coeffs[i], opts, seeds[i], sample_steps=steps,
                          threads=1)
        assert np.array_equal(together.states[i], alone.states[0], equal_nan=True)
        assert np.array_equal(together.final_state[i], alone.final_state[0])
        assert together.failure[i] == alone.failure[0]
    # and they really differ from one another
    assert len({together.final_state[i, 6] for i in range(5)}) == 5


def test_runs_of_different_lengths_packed_into_blocks_keep_their_own_answers(robot):
    # 20 runs of three lengths, interleaved: the kernel packs runs of equal length into the same
    # block (so that no lane idles), and every answer must still land on its own run
    base = load_scenario("turning")
    durations = [1.0, 2.5, 1.7] * 6 + [2.5, 1.0]
    scenarios = [base.model_copy(update={"duration_s": d}) for d in durations]
    coeffs = np.tile([0.009, 0.978, 1.169, 0.001], (20, 1)) * np.linspace(0.6, 1.4, 20)[:, None]
    steps = [0, 60, 120, 240]
    together = run_batch(robot, scenarios, coeffs, sample_steps=steps, threads=2)
    for i in (0, 1, 2, 7, 19):
        alone = run_batch(robot, scenarios[i], coeffs[i], sample_steps=steps, threads=1)
        assert np.array_equal(together.states[i], alone.states[0], equal_nan=True)
        assert np.array_equal(together.final_state[i], alone.final_state[0])
        assert together.final_step[i] == alone.final_step[0] == round(durations[i] / 0.01)
        assert together.failure[i] == alone.failure[0]


@pytest.mark.parametrize("after_arrival_s", [-1.0, 0.8])
@pytest.mark.slow
def test_a_minimum_duration_holds_the_stop_at_goal_like_the_reference(robot, after_arrival_s):
    # stop at the goal, but not before min_duration_s: before the arrival it changes nothing,
    # after it the run goes on (the fit's last sample time comes after some candidates arrive)
    s = load_scenario("turning")
    arrived = simulate_closed_loop(robot, s).arrival_time_s
    held = s.model_copy(update={"min_duration_s": arrived + after_arrival_s})
    ref, res = compare(robot, held)
    assert ref.failure == Failure.NONE
    assert res.arrival_time_s[0] == pytest.approx(arrived, abs=TOL)
    stop_s = ref.t_s[-1]
    if after_arrival_s < 0:
        assert stop_s == pytest.approx(arrived, abs=0.011)
    else:
        assert stop_s == pytest.approx(arrived + after_arrival_s, abs=0.011)


def test_a_run_length_hint_changes_how_blocks_are_packed_but_no_result(robot):
    base = load_scenario("straight").model_copy(update={"duration_s": 1.5})
    coeffs = np.tile([0.008, 0.776, 0.618, 0.007], (24, 1)) * np.linspace(0.5, 2.0, 24)[:, None]
    spec = BatchSpec.build(robot, base, coeffs)
    plain = run_spec(spec, sample_steps=[0, 50, 150], threads=1)
    hint = np.arange(24) * 7.0  # any guess (here: the last run longest): only the packing moves
    hinted = run_spec(spec, sample_steps=[0, 50, 150], threads=1, expected_steps=hint)
    assert not np.array_equal(block_order(spec), block_order(spec, hint))
    assert np.array_equal(plain.states, hinted.states)
    assert np.array_equal(plain.final_state, hinted.final_state)
    with pytest.raises(ValueError, match="expected_steps has shape"):
        run_spec(spec, threads=1, expected_steps=hint[:5])


def test_packing_by_expected_length_leaves_fewer_lanes_idle():
    # runs of 4 lengths, interleaved; a block of 16 lanes runs as long as its longest run
    class Spec:  # the fields block_order reads
        total_steps = np.full(64, 4000)
        goal_steps = np.zeros(64, dtype=np.int64)

    final = np.tile([1000, 4000, 2000, 3000], 16)

    def lane_steps(order):
        return sum(16 * final[order[i:i + 16]].max() for i in range(0, 64, 16))

    assert lane_steps(block_order(Spec)) == 4 * 16 * 4000  # every block as long as the longest
    assert lane_steps(block_order(Spec, final)) == final.sum()  # no lane idles


@pytest.mark.parametrize("runs", [40, 10])  # 3 blocks, more than the threads; 1 block, fewer
def test_threads_share_blocks_without_changing_any_result(robot, runs):
    spec = BatchSpec.build(robot, load_scenario("straight").model_copy(update={"duration_s": 2.0}),
                           np.tile([0.008, 0.776, 0.618, 0.007], (runs, 1)) *
                           np.linspace(0.5, 1.5, runs)[:, None])
    one = run_spec(spec, sample_steps=[0, 50, 200], threads=1)
    many = run_spec(spec, sample_steps=[0, 50, 200], threads=2)
    assert np.array_equal(one.states, many.states)  # no block left out
    assert np.array_equal(one.final_state, many.final_state)
    assert np.array_equal(one.final_step, many.final_step)


def test_memory_is_bounded_unless_the_full_history_is_asked_for(robot):
    s = load_scenario("straight").model_copy(update={"duration_s": 3.0})
    light = run_batch(robot, s, sample_times_s=[0.0, 1.5, 3.0], threads=1)
    assert light.full_states is None
    assert light.states.shape == (1, 3, 16)
    full = run_batch(robot, s, record_full=True, threads=1)
    ref = simulate_closed_loop(robot, s)
    assert full.full_states.shape == (1, 301, 16)
    assert np.allclose(full.full_states[0], ref.states, rtol=0, atol=TOL)
    assert np.array_equal(light.states[0, 1], full.full_states[0, 150])


def test_spec_with_other_coefficients_equals_building_it_with_them(robot):
    s = load_scenario("turning").model_copy(update={"duration_s": 2.0})
    base = BatchSpec.build(robot, [s, s])
    c = [[0.009, 0.978, 1.169, 0.001], [0.02, 0.5, 0.3, 0.01]]
    swapped = run_spec(base.with_coefficients(c), sample_steps=[200], threads=1)
    direct = run_batch(robot, [s, s], c, sample_steps=[200], threads=1)
    assert np.array_equal(swapped.states, direct.states)


def test_sample_times_off_the_step_grid_are_refused_clearly(robot):
    with pytest.raises(ValueError, match="not a whole number of physics steps"):
        run_batch(robot, load_scenario("straight"), sample_times_s=[0.005])


def test_per_run_inputs_of_different_lengths_are_refused(robot):
    s = load_scenario("straight")
    with pytest.raises(ValueError, match="different lengths"):
        BatchSpec.build(robot, [s, s, s], coefficients=np.ones((2, 4)))


def _lane_block(spec, stage, run=0):
    """A kernel module and a work/out pair holding ``spec``'s run ``run`` in every lane."""
    from eelsim.batch import DEFAULT_LANES, kernel_module

    k = kernel_module(spec.n_links, DEFAULT_LANES, stage)
    lanes = DEFAULT_LANES
    work = np.zeros((k.WORK_ROWS + k.OUT_ROWS) * lanes)  # out's rows follow work's
    out = work[k.WORK_ROWS * lanes :]
    for p in range(spec.params.shape[1]):
        work[(k.W_GEOMETRY + p) * lanes : (k.W_GEOMETRY + p + 1) * lanes] = spec.params[run, p]
    return k, work, out, lanes


def _set_rows(k, work, first_row, lanes, values):
    for row in range(values.shape[1]):
        work[(first_row + row) * lanes : (first_row + row + 1) * lanes] = values[:, row]


def _random_states(rng, n, lanes):
    return np.array([np.concatenate([rng.normal(0, 0.6, n), rng.normal(0, 1, 2),
                                     rng.normal(0, 2.0, n), rng.normal(0, 0.2, 2)])
                     for _ in range(lanes)])


@pytest.mark.parametrize(("stage", "n_links"), [("c", 3), ("c", 6), ("numba", 6), ("c", 8)])
@pytest.mark.parametrize("odd_links", [False, True])
def test_recursive_accelerations_equal_the_dense_mass_matrix_solve(robot, odd_links, stage,
                                                                   n_links):
    # the kernel's O(N) articulated-body recursion against dynamics.state_derivative (dense M,
    # Cholesky) on random states, with current and links that differ; joint torques off
    from eelsim.dynamics import state_derivative
    from eelsim.model import SwimmerModel

    robot = robot.model_copy(update={"n_links": n_links})
    if odd_links:
        data = robot.model_dump()
        data["head"] = {"half_length_m": 0.07, "mass_kg": 0.3, "half_axis_vertical_m": 0.03}
        data["tail"] = {"half_length_m": 0.04, "mass_kg": 0.15, "yaw_inertia_kg_m2": 1e-4}
        robot = Robot.model_validate(data)
    scenario = load_scenario("path2")  # has a current
    spec = BatchSpec.build(robot, scenario)
    k, work, out, lanes = _lane_block(spec, stage)
    work[k.W_KP * lanes : (k.W_KP + 1) * lanes] = 0.0
    work[k.W_KD * lanes : (k.W_KD + 1) * lanes] = 0.0
    xs = _random_states(np.random.default_rng(3), robot.n_links, lanes)
    _set_rows(k, work, k.W_Y, lanes, xs)
    k._stage(work, 0.3, 0.005, 1.0, True, False, 0.01 / 6.0, False, False, False)  # acc = f(y)
    model = SwimmerModel.from_robot(robot)
    for r in range(lanes):
        ref = state_derivative(model, xs[r], np.zeros(robot.n_links - 1), scenario.current_m_s)
        got = work[k.W_ACC * lanes + r : (k.W_ACC + xs.shape[1]) * lanes : lanes]
        assert np.allclose(got, ref, rtol=1e-11, atol=1e-11)
    assert np.all(out[k.O_BAD_PIVOT * lanes : (k.O_BAD_PIVOT + 1) * lanes] == 0.0)


@pytest.mark.parametrize("stage", STAGES)
def test_vectorised_condition_bound_brackets_numpys_condition_number(robot, stage):
    # trace(M) trace(M^-1) is >= cond(M) and <= (N + 2)^2 cond(M): the kernel only trusts it to
    # clear a state far below the threshold
    from eelsim.dynamics import mass_matrix
    from eelsim.model import SwimmerModel

    spec = BatchSpec.build(robot, load_scenario("straight"))
    k, work, out, lanes = _lane_block(spec, stage)
    xs = _random_states(np.random.default_rng(5), robot.n_links, lanes)
    _set_rows(k, work, k.W_X, lanes, xs)
    _set_rows(k, work, k.W_Y, lanes, xs)
    k._stage(work, 0.0, 0.005, 1.0, True, False, 0.01 / 6.0, False, False, False)  # sin, cos
    k._cond_bound(work)
    model = SwimmerModel.from_robot(robot)
    nq = robot.n_links + 2
    for r in range(lanes):
        cond = np.linalg.cond(mass_matrix(model, xs[r]))
        bound = out[k.O_COND_BOUND * lanes + r]
        assert cond * (1 - 1e-9) <= bound <= nq**2 * cond


@pytest.mark.parametrize("stage", STAGES)
@pytest.mark.parametrize("advance", [False, True])
def test_stages_that_rotate_the_previous_angles_equal_full_sine_and_cosine(robot, advance, stage):
    # a stage gets sin/cos of its angles by angle addition from the previous stage's, and the
    # gait phase advanced by half a step (stages 2 and 4) or not (1 and 3); that must agree
    # with computing them in full
    spec = BatchSpec.build(robot, load_scenario("path2"))
    k, work, out, lanes = _lane_block(spec, stage)
    rng = np.random.default_rng(11)
    xs = _random_states(rng, robot.n_links, lanes)
    xs[:, 0] += 40.0  # far from 0: the rotation must not lose the large angle's accuracy
    _set_rows(k, work, k.W_X, lanes, xs)
    _set_rows(k, work, k.W_Y, lanes, xs)
    dt, t = 0.01, 12.34
    k._stage(work, t, 0.5 * dt, 1.0, True, False, dt / 6.0, False, False, False)  # stage 1, full
    ys = xs.copy()
    ys[:, : robot.n_links] += rng.uniform(-0.099, 0.099, (lanes, robot.n_links))
    step = 0.5 * dt if advance else 0.0
    results = []
    previous = out.copy()
    for rotate in (True, False):
        out[:] = previous
        _set_rows(k, work, k.W_Y, lanes, ys)
        work[k.W_ACC * lanes : (k.W_ACC + xs.shape[1]) * lanes] = 0.0
        k._stage(work, t + step, 0.0, 1.0, False, False, dt / 6.0, rotate, advance, False)
        results.append(work[k.W_ACC * lanes : (k.W_ACC + xs.shape[1]) * lanes].copy())
    assert np.allclose(results[0], results[1], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("stage", STAGES)
def test_a_stage_rotates_only_while_every_running_lane_moved_little(robot, stage):
    # the stage asked to rotate tests rows offset and live itself: one running lane whose
    # angles moved ROTATE_LIMIT or more since the last stage makes it compute sin and cos in
    # full, bit for bit as if asked to; the same lane no longer running changes nothing
    spec = BatchSpec.build(robot, load_scenario("path2"))
    k, work, out, lanes = _lane_block(spec, stage)
    rng = np.random.default_rng(12)
    xs = _random_states(rng, robot.n_links, lanes)
    _set_rows(k, work, k.W_X, lanes, xs)
    _set_rows(k, work, k.W_Y, lanes, xs)
    dt, t = 0.01, 5.0
    k._stage(work, t, 0.5 * dt, 1.0, True, False, dt / 6.0, False, False, False)  # stage 1, full
    ys = xs.copy()
    ys[:, : robot.n_links] += rng.uniform(-0.05, 0.05, (lanes, robot.n_links))
    previous = out.copy()

    def stage_with(rotate, far_lane_live):
        out[:] = previous
        out[k.O_LIVE * lanes : (k.O_LIVE + 1) * lanes] = 1.0
        out[k.O_LIVE * lanes + 3] = 1.0 if far_lane_live else 0.0
        out[k.O_OFFSET * lanes : (k.O_OFFSET + 1) * lanes] = 0.05
        out[k.O_OFFSET * lanes + 3] = k.ROTATE_LIMIT  # lane 3 moved the limit: too far
        _set_rows(k, work, k.W_Y, lanes, ys)
        work[k.W_ACC * lanes : (k.W_ACC + xs.shape[1]) * lanes] = 0.0
        k._stage(work, t, 0.0, 1.0, False, False, dt / 6.0, rotate, False, False)
        return np.concatenate([work[k.W_ACC * lanes : (k.W_ACC + xs.shape[1]) * lanes],
                               out[k.O_SIN * lanes : (k.O_COS + robot.n_links) * lanes]])

    full = stage_with(False, True)
    assert np.array_equal(stage_with(True, True), full)  # a running lane too far: in full
    rotated = stage_with(True, False)  # that lane stopped: the others rotate
    assert not np.array_equal(rotated, full)
    assert np.allclose(rotated, full, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("stage", STAGES)
def test_the_last_stage_keeps_only_running_lanes_with_a_finite_new_state_and_positive_pivots(
        robot, stage):
    # the last stage writes row keep (1.0: the lane commits its new state) and the block's
    # verdict (cell 0: a running lane failed; cell 1: some lane does not commit), which the
    # driver reads instead of counting over its lanes: written out here independently
    spec = BatchSpec.build(robot, load_scenario("path2"))
    k, work, out, lanes = _lane_block(spec, stage)
    xs = _random_states(np.random.default_rng(5), robot.n_links, lanes)
    _set_rows(k, work, k.W_X, lanes, xs)
    dt = 0.01

    def last_stage(live, bad_pivot_lane=None, nan_lane=None):
        ys = xs.copy()
        if nan_lane is not None:
            ys[nan_lane, robot.n_links + 2] = np.nan
        _set_rows(k, work, k.W_Y, lanes, ys)
        out[k.O_LIVE * lanes : (k.O_LIVE + 1) * lanes] = live
        out[k.O_BAD_PIVOT * lanes : (k.O_BAD_PIVOT + 1) * lanes] = 0.0
        if bad_pivot_lane is not None:
            out[k.O_BAD_PIVOT * lanes + bad_pivot_lane] = 1.0
        k._stage(work, 1.0, 0.0, 1.0, False, True, dt / 6.0, False, False, False)
        xn = np.array([work[(k.W_XN + row) * lanes : (k.W_XN + row + 1) * lanes]
                       for row in range(xs.shape[1])]).T
        finite = np.isfinite(xn).all(axis=1)
        pivots = out[k.O_BAD_PIVOT * lanes : (k.O_BAD_PIVOT + 1) * lanes] == 0.0
        expected = (live != 0.0) & finite & pivots
        keep = out[k.O_KEEP * lanes : (k.O_KEEP + 1) * lanes]
        verdict = out[k.O_STEP_VERDICT * lanes : k.O_STEP_VERDICT * lanes + 2]
        assert np.array_equal(keep, expected.astype(float))
        assert verdict[0] == float(((live != 0.0) & ~expected).any())
        assert verdict[1] == float(not expected.all())
        return keep, verdict

    live = np.ones(lanes)
    keep, verdict = last_stage(live)
    assert keep.all() and verdict.tolist() == [0.0, 0.0]
    keep, verdict = last_stage(live, bad_pivot_lane=2, nan_lane=5)
    assert np.flatnonzero(keep == 0.0).tolist() == [2, 5] and verdict.tolist() == [1.0, 1.0]
    stopped = live.copy()
    stopped[[2, 5, 9]] = 0.0  # lanes that stopped earlier fail nothing, but do not commit
    keep, verdict = last_stage(stopped, bad_pivot_lane=2, nan_lane=5)
    assert np.flatnonzero(keep == 0.0).tolist() == [2, 5, 9] and verdict.tolist() == [0.0, 1.0]


def test_a_block_size_that_is_not_whole_vectors_is_refused(robot):
    with pytest.raises(ValueError, match="multiple of 4"):
        run_batch(robot, load_scenario("straight"), lanes=10)


@pytest.mark.parametrize("stage", STAGES)
def test_the_plain_sweep_equals_the_general_one_without_current_or_servo_line(robot, stage):
    # blocks with no current and no servo line take a backward sweep without those terms; the
    # general sweep adds exact zeros and clamps at infinity there, so the two agree bit for bit
    spec = BatchSpec.build(robot, load_scenario("straight"))
    k, work, out, lanes = _lane_block(spec, stage)
    xs = _random_states(np.random.default_rng(8), robot.n_links, lanes)
    results = []
    for plain in (True, False):
        _set_rows(k, work, k.W_Y, lanes, xs)
        k._stage(work, 0.7, 0.005, 1.0, True, False, 0.01 / 6.0, False, False, plain)
        results.append(work[k.W_ACC * lanes : (k.W_ACC + xs.shape[1]) * lanes].copy())
    assert np.array_equal(results[0], results[1])
    assert np.all(np.isfinite(results[0]))


def test_runs_with_a_current_or_a_servo_line_are_not_plain(robot):
    from eelsim.batch import plain_runs

    still = load_scenario("straight")
    spec = BatchSpec.build(robot, [still, load_scenario("path2")])  # path2 has a current
    assert plain_runs(spec).tolist() == [True, False]
    servo = BatchSpec.build(robot, still, options=LoopOptions(servo_limits=True))
    assert plain_runs(servo).tolist() == [False]


def test_the_kernels_segment_test_is_flags_segments_intersect():
    # the kernel's scalar copy of flags.segments_intersect, on a coarse grid where touching,
    # collinear and degenerate (zero-length) segments are common
    from eelsim.batch import DEFAULT_LANES, kernel_module
    from eelsim.flags import segments_intersect

    k = kernel_module(6, DEFAULT_LANES, "c")
    rng = np.random.default_rng(4)
    answers = set()
    for p1, p2, q1, q2 in rng.integers(0, 4, (3000, 4, 2)).astype(float):
        expect = segments_intersect(p1, p2, q1, q2)
        assert k._segments_intersect(*p1, *p2, *q1, *q2) == expect, (p1, p2, q1, q2)
        answers.add(expect)
    assert answers == {True, False}


def test_driver_helpers_without_reference_counts_never_hand_back_an_array():
    # kernel_template compiles the driver's helpers that allocate nothing without numba's
    # reference counting (_NO_REFCOUNT). Such a function must not return an array: its caller
    # drops a reference to what it gets back, which without the count taken in the callee frees
    # the array under its owner (heap corruption, seen once with _gather returning its argument).
    # The rule is checked on the template's text: no return of a parameter the function indexes.
    import ast
    import inspect

    from eelsim.batch import kernel_template

    tree = ast.parse(inspect.getsource(kernel_template))
    checked = []
    for node in tree.body:
        if not isinstance(node, ast.FunctionDef):
            continue
        no_counts = any(isinstance(d, ast.Call) and any(
            isinstance(k.value, ast.Name) and k.value.id == "_NO_REFCOUNT" for k in d.keywords)
            for d in node.decorator_list)
        if not no_counts:
            continue
        params = {a.arg for a in node.args.args}
        indexed = {n.value.id for n in ast.walk(node)
                   if isinstance(n, ast.Subscript) and isinstance(n.value, ast.Name)}
        for ret in (n for n in ast.walk(node) if isinstance(n, ast.Return) and n.value):
            assert not (isinstance(ret.value, ast.Name) and ret.value.id in params & indexed), (
                f"{node.name} returns its array argument {ret.value.id} without counting it")
            assert not isinstance(ret.value, (ast.Subscript, ast.Attribute)) or not (
                params & {n.id for n in ast.walk(ret.value) if isinstance(n, ast.Name)}), (
                f"{node.name} returns a view of an argument without counting it")
        checked.append(node.name)
    assert "_observe" in checked and "_gather" not in checked
