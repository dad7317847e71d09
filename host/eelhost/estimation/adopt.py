"""Fit a dataset with the model its own comparison recommends (docs/estimation.md, "Model choice").

The robot file names a joint model and a fluid law; a real tank may follow neither. The fits are
made first with the robot file's model; the leave-one-gait-out comparison
(:mod:`eelhost.estimation.selection`) then scores every candidate model on gaits it was not fitted
to. When it recommends another model, that model is fitted again with the full method (the
comparison's own fit of it is only a short polish from a carried-over start); the better of that
fit and the comparison's is kept, and these fits are the ones reported and validated. The robot file's fits are kept
beside them, so a reader sees what the choice changed.

A model is adopted only on the held-out evidence, never on the training fitness: a richer model
always fits its training gaits at least as well, and the comparison prefers the simpler one within
``selection.TIE``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from eelhost.data.experiments import Dataset
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.optimise import FitResult
from eelhost.estimation.parameters import ParameterSpace
from eelhost.estimation.pipeline import FitSettings, fit_motion
from eelhost.estimation.selection import CandidateScore, cross_validate, recommend
from eelhost.progress import phase

log = logging.getLogger(__name__)

Fit = Callable[[str, "ParameterSpace | None", "np.ndarray | None"], tuple[FitResult, Evaluator]]
"""(motion, space or None for the robot file's model, start or None) -> (result, evaluator)."""


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
        """The chosen model's name ("<joint model> x <fluid law>")."""
        return next(iter(self.fits.values())).space.model_name

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
) -> ChosenFits:
    """Fit each motion, compare the candidate models and refit with the recommended one.

    Parameters
    ----------
    dataset : Dataset
    motions : sequence of str
        "straight", "turning" and/or "joint" ("joint" is refitted with the chosen model but
        takes no part in the comparison, whose folds are gaits of one motion type).
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
        The fluid laws the comparison tries (default: the twin's candidate laws).

    Returns
    -------
    ChosenFits
    """
    say = say or log.info

    def default_fit(motion: str, space: ParameterSpace | None,
                    start: np.ndarray | None) -> tuple[FitResult, Evaluator]:
        return fit_motion(dataset, motion, settings, space=space, start=start)

    fit = fit or default_fit
    fits: dict[str, FitResult] = {}
    evaluators: dict[str, Evaluator] = {}
    for motion in motions:
        fits[motion], evaluators[motion] = fit(motion, None, None)
    separate = {m: (r.space, r.values) for m, r in fits.items() if m != "joint"}
    if not (compare and separate):
        return ChosenFits(fits, evaluators)
    with phase(f"cross-validation of the candidate models ({', '.join(separate)})"):
        comparison = cross_validate(dataset, separate, settings, laws=laws, say=say)
    choice = recommend(comparison)
    own = next(iter(fits.values())).space.model_name
    say(f"recommended model: {choice.model}")
    if choice.model == own or not adopt or choice.space is None:
        return ChosenFits(fits, evaluators, comparison)
    say(f"the recommended model {choice.model} is not the robot file's ({own}): fitting it")
    chosen: dict[str, FitResult] = {}
    chosen_evaluators: dict[str, Evaluator] = {}
    for motion in motions:
        res, ev = fit(motion, choice.space, choice.values.get(motion))
        if motion in choice.values and choice.fitness[motion] < res.fitness:
            # the comparison's polish found the lower point: keep it (same space, same data)
            res = replace(res, values=choice.values[motion], fitness=choice.fitness[motion],
                          method=f"{res.method}, comparison's fit kept")
        chosen[motion], chosen_evaluators[motion] = res, ev
    return ChosenFits(chosen, chosen_evaluators, comparison, robot_file_fits=fits)
