"""Holding station: swimming into the current instead of a stop it would carry into something.

A stopped robot rests in the water, not in the tank (docs/planning.md, "The harbour"): in a
current of 0.02-0.06 m/s towards a near obstacle its brake and glide carry it into it, and where
no harbour swim leaves a clear stop the robot was stopped anyway. The robot swims about 0.09 m/s:
headed into the current it makes headway, or holds its place, where stopped it drifts.
:func:`find_station` swims such swims in the twin from the body's estimated state, the robot
swimming on (its gait and phase run on, no restart), each towards a waypoint
:data:`STATION_REACH_M` upstream of the body at a bearing of :data:`STATION_BEARINGS_DEG` from
straight upstream (crabbing across the current trades headway for holding the place), or of
:data:`STATION_HEADING_BEARINGS_DEG` from the body's heading (where it cannot turn upstream),
for :data:`STATION_HORIZON_S`. A swim is judged as the harbour's (the caller's ``gap_of``: the
body's outline less the current estimate's drift allowance) over the whole horizon, and of those
keeping the caller's need the one carried least downstream wins (its centre of mass's
displacement along the current at the horizon's end: headway counts negative), the clearest
among equals (docs/planning.md, "Holding station (session 21)").

This module swims and judges; :class:`eelhost.planning.replan.TankReplanner` decides when to
ask, carries the swim out and judges it again every :data:`STATION_CHECK_S`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from eelhost.planning.geometry import FloatArray
from eelhost.planning.harbour import StopWindow, stop_states, swim_start
from eelhost.planning.search import Guide
from eelhost.planning.twin import Runs, Twin
from eelsim.control import Gait

__all__ = ["LEAST_BAD_GAIN_M", "LEAST_BAD_HORIZON_S", "LEAST_BAD_LEADS_S", "LEAST_BAD_MAX_S",
           "LEAST_BAD_STEP_M", "STATION_BEARINGS_DEG", "STATION_CHECK_S",
           "STATION_HEADING_BEARINGS_DEG", "STATION_HORIZON_S", "STATION_MAX_S",
           "STATION_MIN_CURRENT_M_S", "STATION_REACH_M", "LeastBad", "Station", "find_least_bad",
           "find_station"]

STATION_BEARINGS_DEG = (0.0, 30.0, -30.0, 60.0, -60.0)
"""The station swims' bearings, relative to straight upstream (into the current)."""

STATION_HEADING_BEARINGS_DEG = (0.0, 45.0, -45.0, 90.0, -90.0, 135.0, -135.0, 180.0)
"""More station swims' bearings, relative to the body's heading: a body headed downstream beside
an obstacle cannot turn upstream without sweeping into it, and in a weak current the body's own
glide, not the water, carries a stop into what it swims beside."""

STATION_HORIZON_S = 8.0
"""How long each station swim is judged in the twin: the robot's time to the next check is
0.5 s (:data:`STATION_CHECK_S`), so the swim judged keeps clear far beyond it, as long as a stop
(3 s of brake and 2 s of glide) and a replan's budget after it."""

STATION_REACH_M = 2.0
"""How far upstream of the body each swim's waypoint lies: beyond what it swims (at most about
0.1 m/s of headway), so that the guidance holds a bearing and the waypoint is never reached."""

STATION_CHECK_S = 0.5
"""While holding station the stop and the swim are judged again this often (as the hold's)."""

STATION_MAX_S = 25.0
"""The longest a plan's station lasts, from its first frame; then the stop it put off is made."""

STATION_MIN_CURRENT_M_S = 0.005
"""Below this current (the world's and the estimate's together) there is no upstream to head
into, and a stop drifts a few millimetres: no station is swum."""


LEAST_BAD_HORIZON_S = 1.5
"""How long each least-bad swim is judged (:func:`find_least_bad`): a receding horizon, judged
again every :data:`STATION_CHECK_S` (three checks), the stops along it judged too. Replays of
unseen seed 42073 (session 24): over 3 s no swim kept 10 mm where the stop drifted in; over 1.5 s
one did, and its stop a check on was 25 mm clearer than the stop then (docs/planning.md, "The
least-bad swim (session 24)")."""

LEAST_BAD_GAIN_M = 0.01
"""The gap a least-bad swim must keep over its horizon: the look-ahead's margin (the estimate
moves on while the robot swims it)."""

LEAST_BAD_STEP_M = 0.01
"""How much clearer than the stop judged now a least-bad swim's stop must be: the look-ahead's
margin. The twin's stop a check on missed the one judged there by about as much (replay of
development seed 39016: 11 mm predicted, -2 mm judged a check later), and a swim for less swims
the estimate's noise (docs/planning.md, "The least-bad swim (session 24)")."""

LEAST_BAD_LEADS_S = (0.5, 1.0, 1.5)
"""How far into a least-bad swim its stops are judged: at the next check, and further on (the
stop a check on was worse than the stop now in every replay of session 24 where the first version
judged it alone: the swimming body carries on)."""

