"""The limits every entry point shares: the gait the robot accepts, the water the twin is made for.

The ranges are those of the firmware's ``SetGait`` message (:class:`eelhost.wire.protocol.SetGait`,
docs/firmware.md): amplitude A in (0, 1.5] rad, frequency omega in (0, 20] rad/s (both must be
positive for the robot to swim), phase shift beta in [-pi, pi]. ``--gait`` of ``simulate`` and
``run`` and the gaits of a campaign plan are checked here, so the robot is never sent, and the twin
never asked for, a gait the firmware would refuse.

:data:`MAX_CURRENT_M_S`: the fastest current the twin is asked to swim in, ten times the robot's
fastest steady speed (about 0.1 m/s, docs/model.md section 7); faster water only makes the
integration diverge. ``--current`` and a ``sim://`` URI's ``current=`` both stop there.
"""

from __future__ import annotations

from eelhost.wire import protocol

__all__ = ["GAIT_FIELDS", "MAX_CURRENT_M_S", "gait_problem", "gait_value_problem"]

MAX_CURRENT_M_S = 1.0

GAIT_FIELDS = ("amplitude_rad", "omega_rad_s", "beta_rad")


def gait_problem(values: tuple[float, ...] | list[float]) -> str | None:
    """What is wrong with a gait ``(A, omega[, beta])``, or None when the robot accepts it.

    Parameters
    ----------
    values : sequence of float
        Amplitude (rad), frequency (rad/s) and optionally phase shift (rad).

    Returns
    -------
    str or None
        ``"amplitude_rad 5 outside the robot's range [0, 1.5]"`` and the like.
    """
    for name, value in zip(GAIT_FIELDS, values, strict=False):
        problem = gait_value_problem(name, value)
        if problem:
            return problem
    return None


def gait_value_problem(name: str, value: float) -> str | None:
    """What is wrong with one value of a gait (``name`` one of :data:`GAIT_FIELDS`), or None."""
    lo, hi = {n: (lo, hi) for n, _, lo, hi in protocol.SetGait.LAYOUT}[name]
    if name != "beta_rad" and value <= 0.0:
        return f"{name} must be positive, got {value:g}"
    if lo is not None and hi is not None and not lo <= value <= hi:
        return f"{name} {value:g} outside the robot's range [{lo:g}, {hi:g}]"
    return None
