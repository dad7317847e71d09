"""Intervals that hold: bootstraps of the declared noise and of the fit's misfit (docs/estimation.md).

The fitted model stands in for the robot: each replicate records the training experiments again
from it, through the noise the dataset declares, and refits; the spread of the refits is the
spread an estimate from data like these has, *if the model were right and the declaration
complete*. Neither need hold (issue 32: a dataset declaring no jitter gave every refit the same
data and intervals of zero width), so the fit's own residuals are resampled too.

- **Regenerated recordings** (:func:`regenerate`): the fitted model runs every training task in
  the batched kernel with a new seeded control-period jitter (the timing's ``jitter_s``), is seen
  through the recording's camera (its frame rate, pixel rounding, median filter causal or
  centred), and is read at the recording's own frame times shifted by a new clock offset drawn
  uniformly within the declared ``timestamp_jitter_s``.
- **Residual replicates** (:func:`misfit_replicates`): the fit's noise-free view of each training
  recording (:func:`model_views`) plus a residual curve times a random weight per experiment
  (Webb's six-point weights): a wild cluster bootstrap, each experiment a cluster, so the
  residuals' correlation in time is kept. It needs no declaration: what the model misses
  (misfit, undeclared clock offsets or jitter) is in the residuals. The curve is the recording
  minus the prediction of the fit *without* that experiment (the cluster jackknife's refit):
  with few experiments the fit absorbs much of its in-sample residuals (six parameters, four
  curves), and resampling those gave a tenth of the estimate's error (measured on the
  zero-jitter copy of the bundled dataset: straight C_d's spread 0.007, its error 0.063; with
  the leave-one-out curves 0.05). The jackknife's own spread is reported, not used: a minimax
  fit is not smooth in its data, and its leave-one-out refits jumped (C_d +-50 % on one seed).
- **Refits** (:func:`parametric_bootstrap`): the minimax polish from the estimate, all
  replicates in lock step (one batch per iteration).
- **The noise floor**: the fitness the declared-noise refits reach, each on its regenerated data:
  what a model that contains the plant reaches from data with this noise. A fit whose fitness
  is far above it is dominated by model error the noise does not explain; the noise refits'
  spread is widened by the excess, the ratio of its fitness to the floor's median (at least 1).
- **Intervals**: the estimate +- the wider of the two bootstraps' spreads (each times its
  Student quantile and ``widen``), never narrower than the linearised standard error
  (:mod:`eelhost.estimation.identify`, whose residual variance is never below the pixel
  rounding's), cut to the search bounds; a parameter the data does not identify gets its whole
  search range, since refits from the estimate stay near it however little the data constrains
  it. ``widen`` is the factor the coverage benchmark (``eelbot estimate-bench --coverage``)
  measured to be needed for the 95 % intervals to cover the truth in at least 90 % of synthetic
  tanks whose model contains it.
- **Valleys that fit alike** (:func:`search_valleys`, :func:`profile_targets`): refits from the
  estimate stay in its valley, so the recordings are also refitted from other starts (the other
  motions' fits, points spread over the bounds), and points on lines from the estimate, along
  each parameter's trade with the others and on profiles (a parameter held, the others
  polished) are judged against a fitness threshold set by the bootstrap (:func:`fitness_threshold`:
  what a refit gains on data from the estimate, a test inversion). The interval holds every
  point within it; a parameter another valley puts outside the local interval is reported as not
  identified (docs/estimation.md, "Uncertainty", "Valleys that fit alike").
- **A held current** (:func:`held_current_shift`): a fit that holds the tank's current within
  its interval (:mod:`eelhost.estimation.tank_current`) gets that interval as the current's,
  and each other parameter's half-width grows in quadrature by how far it moves when the current
  is put at the interval's ends (docs/estimation.md, "Uncertainty").
- **Prediction bands** (:func:`eelhost.estimation.validate.prediction_bands`) swim the estimate
  and every refit (:meth:`BootstrapResult.ensemble`), add the declared control jitter's spread
  of the held-out run (:func:`jitter_variance`) and the misfit's growth along a recording
  (:func:`misfit_growth` of each training experiment predicted by the fit without it).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eelhost.data.experiments import Experiment
from eelhost.estimation.coefficients_file import FittedModel
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.local import polish_minimax_many
from eelhost.estimation.space import ParameterSpace
from eelsim.camera import CameraModel, observation_steps, observed_positions
from eelsim.closed_loop import LoopOptions
from eelsim.robot import Robot
from eelsim.timing import LoopTiming

log = logging.getLogger(__name__)

LEVEL = 0.95
# Interval widening measured by the coverage benchmark (docs/estimation_coverage.md): over 20
# seeds with the ambient current fitted, C_f, C_d and C_a were covered in 95 % of the seeds at
# 1.0, the current's x component in 85 %; 1.05 is the factor that component needed for 90 %.
WIDEN = 1.05
# Half-range of a held current component pinned at its interval's end (held_current_shift), m/s.
PINNED_M_S = 1e-6
# Starts spread over the search bounds (scrambled Sobol points) from which the fit's own data are
# refitted to look for other valleys, besides the starts the caller gives (the other motions'
# fits): docs/estimation.md, "Uncertainty", "Valleys that fit alike".
SPREAD_STARTS = 4
# Points tried on each line from the estimate (to each start and each valley found), as
# fractions of the way.
LINE_FRACTIONS = (1 / 6, 1 / 3, 1 / 2, 2 / 3, 5 / 6, 1.0)
# Points tried along the bootstrap refits' principal axis, in its standard deviations.
AXIS_STEPS = (-16.0, -8.0, -4.0, -2.0, 2.0, 4.0, 8.0, 16.0)


def _record(
    plant: Robot,
    model: FittedModel,
    exp: Experiment,
    offsets: np.ndarray,
    seeds: np.ndarray,
    jitter_s: float,
    camera: CameraModel,
) -> list[np.ndarray | None]:
    """What ``camera`` records of ``model`` swimming ``exp``'s task, once per clock offset.

    The recordings are read at the experiment's own frame times shifted by each offset; the
    control period's jitter is ``jitter_s`` (each run seeded by ``seeds``). None where the model
    failed before the recording ended.
    """
    from eelsim.batch import run_batch

    timing = LoopTiming(
        control_period_s=float(exp.timing.get("control_period_s", 0.3)),
        extra_delay_s=float(exp.timing.get("extra_delay_s", 0.0)),
        jitter_s=jitter_s,
    )
    dt = timing.dt_s
    true_times = [np.maximum(exp.t_s - o, 0.0) for o in offsets]
    steps = np.unique(np.concatenate(
        [observation_steps(t, camera, dt, float(t[-1])) for t in true_times]))
    duration = float(steps[-1] + 2) * dt
    # in the model's tank: its fitted ambient current, if any, adds to the declared one
    scenario = exp.scenario.with_added_current(model.current_m_s).model_copy(
        update={"duration_s": duration, "min_duration_s": 0.0})
    options = LoopOptions(timing=timing, camera=camera, stop_at_goal=False)
    res = run_batch(plant, [scenario] * len(offsets), model.coefficients.as_array(), options,
                    seeds=seeds, sample_steps=steps)
    n = plant.n_links
    out: list[np.ndarray | None] = []
    for b, t in enumerate(true_times):
        states = res.states[b]
        if np.isnan(states).any():
            out.append(None)  # the model failed before the recording ended
            continue
        out.append(observed_positions(t, steps, states[:, n : n + 2], states[:, -2:], camera,
                                      dt, float(t[-1])))
    return out


def regenerate(
    robot: Robot,
    model: FittedModel,
    experiments: Sequence[Experiment],
    replicates: int,
    rng: np.random.Generator,
) -> list[list[Experiment] | None]:
    """Record ``experiments`` again from ``model``, ``replicates`` times, with declared noise.

    Parameters
    ----------
    robot : Robot
        The dataset's robot (the model sets its law, coefficients and joint parameters; its
        ambient current, if fitted, adds to each experiment's).
    model : FittedModel
        What generates the data.
    experiments : sequence of Experiment
        The recordings to imitate (task, camera, timing, frame times, noise declarations).
    replicates : int
    rng : numpy Generator
        Draws the clock offsets and the control-jitter seeds.

    Returns
    -------
    list
        Per replicate, the experiments recorded again (same names and frame times, new
        positions; no heading), or None where the model failed in one of them.
    """
    plant = model.robot(robot)
    out: list[list[Experiment] | None] = [[] for _ in range(replicates)]
    for exp in experiments:
        offsets = rng.uniform(-exp.timestamp_jitter_s, exp.timestamp_jitter_s, replicates)
        seeds = rng.integers(0, 2**31, replicates)
        recorded = _record(plant, model, exp, offsets, seeds,
                           float(exp.timing.get("jitter_s", 0.0)), exp.recording_camera())
        for b, pos in enumerate(recorded):
            kept = out[b]
            if kept is None:
                continue
            if pos is None:
                out[b] = None
                continue
            kept.append(dataclasses.replace(exp, position_m=pos, heading_rad=None,
                                            link_angles_rad=None))
    return out


def model_views(
    robot: Robot, model: FittedModel, experiments: Sequence[Experiment]
) -> list[np.ndarray | None]:
    """The model's noise-free view of each experiment, at its frame times.

    No clock offset, no control jitter, and the recording's camera without its pixel rounding
    (a zero-mean noise of the recording, docs/estimation.md): what the fit predicts the
    recording to be. None where the model failed.

    Parameters
    ----------
    robot : Robot
    model : FittedModel
    experiments : sequence of Experiment

    Returns
    -------
    list of ndarray, shape (F, 2), or None
    """
    plant = model.robot(robot)
    return [_record(plant, model, exp, np.zeros(1), np.zeros(1, dtype=np.int64), 0.0,
                    dataclasses.replace(exp.recording_camera(), pixel_m=0.0))[0]
            for exp in experiments]


def jitter_variance(
    robot: Robot,
    model: FittedModel,
    exp: Experiment,
    times_s: np.ndarray,
    draws: int = 8,
    seed: int = 0,
) -> np.ndarray:
    """Per-axis variance the declared control jitter alone gives a run of ``exp``'s task.

    The fitted model swims the task ``draws`` times, each with its own draw of the control
    period's jitter the experiment declares (``timing.jitter_s``), seen through the recording's
    camera without pixel rounding and without a clock offset; the variance is half the mean
    squared distance of the runs from the run without jitter, at ``times_s`` (on the recording's
    clock). A long run can part ways with the jitter (a waypoint circled or not): no parameter
    set predicts which, so a prediction band must hold it (docs/estimation.md, "Prediction
    bands").

    Parameters
    ----------
    robot : Robot
    model : FittedModel
    exp : Experiment
    times_s : ndarray, shape (n,)
        Where the variance is wanted (the recording's clock).
    draws : int
    seed : int
        Seeds the jitter draws.

    Returns
    -------
    ndarray, shape (n,)
        m^2; zeros when the experiment declares no jitter or the model fails without it.
    """
    times_s = np.asarray(times_s, dtype=float)
    jitter_s = float(exp.timing.get("jitter_s", 0.0))
    if jitter_s <= 0 or draws < 1:
        return np.zeros(len(times_s))
    plant = model.robot(robot)
    camera = dataclasses.replace(exp.recording_camera(), pixel_m=0.0)
    centre = _record(plant, model, exp, np.zeros(1), np.zeros(1, dtype=np.int64), 0.0, camera)[0]
    if centre is None:
        return np.zeros(len(times_s))
    runs = _record(plant, model, exp, np.zeros(draws),
                   np.random.default_rng([seed, 17]).integers(0, 2**31, draws), jitter_s, camera)
    # a run that fails is as far as the run goes: left out
    kept = [r for r in runs if r is not None]
    if not kept:
        return np.zeros(len(times_s))
    half_sq = 0.5 * np.mean([np.sum((r - centre) ** 2, axis=1) for r in kept], axis=0)
    return np.interp(times_s, exp.t_s, half_sq)


def webb_weights(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Webb's six-point weights of the wild cluster bootstrap.

    +-sqrt(1/2), +-1, +-sqrt(3/2), each with probability 1/6: mean 0, variance 1, and with four
    clusters 6^4 = 1296 distinct patterns where Rademacher's +-1 gives 16 (Webb 2014, "Reworking
    wild bootstrap based inference for clustered errors"; docs/estimation.md, "Uncertainty").
    """
    values = np.sqrt(np.array([0.5, 1.0, 1.5]))
    return rng.choice(np.concatenate([-values, values]), size=shape)


def misfit_replicates(
    experiments: Sequence[Experiment],
    views: Sequence[np.ndarray],
    replicates: int,
    rng: np.random.Generator,
) -> list[list[Experiment]]:
    """The wild cluster bootstrap's data sets: the fit's view plus reweighted residual curves.

    Each experiment's residual curve (recording minus the fit's view, at every frame) is one
    cluster: a replicate adds it back to the view times one weight (:func:`webb_weights`) per
    experiment and replicate. The curve keeps everything the model misses (misfit, clock offset,
    control jitter, pixels) with its correlation in time; the weight says it might as well have
    been the other way or of another size.

    Parameters
    ----------
    experiments : sequence of Experiment
        The training recordings.
    views : sequence of ndarray, shape (F, 2)
        :func:`model_views` of them (none None).
    replicates : int
    rng : numpy Generator

    Returns
    -------
    list of list of Experiment
    """
    w = webb_weights(rng, (replicates, len(experiments)))
    return [[dataclasses.replace(exp, position_m=view + w[b, e] * (exp.position_m - view),
                                 heading_rad=None, link_angles_rad=None)
             for e, (exp, view) in enumerate(zip(experiments, views, strict=True))]
            for b in range(replicates)]


def misfit_growth(experiments: Sequence[Experiment], views: Sequence[np.ndarray]) -> np.ndarray:
    """How the fit's residuals grow along a recording: (c0, c1) of s^2(t) = c0 + c1 t^2.

    s^2 is the residual's variance per axis (half the squared norm), t the time since the
    recording's first frame, fitted to every frame of the training recordings by non-negative
    least squares: c0 for what does not grow (pixels, clock offsets, the camera), c1 for a
    speed the model gets wrong, whose position error grows with time. The prediction band of a
    held-out trajectory adds it to the parameters' spread (:mod:`eelhost.estimation.validate`).

    Returns
    -------
    ndarray, shape (2,)
        c0 in m^2, c1 in m^2/s^2.
    """
    from scipy.optimize import nnls

    t = np.concatenate([exp.t_s - exp.t_s[0] for exp in experiments])
    s2 = np.concatenate([0.5 * np.sum((exp.position_m - v) ** 2, axis=1)
                         for exp, v in zip(experiments, views, strict=True)])
    a = np.column_stack([np.ones_like(t), t**2])
    coef, _ = nnls(a, s2)
    return np.asarray(coef, dtype=float)


def fitness_threshold(
    noise_drop: np.ndarray, misfit_drop: np.ndarray, excess: float = 1.0,
    level: float = LEVEL,
) -> float:
    """How much worse than the estimate a point may fit and still be one the data allow.

    On each bootstrap replicate the point it was generated from (the estimate) fits worse than
    the replicate's own refit by a drop: what the noise lets a refit gain on data from a known
    point. A point whose fitness on the recordings is within the ``level`` quantile of those
    drops of the estimate's is not rejected by the data (a test inversion: docs/estimation.md,
    "Uncertainty", "Valleys that fit alike"). The declared-noise drops are widened by the fit's
    excess over its noise floor, as their spread is; the residual replicates' drops carry the
    misfit as they are; the larger quantile is the threshold.

    Parameters
    ----------
    noise_drop, misfit_drop : ndarray
        Per replicate, the estimate's fitness on it minus its refit's (non-finite ones, from a
        failed simulation, are left out).
    excess : float
        The fit's fitness over its noise floor (at least 1).
    level : float

    Returns
    -------
    float
        0 when there are no drops.
    """
    parts = []
    for drops, scale in ((noise_drop, excess), (misfit_drop, 1.0)):
        d = np.asarray(drops, dtype=float)
        d = d[np.isfinite(d)]
        if d.size:
            parts.append(scale * float(np.quantile(np.maximum(d, 0.0), level)))
    return max(parts, default=0.0)


@dataclass
class Valleys:
    """What a fit's own data allow beyond the estimate's valley (:func:`search_valleys`).

    Attributes
    ----------
    threshold : float
        The fitness above the estimate's that the data still allow (:func:`fitness_threshold`).
    minima : ndarray, shape (V, K)
        Refits of the recordings from other starts that fit within the threshold and lie
        outside the estimate's own interval in some parameter: other valleys that fit alike.
    minima_fitness : ndarray, shape (V,)
    points : ndarray, shape (P, K)
        Every point tried (the refits, the lines to them and to the starts, the refits'
        principal axis) that fits within the threshold.
    """

    threshold: float
    minima: np.ndarray
    minima_fitness: np.ndarray
    points: np.ndarray

    def widened(
        self, estimate: np.ndarray, half: np.ndarray, bounds: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The interval estimate +- ``half`` grown to hold every allowed point and valley.

        Each other valley gets the estimate's half-width around it (its refits would scatter as
        the estimate's do); the points on the lines are held as they are. Cut to ``bounds``.

        Returns
        -------
        (lower, upper, split) : ndarray, shape (K,) each
            ``split`` says per parameter whether another valley lies outside estimate +- half:
            the data do not tell the valleys apart (the parameter is not identified by them).
        """
        lower, upper = estimate - half, estimate + half
        split = np.zeros(len(estimate), dtype=bool)
        if len(self.minima):
            lower = np.minimum(lower, (self.minima - half).min(axis=0))
            upper = np.maximum(upper, (self.minima + half).max(axis=0))
            split = np.any(np.abs(self.minima - estimate) > half, axis=0)
        if len(self.points):
            lower = np.minimum(lower, self.points.min(axis=0))
            upper = np.maximum(upper, self.points.max(axis=0))
        return np.maximum(lower, bounds[:, 0]), np.minimum(upper, bounds[:, 1]), split


def search_valleys(
    fitness_of: Callable[[np.ndarray], np.ndarray],
    polish: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    estimate: np.ndarray,
    fitness: float,
    threshold: float,
    starts: np.ndarray,
    half: np.ndarray,
    bounds: np.ndarray,
    axis: np.ndarray | None = None,
    coordinates: np.ndarray | None = None,
    trade: np.ndarray | None = None,
) -> Valleys:
    """Other valleys of the fit's data, and points between, that fit within ``threshold``.

    A bootstrap whose refits start from the estimate stays in its valley: where the data let
    parameters trade (the servo model's motor lag against the drags on turning gaits), another
    valley can fit the recordings as well and the refits never see it. So the recordings are
    refitted from ``starts`` (:func:`polish`), and the refits, points on the straight lines from
    the estimate to each start and each refit, points along ``axis``, and points on the lines
    from the estimate towards both bounds of each parameter in ``coordinates``, once with the
    others kept and once with the others moving as they trade against it (``trade``: the
    linearised profile's trace; a parameter the data hold only together with another, such as
    the servo model's motor time constant with its lag, moves far along it only so) are judged
    by their fitness on the recordings: those within ``threshold`` of the estimate's are points the data
    do not reject (an inner approximation of the test-inversion region; docs/estimation.md,
    "Uncertainty", "Valleys that fit alike").

    Parameters
    ----------
    fitness_of : callable
        Points (P, K) -> their fitness on the recordings (P,).
    polish : callable
        Starts (S, K) -> (the refits (S, K), their fitness (S,)).
    estimate : ndarray, shape (K,)
    fitness : float
        The estimate's fitness.
    threshold : float
        :func:`fitness_threshold`.
    starts : ndarray, shape (S, K)
    half : ndarray, shape (K,)
        The estimate's half-widths: a refit farther than this in some parameter is another
        valley.
    bounds : ndarray, shape (K, 2)
    axis : ndarray, shape (K,), optional
        One standard deviation along the bootstrap refits' principal axis; points at
        :data:`AXIS_STEPS` of it are tried.
    coordinates : ndarray of bool, shape (K,), optional
        Parameters moved towards each of their bounds, at :data:`LINE_FRACTIONS` of the way.
    trade : ndarray, shape (K, K), optional
        Row j: how every parameter moves per unit of parameter j along its profile
        (:func:`trade_directions`; row j's own entry 1). Without it the parameters move alone.

    Returns
    -------
    Valleys
    """
    k = len(estimate)
    starts = np.clip(np.atleast_2d(np.asarray(starts, dtype=float)).reshape(-1, k),
                     bounds[:, 0], bounds[:, 1])
    if len(starts):
        minima, minima_fitness = polish(starts)
    else:
        minima, minima_fitness = np.zeros((0, k)), np.zeros(0)
    ends = np.concatenate([starts, minima])
    fractions = np.array(LINE_FRACTIONS)
    lines = (estimate + fractions[None, :, None] * (ends - estimate)[:, None, :]).reshape(-1, k)
    along = (np.zeros((0, k)) if axis is None
             else estimate + np.array(AXIS_STEPS)[:, None] * np.asarray(axis)[None])
    directions = [np.eye(k)] + ([] if trade is None else [np.asarray(trade, dtype=float)])
    alone = [estimate + f * (end - estimate[j]) * d[j]
             for j in (np.flatnonzero(coordinates) if coordinates is not None else [])
             for d in directions if np.isfinite(d[j]).all()
             for end in bounds[j] for f in fractions]
    tried = np.clip(np.concatenate([lines, along, np.reshape(alone, (-1, k))]),
                    bounds[:, 0], bounds[:, 1])
    tried_fitness = fitness_of(tried) if len(tried) else np.zeros(0)
    limit = fitness + threshold
    allowed = np.isfinite(tried_fitness) & (tried_fitness <= limit)
    kept = np.isfinite(minima_fitness) & (minima_fitness <= limit)
    far = np.any(np.abs(minima - estimate) > half, axis=1) if len(minima) else kept
    other = kept & far
    return Valleys(float(threshold), minima[other], minima_fitness[other],
                   np.concatenate([tried[allowed], minima[kept]]))


def profile_targets(
    estimate: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    bounds: np.ndarray,
    free: np.ndarray,
    trade: np.ndarray | None = None,
) -> tuple[list[tuple[int, float]], np.ndarray]:
    """Where to hold each free parameter for a profile polish past its interval's ends.

    For each free parameter and each end of [lower, upper] short of its bound: halfway from
    the end to the bound, and the bound itself; each start has the others moved along their
    trade against it (``trade``, :func:`trade_directions`) where known, cut to the bounds.

    Returns
    -------
    (pins, starts)
        Per profile polish, (index, value), and its start, shape (P, K).
    """
    pins: list[tuple[int, float]] = []
    starts = []
    for j in np.flatnonzero(free):
        span = bounds[j, 1] - bounds[j, 0]
        for reach, end in ((lower[j], bounds[j, 0]), (upper[j], bounds[j, 1])):
            if abs(end - reach) <= 1e-6 * span:
                continue
            for v in (reach + 0.5 * (end - reach), end):
                pins.append((int(j), float(v)))
                starts.append(profile_start(estimate, int(j), float(v), bounds, trade))
    return pins, np.reshape(starts, (-1, len(estimate)))


def profile_start(
    estimate: np.ndarray, j: int, value: float, bounds: np.ndarray,
    trade: np.ndarray | None = None,
) -> np.ndarray:
    """The start of a profile polish holding parameter ``j`` at ``value``.

    The others moved along their trade against it (:func:`trade_directions`) where known, cut
    to the bounds.
    """
    row = (trade[j] if trade is not None and np.isfinite(trade[j]).all()
           else np.eye(len(estimate))[j])
    start = np.clip(estimate + (value - estimate[j]) * row, bounds[:, 0], bounds[:, 1])
    start[j] = value
    return start


def bisect_targets(
    pins: Sequence[tuple[int, float]], allowed: np.ndarray
) -> list[tuple[int, float]]:
    """The second profile round: for each end, between its last allowed and first rejected.

    ``pins`` come in pairs per end, (halfway, bound) as :func:`profile_targets` gives them, and
    ``allowed`` says which fitted within the threshold. An end whose bound fitted is done; one
    whose halfway point fitted tries three quarters of the way, one whose halfway point did not
    a quarter (from the end the interval had).
    """
    out = []
    for k in range(0, len(pins) - 1, 2):
        (j, half), (_, end) = pins[k], pins[k + 1]
        if allowed[k + 1]:
            continue
        reach = 2 * half - end
        out.append((j, (half + end) / 2 if allowed[k] else (reach + half) / 2))
    return out


def trade_directions(samples: np.ndarray, estimate: np.ndarray) -> np.ndarray | None:
    """How the parameters trade against each other, from the bootstrap refits.

    Row j is the regression of every parameter on parameter j over the refits (their second
    moments about the estimate): M[:, j] / M[j, j]. Moving parameter j by t and the others by
    t times the row follows the linearised profile of j (the others at their best for that j,
    if the fitness were quadratic with the refits' covariance). A parameter the refits do not
    move gets a row of nan. None with fewer than two refits.
    """
    if len(samples) < 2:
        return None
    d = samples - estimate
    m = d.T @ d / len(d)
    diag = np.diag(m)
    with np.errstate(divide="ignore", invalid="ignore"):
        rows = np.where(diag[:, None] > 0, m / diag[:, None], np.nan)
    return rows


def spread_starts(bounds: np.ndarray, n: int, seed: int) -> np.ndarray:
    """``n`` starts spread over ``bounds`` (scrambled Sobol points), shape (n, K)."""
    if n < 1:
        return np.zeros((0, len(bounds)))
    from scipy.stats import qmc

    unit = qmc.Sobol(len(bounds), scramble=True, seed=seed).random(n)
    return bounds[:, 0] + unit * (bounds[:, 1] - bounds[:, 0])


def principal_axis(samples: np.ndarray, estimate: np.ndarray, bounds: np.ndarray) -> np.ndarray | None:
    """One standard deviation of ``samples`` about ``estimate`` along their widest direction.

    Measured in the search range's unit cube (so that no parameter's unit dominates), returned
    in the parameters' units; None with fewer than two samples or no spread.
    """
    if len(samples) < 2:
        return None
    span = np.where(bounds[:, 1] > bounds[:, 0], bounds[:, 1] - bounds[:, 0], 1.0)
    centred = (samples - estimate) / span
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    if sv[0] <= 0:
        return None
    return vt[0] * sv[0] / np.sqrt(len(samples) - 1) * span


@dataclass
class BootstrapResult:
    """The bootstrap of one fit: declared noise and the fit's own residuals.

    Attributes
    ----------
    names : tuple of str
    estimate : ndarray, shape (K,)
    samples : ndarray, shape (B, K)
        The refits on data regenerated with the declared noise.
    noise_fitness : ndarray, shape (B,)
        Those refits' fitness, each on its replicate: the noise floor's distribution.
    fitness : float
        The fit's own fitness.
    lower, upper : ndarray, shape (K,)
        The intervals (at ``level``, widened, cut to the bounds).
    level : float
    widen : float
    failed : int
        Replicates left out because the model failed in them.
    misfit_samples : ndarray, shape (B', K)
        The refits of the wild cluster bootstrap over the training experiments' leave-one-out
        residual curves (:func:`misfit_replicates`); empty when the model's noise-free view
        failed.
    growth : ndarray, shape (2,)
        :func:`misfit_growth` (c0 m^2, c1 m^2/s^2) of the training experiments' leave-one-out
        prediction errors (each predicted by its jackknife refit), or of their in-sample
        residuals with fewer than three experiments.
    growth_source : str
        "leave-one-out" or "in-sample".
    experiments : int
        Training experiments of the fit.
    linear_std : ndarray, shape (K,), optional
        The linearised standard errors the interval is never narrower than.
    jackknife : ndarray, shape (E, K)
        The leave-one-experiment-out refits on the recordings (empty with fewer than three):
        their predictions of the experiment left out give the residual curves; their own spread
        is reported (:meth:`jackknife_std`), not used.
    held_shift : ndarray, shape (K,)
        When the fit holds the tank's current within its interval (estimated from every
        motion's experiments, :mod:`eelhost.estimation.tank_current`): how far each parameter
        moves when the current is put at that interval's ends (:func:`held_current_shift`),
        added to the bootstrap's half-width in quadrature. Empty otherwise.
    valleys : Valleys, optional
        The search for other valleys of the recordings (:func:`search_valleys`): the interval
        holds every point it found within the fitness threshold. None when not searched.
    split : ndarray of bool, shape (K,)
        Per parameter, whether another valley that fits within the threshold lies outside the
        local interval: the data do not identify it (:meth:`not_identified`).
    local_lower, local_upper : ndarray, shape (K,)
        The interval before the other valleys widened it (the bootstrap around the estimate
        alone), for comparison.
    """

    names: tuple[str, ...]
    estimate: np.ndarray
    samples: np.ndarray
    noise_fitness: np.ndarray
    fitness: float
    lower: np.ndarray
    upper: np.ndarray
    level: float = LEVEL
    widen: float = WIDEN
    failed: int = 0
    misfit_samples: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    growth: np.ndarray = field(default_factory=lambda: np.zeros(2))
    linear_std: np.ndarray | None = None
    jackknife: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    growth_source: str = "in-sample"
    experiments: int = 0
    held_shift: np.ndarray = field(default_factory=lambda: np.zeros(0))
    valleys: Valleys | None = None
    split: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    local_lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    local_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def not_identified(self) -> list[str]:
        """Parameters another valley fitting within the noise puts outside the local interval."""
        return [n for n, s in zip(self.names, self.split, strict=False) if s]

    @property
    def growth_dof(self) -> int:
        """Degrees of freedom of :attr:`growth`: one less than the experiments behind it."""
        n = len(self.jackknife) if self.growth_source == "leave-one-out" else self.experiments
        return max(1, n - 1)

    @property
    def noise_floor(self) -> float:
        """Median fitness the estimate gets from noise alone."""
        return float(np.median(self.noise_fitness))

    @property
    def excess(self) -> float:
        """The fit's fitness over its noise floor (at least 1): model error noise does not explain."""
        floor = self.noise_floor
        return max(1.0, self.fitness / floor) if floor > 0 else 1.0

    def noise_std(self) -> np.ndarray:
        """Standard deviation of the declared-noise refits, per parameter (0 with fewer than 2)."""
        return _std(self.samples, len(self.names))

    def misfit_std(self) -> np.ndarray:
        """Standard deviation of the residual (wild cluster) refits, per parameter."""
        return _std(self.misfit_samples, len(self.names))

    def jackknife_std(self) -> np.ndarray:
        """The cluster jackknife's standard error: sqrt((E - 1) / E sum_i (x_(i) - x)^2)."""
        e = len(self.jackknife)
        if e < 2:
            return np.zeros(len(self.names))
        return np.sqrt((e - 1) / e * np.sum((self.jackknife - self.estimate) ** 2, axis=0))

    def misfit_dominated(self) -> np.ndarray:
        """Per parameter, whether the residuals set the interval (not the declared noise)."""
        return self.misfit_std() > self.noise_std() * self.excess

    def relative_half_width(self) -> np.ndarray:
        """Half the interval over the estimate's magnitude (inf at 0)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            half = (self.upper - self.lower) / 2
            return np.where(np.abs(self.estimate) > 0, half / np.abs(self.estimate), np.inf)

    def covers(self, truth: np.ndarray) -> np.ndarray:
        """Whether each interval holds the true value."""
        t = np.asarray(truth, dtype=float)
        return (self.lower <= t) & (t <= self.upper)

    def ensemble(self, bounds: np.ndarray | None = None) -> np.ndarray:
        """The estimate and every bootstrap refit: what a prediction band swims.

        Parameters
        ----------
        bounds : ndarray, shape (K, 2), optional
            Search bounds the refits are cut to.

        Returns
        -------
        ndarray, shape (M, K)
            The estimate first.
        """
        parts = [self.estimate[None], self.samples.reshape(-1, len(self.names))]
        if self.misfit_samples.size:
            parts.append(self.misfit_samples)
        out = np.concatenate(parts)
        return out if bounds is None else np.clip(out, bounds[:, 0], bounds[:, 1])

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary, parameters by name."""
        def by_name(v: np.ndarray) -> dict[str, float]:
            return {n: float(x) for n, x in zip(self.names, v, strict=True)}

        return {
            "method": "parametric bootstrap of the declared noise and wild cluster bootstrap of "
                      "the residuals (docs/estimation.md, \"Uncertainty\")",
            "replicates": int(len(self.samples)),
            "misfit_replicates": int(len(self.misfit_samples)),
            "failed_replicates": self.failed,
            "level": self.level,
            "widen": self.widen,
            "noise_floor": self.noise_floor,
            "excess": self.excess,
            "std": by_name(self.noise_std()),
            "misfit_std": by_name(self.misfit_std()),
            "jackknife_std": by_name(self.jackknife_std()),
            "misfit_dominated": [n for n, d in zip(self.names, self.misfit_dominated(),
                                                    strict=True) if d],
            **({"held_current_shift": by_name(self.held_shift)} if self.held_shift.size else {}),
            **({"valleys": {
                "fitness_threshold": self.valleys.threshold,
                "other_valleys": [{"fitness": float(f), "parameters": by_name(v)}
                                  for v, f in zip(self.valleys.minima,
                                                  self.valleys.minima_fitness, strict=True)],
                "allowed_points": int(len(self.valleys.points)),
                "not_identified": self.not_identified(),
            }} if self.valleys is not None else {}),
            "misfit_growth": {"c0_m2": float(self.growth[0]), "c1_m2_s2": float(self.growth[1]),
                              "from": self.growth_source, "dof": self.growth_dof},
            "lower": by_name(self.lower),
            "upper": by_name(self.upper),
        }


def _std(samples: np.ndarray, k: int) -> np.ndarray:
    return samples.std(axis=0, ddof=1) if len(samples) > 1 else np.zeros(k)


def parametric_bootstrap(
    evaluator: Evaluator,
    estimate: np.ndarray,
    fitness: float,
    replicates: int = 20,
    seed: int = 0,
    max_iterations: int = 20,
    widen: float = WIDEN,
    level: float = LEVEL,
    progress: Callable[[str], None] | None = None,
    unidentified: Sequence[str] = (),
    linear_std: np.ndarray | None = None,
    misfit: bool = True,
    starts: Sequence[np.ndarray] = (),
    spread: int = SPREAD_STARTS,
    valleys: bool = True,
    profile: bool = True,
) -> BootstrapResult:
    """Intervals for a fit from refits: the declared noise, and the misfit the noise misses.

    Refitted by the minimax polish from the estimate, each round in lock step:

    1. ``replicates`` data sets recorded again from the fit with the noise the dataset declares
       (:func:`regenerate`; their fitness is the noise floor), and the recordings with each
       experiment left out in turn (the cluster jackknife, with at least three experiments);
    2. ``replicates`` data sets made of the fit's noise-free view plus each experiment's
       leave-one-out residual curve (recording minus the jackknife refit's prediction of it),
       reweighted per experiment (:func:`misfit_replicates`, a wild cluster bootstrap).

    The half-width is ``widen`` x the largest of: t(B - 1) x the noise refits' standard
    deviation x the excess over the noise floor; t(B - 1) x the residual refits' standard
    deviation; z x ``linear_std`` (97.5 % quantiles); cut to the bounds. The declared noise
    alone gave zero width when a dataset declared none (issue 32); the residuals carry whatever
    the model misses, declared or not.

    Parameters
    ----------
    evaluator : Evaluator
        The fit's evaluator (its training experiments, space and settings).
    estimate : ndarray, shape (K,)
        The fitted parameters.
    fitness : float
        Their fitness on the training experiments.
    replicates : int
        B, data sets of each kind.
    seed : int
        Seeds the clock offsets, control jitter and residual weights of the replicates.
    max_iterations : int
        Iterations of each refit's minimax polish.
    widen : float
        Extra widening of every interval (:data:`WIDEN`, measured).
    level : float
        Coverage the intervals aim at.
    progress : callable, optional
        Gets a line when the replicates are recorded.
    unidentified : sequence of str
        Parameters the data does not identify: their interval is the search range.
    linear_std : ndarray, shape (K,), optional
        Linearised standard errors (:attr:`Identifiability.std_error`): the floor of the
        half-widths, so that an interval is never of zero width where the refits all agree.
    misfit : bool
        Include the residual bootstrap (False: the declared noise alone, as before issue 32).
    starts : sequence of ndarray, shape (K,)
        Points of this space to refit the recordings from when looking for other valleys (the
        report gives the other motions' fits).
    spread : int
        Further starts spread over the search bounds (:func:`spread_starts`).
    valleys : bool
        Look for other valleys that fit within the noise and widen the intervals to hold them
        (:func:`search_valleys`; one more round of ``len(starts) + spread`` refits of
        ``2 max_iterations``).
    profile : bool
        With ``valleys``: past each end of each free parameter's interval, refit the others
        with it held halfway to its bound and at its bound (:func:`profile_targets`), then a
        quarter or three quarters of the way as those fitted (:func:`bisect_targets`), and
        hold those that fit within the threshold (two more rounds of up to 4 and 2 polishes
        per free parameter).

    Returns
    -------
    BootstrapResult
    """
    from scipy.stats import norm
    from scipy.stats import t as student_t

    space = evaluator.space
    estimate = np.asarray(estimate, dtype=float)
    model = FittedModel(space, estimate)
    rng = np.random.default_rng(seed)
    experiments = [p.experiment for p in evaluator.prepared]
    recorded = regenerate(evaluator.robot, model, experiments, replicates, rng)
    kept = [r for r in recorded if r is not None]
    failed = replicates - len(kept)
    if failed:
        log.warning("%d of %d bootstrap replicates left out: the model failed in them",
                    failed, replicates)
    n_exp = len(experiments)

    def refit(problems: list[tuple[list, np.ndarray]], in_space: ParameterSpace = space,
              start: np.ndarray = estimate, iterations: int = max_iterations,
              pins: Sequence[tuple[int, float]] = ()) -> tuple[np.ndarray, np.ndarray]:
        """Minimax polish of each (prepared data, experiments kept) from ``start``.

        ``start`` is one point for all, or one per problem. ``pins`` (one (index, value) per
        problem, or none) holds a parameter of each problem at a value: the polish of the
        others is a profile's. Returns the refits (P, K) and their fitness on their own data
        (P,).
        """
        if not problems:
            return np.zeros((0, space.size)), np.zeros(0)

        def pinned(asked: list[np.ndarray]) -> list[np.ndarray]:
            out = [a.copy() for a in asked]
            for a, (j, v) in zip(out, pins, strict=True):
                a[:, j] = v  # the polish sees no slope along it and cannot move it
            return out

        def evaluate(asked: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
            if pins:
                asked = pinned(asked)
            sizes = [len(a) for a in asked]
            sim = evaluator.simulate(np.concatenate(asked))
            out, at = [], 0
            for size, (prep, keep) in zip(sizes, problems, strict=True):
                part = sim.take(slice(at, at + size))
                out.append((evaluator.errors_of(part, prep)[:, keep],
                            evaluator.residual_vectors_of(part, prep)[:, keep]))
                at += size
            return out

        fits = polish_minimax_many(evaluate, in_space,
                                   np.broadcast_to(start, (len(problems), space.size)).copy(),
                                   iterations)
        values = [r.values[None] for r in fits]
        if pins:
            values = pinned(values)
        return (np.concatenate(values).reshape(-1, space.size),
                np.array([r.fitness for r in fits]))

    # round 1: the declared noise's replicates and, on the recordings themselves, each
    # experiment left out in turn (the cluster jackknife)
    everything = np.ones(n_exp, dtype=bool)
    drops = list(range(n_exp)) if misfit and n_exp >= 3 else []
    if progress:
        progress(f"bootstrap: {len(kept)} replicates recorded, refitting them and "
                 f"{len(drops)} leave-one-out fits")
    noise_data = [evaluator.prepare_like(r) for r in kept]
    first, first_fitness = refit([(d, everything) for d in noise_data]
                                 + [(evaluator.prepared, np.arange(n_exp) != i) for i in drops])
    # the refits' fitness on their own replicates: the noise floor
    boot = BootstrapResult(space.names, estimate, first[: len(kept)], first_fitness[: len(kept)],
                           float(fitness), estimate.copy(), estimate.copy(), level, widen,
                           failed, linear_std=None if linear_std is None
                           else np.asarray(linear_std),
                           jackknife=first[len(kept):], experiments=n_exp)
    wild_data: list[list] = []
    wild_fitness = np.zeros(0)
    if misfit:
        # round 2: the wild cluster bootstrap of the residual curves. Each experiment's curve is
        # its recording minus the prediction of the fit without it (leave-one-out), when there
        # is a jackknife: the fit has absorbed part of its in-sample residuals (six parameters,
        # four curves), and resampling those alone gave a tenth of the spread the estimate has
        # (docs/estimation.md, "Uncertainty")
        views = model_views(evaluator.robot, model, experiments)
        loo: list[np.ndarray | None] = list(views)
        if len(drops) == n_exp:
            loo = [model_views(evaluator.robot, FittedModel(space, boot.jackknife[i]),
                               [experiments[i]])[0] for i in drops]
        if any(v is None for v in views):
            log.warning("the fit fails within a training recording: no residual bootstrap")
        else:
            if any(v is None for v in loo):
                loo = list(views)  # a leave-one-out fit fails there: the in-sample residuals
            else:
                boot.growth_source = "leave-one-out" if len(drops) == n_exp else "in-sample"
            residual_views = [v for v in loo if v is not None]
            boot.growth = misfit_growth(experiments, residual_views)
            shifted = [dataclasses.replace(exp, position_m=exp.position_m - r + v)
                       for exp, r, v in zip(experiments, residual_views,
                                            [v for v in views if v is not None], strict=True)]
            # recording - loo view + fit view = fit view + residual: reweighted around the view
            wild = misfit_replicates(shifted, [v for v in views if v is not None], replicates,
                                     np.random.default_rng([seed, 32]))
            wild_data = [evaluator.prepare_like(r) for r in wild]
            boot.misfit_samples, wild_fitness = refit([(d, everything) for d in wild_data])
    # each source's spread times its Student quantile; the widest sets the half-width (the
    # jackknife's own spread is reported, not used: a minimax fit is not smooth in its data, and
    # its leave-one-out refits jumped between the experiments that set the maximum)
    def refit_with_space(in_space: ParameterSpace, start: np.ndarray) -> np.ndarray:
        return refit([(evaluator.prepared, everything)], in_space, start)[0][0]

    def quantile(n: int) -> float:
        return float(student_t.ppf(0.5 + level / 2, n - 1)) if n >= 2 else 0.0

    half = np.maximum.reduce([
        quantile(len(kept)) * boot.noise_std() * boot.excess,
        quantile(len(boot.misfit_samples)) * boot.misfit_std(),
        float(norm.ppf(0.5 + level / 2)) * (np.zeros(space.size) if boot.linear_std is None
                                            else np.nan_to_num(boot.linear_std, posinf=0.0)),
    ]) * widen
    bounds = space.bounds
    held = held_current(space)
    if held.any():
        # the current was estimated from every motion's experiments and is held within its
        # interval: each refit sees the spread of this motion's data around the held value, not
        # the current's own uncertainty, which the coefficients trade against along the swimming
        # axis. That uncertainty is propagated by moving the current to its interval's ends (a
        # 95 % statement, like the half-width) and added in quadrature, as independent sources
        boot.held_shift = held_current_shift(evaluator, estimate, refit_with_space,
                                             max_iterations)
        half = np.hypot(half, boot.held_shift)
    boot.local_lower = np.maximum(estimate - half, bounds[:, 0])
    boot.local_upper = np.minimum(estimate + half, bounds[:, 1])
    if valleys:
        # round 3: the recordings refitted from other starts; the interval holds every valley
        # and every point between that fits within what the noise lets a refit gain
        # (docs/estimation.md, "Uncertainty", "Valleys that fit alike")
        sim0 = evaluator.simulate(estimate[None])
        own = float(evaluator.errors_of(sim0)[0].max())

        def estimate_on(data: list[list]) -> np.ndarray:
            return np.array([evaluator.errors_of(sim0, d)[0].max() for d in data])

        threshold = widen * fitness_threshold(
            estimate_on(noise_data) - first_fitness[: len(kept)],
            estimate_on(wild_data) - wild_fitness, boot.excess, level)
        given = (np.asarray(starts, dtype=float).reshape(-1, space.size) if len(starts)
                 else np.zeros((0, space.size)))
        tried = np.concatenate([given, spread_starts(bounds, spread, seed)])
        if progress:
            progress(f"bootstrap: refitting the recordings from {len(tried)} other starts")

        def polish_from(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return refit([(evaluator.prepared, everything)] * len(points), space, points,
                         2 * max_iterations)

        refits = np.concatenate([boot.samples.reshape(-1, space.size),
                                 boot.misfit_samples.reshape(-1, space.size)])
        free = ~(held_current(space) | np.isin(np.array(space.names), list(unidentified)))
        trade = trade_directions(refits, estimate)
        reference = min(own, float(fitness))
        boot.valleys = search_valleys(
            evaluator.fitness, polish_from, estimate, reference, threshold, tried,
            half, bounds, principal_axis(refits, estimate, bounds), coordinates=free,
            trade=trade)
        boot.lower, boot.upper, boot.split = boot.valleys.widened(estimate, half, bounds)
        if profile:
            # round 4: past each end the search reached, the others polished with the parameter
            # held (a profile), halfway to its bound and at it; then a quarter or three quarters
            # of the way, as those fitted
            pins, pin_starts = profile_targets(estimate, boot.lower, boot.upper, bounds, free,
                                               trade)
            if progress and pins:
                progress(f"bootstrap: {len(pins)} profile polishes")
            for opening in (True, False):
                moved, moved_fitness = refit([(evaluator.prepared, everything)] * len(pins),
                                             space, pin_starts, max_iterations, pins=pins)
                allowed = np.isfinite(moved_fitness) & (moved_fitness <= reference + threshold)
                boot.valleys.points = np.concatenate([boot.valleys.points, moved[allowed]])
                if opening:  # once more, between each end's last allowed and first rejected
                    pins = bisect_targets(pins, allowed)
                    pin_starts = np.reshape([profile_start(estimate, j, v, bounds, trade)
                                             for j, v in pins], (-1, space.size))
            boot.lower, boot.upper, boot.split = boot.valleys.widened(estimate, half, bounds)
    else:
        boot.lower, boot.upper = boot.local_lower.copy(), boot.local_upper.copy()
        boot.split = np.zeros(space.size, dtype=bool)
    # the held current's own interval is the tank's (its bounds here): this motion alone says
    # no more about it than every experiment together did
    whole = np.isin(np.array(space.names), list(unidentified))
    for lo, hi in ((boot.lower, boot.upper), (boot.local_lower, boot.local_upper)):
        lo[held | whole], hi[held | whole] = bounds[held | whole, 0], bounds[held | whole, 1]
    boot.split[held | whole] = False
    return boot


def held_current(space: ParameterSpace) -> np.ndarray:
    """Per parameter of ``space``, whether it is the current held within the tank's interval."""
    mask = np.zeros(space.size, dtype=bool)
    if space.current and space.current_bounds is not None:
        mask[-len(space.current_names):] = True
    return mask


def held_current_shift(
    evaluator: Evaluator,
    estimate: np.ndarray,
    refit: Callable[[ParameterSpace, np.ndarray], np.ndarray],
    max_iterations: int,
) -> np.ndarray:
    """How far each parameter moves when the held current is put at its interval's ends.

    For each component of the current and each end of its held interval, the other parameters
    are refitted (the minimax polish from the estimate, ``max_iterations``) with the current
    fixed there; a component's shift is the larger of its two ends', and the components' shifts
    add in quadrature. The current's own entries are its interval's half-widths.

    Parameters
    ----------
    evaluator : Evaluator
        The fit's evaluator, in the held space.
    estimate : ndarray, shape (K,)
    refit : callable
        (space, start) -> the polished vector in that space (the bootstrap's refit).
    max_iterations : int

    Returns
    -------
    ndarray, shape (K,)
    """
    space = evaluator.space
    held = np.flatnonzero(held_current(space))
    bounds = space.bounds
    shifts = np.zeros((len(held), space.size))
    for row, i in enumerate(held):
        for end in bounds[i]:
            start = estimate.copy()
            start[i] = end
            # this component within a micrometre per second of the end (fixed, for a polish
            # whose unit cube needs a range to divide by), the other free within its interval
            pinned = np.array(bounds[held], dtype=float)
            pinned[row] = [end - PINNED_M_S, end + PINNED_M_S]
            fixed = dataclasses.replace(space, current_bounds=pinned)
            moved = refit(fixed, start)
            shifts[row] = np.maximum(shifts[row], np.abs(moved - estimate))
    shift = np.sqrt(np.sum(shifts**2, axis=0))
    shift[held] = (bounds[held, 1] - bounds[held, 0]) / 2
    return shift
