"""One ambient current for the tank, estimated from every training experiment together.

docs/estimation.md, "Nuisance parameters: the tank's ambient current". The straight and turning
fits each fit a current (:func:`eelhost.estimation.methods.run_fit`), but the experiments were
recorded in one tank. So, once both fits are made:

1. **Each motion's view, weighed by what it tells.** Each motion's own fit is taken to its
   residuals' least-squares point (:func:`_least_squares`, SciPy's bounded trust-region least
   squares from the minimax fit, which balances the worst experiments and with them the misfit),
   and its current there has a covariance (:func:`_spread`: linearised, the other parameters
   profiled out, the wider of the independent-residual and the cluster-robust one). A motion
   whose experiments all swim to one side (:func:`swim_axis`: the paper's straight gaits along
   x, its turning gaits towards their waypoint at 30 deg) tells only its current across that
   axis: along it a current is a speed error its coefficients can make as well, and the
   recording's clock offset and the controller's timing jitter shift it along the track too (on
   a servo tank the straight fit's along-track current came out 4 mm/s off, twice its own
   cluster-robust standard error, its cross-track one within 0.1 mm/s), so its along-track
   view is left out, not weighed (:func:`cross_track_axes`: only when the views left span the
   plane; otherwise every view counts whole). The tank's current is the information-weighted
   least squares of the views (:func:`combine_views`): each view weighs by the inverse of its
   covariance, a one-axis view by the inverse variance of its cross-track current.
2. **Its interval.** The covariance of that combination on every experiment of every motion
   together: from independent residuals or, where wider, cluster-robust with each experiment a
   cluster and Student's t with G - 1 degrees of freedom for all G experiments (a recording's
   residuals move together: its clock offset, its jitter, the misfit). Neither sees a misfit the
   currents absorbed, so it is widened by the Birge ratio of the motions' own currents against
   the tank's (:func:`misfit_scale`): in one tank, with a model that holds the water, they
   differ by their noise only; beyond it, the misfit moved them, and the tank's current as
   much. The interval of each component is the shadow of the 95 % confidence ellipse on its
   axis (simultaneous intervals), and a current is **resolved** when still water lies outside
   that ellipse (the Wald test of both components at once) and at least two motions' views
   each see a current on their own (:func:`sees_a_current`; ``TankCurrent.resolved``): two
   one-axis views fix the current exactly, nothing left to disagree, so a misfit that drifts
   one motion's gaits across their track (a turning all one way that the model gets wrong)
   would otherwise pass for a current. Otherwise the report says "no current resolved", and
   the bounds the fits hold reach still water.
3. **Each motion's fit holds it.** Each motion's parameters are polished again from its
   least-squares point with the current bounded to that interval
   (``ParameterSpace.current_bounds``), so the bootstrap, the identifiability analysis and the
   validation see the tank's current, and a fit can move it only within what all the
   experiments allow.

The currents each experiment declares still add to it as vectors (a stray current that changes
per experiment is declared per experiment). With only one motion nothing changes; one set for
every motion (``{"joint": fit}``, its current already shared) gets the same interval, verdict
and holding from its own view.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
from scipy.optimize import least_squares as scipy_least_squares
from scipy.stats import chi2
from scipy.stats import t as student_t

from eelhost.estimation.evaluate import Evaluator, many_problems
from eelhost.estimation.identify import REL_STEP
from eelhost.estimation.local import FAILED, polish_minimax_many
from eelhost.estimation.optimise import FitResult
from eelhost.estimation.space import (
    CURRENT_BOUND_M_S,
    box_from_unit,
    box_to_unit,
)

log = logging.getLogger(__name__)

# Iterations of each motion's polish holding the tank's current.
HOLD_ITERATIONS = 8
# Residual evaluations (each one run per experiment) of the trust-region least squares that
# takes each motion's fit to its least-squares point; its Jacobians cost K + 1 runs each.
LEAST_SQUARES_EVALUATIONS = 20
Z_95 = 1.959964  # the normal's 97.5 % quantile: the interval c +- z s
# Least half-width of the held interval, m/s: a tenth of a mm/s, so that a polish's unit cube
# keeps a range its finite differences can step in.
MIN_HALF_WIDTH_M_S = 1e-4
# Experiments whose net displacements all lie within this of their mean direction swim one axis.
AXIS_SPREAD_DEG = 20.0
# chi-squared with 2 degrees of freedom at 95 %: still water outside the current's ellipse
RESOLVED_CHI2 = float(chi2.ppf(0.95, 2))
# with 1 degree of freedom: a one-axis view's cross-track current away from still water
SEEN_ACROSS_CHI2 = float(chi2.ppf(0.95, 1))


@dataclass(frozen=True)
class TankCurrent:
    """The tank's ambient current, from every training experiment of both motions.

    Attributes
    ----------
    current_m_s : ndarray, shape (2,)
        (v_x, v_y), m/s.
    half_width_m_s : ndarray, shape (2,)
        Half-width of its interval per component, the shadow of its 95 % confidence ellipse
        (the bounds each motion's fit holds).
    per_motion_m_s : dict of str to ndarray
        The current each motion's own fit had found alone, for the record.
    experiments : int
        Training experiments it was estimated from.
    fitness : float
        The largest held fit's fitness relative to its motion's own fit's (what holding the
        tank's current costs).
    misfit_scale : float
        How much the interval was widened because the motions' own currents disagree beyond
        their intervals (:func:`misfit_scale`; 1: they agree).
    covariance_m2_s2 : ndarray, shape (2, 2), or None
        The current's covariance (widened as the interval), (m/s)^2; None: unknown (then
        ``resolved`` asks each component's interval).
    seen_by : tuple of str, or None
        The motions whose own view, alone, puts still water outside its 95 % interval in what
        it tells (:func:`sees_a_current`); None: not asked (one view).
    """

    current_m_s: np.ndarray
    half_width_m_s: np.ndarray
    per_motion_m_s: dict[str, np.ndarray]
    experiments: int
    fitness: float
    misfit_scale: float = 1.0
    covariance_m2_s2: np.ndarray | None = None
    seen_by: tuple[str, ...] | None = None

    @property
    def outside_ellipse(self) -> bool:
        """Whether still water lies outside the current's 95 % confidence ellipse.

        The Wald test of (0, 0) on both components at once, c^T V^-1 c against chi-squared
        with 2 degrees of freedom (5.99): asking each component's 95 % interval instead calls a
        still tank's current resolved about one time in ten. Without a covariance, whether
        (0, 0) lies outside the interval of either component.
        """
        if self.covariance_m2_s2 is None:
            return bool(np.any(np.abs(self.current_m_s) > self.half_width_m_s))
        c = self.current_m_s
        return bool(float(c @ np.linalg.pinv(self.covariance_m2_s2) @ c) > RESOLVED_CHI2)

    @property
    def corroborated(self) -> bool:
        """Whether at least two motions' views each see a current on their own (or one view)."""
        return self.seen_by is None or len(self.seen_by) >= 2

    @property
    def resolved(self) -> bool:
        """Whether the data hold a current: outside the ellipse, and seen by two motions' views.

        A current is something every motion swims in: where only one motion's view sees it,
        the others' saying still water across their own tracks, it is what that motion's
        model misfit makes as well (module doc, step 2), and it is not called resolved.
        """
        return self.outside_ellipse and self.corroborated

    def text(self) -> str:
        """"0.0050 m/s towards 120 deg (v_x -2.5 +- 0.4 mm/s, v_y +4.3 +- 0.5 mm/s)".

        Prefixed "no current resolved:" when still water lies inside the interval, and followed
        by the widening for the motions' disagreement when there was one.
        """
        vx, vy = self.current_m_s
        hx, hy = 1e3 * self.half_width_m_s
        widened = (f"; widened x{self.misfit_scale:.1f}: the motions' own currents disagree"
                   if self.misfit_scale > 1.0 else "")
        alone = (f"; seen by {', '.join(self.seen_by) or 'no motion'}'s view alone"
                 if self.outside_ellipse and not self.corroborated and self.seen_by is not None
                 else "")
        return (("" if self.resolved else "no current resolved: ")
                + f"{np.hypot(vx, vy):.4f} m/s towards {np.degrees(np.arctan2(vy, vx)):.0f} deg "
                f"(v_x {1e3 * vx:+.1f} +- {hx:.1f} mm/s, v_y {1e3 * vy:+.1f} +- {hy:.1f} mm/s"
                f"{widened}{alone})")

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
            **({} if self.seen_by is None else {"seen_by": list(self.seen_by)}),
            **({} if self.covariance_m2_s2 is None else
               {"covariance_m2_s2": [[float(v) for v in row] for row in self.covariance_m2_s2]}),
        }


