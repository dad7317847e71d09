"""Clock offsets that sit at their search bound (docs/estimation.md, "Validation").

Validation compares each held-out experiment at the offset of its recording's clock that fits
best within +-``ALIGN_S`` (the paper's stated time-stamp uncertainty), beside its own clock. The
bound is a statement about the recording's clock; when most best offsets sit on it, the search
is not finding a clock error but absorbing the model's misfit (a prediction that runs ahead or
behind looks like a late or early clock). :func:`clock_check` says how many sit there and, the
bound revisited, where the offsets would go if the search were ``WIDE_S`` wide: offsets far
beyond any clock's uncertainty are misfit, and the recorded-clock E_x is the figure to trust.
Shifting a recording costs no simulation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.estimation.runs import ALIGN_S, ALIGN_STEP_S
from eelhost.estimation.validate import ValidationRun

WIDE_S = 1.0  # the revisited search's half-width, s


@dataclass(frozen=True)
class ClockCheck:
    """Where the held-out experiments' best clock offsets sit.

    Attributes
    ----------
    bound_s : float
        The validation's search half-width.
    at_bound : tuple of str
        The experiments whose best offset sits on it.
    total : int
        Experiments compared.
    wide_offsets_s : dict of str to float
        Those experiments' best offsets searched within +-``WIDE_S``.
    """

    bound_s: float
    at_bound: tuple[str, ...]
    total: int
    wide_offsets_s: dict[str, float]

    @property
    def beyond_wide(self) -> tuple[str, ...]:
        """The experiments whose offset sits at the revisited bound too (+-``WIDE_S``).

        Their misfit is more than a second of swimming: no clock is that far off, and the
        revisited search cannot say where they would lie.
        """
        return tuple(n for n, o in self.wide_offsets_s.items()
                     if abs(o) >= WIDE_S - ALIGN_STEP_S / 2)

    @property
    def most_at_bound(self) -> bool:
        """Whether more than half of the experiments' offsets sit at the bound."""
        return 2 * len(self.at_bound) > self.total

    def warning(self) -> str | None:
        """The report's warning when most offsets sit at the bound (None otherwise)."""
        if not self.most_at_bound:
            return None
        wide = np.abs(list(self.wide_offsets_s.values()))
        beyond = self.beyond_wide
        return (
            f"{len(self.at_bound)} of {self.total} held-out experiments' best clock offsets sit "
            f"at the +-{self.bound_s:g} s bound of the search. Searched within +-{WIDE_S:g} s "
            f"they would lie at {np.median(wide):.2f} s (median; up to {wide.max():.2f} s)"
            + (f", and {len(beyond)} of them at +-{WIDE_S:g} s again (further still)"
               if beyond else "")
            + ": the offsets absorb the model's misfit, not a clock error, so E_x at the best "
            "offset flatters the model; the recorded-clock E_x is the figure to trust"
        )


def clock_check(runs: Sequence[ValidationRun], bound_s: float = ALIGN_S) -> ClockCheck:
    """Count the best clock offsets at the bound and search those again within +-``WIDE_S``.

    Parameters
    ----------
    runs : sequence of ValidationRun
        Validation runs (:func:`eelhost.estimation.validate.validate`; failed ones are skipped).
    bound_s : float
        The search half-width validation used.

    Returns
    -------
    ClockCheck
    """
    ran = [r for r in runs if np.all(np.isfinite(r.sim_positions_m))]
    at = [r for r in ran if abs(r.row.clock_offset_s) >= bound_s - ALIGN_STEP_S / 2]
    shifts = np.arange(-round(WIDE_S / ALIGN_STEP_S), round(WIDE_S / ALIGN_STEP_S) + 1)
    wide = {}
    for r in at:
        exp = r.experiment
        t0, t1 = exp.t_s[0], exp.t_s[-1]
        gaps = []
        for d in shifts * ALIGN_STEP_S:
            t = np.clip(r.times_s + d, t0, t1)  # the recording holds nothing beyond its ends
            gaps.append(np.linalg.norm(exp.position_at(t) - r.sim_positions_m, axis=-1).mean())
        wide[exp.name] = float(shifts[int(np.argmin(gaps))] * ALIGN_STEP_S)
    return ClockCheck(bound_s, tuple(r.experiment.name for r in at), len(ran), wide)
