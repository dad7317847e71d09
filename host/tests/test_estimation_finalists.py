"""The comparison's finalists refitted from more starts (docs/estimation.md, "The finalists").

Where the joints bind, a full fit whose joint parameters took up the water's misfit sits in a
basin its own polish never leaves; the best few candidates are refitted from the other
candidates' fits and from their joint parameters spread over their whole bounds, and a fit far
above its motion's best is marked.
"""

import numpy as np

from eelhost.estimation.joint_fit import joint_fit
from eelhost.estimation.selection import (
    CandidateScore,
    finalists,
    misfit_ratios,
    separated,
    spread_starts,
    table_markdown,
)
from eelhost.estimation.space import ParameterSpace
from eelsim.fluid import get_fluid_law
from eelsim.robot import load_robot


def _space(joints: str) -> ParameterSpace:
    return ParameterSpace(get_fluid_law("morison"), joint_fit(load_robot(), joints))


def test_the_spread_starts_cover_the_stall_torque_across_its_whole_range_keeping_the_water():
    space = _space("pd_limited")
    k = len(space.coefficient_names)
    base = space.bounds.mean(axis=1)
    base[k] = 0.0657  # a stall torque that took up the misfit (servo_limits seed 22)
    starts = np.array(spread_starts(space, base, levels=(0.1, 0.5, 0.9), steps=0))
    assert starts.shape == (9, space.size)  # every combination of the two joint parameters
    np.testing.assert_array_equal(starts[:, :k], np.tile(base[:k], (9, 1)))  # the water kept
    lo, hi = space.bounds[k]
    stall = np.unique(starts[:, k])
    np.testing.assert_allclose(stall, lo + np.array([0.1, 0.5, 0.9]) * (hi - lo))
    # and each joint parameter alone in even steps over its bounds, the other kept: the plant's
    # narrow valley (0.02 N m, a thousandth of a newton metre wide) is within a step
    fine = np.array(spread_starts(space, base, levels=(0.1, 0.5, 0.9), steps=61))
    assert fine.shape == (9 + 2 * 61, space.size)
    line = fine[9:70]
    np.testing.assert_array_equal(line[:, k + 1], base[k + 1])
    assert line[0, k] == lo and line[-1, k] == hi
    assert np.min(np.abs(line[:, k] - 0.02)) <= 0.0007
    # the paper's PD joints fit no joint parameter: nothing to spread
    assert spread_starts(_space("pd"), _space("pd").bounds.mean(axis=1)) == []


def test_the_polished_starts_are_the_best_distinct_ones_away_from_the_fit_already_made():
    space = _space("pd_limited")
    mid = space.bounds.mean(axis=1)
    width = space.bounds[:, 1] - space.bounds[:, 0]
    near_own = mid + 0.01 * width
    twin = mid + 0.5 * width * np.eye(space.size)[0]
    twin_close = twin + 0.01 * width
    far = mid - 0.4 * width
    failed = mid + 0.3 * width
    points = np.array([near_own, twin, twin_close, far, failed])
    fitness = np.array([0.05, 0.1, 0.11, 0.3, 1e14])
    # the start beside the own fit and the near-twin of a taken start are passed over, and a
    # failed start is never polished
    assert separated(points, fitness, space, 4, away_from=[mid]) == [1, 3]
    assert separated(points, fitness, space, 1, away_from=[mid]) == [1]


def _cand(name, fitness, errors, **kw):
    return CandidateScore(name, 8, fitness, {m: np.array(errors) for m in fitness}, **kw)


def test_the_finalists_are_the_best_that_ran_and_a_far_worse_full_fit_is_marked():
    scores = [
        _cand("pd_limited x linear_quadratic", {"straight": 0.05, "turning": 0.654}, [0.3, 0.4]),
        _cand("pd_limited x morison", {"straight": 0.04, "turning": 0.096}, [0.5, 0.6]),
        _cand("pd x morison", {"straight": 0.2, "turning": 0.3}, [0.9, 1.0]),
        _cand("pd x galilean", {"straight": 0.01, "turning": 0.01}, [0.1, 0.1],
              screened_out=True),
        _cand("servo x morison", {"straight": 0.3, "turning": 0.3}, [0.1, np.nan],
              failed="turning: held out"),
    ]
    # the failed candidate never is one, a screened-out one is not passed here (by position)
    assert finalists(dict(enumerate(scores[:3] + scores[4:])), 2) == [0, 1]
    ratios = misfit_ratios(scores)
    assert set(ratios) == {0, 1, 2}  # the screen's short fits and failed ones not compared
    assert ratios[0]["turning"] == np.float64(0.654) / 0.096
    table = table_markdown(scores)
    assert "0.6540 (x6.8 the best fit)" in table
    assert "0.3000 (x3.1 the best fit)" in table
    assert "0.0960 |" in table and "0.0500 |" in table  # within the factor: unmarked
