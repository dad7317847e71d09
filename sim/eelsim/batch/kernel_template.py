"""The batched closed loop: the driver of the compiled kernel module (see ``eelsim.batch``).

This file is valid Python and is read as text: ``eelsim.batch.loading`` appends the generated part
(``_stage``, ``_screen``, ``_cond_bound`` and the constants: N, lanes, row offsets, thresholds and
codes, from ``eelsim.batch.codegen``) and writes the result to the kernel cache folder, where it is
imported as ``eelsim.batch.kernels.<name>`` and numba compiles and caches it. The placeholders
below are redefined by that later text before anything is compiled; importing this file on its
own is useless. When the generated functions are compiled as C, numba compiles this text once per
(N, lanes) with only the constants that are the same for every fluid law and joint model
(``loading.driver_module``): the rest arrives at run time in ``variant`` (below), and each
variant's module runs that shared driver.

What runs here, for a block of ``LANES`` runs advancing in lock step (one physics step at a time,
so the time, the camera frame schedule and the sample steps are shared; runs that stopped are
still computed but never committed):

1. control updates (offset gamma from the filtered pose, pending queue for the delay) - the
   driver keeps the next step at which some lane has one, the update itself is per lane;
2. sampling of the state;
3. RK4 stage 1 (vectorised), the self-collision screen (vectorised), the condition-number bound
   when some lane updates its control (vectorised), then the checks of ``closed_loop._check`` in
   its order (non-finite, diverging, condition number at update steps, joint limit, link
   intersection) - exact tests only for lanes the screen flags and exact condition numbers only
   where the bound is near the threshold. x's finiteness and fastest rate come from the last
   stage of the step before (x0's from a check at the block's start);
4. the stop rules, RK4 stages 2-4 (vectorised; each stage also does its part of the RK4 sums,
   the last one the finiteness and fastest rate of the new state and which lanes commit it:
   row keep), the pivot and finiteness checks of the new state;
5. camera frames in (t, t + dt]: Hermite pose, pixel quantisation, heading noise, median filter,
   waypoint switching and arrival - for all lanes at once;
6. the lanes still running commit the new state (a copy of the rows when all do, else a select
   per lane).

The order of these operations is that of ``eelsim.closed_loop.simulate_closed_loop``; the tests
compare the two to 1e-9.

``_run_block`` is that list, one step per pass of its loop; the per-lane work of each item is a
function of its own: ``_start_lanes`` (a block's runs into its lanes), ``_update_controls`` (1),
``_record_states`` (2), the generated ``_stage`` (3-4: angles, joint law, fluid forces, the
dynamics' solve and the RK4 sums, see ``eelsim.batch.codegen``) with ``_stage_settings``, then
``_check_state`` and ``_fail_new_state`` (the checks), ``_camera_frames`` (5), ``_commit_kept``
(6) and ``_write_outputs`` (a block's answers). The loop itself keeps only what every step runs
(one count over the lanes that vectorises, the stages and the plain commit); why the pieces are
called rather than inlined is written above them.
"""

import math
from typing import Any

import numba
import numpy as np
from llvmlite import ir as llvm_ir
from numba.core import types
from numba.extending import intrinsic

from eelsim.batch.records import CameraState, CheckScratch, LaneControl, LaneFate, Targets

# Floating-point contraction (FMA) only: no reassociation (it would undo the Cody-Waite range
# reduction of the generated sin/cos) and no "no NaN / no inf" assumptions (the failure checks
# rely on NaN and inf).
_FASTMATH = {"contract"}

NEVER = 2**62  # a step no run reaches

# The driver's helpers that allocate nothing are compiled without numba's reference counting.
# numba counts a reference to every array argument on entry and drops it on return (NRT_incref
# and NRT_decref, an atomic add each) and removes those pairs only in functions whose control
# flow is simple: _observe, called for every camera frame with two dozen arrays, made about 50
# such calls per frame, and a function of the driver cut into pieces made hundreds per step
# (docs/kernel_history.md, session 10). The arrays all belong to _run_block, which outlives
# every call, so there is nothing for the counts to protect. Never for a function that returns
# an array: its caller drops a reference to what it gets back, and without the count taken here
# that frees the array under its owner (heap corruption; _gather had it for one commit).
_NO_REFCOUNT = {"cache": True, "_nrt": False}
_njit: Any = numba.njit  # (numba's type stubs do not list _nrt)


@intrinsic
def _vsqrt(typingctx, x):
    """Sqrt as the LLVM intrinsic: numba calls libm's sqrt, which stops loop vectorisation."""
    sig = types.float64(types.float64)

    def codegen(context, builder, signature, args):
        fn = builder.module.declare_intrinsic("llvm.sqrt", [llvm_ir.DoubleType()])
        return builder.call(fn, args)

    return sig, codegen


@intrinsic
def _data_address(typingctx, array):
    """The address of ``array``'s data, for the C stage's ``work`` argument.

    ``array.ctypes.data`` makes a ctypes view that holds a reference to the array: a reference
    count taken and dropped (an atomic add each) around every call of the stage, four per step,
    which numba's pruning left in the step loop. The array here is the block's buffer, alive
    for the whole block.
    """
    sig = types.intp(array)

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        return builder.ptrtoint(data, context.get_value_type(types.intp))

    return sig, codegen


@intrinsic
def _next_block(typingctx, counter):
    """Atomically add one to ``counter[0]`` and return its value before: the next block to run.

    numba's ``prange`` splits its range into equal contiguous shares fixed in advance, whatever
    the parallel chunk size (measured with both the OpenMP and the workqueue layers): with the
    blocks ordered longest first, one thread would get all the long ones. Threads that take the
    next block from a shared counter when they finish one keep every core busy to the end, and
    a core also busy with other work (a shared machine) simply takes fewer blocks.
    """
    sig = types.int64(counter)

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        one = llvm_ir.Constant(llvm_ir.IntType(64), 1)
        return builder.atomic_rmw("add", array.data, one, "monotonic")

    return sig, codegen


# ---- placeholders, redefined by the generated part appended to this text ----
# thresholds of eelsim.flags, failure codes (eelsim.flags.Failure: FAIL_<name>) and reason codes
# (eelsim.batch.records.Reason: REASON_<name>)
ILL_CONDITION_THRESHOLD = DIVERGENCE_RATE = 0.0
FAIL_NONE = FAIL_TOO_SLOW = FAIL_ILL_CONDITIONED = FAIL_SELF_COLLISION = 0
REASON_NONE = REASON_TOO_SLOW = REASON_NOT_FINITE = REASON_NOT_POSITIVE_DEFINITE = 0
REASON_CONDITION_NUMBER = REASON_JOINT_LIMIT = REASON_LINKS_INTERSECT = REASON_DIVERGED = 0
N_LINKS = 2
LANES = 16
OUT_ROWS = 1
W_Y = W_X = W_ACC = W_XN = W_GAMMA = W_GEOMETRY = W_MASS = W_MU = 0
O_BAD_PIVOT = O_SIN = O_COS = O_NEAR = O_X_BAD = O_FASTEST = O_XN_BAD = O_COND_BOUND = 0
O_TORQUE = O_TORQUE_RATIO = O_SATURATED = 0
O_OFFSET = O_KEEP = O_LIVE = O_STEP_VERDICT = 0
ROTATE_LIMIT = 0.1
RESYNC_STEPS = 16


