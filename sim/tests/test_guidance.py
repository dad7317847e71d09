"""The guidance (eelsim.guidance.Guidance), the one wrap convention, and the batched kernel's copies.

The kernel's camera step (``_observe``: median filter, waypoint switching, arrival), ``_aim`` and
``_heading_offset`` are fed the same frames as the guidance object, lane by lane, and must give
the same filtered poses, targets, arrival times and offsets.
"""

import dataclasses
import math

import numpy as np
import pytest

from eelsim.batch import DEFAULT_LANES, BatchSpec, kernel_module, run_spec
from eelsim.batch.records import CameraState, Targets
from eelsim.camera import quantise_position
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.control import wrap_angle
from eelsim.flags import Failure
from eelsim.guidance import PURSUIT, Guidance, GuidanceLaw
from eelsim.scenario import load_scenario

EDGES = [0.0, -0.0, 1e-300, math.pi, -math.pi, np.nextafter(math.pi, 4), np.nextafter(-math.pi, -4),
         np.nextafter(-math.pi, 0), 3 * math.pi, -3 * math.pi, 2 * math.pi, -2 * math.pi, 7.5, -7.5,
         1e6, -1e6, 0.999, -1.0, 4.0, -4.0]


@pytest.fixture(scope="module")
def kernel():
    return kernel_module(6, DEFAULT_LANES, "c")


def test_wrap_lands_in_minus_pi_exclusive_to_pi_inclusive_and_keeps_inside_angles():
    angles = np.array(EDGES + list(np.random.default_rng(0).uniform(-50, 50, 200)))
    wrapped = wrap_angle(angles)
    assert np.all((wrapped > -math.pi) & (wrapped <= math.pi))
    assert np.allclose(np.cos(wrapped), np.cos(angles), atol=1e-9)
    assert np.allclose(np.sin(wrapped), np.sin(angles), atol=1e-9)
    inside = (angles > -math.pi) & (angles <= math.pi)
    assert np.array_equal(wrapped[inside], angles[inside])
    assert wrap_angle(-math.pi) == math.pi


def test_kernels_wrap_is_control_wrap_angle_to_the_bit(kernel):
    angles = EDGES + list(np.random.default_rng(1).uniform(-50, 50, 200))
    for a in angles:
        assert kernel._wrap_angle(float(a)) == wrap_angle(a), a


def test_median_filter_takes_the_middle_pose_and_unwraps_heading_across_pi():
    g = Guidance([(10.0, 0.0)], 0.15, 0.1, median_window=3)
    g.observe(0.0, 0.0, 0.0, 3.1)
    g.observe(0.1, 0.3, 0.0, -3.1)  # 0.083 rad further, across +-pi
    pose = g.observe(0.2, 0.1, 5.0, 3.12)
    assert pose[0] == 0.1 and pose[1] == 0.0
    assert pose[2] == pytest.approx(3.12)  # median of 3.1, 3.183, 3.12
    assert g.filtered_pose is pose


def test_waypoints_switch_inside_the_acceptance_circle_and_arrival_takes_the_poses_time():
    g = Guidance([(1.0, 0.0), (1.0, 1.0)], 0.15, 0.37, median_window=1)
    assert g.target_index == 0 and not g.arrived and g.arrival_time_s is None
    g.observe(1.0, 0.86, 0.0, 0.0)  # 0.14 m: inside
    assert g.target_index == 1 and np.array_equal(g.target_m, [1.0, 1.0])
    g.observe(2.0, 1.0, 0.85, 0.0)  # exactly 0.15 m: not inside
    assert g.target_index == 1
    g.observe(3.5, 1.0, 0.9, 0.0)
    assert g.arrived and g.arrival_time_s == 3.5 and g.target_m is None
    g.observe(4.0, 1.0, 1.0, 0.0)
    assert g.arrival_time_s == 3.5  # the first arrival counts


def test_offset_steers_towards_the_waypoint_and_is_clipped_only_when_asked():
    free = Guidance([(0.0, 1.0)], 0.15, 2.0, median_window=1)
    assert free.offset() == 0.0  # no pose yet: the last offset (none) holds
    free.observe(0.0, 0.0, 0.0, 0.0)
    assert free.offset() == pytest.approx(2.0 * math.pi / 2)  # waypoint to the left: positive
    clipped = Guidance([(0.0, 1.0)], 0.15, 2.0, median_window=1, offset_limit_rad=1.0)
    clipped.observe(0.0, 0.0, 0.0, 0.0)
    assert clipped.offset() == 1.0
    behind = Guidance([(-1.0, -1e-9)], 0.15, 1.0, median_window=1)
    behind.observe(0.0, 0.0, 0.0, 0.0)
    assert behind.offset() == pytest.approx(-math.pi)  # wrap keeps the error in (-pi, pi]


