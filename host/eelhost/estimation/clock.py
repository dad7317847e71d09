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

The fit's own clock prior is :mod:`eelhost.estimation.clock_prior` (the fit's side: this module
is validation's, and imports it).
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