def share_tank_current(
    fits: dict[str, FitResult],
    evaluators: dict[str, Evaluator],
    say: Callable[[str], None] | None = None,
) -> tuple[dict[str, FitResult], dict[str, Evaluator], TankCurrent | None]:
    """Replace each motion's own current by the tank's, estimated from all motions (module doc).

    Parameters
    ----------
    fits : dict of str to FitResult
        Per motion, its fit (each with its own current); or ``{"joint": fit}``, one set for
        every motion (its current is already shared: it gets its interval and verdict).
    evaluators : dict of str to Evaluator
        Per motion, the evaluator of its training experiments.
    say : callable, optional
        Gets a line with the result.

    Returns
    -------
    (fits, evaluators, TankCurrent or None)
        The fits holding the tank's current and their evaluators (in the held spaces); the
        inputs unchanged and None when fewer than two motions (or no one set) fit a current
        without failing.
    """
    say = say or log.info
    # a fit that scores a failure penalty (a run blew up or fell short) says nothing about the
    # water: its motion keeps its own current
    usable = [m for m in fits if fits[m].space.current and m in evaluators
              and fits[m].fitness < FAILED]
    motions: list[str] = [m for m in ("straight", "turning") if m in usable]
    if len(motions) < 2:
        motions = ["joint"] if usable == ["joint"] and list(fits) == ["joint"] else []
    if not motions:
        return fits, evaluators, None
    evs = [evaluators[m] for m in motions]
    axes: list[np.ndarray | None] = (cross_track_axes([swim_axis(ev) for ev in evs])
                                     if len(evs) > 1 else [None])
    own, current, covariance, scale_by, seeing = estimate(
        evs, [np.asarray(fits[m].values, dtype=float) for m in motions], axes)
    half = np.clip(np.sqrt(RESOLVED_CHI2 * np.clip(np.diag(covariance), 0.0, None)),
                   MIN_HALF_WIDTH_M_S, CURRENT_BOUND_M_S)
    seen_by = (tuple(m for m, sees in zip(motions, seeing, strict=True) if sees)
               if len(motions) > 1 else None)
    tank = TankCurrent(current, half, {m: x[-2:] for m, x in zip(motions, own, strict=True)},
                       sum(len(ev.prepared) for ev in evs), 0.0, scale_by, covariance, seen_by)
    # the bounds each fit holds: the interval, and still water with it where no current is
    # resolved (the data do not rule it out)
    lower, upper = current - half, current + half
    if not tank.resolved:
        lower, upper = np.minimum(lower, 0.0), np.maximum(upper, 0.0)
    new_fits, new_evs = dict(fits), dict(evaluators)
    worst = 0.0
    for m, ev, x in zip(motions, evs, own, strict=True):
        held = replace(ev.space, current_bounds=np.column_stack(
            [np.maximum(lower, -CURRENT_BOUND_M_S), np.minimum(upper, CURRENT_BOUND_M_S)]))
        held_ev = ev.with_space(held)
        # from its own least-squares parameters in the tank's current, and from the motion's
        # own fit with its current brought into the held bounds (the polish clips its start):
        # the lower is kept. From the first alone the held polish could end far above the fit
        # it replaces, and on a failure penalty where the motion's own current had absorbed a
        # misfit (docs/estimation.md, "One current for the tank")
        begins = np.vstack([np.concatenate([x[:-2], current]),
                            np.asarray(fits[m].values, dtype=float)])
        pol = min(polish_minimax_many(many_problems(held_ev), held, begins, HOLD_ITERATIONS),
                  key=lambda fit: float(fit.fitness))
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
        worst = max(worst, float(pol.fitness) / max(float(fits[m].fitness), 1e-9))
    tank = replace(tank, fitness=worst)
    say(f"tank current from {tank.experiments} training experiments ({', '.join(motions)}): "
        f"{tank.text()}; alone: " + "; ".join(
            f"{m} {1e3 * np.hypot(*c):.1f} mm/s towards {np.degrees(np.arctan2(c[1], c[0])):.0f} deg"
            for m, c in tank.per_motion_m_s.items()))
    return new_fits, new_evs, tank


