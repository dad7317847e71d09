"""The camera as a recording declares it: a centred median filter, truncated at the ends."""

import dataclasses
import warnings

import numpy as np
import pytest

from eelsim.camera import CameraModel, observation_steps, observed_positions
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario


@pytest.fixture(scope="module")
def run():
    scenario = load_scenario("turning").model_copy(update={"duration_s": 3.0})
    return simulate_closed_loop(load_robot(), scenario, LoopOptions(stop_at_goal=False))


def _raw_frames(run, frames, camera):
    """Each frame's pixel-rounded position, unfiltered (a window of one frame)."""
    one = dataclasses.replace(camera, median_window=1, median="causal")
    steps = observation_steps(frames, one, 0.01)
    return observed_positions(frames, steps, run.states[steps, 6:8], run.states[steps, -2:],
                              one, 0.01)


@pytest.mark.parametrize("window", [5, 4, 1])
def test_centred_median_is_the_median_of_the_frames_around_each_frame_cut_at_the_ends(
    run, window
):
    camera = CameraModel(median_window=window, median="centred")
    frames = np.arange(0, 80) / camera.fps
    last = frames[-1]
    raw = _raw_frames(run, frames, camera)
    before, after = (window - 1) // 2, window // 2
    expected = np.array([
        np.median(raw[max(0, f - before): min(len(frames), f + after + 1)], axis=0)
        for f in range(len(frames))
    ])
    steps = observation_steps(frames, camera, 0.01, last_time_s=last)
    seen = observed_positions(frames, steps, run.states[steps, 6:8], run.states[steps, -2:],
                              camera, 0.01, last_time_s=last)
    np.testing.assert_array_equal(seen, expected)


def test_centred_median_has_no_lag_where_the_causal_one_trails(run):
    # Swimming at a steady speed the causal median of 5 frames reports where the robot was two
    # frames ago; the centred one where it is (to within a pixel).
    frames = np.arange(30, 80) / 30.0
    truth = _raw_frames(run, frames, CameraModel(pixel_m=0.0))
    gap = {}
    for median in ("causal", "centred"):
        cam = CameraModel(pixel_m=0.0, median=median)
        steps = observation_steps(frames, cam, 0.01)
        seen = observed_positions(frames, steps, run.states[steps, 6:8], run.states[steps, -2:],
                                  cam, 0.01)
        gap[median] = np.linalg.norm(seen - truth, axis=1).mean()
    assert gap["centred"] < 0.25 * gap["causal"]


def test_camera_refuses_an_unknown_median_placement():
    with pytest.raises(ValueError, match="median must be 'causal' or 'centred'"):
        CameraModel(median="ahead")


def test_a_run_that_blew_up_has_no_camera_view_and_raises_no_numpy_warning():
    # a failed candidate's states turn infinite (blow-up) or NaN (ended); the camera model must
    # report no view there (NaN) without numpy's "invalid value" warning (inf times a zero weight)
    camera = CameraModel(pixel_m=0.0)
    times = np.array([0.5, 1.0, 1.55, 2.0])
    steps = observation_steps(times, camera, 0.01, 2.0)
    for bad in (np.inf, np.nan):
        position = np.cumsum(np.full((1, steps.size, 2), 0.001), axis=1)
        velocity = np.full((1, steps.size, 2), 0.1)
        position[0, steps.size // 2:] = bad
        velocity[0, steps.size // 2:] = bad
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            seen = observed_positions(times, steps, position, velocity, camera, 0.01, 2.0)
        assert np.all(np.isfinite(seen[0, :2])) and np.all(np.isnan(seen[0, 2:]))
