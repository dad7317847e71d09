"""A harbour: where a stopping robot's drift stays clear (docs/planning.md, "The harbour").

A stopped robot rests in the water, not in the tank: in a current it is carried on through its
brake and the glide after it. When the twin predicts that a stop decided now (at the goal, or
where no safe continuation exists) would drift within the margin of an obstacle or wall, the robot
first swims a short way and stops there instead. :func:`find_harbour` swims the candidates in the
twin from the body's estimated state, the robot swimming on (its gait and phase run on), each
towards a waypoint :data:`HARBOUR_REACH_M` away at a bearing of :data:`HARBOUR_BEARINGS_DEG` from
the body's heading for one of :data:`HARBOUR_SWIMS_S`, and then the stop itself from where the
swim ends (the brake's frozen S until it ends, then the straight body gliding). A candidate is
judged on the whole of it, the swim and the stop: the smallest gap the caller's ``gap_of`` gives
(the body's outline less the current estimate's drift allowance). The stop at once is the
candidate of no swim, judged the same way.

This module swims and judges; :class:`eelhost.planning.replan.TankReplanner` decides when to ask
and carries the harbour out.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from eelhost.planning.geometry import FloatArray
from eelhost.planning.restart import stopped_twin
from eelhost.planning.search import Guide, leg_start_guide
from eelhost.planning.twin import Twin
from eelsim.control import Gait, braked_gait

__all__ = ["HARBOUR_BEARINGS_DEG", "HARBOUR_CUSHION_M", "HARBOUR_REACH_M", "HARBOUR_SWIMS_S",
           "FINAL_GLIDE_S", "Harbour", "StopWindow", "SwimStart", "find_harbour", "stop_gap_m",
           "stop_states", "swim_start"]

HARBOUR_BEARINGS_DEG = (0.0, 30.0, -30.0, 60.0, -60.0, 90.0, -90.0, 120.0, -120.0, 150.0,
                        -150.0, 180.0)
"""The harbour swims' bearings, relative to the body's heading."""

HARBOUR_SWIMS_S = (1.5, 3.0, 4.5)
"""How long each harbour candidate swims before its stop: the shortest that leaves a clear stop
is taken (the robot stops as near as it can to where it was to stop)."""

HARBOUR_REACH_M = 2.0
"""How far ahead of the body each candidate's waypoint lies: beyond what it swims, so that the
guidance holds a bearing and the waypoint is never reached."""

HARBOUR_CUSHION_M = 0.01
"""A harbour keeps this much more than the look-ahead's margin over its swim and its stop: the
estimate moves on while the robot swims it (a flee judged 16 mm clear was judged under the 10 mm
margin again 0.17 s later, unseen seed 32003: docs/planning.md, "The flee")."""

FINAL_GLIDE_S = 2.0
"""After the final Stop's brake, the straight body's glide the twin swims: the closed-loop
benchmark judges the stop until the body is slower than 0.02 m/s through the water, which took
1 s at most on unseen seeds 30000-30099."""


class StopWindow(NamedTuple):
    """How a stop is swum in the twin from the moment it is decided.

    Attributes
    ----------
    unbrake : callable
        ``unbrake(t_stop_s)``: when the brake's frozen S ends for a stop decided at ``t_stop_s``
        (the final Stop's fixed brake, or the pause's whole number of gait periods).
    after_s : float
        How long the straight body is swum after the brake ends.
    """

    unbrake: Callable[[float], float]
    after_s: float


class Harbour(NamedTuple):
    """A swim after which the stop stays clear (:func:`find_harbour`)."""

    start_step: int
    waypoint_m: tuple[float, float]
    bearing_deg: float  # relative to the body's heading at the start; nan without a swim
    swim_s: float  # 0: stop at once
    gap_m: float  # the smallest gap over the swim and the stop
    swim_gap_m: float  # over the swim alone (inf without a swim)
    stop_gap_m: float  # over the stop after it
    com_m: FloatArray  # the centre of mass while swimming (the corridor; one row without a swim)
    guide: Guide


def stop_states(twin: Twin, gait: Gait, states: FloatArray, t_s: float | FloatArray,
                window: StopWindow, stride: int,
                coefficient_index: Sequence[int] | None = None,
                currents: Sequence[tuple[float, float]] | None = None,
                swum: list[int] | None = None) -> FloatArray:
    """The stops of bodies in ``states`` decided at ``t_s``: braked, then straight.

    Parameters
    ----------
    twin : Twin
        The twin in the estimated water (its gait is the swimming one).
    gait : Gait
        The swimming gait (the brake freezes its phase at ``t_s``).
    states : ndarray, shape (K, 2 N + 4)
        The bodies at ``t_s``.
    t_s : float or ndarray, shape (K,)
        When the stops are decided (one time, or one per body: the planner's check swims each
        run's arrival stop from its own arrival; each brake lasts as long as the first body's:
        ``window.unbrake`` is then a fixed delay, as the final stop's).
    window : StopWindow
    stride : int
        Steps between the samples returned.
    coefficient_index : sequence of int, optional
        Per body, the twin's coefficient set (default the first).
    currents : sequence of (vx, vy), optional
        Per body, the water's current (default the twin's).
    swum : list of int, optional
        Where the run-steps the twin swam are appended (a swim cost's measure, as
        :class:`eelhost.planning.search.SwimCost` counts them).

    Returns
    -------
    ndarray, shape (K, S, 2 N + 4)
        Sample s at ``t_s + s * stride * dt``; NaN where a run ended early.
    """
    dt = twin.dt_s
    n = twin.n_links
    k = len(states)
    times = np.broadcast_to(np.asarray(t_s, dtype=float), (k,))
    t_unbrake = window.unbrake(float(times[0]))
    held = max(int(round((t_unbrake - float(times[0])) / dt)), 0)
    held -= held % stride  # the straight part starts on a sample
    after = int(round(window.after_s / dt))
    nows = [int(round(t / dt)) for t in times]
    index = None if coefficient_index is None else list(coefficient_index)
    water = None if currents is None else list(currents)
    heading = np.mean(states[:, :n], axis=1)
    com = states[:, n : n + 2]
    # waypoints no drift reaches (the heading gain is 0: they steer nothing)
    far = [[(float(com[j, 0] + 1e3 * math.cos(heading[j])),
             float(com[j, 1] + 1e3 * math.sin(heading[j])))] for j in range(k)]
    parts = []
    start = np.asarray(states, dtype=float)
    if held > 0:
        # each body's brake freezes the gait's phase at its own decision (one batch: the frozen
        # phases are per run)
        braked = stopped_twin(twin, braked_gait(gait, float(times[0])))
        runs = braked.run(far, (held + 2) * dt, states=start, start_steps=nows,
                          stride=stride, coefficient_index=index, currents=water,
                          phase_rad=[braked_gait(gait, float(t)).phase_rad for t in times])
        if swum is not None:
            swum.append(int(np.sum(runs.final_step + 1)))
        first = runs.states[:, : held // stride + 1]
        if first.shape[1] < held // stride + 1:
            pad = np.full((k, held // stride + 1 - first.shape[1], first.shape[2]), np.nan)
            first = np.concatenate([first, pad], axis=1)
        parts.append(first[:, :-1])
        start = first[:, -1]
    if after > 0:
        ok = np.isfinite(start[:, 0])
        rest = np.full((k, after // stride + 1, start.shape[1]), np.nan)
        if ok.any():
            straight = stopped_twin(twin)
            rows = np.flatnonzero(ok)
            runs = straight.run([far[j] for j in rows], (after + 2) * dt,
                                states=start[ok], start_steps=[nows[j] + held for j in rows],
                                stride=stride,
                                coefficient_index=None if index is None else [index[j] for j in rows],
                                currents=None if water is None else [water[j] for j in rows])
            if swum is not None:
                swum.append(int(np.sum(runs.final_step + 1)))
            got = runs.states[:, : after // stride + 1]
            rest[ok, : got.shape[1]] = got
        parts.append(rest)
    elif held > 0:
        parts.append(start[:, None])
    return np.concatenate(parts, axis=1) if parts else start[:, None]


def stop_gap_m(twin: Twin, gait: Gait, state: FloatArray, t_s: float, window: StopWindow,
               gap_of: Callable[[FloatArray, FloatArray], FloatArray], stride: int = 3) -> float:
    """The smallest gap of the stop decided at ``t_s``, as :func:`find_harbour` judges it.

    The stop at once alone, without the harbour swims: what the hold compares the present plan
    with while it swims on (docs/planning.md, "The hold"). -inf when the twin's run ended early.

    Parameters
    ----------
    twin, gait, state, t_s, window, gap_of, stride
        As :func:`find_harbour`'s.

    Returns
    -------
    float
    """
    run = stop_states(twin, gait, np.asarray(state, dtype=float)[None], t_s, window, stride)[0]
    return _judged_gap_m(run, 0.0, stride * twin.dt_s, gap_of)


def _judged_gap_m(run: FloatArray, offset_s: float, sample_s: float,
                 gap_of: Callable[[FloatArray, FloatArray], FloatArray]) -> float:
    """The smallest gap ``gap_of`` gives a run sampled every ``sample_s``, ``offset_s`` ahead.

    -inf for a run that ended early (a failure flag): no stop or harbour is judged from it.
    """
    if not np.isfinite(run[:, 0]).all():
        return -math.inf
    ahead = offset_s + np.arange(len(run), dtype=np.float64) * sample_s
    return float(np.min(gap_of(run, ahead)))


class SwimStart(NamedTuple):
    """Where a swim judged from the body's state begins (a harbour's or a station's)."""

    now: int
    """The twin's step at the swim's start."""
    state: FloatArray
    """The body's state, as floats."""
    guide: Guide
    """The guidance's start: a fresh leg from the body."""
    com: FloatArray
    """The centre of mass, m (a view into ``state``)."""