def estimate(evs: list[Any], starts: list[np.ndarray], axes: list[np.ndarray | None]
             ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, float, list[bool]]:
    """The tank's current from the motions' own fits (module doc, steps 1 and 2).

    Parameters
    ----------
    evs : list of Evaluator
        Each motion's evaluator (``residuals``, ``space.bounds``, ``prepared``).
    starts : list of ndarray
        Each motion's fit, its current last.
    axes : list of (ndarray (2,) or None)
        Each motion's swimming axis where only its cross-track current counts
        (:func:`cross_track_axes`).

    Returns
    -------
    (own, current, covariance, scale, seeing)
        Each motion's vector at its least-squares point; the tank's current, m/s; its
        covariance, (m/s)^2, widened by ``scale`` squared; ``scale``, :func:`misfit_scale`;
        per motion, whether its view alone sees a current (:func:`sees_a_current`).
    """
    own = [_least_squares(ev, np.asarray(x, dtype=float)) for ev, x in zip(evs, starts, strict=True)]
    spreads = [_spread(ev, x) for ev, x in zip(evs, own, strict=True)]
    views = [CurrentView(x[-2:], None, a) if s is None else
             CurrentView(x[-2:], s.covariance(), a, s.independent, s.influence)
             for x, s, a in zip(own, spreads, axes, strict=True)]
    current, covariance = combine_views(views)
    scale_by = misfit_scale(current, [(v.current_m_s, v.covariance) for v in views
                                      if v.covariance is not None])
    return own, current, covariance * scale_by**2, scale_by, [sees_a_current(v) for v in views]


