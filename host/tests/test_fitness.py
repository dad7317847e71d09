import numpy as np
import pytest

from eelhost.estimation.fitness import (
    sample_times,
    sampled_velocity,
    trajectory_error,
    validation_errors,
)
from eelsim.flags import Failure, penalty


def test_fitness_matches_a_hand_computed_example():
    t = np.array([0.0, 1.0, 2.0])
    exp = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])  # 1 m/s along x
    sim = np.array([[0.0, 0.0], [1.0, 0.3], [2.0, 0.4]])
    # positions: |0| + 0.3 + 0.4 = 0.7
    # sim velocities (np.gradient): [(0,0.3), (0,0.2), (0,0.1)] + the common (1,0): differences 0.3, 0.2, 0.1
    assert trajectory_error(t, exp, sim, weight=5.0) == pytest.approx(0.7 + 5 * 0.6)


def test_velocity_comes_from_the_sampled_positions():
    t = np.linspace(0, 6, 7)
    p = np.column_stack([0.1 * t, 0.02 * t**2])
    v = sampled_velocity(t, p)
    assert np.allclose(v[:, 0], 0.1)
    assert np.allclose(v[1:-1, 1], 0.04 * t[1:-1])  # central differences are exact for quadratics


def test_trajectory_error_is_zero_for_identical_trajectories_and_vectorises_over_candidates():
    t = np.linspace(0, 10, 7)
    exp = np.column_stack([0.05 * t, np.sin(t)])
    sims = np.stack([exp, exp + [0.01, 0.0]])
    err = trajectory_error(t, exp, sims)
    assert err[0] == 0 and err[1] == pytest.approx(7 * 0.01)


def test_sample_times_are_on_the_physics_grid_inside_the_span_and_not_negative():
    t = sample_times(-0.083, 21.437, 7)
    assert t[0] == 0.0 and t[-1] == pytest.approx(21.43)
    assert np.allclose(np.round(t / 0.01) * 0.01, t) and np.all(np.diff(t) > 0)


def test_penalties_rank_ill_conditioned_above_self_collision_above_too_slow():
    slow = penalty(Failure.TOO_SLOW, distance_left_m=5.0)
    assert penalty(Failure.ILL_CONDITIONED) > penalty(Failure.SELF_COLLISION) > slow > 1e5
    assert penalty(Failure.TOO_SLOW, 0.2) < penalty(Failure.TOO_SLOW, 0.5)  # slow ones stay ranked
    assert penalty(Failure.NONE) == 0


def test_validation_errors_report_the_papers_mean_and_true_rms_in_body_lengths():
    t = np.linspace(0, 10, 35)
    exp = np.column_stack([0.05 * t, np.zeros_like(t)])
    off = np.where(np.arange(35) % 2 == 0, 0.064, 0.0)  # alternate 0.1 BL and 0 offsets in y
    sim = exp + np.column_stack([np.zeros_like(t), off])
    e = validation_errors(t, exp, sim, body_length_m=0.64)
    assert e["Ex_mean_BL"] == pytest.approx(0.1 * 18 / 35)
    assert e["Ex_rms_BL"] == pytest.approx(np.sqrt(0.01 * 18 / 35))
    assert e["Ex_rms_BL"] > e["Ex_mean_BL"]


def test_failures_after_arrival_and_after_the_recording_do_not_count():
    from types import SimpleNamespace

    from eelhost.estimation.runs import Simulated

    prepared = [SimpleNamespace(times_s=np.array([0.0, 10.0]))]
    nan = np.nan
    sim = Simulated(
        positions_m=np.zeros((4, 1, 2, 2)),
        heading_rad=np.zeros((4, 1, 2)),
        failure=np.array([[3], [3], [3], [1]]),
        distance_left_m=np.zeros((4, 1)),
        # arrived at 8 s and collided at 12 s | collided at 9 s, inside the data |
        # collided at 12 s without arriving | too slow
        arrival_time_s=np.array([[8.0], [8.0], [nan], [nan]]),
        failure_time_s=np.array([[12.0], [9.0], [12.0], [15.0]]),
        steps=np.full((4, 1), 1500),
    )
    assert sim.counted_failure(prepared)[:, 0].tolist() == [0, 3, 3, 1]