def _stage(work, t_s, a, wk, first, last, sixth, rotate, advance, plain):  # pragma: no cover
    raise RuntimeError("eelsim.batch.kernel_template is a template; use eelsim.batch")


def _screen(work):  # pragma: no cover - replaced
    raise RuntimeError("eelsim.batch.kernel_template is a template; use eelsim.batch")


def _cond_bound(work):  # pragma: no cover - replaced
    raise RuntimeError("eelsim.batch.kernel_template is a template; use eelsim.batch")


# ---- what the driver learns of the variant at run time (eelsim.batch.loading.driver_module)
# The driver reads only rows that are the same for every fluid law and joint model (the names
# above; the law's and the joint model's own rows come after them), so that one compiled driver
# per (N, lanes) serves every variant. The rest arrives in ``variant``, an int64 array: where
# out's rows start, the offsets in a run's parameters of the inertia and half-length rows, the
# joint limit's row, and the addresses of the C functions of the variant's stage, screen and
# condition bound (0 when they are compiled by numba in the same module).
V_WORK_ROWS, V_INERTIA, V_HALF_LENGTH, V_LIMIT, V_STAGE, V_SCREEN, V_COND_BOUND = range(7)


def _variant(stage_fn=0, screen_fn=0, cond_fn=0):
    """The module's ``variant`` array: the generated part's rows, the C functions' addresses."""
    g = globals()
    return np.array([g["WORK_ROWS"], g["W_INERTIA"] - W_GEOMETRY, g["W_HALF_LENGTH"] - W_GEOMETRY,
                     g["W_LIMIT"], stage_fn, screen_fn, cond_fn], np.int64)


def _pointer_call(c_types, fn, work, *scalars):
    """An intrinsic's signature and code calling the C function at address ``fn``.

    Its arguments: ``work``'s data, then ``scalars`` converted to ``c_types`` (int64 or float64).
    The address is an argument, not a symbol, so the compiled driver does not depend on which
    variant's library it calls, and numba's disk cache of it serves all of them.
    """
    sig = types.void(fn, work, *scalars)

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[1])(context, builder, args[1]).data
        values = [data] + [context.cast(builder, value, ty, c)
                           for value, ty, c in zip(args[2:], signature.args[2:], c_types, strict=True)]
        fnty = llvm_ir.FunctionType(llvm_ir.VoidType(),
                                    [data.type] + [context.get_value_type(c) for c in c_types])
        builder.call(builder.inttoptr(args[0], fnty.as_pointer()), values)
        return context.get_dummy_value()

    return sig, codegen


# The driver's calls of the generated functions: here straight to the numba-compiled ones of the
# same module (the ``fn`` address unused); the driver module (eelsim.batch.loading) redefines
# them as calls through the address (eelsim.batch.c_stage.pointer_call_source).
@_njit(**_NO_REFCOUNT)
def _call_stage(fn, work, t_s, a, wk, first, last, sixth, rotate, advance, plain):
    _stage(work, t_s, a, wk, first, last, sixth, rotate, advance, plain)


@_njit(**_NO_REFCOUNT)
def _call_screen(fn, work):
    _screen(work)


@_njit(**_NO_REFCOUNT)
def _call_cond_bound(fn, work):
    _cond_bound(work)


# ---- scalar helpers (per lane, not in the hot loop) ----


@_njit(**_NO_REFCOUNT)
def _np_mod(a, b):
    """numpy.mod for floats (sign of the divisor), as control.wrap_angle uses it."""
    m = np.fmod(a, b)
    if m != 0.0:
        if (m < 0.0) != (b < 0.0):
            m += b
    else:
        m = math.copysign(0.0, b)
    return m


@_njit(**_NO_REFCOUNT)
def _wrap_angle(a):
    """control.wrap_angle for one angle: a itself in (-pi, pi], else pi - mod(pi - a, 2 pi)."""
    if -math.pi < a <= math.pi:
        return a
    w = math.pi - _np_mod(math.pi - a, 2.0 * math.pi)
    return math.pi if w <= -math.pi else w


@_njit(**_NO_REFCOUNT)
def _heading_offset(px, py, heading, wx, wy, k_theta):
    """guidance.Guidance.offset: k_theta * wrap(atan2(wy - py, wx - px) - heading)."""
    return k_theta * _wrap_angle(math.atan2(wy - py, wx - px) - heading)


@_njit(**_NO_REFCOUNT)
def _guidance_offset(px, py, heading, r, run, target, waypoints, n_waypoints, k_theta, guide,
                     lane_guide):
    """guidance.Guidance.offset for lane r at a control update, the ILOS integral advanced.

    ``guide`` is LoopSettings.guidance (law: 0 pursuit, 1 ILOS, 2 pursuit with the current's
    feed-forward; look-ahead; integral gain; control period; the law's heading gain, 0: the
    run's k_theta; the feed-forward's current x, y, speed U and crab limit); ``lane_guide`` holds
    each lane's first-leg start (rows 0, 1) and integral vector (rows 2, 3). Same expressions, in
    the same order, as ``guidance.ilos_reference`` and ``guidance.feed_forward_reference``.
    """
    if guide[4] > 0.0:
        k_theta = guide[4]
    w = min(target, n_waypoints - 1)
    wx = waypoints[run, w, 0]
    wy = waypoints[run, w, 1]
    if guide[0] == 0.0:
        return _heading_offset(px, py, heading, wx, wy, k_theta)
    if guide[0] == 2.0:
        cx = guide[5]
        cy = guide[6]
        dx = wx - px
        dy = wy - py
        dist = math.sqrt(dx * dx + dy * dy)
        if (cx == 0.0 and cy == 0.0) or dist == 0.0:
            return _heading_offset(px, py, heading, wx, wy, k_theta)
        sine = -(cy * dx - cx * dy) / dist / guide[7]
        sine = min(max(sine, -guide[8]), guide[8])
        return k_theta * _wrap_angle(math.atan2(dy, dx) + math.asin(sine) - heading)
    if w > 0:
        x0 = waypoints[run, w - 1, 0]
        y0 = waypoints[run, w - 1, 1]
    else:
        x0 = lane_guide[0, r]
        y0 = lane_guide[1, r]
    dx = wx - x0
    dy = wy - y0
    if dx * dx + dy * dy < 1e-6:
        return _heading_offset(px, py, heading, wx, wy, k_theta)
    lookahead = guide[1]
    alpha = math.atan2(dy, dx)
    tx = math.cos(alpha)
    ty = math.sin(alpha)
    nx = -ty
    ny = tx
    e = (px - x0) * nx + (py - y0) * ny
    ahead = min(lookahead, math.sqrt(dx * dx + dy * dy) - ((px - x0) * tx + (py - y0) * ty))
    lateral = e + guide[2] * (lane_guide[2, r] * nx + lane_guide[3, r] * ny)
    theta_ref = alpha + math.atan2(-lateral, ahead)
    rate = lookahead * e / (lateral * lateral + lookahead * lookahead)
    lane_guide[2, r] += guide[3] * rate * nx
    lane_guide[3, r] += guide[3] * rate * ny
    return k_theta * _wrap_angle(theta_ref - heading)