def sees_a_current(view: CurrentView) -> bool:
    """Whether one motion's view, alone, puts still water outside its 95 % interval.

    In what it tells: a one-axis view its cross-track current, (n . c)^2 / (n^T S n) against
    chi-squared with 1 degree of freedom (3.84); a whole view both components, c^T S^-1 c
    against 5.99. A view that tells nothing (no covariance) sees nothing.
    """
    if view.covariance is None:
        return False
    if view.axis is None:
        c = view.current_m_s
        return bool(float(c @ np.linalg.pinv(view.covariance) @ c) > RESOLVED_CHI2)
    across = np.array([-view.axis[1], view.axis[0]])
    spread = float(across @ view.covariance @ across)
    return bool(spread > 0 and float(across @ view.current_m_s) ** 2 / spread > SEEN_ACROSS_CHI2)


@dataclass(frozen=True)
class CurrentView:
    """What one motion's own fit says of the tank's current (module doc, step 1).

    Attributes
    ----------
    current_m_s : ndarray, shape (2,)
        The motion's own least-squares current, m/s.
    covariance : ndarray, shape (2, 2), or None
        Its covariance, (m/s)^2 (:func:`_spread`'s wider one), which weighs it; None where the
        motion's other parameters explain its current (it tells nothing).
    axis : ndarray, shape (2,), or None
        The unit axis it swims along when only its cross-track component counts
        (:func:`cross_track_axes`); None: both components count.
    independent : ndarray, shape (2, 2), or None
        Its covariance from independent residuals, (m/s)^2.
    influence : ndarray, shape (G, 2), or None
        Each of its experiments' pull on ``current_m_s`` (the cluster-robust scores through
        the inverse information), m/s: with ``independent``, the tank's covariance is taken on
        every experiment of every motion together.
    """

    current_m_s: np.ndarray
    covariance: np.ndarray | None
    axis: np.ndarray | None = None
    independent: np.ndarray | None = None
    influence: np.ndarray | None = None


