"""The middle rung: a family's or joint model's best gets a medium search before the full one.

docs/estimation.md, "Model comparison" (the screen, the middle rung).
"""

import logging
from dataclasses import replace

import numpy as np
import pytest
from test_estimation_choice import TINY, _small_tank

from eelhost.estimation import selection
from eelhost.estimation.selection import (
    CandidateScore,
    cross_validate,
    middle_rung,
    past_middle_rung,
    recommend,
    table_markdown,
)


def _cand(name, errors, failed=None, fitness=0.1):
    return CandidateScore(name, 4, {"straight": fitness}, {"straight": np.array(errors)},
                          failed=failed)


GRID = [_cand("pd x morison", [0.5, 0.7]), _cand("pd x galilean", [0.1, 0.1]),
        _cand("pd x linear_quadratic", [0.15, 0.17]),
        _cand("pd x resistive_lift", [0.19, 0.23]), _cand("pd x resistive", [0.3, 0.3]),
        _cand("servo x morison", [0.01, np.nan], "fold", fitness=1e9),
        _cand("servo x galilean", [np.nan, np.nan], "fit", fitness=1e8)]


def test_only_the_candidates_passed_as_a_familys_or_joint_models_best_get_the_middle_rung():
    # the best few (galilean 0.1, linear_quadratic 0.16 within twice it) go straight to the full
    # search; resistive's family best (its lift variant, 0.21) and the servo joints' best (every
    # servo candidate failed the screen) passed only as a family's best: the middle rung first
    assert selection.screen_survivors(GRID, len(GRID)) == [1, 2, 3, 5]
    assert middle_rung(GRID, len(GRID)) == [3, 5]
    # with one survivor, linear_quadratic too passes only as its family's best
    assert middle_rung(GRID, len(GRID), survivors=1) == [2, 3, 5]
    # a candidate that joined after the screen and passes on its error is not tried first; one
    # that passes only as its law family's best (among all candidates) is
    joined = [_cand("pd_limited x galilean", [0.09, 0.09]),
              _cand("pd_limited x morison", [0.32, 0.34])]
    assert middle_rung(GRID + joined, len(GRID), joined={"pd_limited"}) == [3, 5, 8]
    # when every candidate failed the screen, all pass and none is tried first
    assert middle_rung([GRID[5], GRID[6]], 2) == []


def test_a_lift_variant_screened_far_worse_than_its_passing_base_passes_with_it_to_the_middle_rung():
    # servo x linear_quadratic_lift nests servo x linear_quadratic (lift off), so the screen's
    # short fits scoring it four times worse say only that its lift is not found yet: it passes
    # with its base, first to the middle rung; morison_lift's base does not pass, nor does it
    grid = [_cand("servo x lighthill_lift", [0.2, 0.2]), _cand("servo x linear_quadratic", [0.3, 0.3]),
            _cand("servo x linear_quadratic_lift", [1.2, 1.2]), _cand("servo x morison", [1.4, 1.6]),
            _cand("servo x morison_lift", [1.8, 1.8])]
    assert selection.lift_variants(grid) == {1: 2, 3: 4}
    assert selection.pass_screen(grid, survivors=2, factor=2.0, family_factor=0.0) == [0, 1, 2]
    assert middle_rung(grid, len(grid), survivors=2) == [2]
    # without its base among the survivors the variant is judged on its own screen error
    assert selection.pass_screen(grid[:1] + grid[2:], survivors=1, family_factor=0.0) == [0]
    # a one-set candidate is not a separate-set base's variant
    assert selection.lift_variants([grid[1], replace(grid[2], model=grid[2].model + ", one set")]) == {}