@_njit(**_NO_REFCOUNT)
def _start_guidance(alive, run_of, guidance_state, filtered, lane_guide):
    """Each lane's first-leg start and ILOS integral from its run (a NaN start: the first pose)."""
    for r in range(alive.shape[0]):
        for row in range(4):
            lane_guide[row, r] = guidance_state[run_of[r], row]
        if np.isnan(lane_guide[0, r]) or np.isnan(lane_guide[1, r]):
            lane_guide[0, r] = filtered[0, r]
            lane_guide[1, r] = filtered[1, r]


@_njit(**_NO_REFCOUNT)
def _sample_guidance(step, sample, sample_steps, alive, run_of, lane_guide, integral_out):
    """The lanes' ILOS integrals at a sample step, before its control update; the next sample."""
    while sample < sample_steps.shape[0] and sample_steps[sample] < step:
        sample += 1
    if sample < sample_steps.shape[0] and sample_steps[sample] == step:
        for r in range(alive.shape[0]):
            if alive[r]:
                integral_out[run_of[r], sample, 0] = lane_guide[2, r]
                integral_out[run_of[r], sample, 1] = lane_guide[3, r]
    return sample


@numba.njit(cache=True)
def _jacobi_condition(m):
    """Condition number (max |eig| / min |eig|) of a symmetric matrix by cyclic Jacobi rotations.

    Jacobi gets the small eigenvalues of an SPD matrix to high relative accuracy, so near the
    threshold it agrees with numpy's SVD-based np.linalg.cond to far better than the threshold's
    own meaning.
    """
    a = m.copy()
    n = a.shape[0]
    for _sweep in range(60):
        off = 0.0
        for p in range(n):
            for q in range(p + 1, n):
                off = max(off, abs(a[p, q]) / math.sqrt(abs(a[p, p] * a[q, q]) + 1e-300))
        if off < 1e-17:
            break
        for p in range(n):
            for q in range(p + 1, n):
                if a[p, q] == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * a[p, q])
                t = math.copysign(1.0, theta) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):
                    akp, akq = a[k, p], a[k, q]
                    a[k, p] = c * akp - s * akq
                    a[k, q] = s * akp + c * akq
                for k in range(n):
                    apk, aqk = a[p, k], a[q, k]
                    a[p, k] = c * apk - s * aqk
                    a[q, k] = s * apk + c * aqk
    big, small = 0.0, np.inf
    for i in range(n):
        v = abs(a[i, i])
        big = max(big, v)
        small = min(small, v)
    if small == 0.0:
        return np.inf
    return big / small


@numba.njit(cache=True)
def _mass_matrix_condition(x, par, n, m, lo, inv, s, c, jx, jy, inertia_at):
    """Condition number of M(x) when it may be above the threshold, else a cheap upper bound.

    The scalar path, for the rare lanes whose vectorised bound (``_cond_bound``) is not far
    below the threshold.

    For SPD M, cond(M) <= trace(M) trace(M^-1) <= (N+2)^2 cond(M), and trace(M^-1) is the squared
    Frobenius norm of L^-1 from the Cholesky factor. When that bound is far below the threshold
    (every physical state: cond is about 1e3-1e4) the run is fine and the bound is returned; only
    otherwise are the eigenvalues computed. The array arguments after ``n`` are scratch space
    (allocations here would cost more than the arithmetic); ``inertia_at``: where the inertia
    rows start in ``par``.
    """
    nq = n + 2
    m[:, :] = 0.0
    lo[:, :] = 0.0
    inv[:, :] = 0.0
    for i in range(n):
        s[i] = math.sin(x[i])
        c[i] = math.cos(x[i])
    # J_j^T (m_j I + mu_j n_j n_j^T) J_j, summed over links, as eelsim.dynamics.mass_matrix
    for j in range(n):
        mj = par[W_MASS - W_GEOMETRY + j]
        muj = par[W_MU - W_GEOMETRY + j]
        a11 = mj + muj * s[j] * s[j]
        a22 = mj + muj * c[j] * c[j]
        a12 = -muj * s[j] * c[j]
        jx[:] = 0.0
        jy[:] = 0.0
        for i in range(n):
            g = par[j * n + i]
            jx[i] = -g * s[i]
            jy[i] = g * c[i]
        jx[n] = 1.0
        jy[n + 1] = 1.0
        for i in range(nq):
            for k in range(nq):
                m[i, k] += jx[i] * (a11 * jx[k] + a12 * jy[k]) + jy[i] * (a12 * jx[k] + a22 * jy[k])
    for i in range(n):
        m[i, i] += par[inertia_at + i]
    trace = 0.0
    for i in range(nq):
        trace += m[i, i]
    ok = True
    for k in range(nq):
        d = m[k, k]
        for j in range(k):
            d -= lo[k, j] * lo[k, j]
        if not d > 0.0:
            ok = False
            break
        lo[k, k] = math.sqrt(d)
        for i in range(k + 1, nq):
            v = m[i, k]
            for j in range(k):
                v -= lo[i, j] * lo[k, j]
            lo[i, k] = v / lo[k, k]
    if ok:
        # L^-1 by forward substitution, column by column
        for col in range(nq):
            for i in range(col, nq):
                v = 1.0 if i == col else 0.0
                for j in range(col, i):
                    v -= lo[i, j] * inv[j, col]
                inv[i, col] = v / lo[i, i]
        inv_trace = 0.0
        for i in range(nq):
            for j in range(nq):
                inv_trace += inv[i, j] * inv[i, j]
        bound = trace * inv_trace
        if bound < 0.5 * ILL_CONDITION_THRESHOLD:
            return bound
    return _jacobi_condition(m)


@_njit(**_NO_REFCOUNT)
def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


@_njit(**_NO_REFCOUNT)
def _on_segment(ax, ay, bx, by, cx, cy, d):
    return (d == 0.0 and min(ax, bx) <= cx <= max(ax, bx) and min(ay, by) <= cy <= max(ay, by))


@_njit(**_NO_REFCOUNT)
def _segments_intersect(p1x, p1y, p2x, p2y, q1x, q1y, q2x, q2y):
    """flags.segments_intersect: closed segments p1-p2 and q1-q2 share a point."""
    d1 = _cross(q2x - q1x, q2y - q1y, p1x - q1x, p1y - q1y)
    d2 = _cross(q2x - q1x, q2y - q1y, p2x - q1x, p2y - q1y)
    d3 = _cross(p2x - p1x, p2y - p1y, q1x - p1x, q1y - p1y)
    d4 = _cross(p2x - p1x, p2y - p1y, q2x - p1x, q2y - p1y)
    if ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4)):
        return True
    return (
        _on_segment(q1x, q1y, q2x, q2y, p1x, p1y, d1)
        or _on_segment(q1x, q1y, q2x, q2y, p2x, p2y, d2)
        or _on_segment(p1x, p1y, p2x, p2y, q1x, q1y, d3)
        or _on_segment(p1x, p1y, p2x, p2y, q2x, q2y, d4)
    )


