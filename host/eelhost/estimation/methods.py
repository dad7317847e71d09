"""The estimation methods, registered by name: the one place a new estimator is added.

A method turns a prepared fit (:class:`FitProblem`: the evaluator of the training experiments,
the settings, where to start, the checkpoint) into a :class:`~eelhost.estimation.optimise.
FitResult`. :func:`eelhost.estimation.pipeline.fit_motion` looks the method up here by
``FitSettings.method``, and ``eelbot estimate --method`` offers every registered name.

The bundled methods (docs/estimation.md):

- ``cmaes`` (default): CMA-ES from the middle of the bounds, then a least-squares polish;
- ``ga``: the paper's genetic algorithm (population 150, 130 generations, uniform crossover);
- ``lsq``: the least-squares polish alone, from ``start``.

To add one: write ``def fit_mine(problem: FitProblem) -> FitResult`` and call
``register_method("mine", fit_mine, "what it does")`` below (or from your own module, imported
before the fit).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from eelhost.estimation.evaluate import EstimationError, Evaluator
from eelhost.estimation.optimise import (
    Checkpoint,
    FitResult,
    Progress,
    fit_cmaes,
    fit_ga,
    polish_least_squares,
)
from eelsim.fluid import FluidCoefficients

if TYPE_CHECKING:  # pipeline imports this module
    from eelhost.estimation.pipeline import FitSettings

__all__ = ["FitMethod", "FitProblem", "get_method", "method_names", "register_method"]


@dataclass(frozen=True)
class FitProblem:
    """Everything a method gets.

    Attributes
    ----------
    evaluator : Evaluator
        Fitness and residuals of candidate coefficients on the training experiments.
    settings : FitSettings
        Seed, budgets, polish iterations.
    start : FluidCoefficients
        Where a local method starts (default: the robot file's coefficients).
    checkpoint : Checkpoint or None
        Where a method that can resume keeps its state.
    resume : bool
        Continue from the checkpoint.
    progress : callable or None
        ``progress(generation, best fitness, simulations)``.
    """

    evaluator: Evaluator
    settings: FitSettings
    start: FluidCoefficients
    checkpoint: Checkpoint | None = None
    resume: bool = False
    progress: Progress | None = None

    def simulations(self) -> int:
        """Closed-loop runs the evaluator has made so far."""
        return self.evaluator.simulations


FitMethod = Callable[[FitProblem], FitResult]


@dataclass(frozen=True)
class _Entry:
    fit: FitMethod
    description: str


_METHODS: dict[str, _Entry] = {}


def register_method(name: str, fit: FitMethod, description: str) -> None:
    """Make an estimation method available as ``FitSettings(method=name)``.

    Parameters
    ----------
    name : str
        The name (``--method`` of ``eelbot estimate``).
    fit : callable
        ``fit(problem) -> FitResult``.
    description : str
        One line for the help.
    """
    _METHODS[name] = _Entry(fit, description)


def method_names() -> tuple[str, ...]:
    """The registered methods' names, in registration order."""
    return tuple(_METHODS)


def get_method(name: str) -> FitMethod:
    """The method registered under ``name``.

    Raises
    ------
    EstimationError
        When no method has that name.
    """
    entry = _METHODS.get(name)
    if entry is None:
        raise EstimationError(f"method must be one of {', '.join(_METHODS)}, got {name!r}")
    return entry.fit


def _fit_cmaes(problem: FitProblem) -> FitResult:
    ev, settings = problem.evaluator, problem.settings
    res = fit_cmaes(
        ev.fitness,
        settings.seed,
        settings.budget,
        checkpoint=problem.checkpoint,
        resume=problem.resume,
        progress=problem.progress,
        simulations=problem.simulations,
    )
    if settings.polish_iterations <= 0:
        return res
    before = ev.simulations
    pol = polish_least_squares(
        ev.residuals, ev.fitness, res.coefficients, res.fitness, settings.polish_iterations
    )
    polished = (len(res.history), pol.fitness, res.simulations + ev.simulations - before)
    if problem.progress:
        problem.progress(*polished)  # the polish is the fit's last step: its count is the total
    return FitResult(
        "cmaes+lsq",
        pol.coefficients,
        pol.fitness,
        res.history + [polished],
        res.evaluations + pol.evaluations,
    )


def _fit_ga(problem: FitProblem) -> FitResult:
    settings = problem.settings
    return fit_ga(
        problem.evaluator.fitness,
        settings.seed,
        settings.pop_size,
        settings.generations,
        problem.checkpoint,
        problem.resume,
        problem.progress,
        problem.simulations,
    )


def _fit_lsq(problem: FitProblem) -> FitResult:
    ev, begin = problem.evaluator, problem.start
    f0 = float(ev.fitness(begin.as_array()[None, :])[0])
    res = polish_least_squares(
        ev.residuals, ev.fitness, begin, f0, max(1, problem.settings.polish_iterations)
    )
    return replace(res, history=[(0, res.fitness, ev.simulations)])  # the polish's runs counted


register_method("cmaes", _fit_cmaes, "CMA-ES + least-squares polish (default)")
register_method("ga", _fit_ga, "the paper's genetic algorithm")
register_method("lsq", _fit_lsq, "least-squares polish only, from the robot file's coefficients")