LEAST_BAD_MAX_S = 15.0
"""The longest a plan's stations and least-bad swims last together; then the stop is made."""


class Station(NamedTuple):
    """A swim into the current judged in the twin (:func:`find_station`)."""

    start_step: int
    waypoint_m: tuple[float, float]
    bearing_deg: float  # relative to straight upstream, or to the heading (``frame``)
    frame: str  # ``upstream`` or ``heading``
    gap_m: float  # the smallest gap over the horizon
    drift_m: float  # the centre of mass's displacement along the current at the horizon's end
    com_m: FloatArray  # the centre of mass while swimming (the corridor)
    guide: Guide


class _Swims(NamedTuple):
    """The station candidates swum from one estimate (:func:`_swim_candidates`)."""

    judged: list[tuple[int, Station]]  # (run index, the swim) of every run swum whole
    runs: Runs  # the twin's runs, one per aim
    ahead_s: FloatArray  # each kept sample's time after the estimate, s


def _swim_candidates(twin: Twin, state: FloatArray, t_s: float,
                     current_m_s: tuple[float, float],
                     gap_of: Callable[[FloatArray, FloatArray], FloatArray],
                     bearings_deg: tuple[float, ...], heading_bearings_deg: tuple[float, ...],
                     horizon_s: float, stride: int) -> _Swims | None:
    """Swim every station aim for ``horizon_s`` in one batch and judge each run's gap.

    The aims: pure pursuit of a waypoint :data:`STATION_REACH_M` away at ``bearings_deg`` from
    straight upstream and at ``heading_bearings_deg`` from the body's heading, the run's gait
    and phase swum on. A run that ended early (a failure flag) is not judged. Each swim's
    ``drift_m`` is its centre of mass's displacement downstream after ``horizon_s``.
    :func:`find_station` and :func:`find_least_bad` choose among the same swims.

    Returns
    -------
    _Swims or None
        None in a current under :data:`STATION_MIN_CURRENT_M_S` (still water: no candidate).
    """
    speed = math.hypot(*current_m_s)
    if speed < STATION_MIN_CURRENT_M_S:
        return None
    dt, n = twin.dt_s, twin.n_links
    now, state, guide, com = swim_start(twin, state, t_s)
    along = np.array(current_m_s, dtype=float) / speed  # downstream, unit
    upstream = math.atan2(-along[1], -along[0])
    heading = float(np.mean(state[:n]))
    aims = ([(b, "upstream", upstream + math.radians(b)) for b in bearings_deg]
            + [(b, "heading", heading + math.radians(b)) for b in heading_bearings_deg])
    targets = [(float(com[0] + STATION_REACH_M * math.cos(a)),
                float(com[1] + STATION_REACH_M * math.sin(a))) for _, _, a in aims]
    k = len(targets)
    last = int(round(horizon_s / (stride * dt)))
    runs = twin.run([[w] for w in targets], horizon_s + 2 * dt,
                    states=np.repeat(state[None], k, 0), start_steps=[now] * k, stride=stride,
                    guidance=[guide] * k if twin.options.guidance.integral else None)
    ahead = np.arange(last + 1, dtype=np.float64) * (stride * dt)
    judged = []
    for j in range(k):
        swum = runs.states[j, : last + 1]
        if swum.shape[0] < last + 1 or not np.isfinite(swum[:, 0]).all():
            continue  # ended early (a failure flag): not judged
        gap = float(np.min(gap_of(swum, ahead)))
        drift = float(np.dot(swum[-1, n : n + 2] - com, along))
        judged.append((j, Station(now, targets[j], aims[j][0], aims[j][1], gap, drift,
                                  swum[:, n : n + 2].copy(), guide)))
    return _Swims(judged, runs, ahead)


