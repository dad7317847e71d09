"""The model choice's check between the training gaits (docs/estimation.md, "Model comparison")."""

from pathlib import Path

import numpy as np
import pytest

from eelhost.data.experiments import Experiment, load_dataset
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.neighbours import (
    SANE_FACTOR,
    bracket_excursion,
    neighbour_excursion,
    neighbour_gaits,
)
from eelhost.estimation.selection import CandidateScore, recommend, table_markdown
from eelhost.estimation.space import ParameterSpace
from eelsim.scenario import grid_scenario

BUNDLED = Path(__file__).resolve().parents[2] / "datasets" / "paper_virtual_tank"


def _exp(motion, amplitude, omega, span_s=10.0):
    t = np.linspace(0.0, span_s, 11)
    return Experiment(f"{motion}_{amplitude}_{omega}", t, np.zeros((11, 2)),
                      grid_scenario(motion, amplitude, omega), motion=motion)


def test_the_neighbours_of_a_corner_design_are_its_edge_midpoints_and_its_centre():
    corners = [_exp("straight", 0.61, 2.7), _exp("straight", 0.61, 3.9, span_s=5.0),
               _exp("straight", 0.87, 2.7), _exp("straight", 0.87, 3.9),
               _exp("turning", 0.61, 2.7), _exp("turning", 0.87, 2.7)]
    near = neighbour_gaits(corners)
    gaits = [(n.experiment.motion, round(n.experiment.scenario.amplitude_rad, 3),
              round(n.experiment.scenario.omega_rad_s, 3), n.bracket) for n in near]
    assert gaits == [("straight", 0.61, 3.3, (0, 1)), ("straight", 0.74, 2.7, (0, 2)),
                     ("straight", 0.74, 3.9, (1, 3)), ("straight", 0.87, 3.3, (2, 3)),
                     ("straight", 0.74, 3.3, (0, 1, 2, 3)),
                     ("turning", 0.74, 2.7, (4, 5))]  # a line: its centre is its edge's midpoint
    # the shortest recording of the bracket is swum, with its span (compared before the goal)
    assert near[0].experiment.span_s == corners[1].span_s
    assert near[0].experiment.scenario.waypoints_m == corners[0].scenario.waypoints_m


def test_a_line_of_gaits_has_a_neighbour_only_between_consecutive_gaits():
    line = [_exp("straight", 0.61, w) for w in (2.7, 3.9, 3.1)]
    near = neighbour_gaits(line)
    omegas = sorted(round(n.experiment.scenario.omega_rad_s, 3) for n in near)
    assert omegas == [2.9, 3.5]  # not 3.3 (3.1 lies between 2.7 and 3.9), and 3.1 is recorded
    assert neighbour_gaits(line[:1]) == []


def test_the_excursion_is_one_inside_the_bracket_and_the_ratio_outside():
    assert bracket_excursion(0.05, [0.03, 0.08]) == 1.0
    assert bracket_excursion(0.16, [0.03, 0.08]) == pytest.approx(2.0)
    assert bracket_excursion(0.01, [0.03, 0.08]) == pytest.approx(3.0)
    assert bracket_excursion(float("nan"), [0.03, 0.08]) == np.inf
    assert bracket_excursion(0.0, [0.03, 0.08]) == np.inf


def _score(name, parameters, errors, between):
    return CandidateScore(name, parameters, {"straight": 0.1}, {"straight": np.array(errors)},
                          between={"straight": between})


def test_the_choice_passes_over_a_candidate_that_is_not_sane_between_its_gaits():
    wild = _score("pd x resistive_lift", 6, [0.10, 0.10], 3.5)  # best folds, wild between
    tame = _score("servo x morison", 6, [0.30, 0.30], 1.1)
    assert not wild.sane and tame.sane
    assert recommend([wild, tame]) is tame
    assert "x3.50 (not sane)" in table_markdown([wild, tame])
    # when none is sane, the least implausible ones are ranked
    wilder = _score("pd x morison", 4, [0.05, 0.05], 3.0 * SANE_FACTOR * 3.5)
    assert recommend([wild, wilder]) is wild
    # a candidate without the check (nothing between its gaits) counts as sane
    assert CandidateScore("pd x morison", 4).sane


@pytest.fixture(scope="module")
def bundled():
    return load_dataset(BUNDLED)


def test_the_truths_model_stays_between_its_training_gaits_and_a_slower_swimmer_does_not(bundled):
    straight = bundled.train["straight"]
    ev = Evaluator(bundled.robot, straight, space=ParameterSpace.for_robot(bundled.robot))
    truth = bundled.truth["straight"].as_array()
    # the plant's own model: its speeds between the corners lie between the corners' speeds
    assert neighbour_excursion(ev, truth) == 1.0
    assert ev.simulations == 5  # four edges and the centre, each swum once
    # ten times the skin friction: a far slower swimmer than the recordings bracket
    slow = truth * np.array([10.0, 1.0, 1.0, 1.0])
    assert neighbour_excursion(ev, slow) > SANE_FACTOR
