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
from eelhost.estimation.coefficients_file import FittedModel
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.fitness import N_SAMPLES_VALIDATE, validation_errors
from eelhost.estimation.runs import Simulated, clock_shifts, declared_clock_bound_s
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
    clock_bound_s: float = 0.0  # the half-width the clock offset was searched within


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
    align_s: float | None = None,
    servo_limits: bool = False,
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
    align_s : float or None
        Half-width of the clock-offset search: each experiment is compared at the offset of its
        recording's clock that fits best (reported), besides its own clock (the paper's E_x).
        None (the default): what each recording declares, its camera's ``timestamp_jitter_s``
        (:func:`~eelhost.estimation.runs.declared_clock_bound_s`; docs/estimation.md,
        "Validation"); 0: its own clock only.
    servo_limits : bool
        Swim the robot with its PD joints on the servos' torque-speed line (the loop's option;
        :class:`~eelhost.estimation.evaluate.Evaluator`).

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
        # the clock search is done below, per recording (its own declared bound): the evaluator
        # compares on the recorded clock
        ev = Evaluator(robot, exps, n_samples=n_samples, backend=backend, align_s=0.0,
                       space=model.space, servo_limits=servo_limits)
        sim: Simulated = ev.simulate(model.values[None, :])
        counted = sim.counted_failure(ev.prepared)
        for j, p in enumerate(ev.prepared):
            failure = Failure(int(counted[0, j]))
            simp = sim.positions_m[0, j]
            offset, unaligned, exp_pos = 0.0, float("nan"), p.exp_positions_m
            bound = declared_clock_bound_s(p.experiment) if align_s is None else align_s
            if np.isnan(simp).any():
                err = dict.fromkeys(
                    ("Ex_mean_BL", "Ev_mean_BL_s", "Ex_rms_BL", "Ev_rms_BL_s"), float("nan")
                )
            else:
                unaligned = validation_errors(p.times_s, exp_pos, simp, bl)["Ex_mean_BL"]
                offset, exp_pos = best_clock_offset(p.experiment, p.times_s, simp, bound)
                err = validation_errors(p.times_s, exp_pos, simp, bl)
            row = ValidationRow(
                p.experiment.name,
                p.experiment.motion,
                key,
                failure=failure.name,
                Ex_mean_unaligned_BL=unaligned,
                clock_offset_s=offset,
                clock_bound_s=bound,
                **err,
            )
            runs.append(
                ValidationRun(p.experiment, p.times_s, exp_pos, simp, sim.heading_rad[0, j], row)
            )
    order = {e.name: i for i, e in enumerate(experiments)}
    return sorted(runs, key=lambda r: order[r.experiment.name])


