"""Local polishes of a fit: the minimax trust region (the paper's fitness) and least squares.

Both work in the unit cube of a :class:`~eelhost.estimation.space.ParameterSpace` with
forward-difference Jacobians, the point and its K perturbations simulated as one batch.

- :func:`polish_minimax` minimises the paper's fitness, the largest per-experiment error, itself.
  That fitness is not smooth twice over: the maximum has a kink where two experiments' errors
  cross (where a minimax optimum usually sits), and each error, a sum of norms of position and
  velocity differences, has a cone-shaped kink wherever one difference passes through zero
  (measured: along C_f an error's slope turns from -14 to +12 within 1e-3 of the range). A
  least-squares polish or a smooth method on the fitness stalls there; a linear model of the
  errors themselves does too. So the model linearises the smooth part, the difference vectors
  r_jk (2-vectors: positions, and w times velocities, at the samples), and keeps the norms and
  the maximum exact: the step d solves the second-order cone programme

      min t  subject to  sum_k |r_jk + R_jk d| <= t for every experiment j,
                         |d|_inf <= radius,  0 <= u + d <= 1

  (R_jk = dr_jk/du by forward differences; the cone solver Clarabel), the minimax analogue of
  Gauss-Newton. The step is taken when the true fitness falls, and the radius grows or shrinks
  with the ratio of the true to the predicted decrease.
- :func:`polish_least_squares` minimises the sum of squared residuals (scipy ``least_squares``),
  the smooth problem the identifiability analysis linearises.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from eelhost.estimation.optimise import FitResult, Objective
from eelhost.estimation.space import ParameterSpace

Evaluate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""Candidates (C, K) -> (errors (C, E), residual vectors (C, E, m, 2)), as
:meth:`Evaluator.evaluate` gives them."""

ManyEvaluate = Callable[[list[np.ndarray]], list[tuple[np.ndarray, np.ndarray]]]
"""The candidates of B problems (a list of (C_b, K) arrays) -> each one's :data:`Evaluate`
answer; an empty array asks nothing of that problem."""

FD_STEP = 1e-3  # forward-difference step in the unit cube (a thousandth of each range)
FAILED = 1e5  # an error this large is a failure penalty: no slopes to follow