def test_a_candidate_far_off_at_the_middle_rung_stops_and_one_within_the_factor_goes_on():
    screened = GRID[:5]  # the screen's best: pd x galilean, 0.1
    middle = {3: _cand("pd x resistive_lift", [0.25, 0.35]),  # 0.30: over twice 0.1
              4: _cand("pd x resistive", [0.18, 0.2]),  # 0.19: within twice 0.1
              5: _cand("servo x morison", [0.01, np.nan], "middle rung: fold")}
    # the failed one goes on: a penalty is not an error, the full search decides
    assert past_middle_rung(middle, screened) == [4, 5]
    assert past_middle_rung(middle, screened, factor=3.5) == [3, 4, 5]
    # the middle rung's own errors count for the best: one below the screen's best lowers it
    middle[6] = _cand("servo x galilean", [0.05, 0.05])
    assert past_middle_rung(middle, screened) == [5, 6]


def test_the_table_says_which_candidates_stopped_at_the_middle_rung_and_never_recommends_one():
    stopped = replace(_cand("pd x resistive_lift", [0.01, 0.03]), screened_out=True,
                      middle_rung=True)
    full = _cand("pd x morison", [0.04, 0.06])
    # its error is lower, yet it is not compared with the full searches' as if searched in full
    assert recommend([stopped, full]) is full and recommend([stopped]) is None
    table = table_markdown([stopped, full])
    assert ("| pd x resistive_lift (stopped at the middle rung) | 4 | 0.1000 | 0.0200 (middle "
            "rung) | 0.0300 (middle rung) |") in table
    assert "screened out" not in table and "(screen)" not in table
    # and the estimate-bench's line of the candidates says so too, not "screened out"
    from eelhost.benchmarks.estimator_accuracy import _model_line

    line = _model_line({"comparison": [stopped, full], "adopted": False, "model": full.model})
    assert "pd x resistive_lift 0.0200 (stopped at the middle rung)" in line
    assert "screened out" not in line


def _rung(ds, middle_budget=12):
    # six candidates, one of which is the screen's best few: the others that pass do so only as
    # a family's or joint model's best, so they get the middle rung first (in the workers)
    return cross_validate(ds, ["straight"], replace(TINY, jobs=2),
                          laws=["morison", "linear_quadratic", "resistive"],
                          joint_models=["pd", "servo"], iterations=2, fold_iterations=2,
                          budget=24, screen_budget=12, survivors=1, final=1, one_set=0,
                          middle_budget=middle_budget)


@pytest.mark.slow
def test_the_middle_rung_stops_those_far_off_and_lets_the_others_on_to_the_full_search(
    tmp_path, caplog, monkeypatch
):
    ds = _small_tank(tmp_path, "head_tail", "paper_robot.toml")
    caplog.set_level(logging.INFO, logger="eelhost.estimation.selection")
    # within SURVIVOR_FACTOR (2) of the best every one tried goes on, and its figures are the
    # full search's, the same as with no middle rung
    scores = _rung(ds)
    tried = [r.getMessage() for r in caplog.records if "middle rung:" in r.getMessage()]
    assert tried and all(t.endswith("goes on to the full search") for t in tried)
    without = _rung(ds, middle_budget=0)
    assert not any(c.middle_rung for c in scores)
    for a, b in zip(scores, without, strict=True):
        assert a.model == b.model and a.screened_out == b.screened_out
        np.testing.assert_array_equal(a.held_out["straight"], b.held_out["straight"])
        assert a.simulations >= b.simulations  # the middle rung's runs are counted too
    # with a factor of 1 those tried stop at the middle rung unless they are the best
    caplog.clear()
    monkeypatch.setattr(selection, "SURVIVOR_FACTOR", 1.0)
    strict = _rung(ds)
    stopped = [c for c in strict if c.middle_rung]
    assert stopped and all(c.screened_out for c in stopped)
    lowest = min(c.mean_held_out for c in strict)
    assert all(c.mean_held_out > lowest for c in stopped)
    assert recommend(strict) not in stopped
    table = table_markdown(strict)
    for c in stopped:
        assert f"| {c.model} (stopped at the middle rung) |" in table
        assert f"{c.mean_held_out:.4f} (middle rung)" in table
    assert sum("stops there" in r.getMessage() for r in caplog.records) == len(stopped)