def test_after_the_last_waypoint_the_offset_still_aims_at_it():
    g = Guidance([(1.0, 0.0)], 0.15, 1.0, median_window=1)
    g.observe(0.0, 0.9, 0.1, 0.0)
    assert g.arrived
    assert g.offset() == pytest.approx(math.atan2(-0.1, 0.1))


@pytest.mark.parametrize("value", [[], [(0, 0)]])
def test_bad_guidance_settings_are_refused(value):
    if not value:
        with pytest.raises(ValueError, match="at least one waypoint"):
            Guidance(value, 0.15, 0.1)
        return
    with pytest.raises(ValueError, match="acceptance radius must be positive"):
        Guidance(value, 0.0, 0.1)
    with pytest.raises(ValueError, match="median window must be at least 1"):
        Guidance(value, 0.15, 0.1, median_window=0)
    with pytest.raises(ValueError, match="offset limit must be positive"):
        Guidance(value, 0.15, 0.1, offset_limit_rad=-1.0)


@pytest.mark.parametrize("window", [1, 4, 5])
def test_kernels_camera_step_and_offset_agree_with_the_guidance(kernel, window):
    # 16 lanes, each its own path towards its own waypoints, headings that cross +-pi and jump
    # by more than a radian now and then (the kernel's slow unwrap path), pixel quantisation
    lanes = DEFAULT_LANES
    rng = np.random.default_rng(window)
    pixel, radius, k_theta = 0.0038, 0.15, 0.37
    direction = rng.uniform(-math.pi, math.pi, lanes)
    ahead = np.stack([np.cos(direction), np.sin(direction)], axis=1)
    waypoints = np.stack([0.3 * ahead, 0.6 * ahead + 0.05 * rng.normal(size=(lanes, 2)),
                          0.6 * ahead], axis=1)
    counts = np.array([3, 2] * (lanes // 2), dtype=np.int64)  # a shorter list pads with its last
    waypoints[counts == 2, 2] = waypoints[counts == 2, 1]
    guides = [Guidance(waypoints[r, : counts[r]], radius, k_theta, window) for r in range(lanes)]
    targets = Targets(np.zeros(lanes, np.int64), np.full(lanes, np.nan), np.full(lanes, np.nan),
                      np.full(lanes, np.nan), np.full(lanes, radius), counts)
    camera = CameraState(np.zeros((window, 3, lanes)), np.zeros(2, np.int64), np.zeros(lanes),
                         np.zeros((3, lanes)), np.zeros(lanes), np.zeros(lanes), np.zeros(lanes))
    alive = np.ones(lanes, np.bool_)
    run_of = np.arange(lanes, dtype=np.int64)
    no_noise = np.zeros((lanes, 0))
    for r in range(lanes):
        kernel._aim(r, r, targets, waypoints)
    heading = direction + math.pi * (np.arange(lanes) % 2)  # half the lanes near +-pi
    for frame in range(240):
        t = frame / 30.0
        px = 0.09 * t * ahead[:, 0] + 0.01 * rng.normal(size=lanes)
        py = 0.09 * t * ahead[:, 1] + 0.01 * rng.normal(size=lanes)
        heading = heading + rng.normal(0, 0.05, lanes) + (1.5 if frame % 37 == 5 else 0.0)
        seen = wrap_angle(heading)  # the camera reports headings in (-pi, pi]
        kx, ky, kh = px.copy(), py.copy(), np.array(seen, dtype=float)
        kernel._observe(frame, kx, ky, kh, alive, run_of, no_noise, pixel, window, camera,
                        targets, waypoints, t)
        for r in range(lanes):
            q = quantise_position(np.array([px[r], py[r]]), pixel)
            pose = guides[r].observe(t, q[0], q[1], float(seen[r]))
            assert np.array_equal(camera.filtered[:, r], pose), (frame, r)
            assert targets.reached[r] == guides[r].target_index
            arrival = guides[r].arrival_time_s
            assert (np.isnan(targets.arrival[r]) if arrival is None
                    else targets.arrival[r] == arrival)
            if frame % 9 == 0:
                w = waypoints[r, min(targets.reached[r], counts[r] - 1)]
                offset = kernel._heading_offset(pose[0], pose[1], pose[2], w[0], w[1], k_theta)
                assert offset == guides[r].offset()
    assert sum(g.arrived for g in guides) >= lanes // 2  # the paths did reach their waypoints


# -- integral line-of-sight guidance (docs/model.md section 4) ---------------------------------

ILOS = GuidanceLaw("ilos", lookahead_m=0.4, integral_gain=0.04)


def test_ilos_steers_back_towards_the_leg_and_its_integral_grows_with_the_cross_track_error():
    # a robot 0.1 m left of the leg (0,0) -> (1,0), heading along it: it must turn right
    # (negative offset), and the integral grows along the leg's left normal
    g = Guidance([(1.0, 0.0)], 0.15, 1.0, median_window=1, law=ILOS, leg_start_m=(0.0, 0.0),
                 control_period_s=0.3)
    g.observe(0.0, 0.5, 0.1, 0.0)
    gamma = g.offset()
    assert gamma == pytest.approx(-math.atan(0.1 / 0.4))
    assert g.integral_s[0] == pytest.approx(0.0, abs=1e-15)
    assert g.integral_s[1] == pytest.approx(0.3 * 0.4 * 0.1 / (0.1**2 + 0.4**2))
    # on the leg with the integral grown, the law still steers right (the integral's doing)
    g.observe(0.1, 0.5, 0.0, 0.0)
    assert g.offset() < 0


def test_ilos_leg_is_from_the_previous_waypoint_once_one_is_reached():
    g = Guidance([(0.0, 0.0), (0.0, 1.0)], 0.15, 1.0, median_window=1, law=ILOS,
                 leg_start_m=(-1.0, 0.0))
    g.observe(0.0, 0.05, 0.0, math.pi / 2)  # inside the first circle: steering to the second
    assert g.target_index == 1
    assert np.array_equal(g.leg_start_m, (0.0, 0.0))
    # 5 cm right of the leg x = 0 going up, heading up: turn left (positive offset)
    assert g.offset() == pytest.approx(math.atan(0.05 / 0.4))


def test_a_laws_own_heading_gain_replaces_the_gaits():
    own = Guidance([(0.0, 1.0)], 0.15, 0.37, median_window=1,
                   law=GuidanceLaw("pursuit", heading_gain=1.2))
    own.observe(0.0, 0.0, 0.0, 0.0)
    assert own.offset() == pytest.approx(1.2 * math.pi / 2)


def test_ilos_aims_back_at_a_waypoint_it_passed_outside_its_circle():
    # 0.2 m beside the leg's end and 0.1 m past it: an infinite line would lead on along +x;
    # the law turns back towards the waypoint
    g = Guidance([(1.0, 0.0)], 0.15, 1.0, median_window=1, law=ILOS, leg_start_m=(0.0, 0.0))
    g.observe(0.0, 1.1, 0.2, 0.0)
    assert not g.arrived
    theta_ref = g.offset()  # k_theta 1, heading 0: the offset is the reference heading
    assert abs(theta_ref) > math.pi / 2


def test_a_law_is_refused_with_its_name_or_a_bad_look_ahead():
    with pytest.raises(ValueError, match="unknown guidance law 'los'"):
        GuidanceLaw("los")
    with pytest.raises(ValueError, match="look-ahead"):
        GuidanceLaw("ilos", lookahead_m=0.0)
    with pytest.raises(ValueError, match="integral gain"):
        GuidanceLaw("ilos", integral_gain=-1.0)
    with pytest.raises(ValueError, match="heading gain"):
        GuidanceLaw("ilos", heading_gain=0.0)


def _cross_current_run(robot, law, **kw):
    s = load_scenario("path2").model_copy(update={
        "waypoints_m": [(1.6, 0.0)], "duration_s": 30.0,
        "current_speed_m_s": 0.02, "current_direction_deg": 90.0})
    return simulate_closed_loop(robot, s, LoopOptions(guidance=law), **kw), s


@pytest.mark.slow
def test_ilos_keeps_the_body_nearer_its_leg_than_pure_pursuit_in_a_cross_current(robot):
    # the robot swims 0.086 m/s; a 0.02 m/s cross-current pushes pure pursuit off the straight
    # leg (it aims at the waypoint and drifts), ILOS learns the crab angle and holds the leg
    n = robot.n_links
    ref, _ = _cross_current_run(robot, PURSUIT)
    ilos, _ = _cross_current_run(robot, ILOS)
    assert ref.failure == Failure.NONE and ilos.failure == Failure.NONE
    off_pursuit = np.abs(ref.states[:, n + 1]).max()
    off_ilos = np.abs(ilos.states[:, n + 1]).max()
    assert off_ilos < 0.6 * off_pursuit, (off_ilos, off_pursuit)
    assert np.abs(ilos.integral_s[-1]).max() > 0  # the integral learnt something


@pytest.mark.parametrize("law", [ILOS, GuidanceLaw("ilos", 0.2, 0.03, heading_gain=1.1)],
                         ids=["gait_gain", "own_gain"])
@pytest.mark.slow
def test_batched_kernel_runs_ilos_as_the_reference_does_and_samples_its_integral(robot, law):
    ILOS = law  # noqa: N806
    ref, s = _cross_current_run(robot, ILOS)
    s2 = s.model_copy(update={"waypoints_m": [(0.5, 0.1), (1.0, -0.2), (1.6, 0.0)],
                              "current_direction_deg": 120.0})
    ref2 = simulate_closed_loop(robot, s2, LoopOptions(guidance=ILOS),
                                guidance_state=(-0.2, 0.05, 0.01, -0.03))
    spec = BatchSpec.build(robot, [s, s2], None, LoopOptions(guidance=ILOS), 0)
    spec = dataclasses.replace(spec, guidance_state=np.array([[np.nan, np.nan, 0.0, 0.0],
                                                              [-0.2, 0.05, 0.01, -0.03]]))
    k = max(len(ref.t_s), len(ref2.t_s))
    res = run_spec(spec, sample_steps=np.arange(k), threads=1)
    for run, r in enumerate((ref, ref2)):
        m = len(r.t_s)
        assert np.allclose(res.states[run, :m], r.states, rtol=0, atol=1e-9 * np.maximum(
            1.0, np.abs(r.states)).max())
        assert np.allclose(res.integral_s[run, :m], r.integral_s, rtol=0, atol=1e-12)
        if r.arrival_time_s is None:
            assert np.isnan(res.arrival_time_s[run])
        else:
            assert res.arrival_time_s[run] == pytest.approx(r.arrival_time_s, abs=1e-9)


# -- pure pursuit with the known current's feed-forward (docs/model.md section 4) --------------

def _ff(current_m_s=(0.0, 0.0), speed_m_s=0.086, **kw):
    return GuidanceLaw("pursuit_ff", **kw).with_water(current_m_s, speed_m_s)


def _bits(x: float) -> bytes:
    return np.float64(x).tobytes()


def test_feed_forward_without_current_is_pure_pursuit_to_the_bit(kernel):
    rng = np.random.default_rng(7)
    guide_pursuit = np.zeros(9)
    guide_ff = np.array([2.0, 0.4, 0.04, 0.3, 0.0, 0.0, 0.0, 0.086, 0.8])
    lane_guide = np.zeros((4, 1))
    waypoints = np.zeros((1, 1, 2))
    for k in range(300):
        x, y, wx, wy = rng.uniform(-2, 2, 4)
        heading = float(rng.choice(EDGES)) if k < len(EDGES) else float(rng.uniform(-9, 9))
        if k % 7 == 0:  # on the waypoint, and along the axes where atan2 meets its signed zeros
            wx, wy = (x, y) if k % 2 else (x, -0.0)
        pursuit = Guidance([(wx, wy)], 1e-9, 0.37, median_window=1)
        ff = Guidance([(wx, wy)], 1e-9, 0.37, median_window=1, law=_ff())
        for g in (pursuit, ff):
            g.observe(0.0, x, y, heading)
        assert _bits(ff.offset()) == _bits(pursuit.offset()), (x, y, wx, wy, heading)
        waypoints[0, 0] = (wx, wy)
        args = (x, y, heading, 0, 0, 0, waypoints, 1, 0.37)
        assert _bits(kernel._guidance_offset(*args, guide_ff, lane_guide)) == _bits(
            kernel._guidance_offset(*args, guide_pursuit, lane_guide)) == _bits(pursuit.offset())


def test_feed_forward_aims_into_the_cross_current_by_the_crab_angle():
    # leg along +x, current 0.03 m/s to the left (+y), U 0.06 m/s: head 30 degrees right so that
    # U h + c points along the leg; the along-leg part of the current changes nothing
    g = Guidance([(1.0, 0.0)], 0.15, 1.0, median_window=1,
                 law=_ff((0.02, 0.03), 0.06))
    g.observe(0.0, 0.0, 0.0, 0.0)
    theta_ref = g.offset()  # k_theta 1, heading 0
    assert theta_ref == pytest.approx(-math.asin(0.5))
    assert 0.06 * math.sin(theta_ref) + 0.03 == pytest.approx(0)  # no ground speed across the leg
    # a cross current of U would square the body to its leg: the sine is clipped at s_max
    strong = Guidance([(1.0, 0.0)], 0.15, 1.0, median_window=1, law=_ff((0.0, -0.06), 0.06))
    strong.observe(0.0, 0.0, 0.0, 0.0)
    assert strong.offset() == pytest.approx(math.asin(0.8))


def test_a_feed_forward_law_is_refused_without_its_speed_or_with_a_bad_crab_limit():
    with pytest.raises(ValueError, match="crab limit"):
        GuidanceLaw("pursuit_ff", crab_limit=1.5)
    with pytest.raises(ValueError, match="speed"):
        GuidanceLaw("pursuit_ff").with_water((0.0, 0.02), 0.0)
    unfilled = GuidanceLaw("pursuit_ff", current_m_s=(0.0, 0.02))
    assert unfilled.needs_water
    with pytest.raises(ValueError, match="speed is not given"):
        Guidance([(1.0, 0.0)], 0.15, 1.0, law=unfilled)
    assert GuidanceLaw("ilos").with_water((0.0, 0.02), 0.08) == GuidanceLaw("ilos")


@pytest.mark.slow
def test_feed_forward_keeps_the_body_nearer_its_leg_than_pure_pursuit_in_a_cross_current(robot):
    # 0.02 m/s across a 1.6 m leg (the robot swims 0.086 m/s): pure pursuit bows 0.21 m
    # downstream, the feed-forward 0.09 m (most of it the start from rest), and arrives sooner
    n = robot.n_links
    ref, _ = _cross_current_run(robot, PURSUIT)
    ff, _ = _cross_current_run(robot, _ff((0.0, 0.02)))
    assert ref.failure == Failure.NONE and ff.failure == Failure.NONE
    off_pursuit = np.abs(ref.states[:, n + 1]).max()
    off_ff = np.abs(ff.states[:, n + 1]).max()
    assert off_ff < 0.6 * off_pursuit, (off_ff, off_pursuit)
    assert ff.arrival_time_s is not None and ref.arrival_time_s is not None
    assert ff.arrival_time_s < ref.arrival_time_s


@pytest.mark.slow
def test_batched_kernel_runs_the_feed_forward_as_the_reference_does(robot):
    law = _ff((0.01, 0.03), 0.086, heading_gain=0.8)
    _, s = _cross_current_run(robot, law)
    s1 = s.model_copy(update={"current_speed_m_s": math.hypot(0.01, 0.03),
                              "current_direction_deg": math.degrees(math.atan2(0.03, 0.01))})
    s2 = s.model_copy(update={"waypoints_m": [(0.5, 0.1), (1.0, -0.2), (1.6, 0.0)],
                              "current_direction_deg": 120.0})  # a water the law is not told of
    refs = [simulate_closed_loop(robot, sc, LoopOptions(guidance=law)) for sc in (s1, s2)]
    spec = BatchSpec.build(robot, [s1, s2], None, LoopOptions(guidance=law), 0)
    k = max(len(r.t_s) for r in refs)
    res = run_spec(spec, sample_steps=np.arange(k), threads=1)
    for run, r in enumerate(refs):
        m = len(r.t_s)
        assert np.allclose(res.states[run, :m], r.states, rtol=0, atol=1e-9 * np.maximum(
            1.0, np.abs(r.states)).max())
        assert r.arrival_time_s is not None
        assert res.arrival_time_s[run] == pytest.approx(r.arrival_time_s, abs=1e-9)