def _with_perturbations(u: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """The point and its K forward perturbations (inwards at the upper bound), and the steps."""
    steps = np.where(u + step <= 1.0, step, -step)
    return np.vstack([u[None, :], u[None, :] + np.diag(steps)]), steps


def cone_step(
    vectors: np.ndarray, jacobian: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, float] | None:
    """The step of the linearised minimax model within a box, and the model's value there.

    Parameters
    ----------
    vectors : ndarray, shape (E, m, 2)
        Residual 2-vectors r_jk; error_j = sum_k |r_jk|.
    jacobian : ndarray, shape (E, m, 2, K)
        Their derivatives.
    lower, upper : ndarray, shape (K,)
        The box for the step.

    Returns
    -------
    (step, value) or None
        None when the cone solver does not solve it.
    """
    import clarabel
    from scipy import sparse

    e, m, _, k = jacobian.shape
    n_cones = e * m
    nvar = k + 1 + n_cones  # d, t, s_jk
    it = k  # index of t
    rows_a, rhs, cones = [], [], []
    # t - sum_k s_jk >= 0 for each experiment
    a = np.zeros((e, nvar))
    a[:, it] = -1.0
    for j in range(e):
        a[j, k + 1 + j * m : k + 1 + (j + 1) * m] = 1.0
    rows_a.append(a)
    rhs.append(np.zeros(e))
    # the box: d <= upper, -d <= -lower
    box = np.zeros((2 * k, nvar))
    box[:k, :k] = np.eye(k)
    box[k:, :k] = -np.eye(k)
    rows_a.append(box)
    rhs.append(np.r_[upper, -lower])
    cones.append(clarabel.NonnegativeConeT(e + 2 * k))
    # (s_jk, r_jk + R_jk d) in the second-order cone
    soc = np.zeros((3 * n_cones, nvar))
    soc_b = np.zeros(3 * n_cones)
    flat_r = vectors.reshape(n_cones, 2)
    flat_j = jacobian.reshape(n_cones, 2, k)
    for c in range(n_cones):
        soc[3 * c, k + 1 + c] = -1.0
        soc[3 * c + 1 : 3 * c + 3, :k] = -flat_j[c]
        soc_b[3 * c + 1 : 3 * c + 3] = flat_r[c]
    rows_a.append(soc)
    rhs.append(soc_b)
    cones += [clarabel.SecondOrderConeT(3)] * n_cones
    q = np.zeros(nvar)
    q[it] = 1.0
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    solver = clarabel.DefaultSolver(
        sparse.csc_matrix((nvar, nvar)), q, sparse.csc_matrix(np.vstack(rows_a)),
        np.concatenate(rhs), cones, settings,
    )
    sol = solver.solve()
    if str(sol.status) not in ("Solved", "AlmostSolved"):
        return None
    x = np.asarray(sol.x)
    return x[:k], float(x[it])


@dataclass
class _TrustRegion:
    """One problem's state in :func:`polish_minimax_many`."""

    u: np.ndarray
    errors: np.ndarray  # at u and its K perturbations, shape (K + 1, E)
    vectors: np.ndarray  # their residual vectors, shape (K + 1, E, m, 2)
    steps: np.ndarray
    radius: float
    history: list[tuple[int, float, int]] = field(default_factory=list)
    evaluations: int = 0
    done: bool = False
    # the step under trial: (step d, its point and perturbations, their steps, predicted decrease)
    trial: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None
    # the parameters whose forward perturbation failed, probed backwards (points, columns)
    probe: tuple[np.ndarray, np.ndarray] | None = None
    probed: bool = False  # the current point's failed perturbations were probed backwards

    @property
    def fitness(self) -> float:
        return float(self.errors[0].max())


def polish_minimax(
    evaluate: Evaluate,
    space: ParameterSpace,
    start: np.ndarray,
    max_iterations: int = 30,
    radius: float = 0.05,
    min_radius: float = 1e-5,
    simulations: Callable[[], int] = lambda: 0,
) -> FitResult:
    """Minimise max_j error_j from ``start`` by the trust-region cone programme (module doc).

    Parameters
    ----------
    evaluate : callable
        Candidates (C, K) -> (errors (C, E), residual vectors (C, E, m, 2))
        (:meth:`Evaluator.evaluate`).
    space : ParameterSpace
    start : ndarray, shape (K,)
        Parameters to start from.
    max_iterations : int
        Steps tried at most (each costs one batch of K + 1 candidates).
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
        lambda xs: [evaluate(xs[0])], space, np.asarray(start, float)[None], max_iterations,
        radius, min_radius, simulations,
    )[0]


def polish_minimax_many(
    evaluate: ManyEvaluate,
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
    evaluate : callable
        See :data:`ManyEvaluate`.
    space : ParameterSpace
    starts : ndarray, shape (B, K)
    max_iterations, radius, min_radius, simulations
        As for :func:`polish_minimax`.

    Returns
    -------
    list of FitResult
        One per problem, each never worse than its start.
    """
    first = [_with_perturbations(u, FD_STEP)
             for u in np.clip(space.to_unit(np.atleast_2d(starts)), 0.0, 1.0)]
    got = evaluate([space.from_unit(pts) for pts, _ in first])
    states = [_TrustRegion(pts[0], e, v, st, radius, evaluations=len(pts))
              for (pts, st), (e, v) in zip(first, got, strict=True)]
    empty = np.zeros((0, space.size))
    for it in range(max_iterations):
        for tr in states:
            if not tr.done:
                _propose(tr, it, simulations())
        asked = [space.from_unit(tr.trial[1]) if tr.trial is not None else
                 space.from_unit(tr.probe[0]) if tr.probe is not None else empty
                 for tr in states]
        if not any(len(a) for a in asked):
            break
        got = evaluate(asked)
        for tr, (e_new, v_new) in zip(states, got, strict=True):
            if tr.trial is not None:
                _judge(tr, e_new, v_new, min_radius)
            elif tr.probe is not None:
                _take_probe(tr, e_new, v_new)
    out = []
    for tr in states:
        tr.history.append((len(tr.history), tr.fitness, simulations()))
        out.append(FitResult("minimax", space, space.from_unit(tr.u), tr.fitness, tr.history,
                             tr.evaluations))
    return out


def _propose(tr: _TrustRegion, iteration: int, simulations: int) -> None:
    """Solve the trust region's cone programme and set the step to try (or finish)."""
    tr.history.append((iteration, tr.fitness, simulations))
    tr.trial = None
    tr.probe = None
    v = tr.vectors
    if tr.fitness >= FAILED or not np.all(np.isfinite(v[0])):  # a failed run: no slopes
        tr.done = True
        return
    jac = np.moveaxis((v[1:] - v[0]) / tr.steps[:, None, None, None], 0, -1)  # (E, m, 2, K)
    blind = ~np.isfinite(jac).all(axis=(0, 1, 2))
    if blind.any() and not tr.probed:
        # a forward perturbation failed (e.g. a run pushed over the too-slow limit, a joint at
        # its stop): probe those parameters backwards before giving up their slope; freezing
        # them had kept a fitted current at exactly its still-water start
        cols = np.flatnonzero(blind)
        back = np.clip(tr.u[None, :] - np.diag(tr.steps)[cols], 0.0, 1.0)
        tr.probe, tr.probed = (back, cols), True
        return
    # a perturbation that failed both ways gives no slope: this step keeps that parameter
    # where it is
    jac[..., blind] = 0.0
    lower = np.where(blind, 0.0, np.maximum(-tr.radius, -tr.u))
    upper = np.where(blind, 0.0, np.minimum(tr.radius, 1.0 - tr.u))
    solved = cone_step(v[0], jac, lower, upper)
    if solved is None:
        tr.done = True
        return
    d, model = solved
    predicted = tr.fitness - model
    if predicted <= 1e-12 * max(1.0, tr.fitness):
        tr.done = True
        return
    pts, steps = _with_perturbations(np.clip(tr.u + d, 0.0, 1.0), FD_STEP)
    tr.trial = (d, pts, steps, predicted)


def _take_probe(tr: _TrustRegion, errors: np.ndarray, vectors: np.ndarray) -> None:
    """Use the backward perturbations that ran in place of the forward ones that failed."""
    assert tr.probe is not None
    _, cols = tr.probe
    tr.evaluations += len(cols)
    for row, col in enumerate(cols):
        if np.all(np.isfinite(vectors[row])) and errors[row].max() < FAILED:
            tr.errors[1 + col], tr.vectors[1 + col] = errors[row], vectors[row]
            tr.steps[col] = -tr.steps[col]
    tr.probe = None


def _judge(tr: _TrustRegion, errors: np.ndarray, vectors: np.ndarray, min_radius: float) -> None:
    """Take or refuse the step tried, and resize the trust region."""
    assert tr.trial is not None
    d, pts, steps, predicted = tr.trial
    tr.evaluations += len(pts)
    f_new = float(errors[0].max()) if np.all(np.isfinite(errors[0])) else np.inf
    ratio = (tr.fitness - f_new) / predicted
    if ratio > 0.01:
        tr.u, tr.errors, tr.vectors, tr.steps = pts[0], errors, vectors, steps
        tr.probed = False
        if ratio > 0.75 and np.max(np.abs(d)) > 0.99 * tr.radius:
            tr.radius = min(2.0 * tr.radius, 0.5)
    if ratio < 0.25:
        tr.radius /= 4.0
    if tr.radius < min_radius:
        tr.done = True


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
