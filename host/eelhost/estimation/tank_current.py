"""One ambient current for the tank, estimated from every training experiment together.

docs/estimation.md, "Nuisance parameters: the tank's ambient current". The straight and turning
fits each fit a current (:func:`eelhost.estimation.methods.run_fit`), but the experiments were
recorded in one tank. The straight experiments all swim along one axis, where a current trades
against the coefficients that set the swimming speed, so a straight fit alone puts noise and
misfit into an along-track current; the turning experiments swim every direction, where a current
and a speed error differ. So, once both fits are made:

1. **Joint fit.** The vector [straight's parameters, turning's parameters, each one-axis
   motion's current along its axis, one current] is polished by the minimax trust region
   (:func:`eelhost.estimation.local.polish_minimax_many`) on every training experiment of both
   motions, each motion's errors divided by its own fit's fitness (so that both motions weigh
   alike whatever their misfit), from three starts in lock step: the straight fit's current, the
   turning fit's and still water. A motion whose experiments all swim to one side
   (:func:`swim_axis`: the paper's straight gaits along x, its turning gaits towards their
   waypoint at 30 deg) swims in the tank's current plus a current of its own along that axis:
   along its axis a current is a speed error its coefficients can make as well, and the bundled
   noise decided which; across it, it is a drift nothing else makes. So the tank's current is
   what the motions see across their axes (:func:`cross_track_axes`: only when those views span
   the plane; otherwise nothing is decoupled). From the best start, Gauss-Newton steps
   (:func:`_least_squares`) take the joint vector to the residuals' least-squares point: the
   interval below is that estimate's, and the minimax point balances the worst experiments, and
   with them the misfit.
2. **Its interval.** The current's linearised standard error s on the joint problem (the
   residuals of both motions stacked, the Jacobian in the unit cube, the residual variance from
   the residuals, never below the pixel rounding's, the other parameters profiled out), and the
   interval c +- z s (z = 1.96) per component; or, where wider, the cluster-robust (sandwich)
   standard error with each experiment a cluster, times Student's t with G - 1 degrees of
   freedom for G experiments: a recording's residuals move together (its clock offset, its
   jitter, the misfit), so they are not independent evidence. Neither sees a misfit the
   current absorbed (the residuals no longer hold it), so the interval is widened by the Birge
   ratio of the motions' own currents (each motion's own fit taken to its least-squares point
   the same way) against the tank's (:func:`misfit_scale`): in one tank,
   with a model that holds the water, they differ by their noise only; beyond it, the misfit
   moved them, and the tank's current as much. When still water lies inside the interval, no
   current is resolved (``TankCurrent.resolved``), and the report says so.
3. **Each motion's fit holds it.** Each motion's parameters are polished again from the joint
   fit with the current bounded to that interval (``ParameterSpace.current_bounds``), so the
   bootstrap, the identifiability analysis and the validation see the tank's current, and a fit
   can move it only within what all the experiments allow.

The currents each experiment declares still add to it as vectors (a stray current that changes
per experiment is declared per experiment). With only one motion (or one set for every motion:
its fit is already shared) nothing changes.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
from scipy.stats import t as student_t

from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.identify import REL_STEP
from eelhost.estimation.local import FAILED, polish_minimax, polish_minimax_many
from eelhost.estimation.optimise import FitResult
from eelhost.estimation.space import (
    CURRENT_BOUND_M_S,
    ParameterSpace,
    box_from_unit,
    box_to_unit,
)

log = logging.getLogger(__name__)

# Iterations of the joint polish and of each motion's polish holding the tank's current.
JOINT_ITERATIONS = 12
HOLD_ITERATIONS = 8
# Gauss-Newton iterations from the minimax fits to the least-squares estimate of the current.
LEAST_SQUARES_ITERATIONS = 3
Z_95 = 1.959964  # the normal's 97.5 % quantile: the interval c +- z s
# Least half-width of the held interval, m/s: a tenth of a mm/s, so that a polish's unit cube
# keeps a range its finite differences can step in.
MIN_HALF_WIDTH_M_S = 1e-4
# Experiments whose net displacements all lie within this of their mean direction swim one axis.
AXIS_SPREAD_DEG = 20.0


@dataclass(frozen=True)
class TankCurrent:
    """The tank's ambient current, from every training experiment of both motions.

    Attributes
    ----------
    current_m_s : ndarray, shape (2,)
        (v_x, v_y), m/s.
    half_width_m_s : ndarray, shape (2,)
        Half-width of its 95 % interval per component (the bounds each motion's fit holds).
    per_motion_m_s : dict of str to ndarray
        The current each motion's own fit had found alone, for the record.
    experiments : int
        Training experiments it was estimated from.
    fitness : float
        The joint fit's largest error relative to each motion's own fitness.
    misfit_scale : float
        How much the interval was widened because the motions' own currents disagree beyond
        their intervals (:func:`misfit_scale`; 1: they agree).
    """

    current_m_s: np.ndarray
    half_width_m_s: np.ndarray
    per_motion_m_s: dict[str, np.ndarray]
    experiments: int
    fitness: float
    misfit_scale: float = 1.0

    @property
    def resolved(self) -> bool:
        """Whether the data hold a current: still water (0, 0) lies outside its interval."""
        return bool(np.any(np.abs(self.current_m_s) > self.half_width_m_s))

    def text(self) -> str:
        """"0.0050 m/s towards 120 deg (v_x -2.5 +- 0.4 mm/s, v_y +4.3 +- 0.5 mm/s)".

        Prefixed "no current resolved:" when still water lies inside the interval, and followed
        by the widening for the motions' disagreement when there was one.
        """
        vx, vy = self.current_m_s
        hx, hy = 1e3 * self.half_width_m_s
        widened = (f"; widened x{self.misfit_scale:.1f}: the motions' own currents disagree"
                   if self.misfit_scale > 1.0 else "")
        return (("" if self.resolved else "no current resolved: ")
                + f"{np.hypot(vx, vy):.4f} m/s towards {np.degrees(np.arctan2(vy, vx)):.0f} deg "
                f"(v_x {1e3 * vx:+.1f} +- {hx:.1f} mm/s, v_y {1e3 * vy:+.1f} +- {hy:.1f} mm/s"
                f"{widened})")

    def to_json(self) -> dict[str, Any]:
        """JSON-ready (``coefficients.json``'s ``tank_current``; docs/data.md)."""
        vx, vy = (float(v) for v in self.current_m_s)
        return {
            "current_x_m_s": vx, "current_y_m_s": vy,
            "speed_m_s": float(np.hypot(vx, vy)),
            "direction_deg": float(np.degrees(np.arctan2(vy, vx))),
            "half_width_m_s": [float(h) for h in self.half_width_m_s],
            "per_motion_alone": {m: [float(v) for v in c] for m, c in self.per_motion_m_s.items()},
            "experiments": self.experiments,
            "resolved": self.resolved,
            "misfit_scale": float(self.misfit_scale),
        }


@dataclass(frozen=True, eq=False)
class _JointCube:
    """The joint vector's bounds and unit-cube mapping (all :func:`polish_minimax_many` uses)."""

    bounds: np.ndarray

    @property
    def size(self) -> int:
        return len(self.bounds)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        return box_from_unit(self.bounds, u)

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        return box_to_unit(self.bounds, x)


def share_tank_current(
    fits: dict[str, FitResult],
    evaluators: dict[str, Evaluator],
    say: Callable[[str], None] | None = None,
) -> tuple[dict[str, FitResult], dict[str, Evaluator], TankCurrent | None]:
    """Replace each motion's own current by the tank's, estimated from all motions (module doc).

    Parameters
    ----------
    fits : dict of str to FitResult
        Per motion, its fit (each with its own current).
    evaluators : dict of str to Evaluator
        Per motion, the evaluator of its training experiments.
    say : callable, optional
        Gets a line with the result.

    Returns
    -------
    (fits, evaluators, TankCurrent or None)
        The fits holding the tank's current and their evaluators (in the held spaces); the
        inputs unchanged and None when fewer than two motions fit a current without failing.
    """
    say = say or log.info
    # a fit that scores a failure penalty (a run blew up or fell short) says nothing about the
    # water: its motion keeps its own current
    motions = [m for m in ("straight", "turning")
               if m in fits and fits[m].space.current and m in evaluators
               and fits[m].fitness < FAILED]
    if len(motions) < 2:
        return fits, evaluators, None
    evs = [evaluators[m] for m in motions]
    own = [np.asarray(fits[m].values, dtype=float) for m in motions]
    ks = [ev.space.size - 2 for ev in evs]  # each motion's parameters before the current
    scale = [1.0 / max(float(fits[m].fitness), 1e-9) for m in motions]
    # a motion whose experiments all swim along one axis gets a current of its own along it
    # (module doc, step 1): there it is a speed error, so the tank's current is what the other
    # motions see along that axis and what every motion sees across it
    axes = cross_track_axes([swim_axis(ev) for ev in evs])
    axial = [i for i, d in enumerate(axes) if d is not None]
    cube = _JointCube(np.vstack(
        [ev.space.bounds[:k] for ev, k in zip(evs, ks, strict=True)]
        + [np.tile([-2 * CURRENT_BOUND_M_S, 2 * CURRENT_BOUND_M_S], (len(axial), 1))]
        + [np.tile([-CURRENT_BOUND_M_S, CURRENT_BOUND_M_S], (2, 1))]).reshape(-1, 2))
    first_extra = sum(ks)

    def split(x: np.ndarray) -> list[np.ndarray]:
        """The joint vectors (C, K) as each motion's vectors (C, k_m + 2)."""
        out, at = [], 0
        for i, k in enumerate(ks):
            current = x[:, -2:]
            if axes[i] is not None:
                current = current + x[:, first_extra + axial.index(i), None] * axes[i]
            out.append(np.hstack([x[:, at:at + k], current]))
            at += k
        return out

    def evaluate(xs: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        # every start's candidates in one batch per motion
        sizes = [len(x) for x in xs]
        both = np.vstack(xs)
        errors, vectors = [], []
        for ev, part, s in zip(evs, split(both), scale, strict=True):
            e, v = ev.evaluate(part)
            errors.append(s * e)
            vectors.append(s * v)
        e_all, v_all = np.concatenate(errors, axis=1), np.concatenate(vectors, axis=1)
        edges = np.cumsum([0] + sizes)
        return [(e_all[a:b], v_all[a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)]

    body = np.concatenate([x[:k] for x, k in zip(own, ks, strict=True)])

    def start(current: np.ndarray) -> np.ndarray:
        # each axial motion's own current along its axis: what its fit found beyond ``current``
        extra = [float((own[i][-2:] - current) @ axes[i]) for i in axial]  # type: ignore[operator]
        return np.concatenate([body, extra, current])

    starts = np.array([start(x[-2:]) for x in own] + [start(np.zeros(2))])
    results = polish_minimax_many(evaluate, cast(ParameterSpace, cube), starts, JOINT_ITERATIONS)
    best = min(results, key=lambda r: r.fitness)
    joint = _least_squares(evs, cube, split, np.asarray(best.values, dtype=float))
    current = joint[-2:]
    half, scale_by = _interval(evs, cube, split, joint, own)
    new_fits, new_evs = dict(fits), dict(evaluators)
    for m, ev, part in zip(motions, evs, split(joint[None]), strict=True):
        held = replace(ev.space, current_bounds=np.column_stack(
            [np.maximum(current - half, -CURRENT_BOUND_M_S),
             np.minimum(current + half, CURRENT_BOUND_M_S)]))
        held_ev = ev.with_space(held)
        # from its joint-fit parameters in the tank's current (not its own along its axis)
        begin = np.concatenate([part[0][:-2], current])
        pol = polish_minimax(held_ev.evaluate, held, begin, HOLD_ITERATIONS)
        runs = held_ev.simulations
        ev.simulations += runs  # the motion's count of simulations includes these
        held_ev.simulations = ev.simulations
        last = fits[m].history[-1] if fits[m].history else (0, pol.fitness, 0)
        history = fits[m].history + [(int(last[0]) + 1, pol.fitness, int(last[2]) + runs)]
        new_fits[m] = FitResult(f"{fits[m].method}, tank current held", held,
                                np.asarray(pol.values, dtype=float), pol.fitness, history,
                                fits[m].evaluations + pol.evaluations,
                                search_evaluations=fits[m].search_evaluations)
        new_evs[m] = held_ev
    tank = TankCurrent(current, half, {m: x[-2:] for m, x in zip(motions, own, strict=True)},
                       sum(len(ev.prepared) for ev in evs), best.fitness, scale_by)
    say(f"tank current from {tank.experiments} training experiments ({', '.join(motions)}): "
        f"{tank.text()}; alone: " + "; ".join(
            f"{m} {1e3 * np.hypot(*c):.1f} mm/s towards {np.degrees(np.arctan2(c[1], c[0])):.0f} deg"
            for m, c in tank.per_motion_m_s.items()))
    return new_fits, new_evs, tank


def misfit_scale(current: np.ndarray, views: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """The factor that widens the tank current's interval when the motions disagree (step 2).

    Each motion's own fit found a current c_m with covariance S_m (its own residuals, the other
    parameters profiled out; along a motion's swimming axis S_m is wide where its coefficients
    trade against it). In one tank and a model that holds the water they differ from the tank's
    current c by their noise only, and Q = sum (c_m - c)^T S_m^-1 (c_m - c) is about chi^2 with
    2 M - 2 degrees of freedom for M motions. A model's misfit moves each motion's current its
    own way; the tank's current, fitted on the same misfit, moves as much, which its interval
    from the residuals cannot see. So the interval is widened by sqrt(Q / (2 M - 2)) when that
    exceeds 1: the Birge ratio (the Particle Data Group's scale factor for measurements that
    disagree beyond their errors).

    Parameters
    ----------
    current : ndarray, shape (2,)
        The tank's current, m/s.
    views : list of (ndarray (2,), ndarray (2, 2))
        Each motion's own current and its covariance, (m/s)^2.

    Returns
    -------
    float
        At least 1.
    """
    if len(views) < 2:
        return 1.0
    q = sum(float((c - current) @ np.linalg.pinv(cov) @ (c - current)) for c, cov in views)
    return float(np.sqrt(max(1.0, q / (2 * len(views) - 2))))


def swim_axis(ev: Evaluator) -> np.ndarray | None:
    """The unit axis every experiment of ``ev`` swims along, or None.

    From the recordings: each one's net displacement, first frame to last. One axis when every
    displacement lies within ``AXIS_SPREAD_DEG`` of their mean direction (the straight gaits);
    circles and paths swim every direction.
    """
    moves = np.array([p.experiment.position_m[-1] - p.experiment.position_m[0]
                      for p in ev.prepared])
    lengths = np.linalg.norm(moves, axis=1)
    if np.any(lengths <= 0):
        return None
    units = moves / lengths[:, None]
    mean = units.mean(axis=0)
    if np.linalg.norm(mean) == 0:
        return None
    axis = mean / np.linalg.norm(mean)
    if np.any(units @ axis < np.cos(np.radians(AXIS_SPREAD_DEG))):
        return None
    return axis


def cross_track_axes(axes: list[np.ndarray | None]) -> list[np.ndarray | None]:
    """The motions' swim axes, or all None where their cross-track drifts cannot fix a current.

    Across its axis each one-axis motion sees the current; along it, only the motions that are
    not one-axis do. The current is found when those views span the plane: a motion without an
    axis, or two axes more than ``AXIS_SPREAD_DEG`` apart. Otherwise (every motion along one
    axis) nothing is decoupled and each motion's along-track current is the tank's, as before.
    """
    given = [d for d in axes if d is not None]
    if len(given) < len(axes):
        return axes
    spread = np.cos(np.radians(AXIS_SPREAD_DEG))
    if any(abs(float(a @ b)) < spread for a in given for b in given):
        return axes
    return [None] * len(axes)


@dataclass(frozen=True)
class _Spread:
    """The current's covariance on a fit (module doc, step 2), (m/s)^2.

    ``independent``: from independent residuals, its 95 % half-width z sqrt(diag); ``robust``:
    cluster-robust (experiments the clusters), its half-width t(G - 1) sqrt(diag), or None with
    one experiment; ``quantile``: t(G - 1) / z, the robust one's widening of z.
    """

    independent: np.ndarray
    robust: np.ndarray | None
    quantile: float

    def half_width(self) -> np.ndarray:
        """The 95 % half-width per component: the wider of the two intervals."""
        half = Z_95 * np.sqrt(np.clip(np.diag(self.independent), 0.0, None))
        if self.robust is not None:
            half = np.maximum(half, Z_95 * self.quantile
                              * np.sqrt(np.clip(np.diag(self.robust), 0.0, None)))
        return half

    def covariance(self) -> np.ndarray:
        """The covariance of the wider interval, as a normal's (the robust one times its t)."""
        if self.robust is None:
            return self.independent
        robust = self.robust * self.quantile**2
        return robust if np.trace(robust) > np.trace(self.independent) else self.independent


def _interval(evs: list[Evaluator], cube: _JointCube,
              split: Callable[[np.ndarray], list[np.ndarray]], joint: np.ndarray,
              own: list[np.ndarray]) -> tuple[np.ndarray, float]:
    """The tank current's 95 % half-width per component and its widening for misfit (step 2).

    ``own`` holds each motion's own fit (its vector, current last) in its own space, taken to
    its least-squares point (:func:`_least_squares`) as ``joint`` was. The half-width on the
    joint problem (:func:`_half_width`) times :func:`misfit_scale` of the motions' own
    currents, each with its covariance on its own residuals.
    """
    def alone(x: np.ndarray) -> list[np.ndarray]:
        return [x]

    own = [_least_squares([ev], _JointCube(ev.space.bounds), alone, x)
           for ev, x in zip(evs, own, strict=True)]
    views = [_spread([ev], _JointCube(ev.space.bounds), alone, x)
             for ev, x in zip(evs, own, strict=True)]
    scale_by = misfit_scale(joint[-2:], [(x[-2:], v.covariance())
                                         for x, v in zip(own, views, strict=True)
                                         if v is not None])
    half = np.clip(scale_by * _half_width(evs, cube, split, joint), MIN_HALF_WIDTH_M_S,
                   CURRENT_BOUND_M_S)
    return half, scale_by


def _half_width(evs: list[Evaluator], cube: _JointCube,
                split: Callable[[np.ndarray], list[np.ndarray]], joint: np.ndarray) -> np.ndarray:
    """Half-width of the current's 95 % interval, per component (module doc, step 2).

    :func:`_spread`'s wider interval; a current the other parameters can explain gets the whole
    search bound.
    """
    spread = _spread(evs, cube, split, joint)
    if spread is None:
        return np.full(2, CURRENT_BOUND_M_S)
    return np.clip(spread.half_width(), MIN_HALF_WIDTH_M_S, CURRENT_BOUND_M_S)


def _jacobian(evs: list[Evaluator], cube: _JointCube,
              split: Callable[[np.ndarray], list[np.ndarray]],
              x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Residuals at ``x`` and its forward-difference neighbours, each motion's, and the Jacobian.

    Returns (r, parts, jac): r (K + 1, M) the stacked residuals at x and at each step, parts the
    same per motion, jac (M, K) in unit-cube coordinates (steps of ``REL_STEP``, backwards at
    the upper bound).
    """
    k = cube.size
    u0 = cube.to_unit(x)
    steps = np.where(u0 + REL_STEP <= 1.0, REL_STEP, -REL_STEP)
    pts = np.vstack([x] + [cube.from_unit(u0 + np.eye(k)[i] * steps[i]) for i in range(k)])
    parts = [ev.residuals(part) for ev, part in zip(evs, split(pts), strict=True)]
    r = np.hstack(parts)
    return r, parts, ((r[1:] - r[0]) / steps[:, None]).T


def _least_squares(evs: list[Evaluator], cube: _JointCube,
                   split: Callable[[np.ndarray], list[np.ndarray]],
                   x: np.ndarray) -> np.ndarray:
    """Gauss-Newton from ``x`` to the residuals' least-squares point (module doc, step 2).

    The interval is that of the least-squares estimate, so the current reported is that
    estimate, not the minimax fit's (which balances the worst experiments, and with them the
    misfit). Each step the minimum-norm solution of J d = -r in the unit cube, clipped to the
    bounds and halved until the sum of squares falls (at most four times); it stops when none does.
    """
    x = np.asarray(x, dtype=float)
    for _ in range(LEAST_SQUARES_ITERATIONS):
        r, _, jac = _jacobian(evs, cube, split, x)
        cost = float(r[0] @ r[0])
        d = np.linalg.lstsq(jac, -r[0], rcond=1e-9)[0]
        u0 = cube.to_unit(x)
        for _ in range(4):
            trial = cube.from_unit(np.clip(u0 + d, 0.0, 1.0))
            rt = np.hstack([ev.residuals(part) for ev, part in zip(evs, split(trial[None]),
                                                                 strict=True)])[0]
            if float(rt @ rt) < cost:
                x = trial
                break
            d = d / 2
        else:
            break
    return x


def _spread(evs: list[Evaluator], cube: _JointCube,
            split: Callable[[np.ndarray], list[np.ndarray]], joint: np.ndarray) -> _Spread | None:
    """The current's covariance at ``joint``, or None where the other parameters explain it.

    As :func:`eelhost.estimation.identify.identifiability` (Jacobian in the unit cube, residual
    variance never below the pixel rounding's), on the residuals of ``evs`` stacked, with the
    other parameters profiled out; and the cluster-robust one with each experiment a cluster.
    """
    k = cube.size
    r, parts, jac = _jacobian(evs, cube, split, joint)
    # each residual's experiment (a cluster): an evaluator's columns are its experiments' blocks
    cluster = np.concatenate([
        first + np.repeat(np.arange(len(ev.prepared)), p.shape[1] // len(ev.prepared))
        for first, ev, p in zip(np.cumsum([0] + [len(ev.prepared) for ev in evs[:-1]]), evs,
                                parts, strict=True)])
    pixel = max(float(p.experiment.recording_camera().pixel_m) for ev in evs for p in ev.prepared)
    sigma2 = max(float(r[0] @ r[0]) / max(1, jac.shape[0] - k), pixel**2 / 12.0)
    # the current's covariance with the other parameters profiled out: its columns' part that
    # no combination of the others' columns explains. A parameter no residual sees (C_m) has no
    # column to trade against the current, so it widens nothing (a plain inverse of J^T J made
    # every share of such a direction infinite)
    others, current = jac[:, :-2], jac[:, -2:]
    u, sing, _ = np.linalg.svd(others, full_matrices=False)
    u = u[:, sing > 1e-9 * sing[0]] if sing.size and sing[0] > 0 else u[:, :0]
    alone = current - u @ (u.T @ current)
    info = alone.T @ alone
    scale = float(np.sum(current**2)) or 1.0
    ranges = cube.bounds[-2:, 1] - cube.bounds[-2:, 0]
    if np.linalg.eigvalsh(info).min() <= 1e-12 * scale:  # the others explain the current
        return None
    bread = np.linalg.inv(info)
    to_m_s = np.outer(ranges, ranges)  # unit-cube covariance to (m/s)^2
    # the same with the residuals correlated within each experiment (a clock offset or a misfit
    # shifts a whole recording): the cluster-robust sandwich, experiments the clusters, with the
    # small-sample factor G / (G - 1) and Student's t with G - 1 degrees of freedom (Cameron &
    # Miller 2015, "A practitioner's guide to cluster-robust inference"). The
    # independent-residual variance above counts every sample as evidence, and gave the servo
    # model's current on a servo tank +-1.1 mm/s, 3.2 mm/s off the truth
    scores = np.array([alone[cluster == g].T @ r[0][cluster == g]
                       for g in np.unique(cluster)])  # (G, 2)
    groups = len(scores)
    if groups < 2:
        return _Spread(sigma2 * bread * to_m_s, None, 1.0)
    robust = bread @ (scores.T @ scores) @ bread * groups / (groups - 1)
    return _Spread(sigma2 * bread * to_m_s, robust * to_m_s,
                   float(student_t.ppf(0.975, groups - 1)) / Z_95)
