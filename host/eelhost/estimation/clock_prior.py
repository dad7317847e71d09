"""The fit's clock prior (docs/estimation.md, "The training clocks: a zero-mean prior").

:func:`centred_offsets` profiles each training recording's clock offset within the bound it
declares, with the offsets' mean held at the prior's 0, the one direction a fit's timing (a
common lag or lead of every run) can mimic; :func:`shifted_recording` reads the recording at
those offsets. The fit's side of the clock, apart from validation's (:mod:`eelhost.estimation.clock`,
which imports the validation that imports the evaluator that uses this).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# Whether a fit's evaluator profiles its training recordings' clock offsets with the zero-mean
# prior by default (Evaluator(clock_prior=None)); docs/estimation_benchmarks.md, "Session 17".
FIT_CLOCK_PRIOR = False


def _refined_best(errors: np.ndarray, shifts_s: np.ndarray) -> np.ndarray:
    """Each row's best offset on the grid, refined by the parabola through its neighbours.

    The refinement keeps the profiled offset (and so the fitness) continuous in the candidate
    where the grid's argmin would jump by a whole step.

    Parameters
    ----------
    errors : ndarray, shape (C, M)
        The error of C candidates against the recording at each of the M grid offsets
        (NaN for a failed run).
    shifts_s : ndarray, shape (M,)
        The grid, ``ALIGN_STEP_S`` apart, ascending.

    Returns
    -------
    ndarray, shape (C,)
        NaN where a row has no finite error.
    """
    c, m = errors.shape
    out = np.full(c, np.nan)
    finite = np.isfinite(errors).any(axis=1)
    if not finite.any() or m == 0:
        return out
    e = np.where(np.isfinite(errors[finite]), errors[finite], np.inf)
    k = np.argmin(e, axis=1)
    best = shifts_s[k].astype(float)
    if m >= 3:
        inner = (k > 0) & (k < m - 1)
        rows = np.flatnonzero(inner)
        a, b, d = e[rows, k[rows] - 1], e[rows, k[rows]], e[rows, k[rows] + 1]
        curv = a - 2.0 * b + d
        with np.errstate(invalid="ignore", divide="ignore"):
            step = np.where((curv > 0) & np.isfinite(curv), 0.5 * (a - d) / curv, 0.0)
        step = np.clip(np.nan_to_num(step), -0.5, 0.5)
        best[rows] += step * (shifts_s[1] - shifts_s[0])
    out[finite] = best
    return out


def centred_offsets(
    errors: Sequence[np.ndarray], shifts_s: Sequence[np.ndarray]
) -> np.ndarray:
    """The training recordings' clock offsets profiled with their mean held at 0.

    Each recording's own best offset (the grid's, refined) is taken, then the candidate's mean
    over its recordings is subtracted, and each result is clipped to the recording's bound.
    The offsets of a fit's recordings are independent draws of clocks declared good to
    +-bound around 0; the one combination of them that the fitted coefficients can mimic is
    their mean (a model that runs late on every gait looks like every clock being early: the
    trade measured in docs/estimation_benchmarks.md, "Session 16 (development seeds 33-34)").
    A prior centred on 0 leaves the data no say in that direction, so its estimate is the
    prior's: 0. The differences between the offsets, which no coefficient set can mimic
    (each recording's own clock), are the data's.

    Parameters
    ----------
    errors : sequence of ndarray, shape (C, M_j)
        Per experiment j: each candidate's error against the recording at each offset of its
        grid (NaN for a failed run).
    shifts_s : sequence of ndarray, shape (M_j,)
        Per experiment: the grid, ascending, ``ALIGN_STEP_S`` apart, symmetric about 0
        (``runs.clock_shifts``).

    Returns
    -------
    ndarray, shape (C, E)
        The offsets at which each candidate compares each recording; 0 where a run failed, and
        all 0 for one experiment alone (its mean is itself).
    """
    best = np.column_stack([_refined_best(np.asarray(e, float), np.asarray(s, float))
                            for e, s in zip(errors, shifts_s, strict=True)])
    seen = np.isfinite(best)
    count = seen.sum(axis=1)
    mean = np.where(count > 0, np.where(seen, best, 0.0).sum(axis=1) / np.maximum(count, 1), 0.0)
    bounds = np.array([float(np.max(np.abs(s))) if len(s) else 0.0 for s in shifts_s])
    centred = np.clip(best - mean[:, None], -bounds, bounds)
    return np.where(seen, centred, 0.0)


def shifted_recording(
    shifted_positions_m: np.ndarray, shifts_s: np.ndarray, offsets_s: np.ndarray
) -> np.ndarray:
    """The recording at arbitrary offsets within its grid, linear between grid offsets.

    Parameters
    ----------
    shifted_positions_m : ndarray, shape (M, n, 2)
        The recording at the sample times plus each grid offset
        (``PreparedExperiment.shifted_positions_m``).
    shifts_s : ndarray, shape (M,)
        The grid, ascending and evenly spaced.
    offsets_s : ndarray, shape (C,)
        The offsets wanted (clipped to the grid).

    Returns
    -------
    ndarray, shape (C, n, 2)
    """
    m = len(shifts_s)
    if m == 1:
        return np.repeat(shifted_positions_m[:1], len(offsets_s), axis=0)
    step = float(shifts_s[1] - shifts_s[0])
    x = np.clip((np.asarray(offsets_s, float) - shifts_s[0]) / step, 0.0, m - 1.0)
    i0 = np.minimum(np.floor(x).astype(int), m - 2)
    f = (x - i0)[:, None, None]
    return (1.0 - f) * shifted_positions_m[i0] + f * shifted_positions_m[i0 + 1]
