"""The worst held-out error counts a prediction that did not swim (docs/estimation.md, "Validation")."""

from __future__ import annotations

import math

import numpy as np

from eelhost.estimation.validate import ValidationRow, ValidationRun, ex_text, worst_ex
from eelsim.flags import Failure


class _Named:
    """The part of an experiment worst_ex reads: its motion."""

    def __init__(self, motion: str) -> None:
        self.motion = motion


def _run(motion: str, ex_bl: float, failure: Failure = Failure.NONE) -> ValidationRun:
    row = ValidationRow(f"{motion}_{ex_bl}", motion, motion, ex_bl, 0.0, ex_bl, 0.0,
                        failure.name, Ex_mean_unaligned_BL=ex_bl)
    empty = np.zeros((0, 2))
    return ValidationRun(_Named(motion), np.zeros(0), empty, empty, np.zeros(0), row)  # type: ignore[arg-type]


def test_a_path_whose_prediction_self_collides_is_the_worst_path_not_passed_over():
    runs = [_run("straight", 0.02), _run("path", 0.03),
            _run("path", float("nan"), Failure.SELF_COLLISION)]
    for aligned in (False, True):
        worst = worst_ex(runs, aligned=aligned)
        assert worst["straight"] == 0.02
        assert math.isinf(worst["path"])
    assert ex_text(worst_ex(runs)["path"]).startswith("failed")


def test_the_worst_of_predictions_that_swam_is_their_largest_error():
    worst = worst_ex([_run("turning", 0.04), _run("turning", 0.01), _run("path", 0.05)])
    assert worst == {"turning": 0.04, "path": 0.05}
    assert ex_text(worst["path"]) == "0.0500"


def test_a_too_slow_prediction_keeps_its_error_over_the_recorded_span():
    # it swam every sample, lagging: its E_x measures the lag
    assert worst_ex([_run("turning", 0.01, Failure.TOO_SLOW)]) == {"turning": 0.01}
