import math

import numpy as np
import pytest

from eelsim.camera import CameraModel, MedianFilter, hermite, quantise_position
from eelsim.closed_loop import (
    JointDrive,
    LoopOptions,
    TwinJoints,
    servo_limited,
    simulate_closed_loop,
)
from eelsim.control import heading_offset, wrap_angle
from eelsim.flags import Failure, segments_intersect
from eelsim.scenario import ScenarioError, grid_scenario, load_scenario, named_scenarios, paper_grid
from eelsim.timing import LoopTiming, TimingError


def endpoint(result, n=6):
    return result.states[-1, n : n + 2]


@pytest.mark.parametrize("motion", ["straight", "turning"])
@pytest.mark.slow
def test_robot_reaches_the_waypoint_for_every_gait_of_the_grid(robot, motion):
    # all 16 gaits in one call of the batched kernel, which test_batch.py shows agrees with
    # simulate_closed_loop to 1e-9 (flags included); one reference run cross-checks here too
    from eelsim.batch import run_batch

    grid = paper_grid(motion)
    res = run_batch(robot, grid, options=LoopOptions())
    assert [Failure(int(f)) for f in res.failure] == [Failure.NONE] * 16
    assert np.all(np.isfinite(res.arrival_time_s))
    for i, scenario in enumerate(grid):
        end = res.final_state[i][6:8]
        assert np.linalg.norm(end - scenario.waypoints_m[0]) < 0.2, scenario.name
    ref = simulate_closed_loop(robot, grid[0])
    assert ref.arrival_time_s == pytest.approx(res.arrival_time_s[0], abs=1e-9)


@pytest.mark.parametrize(
    "waypoint", [(0.0, 1.0), (0.0, -1.0), (-1.0, 0.2)], ids=["left", "right", "behind"]
)
def test_robot_turns_towards_waypoints_on_either_side_and_behind(robot, waypoint):
    # k_theta 0.25: with the turning gain 0.37 a waypoint behind asks for an offset (0.37 pi) that,
    # added to the gait, drives a joint past its limit: that is flagged, see test_joint_beyond...
    s = load_scenario("turning").model_copy(
        update={"waypoints_m": [waypoint], "duration_s": 80.0, "k_theta": 0.25}
    )
    res = simulate_closed_loop(robot, s)
    assert res.failure == Failure.NONE, res.reason
    assert np.linalg.norm(endpoint(res) - waypoint) < 0.2
    if abs(waypoint[0]) < 0.5:  # beside it: it turns to that side (behind: either way round)
        heading = res.states[:, :6].mean(axis=1)
        assert heading[res.t_s <= 6.0].mean() * math.copysign(1.0, waypoint[1]) > 0


def test_offset_is_piecewise_constant_on_the_control_period(robot):
    timing = LoopTiming(dt_s=0.01, control_period_s=0.3)
    res = simulate_closed_loop(robot, load_scenario("turning"), LoopOptions(timing=timing))
    changes = np.flatnonzero(np.diff(res.offset_rad) != 0) + 1
    assert changes.size > 5
    assert np.all(changes % 30 == 0)  # only at update steps (every 30 steps of 0.01 s)


def test_extra_delay_shifts_offset_changes_by_the_delay(robot):
    timing = LoopTiming(dt_s=0.01, control_period_s=0.3, extra_delay_s=0.05)
    res = simulate_closed_loop(robot, load_scenario("turning"), LoopOptions(timing=timing))
    changes = np.flatnonzero(np.diff(res.offset_rad) != 0) + 1
    assert changes.size > 5 and np.all(changes % 30 == 5)


@pytest.mark.slow
def test_jitter_varies_the_period_within_bounds_and_same_seed_gives_same_run(robot):
    opts = LoopOptions(timing=LoopTiming(control_period_s=0.3, jitter_s=0.05))
    s = load_scenario("turning")
    a = simulate_closed_loop(robot, s, opts, seed=3)
    b = simulate_closed_loop(robot, s, opts, seed=3)
    c = simulate_closed_loop(robot, s, opts, seed=4)
    assert np.array_equal(a.states, b.states) and np.array_equal(a.offset_rad, b.offset_rad)
    assert not np.array_equal(a.offset_rad, c.offset_rad)
    gaps = np.diff(np.flatnonzero(np.diff(a.offset_rad) != 0) + 1)
    assert gaps.min() >= 25 and gaps.max() <= 35 and np.ptp(gaps) > 0


