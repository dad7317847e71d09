"""One set of joint parameters for the robot, shared by the straight and turning fits.

docs/estimation.md, "The servo plants' near misses: one servo for the robot (session 15)". The
paper fits the straight and turning gaits apart, each with its own coefficients. Where the joint
model has fitted parameters (the servo's lag and motor time constant, the servo line's stall
torque and no-load speed), each motion's fit varies them too, although the robot has one kind
of joints whatever it swims. Measured on the servo plants (development seeds 29-30): the
straight gaits, whose joints swing symmetrically, hardly see those parameters; their fits put
them at a bound (a motor time constant of 0.05 s for a plant's 0.008 s, a lag of 0.005 s for
0.033 s) and use them as two more knobs to fit the four training gaits' noise, which the
held-out gaits pay for.

So, once the fits are made (and hold the tank's current, :mod:`eelhost.estimation.tank_current`),
each motion's fitted joint parameters are tried for every motion: every motion's coefficients
are polished again (:data:`HOLD_ITERATIONS` minimax iterations) with the joint parameters held
there, and the set whose worst ratio of a motion's held fitness to its own fit's is the lowest
is kept for all motions. The fits keep their spaces (the joint parameters' bounds are not
narrowed there), so the bootstrap and the identifiability analysis see the whole model. A model
without fitted joint parameters (the paper's PD), one set for every motion, a single motion or
a failed fit is left as it is.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from eelhost.estimation.evaluate import Evaluator, many_problems
from eelhost.estimation.local import FAILED, polish_minimax_many
from eelhost.estimation.optimise import FitResult

log = logging.getLogger(__name__)

# Iterations of each motion's polish of its coefficients with the joint parameters held.
HOLD_ITERATIONS = 8
# Half-width of the held joint parameters' bounds, as a fraction of their range: a point for the
# polish (whose finite differences step a thousandth of the range), not a zero-width box.
HOLD_HALF_WIDTH = 1e-6


def share_joints(
    fits: dict[str, FitResult],
    evaluators: dict[str, Evaluator],
    say: Callable[[str], None] | None = None,
) -> tuple[dict[str, FitResult], str | None]:
    """Hold one motion's fitted joint parameters in every motion's fit (module doc).

    Parameters
    ----------
    fits : dict of str to FitResult
        Per motion ("straight", "turning"), its fit of one model.
    evaluators : dict of str to Evaluator
        Per motion, the evaluator of its training experiments (in the fit's space).
    say : callable, optional
        Gets a line with the result.

    Returns
    -------
    (fits, source)
        The fits with the shared joint parameters and the motion whose joint parameters they
        are; the inputs and None when nothing is shared (module doc).
    """
    say = say or log.info
    motions = [m for m in ("straight", "turning") if m in fits and m in evaluators]
    if len(motions) < 2 or set(fits) != set(motions):
        return fits, None
    spaces = [fits[m].space for m in motions]
    first = spaces[0]
    if (not first.joints.names or any(s.model_name != first.model_name for s in spaces)
            or any(fits[m].fitness >= FAILED for m in motions)):
        return fits, None
    k, nj = len(first.coefficient_names), len(first.joints.names)
    held: dict[str, dict[str, FitResult]] = {}
    for source in motions:
        joints = np.asarray(fits[source].values, dtype=float)[k:k + nj]
        held[source] = {}
        for m in motions:
            space = fits[m].space
            span = np.diff(space.joints.bounds, axis=1)[:, 0]
            bounds = np.column_stack([joints - HOLD_HALF_WIDTH * span,
                                      joints + HOLD_HALF_WIDTH * span])
            hold = replace(space, joints=replace(space.joints, bounds=bounds))
            start = np.asarray(fits[m].values, dtype=float).copy()
            start[k:k + nj] = joints
            ev = evaluators[m].with_space(hold)
            pol = polish_minimax_many(many_problems(ev), hold, start[None], HOLD_ITERATIONS)[0]
            evaluators[m].count_from(ev)
            values = np.asarray(pol.values, dtype=float)
            values[k:k + nj] = joints  # exactly the source's (the polish clips inside the box)
            last = fits[m].history[-1] if fits[m].history else (0, pol.fitness, 0)
            history = fits[m].history + [(int(last[0]) + 1, float(pol.fitness),
                                          evaluators[m].simulations)]
            held[source][m] = FitResult(f"{fits[m].method}, joints held", space, values,
                                        float(pol.fitness), history,
                                        fits[m].evaluations + pol.evaluations,
                                        search_evaluations=fits[m].search_evaluations)

    def worst_ratio(source: str) -> float:
        return max(held[source][m].fitness / max(float(fits[m].fitness), 1e-9) for m in motions)

    best = min(motions, key=worst_ratio)
    if worst_ratio(best) >= FAILED:
        return fits, None
    say(f"one set of joint parameters for the robot: the {best} fit's ("
        + ", ".join(f"{n} {v:.4g}" for n, v in zip(
            first.joints.names, fits[best].values[k:k + nj], strict=True))
        + "); fitness " + ", ".join(
            f"{m} {fits[m].fitness:.4f} -> {held[best][m].fitness:.4f}" for m in motions)
        + "; the other motions' joints: " + ", ".join(
            f"{s} worst x{worst_ratio(s):.2f}" for s in motions if s != best))
    return {**fits, **held[best]}, best
