"""Global optimisers for a model's parameters: the paper's GA and CMA-ES with restarts.

All search the unit cube mapped linearly onto the bounds of a
:class:`~eelhost.estimation.space.ParameterSpace` (the fluid law's coefficients and any
fitted joint parameters, by name; docs/estimation.md). The objective is any function mapping
candidates (C, K) to fitness values (C,), normally :meth:`Evaluator.fitness`, evaluated a whole
generation at a time so that the batched kernel sees one big batch. The local polishes are in
:mod:`eelhost.estimation.local`.

Long runs checkpoint after a generation at most every few seconds and after the last: an atomic
``.npz`` of numbers only (each generation's candidates, their fitness values and the simulation
counts), never a pickle, so that a fit folder received from someone else cannot run code.
``resume=True`` starts the optimiser afresh with the same seed, feeds it the checkpoint's
generations (checking that it asks for the same candidates), then goes on evaluating; the result is
that of an uninterrupted run with the same seed (docs/estimation.md, "Checkpoints").
"""

from __future__ import annotations

import hashlib
import json
import math
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from eelhost.errors import UserError
from eelhost.estimation.coefficients_file import FittedModel, fit_entry
from eelhost.estimation.space import ParameterSpace
from eelhost.files import atomic_writer
from eelsim.fluid import FluidCoefficients

Objective = Callable[[np.ndarray], np.ndarray]
Progress = Callable[[int, float, int], None]  # (generation, best fitness, simulations so far)


CHECKPOINT_FORMAT = "eelbot-checkpoint/2"  # /1 was a pickle, no longer read


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
    search_evaluations : int or None
        Of these, the global search's (CMA-ES, within ``--budget``), when a polish followed it;
        None when the fit is one search.
    """

    method: str
    space: ParameterSpace
    values: np.ndarray
    fitness: float
    history: list[tuple[int, float, int]] = field(default_factory=list)
    evaluations: int = 0
    search_evaluations: int | None = None

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
        """JSON-ready summary: the model by name (law, joint model, parameters) and the search.

        Its entry under ``fits`` in ``coefficients.json`` (:func:`~eelhost.estimation.
        coefficients_file.fit_entry`).
        """
        return fit_entry(self.method, self.model, self.fitness, self.evaluations,
                         self.simulations, self.history)


class Checkpoint:
    """An atomic ``.npz`` file of plain arrays holding an optimiser's generations so far.

    The file holds numbers only (the candidates each generation asked, their fitness values and
    the simulation counts; docs/estimation.md, "Checkpoints"), is read with pickle refused, and
    its fingerprint of the settings is checked before anything is built from it: a checkpoint
    from another person's folder can at worst be refused, never run code.

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

    def save(self, arrays: dict[str, Any], force: bool = False) -> None:
        """Write the arrays (numbers only) with the format and the fingerprint.

        Skipped when the last write was less than ``every_s`` ago, unless ``force``.

        Raises
        ------
        TypeError
            An array of Python objects (it would need pickle to be read back).
        """
        if not force and time.monotonic() - self._saved_at < self.every_s:
            return
        data = {name: np.asarray(value) for name, value in arrays.items()}
        for name, value in data.items():
            if value.dtype.kind not in "biuf":
                raise TypeError(f"checkpoint array {name!r} is {value.dtype}, not numbers")
        self._saved_at = time.monotonic()
        with atomic_writer(self.path, "wb") as f:  # readable as the umask says
            named: dict[str, Any] = {"format": np.array(CHECKPOINT_FORMAT),
                                     "fingerprint": np.array(self.fingerprint), **data}
            np.savez(f, allow_pickle=False, **named)

    def load(self) -> dict[str, np.ndarray] | None:
        """Return the saved arrays, or None if there is no checkpoint.

        Raises
        ------
        CheckpointError
            Naming the file: not a checkpoint of this format (a pickle included: it is never
            read), or one made with other settings.
        """
        legacy = self.path.with_suffix(".pkl")
        if not self.path.exists():
            if legacy.exists():
                raise CheckpointError(
                    f"{legacy}: a checkpoint of an earlier eelbot (a pickle, which can run code, "
                    "so it is not read): remove it, or run without --resume"
                )
            return None
        try:
            with np.load(self.path, allow_pickle=False) as z:
                if not isinstance(z, np.lib.npyio.NpzFile):
                    raise ValueError("a single array, not an archive of arrays")
                fmt = str(z["format"]) if "format" in z.files else None
                if fmt != CHECKPOINT_FORMAT:
                    raise CheckpointError(
                        f"{self.path}: not a checkpoint of eelbot (format {fmt!r}, expected "
                        f"{CHECKPOINT_FORMAT!r}): remove it, or run without --resume"
                    )
                if "fingerprint" not in z.files or str(z["fingerprint"]) != self.fingerprint:
                    raise CheckpointError(
                        f"{self.path}: checkpoint was made with other settings (dataset, method, "
                        "seed or budget); remove it or run with the same settings"
                    )
                arrays = {n: z[n] for n in z.files if n not in ("format", "fingerprint")}
        except CheckpointError:
            raise
        except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile) as err:
            raise CheckpointError(
                f"{self.path}: not a readable checkpoint ({type(err).__name__}: {err}); it may "
                "be truncated or not eelbot's (pickles are never read): remove it, or run "
                "without --resume"
            ) from None
        for name, value in arrays.items():
            if value.dtype.kind not in "biuf":
                raise CheckpointError(f"{self.path}: array {name!r} is not numbers")
        return arrays


