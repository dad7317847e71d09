"""Timing of the closed loop: physics step, control period, extra delay and period jitter.

All periods that change what the plant receives are whole multiples of the physics step; this is
checked here with a clear error, once, so that the loop itself counts integer steps. The camera's
30 fps is not a multiple of 0.01 s; the camera observes between steps instead (see ``camera.py``).

The default physics step is the firmware's control period, which like the servo frame and the
baud is defined once in ``protocol/eelbot.toml`` and generated into
:mod:`eelsim.firmware_timing` (docs/firmware.md, "Timing defined once"); the lockstep
(``eelhost.xil.lockstep``) steps the firmware at the same period.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eelsim.firmware_timing import BAUD, CONTROL_PERIOD_US, SERVO_FRAME_US

__all__ = [
    "BAUD",
    "CONTROL_PERIOD_US",
    "PHYSICS_STEP_S",
    "PHYSICS_STEP_US",
    "SERVO_FRAME_US",
    "LoopTiming",
    "TimingError",
    "whole_steps",
]

#: The twin's default physics step, us: the firmware's control period, so that the robot and the
#: twin sample the gait at the same instants and the lockstep ticks the firmware once a step.
PHYSICS_STEP_US = CONTROL_PERIOD_US
#: The same in seconds (10000 us -> 0.01 s exactly as a float: a correctly rounded division).
PHYSICS_STEP_S = PHYSICS_STEP_US / 1_000_000


class TimingError(ValueError):
    """A period that is not a whole multiple of the physics step, or otherwise unusable."""


def whole_steps(period_s: float, dt_s: float, what: str) -> int:
    """Return ``period_s / dt_s`` when it is a whole number, else raise :class:`TimingError`.

    Parameters
    ----------
    period_s : float
        The period to convert.
    dt_s : float
        The physics step.
    what : str
        Name of the period, for the error message.

    Returns
    -------
    int
    """
    if not np.isfinite(period_s) or period_s < 0:
        raise TimingError(f"{what} = {period_s} s must be finite and non-negative")
    steps = round(period_s / dt_s)
    if abs(steps * dt_s - period_s) > 1e-9 * max(dt_s, period_s):
        raise TimingError(
            f"{what} = {period_s} s is not a whole multiple of the physics step dt = {dt_s} s "
            f"(nearest: {steps} steps = {steps * dt_s:g} s)"
        )
    return int(steps)


@dataclass(frozen=True)
class LoopTiming:
    """Timing of the high-level loop (paper section 5.3).

    Attributes
    ----------
    dt_s : float
        Physics step of RK4 (default :data:`PHYSICS_STEP_S`, the firmware's control period).
    control_period_s : float
        The heading offset is recomputed every control period and held in between (zero-order hold).
    extra_delay_s : float
        Delay between the pose used and the moment the new offset reaches the joints (radio, servo
        settling), on top of the camera's own latency.
    jitter_s : float
        Each control period is lengthened or shortened by a whole number of steps drawn uniformly
        from [-jitter_s, +jitter_s] (seeded).
    """

    dt_s: float = PHYSICS_STEP_S
    control_period_s: float = 0.3
    extra_delay_s: float = 0.0
    jitter_s: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt_s) and self.dt_s > 0):
            raise TimingError(f"physics step dt = {self.dt_s} s must be positive")
        period = whole_steps(self.control_period_s, self.dt_s, "control period")
        if period < 1:
            raise TimingError("control period must be at least one physics step")
        whole_steps(self.extra_delay_s, self.dt_s, "extra delay")
        jitter = whole_steps(self.jitter_s, self.dt_s, "period jitter")
        if jitter >= period:
            raise TimingError(
                f"period jitter ({self.jitter_s} s) must be smaller than the control period "
                f"({self.control_period_s} s)"
            )

    @property
    def period_steps(self) -> int:
        """Control period in physics steps."""
        return whole_steps(self.control_period_s, self.dt_s, "control period")

    @property
    def delay_steps(self) -> int:
        """Extra delay in physics steps."""
        return whole_steps(self.extra_delay_s, self.dt_s, "extra delay")

    @property
    def jitter_steps(self) -> int:
        """Largest period change, in physics steps."""
        return whole_steps(self.jitter_s, self.dt_s, "period jitter")

    def update_steps(self, total_steps: int, rng: np.random.Generator) -> np.ndarray:
        """Physics step indices at which the controller computes a new offset.

        The first update is at step 0; each later one follows after the control period plus a
        jitter drawn from ``rng``.

        Parameters
        ----------
        total_steps : int
            Length of the run in steps.
        rng : numpy.random.Generator
            Source of the jitter.

        Returns
        -------
        ndarray of int
        """
        period, jitter = self.period_steps, self.jitter_steps
        if not jitter:
            # every period exactly (the twin's default): the same schedule without the loop,
            # which cost the planner's search a tenth of its processor time (docs/planning.md)
            return np.arange(0, total_steps + 1, period, dtype=np.int64)
        steps = [0]
        while True:
            j = int(rng.integers(-jitter, jitter + 1)) if jitter else 0
            nxt = steps[-1] + period + j
            if nxt > total_steps:
                return np.array(steps, dtype=np.int64)
            steps.append(nxt)
