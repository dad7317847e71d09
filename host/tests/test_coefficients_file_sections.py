"""The report's sections of coefficients.json, read back through coefficients_file's accessors.

The report writes them (estimation/report.py, with BootstrapResult.to_json) and the planner and
the coverage benchmark read them; both sides meet in estimation/coefficients_file.py
(docs/data.md, "coefficients.json").
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from eelhost.estimation.coefficients_file import (
    CoefficientsError,
    ReportedUncertainty,
    prediction_band_coverage,
    read_coefficients_file,
    reported_uncertainty,
    write_coefficients,
)
from eelhost.estimation.uncertainty import BootstrapResult
from eelhost.planning.uncertainty import read_coefficient_model
from eelsim.robot import load_robot

ROBOT = load_robot()
NAMES = ("C_f", "C_d", "C_a", "C_m")
ESTIMATE = np.array([0.008, 0.776, 0.618, 0.007])


class Fit:
    """A fit entry as write_coefficients takes it (the fits' own reading is tested elsewhere)."""

    def to_json(self) -> dict:
        return {"coefficients": dict(zip(NAMES, ESTIMATE.tolist(), strict=True))}


def boot() -> BootstrapResult:
    samples = ESTIMATE * np.array([[0.9], [1.0], [1.1], [1.05], [0.95], [1.02]])
    return BootstrapResult(NAMES, ESTIMATE, samples, np.full(6, 0.02), 0.05,
                           ESTIMATE * 0.8, ESTIMATE * 1.3, level=0.9)


def test_the_reports_bootstrap_section_reads_back_as_written(tmp_path):
    written = boot()
    extra = {"uncertainty": {"joint": written.to_json()},
             "prediction_band": {"level": 0.95, "coverage": {"straight": 0.97, "all": 0.97}}}
    path = write_coefficients(tmp_path / "coefficients.json", {"joint": Fit()}, extra, ROBOT)
    data = read_coefficients_file(path)
    read = reported_uncertainty(data)["joint"]
    assert read.level == pytest.approx(0.9)
    assert read.excess == pytest.approx(written.excess) == pytest.approx(2.5)
    assert np.allclose([read.lower[n] for n in NAMES], written.lower)
    assert np.allclose([read.upper[n] for n in NAMES], written.upper)
    assert np.allclose([read.std[n] for n in NAMES], written.noise_std())
    assert prediction_band_coverage(data, path) == {"straight": 0.97, "all": 0.97}
    # the planner's coefficient model takes the interval's wider side at the written level
    model = read_coefficient_model(path, ROBOT)
    z90 = 1.6448536269514722
    assert np.allclose(model.std["straight"], 0.3 * ESTIMATE / z90)
    assert np.allclose(model.std["turning"], 0.3 * ESTIMATE / z90)


def test_values_that_are_not_finite_numbers_are_left_out_as_not_reported():
    entry = ReportedUncertainty.from_json({
        "level": 1.5, "excess": "big", "lower": {"C_f": 0.1, "C_d": "x", "C_a": float("nan")},
        "upper": [1, 2], "std": {"C_f": True, "C_d": 0.2},
    })
    assert entry.level is None and entry.excess is None
    assert entry.lower == {"C_f": 0.1} and entry.upper == {} and entry.std == {"C_d": 0.2}
    assert entry.samples is None
    assert reported_uncertainty({"uncertainty": {"straight": 3, "turning": {}}}).keys() == {"turning"}
    assert reported_uncertainty({}) == {} and reported_uncertainty({"uncertainty": []}) == {}


def test_a_file_without_prediction_bands_is_refused_naming_it(tmp_path):
    path = tmp_path / "coefficients.json"
    with pytest.raises(CoefficientsError, match="coefficients.json: prediction_band.coverage: none"):
        prediction_band_coverage({"fits": {}}, path)
    bad = json.loads('{"prediction_band": {"coverage": {"straight": "most"}}}')
    with pytest.raises(CoefficientsError, match="expected a number per motion"):
        prediction_band_coverage(bad, path)
