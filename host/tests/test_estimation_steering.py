"""The check of held-out steering beyond the training experiments' (estimation/steering.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from eelhost.data.experiments import Dataset, Experiment
from eelhost.estimation.steering import BEYOND, commanded_offsets, steering_check
from eelsim.camera import MedianFilter, causal_median
from eelsim.control import wrap_angle
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

K_THETA = load_scenario("path1").k_theta


def _still(name: str, waypoints, heading: bool = True, motion: str = "turning") -> Experiment:
    """A robot held at the origin facing +x for 2 s, aiming at ``waypoints``."""
    scenario = load_scenario("path1").model_copy(update={"waypoints_m": waypoints})
    t = np.linspace(0.0, 2.0, 61)
    return Experiment(name, t, np.zeros((t.size, 2)), scenario, motion,
                      heading_rad=np.zeros(t.size) if heading else None)


def _towards(deg: float, far_m: float = 1.0) -> list[tuple[float, float]]:
    return [(far_m * math.cos(math.radians(deg)), far_m * math.sin(math.radians(deg)))]


def _dataset(train, test, paths) -> Dataset:
    return Dataset(Path("."), load_robot(), {"turning": train}, {"turning": test}, paths, {}, {})


def test_the_offset_is_the_pursuit_law_of_the_bearing_to_the_waypoint():
    gamma = commanded_offsets(_still("left", _towards(30.0)))
    assert gamma is not None
    np.testing.assert_allclose(gamma, K_THETA * math.radians(30.0), rtol=1e-12)


def test_inside_the_acceptance_circle_the_next_waypoint_is_aimed_at():
    # the first waypoint's circle holds the robot: the second (to the right) is the target
    gamma = commanded_offsets(_still("two", [(0.05, 0.0), (1.0, -1.0)]))
    assert gamma is not None
    np.testing.assert_allclose(gamma, K_THETA * math.radians(-45.0), rtol=1e-12)


def test_a_path_steering_harder_either_way_than_any_training_run_is_named():
    check = steering_check(_dataset(
        [_still("train", _towards(20.0))],
        [_still("test", _towards(22.0))],
        [_still("path_right", _towards(-45.0), motion="path")]))
    assert math.isclose(check.training_rad, K_THETA * math.radians(20.0))
    assert set(check.beyond) == {"path_right"}
    assert math.isclose(check.beyond["path_right"], 45.0 / 20.0)
    warning = check.warning()
    assert warning is not None and "path_right" in warning and "test" not in warning.split(":")[1]


def test_held_out_runs_within_the_training_steering_give_no_warning():
    check = steering_check(_dataset(
        [_still("train", _towards(20.0))], [_still("test", _towards(-20.0 * BEYOND * 0.99))], []))
    assert check.beyond == {} and check.warning() is None


def test_a_recording_without_headings_is_left_out_not_guessed():
    assert commanded_offsets(_still("no heading", _towards(30.0), heading=False)) is None
    check = steering_check(_dataset([_still("train", _towards(20.0), heading=False)],
                                    [_still("test", _towards(60.0))], []))
    assert math.isnan(check.training_rad) and check.beyond == {}


def test_the_recording_median_is_what_the_controllers_filter_gives_frame_by_frame():
    """One median for both (eelsim.camera): the vectorised form equals MedianFilter.push."""
    rng = np.random.default_rng(3)
    n = 200
    xy = np.cumsum(rng.normal(0.0, 0.01, (n, 2)), axis=0)
    xy[50] += 0.5  # an outlier the median rejects
    # a heading turning through +-pi several times, with noise
    heading = np.asarray(wrap_angle(np.linspace(2.5, 2.5 + 4.0 * math.pi, n)
                                    + rng.normal(0.0, 0.05, n)), dtype=float)
    for window in (1, 3, 5, 8):
        filt = MedianFilter(window)
        streamed = np.array([filt.push(x, y, h) for (x, y), h in zip(xy, heading, strict=True)])
        at_once = causal_median(np.column_stack([xy, heading]), window)
        assert np.allclose(at_once, streamed, rtol=0.0, atol=1e-12)
    # the heading median follows the turn, never the raw angles' jump across +-pi
    assert np.all(np.abs(np.diff(at_once[:, 2])) < 0.5)


def test_a_recording_shorter_than_the_window_takes_the_median_of_the_frames_it_has():
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.1], [5.0, 1.0, 0.2]])
    out = causal_median(poses, 5)
    assert np.allclose(out[0], poses[0])
    assert np.allclose(out[1], poses[:2].mean(axis=0))
    assert np.allclose(out[2], np.median(poses, axis=0))
