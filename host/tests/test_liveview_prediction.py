"""The live view's predicted path: the batched kernel's swim, checked against the reference loop."""

from __future__ import annotations

import numpy as np

from eelhost.field.runloop import RunConfig
from eelhost.vision.synthetic import SyntheticCamera
from eelhost.web.liveview import PREDICTION_SAMPLE_S, LiveView
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

ROBOT = load_robot()
PATH1 = load_scenario("path1")


def _reference_path(view: LiveView, pose, target_index: int, waypoints) -> np.ndarray:
    """The reference closed loop (eelsim.closed_loop) swum from ``pose`` as the view asks."""
    g = view.config.gait
    scenario = PATH1.model_copy(update={
        "name": "reference", "amplitude_rad": g.amplitude_rad, "omega_rad_s": g.omega_rad_s,
        "beta_rad": g.beta_rad, "k_theta": g.k_theta, "waypoints_m": waypoints[target_index:],
        "acceptance_radius_m": view.config.acceptance_radius_m, "duration_s": view.horizon_s,
        "start_position_m": (pose[0], pose[1]), "start_heading_deg": np.degrees(pose[2])})
    run = simulate_closed_loop(ROBOT, scenario, LoopOptions(stop_at_goal=True))
    every = round(PREDICTION_SAMPLE_S / (run.t_s[1] - run.t_s[0]))
    n = ROBOT.n_links
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
