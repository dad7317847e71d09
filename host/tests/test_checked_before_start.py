"""Everything a command is given is checked before anything starts (docs/cli.md).

A campaign plan's gaits against the robot's ranges (as ``run --gait``), its rests, and a ``sim://``
URI's parameters against the limits of the options they stand for: each refused with one line
naming the file or URI and the value, before a take is run or a file written.
"""

from __future__ import annotations

import pytest

from eelhost import cli
from eelhost.link.uri import parse_link_uri

TAKE = "--waypoints 1,0 --gait 0.87,3.9 --duration 1 --no-view --out {tmp}/take"


@pytest.mark.parametrize(
    ("uri", "words"),
    [
        ("sim://?seed=-3", ("seed=-3", ">= 0")),
        ("sim://?current=50,0", ("current speed 50", "1 m/s")),
        ("sim://?current=-0.1,0", ("current speed -0.1",)),
        ("sim://?speed=-2", ("speed=-2",)),
        ("sim://?radio=wifi", ("radio='wifi'",)),
    ],
)
def test_a_sim_uri_is_refused_with_the_options_limits_before_a_take(uri, words, tmp_path, capsys):
    assert cli.main(["run", "--link", uri, *TAKE.format(tmp=tmp_path).split()]) == 2
    err = capsys.readouterr().err
    assert err.startswith("eelbot run: error:") and all(w in err for w in words), err
    assert not list(tmp_path.iterdir())  # nothing recorded


def test_a_sim_uri_within_the_limits_parses():
    parse_link_uri("sim://?seed=3&current=0.02,90&speed=0")


@pytest.mark.parametrize(
    ("line", "words"),
    [
        ("amplitudes_rad = [0.61, 5.0]", ("amplitudes_rad", "amplitude_rad 5 outside")),
        ("omegas_rad_s = [2.7, 25.0]", ("omegas_rad_s", "omega_rad_s 25 outside")),
        ("omegas_rad_s = [0.0, 2.7]", ("omegas_rad_s", "must be positive")),
        ("beta_rad = 4.0", ("beta_rad", "outside")),
        ("distance_m = inf", ("distance_m",)),
        ("rest_s = -5.0", ("rest_s",)),
    ],
)
def test_a_campaign_plan_the_robot_would_refuse_stops_before_its_first_take(line, words, tmp_path,
                                                                           capsys):
    plan = tmp_path / "plan.toml"
    plan.write_text(line + "\n")
    out = tmp_path / "campaign"
    assert cli.main(["campaign", str(plan), "--link", "sim://", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(plan) in err and all(w in err for w in words), err
    assert not out.exists()


@pytest.mark.parametrize("option", ["--rest", "--speed"])
def test_campaign_rest_and_speed_below_zero_are_refused(option, tmp_path, capsys):
    argv = ["campaign", "--link", "sim://", "--out", str(tmp_path / "c"), f"{option}=-5"]
    assert cli.main(argv) == 2
    assert option in capsys.readouterr().err
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize(("budget", "popsize", "restarts"), [(100, 8, "bipop"), (1500, 10, "ipop"),
                                                            (37, 10, "none")])
def test_the_cmaes_budget_is_at_most_what_was_asked(budget, popsize, restarts):
    import numpy as np

    from eelhost.estimation.optimise import fit_cmaes
    from eelhost.estimation.space import ParameterSpace
    from eelsim.fluid import get_fluid_law

    space = ParameterSpace(get_fluid_law("morison"))
    target = np.array([0.008, 0.776, 0.618, 0.007])
    seen = []

    def bowl(c):
        seen.append(len(c))
        return np.sum(((np.atleast_2d(c) - target) / target) ** 2, axis=1) + 1e-3

    res = fit_cmaes(bowl, space, seed=3, max_evaluations=budget, popsize=popsize,
                    restarts=restarts)
    assert res.evaluations == sum(seen) <= budget
    if restarts != "none":
        assert res.evaluations > budget / 2  # restarts spend the budget, up to the last whole run