@numba.njit(cache=True)
def _self_collision(x, par, n, limit, info, half_at):
    """flags.self_collision in its order; returns a reason code and fills ``info`` (i, k, value).

    ``half_at``: where the half-length rows start in ``par``.
    """
    for j in range(n - 1):
        phi = x[j + 1] - x[j]
        if abs(phi) > limit:
            info[0], info[1], info[2] = j, 0, phi
            return REASON_JOINT_LIMIT
    xs = np.empty(n)
    ys = np.empty(n)
    tx = np.empty(n)
    ty = np.empty(n)
    for i in range(n):
        cx, cy = 0.0, 0.0
        for k in range(n):
            g = par[i * n + k]
            cx += g * math.cos(x[k])
            cy += g * math.sin(x[k])
        xs[i] = x[n] + cx
        ys[i] = x[n + 1] + cy
        h = par[half_at + i]
        tx[i] = h * math.cos(x[i])
        ty[i] = h * math.sin(x[i])
    for i in range(n):
        for k in range(i + 2, n):
            if _segments_intersect(xs[i] - tx[i], ys[i] - ty[i], xs[i] + tx[i], ys[i] + ty[i],
                                   xs[k] - tx[k], ys[k] - ty[k], xs[k] + tx[k], ys[k] + ty[k]):
                info[0], info[1], info[2] = i, k, 0.0
                return REASON_LINKS_INTERSECT
    return REASON_NONE


@_njit(**_NO_REFCOUNT)
def _distance_left(px, py, waypoints, n_waypoints, target):
    """closed_loop._distance_left: to the current target, then along the remaining waypoints."""
    if target >= n_waypoints:
        return 0.0
    d = math.sqrt((waypoints[target, 0] - px) ** 2 + (waypoints[target, 1] - py) ** 2)
    for i in range(target, n_waypoints - 1):
        d += math.sqrt((waypoints[i + 1, 0] - waypoints[i, 0]) ** 2
                       + (waypoints[i + 1, 1] - waypoints[i, 1]) ** 2)
    return d


@_njit(**_NO_REFCOUNT)
def _median_of_five(a, b, c, d, e):
    """The middle one of five values (what np.median gives), by min and max without branches."""
    f = max(min(a, b), min(c, d))
    g = min(max(a, b), max(c, d))
    return max(min(e, f), min(max(e, f), g))


