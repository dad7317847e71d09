"""Intervals that span the valleys the data cannot tell apart (docs/estimation.md, "Uncertainty").

The search itself (:func:`search_valleys`) is judged on a function with two valleys whose depths
are known, polished by scipy: no simulation, so the tests are fast and exact.
"""

import numpy as np
from scipy.optimize import minimize

from eelhost.estimation.uncertainty import (
    Valleys,
    bisect_targets,
    fitness_threshold,
    principal_axis,
    profile_start,
    profile_targets,
    search_valleys,
    spread_starts,
    trade_directions,
)

BOUNDS = np.array([[-2.0, 2.0], [-1.0, 1.0]])
ESTIMATE = np.array([1.0, 0.0])
HALF = np.array([0.2, 0.2])


def _two_valleys(depth_gap):
    """Fitness with minima at x = +1 (0) and x = -1 (``depth_gap``), y = 0 in both."""
    def fitness(p):
        p = np.atleast_2d(p)
        x, y = p[:, 0], p[:, 1]
        return np.minimum((x - 1) ** 2, (x + 1) ** 2 + depth_gap) + y**2

    def polish(starts):
        fits = [minimize(lambda q: float(fitness(q)[0]), s, bounds=BOUNDS, method="L-BFGS-B")
                for s in starts]
        return np.array([f.x for f in fits]), np.array([f.fun for f in fits])

    return fitness, polish


def test_a_second_valley_fitting_within_the_threshold_widens_the_interval_over_both():
    fitness, polish = _two_valleys(depth_gap=0.01)
    starts = np.array([[-1.5, 0.5], [1.5, -0.5]])
    found = search_valleys(fitness, polish, ESTIMATE, 0.0, 0.05, starts, HALF, BOUNDS)
    assert len(found.minima) == 1
    assert abs(found.minima[0, 0] + 1) < 1e-3
    lower, upper, split = found.widened(ESTIMATE, HALF, BOUNDS)
    # the other valley with the estimate's half-width around it, and the estimate's own
    assert lower[0] <= -1.2 + 1e-3 and upper[0] >= 1.2 - 1e-9
    # only the parameter the valleys differ in is said to be not identified
    assert split.tolist() == [True, False]
    assert lower[1] >= -0.2 - 1e-6 and upper[1] <= 0.2 + 1e-6


def test_a_second_valley_the_data_reject_leaves_the_interval_local():
    fitness, polish = _two_valleys(depth_gap=1.0)
    starts = np.array([[-1.5, 0.5]])
    found = search_valleys(fitness, polish, ESTIMATE, 0.0, 0.05, starts, HALF, BOUNDS)
    assert len(found.minima) == 0
    lower, upper, split = found.widened(ESTIMATE, HALF, BOUNDS)
    assert not split.any()
    np.testing.assert_allclose(lower, ESTIMATE - HALF)
    np.testing.assert_allclose(upper, ESTIMATE + HALF)


def test_points_between_that_fit_within_the_threshold_stretch_the_interval_along_a_ridge():
    # a flat ridge in x between 0 and 1: the local half-width (0.2) says less than the data
    def fitness(p):
        p = np.atleast_2d(p)
        return np.maximum(0.0, -p[:, 0]) ** 2 + np.maximum(0.0, p[:, 0] - 1) ** 2 + p[:, 1] ** 2

    def polish(starts):  # a polish that does not move: only the line's points can help
        return starts, fitness(starts)

    found = search_valleys(fitness, polish, ESTIMATE, 0.0, 0.01, np.array([[0.0, 0.0]]),
                           HALF, BOUNDS)
    lower, upper, split = found.widened(ESTIMATE, HALF, BOUNDS)
    assert lower[0] <= 0.0 + 1e-9  # the whole ridge down to x = 0 fits as well
    # the start (x = 0) is a point of the ridge, not a polished valley beyond the threshold
    assert upper[0] == ESTIMATE[0] + HALF[0]


def test_the_interval_is_cut_to_the_search_bounds():
    found = Valleys(0.1, np.array([[-1.95, 0.0]]), np.array([0.0]), np.zeros((0, 2)))
    lower, upper, split = found.widened(ESTIMATE, HALF, BOUNDS)
    assert lower[0] == BOUNDS[0, 0]
    assert split[0]


