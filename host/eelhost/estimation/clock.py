"""Clock offsets that sit at their search bound (docs/estimation.md, "Validation").

Validation compares each held-out experiment at the offset of its recording's clock that fits
best within the bound the recording declares (its camera's ``timestamp_jitter_s``; ``ALIGN_S``,
the paper's +-0.1 s, where it declares none), beside its own clock. The bound is a statement
about the recording's clock; when most best offsets sit on it, the search is not finding a clock
error but absorbing the model's misfit (a prediction that runs ahead or behind looks like a late
or early clock). :func:`clock_check` says how many sit there and, the bound revisited, where the
offsets would go if the search were wider (``WIDE_S``, or ten times a wider declared bound):
offsets far beyond the clock's declared uncertainty are misfit, and the recorded-clock E_x is the
figure to trust. Shifting a recording costs no simulation.

It also holds the fit's clock prior (docs/estimation.md, "The training clocks: a zero-mean
prior"): :func:`centred_offsets` profiles each training recording's clock offset within the
bound it declares, with the offsets' mean held at the prior's 0, the one direction a fit's
timing (a common lag or lead of every run) can mimic; :func:`shifted_recording` reads the
recording at those offsets.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.estimation.runs import ALIGN_STEP_S
from eelhost.estimation.validate import ValidationRun, best_clock_offset

WIDE_S = 1.0  # the revisited search's least half-width, s
# The revisited search is at least this many times the widest declared bound: a recording that
# declares a clock good to +-0.5 s is revisited within +-5 s.
WIDE_FACTOR = 10.0
# Whether a fit's evaluator profiles its training recordings' clock offsets with the zero-mean
# prior by default (Evaluator(clock_prior=None)); docs/estimation_benchmarks.md, "Session 17".
FIT_CLOCK_PRIOR = False


@dataclass(frozen=True)
class ClockCheck:
    """Where the held-out experiments' best clock offsets sit.

    Attributes
    ----------
    bound_s : float
        The validation's search half-width: the widest of the recordings' declared bounds.
    at_bound : tuple of str
        The experiments whose best offset sits on its bound.
    total : int
        Experiments compared with a clock search (a recording that declares a bound of 0 is
        compared on its own clock only, and has no offset to sit anywhere).
    wide_offsets_s : dict of str to float
        Those experiments' best offsets searched within +-``wide_s``.
    wide_s : float
        The revisited search's half-width.
    least_bound_s : float or None
        The narrowest declared bound searched, where the recordings declare different ones.
    """

    bound_s: float
    at_bound: tuple[str, ...]
    total: int
    wide_offsets_s: dict[str, float]
    wide_s: float = WIDE_S
    least_bound_s: float | None = None

    @property
    def beyond_wide(self) -> tuple[str, ...]:
        """The experiments whose offset sits at the revisited bound too (+-``wide_s``).

        Their misfit is more than a second of swimming: no clock is that far off, and the
        revisited search cannot say where they would lie.
        """
        return tuple(n for n, o in self.wide_offsets_s.items()
                     if abs(o) >= self.wide_s - ALIGN_STEP_S / 2)

    @property
    def most_at_bound(self) -> bool:
        """Whether more than half of the experiments' offsets sit at the bound."""
        return 2 * len(self.at_bound) > self.total

    def bound_text(self) -> str:
        """"+-0.1 s", or "+-0.05 to +-0.1 s" where the recordings declare different bounds."""
        if self.least_bound_s is not None and self.least_bound_s < self.bound_s:
            return f"+-{self.least_bound_s:g} to +-{self.bound_s:g} s"
        return f"+-{self.bound_s:g} s"

    def warning(self) -> str | None:
        """The report's warning when most offsets sit at the bound (None otherwise)."""
        if not self.most_at_bound:
            return None
        wide = np.abs(list(self.wide_offsets_s.values()))
        beyond = self.beyond_wide
        return (
            f"{len(self.at_bound)} of {self.total} held-out experiments' best clock offsets sit "
            f"at the {self.bound_text()} bound of the search (the time-stamp uncertainty the "
            f"recordings declare, camera.timestamp_jitter_s). Searched within "
            f"+-{self.wide_s:g} s they would lie at {np.median(wide):.2f} s (median; up to "
            f"{wide.max():.2f} s)"
            + (f", and {len(beyond)} of them at +-{self.wide_s:g} s again (further still)"
               if beyond else "")
            + ": the offsets absorb the model's misfit, not a clock error, so E_x at the best "
            "offset flatters the model; the recorded-clock E_x is the figure to trust (or the "
            "declared time-stamp uncertainty is wrong)"
        )


def clock_check(runs: Sequence[ValidationRun], bound_s: float | None = None) -> ClockCheck:
    """Count the best clock offsets at their bound and search those again more widely.

    Parameters
    ----------
    runs : sequence of ValidationRun
        Validation runs (:func:`eelhost.estimation.validate.validate`; failed ones are skipped).
    bound_s : float, optional
        The search half-width validation used for every run; None (the default): each run's own
        (``ValidationRow.clock_bound_s``, what its recording declares).

    Returns
    -------
    ClockCheck
    """
    ran = [r for r in runs if np.all(np.isfinite(r.sim_positions_m))]
    bounds = {r.experiment.name: (r.row.clock_bound_s if bound_s is None else bound_s)
              for r in ran}
    searched = [r for r in ran if bounds[r.experiment.name] >= ALIGN_STEP_S]
    at = [r for r in searched
          if abs(r.row.clock_offset_s) >= bounds[r.experiment.name] - ALIGN_STEP_S / 2]
    widest = max((bounds[r.experiment.name] for r in searched), default=0.0)
    least = min((bounds[r.experiment.name] for r in searched), default=0.0)
    wide_s = max(WIDE_S, WIDE_FACTOR * widest)
    wide = {}
    for r in at:  # validation's own search, within the revisited bound
        wide[r.experiment.name] = best_clock_offset(r.experiment, r.times_s, r.sim_positions_m,
                                                    wide_s)[0]
    return ClockCheck(widest, tuple(r.experiment.name for r in at), len(searched), wide, wide_s,
                      least if least < widest else None)


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