def combine_views(views: list[CurrentView]) -> tuple[np.ndarray, np.ndarray]:
    """The tank's current from the motions' views: information-weighted least squares.

    c = (sum H_m)^-1 sum H_m c_m, where H_m is a view's information: S_m^-1 for a view whose
    both components count, and n n^T / (n^T S_m n) for a one-axis motion (n its cross-track
    unit vector, n^T S_m n the variance of its cross-track current). Its covariance is
    (sum H_m)^-1; or, when every view carries its ``independent`` covariance and its
    experiments' ``influence``, that of c = sum A_m c_m (A_m = (sum H)^-1 H_m) on all the
    experiments together, as :func:`_spread` does for one fit: sum A_m S_ind,m A_m^T from
    independent residuals, or where wider the cluster-robust sum over every experiment g of
    (A_m d_g)(A_m d_g)^T G / (G - 1), times (t(G - 1) / z)^2. A direction no view informs (the
    information singular there) gets a variance as wide as the whole search bound, and the
    current there is the views' mean.

    Parameters
    ----------
    views : list of CurrentView

    Returns
    -------
    (ndarray (2,), ndarray (2, 2))
        The current, m/s, and its covariance, (m/s)^2.
    """
    told = [v for v in views if v.covariance is not None]
    weights = []
    for view in told:
        assert view.covariance is not None
        if view.axis is None:
            weights.append(np.linalg.pinv(view.covariance))
        else:
            across = np.array([-view.axis[1], view.axis[0]])
            weights.append(np.outer(across, across)
                           / max(float(across @ view.covariance @ across), 1e-30))
    info = sum(weights, np.zeros((2, 2)))
    rhs = sum((w @ v.current_m_s for w, v in zip(weights, told, strict=True)), np.zeros(2))
    mean = np.mean([v.current_m_s for v in told] or [np.zeros(2)], axis=0)
    values, vectors = np.linalg.eigh(info)
    blind = CURRENT_BOUND_M_S**2 / RESOLVED_CHI2  # a variance whose interval is the whole bound
    inverse, unseen, current = np.zeros((2, 2)), np.zeros((2, 2)), np.zeros(2)
    for value, vector in zip(values, vectors.T, strict=True):
        if value > 1e-9 * max(float(values.max()), 1e-300):
            inverse += np.outer(vector, vector) / value
            current += vector * float(vector @ rhs) / value
        else:
            unseen += np.outer(vector, vector) * blind
            current += vector * float(vector @ mean)
    sandwiches = [(v.independent, v.influence) for v in told]
    if not told or any(i is None or d is None for i, d in sandwiches):
        return current, inverse + unseen
    gains = [inverse @ w for w in weights]
    independent = sum((g @ cast(np.ndarray, i) @ g.T
                       for g, (i, _) in zip(gains, sandwiches, strict=True)), np.zeros((2, 2)))
    pulls = np.vstack([cast(np.ndarray, d) @ g.T
                       for g, (_, d) in zip(gains, sandwiches, strict=True)])
    groups = len(pulls)
    covariance = independent
    if groups >= 2:
        quantile = float(student_t.ppf(0.975, groups - 1)) / Z_95
        robust = pulls.T @ pulls * groups / (groups - 1) * quantile**2
        if np.trace(robust) > np.trace(independent):
            covariance = robust
    return current, covariance + unseen


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
    influence: np.ndarray | None = None  # (G, 2): each experiment's pull on the current, m/s

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


