"""A restart from rest: the stopped robot's drift in the twin (docs/planning.md, "A restart from rest").

When the tank's replanner finds no swimming continuation (``no_safe_continuation``), the run need
not end: the robot's gait is set to amplitude 0 (``SetGait`` with A = 0 while it stays running, so
the gait's phase runs on and the offsets it is sent keep the firmware's link watchdog fed), its
joints straighten, and the body coasts towards rest in the water. The twin swims that stopped body
(:func:`stopped_twin`: the same robot, loop timing and current, the gait's amplitude and heading
gain 0, so its offset is 0 as the firmware's while stopped) to say whether the drift stays clear
(:func:`drift`), and a replan is then searched from the state it predicts for the restart, like a
first plan from a body (nearly) at rest. :class:`eelhost.planning.replan.TankReplanner` runs the
sequence; ``eelbot run --restarts`` bounds how often.

A straight body glides far, so by default the pause first brakes: the body is frozen in a deep S
(:func:`eelsim.control.braked_gait`, omega 0) until :func:`unbrake_time`, a whole number of gait
periods on, and only then straightens; :func:`paused_drift` swims both (docs/planning.md, "The
brake in the pause").
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from eelhost.planning.geometry import FloatArray
from eelhost.planning.twin import Twin
from eelsim.control import Gait
from eelsim.guidance import PURSUIT

__all__ = ["BRAKE_HOLD_S", "DRIFT_AFTER_S", "RESTARTS", "backing_gait", "paused_drift", "unbrake_time", "REST_BUDGET_MAX_S", "REST_BUDGET_S", "REST_PAUSE_MAX_S",
           "REST_RETRY_S", "REST_SETTLE_S", "REST_TRIES", "drift", "stopped_gait", "stopped_twin"]

RESTARTS = 2
"""Restarts from rest a run may make (``eelbot run --restarts``; docs/planning.md)."""

REST_SETTLE_S = 0.3
"""The robot's time from the stop to the rest replan's request: the joints are straight by then,
and the camera's estimate of the straight, coasting body is what the replan starts from (a straight
body coasts a long way: from 0.15 m/s it still glides at 0.09 m/s 4 s later in the twin)."""

REST_BUDGET_S = 2.0
"""The rest replan's least wall-clock budget (the early replans' 2 s): it starts from the state the twin
predicts for when the budget ends, and the stopped robot waits meanwhile."""

REST_BUDGET_MAX_S = 5.0
"""The rest replan's longest budget: where the drift stays clear that long (a loaded machine's
rest replans ran out of time in 2 s on development seed 25022, the body 110 mm clear)."""

REST_TRIES = 1
"""Rest replans a pause may ask for: after a failed one, another later in the pause from the body
then, while the drift stays clear (``TankReplanner(rest_tries=)``; docs/planning.md)."""

REST_RETRY_S = 0.5
"""The robot's time from a failed rest replan to the next try's request."""

REST_PAUSE_MAX_S = 10.0
"""With retries, the stop's drift is swum at least this long (plus :data:`DRIFT_AFTER_S`): the
latest restart a later try may plan for."""

DRIFT_AFTER_S = 0.5
"""The twin swims the stopped body from the stop to this long after the planned restart (the
settle and the budget): the drift must stay clear until the new plan has had time to act."""


BRAKE_HOLD_S = 2.0
"""The least time a pause holds the brake (the body frozen in a deep S: a coasting body's speed
falls from 0.05-0.08 m/s to about 0.01 m/s in 2-3 s over ``sim://``) before its joints straighten
for the restart. The brake ends a whole number of gait periods after it began
(:func:`unbrake_time`), so that the firmware's phase, frozen meanwhile, resumes where the twin's
own phase (omega t) is: docs/planning.md, "The brake in the pause"."""


DRIFT_JOINT_LIMIT_RAD = math.pi
"""The stopped twin's mechanical joint limit: none in effect (:func:`stopped_twin`)."""

STOPPED_AMPLITUDE_RAD = 1e-9
"""The stopped twin's amplitude: 0 in effect (a scenario's amplitude must be positive)."""


def stopped_gait(gait: Gait) -> Gait:
    """The gait of a stopped robot: amplitude 0 and heading gain 0 (offset 0), same omega, beta.

    Parameters
    ----------
    gait : Gait

    Returns
    -------
    Gait
    """
    # the scenario's amplitude must be positive: 1e-9 rad swings the joints by nothing
    return dataclasses.replace(gait, amplitude_rad=STOPPED_AMPLITUDE_RAD, k_theta=0.0)


def backing_gait(gait: Gait, amplitude_rad: float) -> Gait:
    """The gait of a robot backing (or braking): the travelling wave reversed, offset 0.

    The same omega, beta negated (the wave runs from the tail to the head and pushes the body
    backwards: the firmware takes any beta in [-pi, pi], ``SetGait``), amplitude
    ``amplitude_rad``, heading gain 0. In the twin a small amplitude brakes the coasting body
    and a large one backs it out (docs/planning.md, "A restart from rest").

    Parameters
    ----------
    gait : Gait
    amplitude_rad : float

    Returns
    -------
    Gait
    """
    return dataclasses.replace(gait, amplitude_rad=max(amplitude_rad, STOPPED_AMPLITUDE_RAD),
                               beta_rad=-gait.beta_rad, k_theta=0.0)


def stopped_twin(twin: Twin, gait: Gait | None = None) -> Twin:
    """``twin`` with the stopped gait and pure pursuit (whose gain is the gait's: 0).

    The joints' references are 0 and the offset is 0, as the firmware's while its amplitude is 0
    and its offset 0, so the run is the body's drift with its joints held straight. Its joints'
    mechanical limit is :data:`DRIFT_JOINT_LIMIT_RAD`: the drift is swum whole.

    Parameters
    ----------
    twin : Twin
    gait : Gait, optional
        The paused gait (its heading gain 0), e.g. :func:`backing_gait`; default
        :func:`stopped_gait` of the twin's.

    Returns
    -------
    Twin
    """
    options = dataclasses.replace(twin.options, guidance=PURSUIT)
    paused = stopped_gait(twin.gait) if gait is None else gait
    # a stopped body's drift is predicted, not planned: the mechanical limit's flag (a planning
    # criterion that ends a run) cut the drift of a body braked in a hard turn short, its brake's
    # S overshooting the limit by 0.007 rad, and a verdict on the part before was optimistic
    # (docs/planning.md, "The harbour")
    joints = twin.robot.joints.model_copy(update={"limit_rad": DRIFT_JOINT_LIMIT_RAD})
    return Twin(twin.robot.with_joints(joints), twin.coefficients, paused, options,
                twin.current_m_s, twin.acceptance_radius_m, twin.threads, twin.model)


def drift(twin: Twin, state: FloatArray, t_s: float, duration_s: float,
          stride: int = 3) -> FloatArray:
    """The stopped body's states from ``state`` at ``t_s`` over ``duration_s``.

    Parameters
    ----------
    twin : Twin
        A stopped twin (:func:`stopped_twin`).
    state : ndarray (2 N + 4,)
        The body's state at ``t_s``.
    t_s : float
        The robot's time of ``state`` (the gait's phase; no effect at amplitude 0).
    duration_s : float
    stride : int
        Steps between the states returned.

    Returns
    -------
    ndarray, shape (S, 2 N + 4)
        Sample s at ``t_s + s * stride * twin.dt_s``; only finite rows.
    """
    now = int(round(t_s / twin.dt_s))
    n = twin.n_links
    heading = float(np.mean(state[:n]))
    com = np.asarray(state[n : n + 2], dtype=float)
    # a waypoint no drift reaches: the run must not end at it (the gain is 0: it steers nothing)
    far = com + 1.0e3 * np.array([math.cos(heading), math.sin(heading)])
    runs = twin.run([[(float(far[0]), float(far[1]))]], duration_s + 2 * twin.dt_s,
                    states=np.asarray(state, dtype=float)[None], start_steps=[now],
                    stride=stride)
    states = runs.states[0]
    return np.asarray(states[np.isfinite(states[:, 0])], dtype=float)


def unbrake_time(gait: Gait, t_brake_s: float, hold_s: float = BRAKE_HOLD_S) -> float:
    """When a brake begun at ``t_brake_s`` ends: the first whole gait period at least ``hold_s`` on.

    The brake freezes the firmware's phase at omega t_b (:func:`eelsim.control.braked_gait`);
    SetGait with amplitude 0 and the gait's omega a whole number k of periods 2 pi / omega later
    lets it run on from there, which is omega t again modulo 2 pi: the twin's gait from the
    restart on needs no phase of its own.

    Parameters
    ----------
    gait : Gait
        The swimming gait (its omega).
    t_brake_s : float
        When the brake began (the frame time its SetGait was sent for).
    hold_s : float

    Returns
    -------
    float
        t_brake_s + k 2 pi / omega with k >= 1 the least for which k 2 pi / omega >= hold_s.
    """
    period = 2.0 * math.pi / gait.omega_rad_s
    return t_brake_s + max(math.ceil(hold_s / period - 1e-9), 1) * period


def paused_drift(braked: Twin, stopped: Twin, state: FloatArray, t_s: float,
                 t_unbrake_s: float, duration_s: float, stride: int = 3) -> FloatArray:
    """A paused body's states: braked until ``t_unbrake_s``, then stopped (joints straight).

    Parameters
    ----------
    braked, stopped : Twin
        The paused robot before and after the brake ends (:func:`stopped_twin` with
        :func:`eelsim.control.braked_gait`, and with :func:`stopped_gait`).
    state : ndarray (2 N + 4,)
        The body's state at ``t_s``.
    t_s, t_unbrake_s, duration_s : float
    stride : int
        Steps between the states returned.

    Returns
    -------
    ndarray, shape (S, 2 N + 4)
        Sample s at ``t_s + s * stride * dt`` (as :func:`drift`); only finite rows.
    """
    dt = braked.dt_s
    held = max(int(round((t_unbrake_s - t_s) / dt)), 0)
    total = int(round(duration_s / dt))
    if held >= total:
        return drift(braked, state, t_s, duration_s, stride)
    if held == 0:
        return drift(stopped, state, t_s, duration_s, stride)
    first = drift(braked, state, t_s, held * dt, 1)
    if len(first) <= held:
        return first[::stride]
    rest = drift(stopped, first[held], t_s + held * dt, (total - held) * dt, 1)
    # the stopped twin starts at the unbraked step: its phase omega t is the firmware's there
    return np.concatenate([first[:held], rest])[::stride]