def swim_start(twin: Twin, state: FloatArray, t_s: float) -> SwimStart:
    """The start of swims from ``state`` at ``t_s``, as the harbour's and the station's begin.

    Parameters
    ----------
    twin : Twin
    state : ndarray, shape (2 N + 4,)
        The body's state.
    t_s : float
        The robot's time of the state, s.

    Returns
    -------
    SwimStart
    """
    n = twin.n_links
    state = np.asarray(state, dtype=float)
    return SwimStart(int(round(t_s / twin.dt_s)), state, leg_start_guide(state, n, (0.0, 0.0)),
                     state[n : n + 2])


def find_harbour(twin: Twin, gait: Gait, state: FloatArray, t_s: float, window: StopWindow,
                 gap_of: Callable[[FloatArray, FloatArray], FloatArray], need_m: float,
                 bearings_deg: tuple[float, ...] = HARBOUR_BEARINGS_DEG,
                 swims_s: tuple[float, ...] = HARBOUR_SWIMS_S, stride: int = 3
                 ) -> tuple[Harbour, Harbour | None, Harbour | None]:
    """The stop at once, the nearest harbour whose swim and stop keep ``need_m``, the clearest.

    Parameters
    ----------
    twin : Twin
        The twin in the estimated water, swimming ``gait``.
    gait : Gait
    state : ndarray (2 N + 4,)
        The body's estimated state at ``t_s``.
    t_s : float
        The robot's time of ``state``.
    window : StopWindow
        How the stop is swum.
    gap_of : callable
        ``gap_of(states (S, 2 N + 4), ahead_s (S,))``: the gap each sample keeps, ``ahead_s``
        after ``t_s`` (the caller's outline less its drift allowance).
    need_m : float
        The gap a harbour must keep over its swim and its stop.
    bearings_deg, swims_s : tuple of float
    stride : int

    Returns
    -------
    (Harbour, Harbour or None, Harbour or None)
        The stop at once (``swim_s`` 0); of the swims whose gap exceeds ``need_m`` the
        shortest, the clearest among those (None when none does); and the clearest swim of those
        judged (all of them when none keeps ``need_m``; None when every run failed).
    """
    dt, n = twin.dt_s, twin.n_links
    now, state, guide, com = swim_start(twin, state, t_s)

    def judged(run: FloatArray, offset_s: float) -> float:
        return _judged_gap_m(run, offset_s, stride * dt, gap_of)

    at_once_gap = stop_gap_m(twin, gait, state, t_s, window, gap_of, stride)
    at_once = Harbour(now, (float(com[0]), float(com[1])), math.nan, 0.0, at_once_gap, math.inf,
                      at_once_gap, com[None].copy(), guide)
    heading = float(np.mean(state[:n]))
    targets = [(float(com[0] + HARBOUR_REACH_M * math.cos(heading + math.radians(b))),
                float(com[1] + HARBOUR_REACH_M * math.sin(heading + math.radians(b))))
               for b in bearings_deg]
    k = len(targets)
    longest = max(swims_s)
    runs = twin.run([[w] for w in targets], longest + 2 * dt,
                    states=np.repeat(state[None], k, 0), start_steps=[now] * k, stride=stride,
                    guidance=[guide] * k if twin.options.guidance.integral else None)
    best: Harbour | None = None
    clearest: Harbour | None = None
    for swim_s in sorted(swims_s):
        last = int(round(swim_s / (stride * dt)))
        swum = runs.states[:, : last + 1]
        if swum.shape[1] < last + 1:
            continue
        ends = swum[:, -1]
        fine = np.isfinite(ends[:, 0])
        if not fine.any():
            continue
        got = stop_states(twin, gait, ends[fine], t_s + last * stride * dt, window, stride)
        stops = np.full((k, got.shape[1], state.size), np.nan)
        stops[fine] = got
        for j in range(k):
            if not fine[j]:
                continue
            swim_gap = judged(swum[j], 0.0)
            stop_gap = judged(stops[j], last * stride * dt)
            gap = min(swim_gap, stop_gap)
            if clearest is None or gap > clearest.gap_m:
                clearest = Harbour(now, targets[j], bearings_deg[j], last * stride * dt, gap,
                                   swim_gap, stop_gap, swum[j, :, n : n + 2].copy(), guide)
                if gap > need_m and (best is None or gap > best.gap_m):
                    best = clearest
        if best is not None:
            break
    return at_once, best, clearest
