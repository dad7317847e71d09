"""Local polishes of a fit: the minimax trust region (the paper's fitness) and least squares.

Both work in the unit cube of a :class:`~eelhost.estimation.parameters.ParameterSpace` with
forward-difference Jacobians, the point and its K perturbations simulated as one batch.

- :func:`polish_minimax` minimises the paper's fitness, the largest per-experiment error, itself.
  The maximum is not smooth where two experiments' errors cross, which is where a minimax
  optimum usually sits; a least-squares polish, or a smooth method on the maximum, stalls there
  (measured: docs/estimation_benchmarks.md). It is a sequential linear programme in the epigraph
  form with a trust region (Madsen's method for minimax): at x, with the errors e and their
  Jacobian J, the step d solves  min t  subject to  e + J d <= t,  |d|_inf <= radius,
  0 <= x + d <= 1  (``scipy.optimize.linprog``); the step is taken when the true maximum falls,
  and the radius grows or shrinks with the ratio of the true to the predicted decrease.
- :func:`polish_least_squares` minimises the sum of squared residuals (scipy ``least_squares``),
  the smooth problem the identifiability analysis linearises.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from eelhost.estimation.optimise import FitResult, Objective
from eelhost.estimation.parameters import ParameterSpace

Errors = Callable[[np.ndarray], np.ndarray]  # candidates (C, K) -> per-experiment errors (C, E)

FD_STEP = 1e-3  # forward-difference step in the unit cube (a thousandth of each range)


def _with_perturbations(u: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """The point and its K forward perturbations (inwards at the upper bound), and the steps."""
    steps = np.where(u + step <= 1.0, step, -step)
    return np.vstack([u[None, :], u[None, :] + np.diag(steps)]), steps


ManyErrors = Callable[[list[np.ndarray]], list[np.ndarray]]
"""Candidates of B problems (a list of (C_b, K) arrays) -> their errors (a list of (C_b, E))."""


@dataclass
class _TrustRegion:
    """One problem's state in :func:`polish_minimax_many`."""

    u: np.ndarray
    errors: np.ndarray  # at u and its K perturbations, shape (K + 1, E)
    steps: np.ndarray
    radius: float
    history: list[tuple[int, float, int]] = field(default_factory=list)
    evaluations: int = 0
    done: bool = False
    # the step under trial: (step d, its point and perturbations, their steps, predicted decrease)
    trial: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None

    @property
    def fitness(self) -> float:
        return float(self.errors[0].max())


def polish_minimax(
    errors: Errors,
    space: ParameterSpace,
    start: np.ndarray,
    max_iterations: int = 30,
    radius: float = 0.05,
    min_radius: float = 1e-5,
    simulations: Callable[[], int] = lambda: 0,
) -> FitResult:
    """Minimise max_j error_j from ``start`` by a trust-region sequential linear programme.

    Parameters
    ----------
    errors : callable
        Candidates (C, K) -> per-experiment errors (C, E) (:meth:`Evaluator.errors`).
    space : ParameterSpace
    start : ndarray, shape (K,)
        Parameters to start from.
    max_iterations : int
        Linear programmes at most (each costs one batch of K + 1 candidates).
    radius : float
        Initial trust radius in the unit cube.
    min_radius : float
        Stop when the radius falls below this.
    simulations : callable
        Closed-loop runs so far (for the history).

    Returns
    -------
    FitResult
        Never worse than the start.
    """
    return polish_minimax_many(
        lambda xs: [errors(xs[0])], space, np.asarray(start, float)[None], max_iterations,
        radius, min_radius, simulations,
    )[0]