def test_period_that_is_not_a_whole_number_of_steps_is_refused_clearly():
    with pytest.raises(
        TimingError,
        match=r"control period = 0.305 s is not a whole multiple of the physics step dt = 0.01 s",
    ):
        LoopTiming(dt_s=0.01, control_period_s=0.305)
    with pytest.raises(TimingError, match="extra delay"):
        LoopTiming(dt_s=0.01, extra_delay_s=0.015)


def test_pixel_quantisation_rounds_to_pixel_centres_within_half_a_pixel():
    rng = np.random.default_rng(0)
    p = rng.uniform(-2, 2, size=(1000, 2))
    q = quantise_position(p, 0.0038)
    assert np.abs(q - p).max() <= 0.0019 + 1e-12
    centres = q / 0.0038 - 0.5
    assert np.allclose(centres, np.round(centres))


def test_median_filter_rejects_an_outlier_and_follows_a_step():
    f = MedianFilter(5)
    out = [f.push(x, 0.0, 0.0)[0] for x in [0, 0, 0, 5.0, 0, 0, 0, 0]]
    assert max(out) == 0.0  # a single outlier never gets through
    g = MedianFilter(5)
    out = [g.push(x, 0.0, 0.0)[0] for x in [0, 0, 0, 0, 0, 1, 1, 1, 1]]
    assert out[6] == 0.0 and out[7] == 1.0  # a step passes once it fills half the window


def test_median_filter_unwraps_heading_across_pi():
    f = MedianFilter(3)
    for h in [3.1, -3.1, 3.12]:
        out = f.push(0, 0, h)
    assert abs(wrap_angle(out[2] - 3.12)) < 0.05  # not the median of raw angles (about 3.1 vs -3.1)


def test_camera_interpolation_is_exact_for_cubic_motion():
    # Hermite interpolation reproduces any cubic exactly
    f = lambda t: 0.3 * t**3 - t**2 + 0.2 * t + 1.0  # noqa: E731
    df = lambda t: 0.9 * t**2 - 2 * t + 0.2  # noqa: E731
    h = 0.01
    for s in (0.0, 0.33, 0.5, 1.0):
        assert hermite(f(1.0), df(1.0), f(1.0 + h), df(1.0 + h), h, s) == pytest.approx(
            f(1.0 + s * h), abs=1e-14
        )


def test_camera_frames_come_at_30_fps_and_controller_sees_quantised_filtered_pose(robot):
    res = simulate_closed_loop(robot, load_scenario("straight"))
    assert np.allclose(np.diff(res.camera_t_s), 1 / 30)
    q = res.camera_pose[:, :2] / 0.0038 - 0.5
    assert np.allclose(q, np.round(q))  # medians of an odd window are pixel centres


def test_heading_offset_wraps_the_error_to_the_short_way_round():
    # heading 170 deg, waypoint at -170 deg: error is +20 deg, not -340 deg
    g = heading_offset(
        (0, 0), math.radians(170), (math.cos(math.radians(-170)), math.sin(math.radians(-170))), 1.0
    )
    assert g == pytest.approx(math.radians(20))


