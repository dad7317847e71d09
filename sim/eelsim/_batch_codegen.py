"""Source generator for the batched kernel's hot loop (one RK4 stage for a block of runs).

Why generate code: the right-hand side of the swimmer for N links is a few hundred lines of
straight-line arithmetic once the loops over links are unrolled. Written that way, inside a single
loop over the runs of a block ("lanes"), every intermediate is a scalar local, LLVM keeps them in
(vector) registers and vectorises the lane loop: each machine instruction advances 4 runs (AVX2).
The same maths written with loops over links and small arrays goes through memory at every
operation and runs about half as fast. The generated text is written once per (N, lanes) next to
the package (in ``__pycache__``), so numba's on-disk cache works across processes.

The arithmetic mirrors ``eelsim.dynamics`` (compact per-link form, spec section 2) and
``eelsim.control`` (gait, PD, servo line) term by term; the only deliberate differences are in
rounding (sums in another order, the gait phases by angle addition, an own vectorisable sin/cos),
all at the 1e-16 level, which the tests check stays below 1e-9 on whole closed-loop runs.

Memory layout: ``work`` and ``out`` are flat float64 arrays holding rows of ``lanes`` values;
``work[row * lanes + r]`` is quantity ``row`` of lane ``r``. Row offsets are literals in the
generated text, so LLVM sees constant distances between accesses and needs no aliasing checks
beyond one between ``work`` and ``out``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# Taylor coefficients of sin and cos; after reduction to |r| <= pi/4 the first omitted terms are
# below 1e-19 (sin, r^19/19!) and 1e-20 (cos, r^20/20!), so rounding dominates (about 1 ulp).
_SIN_TAYLOR = [(-1.0) ** k / math.factorial(2 * k + 1) for k in range(1, 9)]
_COS_TAYLOR = [(-1.0) ** k / math.factorial(2 * k) for k in range(1, 10)]
# pi/2 split in three parts (33 + 33 + 53 significant bits) for Cody-Waite range reduction: k*PIO2_1
# and k*PIO2_2 are exact for |k| < 2^20, i.e. angles up to about 1.6e6 rad.
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624879595063154e-21
# Two links can only touch when their centres are closer than the sum of their half-lengths; the
# screen flags pairs within that distance (squared, plus this relative margin for rounding) for the
# exact segment test of eelsim.flags, which runs only then.
_SCREEN_MARGIN = 1e-6


@dataclass(frozen=True)
class Layout:
    """Row offsets of the per-lane quantities in the flat ``work`` and ``out`` buffers.

    Attributes
    ----------
    n_links : int
        N.
    lanes : int
        Runs per block.
    work : dict
        Name -> first row in ``work``.
    work_rows : int
        Total rows of ``work``.
    out : dict
        Name -> first row in ``out``.
    out_rows : int
        Total rows of ``out``.
    """

    n_links: int
    lanes: int
    work: dict[str, int]
    work_rows: int
    out: dict[str, int]
    out_rows: int


def make_layout(n_links: int, lanes: int) -> Layout:
    """Assign rows to every per-lane quantity the stage function reads or writes.

    Parameters
    ----------
    n_links : int
        N.
    lanes : int
        Runs per block.

    Returns
    -------
    Layout
    """
    n = n_links
    sizes_work = [
        ("y", 2 * n + 4),  # the stage state (theta, p, theta_dot, p_dot)
        ("gamma", 1),  # held steering offset
        ("geometry", n * n),  # G[j, i] at row j * N + i
        ("gmg", n * n),  # sum_j m_j G[j, i] G[j, k], at row i * N + k
        ("sm", n),  # sum_j m_j G[j, i]
        ("mass", n),
        ("mu", n),
        ("ct", n),
        ("cn", n),
        ("lambda2", n),
        ("lambda3", n),
        ("inertia", n),  # J_i + lambda_1,i
        ("mass_sum", 1),
        ("amp", n - 1),  # A_j
        ("cos_beta", n - 1),  # cos((j - 1) beta)
        ("sin_beta", n - 1),
        ("omega", 1),
        ("kp", 1),
        ("kd", 1),
        ("limit", 1),  # mechanical joint limit (self-collision check)
        ("clamp", 1),  # joint references are clamped to +-this (JointSpec.command_limit_rad)
        ("half_length", n),
        ("stall", 1),  # servo stall torque (inf when the servo model is off)
        ("inv_no_load", 1),  # 1 / servo no-load speed (0 when off): a multiply, not a division
        ("vcx", 1),
        ("vcy", 1),
    ]
    sizes_out = [("k", 2 * n + 4), ("bad_pivot", 1), ("sin", n), ("cos", n), ("near", 1)]

    def assign(sizes: list[tuple[str, int]]) -> tuple[dict[str, int], int]:
        rows, at = {}, 0
        for name, size in sizes:
            rows[name] = at
            at += size
        return rows, at

    work, work_rows = assign(sizes_work)
    out, out_rows = assign(sizes_out)
    return Layout(n, lanes, work, work_rows, out, out_rows)


class _Emitter:
    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.lines: list[str] = []

    def w(self, name: str, index: int = 0) -> str:
        """Expression reading ``work`` row ``name[index]`` of lane r."""
        return f"work[{(self.layout.work[name] + index) * self.layout.lanes} + r]"

    def o(self, name: str, index: int = 0) -> str:
        return f"out[{(self.layout.out[name] + index) * self.layout.lanes} + r]"

    def line(self, text: str) -> None:
        self.lines.append("        " + text)

    def sincos(self, arg: str, s: str, c: str) -> None:
        """Emit s = sin(arg), c = cos(arg) without calls or branches (so the lane loop vectorises).

        Cody-Waite reduction to r in [-pi/4, pi/4], Taylor polynomials, quadrant by selects.
        """
        t = f"_{s}"
        self.line(f"{t}k = np.floor({arg} * {2.0 / math.pi!r} + 0.5)")
        self.line(f"{t}r = (({arg} - {t}k * {_PIO2_1!r}) - {t}k * {_PIO2_2!r}) - {t}k * {_PIO2_3!r}")
        self.line(f"{t}z = {t}r * {t}r")
        poly = f"{_SIN_TAYLOR[-1]!r}"
        for coef in reversed(_SIN_TAYLOR[:-1]):
            poly = f"{coef!r} + {t}z * ({poly})"
        self.line(f"{t}sr = {t}r + {t}r * {t}z * ({poly})")
        poly = f"{_COS_TAYLOR[-1]!r}"
        for coef in reversed(_COS_TAYLOR[:-1]):
            poly = f"{coef!r} + {t}z * ({poly})"
        self.line(f"{t}cr = 1.0 + {t}z * ({poly})")
        # quadrant q = k mod 4: sin x = +-(sin r or cos r), cos x likewise
        self.line(f"{t}q = {t}k - 4.0 * np.floor({t}k * 0.25)")
        self.line(f"{t}odd = {t}q - 2.0 * np.floor({t}q * 0.5)")
        self.line(f"{s} = {t}cr if {t}odd == 1.0 else {t}sr")
        self.line(f"{c} = {t}sr if {t}odd == 1.0 else {t}cr")
        self.line(f"{s} = -{s} if {t}q >= 2.0 else {s}")
        self.line(f"{c} = -{c} if abs({t}q - 1.5) < 1.0 else {c}")


def _stage_body(layout: Layout) -> list[str]:
    n = layout.n_links
    e = _Emitter(layout)
    line = e.line
    w, o = e.w, e.o
    nq = n + 2  # generalised coordinates (theta, p)

    line("# ---- stage state and per-lane parameters")
    for i in range(n):
        line(f"th{i} = {w('y', i)}")
        line(f"om{i} = {w('y', n + 2 + i)}")
    line(f"vx = {w('y', 2 * n + 2)}")
    line(f"vy = {w('y', 2 * n + 3)}")
    line(f"gam = {w('gamma')}")
    line(f"vcx = {w('vcx')}")
    line(f"vcy = {w('vcy')}")
    for i in range(n):
        line(f"m{i} = {w('mass', i)}")
        line(f"mu{i} = {w('mu', i)}")
        for k in range(n):
            line(f"g{i}_{k} = {w('geometry', i * n + k)}")

    line("# ---- link angles: sin, cos (stored for the self-collision screen)")
    for i in range(n):
        e.sincos(f"th{i}", f"s{i}", f"c{i}")
        line(f"{o('sin', i)} = s{i}")
        line(f"{o('cos', i)} = c{i}")

    line("# ---- gait and joint PD (control.gait_reference, joint_pd_torque, servo_limited)")
    line(f"omega = {w('omega')}")
    line(f"kp = {w('kp')}")
    line(f"kd = {w('kd')}")
    line(f"lim = {w('clamp')}")
    line(f"stall = {w('stall')}")
    line(f"inv_noload = {w('inv_no_load')}")
    # sin(omega t + j beta) by angle addition: one sin/cos per stage instead of N - 1
    e.sincos("omega * t_s", "sp", "cp")
    for j in range(n - 1):
        line(f"amp = {w('amp', j)}")
        line(f"cb = {w('cos_beta', j)}")
        line(f"sb = {w('sin_beta', j)}")
        line("al = amp * (sp * cb + cp * sb) + gam")
        line("al = min(max(al, -lim), lim)")
        line("ald = amp * omega * (cp * cb - sp * sb)")
        line(f"phd = om{j + 1} - om{j}")
        line(f"u = kp * (al - (th{j + 1} - th{j})) + kd * (ald - phd)")
        # servo torque-speed line; stall = inf and 1/no_load = 0 when the servo model is off,
        # which leaves u unchanged exactly
        line("rr = phd * inv_noload")
        line("hi = stall * min(1.0, 1.0 - rr)")
        line("lo = -stall * min(1.0, 1.0 + rr)")
        line(f"u{j} = min(max(u, lo), hi)")

    line("# ---- link kinematics: velocities and centripetal accelerations (Jdot q_dot)")
    for i in range(n):
        line(f"w2_{i} = om{i} * om{i}")
    for j in range(n):
        sx = " + ".join(f"g{j}_{i} * (s{i} * om{i})" for i in range(n))
        sy = " + ".join(f"g{j}_{i} * (c{i} * om{i})" for i in range(n))
        line(f"lvx{j} = vx - ({sx})")
        line(f"lvy{j} = vy + ({sy})")
        ax = " + ".join(f"g{j}_{i} * (c{i} * w2_{i})" for i in range(n))
        ay = " + ".join(f"g{j}_{i} * (s{i} * w2_{i})" for i in range(n))
        line(f"ax{j} = -({ax})")
        line(f"ay{j} = -({ay})")

    line("# ---- per-link forces: Morison drag, added-mass current term, centripetal inertia")
    for j in range(n):
        line(f"rx = lvx{j} - vcx")
        line(f"ry = lvy{j} - vcy")
        line(f"vt = c{j} * rx + s{j} * ry")
        line(f"vn = -s{j} * rx + c{j} * ry")
        line(f"ft = -{w('ct', j)} * (vt + abs(vt) * vt)")
        line(f"fn = -{w('cn', j)} * (vn + abs(vn) * vn)")
        line(f"curn = -mu{j} * om{j} * (c{j} * vcx + s{j} * vcy)")
        line(f"msc = mu{j} * s{j} * c{j}")
        line(f"ix = (m{j} + mu{j} * s{j} * s{j}) * ax{j} - msc * ay{j}")
        line(f"iy = -msc * ax{j} + (m{j} + mu{j} * c{j} * c{j}) * ay{j}")
        line(f"fx{j} = (ft * c{j} - fn * s{j}) + (-curn * s{j}) - ix")
        line(f"fy{j} = (ft * s{j} + fn * c{j}) + curn * c{j} - iy")

    line("# ---- generalised forces Q = sum_j J_j^T F_j + fluid yaw damping + joint torques")
    for i in range(n):
        gx = " + ".join(f"g{j}_{i} * fx{j}" for j in range(n))
        gy = " + ".join(f"g{j}_{i} * fy{j}" for j in range(n))
        tau = []
        if i > 0:
            tau.append(f"+ u{i - 1}")
        if i < n - 1:
            tau.append(f"- u{i}")
        line(f"q{i} = -s{i} * ({gx}) + c{i} * ({gy})")
        line(
            f"q{i} = q{i} + (-{w('lambda2', i)} * om{i} - {w('lambda3', i)} * abs(om{i}) * om{i}"
            f" {' '.join(tau)})"
        )
    line(f"q{n} = {' + '.join(f'fx{j}' for j in range(n))}")
    line(f"q{n + 1} = {' + '.join(f'fy{j}' for j in range(n))}")

    line("# ---- mass matrix M (spec section 2) in the rotated form:")
    line("# M_tt[i,k] = cos(th_i - th_k) sum_j m_j G_ji G_jk + sum_j mu_j b_ji b_jk,")
    line("# b_ji = G_ji cos(th_j - th_i); M_tp and M_pp follow from the same J_j^T A_j J_j")
    for i in range(n):
        for k in range(i + 1, n):
            line(f"cd{i}_{k} = c{i} * c{k} + s{i} * s{k}")

    def cd(a: int, b: int) -> str:
        return "1.0" if a == b else f"cd{min(a, b)}_{max(a, b)}"

    for j in range(n):
        for i in range(n):
            if i == j:
                line(f"b{j}_{i} = g{j}_{i}")
            else:
                line(f"b{j}_{i} = g{j}_{i} * {cd(j, i)}")
            line(f"mb{j}_{i} = mu{j} * b{j}_{i}")
    for i in range(n):
        for k in range(i, n):
            mu_part = " + ".join(f"mb{j}_{i} * b{j}_{k}" for j in range(n))
            if i == k:
                line(f"a{i}_{i} = {w('gmg', i * n + i)} + ({mu_part}) + {w('inertia', i)}")
            else:
                line(f"a{i}_{k} = {cd(i, k)} * {w('gmg', i * n + k)} + ({mu_part})")
    for i in range(n):
        sx = " + ".join(f"mb{j}_{i} * s{j}" for j in range(n))
        sy = " + ".join(f"mb{j}_{i} * c{j}" for j in range(n))
        line(f"a{i}_{n} = -s{i} * {w('sm', i)} - ({sx})")
        line(f"a{i}_{n + 1} = c{i} * {w('sm', i)} + ({sy})")
    line(f"msum = {w('mass_sum')}")
    line(f"a{n}_{n} = msum + ({' + '.join(f'mu{j} * s{j} * s{j}' for j in range(n))})")
    line(f"a{n}_{n + 1} = -({' + '.join(f'mu{j} * s{j} * c{j}' for j in range(n))})")
    line(f"a{n + 1}_{n + 1} = msum + ({' + '.join(f'mu{j} * c{j} * c{j}' for j in range(n))})")

    line("# ---- M = L D L^T (unit L), unrolled. No square roots: the pivots D_k are the squares of")
    line("# the Cholesky diagonal, and a pivot <= 0 is what makes LAPACK (OpenBLAS potf2) refuse M")
    line("# (a NaN pivot is not refused there either: NaN propagates to the state)")
    line("bad = 0.0")
    for k in range(nq):
        d = " - ".join([f"a{k}_{k}"] + [f"l{k}_{j} * e{k}_{j}" for j in range(k)])
        line(f"dk = {d}")
        line("bad = 1.0 if dk <= 0.0 else bad")
        line(f"inv{k} = 1.0 / dk")
        for i in range(k + 1, nq):
            v = " - ".join([f"a{k}_{i}"] + [f"l{i}_{j} * e{k}_{j}" for j in range(k)])
            line(f"e{i}_{k} = {v}")  # L[i, k] D[k]
            line(f"l{i}_{k} = e{i}_{k} * inv{k}")
    line(f"{o('bad_pivot')} = bad")
    line("# ---- solve L z = Q, then D L^T qdd = z")
    for i in range(nq):
        v = " - ".join([f"q{i}"] + [f"l{i}_{j} * z{j}" for j in range(i)])
        line(f"z{i} = {v}")
    for i in reversed(range(nq)):
        v = " - ".join([f"z{i} * inv{i}"] + [f"l{j}_{i} * x{j}" for j in range(i + 1, nq)])
        line(f"x{i} = {v}")

    line("# ---- derivative (theta_dot, p_dot, theta_ddot, p_ddot)")
    for i in range(n):
        line(f"{o('k', i)} = om{i}")
    line(f"{o('k', n)} = vx")
    line(f"{o('k', n + 1)} = vy")
    for i in range(nq):
        line(f"{o('k', n + 2 + i)} = x{i}")
    return e.lines


def _screen_body(layout: Layout) -> list[str]:
    n = layout.n_links
    e = _Emitter(layout)
    line, w, o = e.line, e.w, e.o
    line("lim = " + w("limit"))
    line("near = 0.0")
    for j in range(n - 1):
        line(f"near = 1.0 if abs({w('y', j + 1)} - {w('y', j)}) > lim else near")
    for i in range(n):
        line(f"s{i} = {o('sin', i)}")
        line(f"c{i} = {o('cos', i)}")
        line(f"h{i} = {w('half_length', i)}")
    for j in range(n):
        gx = " + ".join(f"{w('geometry', j * n + i)} * c{i}" for i in range(n))
        gy = " + ".join(f"{w('geometry', j * n + i)} * s{i}" for i in range(n))
        line(f"px{j} = {w('y', n)} + ({gx})")
        line(f"py{j} = {w('y', n + 1)} + ({gy})")
    for i in range(n):
        for k in range(i + 2, n):
            line(f"dx = px{k} - px{i}")
            line(f"dy = py{k} - py{i}")
            line(f"reach = (h{i} + h{k}) * (h{i} + h{k}) * {1.0 + _SCREEN_MARGIN!r}")
            line("near = 1.0 if dx * dx + dy * dy <= reach else near")
    line(f"{o('near')} = near")
    return e.lines


def generate_stage_source(layout: Layout) -> str:
    """Source of ``_stage(work, out, t_s)``: one right-hand-side evaluation for a block of lanes.

    Parameters
    ----------
    layout : Layout
        Row assignment (and N, lanes).

    Returns
    -------
    str
        Python source defining ``_stage``, to be appended to the kernel module's text.
    """
    consts = [f"N_LINKS = {layout.n_links}", f"LANES = {layout.lanes}",
              f"WORK_ROWS = {layout.work_rows}", f"OUT_ROWS = {layout.out_rows}"]
    consts += [f"W_{k.upper()} = {v}" for k, v in layout.work.items()]
    consts += [f"O_{k.upper()} = {v}" for k, v in layout.out.items()]
    head = [
        "",
        "",
        f"# ---- generated for N = {layout.n_links}, {layout.lanes} lanes by eelsim._batch_codegen",
        *consts,
        "",
        "",
        "@numba.njit(cache=True, fastmath=_FASTMATH, error_model='numpy', boundscheck=False)",
        "def _stage(work, out, t_s):  # noqa: C901",
        '    """Evaluate the swimmer\'s right-hand side at the stage state of every lane."""',
        f"    for r in range({layout.lanes}):",
    ]
    screen = [
        "",
        "",
        "@numba.njit(cache=True, fastmath=_FASTMATH, error_model='numpy', boundscheck=False)",
        "def _screen(work, out):",
        '    """Flag lanes whose joints are past the limit or whose non-adjacent links are close."""',
        f"    for r in range({layout.lanes}):",
    ]
    return "\n".join(head + _stage_body(layout) + screen + _screen_body(layout)) + "\n"
