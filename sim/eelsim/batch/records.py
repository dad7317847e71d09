"""The records the compiled kernel takes and the codes it returns (shared by Python and the kernel).

The kernel's entry point takes four records instead of three dozen arrays: what each run is
(:class:`RunInputs`), when the camera sees it (:class:`FrameTable`), how the loop runs
(:class:`LoopSettings`) and where the answers go (:class:`RunOutputs`). numba passes named tuples
of arrays and scalars by value, field by field, so grouping costs nothing at run time; the tuple
classes live in this ordinary module so that numba's on-disk cache finds them by name in every
process. Inside a block, the camera's state (:class:`CameraState`) and each lane's waypoint
(:class:`Targets`) are records too.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


class Reason(enum.IntEnum):
    """Why a run was flagged; ``BatchResult.reason`` turns it into the reference's text."""

    NONE = 0
    TOO_SLOW = 1
    NOT_FINITE = 2
    NOT_POSITIVE_DEFINITE = 3
    CONDITION_NUMBER = 4
    JOINT_LIMIT = 5
    LINKS_INTERSECT = 6
    DIVERGED = 7


class RunInputs(NamedTuple):
    """Per-run inputs (R runs; see ``BatchSpec`` for each field's meaning).

    ``order`` is the order in which runs fill the blocks (``block_order``); ``plain_run`` says
    which runs have neither current nor servo line (``plain_runs``); ``guidance_state`` (R, 4)
    is each run's first-leg start (NaN: the first filtered pose) and ILOS integral vector.
    """

    order: IntArray
    params: FloatArray
    x0: FloatArray
    total_steps: IntArray
    goal_steps: IntArray
    waypoints: FloatArray
    n_waypoints: IntArray
    radius: FloatArray
    k_theta: FloatArray
    delay_steps: IntArray
    update_steps: IntArray
    update_count: IntArray
    noise: FloatArray
    plain_run: BoolArray
    guidance_state: FloatArray


class FrameTable(NamedTuple):
    """The camera frames, shared by all runs.

    For each frame: the step whose interval (t_k, t_k + dt] holds it, its fraction of that step
    and its time (frame 0 is seen at t = 0, before the first step).
    """

    step: IntArray
    fraction: FloatArray
    time: FloatArray


class LoopSettings(NamedTuple):
    """How the loop runs, shared by all runs.

    Attributes
    ----------
    dt : float
        Physics step, s.
    pixel : float
        Camera pixel size, m (0: no quantisation).
    window : int
        Frames in the moving median.
    stop_at_goal : bool
        End a run at its goal (from its goal step on).
    pending_size : int
        Room for offsets waiting out the loop's extra delay.
    record_full : bool
        Keep every step's state.
    sample_steps : ndarray of int
        Sorted unique steps at which states are sampled.
    guidance : ndarray, shape (9,)
        The guidance law (``eelsim.guidance.GuidanceLaw``): 0 pure pursuit, 1 ILOS or 2 pure
        pursuit with the known current's feed-forward, the look-ahead, the integral gain, the
        control period the integral advances by, the law's heading gain (0: each run's own
        k_theta), and the feed-forward's current (x, y), speed U and crab limit.
    """

    dt: float
    pixel: float
    window: int
    stop_at_goal: bool
    pending_size: int
    record_full: bool
    sample_steps: IntArray
    guidance: FloatArray


class RunOutputs(NamedTuple):
    """Where the kernel writes each run's answers (see ``BatchResult``).

    ``integral`` (R, S, 2) is the ILOS integral vector at each sample step, before that step's
    control update (what a run restarted there starts from).
    """

    states: FloatArray
    full: FloatArray
    arrival: FloatArray
    failure: IntArray
    failure_time: FloatArray
    reason: IntArray
    reason_index: IntArray
    reason_value: FloatArray
    final_state: FloatArray
    final_step: IntArray
    target: IntArray
    distance: FloatArray
    torque_ratio: FloatArray
    saturated: IntArray
    integral: FloatArray