class _Generations:
    """The generations of a fit: replayed from a checkpoint, then evaluated and recorded.

    A resumed fit starts its optimiser afresh with the same seed and feeds it, generation by
    generation, the fitness values the checkpoint holds, after checking that it asks for the same
    candidates; the optimiser then stands exactly where it stood when the checkpoint was written
    (its state is a function of the seed and of what it was told), with nothing but numbers read.

    Parameters
    ----------
    objective : callable
        Candidates (C, K) in the space's units -> fitness (C,).
    space : ParameterSpace
    checkpoint : Checkpoint or None
    resume : bool
    simulations : callable
        The evaluator's count of closed-loop runs.
    """

    def __init__(
        self,
        objective: Objective,
        space: ParameterSpace,
        checkpoint: Checkpoint | None,
        resume: bool,
        simulations: Callable[[], int],
    ) -> None:
        self.objective, self.space, self.checkpoint = objective, space, checkpoint
        self._simulations = simulations
        self.xs: list[np.ndarray] = []
        self.fs: list[np.ndarray] = []
        self.counts: list[int] = []  # the fit's closed-loop runs after each generation
        self._stored: tuple[list[np.ndarray], list[np.ndarray], list[int]] = ([], [], [])
        if checkpoint is not None and resume:
            arrays = checkpoint.load()
            if arrays is not None:
                self._stored = self._split(arrays, checkpoint.path, space.size)
        # a resumed fit's count goes on from its checkpoint's (the evaluator of a new process
        # starts at 0, and replaying runs nothing)
        self._base = self._stored[2][-1] if self._stored[2] else 0
        self._start = simulations() if self._stored[2] else 0

    @staticmethod
    def _split(
        arrays: dict[str, np.ndarray], path: Path, size: int
    ) -> tuple[list[np.ndarray], list[np.ndarray], list[int]]:
        try:
            x, f = arrays["x"].astype(float), arrays["f"].astype(float)
            sizes, counts = arrays["sizes"].astype(np.int64), arrays["simulations"].astype(np.int64)
        except KeyError as err:
            raise CheckpointError(f"{path}: checkpoint has no array {err}: remove it") from None
        if (x.ndim != 2 or x.shape[1] != size or f.shape != (len(x),) or sizes.ndim != 1
                or counts.shape != sizes.shape or (sizes < 0).any() or sizes.sum() != len(x)):
            raise CheckpointError(
                f"{path}: checkpoint arrays do not fit together (candidates {x.shape}, fitness "
                f"{f.shape}, generations {sizes.shape}, {size} parameters expected): remove it"
            )
        cuts = np.cumsum(sizes)[:-1]
        return list(np.split(x, cuts)), list(np.split(f, cuts)), [int(c) for c in counts]

    @property
    def replaying(self) -> bool:
        """Whether the next generation comes from the checkpoint."""
        return len(self.xs) < len(self._stored[0])

    def evaluate(self, unit: np.ndarray) -> np.ndarray:
        """Fitness of a generation's candidates (in the unit cube), replayed or evaluated."""
        unit = np.asarray(unit, dtype=float)
        g = len(self.xs)
        if self.replaying:
            x, f, count = self._stored[0][g], self._stored[1][g], self._stored[2][g]
            if x.shape != unit.shape or not np.allclose(x, unit, rtol=0.0, atol=1e-9):
                assert self.checkpoint is not None
                raise CheckpointError(
                    f"{self.checkpoint.path}: generation {g} of the checkpoint asked for other "
                    "candidates than this run does (another version of numpy, pymoo or pycma?): "
                    "remove it, or run without --resume"
                )
        else:
            f = np.asarray(self.objective(self.space.from_unit(unit)), dtype=float)
            count = self._base + self._simulations() - self._start
        self.xs.append(unit.copy())
        self.fs.append(f)
        self.counts.append(count)
        return f

    @property
    def simulations(self) -> int:
        """The fit's closed-loop runs so far (across a resume)."""
        return self.counts[-1] if self.counts else 0

    @property
    def evaluations(self) -> int:
        """Candidates evaluated so far (across a resume)."""
        return int(sum(len(f) for f in self.fs))

    def save(self, force: bool = False) -> None:
        """Checkpoint the generations (not while replaying: the file already holds them)."""
        if self.checkpoint is None or (self.replaying and not force):
            return
        if not self.xs:
            return
        self.checkpoint.save(
            {"x": np.concatenate(self.xs), "f": np.concatenate(self.fs),
             "sizes": np.array([len(f) for f in self.fs], dtype=np.int64),
             "simulations": np.array(self.counts, dtype=np.int64)},
            force=force,
        )


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
    generations_ = _Generations(objective, space, checkpoint, resume, simulations)
    algo = GA(
        pop_size=pop_size,
        crossover=UniformCrossover(prob=0.8),
        mutation=_seeded_gaussian_mutation(sigma=0.1),
        eliminate_duplicates=True,
    )
    algo.setup(problem, seed=seed, termination=("n_gen", generations))
    history: list[tuple[int, float, int]] = []
    while algo.has_next():
        pop = algo.ask()
        f = generations_.evaluate(pop.get("X"))
        PymooEvaluator().eval(StaticProblem(problem, F=f.reshape(-1, 1)), pop)
        algo.tell(infills=pop)
        best = float(algo.opt.get("F").min())
        history.append((algo.n_gen - 1, best, generations_.simulations))
        generations_.save(force=not algo.has_next())
        if progress:
            progress(*history[-1])
    best_x = space.from_unit(algo.opt.get("X")[0])
    return FitResult("ga", space, best_x, float(algo.opt.get("F").min()), history,
                     generations_.evaluations)