def test_the_threshold_is_the_quantile_of_what_refits_gain_with_the_noise_widened_by_the_excess():
    noise = np.array([0.01, 0.02, 0.03, 0.04, np.nan])
    misfit = np.array([-0.5, 0.01])  # a refit worse than its start gains nothing
    got = fitness_threshold(noise, misfit, excess=2.0, level=0.5)
    assert np.isclose(got, 2.0 * 0.025)
    assert np.isclose(fitness_threshold(noise, np.array([0.3]), excess=1.0, level=0.5), 0.3)
    assert fitness_threshold(np.zeros(0), np.zeros(0)) == 0.0


def test_spread_starts_lie_within_the_bounds_and_are_reproducible():
    a = spread_starts(BOUNDS, 4, seed=3)
    assert a.shape == (4, 2)
    assert np.all((a >= BOUNDS[:, 0]) & (a <= BOUNDS[:, 1]))
    np.testing.assert_array_equal(a, spread_starts(BOUNDS, 4, seed=3))
    assert spread_starts(BOUNDS, 0, seed=3).shape == (0, 2)


def test_the_principal_axis_follows_the_refits_widest_spread():
    rng = np.random.default_rng(0)
    t = rng.normal(size=200)
    samples = ESTIMATE + np.column_stack([0.4 * t, -0.2 * t]) + 1e-4 * rng.normal(size=(200, 2))
    axis = principal_axis(samples, ESTIMATE, BOUNDS)
    assert axis is not None
    # the trade is x against -y; one standard deviation along it
    assert axis[0] * axis[1] < 0
    assert np.isclose(abs(axis[0]), 0.4, rtol=0.15) and np.isclose(abs(axis[1]), 0.2, rtol=0.15)
    assert principal_axis(samples[:1], ESTIMATE, BOUNDS) is None


def test_the_report_warns_about_parameters_another_valley_fits_alike():
    from eelhost.estimation.diagnostics import fit_warnings
    from eelhost.estimation.space import ParameterSpace
    from eelhost.estimation.uncertainty import BootstrapResult
    from eelsim.robot import load_robot

    space = ParameterSpace.for_robot(load_robot())
    x = space.bounds.mean(axis=1)
    k = space.size
    other = x.copy()
    other[1] *= 1.5  # C_d in another valley
    boot = BootstrapResult(space.names, x, np.tile(x, (3, 1)), np.full(3, 0.1), 0.1,
                           x - 0.01, x + 0.01)
    assert fit_warnings("turning", space, x, boot) == []
    boot.valleys = Valleys(0.02, other[None], np.array([0.105]), other[None])
    boot.split = np.arange(k) == 1
    (warning,) = fit_warnings("turning", space, x, boot)
    assert "C_d not identified" in warning and f"{other[1]:.4g}" in warning
    assert boot.to_json()["valleys"]["not_identified"] == ["C_d"]


def test_a_parameter_the_data_hardly_hold_reaches_its_bounds_when_moved_alone():
    # y hardly matters: moved alone, it fits within the threshold right to its bounds
    def fitness(p):
        p = np.atleast_2d(p)
        return (p[:, 0] - 1) ** 2 + 1e-4 * p[:, 1] ** 2

    def polish(starts):
        return starts, fitness(starts)

    none = search_valleys(fitness, polish, ESTIMATE, 0.0, 0.01, np.zeros((0, 2)), HALF, BOUNDS)
    assert none.widened(ESTIMATE, HALF, BOUNDS)[0][1] == -HALF[1]
    found = search_valleys(fitness, polish, ESTIMATE, 0.0, 0.01, np.zeros((0, 2)), HALF, BOUNDS,
                           coordinates=np.array([True, True]))
    lower, upper, split = found.widened(ESTIMATE, HALF, BOUNDS)
    np.testing.assert_allclose([lower[1], upper[1]], BOUNDS[1])
    # x is held by the data: moved alone it leaves the threshold within 0.1 of the estimate
    assert 0.8 <= lower[0] and upper[0] <= 1.2
    assert not split.any()  # points along a line are not other valleys


