"""The live view's predicted path: the batched kernel's swim, checked against the reference loop."""

from __future__ import annotations

import numpy as np

from eelhost.field.runloop import FrameReport, RunConfig
from eelhost.vision.localise import Localiser
from eelhost.vision.synthetic import SyntheticCamera
from eelhost.web.liveview import PREDICTION_SAMPLE_S, LiveView
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.guidance import PURSUIT, GuidanceLaw
from eelsim.robot import SERVO_ROBOT, load_robot
from eelsim.scenario import load_scenario

ROBOT = load_robot()
PATH1 = load_scenario("path1")


def _reference_path(view: LiveView, pose, target_index: int, waypoints, robot=ROBOT,
                    current=(0.0, 0.0), law=PURSUIT) -> np.ndarray:
    """The reference closed loop (eelsim.closed_loop) swum from ``pose`` as the view asks."""
    g = view.config.gait
    scenario = PATH1.model_copy(update={
        "current_speed_m_s": current[0], "current_direction_deg": current[1],
        "name": "reference", "amplitude_rad": g.amplitude_rad, "omega_rad_s": g.omega_rad_s,
        "beta_rad": g.beta_rad, "k_theta": g.k_theta, "waypoints_m": waypoints[target_index:],
        "acceptance_radius_m": view.config.acceptance_radius_m, "duration_s": view.horizon_s,
        "start_position_m": (pose[0], pose[1]), "start_heading_deg": np.degrees(pose[2])})
    run = simulate_closed_loop(robot, scenario, LoopOptions(stop_at_goal=True, guidance=law))
    every = round(PREDICTION_SAMPLE_S / (run.t_s[1] - run.t_s[0]))
    n = robot.n_links
    return run.states[::every, n:n + 2]


def test_the_views_prediction_is_the_reference_loops_path_and_ends_at_the_goal():
    waypoints = [(0.9, 0.3), (1.6, 0.9)]
    view = LiveView(SyntheticCamera(ROBOT).calibration(), ROBOT,
                    RunConfig(PATH1.gait, waypoints), horizon_s=8.0, predict_every_s=60.0)
    try:
        for pose, index in (((0.2, 0.1, 0.3), 0), ((1.3, 0.65, 0.7), 1)):
            predicted = view.predict(np.asarray(pose), index)
            expected = _reference_path(view, pose, index, waypoints)
            # two implementations of the twin's loop: the same path to rounding, point for point
            assert predicted.shape == expected.shape
            assert np.allclose(predicted, expected, rtol=0.0, atol=1e-9)
            assert np.allclose(predicted[0], pose[:2])
        # near the last waypoint the twin reaches it within the 8 s, and the path stops there
        assert len(predicted) < round(view.horizon_s / PREDICTION_SAMPLE_S)
        assert np.hypot(*(predicted[-1] - waypoints[-1])) <= view.config.acceptance_radius_m + 0.02
    finally:
        view.close()


def test_a_planned_runs_view_predicts_with_the_planners_robot_in_the_known_current():
    # eelbot run --plan --coefficients-file: the view swims the fitted model's robot (here the
    # servo-joint file) in the current the planner knows, not the robot file's in still water
    servo = load_robot(SERVO_ROBOT)
    waypoints = [(0.9, 0.3), (1.6, 0.9)]
    view = LiveView(SyntheticCamera(ROBOT).calibration(), ROBOT,
                    RunConfig(PATH1.gait, waypoints), horizon_s=4.0, predict_every_s=60.0,
                    twin=servo, current_m_s=(0.0, -0.03))
    try:
        pose = np.asarray((0.2, 0.1, 0.3))
        predicted = view.predict(pose, 0)
        expected = _reference_path(view, pose, 0, waypoints, robot=servo, current=(0.03, -90.0))
        assert np.allclose(predicted, expected, rtol=0.0, atol=1e-9)
        robot_files = _reference_path(view, pose, 0, waypoints)
        assert np.max(np.hypot(*(predicted - robot_files).T)) > 0.02  # not the robot file's
    finally:
        view.close()


def test_the_view_predicts_with_the_runs_guidance_law_not_pure_pursuit():
    # a plan found with pursuit_ff (eelbot run --plan --guidance pursuit_ff or auto): the run
    # loop steers with that law filled in with the planner's known current, and so does the view
    waypoints = [(0.9, 0.3), (1.6, 0.9)]
    law = GuidanceLaw("pursuit_ff").with_water((0.0, -0.03), 0.086)
    view = LiveView(SyntheticCamera(ROBOT).calibration(), ROBOT,
                    RunConfig(PATH1.gait, waypoints, guidance=law), horizon_s=4.0,
                    predict_every_s=60.0, current_m_s=(0.0, -0.03))
    try:
        pose = np.asarray((0.2, 0.1, 0.3))
        predicted = view.predict(pose, 0)
        expected = _reference_path(view, pose, 0, waypoints, current=(0.03, -90.0), law=law)
        assert np.allclose(predicted, expected, rtol=0.0, atol=1e-9)
        pursuit = _reference_path(view, pose, 0, waypoints, current=(0.03, -90.0))
        assert np.max(np.hypot(*(predicted - pursuit).T)) > 0.005  # not pure pursuit's path
    finally:
        view.close()


def test_the_view_draws_and_predicts_a_replans_waypoints_once_the_loop_steers_to_them():
    cam = SyntheticCamera(ROBOT)
    first, replanned = [(0.9, 0.3), (1.6, 0.9)], [(0.6, 0.8)]
    view = LiveView(cam.calibration(), ROBOT, RunConfig(PATH1.gait, first), horizon_s=3.0,
                    predict_every_s=60.0)
    try:
        frame = np.zeros((*cam.calibration().image_size_px[::-1], 3), dtype=np.uint8)
        loc = Localiser(cam.calibration(), ROBOT).localise(0.0, frame)  # nothing seen
        pose = np.asarray((0.2, 0.1, 0.3))
        view.update(FrameReport(1.0, frame, loc, pose, 0))  # the run's own waypoints
        assert len(view.state()["waypoints"]) == 2
        view.update(FrameReport(1.1, frame, loc, pose, 0, replanned))
        drawn = view.state()["waypoints"]
        assert len(drawn) == 1
        assert np.allclose(drawn[0]["centre"], cam.calibration().to_px(np.array([[0.6, 0.8]]))[0],
                           atol=0.1)
        # the prediction heads for the replan's waypoint, not the first plan's
        assert view.waypoints_m == replanned
        predicted = view.predict(pose, 0, view.waypoints_m)
        expected = _reference_path(view, pose, 0, replanned)
        assert np.allclose(predicted, expected, rtol=0.0, atol=1e-9)
    finally:
        view.close()
