"""Does a candidate stay sane between its training gaits? (docs/estimation.md, "Model comparison").

Leave-one-gait-out folds cannot see how a model behaves *between* the training gaits when these
sit at the corners of the gait grid (the paper's design: two amplitudes x two frequencies per
motion). Each fold then holds out a corner and trains on the other three, so every fold tests an
extrapolation and none an interpolation; and every fold still trains on both frequencies. A model
can fit the corners and swim the gaits between them at a wildly wrong speed: on the
`stalling_foil` plant the comparison chose such a model, whose held-out straight runs were 2.1
body lengths off (docs/estimation_benchmarks.md).

The check asks each fitted candidate to swim the **neighbour gaits** of its training gaits: the
midpoint of every edge of the training design (two training gaits that differ in amplitude only
or frequency only, with no training gait between them) and the design's centre (when it varies
both), each with the
task of a training experiment of the same motion. Nothing was recorded there, so the prediction
is compared with what the recordings *bracket*: the mean speed (:func:`eelhost.estimation.speeds
.mean_speed`) of the training gaits it lies between (an edge's two; every training gait of the
motion for the centre). The assumption is the weakest physical one about an undulatory swimmer:
its mean speed varies smoothly and monotonically with amplitude and frequency over a small grid
(Lighthill's elongated-body theory: the speed follows the body wave's speed, proportional to the
frequency; Gray 1933 and Bainbridge 1958 measured fish speeds rising linearly with tail-beat
frequency), so a gait between two recorded gaits swims at a speed between theirs. The candidate's
**excursion** is the worst ratio by which a neighbour's predicted speed leaves its bracket
(1 inside it; ``v / max`` above, ``min / v`` below; infinite for a failed or motionless run).
:func:`eelhost.estimation.selection.recommend` trusts only candidates within :data:`SANE_FACTOR`
of their brackets: twice the faster neighbour's speed or half the slower one's is not a noise
level but a different swimmer.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.data.experiments import Experiment
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.fitness import N_SAMPLES_VALIDATE
from eelhost.estimation.runs import prepare
from eelsim.flags import Failure

SANE_FACTOR = 2.0  # a neighbour gait's predicted speed may leave its bracket by this ratio at most


@dataclass(frozen=True)
class Neighbour:
    """A gait between training gaits, and the training experiments that bracket it.

    Attributes
    ----------
    experiment : Experiment
        The task of the shortest-recorded bracketing experiment with the neighbour's gait (its
        recording is that experiment's and is not compared; its span is the neighbour's).
    bracket : tuple of int
        Positions, in the experiments handed to :func:`neighbour_gaits`, of the training gaits it
        lies between.
    """

    experiment: Experiment
    bracket: tuple[int, ...]


def _gait(exp: Experiment) -> tuple[float, float]:
    return float(exp.scenario.amplitude_rad), float(exp.scenario.omega_rad_s)


def _with_gait(template: Experiment, amplitude: float, omega: float) -> Experiment:
    name = f"{template.motion}_A{amplitude:.3f}_w{omega:.3f} (between training gaits)"
    scenario = template.scenario.model_copy(
        update={"name": name, "amplitude_rad": amplitude, "omega_rad_s": omega})
    return dataclasses.replace(template, name=name, scenario=scenario)


def neighbour_gaits(experiments: Sequence[Experiment]) -> list[Neighbour]:
    """The gaits between the training gaits of each motion (module docstring).

    Per motion: the midpoint of every edge of its training design (two gaits with the same
    amplitude, or the same frequency, and no training gait of that motion between them), then the
    centre of its gaits (bracketed by all of them) unless it is a training gait or an edge's
    midpoint already, when its gaits vary in both amplitude and frequency (a line's edges cover
    its inside). A motion with one training gait has none.

    Parameters
    ----------
    experiments : sequence of Experiment
        Training experiments, of one or several motions.

    Returns
    -------
    list of Neighbour
    """
    out: list[Neighbour] = []
    motions = dict.fromkeys(e.motion for e in experiments)
    for motion in motions:
        idx = [i for i, e in enumerate(experiments) if e.motion == motion]
        gaits = {i: _gait(experiments[i]) for i in idx}
        seen = {gaits[i] for i in idx}
        for a, i in enumerate(idx):
            for j in idx[a + 1:]:
                (ai, wi), (aj, wj) = gaits[i], gaits[j]
                if (ai == aj) == (wi == wj):  # the same gait, or both parts differ: no edge
                    continue
                lo, hi = np.minimum(gaits[i], gaits[j]), np.maximum(gaits[i], gaits[j])
                between = any(np.all(lo <= g) and np.all(g <= hi) and g not in (gaits[i], gaits[j])
                              for g in (gaits[k] for k in idx))
                mid = ((ai + aj) / 2.0, (wi + wj) / 2.0)
                if between or mid in seen:
                    continue
                seen.add(mid)
                out.append(_neighbour(experiments, mid, (i, j)))
        centre = tuple(float(v) for v in np.mean([gaits[i] for i in idx], axis=0))
        spread = np.ptp([gaits[i] for i in idx], axis=0) if idx else np.zeros(2)
        if np.all(spread > 0.0) and centre not in seen:  # a line's edges cover its inside
            out.append(_neighbour(experiments, (centre[0], centre[1]), tuple(idx)))
    return out


def _neighbour(experiments: Sequence[Experiment], gait: tuple[float, float],
               bracket: tuple[int, ...]) -> Neighbour:
    # the shortest recording of the bracket (the fastest swimmer's, on a task that ends at its
    # goal) is the template: a neighbour that swims no faster than its bracket is compared
    # before it reaches the goal, not while it circles there (where a fast model's joints may
    # collide, and nothing was ever recorded)
    template = min(bracket, key=lambda i: experiments[i].span_s[1] - experiments[i].span_s[0])
    return Neighbour(_with_gait(experiments[template], *gait), bracket)


def bracket_excursion(predicted_m_s: float, bracket_m_s: Sequence[float]) -> float:
    """The ratio by which a predicted speed leaves the bracket of recorded speeds (1: inside).

    Parameters
    ----------
    predicted_m_s : float
        NaN for a failed run.
    bracket_m_s : sequence of float
        The bracketing training gaits' recorded mean speeds.

    Returns
    -------
    float
        ``v / max`` above the bracket, ``min / v`` below it, 1 inside; inf for a failed run or
        one that does not move.
    """
    lo, hi = float(np.min(bracket_m_s)), float(np.max(bracket_m_s))
    v = float(predicted_m_s)
    if not np.isfinite(v) or v <= 0.0:
        return float("inf")
    return max(1.0, v / hi, lo / v)


def neighbour_excursion(ev: Evaluator, values: np.ndarray) -> float:
    """The worst excursion of one candidate's predictions between its training gaits.

    ``ev`` is the candidate's evaluator on its training experiments (its robot, space and
    backend); ``values`` its fit. The neighbour gaits are simulated once each (their runs are
    added to ``ev``'s counts), the recorded and predicted mean speeds taken over
    :data:`~eelhost.estimation.fitness.N_SAMPLES_VALIDATE` samples of each run's span.

    Parameters
    ----------
    ev : Evaluator
    values : ndarray, shape (K,)

    Returns
    -------
    float
        1.0 when the design has no neighbour gait (nothing to check).
    """
    from eelhost.estimation.speeds import mean_speed

    training = [p.experiment for p in ev.prepared]
    neighbours = neighbour_gaits(training)
    if not neighbours:
        return 1.0
    recorded = []
    for exp in training:
        p = prepare(exp, N_SAMPLES_VALIDATE)
        recorded.append(mean_speed(p.times_s, p.exp_positions_m))
    near = copy.copy(ev)
    near.n_samples = N_SAMPLES_VALIDATE
    near.prepared = near.prepare_like([n.experiment for n in neighbours])
    near.backend = ev.backend.fresh()
    near.simulations, near.steps = 0, 0
    sim = near.simulate(np.asarray(values, float)[None, :])
    ev.count_from(near)
    # a failure after the run's arrival and its last sample does not count (it circles its goal
    # where nothing is compared); too slow to reach the goal in time is a speed, which is what is
    # compared; a run that blew up or collided with itself before its last sample has none
    counted = sim.counted_failure(near.prepared)
    worst = 1.0
    for j, (n, p) in enumerate(zip(neighbours, near.prepared, strict=True)):
        pos = sim.positions_m[0, j]
        broken = int(counted[0, j]) not in (int(Failure.NONE), int(Failure.TOO_SLOW))
        failed = broken or bool(np.isnan(pos).any())
        v = float("nan") if failed else mean_speed(p.times_s, pos)
        worst = max(worst, bracket_excursion(v, [recorded[i] for i in n.bracket]))
    return worst