@pytest.mark.slow
def test_current_drifts_path2_downstream_and_controller_still_reaches_every_waypoint(robot):
    with_current = load_scenario("path2")
    still = with_current.model_copy(update={"current_speed_m_s": 0.0})
    a = simulate_closed_loop(robot, with_current)
    b = simulate_closed_loop(robot, still)
    assert a.failure == Failure.NONE and b.failure == Failure.NONE
    assert (
        a.arrival_time_s > b.arrival_time_s
    )  # swimming against a current towards 180 deg is slower
    n = 6
    k = min(len(a.t_s), len(b.t_s))
    drift = a.states[:k, n] - b.states[:k, n]
    assert drift[k // 2] < 0  # pushed towards -x


def test_too_slow_flag_when_the_gait_cannot_arrive_in_time(robot):
    s = load_scenario("straight").model_copy(update={"amplitude_rad": 0.05, "duration_s": 10.0})
    res = simulate_closed_loop(robot, s)
    assert res.failure == Failure.TOO_SLOW
    assert res.distance_left_m > 1.0
    assert res.penalty == pytest.approx(1e6 * res.distance_left_m)
    assert "waypoints by T_max" in res.reason


def test_ill_conditioned_flag_when_a_stiff_gain_blows_up_rk4(robot):
    stiff = robot.model_copy(
        update={"joints": robot.joints.model_copy(update={"kd_nms_per_rad": 1.0})}
    )
    res = simulate_closed_loop(stiff, load_scenario("straight"))
    assert res.failure == Failure.ILL_CONDITIONED
    assert res.failure_time_s < 2.0
    assert res.penalty == 1e16


def test_self_collision_flag_when_the_body_curls_until_links_cross(robot):
    loose = robot.model_copy(update={"joints": robot.joints.model_copy(update={"limit_rad": 3.0})})
    s = load_scenario("straight").model_copy(update={"k_theta": 6.0, "waypoints_m": [(-1.0, 0.1)]})
    res = simulate_closed_loop(loose, s)
    assert res.failure == Failure.SELF_COLLISION
    assert "intersect" in res.reason and res.penalty == 1e14


def test_joint_beyond_its_limit_is_a_self_collision(robot):
    s = load_scenario("straight").model_copy(update={"k_theta": 6.0, "waypoints_m": [(-1.0, 0.1)]})
    tight = robot.model_copy(update={"joints": robot.joints.model_copy(update={"limit_rad": 0.5})})
    res = simulate_closed_loop(tight, s)
    assert res.failure == Failure.SELF_COLLISION and "beyond its limit" in res.reason


def test_segments_intersect_detects_crossing_touching_and_disjoint():
    a, b = np.array([0.0, 0.0]), np.array([1.0, 1.0])
    assert segments_intersect(a, b, np.array([0.0, 1.0]), np.array([1.0, 0.0]))
    assert segments_intersect(a, b, np.array([1.0, 1.0]), np.array([2.0, 0.0]))  # touching end
    assert not segments_intersect(a, b, np.array([0.0, 1.0]), np.array([0.4, 2.0]))
    assert not segments_intersect(a, b, np.array([0.0, 0.1]), np.array([1.0, 1.1]))  # parallel


def test_servo_limit_follows_the_torque_speed_line():
    u = servo_limited(np.array([5.0, 5.0, -5.0, 0.3]), np.array([0.0, 4.0, 4.0, 4.0]), 1.26, 8.0)
    assert u == pytest.approx([1.26, 0.63, -1.26, 0.3])


def test_servo_limits_option_keeps_torques_and_speeds_within_the_servo(robot):
    res = simulate_closed_loop(robot, load_scenario("straight"), LoopOptions(servo_limits=True))
    assert res.failure == Failure.NONE
    n = 6
    assert np.abs(np.diff(res.states[:, n + 2 : 2 * n + 2], axis=1)).max() < 8.0


def test_paper_scenarios_are_available_by_name():
    names = named_scenarios()
    assert len([k for k in names if k.startswith(("straight_", "turning_"))]) == 32
    assert names["path2"].current_m_s[0] == pytest.approx(-0.03)
    assert grid_scenario("turning", 0.61, 2.7).waypoints_m[0] == pytest.approx(
        (1.4 * math.cos(math.radians(30)), 1.4 * math.sin(math.radians(30)))
    )


def test_unknown_scenario_and_bad_scenario_file_are_refused_clearly(tmp_path):
    with pytest.raises(ScenarioError, match="unknown scenario 'strait'"):
        load_scenario("strait")
    bad = tmp_path / "task.toml"
    bad.write_text(
        "amplitude_rad = 0.8\nomega_rad_s = 3.0\nk_theta = 0.1\nwaypoints_m = [[1, 0]]\nspeed = 3\n"
    )
    with pytest.raises(ScenarioError, match=r"task.toml: invalid scenario:\n  speed: unknown key"):
        load_scenario(bad)


def test_camera_model_rejects_nonsense():
    with pytest.raises(ValueError, match="median window"):
        CameraModel(median_window=0)


class _RecordingJoints:
    """The twin's joints, keeping every offset command and optionally holding the torques."""

    def __init__(self, robot, scenario, hold=False):
        self.twin = TwinJoints(robot, scenario.gait, robot.n_links)
        self.hold = hold
        self.commands = []

    def on_step(self, step, t_s, state, offset_command):
        if offset_command is not None:
            self.commands.append((step, offset_command))
        drive = self.twin.on_step(step, t_s, state, offset_command)
        if self.hold:  # a controller ticked once per step: the law at the step's start, held
            return JointDrive(drive.torque_nm(t_s, state), drive.alpha_rad, drive.offset_rad)
        return drive


def test_a_joint_controller_gets_each_offset_after_the_delay_and_the_default_is_unchanged(robot):
    scenario = load_scenario("turning").model_copy(update={"duration_s": 4.0})
    options = LoopOptions(timing=LoopTiming(control_period_s=0.3, extra_delay_s=0.05))
    twin = simulate_closed_loop(robot, scenario, options, seed=3)
    joints = _RecordingJoints(robot, scenario)
    same = simulate_closed_loop(robot, scenario, options, seed=3, joints=joints)
    np.testing.assert_array_equal(same.states, twin.states)  # bit for bit
    np.testing.assert_array_equal(same.camera_pose, twin.camera_pose)
    steps = [k for k, _ in joints.commands]
    assert steps == list(range(5, len(twin.t_s), 30))  # every update (30 steps) plus 5
    recorded = twin.offset_rad[steps]
    np.testing.assert_array_equal(recorded, [g for _, g in joints.commands])


def test_held_torques_drive_the_plant_and_swim_close_to_the_twin(robot):
    scenario = load_scenario("straight").model_copy(update={"duration_s": 4.0})
    options = LoopOptions(stop_at_goal=False)
    twin = simulate_closed_loop(robot, scenario, options)
    held = simulate_closed_loop(
        robot, scenario, options, joints=_RecordingJoints(robot, scenario, hold=True)
    )
    assert held.failure == twin.failure and len(held.t_s) == len(twin.t_s)
    # Same references until the poses, and so the offsets, part (the first control period).
    np.testing.assert_array_equal(held.alpha_rad[:30], twin.alpha_rad[:30])
    gap = np.linalg.norm(held.states[:, 6:8] - twin.states[:, 6:8], axis=1)
    assert 0.0 < gap.max() < 0.01  # the hold changes the swim, a little (cf. hil_tests)


def test_camera_observation_from_states_reproduces_the_closed_loops_camera(robot):
    from eelsim.camera import observation_steps, observed_positions

    res = simulate_closed_loop(robot, load_scenario("turning"))
    frames = res.camera_t_s[res.camera_t_s <= res.t_s[-1] - 0.05]
    steps = observation_steps(frames, CameraModel(), 0.01)
    seen = observed_positions(
        frames, steps, res.states[steps, 6:8], res.states[steps, -2:], CameraModel(), 0.01
    )
    assert np.array_equal(seen, res.camera_pose[: len(frames), :2])


def test_camera_observation_of_several_runs_at_once_matches_each_runs_camera(robot):
    from eelsim.camera import observation_steps, observed_positions

    runs = [
        simulate_closed_loop(robot, load_scenario(name).model_copy(update={"duration_s": 2.0}),
                             LoopOptions(stop_at_goal=False))
        for name in ("turning", "straight")
    ]
    frames = runs[0].camera_t_s[runs[0].camera_t_s <= 1.9]
    queries = np.concatenate([frames, frames[3:-1] + 0.01])  # on frames and between them
    steps = observation_steps(queries, CameraModel(), 0.01)
    states = np.stack([r.states[steps] for r in runs])
    seen = observed_positions(
        queries, steps, states[..., 6:8], states[..., -2:], CameraModel(), 0.01
    )
    assert seen.shape == (2, queries.size, 2)
    for k, run in enumerate(runs):
        pose = run.camera_pose[: len(frames), :2]
        assert np.array_equal(seen[k, : len(frames)], pose)
        # between frames: the linear interpolation of the two frames' filtered positions
        s = (frames[3:-1] + 0.01) * 30.0 - np.floor((frames[3:-1] + 0.01) * 30.0 + 1e-9)
        expected = (1 - s)[:, None] * pose[3:-1] + s[:, None] * pose[4:]
        np.testing.assert_allclose(seen[k, len(frames):], expected, rtol=0, atol=1e-15)


def test_camera_observation_names_a_missing_step():
    from eelsim.camera import observed_positions

    steps = np.arange(10)  # the query at 0.2 s needs steps up to 20
    with pytest.raises(ValueError, match="state at step .* is missing"):
        observed_positions(
            np.array([0.2]), steps, np.zeros((10, 2)), np.zeros((10, 2)), CameraModel(), 0.01
        )
