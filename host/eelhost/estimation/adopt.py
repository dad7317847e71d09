"""Fit a dataset with the model its own comparison recommends (docs/estimation.md, "Model choice").

The robot file names a joint model and a fluid law; a real tank may follow neither. The
leave-one-gait-out comparison (:mod:`eelhost.estimation.selection`) then scores every
candidate of the joint model x law grid, each fitted from its own starts, on gaits it was not
fitted to, with separate straight and turning sets and with one set for every motion. When it
recommends another model, that model is fitted again with the full method; the better of that
fit and the comparison's is kept, and these fits are the ones reported and validated. The robot
file's fits are kept beside them, so a reader sees what the choice changed. Nothing of the choice
starts from the robot file's values, so the same tank gives the same model from either bundled
robot file.

A model is adopted only on the held-out evidence, never on the training fitness: a richer model
always fits its training gaits at least as well, and the comparison prefers the simpler one within
``selection.TIE`` or one standard error of the folds (``selection.recommend``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from eelhost.data.experiments import Dataset
from eelhost.estimation.evaluate import Evaluator, simulations_counter
from eelhost.estimation.methods import FitSettings
from eelhost.estimation.optimise import FitResult
from eelhost.estimation.pipeline import fit_motion
from eelhost.estimation.selection import ONE_SET, CandidateScore, cross_validate, recommend
from eelhost.estimation.space import ParameterSpace
from eelhost.progress import phase

log = logging.getLogger(__name__)

Fit = Callable[[str, "ParameterSpace | None", "np.ndarray | None"], tuple[FitResult, Evaluator]]
"""(motion, space or None for the robot file's model, start or None) -> (result, evaluator)."""

FitMany = Callable[[Sequence[tuple[str, "ParameterSpace | None", "np.ndarray | None"]]],
                   list[tuple[FitResult, Evaluator]]]
"""Several :data:`Fit` asks at once (the report's runs them in worker processes), in order."""


@dataclass
class ChosenFits:
    """A dataset's fits with the model chosen for it.

    Attributes
    ----------
    fits : dict of str to FitResult
        Per motion, the fit of the chosen model (the one to report and validate).
    evaluators : dict of str to Evaluator
        Per motion, the evaluator of that fit (its training experiments in its space).
    comparison : list of CandidateScore or None
        The candidates' cross-validation (None: not compared).
    robot_file_fits : dict of str to FitResult or None
        The robot file's model's fits when another model was adopted, else None.
    """

    fits: dict[str, FitResult]
    evaluators: dict[str, Evaluator]
    comparison: list[CandidateScore] | None = None
    robot_file_fits: dict[str, FitResult] | None = None

    @property
    def model(self) -> str:
        """The chosen model's name ("<joint model> x <fluid law>", ", one set" for one set)."""
        name = next(iter(self.fits.values())).space.model_name
        return f"{name}, {ONE_SET}" if set(self.fits) == {"joint"} else name

    @property
    def adopted(self) -> bool:
        """Whether the chosen model is another than the robot file's."""
        return self.robot_file_fits is not None


def fit_and_choose(
    dataset: Dataset,
    motions: Sequence[str],
    settings: FitSettings,
    compare: bool = True,
    adopt: bool = True,
    fit: Fit | None = None,
    say: Callable[[str], None] | None = None,
    laws: Sequence[str] | None = None,
    joint_models: Sequence[str] | None = None,
    fit_many: FitMany | None = None,
) -> ChosenFits:
    """Compare the candidate models, then fit the recommended one with the full method.

    Without the comparison the robot file's model is fitted. With it, the recommended model is
    fitted with the full method (the comparison's own fit kept where lower); when that is not the
    robot file's model, the comparison's fits of the robot file's model are kept beside it.

    Parameters
    ----------
    dataset : Dataset
    motions : sequence of str
        "straight", "turning" and/or "joint" ("joint", one set for every motion, asked for by
        the caller, is fitted with the chosen model; the comparison tries one set for every
        motion on its own and, when it predicts best, fits only that).
    settings : FitSettings
    compare : bool
        Run the cross-validated comparison (without it the robot file's model is kept).
    adopt : bool
        Refit with the recommended model when it is not the robot file's (otherwise the
        comparison is only reported).
    fit : callable, optional
        Makes one fit (default: :func:`eelhost.estimation.pipeline.fit_motion` with
        ``settings``); the report passes one that keeps checkpoints and shows progress.
    say : callable, optional
        Gets a line per step.
    laws : sequence of str, optional
        The fluid laws the comparison tries (default:
        :func:`eelhost.estimation.selection.default_laws`, the twin's candidate laws and their lift
        variants).
    joint_models : sequence of str, optional
        The joint models it tries (default: those offered by default and the robot file's,
        ``eelsim.joints.default_grid_models``).
    fit_many : callable, optional
        Makes several independent fits at once, e.g. the straight and turning fits side by
        side (default: ``fit`` on each in turn).

    Returns
    -------
    ChosenFits
    """
    say = say or log.info

    def default_fit(motion: str, space: ParameterSpace | None,
                    start: np.ndarray | None) -> tuple[FitResult, Evaluator]:
        return fit_motion(dataset, motion, settings, space=space, start=start)

    fit = fit or default_fit
    own = ParameterSpace.for_robot(dataset.robot, current=settings.fit_current)
    separate = [m for m in motions if m != "joint"]
    if not (compare and separate):
        return _fit_all(fit, fit_many, motions, None, None)
    with phase(f"cross-validation of the candidate models ({', '.join(separate)})",
               simulations_counter()):
        comparison = cross_validate(dataset, separate, settings, laws=laws, say=say,
                                    joint_models=joint_models)
    choice = recommend(comparison)
    if choice is None or choice.space is None:
        say("every candidate model failed its cross-validation: the robot file's model is fitted")
        return replace(_fit_all(fit, fit_many, motions, None, None), comparison=comparison)
    say(f"recommended model: {choice.model}")
    kept = next((c for c in comparison if c.model == own.model_name), None)
    if choice.model == own.model_name or not adopt:
        # the robot file's model: fitted with the full method (the comparison's fit of it kept
        # where lower; with --keep-model, also when another model is recommended)
        return replace(_fit_all(fit, fit_many, motions, None, kept), comparison=comparison)
    say(f"the recommended model {choice.model} is not the robot file's ({own.model_name}): "
        "fitting it")
    chosen = _fit_all(fit, fit_many, ["joint"] if choice.one_set else list(motions), choice.space, choice)
    chosen.comparison = comparison
    if kept is not None and not kept.failed:
        # the robot file's model as the comparison fitted it (from its own starts; the screen's
        # short fits when the screen dropped it, and named so)
        how = ("multi-start (comparison's middle rung)" if kept.middle_rung
               else "multi-start (comparison's screen)" if kept.screened_out
               else "multi-start (comparison)")
        chosen.robot_file_fits = {
            m: FitResult(how, own, v, kept.fitness[m],
                         [(0, kept.fitness[m], kept.simulations)]) for m, v in kept.values.items()}
    else:
        chosen.robot_file_fits = _fit_all(fit, fit_many, motions, None, None).fits
    return chosen


def _fit_all(fit: Fit, fit_many: FitMany | None, motions: Sequence[str],
             space: ParameterSpace | None, choice: CandidateScore | None) -> ChosenFits:
    """Each motion fitted with the full method, the comparison's fit kept where lower.

    The motions' fits are independent: ``fit_many`` (when given) makes them at once.
    """
    asks = [(m, space, choice.values.get(m) if choice is not None else None) for m in motions]
    done = fit_many(asks) if fit_many is not None else [fit(*ask) for ask in asks]
    fits: dict[str, FitResult] = {}
    evaluators: dict[str, Evaluator] = {}
    for motion, (res, evaluators[motion]) in zip(motions, done, strict=True):
        fits[motion] = _lower(res, choice, motion) if choice is not None else res
    return ChosenFits(fits, evaluators)


def _lower(res: FitResult, choice: CandidateScore, motion: str) -> FitResult:
    """The full method's fit, or the comparison's own fit of the model where that is lower.

    Both are fits of the same model to the same training experiments, each from starts that
    owe nothing to the robot file.
    """
    if motion in choice.values and choice.fitness[motion] < res.fitness:
        return replace(res, values=choice.values[motion], fitness=choice.fitness[motion],
                       method=f"{res.method}, comparison's fit kept")
    return res
