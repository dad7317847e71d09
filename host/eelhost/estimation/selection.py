"""Which candidate model to trust: leave-one-gait-out cross-validation (docs/estimation.md).

A candidate model is a joint model with a fluid law (:func:`eelhost.estimation.parameters.spaces_of`):
the robot's joint model with each of the twin's candidate laws (``eelsim.fluid.candidate_laws``),
and each other joint model of the twin with the robot's law, on the joints of the bundled robot
file that uses it; when another joint model predicts best, it is then tried with every law (a
step of a search over the joint model x law grid: the robot file's own joint model is tried with
every law from the start, so a second step is only paid for where the joints are wrong). For
each fit (straight, turning)
every training experiment, one gait (amplitude, frequency), is held out in turn: the candidate is
refitted on the others and scored on the held-out one by the fitness's per-experiment error
(docs/estimation.md, "Fitness"). A model that only fits better because it has more freedom to
absorb the training gaits' noise or the plant's missing physics predicts held-out gaits worse.

Each refit is the minimax polish (:func:`eelhost.estimation.local.polish_minimax`) started from
the candidate's fit on all training experiments; that fit itself starts from the main fit's
parameters carried over by name (:func:`carry_over`) and is polished, so every candidate costs
a few hundred simulations per fold instead of a global search; where the carried-over parameters
fail in the candidate (the ``galilean`` law's reactive terms make the robot swim at less than half
the speed with table 3's coefficients), the candidate gets a global fit of its own with the main
fit's method. The warm start is shared by all candidates alike; it favours none.

The recommendation is the candidate with the lowest mean held-out error over all folds of all
fits; one within ``TIE`` of it with fewer parameters is preferred (the simpler model predicts as
well).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from eelhost.data.experiments import Dataset
from eelhost.estimation.evaluate import EstimationError, Evaluator
from eelhost.estimation.local import FAILED, polish_minimax
from eelhost.estimation.methods import FitProblem, run_fit
from eelhost.estimation.parameters import ParameterSpace, joint_model_name, spaces_of
from eelhost.estimation.pipeline import FitSettings, training_experiments

log = logging.getLogger(__name__)

TIE = 0.02  # relative: held-out errors this close count as equal
POLISH_ITERATIONS = 12


def carry_over(values: Mapping[str, float], space: ParameterSpace, default: np.ndarray) -> np.ndarray:
    """A start in ``space`` from another model's parameters, by name.

    A name the other model has is taken as it is; a law's split coefficient (``C_f_lin``,
    ``C_f_quad``) takes its unsplit one (``C_f``), the ``galilean`` law being the split law with
    both equal (from the paper's law this is only a start: the split law adds the reactive
    terms); anything else keeps ``default``. The result is clipped to the bounds.

    Parameters
    ----------
    values : mapping of str to float
    space : ParameterSpace
    default : ndarray, shape (K,)

    Returns
    -------
    ndarray, shape (K,)
    """
    out = np.array(default, dtype=float)
    for i, name in enumerate(space.names):
        base = name.rsplit("_", 1)[0] if name.endswith(("_lin", "_quad")) else name
        if name in values:
            out[i] = values[name]
        elif base in values:
            out[i] = values[base]
    b = space.bounds
    return np.clip(out, b[:, 0], b[:, 1])


@dataclass
class CandidateScore:
    """One candidate model's cross-validation.

    Attributes
    ----------
    model : str
        "<joint model> x <fluid law>".
    parameters : int
        Its parameter count.
    fitness : dict of str to float
        Its fitness on all training experiments, per fit.
    held_out : dict of str to ndarray
        Per fit, the error of each held-out gait (in training order).
    simulations : int
    space : ParameterSpace or None
        The candidate's parameter space (what a refit with it fits).
    values : dict of str to ndarray
        Per fit, its parameters fitted on all training experiments (a refit's start).
    """

    model: str
    parameters: int
    fitness: dict[str, float] = field(default_factory=dict)
    held_out: dict[str, np.ndarray] = field(default_factory=dict)
    simulations: int = 0
    space: ParameterSpace | None = None
    values: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def mean_held_out(self) -> float:
        """Mean held-out error over every fold of every fit."""
        return float(np.mean(np.concatenate(list(self.held_out.values()))))

    @property
    def worst_held_out(self) -> float:
        """Largest held-out error."""
        return float(np.max(np.concatenate(list(self.held_out.values()))))


def recommend(scores: Sequence[CandidateScore]) -> CandidateScore:
    """The candidate to trust (module docstring): lowest mean held-out error, ties to the simpler."""
    best = min(scores, key=lambda c: c.mean_held_out)
    close = [c for c in scores if c.mean_held_out <= best.mean_held_out * (1 + TIE)]
    return min(close, key=lambda c: (c.parameters, c.mean_held_out))


def cross_validate(
    dataset: Dataset,
    fitted: Mapping[str, tuple[ParameterSpace, np.ndarray]],
    settings: FitSettings,
    laws: Sequence[str] | None = None,
    iterations: int = POLISH_ITERATIONS,
    say: Callable[[str], None] | None = None,
    joint_models: Sequence[str] | None = None,
) -> list[CandidateScore]:
    """Leave-one-gait-out cross-validation of the candidate models (module docstring).

    Parameters
    ----------
    dataset : Dataset
    fitted : mapping
        Per fit ("straight", "turning"), the main fit's space and parameters.
    settings : FitSettings
        The evaluator's backend and clock search.
    laws : sequence of str, optional
        Fluid laws to try with the robot's joint model (default: the twin's candidate laws).
    iterations : int
        Polish iterations per refit.
    say : callable, optional
        Gets a line per candidate.
    joint_models : sequence of str, optional
        Joint models to try besides the robot's, each with its fluid law (default: every one
        the twin has; :func:`eelhost.estimation.parameters.spaces_of`). When one of them
        predicts best, it is then tried with each of ``laws`` too.

    Returns
    -------
    list of CandidateScore
        In the order of the candidates (those of the second step last).

    Raises
    ------
    EstimationError
        When a fit has fewer than two training experiments.
    """
    from eelsim.fluid import candidate_laws, get_fluid_law

    robot = dataset.robot
    laws = list(laws) if laws is not None else list(candidate_laws())
    # every candidate fits the tank's ambient current when the main fits do: compared on equal terms
    current = any(space.current for space, _ in fitted.values())
    for motion in fitted:
        if len(training_experiments(dataset, motion)) < 2:
            raise EstimationError(
                f"cross-validation of {motion!r} needs two training experiments or more"
            )
    scores = [_score(dataset, space, fitted, settings, iterations)
              for space in spaces_of(robot, laws, current, joint_models)]
    for score in scores:
        _said(score, say)
    best = recommend(scores)
    if best.space is not None and best.space.joints.model != joint_model_name(robot):
        # another joint model predicts better: try it with every other law too (one step of a
        # search over the joint model x law grid), started from its own fit
        tried = {score.model for score in scores}
        start = {m: (best.space, best.values[m]) for m in fitted}
        for law in laws:
            space = ParameterSpace(get_fluid_law(law), best.space.joints, current=current)
            if space.model_name not in tried:
                scores.append(_score(dataset, space, start, settings, iterations))
                _said(scores[-1], say)
    return scores


def _said(score: CandidateScore, say: Callable[[str], None] | None) -> None:
    log.info("%s: mean held-out error %.4g", score.model, score.mean_held_out)
    if say:
        say(f"cross-validation: {score.model}: mean held-out error {score.mean_held_out:.4f}")


def _score(
    dataset: Dataset,
    space: ParameterSpace,
    fitted: Mapping[str, tuple[ParameterSpace, np.ndarray]],
    settings: FitSettings,
    iterations: int,
) -> CandidateScore:
    """One candidate's fit on all training experiments and its leave-one-gait-out errors."""
    robot = dataset.robot
    score = CandidateScore(space.model_name, space.size, space=space)

    def evaluator(chosen: list) -> Evaluator:
        return Evaluator(robot, chosen, backend=settings.backend, align_s=settings.align_s,
                         space=space)

    for motion, (main_space, main_values) in fitted.items():
        exps = training_experiments(dataset, motion)
        full_ev = evaluator(exps)
        start = carry_over(main_space.as_dict(main_values), space, space.start(robot))
        full = polish_minimax(full_ev.evaluate, space, start, iterations)
        if full.fitness >= FAILED:
            # the carried-over parameters fail in this model (e.g. it swims slower): a global
            # fit of its own, as the main fit was made
            log.info("%s, %s: carried-over start fails; fitting globally", space.model_name,
                     motion)
            full = run_fit(FitProblem(full_ev, settings, start))
        score.fitness[motion] = full.fitness
        score.values[motion] = np.asarray(full.values, dtype=float)
        score.simulations += full_ev.simulations
        errors = []
        for j, held in enumerate(exps):
            fold_ev = evaluator([e for i, e in enumerate(exps) if i != j])
            refit = polish_minimax(fold_ev.evaluate, space, full.values, iterations)
            test_ev = evaluator([held])
            errors.append(float(test_ev.errors(refit.values[None])[0, 0]))
            score.simulations += fold_ev.simulations + test_ev.simulations
        score.held_out[motion] = np.array(errors)
    return score


def table_markdown(scores: Sequence[CandidateScore]) -> str:
    """The comparison as a markdown table, the recommended candidate marked."""
    choice = recommend(scores)
    motions = list(scores[0].held_out)
    head = ("| model | parameters | " + " | ".join(f"fitness {m}" for m in motions)
            + " | mean held-out error | worst held-out error | simulations |")
    lines = [head, "|---|---|" + "---|" * len(motions) + "---|---|---|"]
    for c in scores:
        mark = " (recommended)" if c is choice else ""
        lines.append(
            f"| {c.model}{mark} | {c.parameters} | "
            + " | ".join(f"{c.fitness[m]:.4f}" for m in motions)
            + f" | {c.mean_held_out:.4f} | {c.worst_held_out:.4f} | {c.simulations} |"
        )
    return "\n".join(lines)