def _jacobian(ev: Evaluator, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residuals at ``x`` and the Jacobian there, in unit-cube coordinates.

    Returns (r, jac): r (K + 1, M) the residuals at x and at each forward step (one batch of
    K + 1 runs), jac (M, K) (steps of ``REL_STEP`` in the unit cube of ``ev.space.bounds``,
    backwards at the upper bound).
    """
    bounds = ev.space.bounds
    k = len(bounds)
    u0 = box_to_unit(bounds, x)
    steps = np.where(u0 + REL_STEP <= 1.0, REL_STEP, -REL_STEP)
    pts = np.vstack([x] + [box_from_unit(bounds, u0 + np.eye(k)[i] * steps[i])
                           for i in range(k)])
    r = np.asarray(ev.residuals(pts))
    return r, ((r[1:] - r[0]) / steps[:, None]).T


def _least_squares(ev: Evaluator, x: np.ndarray) -> np.ndarray:
    """From ``x`` to the residuals' least-squares point within the bounds (module doc, step 1).

    The interval is that of the least-squares estimate, so the current reported is that
    estimate, not the minimax fit's (which balances the worst experiments, and with them the
    misfit). SciPy's trust-region reflective least squares (``scipy.optimize.least_squares``,
    ``method="trf"``: bounds kept, parameters at a bound handled) in the unit cube, with the
    forward-difference Jacobian of :func:`_jacobian` (one batch of K + 1 runs), at most
    ``LEAST_SQUARES_EVALUATIONS`` residual evaluations. A fixed number of Gauss-Newton steps
    halved until the sum of squares fell stopped short where a parameter sat at its bound (the
    servo model's motor time constant): the current it returned fitted worse than the truth's.
    Returns ``x`` when nothing fits better.
    """
    bounds = ev.space.bounds
    x = np.asarray(x, dtype=float)
    u0 = np.clip(box_to_unit(bounds, x), 0.0, 1.0)

    def residuals(u: np.ndarray) -> np.ndarray:
        return np.asarray(ev.residuals(box_from_unit(bounds, np.clip(u, 0.0, 1.0))[None]))[0]

    def jacobian(u: np.ndarray) -> np.ndarray:
        return _jacobian(ev, box_from_unit(bounds, np.clip(u, 0.0, 1.0)))[1]

    r0 = residuals(u0)
    fit = scipy_least_squares(residuals, u0, jac=jacobian, bounds=(0.0, 1.0), method="trf",
                              max_nfev=LEAST_SQUARES_EVALUATIONS, x_scale=1.0)
    if not np.all(np.isfinite(fit.x)) or 2.0 * float(fit.cost) >= float(r0 @ r0):
        return x
    return box_from_unit(bounds, np.clip(fit.x, 0.0, 1.0))


def _spread(ev: Evaluator, x: np.ndarray) -> _Spread | None:
    """The current's covariance at ``x``, or None where the other parameters explain it.

    As :func:`eelhost.estimation.identify.identifiability` (Jacobian in the unit cube, residual
    variance never below the pixel rounding's), with the other parameters profiled out; and the
    cluster-robust one with each experiment a cluster.
    """
    bounds = ev.space.bounds
    k = len(bounds)
    r, jac = _jacobian(ev, x)
    # each residual's experiment (a cluster): the evaluator's columns are its experiments' blocks
    groups = len(ev.prepared)
    cluster = np.repeat(np.arange(groups), r.shape[1] // groups)
    pixel = max(float(p.experiment.recording_camera().pixel_m) for p in ev.prepared)
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
    ranges = bounds[-2:, 1] - bounds[-2:, 0]
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
                       for g in range(groups)])  # (G, 2)
    if groups < 2:
        return _Spread(sigma2 * bread * to_m_s, None, 1.0)
    robust = bread @ (scores.T @ scores) @ bread * groups / (groups - 1)
    return _Spread(sigma2 * bread * to_m_s, robust * to_m_s,
                   influence=(scores @ bread) * ranges,
                   quantile=float(student_t.ppf(0.975, groups - 1)) / Z_95)
