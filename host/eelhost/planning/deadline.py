"""A deadline its owner may bring forward: a replan that a more urgent one can cut short.

The search, the check and the replanner read a deadline as a number (``float(deadline)``) before
every batch of swims; a :class:`Deadline` reads as its present value, so the replanner can move it
to *now* from the run loop's thread while the replan's worker is searching, and the worker stops
at its next batch as at any deadline (docs/planning.md, "Calm replans get more time").
"""

from __future__ import annotations

import math


class Deadline:
    """A time on a clock (``time.monotonic()`` for the tank's replans) that may only come earlier.

    Parameters
    ----------
    at_s : float
        The deadline, s on the reader's clock.
    """

    def __init__(self, at_s: float) -> None:
        self._at_s = float(at_s)
        self.cut_at_s: float | None = None

    def __float__(self) -> float:
        # a float read is atomic: the worker sees the old or the new deadline, never half
        return self._at_s

    def __repr__(self) -> str:
        return f"Deadline({self._at_s:.3f}{', cut' if self.cut else ''})"

    @property
    def cut(self) -> bool:
        """Whether :meth:`cut_to` brought the deadline forward."""
        return self.cut_at_s is not None

    def cut_to(self, now_s: float) -> None:
        """Bring the deadline forward to ``now_s`` (never later than it was).

        Parameters
        ----------
        now_s : float
            The reader clock's present time.
        """
        if math.isfinite(now_s) and now_s < self._at_s:
            self._at_s = float(now_s)
        self.cut_at_s = float(now_s)
