"""Joint models that join the comparison after its screen, with the laws it ranks best.

docs/estimation.md, "Model comparison": the PD loop on the servo's torque-speed line
(``pd_limited``) is not in the default grid with every law, but joins after the screen with every
base law of the grid and the two laws the screen ranks best, its line starting off.
"""

import importlib.util
from pathlib import Path

import numpy as np

from eelhost.estimation.joint_fit import joint_fit
from eelhost.estimation.selection import (
    CandidateScore,
    after_screen_laws,
    carry_over,
    default_laws,
    pass_screen,
)
from eelhost.estimation.space import ParameterSpace
from eelsim.fluid import get_fluid_law
from eelsim.joints import after_screen_models, default_grid_models
from eelsim.robot import load_robot


def _cand(name, errors, failed=None):
    return CandidateScore(name, 4, {"straight": 0.1}, {"straight": np.array(errors)},
                          failed=failed)


def test_the_pd_loop_on_the_servo_line_joins_a_default_grid_that_lacks_it():
    assert "pd_limited" not in default_grid_models("pd")
    assert after_screen_models(default_grid_models("pd")) == ["pd_limited"]
    assert after_screen_models(default_grid_models("servo")) == ["pd_limited"]
    # a robot file on the servo line has it in its grid with every law already
    assert after_screen_models(default_grid_models("pd_limited")) == []


def test_the_joining_model_takes_the_screens_best_distinct_laws_on_any_joint_model():
    grid = [_cand("pd x morison", [0.3, 0.3]), _cand("pd x galilean", [0.5, 0.5]),
            _cand("servo x morison", [0.2, 0.2]), _cand("servo x lighthill_lift", [0.25, 0.25]),
            _cand("servo x galilean", [np.nan, 0.1], failed="fold")]
    # morison (servo 0.2, then pd 0.3, the same law) and lighthill_lift; a failed one ranks last
    assert after_screen_laws(grid) == ["morison", "lighthill_lift"]
    assert after_screen_laws(grid, count=3) == ["morison", "lighthill_lift", "galilean"]


def test_the_joining_model_is_tried_with_every_base_law_however_low_the_screen_ranks_it():
    # on joints that bind, the screen ranks laws by the misfit they absorb: the water's own law
    # (here morison) may rank last on the wrong joints and must still be tried on the joined ones
    grid = [_cand("pd x linear_quadratic", [0.2, 0.2]), _cand("pd x resistive_lift", [0.3, 0.3]),
            _cand("pd x galilean", [0.4, 0.4]), _cand("pd x morison", [0.9, 0.9])]
    laws = ["morison", "galilean", "linear_quadratic", "resistive", "morison_lift",
            "resistive_lift"]
    chosen = after_screen_laws(grid, grid_laws=laws)
    # the screen's two best first (a lift variant among them), then the other base laws in the
    # grid's order; no lift variant the screen did not rank best
    assert chosen == ["linear_quadratic", "resistive_lift", "morison", "galilean", "resistive"]
    # a grid named without a base law does not gain one
    assert after_screen_laws(grid, grid_laws=["linear_quadratic", "resistive_lift"]) == [
        "linear_quadratic", "resistive_lift"]


def test_a_joined_model_passes_the_screen_on_its_errors_not_as_a_joint_models_best():
    grid = [_cand("pd x morison", [0.1, 0.1]), _cand("servo x morison", [0.12, 0.12]),
            _cand("pd_limited x morison", [0.9, 0.9]), _cand("pd_limited x galilean", [0.05, 0.05])]
    # pd_limited x galilean is the best: it passes; its other candidate is far off and does not
    assert pass_screen(grid, survivors=2, factor=2.0, family_factor=0.0,
                       joined={"pd_limited"}) == [0, 1, 3]
    # counted as a joint model of its own, its best would pass whatever its error
    grid[3] = _cand("pd_limited x galilean", [0.8, 0.8])
    assert 3 in pass_screen(grid, survivors=2, factor=2.0, family_factor=0.0)
    assert pass_screen(grid, survivors=2, factor=2.0, family_factor=0.0,
                       joined={"pd_limited"}) == [0, 1]


def test_a_pd_fit_carried_to_the_servo_line_starts_with_the_line_off():
    pd = ParameterSpace(get_fluid_law("morison"), joint_fit(load_robot(), "pd"))
    limited = ParameterSpace(get_fluid_law("morison"), joint_fit(load_robot(), "pd_limited"))
    fitted = pd.bounds[:, 0] + 0.3 * (pd.bounds[:, 1] - pd.bounds[:, 0])
    start = carry_over(pd.as_dict(fitted), limited, limited.bounds.mean(axis=1))
    line = [limited.names.index(n) for n in ("servo_max_torque_nm", "servo_max_speed_rad_s")]
    # the line at its bounds' far end (the largest stall torque and no-load speed): plain PD
    np.testing.assert_array_equal(start[line], limited.bounds[line, 1])
    np.testing.assert_array_equal(np.delete(start, line), fitted)


def test_setup_compiles_the_joining_models_kernels_with_every_default_law():
    path = Path(__file__).parents[2] / "scripts" / "warm_kernels.py"
    spec = importlib.util.spec_from_file_location("warm_kernels", path)
    assert spec is not None and spec.loader is not None
    warm = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(warm)
    main = warm.variant_lists()["main"]
    assert {(law, "pd_limited") for law in default_laws()} <= {(v[2], v[3]) for v in main}


def test_a_joined_candidate_passes_beside_the_grids_own_survivors_never_instead_of_one():
    from eelhost.estimation.selection import screen_survivors

    grid = [_cand("pd x morison", [0.10, 0.10]), _cand("pd x morison_lift", [0.08, 0.08]),
            _cand("pd x galilean", [0.5, 0.5]), _cand("servo x morison", [0.3, 0.3])]
    joined = [_cand("pd_limited x morison_lift", [0.09, 0.09]),
              _cand("pd_limited x morison", [0.9, 0.9])]
    own = pass_screen(grid, survivors=2, family_factor=0.0)
    assert own == [0, 1, 3]
    # among all, pd_limited x morison_lift would take pd x morison's place in the best two;
    # here it passes beside it, and its far-off sibling does not pass
    assert 0 not in pass_screen(grid + joined, survivors=2, family_factor=0.0,
                                joined={"pd_limited"})
    assert screen_survivors(grid + joined, len(grid), survivors=2,
                            joined={"pd_limited"}) == [0, 1, 3, 4]
