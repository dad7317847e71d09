"""Global optimisers for a model's parameters: the paper's GA and CMA-ES with restarts.

All search the unit cube mapped linearly onto the bounds of a
:class:`~eelhost.estimation.parameters.ParameterSpace` (the fluid law's coefficients and any
fitted joint parameters, by name; docs/estimation.md). The objective is any function mapping
candidates (C, K) to fitness values (C,), normally :meth:`Evaluator.fitness`, evaluated a whole
generation at a time so that the batched kernel sees one big batch. The local polishes are in
:mod:`eelhost.estimation.local`.

Long runs checkpoint after a generation at most every few seconds and after the last (an atomic
pickle of the optimiser, its random state and the history: about 30 ms for the GA, a tenth of
one of its generations); ``resume=True`` continues from the checkpoint, replaying the generations
since, and gives the same result as an uninterrupted run with the same seed.
"""

from __future__ import annotations

import hashlib
import json
import math
import pickle
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cloudpickle
import numpy as np

from eelhost.errors import UserError
from eelhost.estimation.parameters import FittedModel, ParameterSpace
from eelhost.files import atomic_writer
from eelsim.fluid import FluidCoefficients

Objective = Callable[[np.ndarray], np.ndarray]
Progress = Callable[[int, float, int], None]  # (generation, best fitness, simulations so far)


class CheckpointError(UserError, ValueError):
    """A checkpoint that belongs to another fit (other dataset, method, seed or budget)."""