def polish_minimax_many(
    errors: ManyErrors,
    space: ParameterSpace,
    starts: np.ndarray,
    max_iterations: int = 30,
    radius: float = 0.05,
    min_radius: float = 1e-5,
    simulations: Callable[[], int] = lambda: 0,
) -> list[FitResult]:
    """:func:`polish_minimax` of B problems in lock step, their candidates evaluated together.

    The parametric bootstrap refits many regenerated data sets from one estimate; each
    iteration asks for every unfinished problem's candidates in one call, so that the batched
    kernel simulates them as one batch.

    Parameters
    ----------
    errors : callable
        A list of B candidate arrays (C_b, K) -> the list of their errors (C_b, E); an empty
        array asks nothing of that problem.
    space : ParameterSpace
    starts : ndarray, shape (B, K)
    max_iterations, radius, min_radius, simulations
        As for :func:`polish_minimax`.

    Returns
    -------
    list of FitResult
        One per problem, each never worse than its start.
    """
    from scipy.optimize import linprog

    k = space.size
    first = [_with_perturbations(u, FD_STEP)
             for u in np.clip(space.to_unit(np.atleast_2d(starts)), 0.0, 1.0)]
    got = errors([space.from_unit(pts) for pts, _ in first])
    states = [_TrustRegion(pts[0], e, st, radius, evaluations=len(pts))
              for (pts, st), e in zip(first, got, strict=True)]
    empty = np.zeros((0, k))
    for it in range(max_iterations):
        for tr in states:
            if tr.done:
                continue
            e, f = tr.errors[0], tr.fitness
            tr.history.append((it, f, simulations()))
            tr.trial = None
            if not np.all(np.isfinite(tr.errors)) or f >= 1e5:  # a failed run: no slopes
                tr.done = True
                continue
            jac = ((tr.errors[1:] - e) / tr.steps[:, None]).T  # (E, K)
            # variables (d, t): minimise t subject to J d - t <= -e, in the box and the cube
            lo = np.maximum(-tr.radius, -tr.u)
            hi = np.minimum(tr.radius, 1.0 - tr.u)
            lp = linprog(
                np.r_[np.zeros(k), 1.0],
                A_ub=np.hstack([jac, -np.ones((len(e), 1))]),
                b_ub=-e,
                bounds=[*zip(lo, hi, strict=True), (None, None)],
                method="highs",
            )
            predicted = f - float(lp.x[k]) if lp.status == 0 else 0.0
            if predicted <= 1e-12 * max(1.0, f):
                tr.done = True
                continue
            d = lp.x[:k]
            pts, steps = _with_perturbations(np.clip(tr.u + d, 0.0, 1.0), FD_STEP)
            tr.trial = (d, pts, steps, predicted)
        asked = [space.from_unit(tr.trial[1]) if tr.trial is not None else empty for tr in states]
        if not any(len(a) for a in asked):
            break
        got = errors(asked)
        for tr, e_new in zip(states, got, strict=True):
            if tr.trial is None:
                continue
            d, pts, steps, predicted = tr.trial
            tr.evaluations += len(pts)
            f_new = float(e_new[0].max()) if np.all(np.isfinite(e_new[0])) else np.inf
            ratio = (tr.fitness - f_new) / predicted
            if ratio > 0.01:
                tr.u, tr.errors, tr.steps = pts[0], e_new, steps
                if ratio > 0.75 and np.max(np.abs(d)) > 0.99 * tr.radius:
                    tr.radius = min(2.0 * tr.radius, 0.5)
            if ratio < 0.25:
                tr.radius /= 4.0
            if tr.radius < min_radius:
                tr.done = True
    out = []
    for tr in states:
        tr.history.append((len(tr.history), tr.fitness, simulations()))
        out.append(FitResult("minimax", space, space.from_unit(tr.u), tr.fitness, tr.history,
                             tr.evaluations))
    return out


def polish_least_squares(
    residuals: Callable[[np.ndarray], np.ndarray],
    objective: Objective,
    space: ParameterSpace,
    start: np.ndarray,
    start_fitness: float,
    max_iterations: int = 20,
) -> FitResult:
    """Local least-squares polish (scipy ``least_squares``, trust region, finite differences).

    The polished point is kept only if its minimax fitness is no worse than the start's (least
    squares and minimax differ).

    Parameters
    ----------
    residuals : callable
        Candidates (C, K) -> stacked residuals (C, M) (:meth:`Evaluator.residuals`).
    objective : callable
        Candidates -> minimax fitness, to judge the result.
    space : ParameterSpace
    start : ndarray, shape (K,)
    start_fitness : float
    max_iterations : int
        Jacobian evaluations at most.

    Returns
    -------
    FitResult
    """
    from scipy.optimize import least_squares

    u0 = np.clip(space.to_unit(np.asarray(start, dtype=float)), 1e-6, 1 - 1e-6)
    evaluations = 0

    def fun(u: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        return residuals(space.from_unit(u)[None, :])[0]

    def jac(u: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        pts, steps = _with_perturbations(u, FD_STEP)
        r = residuals(space.from_unit(pts))
        evaluations += len(pts)
        return ((r[1:] - r[0]) / steps[:, None]).T

    sol = least_squares(fun, u0, jac=jac, bounds=(0.0, 1.0), max_nfev=max_iterations, x_scale="jac")
    cand = space.from_unit(sol.x)
    f = float(objective(cand[None, :])[0])
    evaluations += 1
    if f <= start_fitness:
        return FitResult("lsq", space, cand, f, [(0, f, 0)], evaluations)
    return FitResult("lsq", space, np.asarray(start, float), start_fitness,
                     [(0, start_fitness, 0)], evaluations)