def best_clock_offset(
    experiment: Experiment, times_s: np.ndarray, sim_positions_m: np.ndarray, bound_s: float
) -> tuple[float, np.ndarray]:
    """The recording's clock offset within +-``bound_s`` that brings it nearest the prediction.

    docs/estimation.md, "Validation": the offsets ``runs.clock_shifts(bound_s)`` apart by
    ``ALIGN_STEP_S`` (just 0 for a bound of 0), the one whose mean distance between the shifted
    recording and the prediction is least. A recording holds nothing beyond its ends, so a shift
    past them reads its first or last position (``Experiment.position_at`` interpolates inside
    the recorded span).

    Parameters
    ----------
    experiment : Experiment
        The recording.
    times_s : ndarray, shape (n,)
        The sample times of the prediction.
    sim_positions_m : ndarray, shape (n, 2)
        The predicted centre of mass at those times.
    bound_s : float
        The search half-width, s.

    Returns
    -------
    offset_s : float
        The best offset.
    positions_m : ndarray, shape (n, 2)
        The recording at ``times_s + offset_s``.
    """
    shifts = clock_shifts(bound_s)
    shifted = np.stack([experiment.position_at(times_s + d) for d in shifts])
    gaps = np.linalg.norm(shifted - sim_positions_m, axis=-1).mean(axis=-1)
    k = int(np.argmin(gaps))
    return float(shifts[k]), shifted[k]


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
        Motion ("straight", "turning", "path") -> worst E_x, in the runs' order of motions. A run
        without an E_x (its prediction failed before the last sample: a self-collision, an
        ill-conditioned step) makes its motion's worst infinite: a prediction that did not swim
        the experiment is the worst there is, not one to pass over (docs/estimation.md,
        "Validation"; :func:`ex_text` prints it). A run flagged too slow keeps its E_x, which
        measures its lag over the recorded span.
    """
    worst: dict[str, float] = {}
    for run in runs:
        ex = run.row.Ex_mean_BL if aligned else run.row.Ex_mean_unaligned_BL
        if not np.isfinite(ex):
            ex = float("inf")
        worst[run.experiment.motion] = max(worst.get(run.experiment.motion, -np.inf), ex)
    return worst


def ex_text(ex_bl: float) -> str:
    """A worst E_x in words: "0.0312" BL, or "failed" where a prediction did not swim."""
    return f"{ex_bl:.4f}" if np.isfinite(ex_bl) else "failed (a prediction did not swim)"


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


# ---- prediction bands (docs/estimation.md, "Prediction bands")

BAND_LEVEL = 0.95
# Extra widening of the bands, as measured by the band coverage benchmark
# (docs/estimation_coverage.md): 1, none.
BAND_WIDEN = 1.0
# Runs of each held-out task with their own draw of the declared control jitter (the band's
# jitter share, uncertainty.jitter_variance).
JITTER_DRAWS = 8


@dataclass
class PredictionBand:
    """The prediction band of one held-out experiment, and whether the recording stays in it.

    Attributes
    ----------
    name, motion, coefficients : str
        The experiment, its motion type and the fitted set that predicts it.
    times_s : ndarray, shape (n,)
        Sample times (the recording's clock).
    centre_m : ndarray, shape (n, 2)
        The fit's prediction (NaN where it failed).
    radius_m : ndarray, shape (n,)
        The band's radius around it.
    inside : ndarray of bool, shape (n,)
        Whether the recorded position lies within the band (False where the prediction failed).
    """

    name: str
    motion: str
    coefficients: str
    times_s: np.ndarray
    centre_m: np.ndarray
    radius_m: np.ndarray
    inside: np.ndarray

    @property
    def coverage(self) -> float:
        """Fraction of the sampled positions inside the band."""
        return float(self.inside.mean())


def band_radius(
    spread_m2: np.ndarray, t_s: np.ndarray, growth: np.ndarray, level: float = BAND_LEVEL,
    widen: float = BAND_WIDEN, dof: int | None = None,
) -> np.ndarray:
    """The band's radius: a 2-D prediction region of per-axis variance spread + misfit.

    The per-axis variance at time t since the recording's start is the ensemble's spread (half
    the mean squared distance of the refits' predictions from the fit's) plus the misfit's
    c0 + c1 t^2 (:func:`eelhost.estimation.uncertainty.misfit_growth`). With the variance known,
    the radius is sqrt(chi2_2(level)) = sqrt(-2 ln(1 - level)) standard deviations; estimated from
    ``dof`` + 1 independent curves (the training experiments), it is sqrt(2 F(level; 2, dof))
    standard deviations, the prediction region of a 2-D normal whose variance is estimated
    (Hotelling): with four experiments 4.37 instead of 2.45. Times ``widen``.

    Parameters
    ----------
    spread_m2 : ndarray, shape (n,)
    t_s : ndarray, shape (n,)
    growth : ndarray, shape (2,)
        (c0 m^2, c1 m^2/s^2).
    level, widen : float
    dof : int, optional
        Degrees of freedom of the variance's estimate (None: known).

    Returns
    -------
    ndarray, shape (n,)
    """
    if dof is None:
        k = np.sqrt(-2.0 * np.log(1.0 - level))
    else:
        from scipy.stats import f as fisher

        k = float(np.sqrt(2.0 * fisher.ppf(level, 2, max(1, dof))))
    return widen * k * np.sqrt(spread_m2 + growth[0] + growth[1] * t_s**2)


def prediction_bands(
    robot: Robot,
    fitted: dict[str, FittedModel],
    ensembles: dict[str, np.ndarray],
    growth: dict[str, np.ndarray],
    experiments: Sequence[Experiment],
    n_samples: int = N_SAMPLES_VALIDATE,
    backend: str = "auto",
    level: float = BAND_LEVEL,
    widen: float = BAND_WIDEN,
    dof: dict[str, int] | None = None,
    jitter_draws: int = JITTER_DRAWS,
    seed: int = 0,
) -> list[PredictionBand]:
    """95 % prediction bands of held-out experiments, and their coverage of the recordings.

    Each experiment is swum by its fitted set's ensemble (the estimate and its bootstrap refits,
    :meth:`eelhost.estimation.uncertainty.BootstrapResult.ensemble`): the spread of their
    predictions is the parameters' share; the estimate swum again with ``jitter_draws`` draws of
    the control jitter the experiment declares gives the jitter's share
    (:func:`eelhost.estimation.uncertainty.jitter_variance`); the training residuals' growth is
    the misfit's (:func:`band_radius`). The recording is compared on its own clock.

    Parameters
    ----------
    robot : Robot
    fitted : dict
        Fitted models per motion type, as for :func:`validate`.
    ensembles : dict
        Per fitted set, parameter vectors of its space, shape (M, K), the estimate first.
    growth : dict
        Per fitted set, the misfit growth (c0, c1).
    experiments : sequence of Experiment
        The held-out experiments and paths.
    n_samples, backend, level, widen
        Samples per experiment, evaluator backend, the band's level and extra widening.
    dof : dict, optional
        Per fitted set, the degrees of freedom of its misfit's estimate (:func:`band_radius`;
        default: the variance taken as known).
    jitter_draws : int
        Runs per experiment for the declared control jitter's share (0: none).
    seed : int
        Seeds those runs' jitter.

    Returns
    -------
    list of PredictionBand
        In the experiments' order; sets without an ensemble are left out.
    """
    from eelhost.estimation.uncertainty import jitter_variance

    bands: list[PredictionBand] = []
    groups: dict[str, list[Experiment]] = {}
    for exp in experiments:
        key = coefficient_set_for(exp.motion, fitted)
        if key in ensembles:
            groups.setdefault(key, []).append(exp)
    for key, exps in groups.items():
        ev = Evaluator(robot, exps, n_samples=n_samples, backend=backend, space=fitted[key].space)
        sim = ev.simulate(np.atleast_2d(ensembles[key]))
        for j, p in enumerate(ev.prepared):
            pos = sim.positions_m[:, j]  # (M, n, 2)
            centre = pos[0]
            members = pos[1:][~np.isnan(pos[1:]).any(axis=(1, 2))]
            spread = (0.5 * np.mean(np.sum((members - centre) ** 2, axis=-1), axis=0)
                      if len(members) else np.zeros(len(p.times_s)))
            # what the declared control jitter alone does to this run: no parameter set
            # predicts it (a long path circles a waypoint or not with it)
            spread = spread + jitter_variance(robot, fitted[key], p.experiment, p.times_s,
                                              jitter_draws, seed)
            radius = band_radius(spread, p.times_s - p.experiment.t_s[0], growth[key], level,
                                 widen, None if dof is None else dof.get(key))
            gap = np.linalg.norm(p.exp_positions_m - centre, axis=-1)
            inside = np.where(np.isnan(gap), False, gap <= radius)
            bands.append(PredictionBand(p.experiment.name, p.experiment.motion, key, p.times_s,
                                        centre, radius, inside))
    order = {e.name: i for i, e in enumerate(experiments)}
    return sorted(bands, key=lambda b: order[b.name])


def band_coverage(bands: Sequence[PredictionBand]) -> dict[str, float]:
    """Fraction of held-out positions inside their bands, per motion type and ``"all"``."""
    out: dict[str, list[np.ndarray]] = {}
    for b in bands:
        out.setdefault(b.motion, []).append(b.inside)
        out.setdefault("all", []).append(b.inside)
    return {m: float(np.concatenate(v).mean()) for m, v in out.items()}


def bands_markdown(bands: Sequence[PredictionBand], body_length_m: float) -> str:
    """The bands as a table: per experiment, coverage and the radius at the start and end (BL)."""
    lines = ["| experiment | motion | coefficients | positions inside | radius, first sample (BL) "
             "| radius, last sample (BL) |", "|---|---|---|---|---|---|"]
    lines += [f"| {b.name} | {b.motion} | {b.coefficients} | {b.coverage * 100:.0f} % | "
              f"{b.radius_m[0] / body_length_m:.4f} | {b.radius_m[-1] / body_length_m:.4f} |"
              for b in bands]
    return "\n".join(lines)