def test_a_parameter_held_only_together_with_another_follows_their_trade_to_its_bounds():
    # the data hold x + y (a total delay, say), hardly y itself: y moved alone leaves the
    # threshold at once, y moved with x along their trade reaches its bounds
    def fitness(p):
        p = np.atleast_2d(p)
        return 100 * (p[:, 0] + p[:, 1] - 1) ** 2 + 1e-4 * p[:, 1] ** 2

    def polish(starts):
        return starts, fitness(starts)

    t = np.linspace(-0.1, 0.1, 9)
    refits = ESTIMATE + np.column_stack([-t, t])  # the bootstrap's refits along the trade
    trade = trade_directions(refits, ESTIMATE)
    np.testing.assert_allclose(trade, [[1.0, -1.0], [-1.0, 1.0]])
    mask = np.array([False, True])
    alone = search_valleys(fitness, polish, ESTIMATE, 0.0, 0.01, np.zeros((0, 2)), HALF,
                           BOUNDS, coordinates=mask)
    assert alone.widened(ESTIMATE, HALF, BOUNDS)[1][1] == HALF[1]
    traded = search_valleys(fitness, polish, ESTIMATE, 0.0, 0.01, np.zeros((0, 2)), HALF,
                            BOUNDS, coordinates=mask, trade=trade)
    lower, upper, _ = traded.widened(ESTIMATE, HALF, BOUNDS)
    np.testing.assert_allclose([lower[1], upper[1]], BOUNDS[1])
    assert lower[0] <= 0.0 + 1e-9  # x went with it
    assert trade_directions(refits[:1], ESTIMATE) is None


def test_profile_targets_lie_past_each_interval_end_short_of_its_bound():
    lower, upper = np.array([0.8, -1.0]), np.array([1.2, 0.2])  # y's lower end is its bound
    trade = np.array([[1.0, -1.0], [-1.0, 1.0]])
    pins, starts = profile_targets(ESTIMATE, lower, upper, BOUNDS, np.array([True, True]), trade)
    assert [j for j, _ in pins] == [0, 0, 0, 0, 1, 1]
    np.testing.assert_allclose([v for _, v in pins], [-0.6, -2.0, 1.6, 2.0, 0.6, 1.0])
    # each start holds its parameter at the target, the other moved along their trade
    np.testing.assert_allclose(starts[[p[0] for p in pins].index(1) + 1], [0.0, 1.0])
    np.testing.assert_allclose(starts[2], [1.6, -0.6])
    assert np.all((starts >= BOUNDS[:, 0]) & (starts <= BOUNDS[:, 1]))
    assert profile_targets(ESTIMATE, lower, upper, BOUNDS, np.array([False, False]))[0] == []


def test_the_second_profile_round_bisects_between_the_last_allowed_and_first_rejected():
    pins = [(0, 1.5), (0, 2.0), (1, -0.5), (1, -1.0), (2, 3.0), (2, 4.0)]
    allowed = np.array([True, False, False, False, True, True])
    got = bisect_targets(pins, allowed)
    # end 0: halfway fitted, the bound did not -> three quarters; end 1 (from 0): a quarter;
    # end 2: its bound fitted -> done
    assert [j for j, _ in got] == [0, 1]
    np.testing.assert_allclose([v for _, v in got], [1.75, -0.25])
    start = profile_start(ESTIMATE, 1, 0.6, BOUNDS, np.array([[1.0, -1.0], [-1.0, 1.0]]))
    np.testing.assert_allclose(start, [0.4, 0.6])


def test_the_coverage_table_counts_the_local_intervals_and_the_not_identified_beside_the_final():
    from eelhost.benchmarks.estimator_coverage import Coverage, Intervals, coverage_markdown

    truth = np.array([1.0, 2.0])
    seeds = [
        # the local interval misses x, the valley search's holds it and says not identified
        Intervals(np.array([1.5, 2.0]), np.array([0.5, 1.9]), np.array([2.0, 2.1]),
                  np.array([True, False]), np.array([1.3, 1.9]), np.array([1.7, 2.1])),
        Intervals(np.array([1.0, 2.0]), np.array([0.9, 1.9]), np.array([1.1, 2.1]),
                  np.array([False, False]), np.array([0.9, 1.9]), np.array([1.1, 2.1])),
    ]
    cov = Coverage(("x", "y"), truth, seeds)
    np.testing.assert_allclose(cov.rate(), [1.0, 1.0])
    np.testing.assert_allclose(cov.local_rate(), [0.5, 1.0])
    np.testing.assert_array_equal(cov.flagged(), [1, 0])
    table = coverage_markdown(cov, "cmd")
    assert "| x | 100 % | 1.00 | 50 % | 1 of 2 |" in table
