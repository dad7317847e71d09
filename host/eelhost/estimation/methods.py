"""The estimation methods, registered by name: the one place a new estimator is added.

A method turns a prepared fit (:class:`FitProblem`: the evaluator of the training experiments,
the settings, where to start, the checkpoint) into a :class:`~eelhost.estimation.optimise.
FitResult`. :func:`eelhost.estimation.pipeline.fit_motion` looks the method up here by
``FitSettings.method``, and ``eelbot estimate --method`` offers every registered name. How a fit
is run (:class:`FitSettings`: the method, seed, budgets, backend) is defined here, beside the
methods that read it.

The bundled methods (docs/estimation.md):

- ``cmaes`` (default): CMA-ES from the middle of the bounds, restarted (BIPOP) while budget is
  left, then the minimax trust-region polish (:func:`eelhost.estimation.local.polish_minimax`);
- ``cmaes-lsq``: one CMA-ES run, then a least-squares polish (the default before the minimax
  polish; kept to compare);
- ``ga``: the paper's genetic algorithm (population 150, 130 generations, uniform crossover);
- ``minimax``: the minimax polish alone, from ``start``;
- ``lsq``: the least-squares polish alone, from ``start``.

:func:`run_fit` runs the settings' method; a space that fits the tank's ambient current is fitted in
two stages (see there).

To add one: write ``def fit_mine(problem: FitProblem) -> FitResult`` decorated with
``@ESTIMATORS.add("mine", "what it does")``, here or in your own package, which names it in the
``eelbot.estimators`` entry-point group (docs/architecture.md, "Extension points"); the method is
then offered by ``eelbot estimate --method`` and the report's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from eelhost.estimation.evaluate import EstimationError, Evaluator
from eelhost.estimation.local import polish_least_squares, polish_minimax
from eelhost.estimation.optimise import Checkpoint, FitResult, Progress, fit_cmaes, fit_ga
from eelsim.registry import Registry

__all__ = ["ESTIMATORS", "FitMethod", "FitProblem", "get_method", "method_descriptions",
           "method_names", "register_method", "run_fit"]

# Least iterations of the minimax polish that fits the ambient current (run_fit's second stage).
CURRENT_POLISH_ITERATIONS = 10


@dataclass(frozen=True)
class FitSettings:
    """How a fit is run.

    Attributes
    ----------
    method : str
        A registered method (this module's registry): "cmaes", "ga", ...
    seed : int
    budget : int
        Candidates for CMA-ES over all its runs (the GA's is population x generations).
    pop_size, generations : int
        GA settings (the paper's 150 and 130).
    polish_iterations : int
        Iterations of the local polish after CMA-ES (0: none).
    restarts : str
        CMA-ES restarts: "none", "ipop" or "bipop" (:func:`eelhost.estimation.optimise.fit_cmaes`).
    backend : str
        Evaluator backend ("auto", "batch", "reference").
    align_s : float
        Half-width of each experiment's clock-offset search during fitting (default 0: the
        paper's protocol). With few training experiments the offsets trade off against the
        coefficients (measured: C_a 48 % off on the bundled dataset), so it is off by default.
    fit_current : bool
        Fit the tank's unknown ambient current (v_x, v_y) with the coefficients, a nuisance
        shared by the experiments (:class:`~eelhost.estimation.space.ParameterSpace`;
        docs/estimation.md, "Nuisance parameters").
    jobs : int or None
        Worker processes of the model comparison's independent fits (docs/estimation.md,
        "Choosing the model"); None: one per core, 1: in this process. The scores do not
        depend on it.
    """

    method: str = "cmaes"
    seed: int = 0
    budget: int = 1500
    pop_size: int = 150
    generations: int = 130
    polish_iterations: int = 30
    backend: str = "auto"
    align_s: float = 0.0
    restarts: str = "bipop"
    fit_current: bool = True
    jobs: int | None = None


@dataclass(frozen=True)
class FitProblem:
    """Everything a method gets.

    Attributes
    ----------
    evaluator : Evaluator
        Fitness and residuals of candidate coefficients on the training experiments.
    settings : FitSettings
        Seed, budgets, polish iterations.
    start : ndarray, shape (K,)
        Where a local method starts, a vector of ``evaluator.space`` (default: the robot file's
        values).
    checkpoint : Checkpoint or None
        Where a method that can resume keeps its state.
    resume : bool
        Continue from the checkpoint.
    progress : callable or None
        ``progress(generation, best fitness, simulations)``.
    """

    evaluator: Evaluator
    settings: FitSettings
    start: np.ndarray
    checkpoint: Checkpoint | None = None
    resume: bool = False
    progress: Progress | None = None

    def simulations(self) -> int:
        """Closed-loop runs the evaluator has made so far."""
        return self.evaluator.simulations


FitMethod = Callable[[FitProblem], FitResult]


ESTIMATORS: Registry[FitMethod] = Registry("estimation method", "eelbot.estimators")
"""The registered methods, by name (:mod:`eelsim.registry`; plug-ins: group ``eelbot.estimators``).

Each bundled method registers itself below, beside its definition: ``@ESTIMATORS.add("name",
"one line")``."""


def register_method(name: str, fit: FitMethod, description: str) -> None:
    """Make an estimation method available as ``FitSettings(method=name)``.

    The same as ``ESTIMATORS.add(name, fit, description)``.

    Parameters
    ----------
    name : str
        The name (``--method`` of ``eelbot estimate``).
    fit : callable
        ``fit(problem) -> FitResult``.
    description : str
        One line for the help.

    Raises
    ------
    eelsim.registry.DuplicateNameError
        When another method has that name.
    """
    ESTIMATORS.add(name, fit, description)


def method_names() -> tuple[str, ...]:
    """The registered methods' names, in registration order (plug-ins included)."""
    return ESTIMATORS.names()


def method_descriptions() -> dict[str, str]:
    """Each registered method's one-line description, by name (the ``--method`` help)."""
    return ESTIMATORS.descriptions()


def get_method(name: str) -> FitMethod:
    """The method registered under ``name``.

    Raises
    ------
    EstimationError
        When no method has that name (the message lists the known ones).
    """
    if name not in ESTIMATORS:
        raise EstimationError(ESTIMATORS.unknown_message(name))
    return ESTIMATORS[name]


def _global_cmaes(problem: FitProblem, restarts: str) -> FitResult:
    ev, settings = problem.evaluator, problem.settings
    return fit_cmaes(
        ev.fitness,
        ev.space,
        settings.seed,
        settings.budget,
        restarts=restarts,
        checkpoint=problem.checkpoint,
        resume=problem.resume,
        progress=problem.progress,
        simulations=problem.simulations,
    )


def _then(
    problem: FitProblem, first: FitResult, polished: FitResult, method: str, polish_runs: int
) -> FitResult:
    """The global result followed by its polish, as one result (the better of the two).

    The polish is the fit's last step: its simulations count (the global search's, which goes on
    across a resume, plus the polish's ``polish_runs``) is the fit's total, reported to the
    progress too.
    """
    best = polished if polished.fitness <= first.fitness else first
    last = (len(first.history), best.fitness, first.simulations + polish_runs)
    if problem.progress:
        problem.progress(*last)
    return FitResult(
        method,
        first.space,
        best.values,
        best.fitness,
        first.history + [last],
        first.evaluations + polished.evaluations,
        search_evaluations=(first.search_evaluations if first.search_evaluations is not None
                            else first.evaluations),
    )


@ESTIMATORS.add("cmaes", "CMA-ES with restarts + minimax polish (default)")
def _fit_cmaes(problem: FitProblem) -> FitResult:
    ev, settings = problem.evaluator, problem.settings
    res = _global_cmaes(problem, settings.restarts)
    if settings.polish_iterations <= 0:
        return res
    before = ev.simulations
    pol = polish_minimax(ev.evaluate, ev.space, res.values, settings.polish_iterations,
                         simulations=problem.simulations)
    return _then(problem, res, pol, f"{res.method}+minimax", ev.simulations - before)


@ESTIMATORS.add("cmaes-lsq", "one CMA-ES run + least-squares polish")
def _fit_cmaes_lsq(problem: FitProblem) -> FitResult:
    ev, settings = problem.evaluator, problem.settings
    res = _global_cmaes(problem, "none")
    if settings.polish_iterations <= 0:
        return res
    before = ev.simulations
    pol = polish_least_squares(
        ev.residuals, ev.fitness, ev.space, res.values, res.fitness, settings.polish_iterations
    )
    return _then(problem, res, pol, "cmaes+lsq", ev.simulations - before)


@ESTIMATORS.add("ga", "the paper's genetic algorithm")
def _fit_ga(problem: FitProblem) -> FitResult:
    settings = problem.settings
    return fit_ga(
        problem.evaluator.fitness,
        problem.evaluator.space,
        settings.seed,
        settings.pop_size,
        settings.generations,
        problem.checkpoint,
        problem.resume,
        problem.progress,
        problem.simulations,
    )


@ESTIMATORS.add("minimax", "minimax polish only, from the robot file's values")
def _fit_minimax(problem: FitProblem) -> FitResult:
    ev = problem.evaluator
    return polish_minimax(ev.evaluate, ev.space, problem.start,
                          max(1, problem.settings.polish_iterations),
                          simulations=problem.simulations)


@ESTIMATORS.add("lsq", "least-squares polish only, from the robot file's values")
def _fit_lsq(problem: FitProblem) -> FitResult:
    ev, begin = problem.evaluator, problem.start
    f0 = float(ev.fitness(begin[None, :])[0])
    res = polish_least_squares(
        ev.residuals, ev.fitness, ev.space, begin, f0, max(1, problem.settings.polish_iterations)
    )
    return replace(res, history=[(0, res.fitness, ev.simulations)])  # the polish's runs counted


def run_fit(problem: FitProblem) -> FitResult:
    """Fit with the settings' method; the ambient current, if in the space, in a second stage.

    Stage 1 is the method on the space without the current (the declared water), from the
    start's other parameters; stage 2 the minimax polish of the whole space from its result in
    still water (``polish_iterations``, at least :data:`CURRENT_POLISH_ITERATIONS`). Why not at
    once: straight experiments all swim along one axis, where a current trades against the
    coefficients that set the swimming speed; searched globally together, CMA-ES settled in that
    valley (measured on a small tank with a 5 mm/s current: fitness 0.090 after 1500 candidates,
    current x-component 6x the true one), while the polish from the still-water fit found the
    truth's optimum (0.035, the current within 0.3 mm/s) for a fraction of the runs.

    Parameters
    ----------
    problem : FitProblem

    Returns
    -------
    FitResult
        In the problem's space; its history and simulations count both stages.
    """
    fit = get_method(problem.settings.method)
    ev, space = problem.evaluator, problem.evaluator.space
    if not space.current:
        return fit(problem)
    still = replace(space, current=False)
    still_ev = ev.with_space(still)
    k = still.size
    first = fit(replace(problem, evaluator=still_ev, start=np.asarray(problem.start)[:k]))
    ev.count_from(still_ev)
    begin = np.concatenate([first.values, np.zeros(len(space.current_names))])
    in_space = FitResult(first.method, space, begin, first.fitness, first.history,
                         first.evaluations, search_evaluations=first.search_evaluations)
    before = ev.simulations
    iterations = max(problem.settings.polish_iterations, CURRENT_POLISH_ITERATIONS)
    pol = polish_minimax(ev.evaluate, space, begin, iterations, simulations=problem.simulations)
    return _then(problem, in_space, pol, f"{first.method}+current", ev.simulations - before)