@dataclass
class FitResult:
    """Outcome of a fit.

    Attributes
    ----------
    method : str
    space : ParameterSpace
        What the values are.
    values : ndarray, shape (K,)
        Best candidate found.
    fitness : float
        Its fitness.
    history : list of (generation, best fitness, simulations)
        Progress per generation (for the fitness-against-generation figure); the count of
        closed-loop runs is the whole fit's, across a resume.
    evaluations : int
        Candidates evaluated (each is one simulation per training experiment).
    """

    method: str
    space: ParameterSpace
    values: np.ndarray
    fitness: float
    history: list[tuple[int, float, int]] = field(default_factory=list)
    evaluations: int = 0

    @property
    def coefficients(self) -> FluidCoefficients:
        """The fluid law's coefficients of the best candidate."""
        return self.space.coefficients(self.values)

    @property
    def model(self) -> FittedModel:
        """The best candidate as a fitted model."""
        return FittedModel(self.space, np.asarray(self.values, dtype=float))

    @property
    def simulations(self) -> int:
        """Closed-loop runs of the whole fit (the last count of the history; 0 without one)."""
        return int(self.history[-1][2]) if self.history else 0

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary: the model by name (law, joint model, parameters) and the search."""
        return {
            "method": self.method,
            **self.model.to_json(),
            "fitness": self.fitness,
            "evaluations": self.evaluations,
            "simulations": self.simulations,
            "history": [list(h) for h in self.history],
        }


class Checkpoint:
    """An atomic pickle file holding an optimiser's state between generations.

    Parameters
    ----------
    path : str or Path
    settings : dict
        What the run was started with; a resume with other settings is refused.
    every_s : float
        :meth:`save` writes at most this often unless forced (the first save always writes).
    """

    def __init__(self, path: str | Path, settings: dict[str, Any], every_s: float = 5.0) -> None:
        self.path = Path(path)
        self.every_s = every_s
        self._saved_at = -math.inf
        self.fingerprint = hashlib.sha256(
            json.dumps(settings, sort_keys=True, default=str).encode()
        ).hexdigest()

    # numpy's legacy global generator is saved because pycma draws from it (NPY002 is about new
    # code choosing it; here we must follow what the libraries use).
    def save(self, state: dict[str, Any], force: bool = False) -> None:
        """Write the state (with the fingerprint and numpy's global random state).

        Skipped when the last write was less than ``every_s`` ago, unless ``force``.
        """
        if not force and time.monotonic() - self._saved_at < self.every_s:
            return
        self._saved_at = time.monotonic()
        state = {**state, "fingerprint": self.fingerprint, "np_random": np.random.get_state()}  # noqa: NPY002
        with atomic_writer(self.path, "wb") as f:  # readable as the umask says
            cloudpickle.dump(state, f)  # pymoo holds local functions plain pickle refuses

    def load(self) -> dict[str, Any] | None:
        """Return the saved state (restoring numpy's global random state), or None if none."""
        if not self.path.exists():
            return None
        try:
            with open(self.path, "rb") as f:
                state = pickle.load(f)
        except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, IndexError) as err:
            raise CheckpointError(
                f"{self.path}: not a readable checkpoint ({type(err).__name__}: {err}); it may "
                "be truncated or from another version: remove it, or run without --resume"
            ) from None
        if not isinstance(state, dict):
            raise CheckpointError(f"{self.path}: not a checkpoint of eelbot (remove it)")
        if state.get("fingerprint") != self.fingerprint:
            raise CheckpointError(
                f"{self.path}: checkpoint was made with other settings (dataset, method, seed or "
                "budget); remove it or run with the same settings"
            )
        np.random.set_state(state["np_random"])  # noqa: NPY002
        return state


def _start(checkpoint: Checkpoint | None, resume: bool) -> dict[str, Any] | None:
    if checkpoint is None or not resume:
        return None
    return checkpoint.load()


def _count_across_resume(
    simulations: Callable[[], int], state: dict[str, Any] | None
) -> Callable[[], int]:
    """The simulations count of the whole fit: a resumed one goes on from its checkpoint's count.

    The evaluator of a new process starts at 0; without this the count in the history and the
    progress would restart at every resume while the candidates' count (``evaluations``) goes on.
    """
    if state is None or not state["history"]:
        return simulations
    base, start = int(state["history"][-1][2]), simulations()
    return lambda: base + simulations() - start


def _seeded_gaussian_mutation(sigma: float = 0.1):
    """Gaussian mutation that draws every random number from the algorithm's generator.

    pymoo 0.6.2's ``GaussianMutation`` repairs out-of-bounds values with an unseeded generator, so
    two runs with the same seed differ; this one reflects a mutated value that leaves the unit cube
    to a uniform point between its parent and the bound, from the seeded generator.
    """
    from pymoo.core.mutation import Mutation

    class SeededGaussianMutation(Mutation):
        def _do(self, problem, X, random_state=None, **kwargs):  # noqa: N803 (pymoo's names)
            X = X.astype(float)
            prob = self.get_prob_var(problem, size=len(X))
            mutate = random_state.random(X.shape) < np.asarray(prob)[:, None]
            child = np.where(mutate, random_state.normal(X, sigma), X)
            lo, hi = problem.xl, problem.xu
            out_lo, out_hi = child < lo, child > hi
            r = random_state.random(X.shape)
            child = np.where(out_lo, lo + r * (X - lo), child)
            return np.where(out_hi, hi - r * (hi - X), child)

    return SeededGaussianMutation()


def fit_ga(
    objective: Objective,
    space: ParameterSpace,
    seed: int = 0,
    pop_size: int = 150,
    generations: int = 130,
    checkpoint: Checkpoint | None = None,
    resume: bool = False,
    progress: Progress | None = None,
    simulations: Callable[[], int] = lambda: 0,
) -> FitResult:
    """The paper's genetic algorithm (pymoo GA, uniform = MATLAB's scattered crossover).

    Parameters
    ----------
    objective : callable
        Candidates (C, K) -> fitness (C,).
    space : ParameterSpace
        The parameters and their bounds.
    seed : int
    pop_size, generations : int
        150 and 130 in the paper.
    checkpoint : Checkpoint, optional
    resume : bool
        Continue from the checkpoint if there is one.
    progress : callable, optional
        Called after each generation with (generation, best fitness, simulations).
    simulations : callable
        Returns the number of closed-loop runs done so far (for the history).

    Returns
    -------
    FitResult
    """
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.core.evaluator import Evaluator as PymooEvaluator
    from pymoo.core.problem import Problem
    from pymoo.operators.crossover.ux import UniformCrossover
    from pymoo.problems.static import StaticProblem

    problem = Problem(n_var=space.size, n_obj=1, xl=0.0, xu=1.0)
    state = _start(checkpoint, resume)
    if state is None:
        algo = GA(
            pop_size=pop_size,
            crossover=UniformCrossover(prob=0.8),
            mutation=_seeded_gaussian_mutation(sigma=0.1),
            eliminate_duplicates=True,
        )
        algo.setup(problem, seed=seed, termination=("n_gen", generations))
        history: list[tuple[int, float, int]] = []
        evaluations = 0
    else:
        algo, history, evaluations = state["algorithm"], state["history"], state["evaluations"]
    simulations = _count_across_resume(simulations, state)
    while algo.has_next():
        pop = algo.ask()
        f = np.asarray(objective(space.from_unit(pop.get("X"))), dtype=float)
        evaluations += len(f)
        PymooEvaluator().eval(StaticProblem(problem, F=f.reshape(-1, 1)), pop)
        algo.tell(infills=pop)
        best = float(algo.opt.get("F").min())
        history.append((algo.n_gen - 1, best, simulations()))
        if checkpoint is not None:
            checkpoint.save(
                {"algorithm": algo, "history": history, "evaluations": evaluations},
                force=not algo.has_next(),
            )
        if progress:
            progress(*history[-1])
    best_x = space.from_unit(algo.opt.get("X")[0])
    return FitResult("ga", space, best_x, float(algo.opt.get("F").min()), history, evaluations)


RESTART_SCHEMES = ("none", "ipop", "bipop")


@dataclass
class _Restarts:
    """Where a restarted CMA-ES is: the run under way, the best so far, the budget spent.

    Kept whole in the checkpoint, so that a resumed fit continues the same sequence of runs.
    """

    scheme: str
    base_popsize: int
    sigma0: float
    rng: np.random.Generator
    runs: int = 0
    kind: str = "first"
    large_runs: int = 0
    large_evaluations: int = 0
    small_evaluations: int = 0
    evaluations: int = 0
    best_u: np.ndarray | None = None
    best_f: float = math.inf
    history: list[tuple[int, float, int]] = field(default_factory=list)

    def next_run(self, dimension: int, start_u: np.ndarray) -> tuple[np.ndarray, float, int]:
        """Start point, step and population of the next run.

        IPOP doubles the population; BIPOP (Hansen 2009) alternates such large runs with cheap
        small runs of smaller steps.
        """
        first = self.runs == 0
        self.runs += 1
        x0 = start_u if first else self.rng.uniform(0.0, 1.0, dimension)
        if first or self.scheme == "none":
            self.kind = "first"
            return x0, self.sigma0, self.base_popsize
        large = self.base_popsize * 2 ** (self.large_runs + 1)
        if self.scheme == "ipop" or self.small_evaluations >= self.large_evaluations:
            self.kind = "large"
            self.large_runs += 1
            return x0, self.sigma0, large
        self.kind = "small"
        u = self.rng.uniform()
        popsize = int(self.base_popsize * (0.5 * large / self.base_popsize) ** (u * u))
        return x0, self.sigma0 * 10.0 ** (-2.0 * self.rng.uniform()), max(self.base_popsize, popsize)

    def spent(self, count: int) -> None:
        """Count ``count`` evaluations against the run under way."""
        self.evaluations += count
        if self.kind == "large":
            self.large_evaluations += count
        elif self.kind == "small":
            self.small_evaluations += count


def fit_cmaes(
    objective: Objective,
    space: ParameterSpace,
    seed: int = 0,
    max_evaluations: int = 1500,
    popsize: int = 12,
    start: np.ndarray | None = None,
    sigma0: float = 0.25,
    restarts: str = "none",
    checkpoint: Checkpoint | None = None,
    resume: bool = False,
    progress: Progress | None = None,
    simulations: Callable[[], int] = lambda: 0,
    tolerance: float = 1e-7,
) -> FitResult:
    """CMA-ES (pycma) in the unit cube, a generation per batch, optionally restarted.

    Parameters
    ----------
    objective : callable
        Candidates (C, K) -> fitness (C,).
    space : ParameterSpace
        The parameters and their bounds.
    seed : int
    max_evaluations : int
        Budget of candidates over all runs.
    popsize : int
        Candidates per generation of the first run.
    start : ndarray, optional
        Initial mean (parameters); default the middle of the bounds. Restarts start at seeded
        uniform points of the cube.
    sigma0 : float
        Initial step in the unit cube.
    restarts : {"none", "ipop", "bipop"}
        After a run converges, start another while budget is left: "ipop" doubles the
        population each time; "bipop" alternates such large runs with small runs of smaller
        steps, spending about as much on each kind.
    checkpoint, resume, progress, simulations
        As for :func:`fit_ga`.
    tolerance : float
        A run ends when its steps fall below this in the unit cube (pycma's ``tolx``) or its
        fitness values stop changing by more than this (``tolfun``).

    Returns
    -------
    FitResult
    """
    import cma

    if restarts not in RESTART_SCHEMES:
        raise ValueError(f"restarts must be one of {', '.join(RESTART_SCHEMES)}, got {restarts!r}")
    state = _start(checkpoint, resume)
    start_u = np.clip(space.to_unit(start) if start is not None else np.full(space.size, 0.5),
                      0.0, 1.0)
    if state is None:
        run = _Restarts(restarts, popsize, sigma0, np.random.default_rng(seed + 7919))
        es = None
    else:
        run, es = state["run"], state["es"]
    # a resumed fit's simulations count goes on from its checkpoint's
    simulations = _count_across_resume(
        simulations, None if state is None else {"history": state["run"].history}
    )
    while True:
        if es is None or es.stop():
            left = max_evaluations - run.evaluations
            if es is not None and (restarts == "none" or left < 2 * popsize):
                break
            if left <= 0:
                break
            x0, sigma, lam = run.next_run(space.size, start_u)
            es = cma.CMAEvolutionStrategy(
                x0.tolist(),
                sigma,
                {
                    "bounds": [0.0, 1.0],
                    "seed": seed + run.runs,
                    "popsize": lam,
                    "verbose": -9,
                    "maxfevals": left,
                    "tolfun": tolerance,
                    "tolx": tolerance,
                },
            )
            if es.stop():  # no budget even for one generation
                break
        xs = np.array(es.ask())
        f = np.asarray(objective(space.from_unit(xs)), dtype=float)
        run.spent(len(f))
        es.tell(list(xs), f.tolist())
        i = int(np.argmin(f))
        if f[i] < run.best_f:
            run.best_u, run.best_f = xs[i].copy(), float(f[i])
        run.history.append((len(run.history), run.best_f, simulations()))
        if checkpoint is not None:
            checkpoint.save({"run": run, "es": es}, force=False)
        if progress:
            progress(*run.history[-1])
    if checkpoint is not None:
        checkpoint.save({"run": run, "es": es}, force=True)
    if run.best_u is None:
        raise RuntimeError("CMA-ES stopped before evaluating a candidate")
    method = "cmaes" if restarts == "none" else f"cmaes-{restarts}"
    return FitResult(
        method, space, space.from_unit(run.best_u), run.best_f, run.history, run.evaluations
    )