def find_station(twin: Twin, state: FloatArray, t_s: float, current_m_s: tuple[float, float],
                 gap_of: Callable[[FloatArray, FloatArray], FloatArray], need_m: float,
                 bearings_deg: tuple[float, ...] = STATION_BEARINGS_DEG,
                 heading_bearings_deg: tuple[float, ...] = STATION_HEADING_BEARINGS_DEG,
                 horizon_s: float = STATION_HORIZON_S, stride: int = 3
                 ) -> tuple[Station | None, Station | None]:
    """The station swim keeping ``need_m`` carried least downstream, and the clearest swim.

    Parameters
    ----------
    twin : Twin
        The twin in the estimated water, swimming the run's gait.
    state : ndarray (2 N + 4,)
        The body's estimated state at ``t_s``.
    t_s : float
        The robot's time of ``state``.
    current_m_s : (vx, vy)
        The current the body swims in (the world's and the estimate's): upstream is against it.
    gap_of : callable
        ``gap_of(states (S, 2 N + 4), ahead_s (S,))``: the gap each sample keeps, ``ahead_s``
        after ``t_s`` (the caller's outline less its drift allowance, as a stop's).
    need_m : float
        The gap a station swim must keep over the horizon.
    bearings_deg : tuple of float
        Bearings from straight upstream.
    heading_bearings_deg : tuple of float
        Bearings from the body's heading.
    horizon_s : float
    stride : int

    Returns
    -------
    (Station or None, Station or None)
        Of the swims whose gap exceeds ``need_m``, the one whose centre of mass ends least far
        downstream (None when none does, or in a current under
        :data:`STATION_MIN_CURRENT_M_S`); the clearest of all judged (None when no run swam the
        whole horizon).
    """
    swims = _swim_candidates(twin, state, t_s, current_m_s, gap_of, bearings_deg,
                             heading_bearings_deg, horizon_s, stride)
    if swims is None:
        return None, None
    best: Station | None = None
    clearest: Station | None = None
    for _, got in swims.judged:
        gap, drift = got.gap_m, got.drift_m
        if clearest is None or gap > clearest.gap_m:
            clearest = got
        if gap > need_m and (best is None or drift < best.drift_m - 1e-3
                             or (abs(drift - best.drift_m) <= 1e-3 and gap > best.gap_m)):
            best = got
    return best, clearest


class LeastBad(NamedTuple):
    """A station candidate judged as a least-bad swim (:func:`find_least_bad`)."""

    swim: Station  # its ``gap_m`` the smallest gap over the short horizon
    stop_gap_m: float  # the clearest of the stops decided along the swim (-inf: none swum whole)


def find_least_bad(twin: Twin, gait: Gait, state: FloatArray, t_s: float,
                   current_m_s: tuple[float, float],
                   gap_of: Callable[[FloatArray, FloatArray], FloatArray], window: StopWindow,
                   need_m: float = LEAST_BAD_GAIN_M, horizon_s: float = LEAST_BAD_HORIZON_S,
                   leads_s: tuple[float, ...] = LEAST_BAD_LEADS_S, stride: int = 3
                   ) -> LeastBad | None:
    """Of the station candidates swum clear by ``need_m``, the one leaving the clearest stop.

    The swims are :func:`find_station`'s (13 aims, the run's gait and phase swum on), each judged
    over ``horizon_s`` only, and the stops decided ``leads_s`` into it swum from its states there
    as ``window`` says; a swim is worth the clearest of its stops. The robot swims the best a
    check and judges again from the next estimate: a receding horizon towards a better stop
    (docs/planning.md, "The least-bad swim (session 24)").

    Parameters
    ----------
    twin : Twin
        The twin in the estimated water, swimming ``gait``.
    gait : Gait
        The swimming gait (a stop's brake freezes its phase).
    state : ndarray (2 N + 4,)
        The body's estimated state at ``t_s``.
    t_s : float
        The robot's time of ``state``.
    current_m_s : (vx, vy)
        The current the body swims in (the world's and the estimate's).
    gap_of : callable
        ``gap_of(states (S, 2 N + 4), ahead_s (S,))``, as :func:`find_station`'s.
    window : StopWindow
        How the stop is swum (the pause's or the final stop's).
    need_m : float
        The gap a swim must keep over ``horizon_s``.
    horizon_s : float
        How long each swim is judged.
    leads_s : tuple of float
        How far into the swim its stops are decided (at most ``horizon_s``).
    stride : int

    Returns
    -------
    LeastBad or None
        Of the swims keeping ``need_m``, the one whose clearest stop is clearest (its
        ``stop_gap_m`` that stop's gap); None in a current under
        :data:`STATION_MIN_CURRENT_M_S` or when no swim keeps ``need_m`` over the whole horizon.
    """
    swims = _swim_candidates(twin, state, t_s, current_m_s, gap_of, STATION_BEARINGS_DEG,
                             STATION_HEADING_BEARINGS_DEG, horizon_s, stride)
    if swims is None:
        return None
    runs, ahead = swims.runs, swims.ahead_s
    last, dt = len(ahead) - 1, twin.dt_s
    leads = sorted({min(max(int(round(lead / (stride * dt))), 1), last) for lead in leads_s})
    clear = [(j, swim) for j, swim in swims.judged if swim.gap_m > need_m]
    if not clear:
        return None
    rows = [j for j, _ in clear]
    stop_best = np.full(len(clear), -math.inf)
    for lead in leads:
        # one batch per lead: each stop's brake freezes the phase at its own decision
        stops = stop_states(twin, gait, runs.states[rows, lead], t_s + float(ahead[lead]),
                            window, stride)
        judged = ahead[lead] + np.arange(stops.shape[1], dtype=np.float64) * (stride * dt)
        for i, stop in enumerate(stops):
            if np.isfinite(stop[:, 0]).all():
                stop_best[i] = max(stop_best[i], float(np.min(gap_of(stop, judged))))
    i = int(np.argmax(stop_best))
    return LeastBad(clear[i][1], float(stop_best[i]))