@_njit(**_NO_REFCOUNT)
def _median_by_ranks(med, count, filtered, rank, total):
    """np.median of the first ``count`` slots of ``med[slot, channel, lane]`` for every lane.

    The value of rank (count - 1) // 2 and count // 2 (their mean when count is even), rank i
    being the number of values that sort before value i with ties broken by slot: the order a
    stable sort gives, without branches, so that it runs across lanes (a sort per lane
    mispredicted its branches, and cost three times as much).
    """
    lo = float((count - 1) // 2)
    hi = float(count // 2)
    for ch in range(3):
        for r in range(LANES):
            total[r] = 0.0
        for i in range(count):
            for r in range(LANES):
                rank[r] = 0.0
            for j in range(count):
                if j < i:
                    for r in range(LANES):
                        rank[r] += 1.0 if med[j, ch, r] <= med[i, ch, r] else 0.0
                elif j > i:
                    for r in range(LANES):
                        rank[r] += 1.0 if med[j, ch, r] < med[i, ch, r] else 0.0
            for r in range(LANES):
                v = med[i, ch, r]
                total[r] += (v if rank[r] == lo else 0.0) + (v if rank[r] == hi else 0.0)
        for r in range(LANES):
            filtered[ch, r] = total[r] * 0.5


@_njit(**_NO_REFCOUNT, error_model="numpy")  # no zero test in the loops: pixel > 0 there
def _observe(frame, px, py, heading, alive, run_of, noise, pixel, window, camera, targets,
             waypoints, frame_time):
    """One camera frame for every lane of the block, as loops over the lanes that vectorise.

    ``px``, ``py``, ``heading``: the pose each lane's camera sees (lanes that stopped are
    computed too and ignored). Pixel quantisation and heading noise (the camera model of
    ``closed_loop``), then what ``guidance.Guidance.observe`` does: unwrapping against the last
    heading, the moving median over the last ``window`` frames (``camera.median[slot, channel,
    lane]``; every lane of a block sees the same frames, so the ring's slot and fill are the
    block's) and waypoint switching with arrival (``targets``).

    The median: :func:`_median_of_five` for the default window once full, else
    :func:`_median_by_ranks`.
    """
    med, med_state, last_heading, filtered, turn, rank, total = camera
    if pixel > 0.0:
        for r in range(LANES):
            px[r] = (np.floor(px[r] / pixel) + 0.5) * pixel
            py[r] = (np.floor(py[r] / pixel) + 0.5) * pixel
    if noise.shape[1] > 0:
        for r in range(LANES):
            heading[r] = heading[r] + noise[run_of[r], frame]
    count = med_state[0]
    if count > 0:
        # the unwrapped change is wrap(d), d itself for |d| < 1 < pi (frame-to-frame heading
        # changes are far smaller): the general case only when some lane turned that far
        widest = 0.0
        for r in range(LANES):
            d = heading[r] - last_heading[r]
            turn[r] = d
            widest = max(widest, abs(d))
        if not widest < 1.0:
            for r in range(LANES):
                d = turn[r]
                if abs(d) >= 1.0:
                    turn[r] = _wrap_angle(d)
        for r in range(LANES):
            heading[r] = last_heading[r] + turn[r]
    slot = med_state[1]
    for r in range(LANES):
        last_heading[r] = heading[r]
        med[slot, 0, r] = px[r]
        med[slot, 1, r] = py[r]
        med[slot, 2, r] = heading[r]
    med_state[1] = (slot + 1) % window
    if count < window:
        count += 1
        med_state[0] = count
    if count == 5:
        # the default window, once filled: the middle value by min and max, lanes innermost so
        # that each channel is one loop over contiguous lanes (it vectorises)
        for ch in range(3):
            for r in range(LANES):
                filtered[ch, r] = _median_of_five(med[0, ch, r], med[1, ch, r], med[2, ch, r],
                                                  med[3, ch, r], med[4, ch, r])
    else:
        _median_by_ranks(med, count, filtered, rank, total)
    # waypoint switching: targets.x/y hold each lane's current waypoint (NaN after the last)
    target, arrival, target_x, target_y, lane_radius, lane_waypoints = targets
    hits = 0
    for r in range(LANES):
        dx = filtered[0, r] - target_x[r]
        dy = filtered[1, r] - target_y[r]
        hits += (_vsqrt(dx * dx + dy * dy) < lane_radius[r]) & alive[r]
    if hits > 0:
        for r in range(LANES):
            dx = filtered[0, r] - target_x[r]
            dy = filtered[1, r] - target_y[r]
            if alive[r] and _vsqrt(dx * dx + dy * dy) < lane_radius[r]:
                target[r] += 1
                _aim(r, run_of[r], targets, waypoints)
                if target[r] == lane_waypoints[r] and np.isnan(arrival[r]):
                    arrival[r] = frame_time


@_njit(**_NO_REFCOUNT)
def _aim(r, run, targets, waypoints):
    """Lane r's current waypoint into targets.x/y (NaN once the last one is reached)."""
    if targets.reached[r] < targets.n_waypoints[r]:
        targets.x[r] = waypoints[run, targets.reached[r], 0]
        targets.y[r] = waypoints[run, targets.reached[r], 1]
    else:
        targets.x[r] = np.nan
        targets.y[r] = np.nan


@_njit(**_NO_REFCOUNT)
def _frame_poses(work, s, h, seen_x, seen_y, seen_heading):
    """The pose every lane's camera sees at fraction ``s`` of the step (rows x to xn, length h).

    camera.hermite of closed_loop's pose_and_rate (p and the mean angle, with their rates) at
    both ends of the step: its weights computed as it computes them and the terms summed in its
    order, the mean angle summed in pose_and_rate's order, so the pose is the same to the bit. At
    s = 0 the weights are (1, 0, 0, 0): the step's start itself. One loop over the lanes that
    vectorises.
    """
    s2, s3 = s * s, s * s * s
    k0, k1, k2, k3 = 2 * s3 - 3 * s2 + 1, (s3 - 2 * s2 + s) * h, -2 * s3 + 3 * s2, (s3 - s2) * h
    n = N_LINKS
    for r in range(LANES):
        h0 = 0.0
        hd0 = 0.0
        h1 = 0.0
        hd1 = 0.0
        for i in range(n):
            h0 += work[(W_X + i) * LANES + r]
            hd0 += work[(W_X + n + 2 + i) * LANES + r]
            h1 += work[(W_XN + i) * LANES + r]
            hd1 += work[(W_XN + n + 2 + i) * LANES + r]
        seen_x[r] = (((k0 * work[(W_X + n) * LANES + r] + k1 * work[(W_X + 2 * n + 2) * LANES + r])
                      + k2 * work[(W_XN + n) * LANES + r])
                     + k3 * work[(W_XN + 2 * n + 2) * LANES + r])
        seen_y[r] = (((k0 * work[(W_X + n + 1) * LANES + r]
                       + k1 * work[(W_X + 2 * n + 3) * LANES + r])
                      + k2 * work[(W_XN + n + 1) * LANES + r])
                     + k3 * work[(W_XN + 2 * n + 3) * LANES + r])
        seen_heading[r] = ((k0 * (h0 / n) + k1 * (hd0 / n)) + k2 * (h1 / n)) + k3 * (hd1 / n)


@_njit(**_NO_REFCOUNT)
def _check_start(work, out):
    """Finiteness and fastest rate of the block's initial states (rows x_bad and fastest).

    After step 0 the last RK4 stage writes both for the new state, which is the next step's x
    whenever the lane goes on (a lane whose new state is not finite stops there).
    """
    for r in range(LANES):
        bad = 0.0
        fastest = 0.0
        for row in range(2 * N_LINKS + 4):
            v = work[(W_X + row) * LANES + r]
            bad += v - v
            if row >= N_LINKS + 2:
                fastest = max(fastest, abs(v))
        out[O_X_BAD * LANES + r] = bad
        out[O_FASTEST * LANES + r] = fastest


@numba.njit(cache=True)
def _zeros_on_cache_lines(count):
    """np.zeros(count) that starts on a 64-byte boundary (numba's allocator aligns to 32).

    Paired A/B on the GA generation, aligned against not: faster in seven of eight comparisons
    in separate processes (median time ratios 0.86-0.98), 1.01 in the eighth; the likely cause
    is address aliasing at some 4 KB offsets (docs/kernel_history.md, session 3).
    """
    raw = np.zeros(count + 8)
    skip = ((64 - raw.ctypes.data % 64) % 64) // 8
    return raw[skip : skip + count]


@numba.njit(cache=True)  # returns an array: it must count the reference it hands back
def _gather(work, base, r, ns, dest):
    """The state of lane r from work rows ``base`` on, as a vector (for the scalar checks)."""
    for row in range(ns):
        dest[row] = work[(base + row) * LANES + r]
    return dest


# ---- the block's loop, in pieces (one job each; _run_block below reads as the list above) ----
# Why the pieces are ordinary compiled functions, called only when they have work, and not
# inlined by numba (inline="always"): numba inlines in its own IR, where every array handed to
# an inlined function is a new reference, and in a function this size LLVM's reference-count
# pruning gives up: the pieces inlined that way made about 600 calls to NRT_incref/NRT_decref in
# the step loop and the GA generation 1.5 times slower (tools/kernel_ab.py, final states
# identical; docs/kernel_history.md, session 10). numba does not inline separately compiled
# functions either, so each call costs its arguments (seven words per array). Hence: the
# per-lane work sits in pieces behind a test that is false on most steps (a control update every
# 30 steps, a sample step, a camera frame every third step, a check that fires, a block's start
# and end), and what every step runs - one count over the lanes that vectorises, the RK4 stages
# and the commit - stays in _run_block's loop. The stages are called through _rk4_stage (no
# reference counts; _stage_settings in it takes scalars only and is inlined).


@_njit(**_NO_REFCOUNT)
def _start_lanes(first, runs, work, out, fate, control, targets):
    """Load the block's runs into its lanes: parameters, initial state, schedules, first waypoint.

    Lanes past the last run hold the block's first run again (never committed: not alive), so
    that every lane computes finite numbers. Returns whether no lane has a servo line or a
    current (``batch.plain_runs``): the stage then leaves those terms out of its sweep.
    """
    (order, params, x0, total_steps, goal_steps, waypoints, n_waypoints, radius, _k_theta,
     _delay_steps, update_steps, update_count, _noise, plain_run, _guidance_state) = runs
    n_runs = x0.shape[0]
    plain = True
    for r in range(LANES):
        fate.alive[r] = first + r < n_runs
        out[O_LIVE * LANES + r] = 1.0 if fate.alive[r] else 0.0
        run = order[first + r] if first + r < n_runs else order[first]
        fate.run[r] = run
        for p in range(params.shape[1]):
            work[(W_GEOMETRY + p) * LANES + r] = params[run, p]
        for row in range(2 * N_LINKS + 4):
            work[(W_X + row) * LANES + r] = x0[run, row]
        targets.radius[r] = radius[run]
        fate.total[r] = total_steps[run]
        fate.goal[r] = goal_steps[run]
        if update_count[run] > 0:
            control.update_at[r] = update_steps[run, 0]
        targets.n_waypoints[r] = n_waypoints[run]
        _aim(r, run, targets, waypoints)
        plain = plain and plain_run[run]
    return plain


@_njit(**_NO_REFCOUNT)
def _update_controls(step, work, runs, pending_size, guide, fate, control, filtered, target,
                     lane_guide):
    """Control updates and delayed offsets of the lanes that have one at ``step``.

    An update computes the guidance offset from the filtered pose and queues it to act after the
    run's delay; every offset whose step has come acts, in order (closed_loop's pending queue).
    The offset in force goes to the stage's gamma row. Returns whether some lane updated (the
    condition-number bound is computed only then).
    """
    (gamma, next_update, update_at, pending_at, pend_step, pend_value, pend_head, pend_count,
     is_update) = control
    any_update = False
    for r in range(LANES):
        if not fate.alive[r]:
            continue
        run = fate.run[r]
        if update_at[r] == step:
            is_update[r] = True
            any_update = True
            k = next_update[r] + 1
            next_update[r] = k
            update_at[r] = runs.update_steps[run, k] if k < runs.update_count[run] else NEVER
            offset = _guidance_offset(filtered[0, r], filtered[1, r], filtered[2, r], r, run,
                                      target[r], runs.waypoints, runs.n_waypoints[run],
                                      runs.k_theta[run], guide, lane_guide)
            slot = (pend_head[r] + pend_count[r]) % pending_size
            pend_step[r, slot] = step + runs.delay_steps[run]
            pend_value[r, slot] = offset
            pend_count[r] += 1
        while pend_count[r] > 0 and pend_step[r, pend_head[r]] <= step:
            gamma[r] = pend_value[r, pend_head[r]]
            pend_head[r] = (pend_head[r] + 1) % pending_size
            pend_count[r] -= 1
        pending_at[r] = pend_step[r, pend_head[r]] if pend_count[r] > 0 else NEVER
        work[W_GAMMA * LANES + r] = gamma[r]
    return any_update


@_njit(**_NO_REFCOUNT)
def _record_states(step, sample, sampled, record_full, work, fate, states_out, full_out):
    """The live lanes' states at ``step`` into the outputs.

    At a sample step (``sampled``: ``sample`` is its index), and every step when the full
    history is asked for. The reference records before its checks, so this comes before them.
    """
    ns = 2 * N_LINKS + 4
    if sampled:
        for r in range(LANES):
            if fate.alive[r]:
                for row in range(ns):
                    states_out[fate.run[r], sample, row] = work[(W_X + row) * LANES + r]
    if record_full:
        for r in range(LANES):
            if fate.alive[r]:
                for row in range(ns):
                    full_out[fate.run[r], step, row] = work[(W_X + row) * LANES + r]


@numba.njit(cache=True)
def _check_state(step, t, work, out, params, stop_at_goal, fate, is_update, arrival, scratch,
                 variant):
    """closed_loop._check of x for the live lanes, in its order, and the stop rules.

    Non-finite, diverging, the condition number at control updates, the joint limit and link
    intersection: the first that fires stops the lane with its reason. The vectorised bound (row
    cond_bound) settles every physical state; the exact condition number (the scalar path) is
    computed only near the threshold, the exact self-collision test only for lanes the screen
    flagged. A lane that passes stops when its time is up or it is at its goal. ``variant``: the
    variant's rows (V_INERTIA, V_HALF_LENGTH, V_LIMIT).
    """
    n = N_LINKS
    ns = 2 * n + 4
    for r in range(LANES):
        if not fate.alive[r]:
            continue
        run = fate.run[r]
        code = REASON_NONE
        if np.isnan(out[O_X_BAD * LANES + r]):
            code = REASON_NOT_FINITE
        elif out[O_FASTEST * LANES + r] > DIVERGENCE_RATE:
            code = REASON_DIVERGED
        elif is_update[r]:
            cond = out[O_COND_BOUND * LANES + r]
            if not cond < 0.5 * ILL_CONDITION_THRESHOLD:
                cond = _mass_matrix_condition(_gather(work, W_X, r, ns, scratch.state),
                                              params[run], n, scratch.m, scratch.lo,
                                              scratch.inv, scratch.s, scratch.c, scratch.jx,
                                              scratch.jy, variant[V_INERTIA])
            if not cond < ILL_CONDITION_THRESHOLD:
                code = REASON_CONDITION_NUMBER
                fate.reason_value[r] = cond
        if code == REASON_NONE and out[O_NEAR * LANES + r] != 0.0:
            code = _self_collision(_gather(work, W_X, r, ns, scratch.state), params[run], n,
                                   work[variant[V_LIMIT] * LANES + r], scratch.info,
                                   variant[V_HALF_LENGTH])
            if code != REASON_NONE:
                fate.reason_index[r, 0] = int(scratch.info[0])
                fate.reason_index[r, 1] = int(scratch.info[1])
                fate.reason_value[r] = scratch.info[2]
        if code != REASON_NONE:
            self_hit = code == REASON_JOINT_LIMIT or code == REASON_LINKS_INTERSECT
            fate.failure[r] = FAIL_SELF_COLLISION if self_hit else FAIL_ILL_CONDITIONED
            fate.reason[r] = code
            fate.failure_time[r] = t
            fate.alive[r] = False
            out[O_LIVE * LANES + r] = 0.0
            fate.final_step[r] = step
        elif ((stop_at_goal and not np.isnan(arrival[r]) and step >= fate.goal[r])
              or step >= fate.total[r]):
            fate.alive[r] = False
            out[O_LIVE * LANES + r] = 0.0
            fate.final_step[r] = step


@numba.njit(cache=True, inline="always")  # scalars only: inlined with no reference to count
def _stage_settings(st, step, t, dt):
    """RK4 stage ``st``'s time, step fraction, weight in the sums and whether it may rotate.

    Rotating: sin and cos by rotation of the previous stage's rather than in full; it also needs
    every live lane to have moved little, which the generated stage tests itself (rows offset
    and live; the driver keeps row live equal to ``alive``). Stage 1 rotates stage 4's angles
    (which left their offset), with the full sin and cos every RESYNC_STEPS steps (and at step
    0), so that the chain of rotations keeps its rounding small.
    """
    half = 0.5 * dt
    if st == 0:
        return t, half, 1.0, step % RESYNC_STEPS != 0
    if st == 1:
        return t + half, half, 2.0, True
    if st == 2:
        return t + half, dt, 2.0, True
    return t + dt, 0.0, 1.0, True


@_njit(**_NO_REFCOUNT)
def _count_live(alive):
    """How many lanes are still running."""
    live = 0
    for r in range(LANES):
        live += alive[r]
    return live


@_njit(**_NO_REFCOUNT)
def _next_due(alive, update_at, pending_at):
    """The first step at which a live lane has a control update or a delayed offset due."""
    due = NEVER
    for r in range(LANES):
        if alive[r]:
            due = min(due, update_at[r], pending_at[r])
    return due


@_njit(**_NO_REFCOUNT)
def _rk4_stage(work, st, step, t, dt, plain, stage_fn):
    """RK4 stage ``st`` of the step at ``t`` for every lane (the generated ``_stage``).

    Its own function, without reference counts: called from _run_block's stage loop directly,
    the stage made numba take and drop a reference to the block's buffer around three of the
    four calls of every step (an atomic add each).
    """
    t_s, a, wk, may_rotate = _stage_settings(st, step, t, dt)
    _call_stage(stage_fn, work, t_s, a, wk, st == 0, st == 3, dt / 6.0, may_rotate,
                st == 1 or st == 3, plain)


@_njit(**_NO_REFCOUNT)
def _fail_new_state(step, t, dt, out, fate):
    """Stop the live lanes whose new state xn failed (row keep is 0 for them).

    A non-positive pivot of the stage's solve fails the lane at t, a new state that is not
    finite at t + dt (the reference's order).
    """
    for r in range(LANES):
        if not fate.alive[r] or out[O_KEEP * LANES + r] != 0.0:
            continue
        code = REASON_NONE
        if out[O_BAD_PIVOT * LANES + r] > 0.0:
            code = REASON_NOT_POSITIVE_DEFINITE
            fate.failure_time[r] = t
        elif np.isnan(out[O_XN_BAD * LANES + r]):
            code = REASON_NOT_FINITE
            fate.failure_time[r] = t + dt
        fate.failure[r] = FAIL_ILL_CONDITIONED
        fate.reason[r] = code
        fate.alive[r] = False
        out[O_LIVE * LANES + r] = 0.0
        fate.final_step[r] = step


@_njit(**_NO_REFCOUNT)
def _camera_frames(step, frame, dt, frames, work, runs, pixel, window, fate, camera, targets,
                   seen_x, seen_y, seen_heading):
    """Observe the camera frames in (t, t + dt]; return the next frame's index.

    Each frame sees the Hermite-interpolated pose between x and xn (_frame_poses) through the
    camera model and the guidance's filter (_observe); ``seen_*`` are scratch for the poses.
    """
    while frame < frames.step.shape[0] and frames.step[frame] == step:
        _frame_poses(work, frames.fraction[frame], dt, seen_x, seen_y, seen_heading)
        _observe(frame, seen_x, seen_y, seen_heading, fate.alive, fate.run, runs.noise, pixel,
                 window, camera, targets, runs.waypoints, frames.time[frame])
        frame += 1
    return frame


@_njit(**_NO_REFCOUNT)
def _commit_kept(work, out):
    """The kept lanes' new state xn becomes x, a select per lane (row keep of ``out``).

    For the steps on which some lane stops; otherwise _run_block copies the rows whole.
    """
    for row in range(2 * N_LINKS + 4):
        for r in range(LANES):
            i = row * LANES + r
            keep = out[O_KEEP * LANES + r]
            work[W_X * LANES + i] = work[W_XN * LANES + i] if keep != 0.0 else work[W_X * LANES + i]


@_njit(**_NO_REFCOUNT)
def _write_outputs(first, dt, work, out, runs, outputs, fate, targets):
    """Copy each run's answers from its lane into the outputs.

    A run that neither failed nor arrived is too slow (reason index: the waypoint it was heading
    for); the final state and the distance left go out too.
    """
    n_runs = runs.x0.shape[0]
    for r in range(LANES):
        if first + r >= n_runs:
            continue
        run = fate.run[r]
        if fate.failure[r] == FAIL_NONE and np.isnan(targets.arrival[r]):
            fate.failure[r] = FAIL_TOO_SLOW
            fate.reason[r] = REASON_TOO_SLOW
            fate.failure_time[r] = fate.final_step[r] * dt
            fate.reason_index[r, 0] = targets.reached[r]
        outputs.arrival[run] = targets.arrival[r]
        outputs.failure[run] = fate.failure[r]
        outputs.failure_time[run] = fate.failure_time[r]
        outputs.reason[run] = fate.reason[r]
        outputs.reason_index[run, 0] = fate.reason_index[r, 0]
        outputs.reason_index[run, 1] = fate.reason_index[r, 1]
        outputs.reason_value[run] = fate.reason_value[r]
        for row in range(2 * N_LINKS + 4):
            outputs.final_state[run, row] = work[(W_X + row) * LANES + r]
        outputs.final_step[run] = fate.final_step[r]
        outputs.target[run] = targets.reached[r]
        outputs.torque_ratio[run] = out[O_TORQUE_RATIO * LANES + r]
        outputs.saturated[run] = int(out[O_SATURATED * LANES + r])
        outputs.distance[run] = _distance_left(work[(W_X + N_LINKS) * LANES + r],
                                               work[(W_X + N_LINKS + 1) * LANES + r],
                                               runs.waypoints[run], runs.n_waypoints[run],
                                               targets.reached[r])


@numba.njit(cache=True)
def _run_block(block, runs, frames, loop, outputs, variant):
    """Run block ``block`` (runs ``runs.order[block * LANES ...]``) to its end (module docstring).

    ``runs``, ``frames``, ``loop`` and ``outputs`` are the records of ``eelsim.batch.records``.
    The lanes' states live in ``work`` (rows W_X: the step's start, W_XN: its end), so the
    generated code reads and writes them with constant offsets; everything per lane and per step
    that does not vectorise (control updates, checks, camera) reads single numbers from there.
    Each step is the sequence of the module docstring; the per-lane work is in the pieces above.
    ``variant``: what the driver learns of the variant at run time (V_WORK_ROWS ...).
    """
    dt, pixel, window, stop_at_goal, pending_size, record_full, sample_steps, guide = loop
    n = N_LINKS
    ns = 2 * n + 4
    first = block * LANES
    # one buffer: the rows of work, then those of out (the generated code indexes it whole)
    work_rows = variant[V_WORK_ROWS]
    stage_fn = variant[V_STAGE]
    screen_fn = variant[V_SCREEN]
    cond_fn = variant[V_COND_BOUND]
    work = _zeros_on_cache_lines((work_rows + OUT_ROWS) * LANES)
    out = work[work_rows * LANES :]
    # the lanes' records; the arrays that every step's loops read are named once here (taking
    # them out of a record inside the loop would count a reference each time)
    alive = np.zeros(LANES, np.bool_)
    lane_total = np.zeros(LANES, np.int64)
    lane_goal = np.zeros(LANES, np.int64)
    fate = LaneFate(np.empty(LANES, np.int64), alive, lane_total, lane_goal,
                    np.zeros(LANES, np.int64), np.zeros(LANES, np.int64), np.full(LANES, np.nan),
                    np.zeros((LANES, 2), np.int64), np.zeros(LANES), np.zeros(LANES, np.int64))
    update_at = np.full(LANES, NEVER, np.int64)
    pending_at = np.full(LANES, NEVER, np.int64)
    is_update = np.zeros(LANES, np.bool_)
    control = LaneControl(np.zeros(LANES), np.zeros(LANES, np.int64), update_at, pending_at,
                          np.zeros((LANES, pending_size), np.int64),
                          np.zeros((LANES, pending_size)), np.zeros(LANES, np.int64),
                          np.zeros(LANES, np.int64), is_update)
    # the camera's state, lanes innermost (see _observe), and the lanes' waypoints
    filtered = np.zeros((3, LANES))
    camera = CameraState(np.zeros((window, 3, LANES)), np.zeros(2, np.int64), np.zeros(LANES),
                         filtered, np.zeros(LANES), np.zeros(LANES), np.zeros(LANES))
    arrival = np.full(LANES, np.nan)
    targets = Targets(np.zeros(LANES, np.int64), arrival, np.full(LANES, np.nan),
                      np.full(LANES, np.nan), np.zeros(LANES), np.zeros(LANES, np.int64))
    lane_guide = np.zeros((4, LANES))  # guidance: first-leg start, ILOS integral
    seen_x = np.zeros(LANES)  # the pose each lane's camera sees
    seen_y = np.zeros(LANES)
    seen_heading = np.zeros(LANES)
    scratch = CheckScratch(np.empty(ns), np.zeros(3), np.empty((n + 2, n + 2)),
                           np.empty((n + 2, n + 2)), np.empty((n + 2, n + 2)), np.empty(n),
                           np.empty(n), np.empty(n + 2), np.empty(n + 2))
    plain = _start_lanes(first, runs, work, out, fate, control, targets)
    # the frame at t = 0 sees the initial pose (fraction 0 of the first step; the xn rows are
    # still zero)
    _frame_poses(work, 0.0, dt, seen_x, seen_y, seen_heading)
    _observe(0, seen_x, seen_y, seen_heading, alive, fate.run, runs.noise, pixel, window, camera,
             targets, runs.waypoints, frames.time[0])
    _start_guidance(alive, fate.run, runs.guidance_state, filtered, lane_guide)
    _check_start(work, out)
    frame = 1
    frame_step = frames.step
    n_frames = frame_step.shape[0]
    n_samples = sample_steps.shape[0]
    sample = 0
    guide_sample = 0
    step = 0
    # the live lanes and the next step at which one has a control update or a delayed offset
    # due, kept up to date where they change (a count over the lanes at every step had
    # compiled to scalar code over the bool arrays)
    live = _count_live(alive)
    next_due = _next_due(alive, update_at, pending_at)
    while True:
        if live == 0:
            break
        t = step * dt
        # the call only on a sample step: made every step it cost a fifth of the driver's time
        if guide_sample < n_samples and sample_steps[guide_sample] <= step:
            guide_sample = _sample_guidance(step, guide_sample, sample_steps, alive, fate.run,
                                            lane_guide, outputs.integral)
        # 1. control updates; offsets act after the delay (pending queue, in order). A lane
        # that stopped since next_due was found may leave it early: the call then finds
        # nothing to do.
        any_update = False
        if step >= next_due:
            any_update = _update_controls(step, work, runs, pending_size, guide, fate, control,
                                          filtered, targets.reached, lane_guide)
            next_due = _next_due(alive, update_at, pending_at)
        # 2. samples (the reference records every step before its checks)
        while sample < n_samples and sample_steps[sample] < step:
            sample += 1
        sampled = sample < n_samples and sample_steps[sample] == step
        if sampled or record_full:
            _record_states(step, sample, sampled, record_full, work, fate, outputs.states,
                           outputs.full)
        # 3.-4. the four RK4 stages from y = x (same sums as integrate.rk4_step, done inside the
        # stages). One call site on purpose: LLVM inlines the generated stage into this
        # function, and four call sites made four copies of it (a minute of cold compile
        # instead of seconds). After stage 1 at x (its sin/cos feed the collision screen) come
        # the checks of closed_loop._check.
        for i in range(ns * LANES):  # the rows x are contiguous: one flat copy
            work[W_Y * LANES + i] = work[W_X * LANES + i]
        for st in range(4):
            # (the stage itself turns rotate off unless every live lane moved little)
            _rk4_stage(work, st, step, t, dt, plain, stage_fn)
            if st == 0:
                _call_screen(screen_fn, work)
                if any_update:
                    _call_cond_bound(cond_fn, work)
                # the lanes that fail a check or stop here (most steps: none), counted by a
                # loop that vectorises; the checks run only for them
                flagged = 0
                for r in range(LANES):
                    bound = out[O_COND_BOUND * LANES + r]
                    x_bad = out[O_X_BAD * LANES + r]
                    stops = ((x_bad != x_bad) | (out[O_FASTEST * LANES + r] > DIVERGENCE_RATE)
                             | (out[O_NEAR * LANES + r] != 0.0) | (step >= lane_total[r])
                             | (stop_at_goal & (arrival[r] == arrival[r])
                                & (step >= lane_goal[r]))
                             | (is_update[r] & ((bound >= 0.5 * ILL_CONDITION_THRESHOLD)
                                                | (bound != bound))))
                    flagged += alive[r] & stops
                if flagged > 0:
                    _check_state(step, t, work, out, runs.params, stop_at_goal, fate, is_update,
                                 arrival, scratch, variant)
                    live = _count_live(alive)
        # the pivot and finiteness of the new state: the last stage wrote row keep and the
        # block's verdict (some live lane failed; some lane does not commit)
        if out[O_STEP_VERDICT * LANES] != 0.0:
            _fail_new_state(step, t, dt, out, fate)
            live = _count_live(alive)
        # 5. camera frames in (t, t + dt] see the Hermite-interpolated pose
        if frame < n_frames and frame_step[frame] == step:
            frame = _camera_frames(step, frame, dt, frames, work, runs, pixel, window, fate,
                                   camera, targets, seen_x, seen_y, seen_heading)
        # 6. lanes still running commit the step: a plain copy of the rows when every lane
        # does (most steps; the select per lane cost about 11 ns per run and step)
        if out[O_STEP_VERDICT * LANES + 1] == 0.0:
            for i in range(ns * LANES):
                work[W_X * LANES + i] = work[W_XN * LANES + i]
        else:
            _commit_kept(work, out)
        if any_update:  # the flags of this step's updates, for the checks above
            for r in range(LANES):
                is_update[r] = False
        step += 1
    _write_outputs(first, dt, work, out, runs, outputs, fate, targets)


@numba.njit(cache=True, parallel=True)
def _run_blocks(runs, frames, loop, outputs, threads, variant):
    """Run every block of LANES runs on ``threads`` threads, each taking the next block when free.

    Block b runs ``runs.order[b * LANES : (b + 1) * LANES]``: the caller orders the runs so that
    a block's lanes end at about the same step (a lane that has ended idles until its block
    ends), longest blocks first. ``threads`` is numba's thread count (asking numba for it in here
    would keep numba from caching this function).
    """
    n_blocks = (runs.x0.shape[0] + LANES - 1) // LANES
    counter = np.zeros(1, dtype=np.int64)
    for _ in numba.prange(max(1, min(threads, n_blocks))):
        block = _next_block(counter)
        while block < n_blocks:
            _run_block(block, runs, frames, loop, outputs, variant)
            block = _next_block(counter)


def run_blocks(runs, frames, loop, outputs, threads):
    """Run every block (:func:`_run_blocks`) with this module's generated functions.

    A module whose stage is compiled as C redefines this to run the shared driver module with
    its library's functions (eelsim.batch.loading).
    """
    _run_blocks(runs, frames, loop, outputs, threads, _variant())
