"""Optimisers for the coefficients: the paper's GA, CMA-ES, and a least-squares polish.

All search in the unit cube mapped linearly onto :data:`BOUNDS` (documented in docs/estimation.md;
wide enough for the paper's table 3). The objective is any function mapping candidates (C, 4) to
fitness values (C,), normally :meth:`Evaluator.fitness`, evaluated a whole generation at a time so
that the batched kernel sees one big batch.

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
from eelhost.files import atomic_writer
from eelsim.fluid import FluidCoefficients
from eelsim.robot import HydroCoefficients

# Search bounds (C_f, C_d, C_a, C_m). Table 3: C_f 0.008-0.009, C_d 0.78-0.98, C_a 0.62-1.17,
# C_m 0.001-0.007; slender-body estimates (Kelasidi) put C_f near 0.03 and C_a, C_m near 1.
BOUNDS = np.array([[0.0005, 0.1], [0.05, 3.0], [0.05, 3.0], [0.0, 1.0]])
NAMES = ("C_f", "C_d", "C_a", "C_m")

Objective = Callable[[np.ndarray], np.ndarray]
Progress = Callable[[int, float, int], None]  # (generation, best fitness, simulations so far)


def from_unit(u: np.ndarray) -> np.ndarray:
    """Map unit-cube points to coefficients."""
    u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    return BOUNDS[:, 0] + u * (BOUNDS[:, 1] - BOUNDS[:, 0])


def to_unit(c: np.ndarray) -> np.ndarray:
    """Map coefficients to the unit cube."""
    return (np.asarray(c, dtype=float) - BOUNDS[:, 0]) / (BOUNDS[:, 1] - BOUNDS[:, 0])


class CheckpointError(UserError, ValueError):
    """A checkpoint that belongs to another fit (other dataset, method, seed or budget)."""


@dataclass
class FitResult:
    """Outcome of a fit.

    Attributes
    ----------
    method : str
    coefficients : FluidCoefficients
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
    coefficients: FluidCoefficients
    fitness: float
    history: list[tuple[int, float, int]] = field(default_factory=list)
    evaluations: int = 0

    @property
    def simulations(self) -> int:
        """Closed-loop runs of the whole fit (the last count of the history; 0 without one)."""
        return int(self.history[-1][2]) if self.history else 0

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "method": self.method,
            "coefficients": self.coefficients.model_dump(),
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
        Candidates (C, 4) -> fitness (C,).
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

    problem = Problem(n_var=4, n_obj=1, xl=0.0, xu=1.0)
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
        f = np.asarray(objective(from_unit(pop.get("X"))), dtype=float)
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
    best_x = from_unit(algo.opt.get("X")[0])
    return FitResult(
        "ga",
        HydroCoefficients.from_array(best_x),
        float(algo.opt.get("F").min()),
        history,
        evaluations,
    )


def fit_cmaes(
    objective: Objective,
    seed: int = 0,
    max_evaluations: int = 1200,
    popsize: int = 12,
    start: np.ndarray | None = None,
    sigma0: float = 0.25,
    checkpoint: Checkpoint | None = None,
    resume: bool = False,
    progress: Progress | None = None,
    simulations: Callable[[], int] = lambda: 0,
) -> FitResult:
    """CMA-ES (pycma) in the unit cube, a generation per batch.

    Parameters
    ----------
    objective : callable
        Candidates (C, 4) -> fitness (C,).
    seed : int
    max_evaluations : int
        Budget of candidates.
    popsize : int
        Candidates per generation.
    start : ndarray, optional
        Initial mean (coefficients); default the middle of the bounds.
    sigma0 : float
        Initial step in the unit cube.
    checkpoint, resume, progress, simulations
        As for :func:`fit_ga`.

    Returns
    -------
    FitResult
    """
    import cma

    state = _start(checkpoint, resume)
    if state is None:
        x0 = to_unit(start) if start is not None else np.full(4, 0.5)
        es = cma.CMAEvolutionStrategy(
            np.clip(x0, 0.0, 1.0).tolist(),
            sigma0,
            {
                "bounds": [0.0, 1.0],
                "seed": seed + 1,
                "popsize": popsize,
                "verbose": -9,
                "maxfevals": max_evaluations,
                "tolfun": 1e-9,
                "tolx": 1e-7,
            },
        )
        history: list[tuple[int, float, int]] = []
        best_u, best_f, evaluations = None, np.inf, 0
    else:
        es, history = state["es"], state["history"]
        best_u, best_f, evaluations = state["best_u"], state["best_f"], state["evaluations"]
    simulations = _count_across_resume(simulations, state)
    while not es.stop():
        xs = np.array(es.ask())
        f = np.asarray(objective(from_unit(xs)), dtype=float)
        evaluations += len(f)
        es.tell(list(xs), f.tolist())
        i = int(np.argmin(f))
        if f[i] < best_f:
            best_u, best_f = xs[i].copy(), float(f[i])
        history.append((len(history), best_f, simulations()))
        if checkpoint is not None:
            checkpoint.save(
                {
                    "es": es,
                    "history": history,
                    "best_u": best_u,
                    "best_f": best_f,
                    "evaluations": evaluations,
                },
                force=bool(es.stop()),
            )
        if progress:
            progress(*history[-1])
    if best_u is None:
        raise RuntimeError("CMA-ES stopped before evaluating a candidate")
    return FitResult(
        "cmaes", HydroCoefficients.from_array(from_unit(best_u)), best_f, history, evaluations
    )


def polish_least_squares(
    residuals: Callable[[np.ndarray], np.ndarray],
    objective: Objective,
    start: FluidCoefficients,
    start_fitness: float,
    max_iterations: int = 20,
) -> FitResult:
    """Local least-squares polish (scipy ``least_squares``, trust region, finite differences).

    The polished point is kept only if its minimax fitness is no worse than the start's (least
    squares and minimax differ).

    Parameters
    ----------
    residuals : callable
        Candidates (C, 4) -> stacked residuals (C, M) (:meth:`Evaluator.residuals`).
    objective : callable
        Candidates -> minimax fitness, to judge the result.
    start : FluidCoefficients
    start_fitness : float
    max_iterations : int
        Jacobian evaluations at most.

    Returns
    -------
    FitResult
    """
    from scipy.optimize import least_squares

    u0 = np.clip(to_unit(start.as_array()), 1e-6, 1 - 1e-6)
    step = 1e-3
    evaluations = 0

    def fun(u: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        return residuals(from_unit(u)[None, :])[0]

    def jac(u: np.ndarray) -> np.ndarray:
        # One batch: the point's four forward perturbations (stepping inwards at the upper bound).
        nonlocal evaluations
        steps = np.where(u + step <= 1.0, step, -step)
        pts = np.repeat(u[None, :], 4, axis=0) + np.diag(steps)
        r = residuals(from_unit(np.vstack([u[None, :], pts])))
        evaluations += 5
        return ((r[1:] - r[0]) / steps[:, None]).T

    sol = least_squares(fun, u0, jac=jac, bounds=(0.0, 1.0), max_nfev=max_iterations, x_scale="jac")
    cand = from_unit(sol.x)
    f = float(objective(cand[None, :])[0])
    evaluations += 1
    if f <= start_fitness:
        return FitResult("lsq", HydroCoefficients.from_array(cand), f, [(0, f, 0)], evaluations)
    return FitResult("lsq", start, start_fitness, [(0, start_fitness, 0)], evaluations)
