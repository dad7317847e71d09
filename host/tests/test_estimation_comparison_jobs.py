"""The model comparison in worker processes gives the serial run's scores, bit for bit.

docs/estimation.md, "Model comparison" (worker processes).
"""

from dataclasses import replace

import numpy as np
import pytest

from eelhost.data.experiments import BUNDLED_DATASET, load_dataset
from eelhost.estimation.evaluate import simulations_counter
from eelhost.estimation.methods import FitSettings
from eelhost.estimation.selection import cross_validate

SMALL = FitSettings(method="minimax", polish_iterations=1)


def _compare(jobs):
    counted = simulations_counter()
    scores = cross_validate(load_dataset(BUNDLED_DATASET), ["straight", "turning"],
                            replace(SMALL, jobs=jobs), laws=["morison", "linear_quadratic"],
                            joint_models=["pd"], iterations=1, fold_iterations=1, budget=12,
                            one_set=0)
    return scores, counted().get("sims", 0)


@pytest.mark.slow
def test_the_comparison_in_two_worker_processes_scores_exactly_as_the_serial_run():
    serial, serial_runs = _compare(1)
    spread, spread_runs = _compare(2)
    assert [c.model for c in spread] == [c.model for c in serial]
    for a, b in zip(serial, spread, strict=True):
        assert a.fitness == b.fitness
        assert a.failed == b.failed
        for m in a.values:
            np.testing.assert_array_equal(b.values[m], a.values[m])
            np.testing.assert_array_equal(b.held_out[m], a.held_out[m])
        assert b.simulations == a.simulations > 0
    # the workers' runs reach this process's count (the progress line's sims=)
    assert spread_runs == serial_runs == sum(c.simulations for c in serial)


@pytest.mark.slow
def test_the_reports_bootstraps_in_worker_processes_are_the_serial_runs(tmp_path):
    # each fit's identifiability and bootstrap run as one task per fit (estimation/report.py):
    # in two worker processes they must give the serial run's intervals, bit for bit
    import json

    from eelhost.estimation.report import run_report

    dataset = load_dataset(BUNDLED_DATASET)
    data = {}
    for jobs in (1, 2):
        run_report(dataset, tmp_path / str(jobs), settings=replace(SMALL, jobs=jobs),
                   bootstrap_replicates=2, compare_models=False)
        data[jobs] = json.loads((tmp_path / str(jobs) / "coefficients.json").read_text())
    for key in ("uncertainty", "identifiability", "prediction_band", "fits"):
        assert data[2][key] == data[1][key]
    assert set(data[1]["uncertainty"]) == {"straight", "turning"}