RESTART_SCHEMES = ("none", "ipop", "bipop")


@dataclass
class _Restarts:
    """Where a restarted CMA-ES is: the run under way, the best so far, the budget spent.

    Rebuilt on a resume by replaying the checkpoint's generations, so that a resumed fit continues
    the same sequence of runs.
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
        Budget of candidates over all runs, at most: a generation that would go beyond it is
        not started (pycma's own ``maxfevals`` stops only after it), except the very first.
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
    generations = _Generations(objective, space, checkpoint, resume, simulations)
    start_u = np.clip(space.to_unit(start) if start is not None else np.full(space.size, 0.5),
                      0.0, 1.0)
    run = _Restarts(restarts, popsize, sigma0, np.random.default_rng(seed + 7919))
    es = None
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
        if run.evaluations and run.evaluations + es.popsize > max_evaluations:
            break  # the budget is "at most" (docs/estimation.md): no generation beyond it
        xs = np.array(es.ask())
        f = generations.evaluate(xs)
        run.spent(len(f))
        es.tell(list(xs), f.tolist())
        i = int(np.argmin(f))
        if f[i] < run.best_f:
            run.best_u, run.best_f = xs[i].copy(), float(f[i])
        run.history.append((len(run.history), run.best_f, generations.simulations))
        generations.save()
        if progress:
            progress(*run.history[-1])
    generations.save(force=True)
    if run.best_u is None:
        raise RuntimeError("CMA-ES stopped before evaluating a candidate")
    method = "cmaes" if restarts == "none" else f"cmaes-{restarts}"
    return FitResult(
        method, space, space.from_unit(run.best_u), run.best_f, run.history, run.evaluations
    )
