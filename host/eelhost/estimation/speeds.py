"""The per-gait mean-speed error of held-out predictions (docs/estimation.md, "Validation").

Kelasidi et al. (Mamba, IEEE Robotics & Automation Magazine 2016) judge coefficients fitted on one
gait by how well they predict the mean speed of others: about 1 % on the identification gait, at
worst 10-13 % on the rest. The report gives the same figure beside the paper's E_x, which mixes a
speed error with a heading error and grows with the run's length.

The mean speed of a run is the length of its centre of mass's path through the validation samples
(35 over the recorded span) divided by the span: for a straight run the net forward speed, for a
turning run or a path the speed along the curve. The recording and the prediction are sampled at
the same times (the recording on its own clock), so their ratio is the prediction's speed error.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.estimation.validate import ValidationRun


@dataclass(frozen=True)
class SpeedError:
    """One held-out run's mean speed, recorded and predicted.

    Attributes
    ----------
    name, motion : str
    amplitude_rad, omega_rad_s : float
        The gait.
    recorded_m_s, predicted_m_s : float
        Mean speeds (NaN for a prediction that failed).
    ex_recorded_clock_bl : float
        The run's E_x on the recording's clock, BL.
    """

    name: str
    motion: str
    amplitude_rad: float
    omega_rad_s: float
    recorded_m_s: float
    predicted_m_s: float
    ex_recorded_clock_bl: float

    @property
    def error_percent(self) -> float:
        """(predicted - recorded) / recorded, in %."""
        return 100.0 * (self.predicted_m_s - self.recorded_m_s) / self.recorded_m_s


def mean_speed(times_s: np.ndarray, positions_m: np.ndarray) -> float:
    """Path length through sampled positions over their span, m/s (module docstring).

    Parameters
    ----------
    times_s : ndarray, shape (n,)
    positions_m : ndarray, shape (n, 2)

    Returns
    -------
    float
    """
    steps = np.linalg.norm(np.diff(np.asarray(positions_m, float), axis=0), axis=-1)
    return float(steps.sum() / (times_s[-1] - times_s[0]))


def speed_errors(runs: Sequence[ValidationRun]) -> list[SpeedError]:
    """The mean-speed error of every validation run, in the runs' order."""
    out = []
    for run in runs:
        recorded = run.experiment.position_at(run.times_s)
        scenario = run.experiment.scenario
        out.append(SpeedError(
            run.experiment.name, run.experiment.motion, float(scenario.amplitude_rad),
            float(scenario.omega_rad_s), mean_speed(run.times_s, recorded),
            mean_speed(run.times_s, run.sim_positions_m), run.row.Ex_mean_unaligned_BL))
    return out


def speeds_markdown(errors: Sequence[SpeedError]) -> str:
    """The per-gait table and, per motion, the mean and worst absolute speed error."""
    lines = [
        "| experiment | motion | A (rad) | omega (rad/s) | recorded mean speed (m/s) | "
        "predicted (m/s) | speed error (%) | E_x, recorded clock (BL) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {e.name} | {e.motion} | {e.amplitude_rad:.2f} | {e.omega_rad_s:.2f} | "
        f"{e.recorded_m_s:.4f} | {e.predicted_m_s:.4f} | {e.error_percent:+.1f} | "
        f"{e.ex_recorded_clock_bl:.4f} |"
        for e in errors
    ]
    summary = []
    for motion in dict.fromkeys(e.motion for e in errors):
        errs = np.array([abs(e.error_percent) for e in errors if e.motion == motion])
        ran = errs[np.isfinite(errs)]
        if ran.size:
            summary.append(f"{motion}: mean {ran.mean():.1f} %, worst {ran.max():.1f} %"
                           + (f" ({errs.size - ran.size} failed)" if ran.size < errs.size
                              else ""))
    return "\n".join(lines) + ("\n\nAbsolute speed error, " + "; ".join(summary) + "."
                               if summary else "")