class CameraState(NamedTuple):
    """The camera pipeline's state in a block, lanes innermost (the kernel's ``_observe``).

    Attributes
    ----------
    median : ndarray, shape (window, 3, lanes)
        The last frames' (x, y, heading), a ring.
    fill : ndarray of int, shape (2,)
        Frames in the ring and its next slot (every lane of a block sees the same frames).
    last_heading : ndarray, shape (lanes,)
        The last unwrapped heading.
    filtered : ndarray, shape (3, lanes)
        The filtered pose.
    turn, rank, total : ndarray, shape (lanes,)
        Scratch space.
    """

    median: FloatArray
    fill: IntArray
    last_heading: FloatArray
    filtered: FloatArray
    turn: FloatArray
    rank: FloatArray
    total: FloatArray


class Targets(NamedTuple):
    """Each lane's waypoint (the kernel's ``_observe`` and ``_aim``).

    Attributes
    ----------
    reached : ndarray of int
        Waypoints reached (the index of the current one).
    arrival : ndarray
        Frame time at which the last one was reached (NaN before).
    x, y : ndarray
        The current waypoint (NaN after the last).
    radius : ndarray
        Acceptance radius.
    n_waypoints : ndarray of int
        Number of waypoints.
    """

    reached: IntArray
    arrival: FloatArray
    x: FloatArray
    y: FloatArray
    radius: FloatArray
    n_waypoints: IntArray


class LaneControl(NamedTuple):
    """Each lane's control state in a block (the kernel's ``_update_controls``).

    Attributes
    ----------
    gamma : ndarray
        The heading offset in force (it also goes to the stage's ``gamma`` row).
    next_update : ndarray of int
        Index of the lane's next control update in ``RunInputs.update_steps``.
    update_at, pending_at : ndarray of int
        The step of the lane's next control update and of its next pending offset (``NEVER``:
        none); a vectorised test per step finds the lanes with something to do.
    pend_step, pend_value : ndarray, shape (lanes, pending_size)
        The pending queue (a ring): the step each offset acts from and the offset.
    pend_head, pend_count : ndarray of int
        The ring's head and length.
    is_update : ndarray of bool
        The lane updates its control at this step (the condition check runs then).
    """

    gamma: FloatArray
    next_update: IntArray
    update_at: IntArray
    pending_at: IntArray
    pend_step: IntArray
    pend_value: FloatArray
    pend_head: IntArray
    pend_count: IntArray
    is_update: BoolArray


class LaneFate(NamedTuple):
    """How each lane of a block is doing and how it ended (copied to ``RunOutputs`` at the end).

    Attributes
    ----------
    run : ndarray of int
        The run each lane holds (an idle lane repeats the block's first run, never committed).
    alive : ndarray of bool
        The lane is still running.
    total, goal : ndarray of int
        The lane's last step, and the step from which it stops at its goal (``stop_at_goal``).
    failure, reason : ndarray of int
        Failure and reason codes (``eelsim.flags.Failure``, :class:`Reason`).
    failure_time : ndarray
        When it failed (NaN: it did not).
    reason_index : ndarray of int, shape (lanes, 2)
        The joint or the link pair a self-collision names.
    reason_value : ndarray
        The condition number or joint angle the reason names.
    final_step : ndarray of int
        The step at which the lane stopped.

    (The lanes' torque figures, the largest |u| over the stall torque and the steps outside the
    servo's torque-speed line, are the generated stage's rows ``torque_ratio`` and ``saturated``,
    and ``alive`` has a copy there too, row ``live``, for the stage's own tests.)
    """

    run: IntArray
    alive: BoolArray
    total: IntArray
    goal: IntArray
    failure: IntArray
    reason: IntArray
    failure_time: FloatArray
    reason_index: IntArray
    reason_value: FloatArray
    final_step: IntArray


class CheckScratch(NamedTuple):
    """Scratch space for the scalar checks of one lane (allocations per check cost more).

    Attributes
    ----------
    state : ndarray, shape (2 N + 4,)
        The lane's state, gathered from ``work``.
    info : ndarray, shape (3,)
        What a self-collision check found (i, k, value).
    m, lo, inv : ndarray, shape (N + 2, N + 2)
        Mass matrix, its Cholesky factor and the factor's inverse.
    s, c : ndarray, shape (N,)
        sin and cos of the link angles.
    jx, jy : ndarray, shape (N + 2,)
        One link's Jacobian rows.
    """

    state: FloatArray
    info: FloatArray
    m: FloatArray
    lo: FloatArray
    inv: FloatArray
    s: FloatArray
    c: FloatArray
    jx: FloatArray
    jy: FloatArray
