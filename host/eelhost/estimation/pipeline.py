"""The estimation chain: fit each motion type, validate, quantify uncertainty, write a report.

The methods (``method``: ``cmaes``, the default; ``ga``, the paper's; ``lsq``) are registered by
name in :mod:`eelhost.estimation.methods`, the one place a new estimator is added.

``motion`` is "straight" or "turning" (the paper's separate fits) or "joint" (one coefficient set
for the robot, fitted on the training experiments of both motion types).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from eelhost.data.experiments import Dataset, Experiment
from eelhost.estimation.evaluate import EstimationError, Evaluator
from eelhost.estimation.methods import (
    FitProblem,
    FitSettings,
    run_fit,
)
from eelhost.estimation.optimise import Checkpoint, FitResult
from eelhost.estimation.space import ParameterSpace


def training_experiments(dataset: Dataset, motion: str) -> list[Experiment]:
    """The training experiments of a motion type ("joint": of all motion types)."""
    if motion == "joint":
        return [e for exps in dataset.train.values() for e in exps]
    if motion not in dataset.train:
        raise EstimationError(
            f"dataset has no training experiments for motion {motion!r} (has {sorted(dataset.train)})"
        )
    return list(dataset.train[motion])


def fit_motion(
    dataset: Dataset,
    motion: str,
    settings: FitSettings,
    checkpoint_dir: str | Path | None = None,
    resume: bool = False,
    progress: Callable[[int, float, int], None] | None = None,
    start: np.ndarray | None = None,
    map_function: Callable | None = None,
    space: ParameterSpace | None = None,
    experiments: list[Experiment] | None = None,
) -> tuple[FitResult, Evaluator]:
    """Fit the parameters of one motion type.

    Parameters
    ----------
    dataset : Dataset
    motion : str
        "straight", "turning" or "joint".
    settings : FitSettings
    checkpoint_dir : str or Path, optional
        Where to keep the per-generation checkpoint.
    resume : bool
        Continue from a checkpoint.
    progress : callable, optional
        (generation, best fitness, simulations).
    start : ndarray, optional
        Start of the local methods, a vector of the space (default: the robot file's values).
    map_function : callable, optional
        Spreads the evaluation (e.g. a Dask client's map).
    space : ParameterSpace, optional
        The candidate model (default: the dataset robot's fluid law and joint model, with the
        ambient current when ``settings.fit_current``).
    experiments : list of Experiment, optional
        Fit these instead of the motion's training experiments (cross-validation folds).

    Returns
    -------
    (FitResult, Evaluator)
        The result (``evaluations`` counts candidates; the evaluator's ``simulations`` counts runs).
    """
    space = space or ParameterSpace.for_robot(dataset.robot, current=settings.fit_current)
    ev = Evaluator(
        dataset.robot,
        experiments if experiments is not None else training_experiments(dataset, motion),
        backend=settings.backend,
        align_s=settings.align_s,
        map_function=map_function,
        space=space,
    )
    ck = None
    if checkpoint_dir is not None:
        # (the comparison's worker count changes no result: a resume with another one continues)
        ident = {"dataset": str(dataset.folder.resolve()), "motion": motion,
                 "model": space.model_name,
                 **{k: v for k, v in settings.__dict__.items() if k != "jobs"}}
        tag = space.model_name.replace(" x ", "_")
        ck = Checkpoint(
            Path(checkpoint_dir) / f"checkpoint_{motion}_{tag}_{settings.method}.npz", ident
        )
    begin = space.start(dataset.robot) if start is None else np.asarray(start, dtype=float)
    problem = FitProblem(ev, settings, begin, ck, resume, progress)
    res = run_fit(problem)
    return res, ev
