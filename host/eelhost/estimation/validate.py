"""Validation: how well fitted models predict experiments that were not used for fitting.

For every test experiment and path the twin runs the same task with the coefficients of its motion
type (paths use the turning set, or the joint set when there is one); both trajectories are sampled
at n = 35 times over the experiment's span, and the paper's E_x (mean of position-error norms, BL)
and E_v (BL/s), plus the true RMS of the same norms, are reported.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.data.experiments import Experiment
from eelhost.estimation.evaluate import ALIGN_S, Evaluator, Simulated
from eelhost.estimation.fitness import N_SAMPLES_VALIDATE, validation_errors
from eelhost.estimation.parameters import FittedModel
from eelsim.flags import Failure
from eelsim.robot import Robot


@dataclass
class ValidationRow:
    """Errors of one experiment (see :func:`eelhost.estimation.fitness.validation_errors`)."""

    name: str
    motion: str
    coefficients: str
    Ex_mean_BL: float  # noqa: N815 (the paper's symbols)
    Ev_mean_BL_s: float  # noqa: N815
    Ex_rms_BL: float  # noqa: N815
    Ev_rms_BL_s: float  # noqa: N815
    failure: str
    Ex_mean_unaligned_BL: float = float("nan")  # noqa: N815 (on the recording's own clock)
    clock_offset_s: float = 0.0


@dataclass
class ValidationRun:
    """One experiment with its simulation, for tables and figures."""

    experiment: Experiment
    times_s: np.ndarray
    exp_positions_m: np.ndarray
    sim_positions_m: np.ndarray
    sim_heading_rad: np.ndarray
    row: ValidationRow


def coefficient_set_for(motion: str, fitted: dict[str, FittedModel]) -> str:
    """Which fitted set predicts an experiment of this motion type."""
    if "joint" in fitted:
        return "joint"
    if motion == "path":
        return "turning" if "turning" in fitted else next(iter(fitted))
    return motion if motion in fitted else next(iter(fitted))


def validate(
    robot: Robot,
    fitted: dict[str, FittedModel],
    experiments: Sequence[Experiment],
    n_samples: int = N_SAMPLES_VALIDATE,
    backend: str = "auto",
    align_s: float = ALIGN_S,
) -> list[ValidationRun]:
    """Predict each experiment with the fitted coefficients and measure the errors.

    Parameters
    ----------
    robot : Robot
    fitted : dict
        Fitted models per motion type ("straight", "turning") or "joint".
    experiments : sequence of Experiment
    n_samples : int
        Samples per experiment (35 in the paper).
    backend : str
        Evaluator backend.
    align_s : float
        Half-width of the clock-offset search: each experiment is compared at the offset of its
        recording's clock that fits best (reported), besides its own clock (the paper's E_x).

    Returns
    -------
    list of ValidationRun
    """
    bl = robot.body_length_m()
    runs: list[ValidationRun] = []
    groups: dict[str, list[Experiment]] = {}
    for exp in experiments:
        groups.setdefault(coefficient_set_for(exp.motion, fitted), []).append(exp)
    for key, exps in groups.items():
        model = fitted[key]
        ev = Evaluator(robot, exps, n_samples=n_samples, backend=backend, align_s=align_s,
                       space=model.space)
        sim: Simulated = ev.simulate(model.values[None, :])
        counted = sim.counted_failure(ev.prepared)
        for j, p in enumerate(ev.prepared):
            failure = Failure(int(counted[0, j]))
            simp = sim.positions_m[0, j]
            offset, unaligned, exp_pos = 0.0, float("nan"), p.exp_positions_m
            if np.isnan(simp).any():
                err = dict.fromkeys(
                    ("Ex_mean_BL", "Ev_mean_BL_s", "Ex_rms_BL", "Ev_rms_BL_s"), float("nan")
                )
            else:
                unaligned = validation_errors(p.times_s, exp_pos, simp, bl)["Ex_mean_BL"]
                # the recording's clock offset that fits best (just 0 without alignment)
                gaps = np.linalg.norm(p.shifted_positions_m - simp, axis=-1).mean(axis=-1)
                k = int(np.argmin(gaps))
                offset, exp_pos = float(p.shifts_s[k]), p.shifted_positions_m[k]
                err = validation_errors(p.times_s, exp_pos, simp, bl)
            row = ValidationRow(
                p.experiment.name,
                p.experiment.motion,
                key,
                failure=failure.name,
                Ex_mean_unaligned_BL=unaligned,
                clock_offset_s=offset,
                **err,
            )
            runs.append(
                ValidationRun(p.experiment, p.times_s, exp_pos, simp, sim.heading_rad[0, j], row)
            )
    order = {e.name: i for i, e in enumerate(experiments)}
    return sorted(runs, key=lambda r: order[r.experiment.name])


def worst_ex(runs: Sequence[ValidationRun], aligned: bool = False) -> dict[str, float]:
    """The worst E_x (BL) per motion type of validation runs.

    Parameters
    ----------
    runs : sequence of ValidationRun
    aligned : bool
        At each experiment's best clock offset instead of on the recording's own clock (the
        paper's E_x).

    Returns
    -------
    dict of str to float
        Motion ("straight", "turning", "path") -> worst E_x, in the runs' order of motions; runs
        without an E_x (NaN) are passed over, as the table's failure column reports them.
    """
    worst: dict[str, float] = {}
    for run in runs:
        ex = run.row.Ex_mean_BL if aligned else run.row.Ex_mean_unaligned_BL
        worst[run.experiment.motion] = float(np.fmax(worst.get(run.experiment.motion, np.nan), ex))
    return worst


def table_markdown(rows: Sequence[ValidationRow]) -> str:
    """A table like the paper's table 4 (both error definitions, labelled)."""
    head = (
        "| experiment | motion | coefficients | E_x mean (BL) | E_v mean (BL/s) | E_x RMS (BL) | "
        "E_v RMS (BL/s) | clock offset (s) | E_x mean, recorded clock (BL) | flag |\n"
        "|---|---|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"| {r.name} | {r.motion} | {r.coefficients} | {r.Ex_mean_BL:.4f} | {r.Ev_mean_BL_s:.4f} | "
            f"{r.Ex_rms_BL:.4f} | {r.Ev_rms_BL_s:.4f} | {r.clock_offset_s:+.2f} | "
            f"{r.Ex_mean_unaligned_BL:.4f} | {r.failure} |"
        )
    return "\n".join(lines)


def table_csv(rows: Sequence[ValidationRow]) -> str:
    """The same table as CSV."""
    cols = [
        "name",
        "motion",
        "coefficients",
        "Ex_mean_BL",
        "Ev_mean_BL_s",
        "Ex_rms_BL",
        "Ev_rms_BL_s",
        "clock_offset_s",
        "Ex_mean_unaligned_BL",
        "failure",
    ]
    lines = [",".join(cols)]
    for r in rows:
        lines.append(",".join(str(getattr(r, c)) for c in cols))
    return "\n".join(lines) + "\n"
