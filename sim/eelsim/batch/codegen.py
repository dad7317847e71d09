"""Source generator for the batched kernel's hot loop (one RK4 stage for a block of runs).

Why generate code: the right-hand side of the swimmer for N links is a few hundred lines of
straight-line arithmetic once the loops over links are unrolled. Written that way, inside a single
loop over the runs of a block ("lanes"), every intermediate is a scalar local, LLVM keeps them in
(vector) registers or spills them to the stack, and vectorises the lane loop: each machine
instruction advances 4 runs (AVX2). The same maths written with loops over links and small arrays
goes through memory at every operation and runs about half as fast. The generated text is written
once per (N, lanes, stage, fluid law) to the kernel cache folder (``eelsim.batch.loading``), so
numba's on-disk cache works across processes.

The physics is that of ``eelsim.dynamics`` (compact per-link form, docs/model.md section 2) and
``eelsim.control`` (gait, PD, servo line), with the fluid law's forces written by the law itself
(:meth:`eelsim.fluid.FluidLaw.emit_link_forces`), but the accelerations are not computed by assembling
the dense (N+2) x (N+2) mass matrix M and factoring it (that was ~40 % of a stage and O(N^3)).
They come from an O(N) articulated-body recursion over the chain, which solves the same
Newton-Euler equations M q_ddot = Q stands for (the reference's Q = sum J^T (F - A Jdot q_dot) is
d'Alembert's principle for them):

- link j (centre acceleration a_j, angle theta_j, half-length h, tangent t, normal n):
  A_j a_j = F_j + f_j + g_j and I_j theta_ddot_j = tau_j + h n.f_j - h n.g_j, where
  A_j = m_j I + mu_j n n^T, I_j = J_j + lambda_1,j, F_j the drag and current force, tau_j the
  fluid and joint torques, f_j the force of link j+1 on link j at the front joint point and g_j
  that of link j-1 at the back one;
- rigid links: front point acceleration = back point acceleration + 2 d_j and
  a_j = back + d_j, with d_j = h theta_ddot_j n - h om_j^2 t;
- a free pin passes no torque, so the links beyond joint j answer the acceleration e of the
  joint point with a force given by a 2 x 2 "articulated inertia" P and a bias z
  (force on them = P e - z). The backward sweep (head to tail) builds P and z link by link:
  with w = 2h P' n + h (m + mu) n and D = I + 4 h^2 n.P'n + h^2 (m + mu) (primes: link j+1's),
  theta_ddot_j = (rho_j - w.e) / D with rho_j = tau_j + h n.F_j + 2h n.z' + 4h k (P'n).t,
  k = h om^2, and P = A_j + P' - w w^T / D, z = F_j + z' + k (m t + 2 P't) - w rho_j / D;
- the tail has nothing behind it: P e = z gives its back point's acceleration (a 2 x 2 solve);
  the forward sweep (tail to head) then gives theta_ddot_j, d_j and a_j, and p_ddot is the
  mass-weighted mean of the a_j.

The positive pivots D_j, P_11 and det P play the role of the Cholesky pivots (a pivot <= 0 flags
the run as the reference's LinAlgError does). Link velocities also come from a recursion along
the chain instead of the N x N geometry matrix. The results differ from the reference by
rounding only (about 1e-13 relative on random states; the tests check 1e-11 there and 1e-9 on
whole closed-loop runs). The dense M is still generated, for the condition-number bound that the
kernel evaluates at control updates (``_cond_bound``).

Other deliberate differences, all at rounding level: sums in another order, the gait phases by
angle addition, an own vectorisable sin/cos, fused multiply-adds.

Memory layout: ``work`` and ``out`` are flat float64 arrays holding rows of ``lanes`` values;
``work[row * lanes + r]`` is quantity ``row`` of lane ``r``. Row offsets are literals in the
generated text, so LLVM sees constant distances between accesses and needs no aliasing checks
beyond one between ``work`` and ``out``. The RK4 bookkeeping (accumulator, next stage's input,
the new state) is done at the end of each stage, on rows of ``work``, so the driver in
``eelsim.batch.kernel_template`` never loops over the state itself.
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass

import numpy as np

from eelsim.batch.records import Reason
from eelsim.flags import DIVERGENCE_RATE, ILL_CONDITION_THRESHOLD, Failure
from eelsim.fluid import DEFAULT_FLUID_LAW, FluidLaw, get_fluid_law
from eelsim.fluid.base import KERNEL_INPUTS, KERNEL_OUTPUTS, KERNEL_TEMPORARY_PREFIX
from eelsim.joints import DEFAULT_JOINT_MODEL, JointModel, get_joint_model
from eelsim.joints import base as joint_base

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
# A stage gets sin and cos of its angles by rotating the previous stage's when every live lane's
# offset (at most dt/2 |theta_dot|, 0.05 rad at 10 rad/s) is below this; the series of _rotate
# are exact to an ulp up to here.
_ROTATE_LIMIT = 0.1
# Every stage rotates the previous stage's sin and cos (a chain, a rounding of an ulp or so per
# stage); every this many steps stage 1 computes them in full again, so that the chain's rounding
# stays below 1e-14.
_RESYNC_STEPS = 16
# what the backward sweep hands from one link's lane loop to the next (rows ``carry``): the
# articulated inertia P and bias z at the joint point, the pivot flag and the velocity (relative
# to the water) of the joint point the walk down the chain has reached
_CARRY = ("pxx", "pxy", "pyy", "zx", "zy", "bad", "lvx", "lvy")


def screen_pairs(n_links: int) -> list[tuple[int, int]]:
    """The link pairs the self-collision screen tests: (i, k) with k >= i + 2.

    Parameters
    ----------
    n_links : int

    Returns
    -------
    list of (int, int)
    """
    return [(i, k) for i in range(n_links) for k in range(i + 2, n_links)]


def screen_reach(half_length: np.ndarray) -> np.ndarray:
    """Squared reach of each screened pair, (h_i + h_k)^2 (1 + margin), per run.

    Parameters
    ----------
    half_length : ndarray, shape (R, N)

    Returns
    -------
    ndarray, shape (R, len(screen_pairs(N)))
    """
    pairs = np.array(screen_pairs(half_length.shape[1]), dtype=np.int64).reshape(-1, 2)
    total = half_length[:, pairs[:, 0]] + half_length[:, pairs[:, 1]]
    return total * total * (1.0 + _SCREEN_MARGIN)


@dataclass(frozen=True)
class Layout:
    """Row offsets of the per-lane quantities in the flat ``work`` and ``out`` buffers.

    Attributes
    ----------
    n_links : int
        N.
    lanes : int
        Runs per block.
    law : FluidLaw
        The fluid law whose forces the stage computes.
    joints : JointModel
        The joint model: its law's rows, and which dynamics the stage solves (free joints by
        the articulated-body recursion, kinematic ones by the prescribed-shape system).
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
    law: FluidLaw
    joints: JointModel
    work: dict[str, int]
    work_rows: int
    out: dict[str, int]
    out_rows: int


def make_layout(n_links: int, lanes: int, law: FluidLaw | None = None,
                joints: JointModel | None = None) -> Layout:
    """Assign rows to every per-lane quantity the stage function reads or writes.

    Parameters
    ----------
    n_links : int
        N.
    lanes : int
        Runs per block.
    law : FluidLaw, optional
        The fluid law (default: the default law); its ``kernel_rows`` get one row per link.
    joints : JointModel, optional
        The joint model (default: the default model); its ``kernel_rows`` get one row each.

    Returns
    -------
    Layout
    """
    n = n_links
    law = law if law is not None else get_fluid_law(DEFAULT_FLUID_LAW)
    joints = joints if joints is not None else get_joint_model(DEFAULT_JOINT_MODEL)
    sizes_work = [
        ("y", 2 * n + 4),  # the stage state (theta, p, theta_dot, p_dot)
        ("x", 2 * n + 4),  # the state at the start of the step
        ("acc", 2 * n + 4),  # RK4 accumulator k1 + 2 k2 + 2 k3 (+ k4)
        ("xn", 2 * n + 4),  # the state at the end of the step (valid after stage 4)
        ("gamma", 1),  # held steering offset
        ("geometry", n * n),  # G[j, i] at row j * N + i
        ("gmg", n * n),  # sum_j m_j G[j, i] G[j, k], at row i * N + k (condition bound only)
        ("sm", n),  # sum_j m_j G[j, i] (condition bound only)
        ("mass_sum", 1),
        ("mass", n),
        ("mu", n),  # the fluid law's added mass mu_n
        *((name, n) for name in law.kernel_rows),  # the fluid law's own rows
        ("inertia", n),  # J_i + lambda_1,i
        ("hm", n),  # h_j (m_j + mu_j)
        ("dd0", n),  # J_j + lambda_1,j + h_j^2 (m_j + mu_j): D_j of a link with nothing beyond
        ("four_h2", n),  # (2 h_j)^2
        ("mass_weight", n),  # m_j / sum(m): p is the mass-weighted mean of the link centres
        ("amp", n - 1),  # A_j
        ("amp_omega", n - 1),  # A_j omega
        ("cos_beta", n - 1),  # cos((j - 1) beta)
        ("sin_beta", n - 1),
        ("omega", 1),
        ("cos_whalf", 1),  # cos(omega dt / 2), sin: the gait phase's half step
        ("sin_whalf", 1),
        *((name, 1) for name in joints.kernel_rows),  # the joint model's own rows
        ("limit", 1),  # mechanical joint limit (self-collision check)
        ("clamp", 1),  # joint references are clamped to +-this (JointParameters.command_limit_rad)
        ("half_length", n),
        # the screen's squared reach of each link pair (i, k >= i + 2), in screen_pairs' order
        ("reach", len(screen_pairs(n))),
        # the servo's torque-speed line, against which the driver counts saturated steps
        ("torque_limit", 1),  # stall torque
        ("torque_slope", 1),  # stall torque / no-load speed
        ("vcx", 1),
        ("vcy", 1),
    ]
    sizes_out = [
        ("bad_pivot", 1),  # a pivot of the solve was <= 0 in one of the step's stages
        ("sin", n),  # sin and cos of the last stage's angles (stage 1's for the screen)
        ("cos", n),
        ("near", 1),  # the screen's verdict: joint past its limit or two links close
        ("x_bad", 1),  # x0 is not finite (NaN when any component is NaN or infinite; step 0)
        ("fastest", 1),  # max |rate| of x (x0's, then each new state's from the last stage)
        ("xn_bad", 1),  # the same for the new state
        # what the stage's loops pass on to each other (see _stage_body)
        ("gait_sin", 1),
        ("gait_cos", 1),
        ("ang", n),  # the angles whose sin and cos the rows sin, cos hold (the last stage's)
        ("offset", 1),  # max |angle - ang| of the next stage's input (next step's after stage 4)
        ("head_vx", 1),
        ("head_vy", 1),
        ("kc", n),
        ("torque", n - 1),  # joint j's torque u_j (on link j + 1, minus it on link j), loop 1c
        # the lane's largest max_j |u_j| / stall torque over its steps so far, and its steps
        # with some u_j outside the torque-speed line (loop 6, live lanes only)
        ("torque_ratio", 1),
        ("saturated", 1),
        # (kinematic joints: what the joints must give, from stage 1's solve)
        ("jacc", n - 1),  # kinematic joints: joint j's acceleration phi_ddot_j, loop 1c
        ("tqf", n),  # kinematic joints: the fluid torque on link j, loop 2a
        ("centre", 4),  # kinematic joints: the chain's mean position and acceleration (2s)
        ("fxn", n),  # minus the fluid force on link j, x and y (loop 2ab for its recursion step; 2a for 2s)
        ("fyn", n),
        ("rho0", n),  # tau_j + h n.F_j: the part of rho_j that the recursion does not change
        ("carry", len(_CARRY)),  # the backward sweep's running values from one link's loop to the next
        ("gx", n),  # w / D: theta_ddot_j = rd_j - g_j . e_j in the forward sweep
        ("gy", n),
        ("rd", n),  # rho / D
        ("qdd", n + 2),  # the accelerations (theta_ddot, p_ddot) handed to the RK4 sums
        ("tail_ex", 1),
        ("tail_ey", 1),
        ("cond_bound", 1),  # trace(M) trace(M^-1) >= cond(M); inf when a pivot is <= 0
        ("keep", 1),  # 1.0 for the lanes that commit the step (the last stage's loop 4b)
        # the block's step (the last stage): [0] 1.0 when a live lane's new state failed,
        # [1] 1.0 when some lane does not commit (loop 4b; the driver reads lane 0 and 1)
        ("step_verdict", 1),
        ("live", 1),  # 1.0 for the lanes still running (set by the driver when that changes)
    ]

    def assign(sizes: list[tuple[str, int]]) -> tuple[dict[str, int], int]:
        rows, at = {}, 0
        for name, size in sizes:
            rows[name] = at
            at += size
        return rows, at

    work, work_rows = assign(sizes_work)
    out, out_rows = assign(sizes_out)
    if len(work) != len(sizes_work):
        raise ValueError(f"fluid law {law.name!r} or joint model {joints.name!r}: a kernel row "
                         f"name is taken by the kernel")
    return Layout(n, lanes, law, joints, work, work_rows, out, out_rows)


class _Emitter:
    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.lines: list[str] = []
        self.indent = 0  # extra indentation of the current loop (inside an if)

    def w(self, name: str, index: int = 0) -> str:
        """Expression reading ``work`` row ``name[index]`` of lane r."""
        return f"work[{(self.layout.work[name] + index) * self.layout.lanes} + r]"

    def o(self, name: str, index: int = 0) -> str:
        """Expression reading ``out`` row ``name[index]`` of lane r (``out`` follows ``work``)."""
        row = self.layout.work_rows + self.layout.out[name] + index
        return f"work[{row * self.layout.lanes} + r]"

    def line(self, text: str) -> None:
        self.lines.append(" " * (8 + self.indent) + text)

    def loop(self, title: str, indent: int = 0) -> None:
        """Start a new loop over the lanes (the function body holds several)."""
        self.indent = indent
        pad = " " * (4 + indent)
        self.lines.append(f"{pad}# ---- {title}")
        self.lines.append(f"{pad}for r in range({self.layout.lanes}):")

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


def _rotate(e: _Emitter, d: str, s0: str, c0: str, s: str, c: str) -> None:
    """Emit s = sin(x + d), c = cos(x + d) from s0 = sin x, c0 = cos x, for |d| <= _ROTATE_LIMIT.

    Taylor series of sin d to d^9 and cos d to d^10: the first omitted terms are below 3e-19 and
    3e-21 for |d| <= 0.1, well under an ulp.
    """
    line = e.line
    line(f"z = {d} * {d}")
    poly = f"{_SIN_TAYLOR[3]!r}"
    for coef in reversed(_SIN_TAYLOR[:3]):
        poly = f"{coef!r} + z * ({poly})"
    line(f"sd = {d} + {d} * z * ({poly})")
    poly = f"{_COS_TAYLOR[4]!r}"
    for coef in reversed(_COS_TAYLOR[:4]):
        poly = f"{coef!r} + z * ({poly})"
    line(f"cd = 1.0 + z * ({poly})")
    line(f"sa = {s0}")
    line(f"ca = {c0}")
    line(f"{s} = sa * cd + ca * sd")
    line(f"{c} = ca * cd - sa * sd")


def _head_velocity(e: _Emitter) -> None:
    """Emit the head's velocity relative to the water (rows head_vx, head_vy) from s_i, c_i."""
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o
    line("# the head's velocity relative to the water, v_N = p_dot + sum_i G_Ni om_i n_i with")
    line("# n = (-s, c); the backward sweep walks down from it, v_j = v_(j+1) - h_j om_j n_j")
    line("# - h_(j+1) om_(j+1) n_(j+1) (O(N), instead of the reference's G @ (s om))")
    last = (n - 1) * n
    gs = " + ".join(f"{w('geometry', last + i)} * (s{i} * {w('y', n + 2 + i)})" for i in range(n))
    gc = " + ".join(f"{w('geometry', last + i)} * (c{i} * {w('y', n + 2 + i)})" for i in range(n))
    line(f"{o('head_vx')} = ({w('y', 2 * n + 2)} - ({gs})) - {w('vcx')}")
    line(f"{o('head_vy')} = ({w('y', 2 * n + 3)} + ({gc})) - {w('vcy')}")


def _joint_law(e: _Emitter, plain: bool) -> None:
    """Emit 1c: every joint's law (control.gait_reference, the joint model's drive).

    The torques u of a torque-driven model (the PD law, clipped to the servo line unless
    ``plain``) or the accelerations phi_ddot of a kinematic one (the servo law). At the start of
    the backward sweep's first loop (_backward_sweep): the joints' chains of clamps run beside
    the head's fluid force (as a loop of its own before it, the stage took 1.01-1.02 times as
    long; docs/kernel_history.md, session 13).
    """
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o
    model = e.layout.joints
    target = "jacc" if model.kinematic else "torque"
    title = "joint accelerations" if model.kinematic else "joint torques"
    line(f"# 1c. {title}" + (" (no servo line)" if plain and not model.kinematic else ""))
    line("# the gait phase's sin and cos give each joint's by angle addition; joint jt lies")
    line("# between links jt and jt + 1 and acts +u on link jt + 1, -u on link jt")
    line(f"sp = {o('gait_sin')}")
    line(f"cp = {o('gait_cos')}")
    line("gam = " + w("gamma"))
    line("lim = " + w("clamp"))
    for jt in range(n - 1):
        j = jt + 1
        line(f"cb = {w('cos_beta', jt)}")
        line(f"sb = {w('sin_beta', jt)}")
        line(f"al = min(max({w('amp', jt)} * (sp * cb + cp * sb) + gam, -lim), lim)")
        line(f"ald = {w('amp_omega', jt)} * (cp * cb - sp * sb)")
        line(f"ph = {w('y', j)} - {w('y', jt)}")
        line(f"phd = {w('y', n + 2 + j)} - {w('y', n + 2 + jt)}")
        emit_joint_law(e, plain)
        line(f"{o(target, jt)} = jout")


def emit_joint_law(e: _Emitter, plain: bool) -> None:
    """Emit the joint model's code for one joint, after checking what it assigns.

    The model may assign only ``jout`` and ``jm_`` temporaries
    (:meth:`eelsim.joints.JointModel.emit_joint`), and must assign ``jout``.

    Raises
    ------
    ValueError
        Naming the model and the offending name.
    """
    model = e.layout.joints
    start = len(e.lines)
    model.emit_joint(e, plain)
    assigned = _assigned(e.lines[start:])
    wrong = sorted(name for name in assigned if name != joint_base.KERNEL_OUTPUT
                   and not name.startswith(joint_base.KERNEL_TEMPORARY_PREFIX))
    if wrong or joint_base.KERNEL_OUTPUT not in assigned:
        raise ValueError(
            f"joint model {model.name!r}: its kernel code assigns {wrong} and "
            f"{'sets' if joint_base.KERNEL_OUTPUT in assigned else 'leaves unset'} "
            f"{joint_base.KERNEL_OUTPUT}; it must assign {joint_base.KERNEL_OUTPUT} and otherwise "
            f"only {joint_base.KERNEL_TEMPORARY_PREFIX}... temporaries (reading "
            f"{', '.join(joint_base.KERNEL_INPUTS)})"
        )


def _assigned(lines: list[str]) -> set[str]:
    """The names the statements ``lines`` assign."""
    names: set[str] = set()
    for text in lines:
        for node in ast.walk(ast.parse(text.strip())):
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                names.add(node.id)
    return names


def _read_before_assigned(lines: list[str], prefix: str) -> list[str]:
    """The names starting with ``prefix`` that the statements ``lines`` read before assigning."""
    assigned: set[str] = set()
    early: set[str] = set()
    for text in lines:
        tree = ast.parse(text.strip())
        for node in ast.walk(tree):  # a statement's reads come before its own assignment
            if (isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load)
                    and node.id.startswith(prefix) and node.id not in assigned):
                early.add(node.id)
        assigned |= _assigned([text])
    return sorted(early)


def emit_law_forces(e: _Emitter, link: int, still_water: bool) -> None:
    """Emit the fluid law's code for one link (its batched form), after checking what it assigns.

    The law may assign only its outputs and ``fl_`` temporaries
    (:meth:`eelsim.fluid.FluidLaw.emit_link_forces`), and must assign every output: a law that
    clobbered the sweep's locals would give wrong numbers silently. Nor may it read a
    temporary before assigning it for this link: each link's code runs in a lane loop of its
    own (torque-driven joints, loop 2ab), where another link's value is not there.

    Parameters
    ----------
    e : _Emitter
        Where the lines go (``e.line``).
    link : int
        The link.
    still_water : bool
        The block has no current.

    Raises
    ------
    ValueError
        Naming the law and the offending name.
    """
    law = e.layout.law
    start = len(e.lines)
    law.emit_link_forces(e, link, still_water)
    carried = _read_before_assigned(e.lines[start:], KERNEL_TEMPORARY_PREFIX)
    if carried:
        raise ValueError(
            f"fluid law {law.name!r}: its kernel code for link {link} reads {carried} before "
            "assigning them; each link's code runs in a lane loop of its own, so a temporary "
            "cannot carry from one link to another"
        )
    assigned = _assigned(e.lines[start:])
    wrong = sorted(name for name in assigned if name not in KERNEL_OUTPUTS
                   and not name.startswith(KERNEL_TEMPORARY_PREFIX))
    missing = sorted(set(KERNEL_OUTPUTS) - assigned)
    if wrong or missing:
        raise ValueError(
            f"fluid law {law.name!r}: its kernel code for link {link} assigns {wrong} and leaves "
            f"{missing} unassigned; it must assign {', '.join(KERNEL_OUTPUTS)} and otherwise only "
            f"{KERNEL_TEMPORARY_PREFIX}... temporaries (reading {', '.join(KERNEL_INPUTS)})"
        )


def _backward_sweep(e: _Emitter, plain: bool) -> None:
    """Emit loop 2, the backward sweep (see _stage_body): head to tail, one lane loop per link.

    The first loop starts with the joints' law (1c, _joint_law).
    Torque-driven joints: link j's loop (2ab) walks the velocity down to link j, gives its
    fluid force and torque and then its step of the articulated-body recursion; P, z, the pivot
    flag and the walk's velocity go on to link j - 1's loop through rows ``carry``. The force
    work does not wait on the recursion's chain (P, the pivot, its division, P again), so the
    processor runs it beside the chain of the loop before: as a loop of its own before the
    recursion (session 5's shape) the stage took 1.06 times as long on the AVX-512 VM, whose
    16-lane block is only two vectors, two chains in flight (docs/kernel_history.md, session 13).
    Kinematic joints: one loop (2a) of every link's force and torque, for loop 2s.

    ``plain``: for blocks whose lanes all have no servo line and no current, without those terms
    (the numbers are the same: the general code adds exact zeros and clamps at infinity there).
    """
    n = e.layout.n_links
    line, o = e.line, e.o
    suffix = " (no servo line, no current)" if plain else ""
    if e.layout.joints.kinematic:
        e.loop("2a. the joints' law, link velocities, fluid forces and torques" + suffix, indent=4)
        _joint_law(e, plain)
        _link_forces_comment(e)
        line(f"lvx = {o('head_vx')}")
        line(f"lvy = {o('head_vy')}")
        for j in reversed(range(n)):
            _link_forces(e, j, plain)
        return
    for j in reversed(range(n)):
        law = "the joints' law (1c); " if j == n - 1 else ""
        e.loop(f"2ab. link {j}: {law}its velocity, fluid force and torque, its step of the"
               f" articulated-body recursion{suffix}", indent=4)
        if j == n - 1:
            _joint_law(e, plain)
            _link_forces_comment(e)
            line("# Articulated-body recursion (module docstring): the links beyond joint j push on")
            line("# link j with f = z - P e_j, e_j the acceleration of the joint point (P: 2x2")
            line("# articulated inertia through a free pin, z: bias force).")
            line(f"lvx = {o('head_vx')}")
            line(f"lvy = {o('head_vy')}")
            line("bad = 0.0")
        else:
            for index, name in enumerate(_CARRY):
                line(f"{name} = {o('carry', index)}")
        _link_forces(e, j, plain)
        _recursion_link(e, j)
        if j > 0:
            for index, name in enumerate(_CARRY):
                line(f"{o('carry', index)} = {name}")
    line("# the tail is free (no link behind it): P e = z gives its back point's acceleration.")
    line("# The positive pivots D_j, P_11 and det P play the role of M's Cholesky pivots: one")
    line("# <= 0 is what makes LAPACK refuse M (a NaN pivot is not refused there either)")
    line("det = pxx * pyy - pxy * pxy")
    line("bad = 1.0 if det <= 0.0 else bad")
    line("bad = 1.0 if pxx <= 0.0 else bad")
    line("idet = 1.0 / det")
    line(f"{o('tail_ex')} = (pyy * zx - pxy * zy) * idet")
    line(f"{o('tail_ey')} = (pxx * zy - pxy * zx) * idet")
    line(f"{o('bad_pivot')} = max({o('bad_pivot')}, bad)")


def _link_forces_comment(e: _Emitter) -> None:
    line = e.line
    line("# Each link's velocity relative to the water walks down the chain from the head's:")
    line("# (lvx, lvy) is that of the joint point in front of link j, the link's centre is")
    line("# h om n_j = h om (-s, c) behind it and the next joint point as much again. The fluid")
    line(f"# law ({e.layout.law.name}) gives minus its force (fxn, fyn), minus the normal part fnn")
    line("# and minus its torque tqn; k = h om^2: centripetal acceleration -k t.")


def _link_forces(e: _Emitter, j: int, plain: bool) -> None:
    """Emit link j's velocity (walking (lvx, lvy) on), fluid force and torque (rows fxn, ...)."""
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o
    line(f"s = {o('sin', j)}")
    line(f"c = {o('cos', j)}")
    line(f"om = {w('y', n + 2 + j)}")
    line(f"h = {w('half_length', j)}")
    line("hw = h * om")
    line("hws = hw * s")
    line("hwc = hw * c")
    if j < n - 1:  # the head's row holds its centre's velocity already
        line("lvx = lvx + hws")
        line("lvy = lvy - hwc")
    emit_law_forces(e, j, still_water=plain)
    line(f"{o('fxn', j)} = fxn")
    line(f"{o('fyn', j)} = fyn")
    if e.layout.joints.kinematic:
        line(f"{o('tqf', j)} = -tqn")
    else:
        if 0 < j < n - 1:
            joint = f"({o('torque', j - 1)} - {o('torque', j)})"
        elif j > 0:
            joint = o("torque", j - 1)
        else:
            joint = f"-{o('torque', j)}"
        line(f"tq = {joint} - tqn")
        line("# n . F_j is -fnn")
        line(f"{o('rho0', j)} = tq - h * fnn")
    line(f"{o('kc', j)} = h * (om * om)")
    if j > 0:
        line("lvx = lvx + hws")
        line("lvy = lvy - hwc")


def _recursion_link(e: _Emitter, j: int) -> None:
    """Emit link j's step of the articulated-body recursion (P, z, the pivot flag; rows gx...)."""
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o
    line(f"s = {o('sin', j)}")
    line(f"c = {o('cos', j)}")
    line(f"m = {w('mass', j)}")
    line(f"mu = {w('mu', j)}")
    line(f"hm = {w('hm', j)}")
    line(f"k = {o('kc', j)}")
    if j == n - 1:  # the head: nothing beyond it
        line("wx = -hm * s")
        line("wy = hm * c")
        line(f"dd = {w('dd0', j)}")
        line(f"rho = {o('rho0', j)}")
    else:
        line("anx = c * pxy - s * pxx")  # P n
        line("any = c * pyy - s * pxy")
        line("atx = c * pxx + s * pxy")  # P t
        line("aty = c * pxy + s * pyy")
        line(f"hh = {w('half_length', j)} + {w('half_length', j)}")
        line("wx = hh * anx - hm * s")
        line("wy = hh * any + hm * c")
        line(f"dd = {w('dd0', j)} + {w('four_h2', j)} * (c * any - s * anx)")
        line(f"rho = {o('rho0', j)} + hh * ((c * zy - s * zx) + (k + k) * (c * anx + s * any))")
    line("bad = 1.0 if dd <= 0.0 else bad")
    line("inv = 1.0 / dd")
    line("rd = rho * inv")
    line("gx = wx * inv")
    line("gy = wy * inv")
    line(f"{o('gx', j)} = gx")
    line(f"{o('gy', j)} = gy")
    line(f"{o('rd', j)} = rd")
    if j == n - 1:
        line("pxx = (m + mu * (s * s)) - gx * wx")
        line("pxy = -mu * (s * c) - gx * wy")
        line("pyy = (m + mu * (c * c)) - gy * wy")
        line(f"zx = (m * k * c - {o('fxn', j)}) - wx * rd")
        line(f"zy = (m * k * s - {o('fyn', j)}) - wy * rd")
    else:
        line("pxx = (pxx + (m + mu * (s * s))) - gx * wx")
        line("pxy = (pxy - mu * (s * c)) - gx * wy")
        line("pyy = (pyy + (m + mu * (c * c))) - gy * wy")
        line(f"zx = ((zx - {o('fxn', j)}) + k * (m * c + (atx + atx))) - wx * rd")
        line(f"zy = ((zy - {o('fyn', j)}) + k * (m * s + (aty + aty))) - wy * rd")


def _stage_body(layout: Layout) -> list[str]:
    """One RK4 stage for every lane, as a series of short loops over the lanes (see below).

    Why many loops: as one loop body the stage kept about 45 values alive across the sweeps
    over the links, far more than the 16 vector registers, and the compiler's schedule of the
    long straight-line block spilled and reloaded about 40 % of its instructions (LLVM's, when
    this was measured). Split where few values cross, each body fits, and what crosses goes
    through rows of ``out`` once instead of through many spills. The recursion, whose chain
    (P, the pivot, its division, P again) is long, runs one short loop per link, so that the
    processor overlaps the lane vectors' chains; loops without such a chain gain nothing from
    being cut (docs/kernel_history.md, session 5). Where a loop's chain leaves the processor
    idle, independent work shares the loop: each link's fluid force rides in its recursion
    loop, and the RK4 sums of the rows that do not wait for the accelerations in the forward
    sweep's (session 13).

    1. sin and cos of the link angles (a/b) and of the gait phase, the head's velocity;
    2. the backward sweep (head to tail), one loop per link: its velocity, fluid force and
       torque, its step of the articulated-body recursion; the tail's 2 x 2 solve (kinematic
       joints: one loop of the forces); 1c, every joint's torque or acceleration, at the start
       of its first loop;
    3. the forward sweep (tail to head; kinematic joints: 2s, the 3 x 3 balance), inside
       4. the RK4 sums' loop.
    """
    n = layout.n_links
    e = _Emitter(layout)
    line = e.line
    w, o = e.w, e.o

    line("# ---- 1. angles. sin and cos of the link angles and of the gait phase, either by")
    line("# rotating the previous stage's (rows ang, sin, cos: angle addition with a short series,")
    line(f"# when every live lane (row live) moved less than {_ROTATE_LIMIT} rad since: the")
    line("# first loop below turns ``rotate`` off otherwise) or in full; both leave the new ones in")
    line("# those rows. The gait phase advances by")
    line("# half a step in stages 2 and 4 (``advance``) and stays in stages 1 and 3.")
    line("# The flags choose between whole loops, never inside one: a select per lane on a flag")
    line("# had cost about 10 ns per run and stage.")
    lanes = layout.lanes
    e.lines.append("    if first:")
    e.lines.append(f"        for i in range({(2 * n + 4) * lanes}):")
    e.lines.append(f"            work[{layout.work['acc'] * lanes} + i] = 0.0")
    e.lines.append(f"        for i in range({lanes}):")
    e.lines.append(
        f"            work[{(layout.work_rows + layout.out['bad_pivot']) * lanes} + i] = 0.0"
    )
    # the driver's own loop for this test, a numba function called before each stage, did not
    # vectorise and cost about 4 % of a step (docs/kernel_history.md, session 11); here it does.
    # A NaN offset is not small: that lane's blow-up then goes through the full sin and cos.
    e.lines.append("    if rotate:")
    e.lines.append("        far = 0.0")
    e.loop("1. may the angles rotate? (no live lane moved ROTATE_LIMIT or more)", indent=4)
    line(f"far = far if {o('offset')} < {_ROTATE_LIMIT!r} else "
         f"(1.0 if {o('live')} != 0.0 else far)")
    e.lines.append("        rotate = far == 0.0")
    e.lines.append("    if rotate:")
    e.lines.append("        if advance:")
    e.loop("1a. the gait phase advanced by half a step", indent=8)
    line(f"gs = {o('gait_sin')}")
    line(f"gc = {o('gait_cos')}")
    line(f"{o('gait_sin')} = gs * {w('cos_whalf')} + gc * {w('sin_whalf')}")
    line(f"{o('gait_cos')} = gc * {w('cos_whalf')} - gs * {w('sin_whalf')}")
    e.loop("1a. angles by rotation of the previous ones", indent=4)
    for i in range(n):
        line(f"y = {w('y', i)}")
        line(f"d = y - {o('ang', i)}")
        _rotate(e, "d", o("sin", i), o("cos", i), f"s{i}", f"c{i}")
        line(f"{o('sin', i)} = s{i}")
        line(f"{o('cos', i)} = c{i}")
        line(f"{o('ang', i)} = y")
    _head_velocity(e)
    e.lines.append("    else:")
    e.loop("1b. angles in full", indent=4)
    for i in range(n):
        line(f"y = {w('y', i)}")
        e.sincos("y", f"s{i}", f"c{i}")
        line(f"{o('sin', i)} = s{i}")
        line(f"{o('cos', i)} = c{i}")
        line(f"{o('ang', i)} = y")
    # sin(omega t + j beta) by angle addition: one sin/cos per stage instead of N - 1
    e.sincos(f"{w('omega')} * t_s", "sp", "cp")
    line(f"{o('gait_sin')} = sp")
    line(f"{o('gait_cos')} = cp")
    _head_velocity(e)
    e.indent = 0

    e.lines.append("    if plain:")
    _backward_sweep(e, True)
    e.lines.append("    else:")
    _backward_sweep(e, False)
    e.indent = 0

    _rk4_sums(e)
    e.lines.append("    if first:")
    if layout.joints.kinematic:
        _prescribed_shape_torques(e)
    _torque_use(e)
    return e.lines


def _torque_use(e: _Emitter) -> None:
    """Emit loop 6 (stage 1 only): the step's torques against the servo's torque-speed line.

    Per lane, from stage 1's rows torque (the torques at the step's start x): the largest |u_j|
    as a fraction of the stall torque, and whether some joint is outside the line
    (closed_loop.outside_torque_speed_line's expression, a tolerance of 1e-9 of the stall
    torque). A live lane (row live) folds them into its running figures: row torque_ratio, the
    largest fraction so far, and row saturated, its steps outside the line (a count held as a
    float, exact far beyond any run's steps); the driver copies both out at the block's end. A
    torque that is not finite counts for neither, as in the reference. Done here, the lane loop
    vectorises: as a loop of the driver it had cost about half of the driver (session 9), and
    its fold into the lanes' records, left in the driver then, about 1 % of a step (session 11).
    """
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o
    e.loop("6. the torques against the torque-speed line (stage 1)", indent=4)
    line(f"stall = {w('torque_limit')}")
    line(f"slope = {w('torque_slope')}")
    line("tol = 1e-9 * stall")
    line("big = 0.0")
    line("outside = 0.0")
    for j in range(n - 1):
        line(f"u = {o('torque', j)}")
        line(f"q = ({w('x', n + 3 + j)} - {w('x', n + 2 + j)}) * slope")
        line("upper = min(stall, stall - q)")
        line("lower = max(-stall, -stall - q)")
        line("big = abs(u) if abs(u) > big else big")
        line("outside = 1.0 if u > upper + tol else outside")
        line("outside = 1.0 if u < lower - tol else outside")
    line("frac = big / stall")
    line(f"peak = {o('torque_ratio')}")
    line(f"live = {o('live')}")
    line(f"{o('torque_ratio')} = (frac if frac > peak else peak) if live != 0.0 else peak")
    line(f"{o('saturated')} = {o('saturated')} + (outside if live != 0.0 else 0.0)")


def _forward_sweep(e: _Emitter) -> None:
    """Emit the articulated-body recursion's forward sweep (3, in the RK4 sums' loop)."""
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o
    line("# 3. the forward sweep (in the RK4 sums' loop)")
    line("# tail to head: theta_ddot_j = rd_j - g_j . e_j, link centre acceleration a_j = e + d")
    line("# and the next joint point's e + 2 d, d = h theta_ddot n - k t; p_ddot = sum_j w_j a_j.")
    line("# Written so that the chain from one joint point to the next is two multiply-adds for")
    line("# theta_ddot and one for e (the rest hangs off it): the sweep is a dependent chain,")
    line("# and its latency, not the arithmetic, had set the loop's pace.")
    line(f"ex = {o('tail_ex')}")
    line(f"ey = {o('tail_ey')}")
    line("pdx = 0.0")
    line("pdy = 0.0")
    for j in range(n):
        line(f"s = {o('sin', j)}")
        line(f"c = {o('cos', j)}")
        line(f"k = {o('kc', j)}")
        line(f"h = {w('half_length', j)}")
        line(f"xj = ({o('rd', j)} - {o('gy', j)} * ey) - {o('gx', j)} * ex")
        line(f"{o('qdd', j)} = xj")
        line("hs = h * s")
        line("hc = h * c")
        line("kc = k * c")
        line("ks = k * s")
        line("dx = -(hs * xj + kc)")
        line("dy = hc * xj - ks")
        line(f"pdx = pdx + {w('mass_weight', j)} * (ex + dx)")
        line(f"pdy = pdy + {w('mass_weight', j)} * (ey + dy)")
        if j < n - 1:
            line("ex = (ex - (kc + kc)) - (hs + hs) * xj")
            line("ey = (ey - (ks + ks)) + (hc + hc) * xj")
    line(f"{o('qdd', n)} = pdx")
    line(f"{o('qdd', n + 1)} = pdy")


def _prescribed_shape(e: _Emitter, part: str) -> None:
    """Emit 2s: kinematic joints, the 3 x 3 system of the body's force and moment balance.

    In two parts, both in the RK4 sums' loop (``_rk4_sums``): ``"sums"``, the chain over the
    links and the balance's sums, and ``"solve"``, the 3 x 3 solve and the accelerations.

    docs/model.md section 4 ("Joint models") and ``eelsim.dynamics.prescribed_shape_accelerations``
    solve (T^T M T) s_ddot = T^T (Q0 - M c) with the dense M; here the same balance is summed
    link by link, O(N). With theta_ddot_j = th0 + beta_j (beta_j: the joint accelerations summed
    from the tail), link j's centre accelerates as a_j = p_ddot + th0 g_j + b_j, where g_j is its
    position relative to the centre of mass turned by 90 degrees and b_j its acceleration at
    th0 = 0, p_ddot = 0. Force: sum A_j a_j = sum F_j; moment about the centre of mass:
    sum (I_j theta_ddot_j + g_j . A_j a_j) = sum (tau_j + g_j . F_j) (A_j = m_j I + mu_j n n^T,
    I_j = J_j + lambda_1,j; the joint torques cancel). The chain gives positions P_j and
    accelerations C_j relative to the tail's centre in one pass, and the sums are corrected to
    the centre of mass (Pm, Cm: their mass-weighted means) at the end: g_j = R (P_j - Pm),
    b_j = C_j - Cm. The 3 x 3 matrix is factored L D L^T; a pivot <= 0 flags the run as the
    reference's Cholesky does.
    """
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o
    if part == "solve":
        _shape_solve(e)
        return
    line("# 2s. prescribed shape: the body's force and moment balance (3 x 3), in the RK4 sums' loop")
    for name in ("px", "py", "ex", "ey", "beta", "axx", "axy", "ayy", "agx", "agy", "gag",
                 "itot", "rsx", "rsy", "ge", "tb", "pmx", "pmy", "cmx", "cmy"):
        line(f"{name} = 0.0")
    for j in range(n):
        _shape_chain_link(e, j)
        line(f"m = {w('mass', j)}")
        line(f"mus = {w('mu', j)} * s")
        line(f"muc = {w('mu', j)} * c")
        line("a11 = m + mus * s")
        line("a12 = -(mus * c)")
        line("a22 = m + muc * c")
        line("gx = -py")
        line("gy = px")
        line("agxj = a11 * gx + a12 * gy")
        line("agyj = a12 * gx + a22 * gy")
        line(f"rx = -{o('fxn', j)} - (a11 * cx + a12 * cy)")
        line(f"ry = -{o('fyn', j)} - (a12 * cx + a22 * cy)")
        line(f"inert = {w('inertia', j)}")
        line("axx = axx + a11")
        line("axy = axy + a12")
        line("ayy = ayy + a22")
        line("agx = agx + agxj")
        line("agy = agy + agyj")
        line("gag = gag + (gx * agxj + gy * agyj)")
        line("itot = itot + inert")
        line("rsx = rsx + rx")
        line("rsy = rsy + ry")
        line("ge = ge + (gx * rx + gy * ry)")
        line(f"tb = tb + ({o('tqf', j)} - inert * beta)")
        line(f"wj = {w('mass_weight', j)}")
        line("pmx = pmx + wj * px")
        line("pmy = pmy + wj * py")
        line("cmx = cmx + wj * cx")
        line("cmy = cmy + wj * cy")


def _shape_solve(e: _Emitter) -> None:
    """Emit the second part of 2s (see _prescribed_shape): the solve and the accelerations."""
    n = e.layout.n_links
    line, o = e.line, e.o
    line("# to the centre of mass: Gm = R Pm, and A Gm, A Cm with A = sum A_j")
    line("gmx = -pmy")
    line("gmy = pmx")
    line("agmx = axx * gmx + axy * gmy")
    line("agmy = axy * gmx + ayy * gmy")
    line("acmx = axx * cmx + axy * cmy")
    line("acmy = axy * cmx + ayy * cmy")
    line("spx = agx - agmx")
    line("spy = agy - agmy")
    line("saa = ((itot + gag) - 2.0 * (gmx * agx + gmy * agy)) + (gmx * agmx + gmy * agmy)")
    line("bpx = rsx + acmx")
    line("bpy = rsy + acmy")
    line("ba = (((tb + ge) + (agx * cmx + agy * cmy)) - (gmx * rsx + gmy * rsy))"
         " - (gmx * acmx + gmy * acmy)")
    line("# L D L^T of [[axx, axy, spx], [axy, ayy, spy], [spx, spy, saa]]")
    line("bad = 1.0 if axx <= 0.0 else 0.0")
    line("i1 = 1.0 / axx")
    line("l21 = axy * i1")
    line("l31 = spx * i1")
    line("d2 = ayy - l21 * axy")
    line("bad = 1.0 if d2 <= 0.0 else bad")
    line("i2 = 1.0 / d2")
    line("l32 = (spy - l31 * axy) * i2")
    line("d3 = (saa - l31 * spx) - l32 * l32 * d2")
    line("bad = 1.0 if d3 <= 0.0 else bad")
    line("y2 = bpy - l21 * bpx")
    line("th0 = ((ba - l31 * bpx) - l32 * y2) / d3")
    line("pdy = y2 * i2 - l32 * th0")
    line("pdx = (bpx * i1 - l21 * pdy) - l31 * th0")
    line(f"{o('bad_pivot')} = max({o('bad_pivot')}, bad)")
    line("beta = 0.0")
    for j in range(n):
        if j > 0:
            line(f"beta = beta + {o('jacc', j - 1)}")
        line(f"{o('qdd', j)} = th0 + beta")
    line(f"{o('qdd', n)} = pdx")
    line(f"{o('qdd', n + 1)} = pdy")
    for index, name in enumerate(("pmx", "pmy", "cmx", "cmy")):
        line(f"{o('centre', index)} = {name}")


def _shape_chain_link(e: _Emitter, j: int) -> None:
    """Emit one link of the kinematic chain from the tail (loops 2s and 5).

    Sets ``s``, ``c``, ``k`` (theta_dot^2), ``h``; ``px``, ``py``: the link centre relative to the
    tail's; ``beta``: the joint accelerations summed from the tail; ``cx``, ``cy``: the centre's
    acceleration at th0 = 0, p_ddot = 0 (back point + d, d = h beta n - k t); ``ex``, ``ey``: the
    next joint point's.
    """
    line, w, o = e.line, e.w, e.o
    line(f"s = {o('sin', j)}")
    line(f"c = {o('cos', j)}")
    line(f"k = {o('kc', j)}")
    line(f"h = {w('half_length', j)}")
    line("htx = h * c")
    line("hty = h * s")
    if j > 0:
        line(f"beta = beta + {o('jacc', j - 1)}")
        line("px = px + (phtx + htx)")
        line("py = py + (phty + hty)")
    line("phtx = htx")
    line("phty = hty")
    line("hb = h * beta")
    line("dx = -(hb * s) - k * c")
    line("dy = hb * c - k * s")
    line("cx = ex + dx")
    line("cy = ey + dy")
    line("ex = cx + dx")
    line("ey = cy + dy")


def _prescribed_shape_torques(e: _Emitter) -> None:
    """Emit loop 5 (stage 1 only): the torques the kinematic joints must give.

    Newton-Euler from the tail: f_j, the force of link j + 1 on link j at joint j, is
    f_(j-1) + A_j a_j - F_j, and joint j's torque u_j = u_(j-1) + tau_j + h_j t_j x (f_j +
    f_(j-1)) - I_j theta_ddot_j (f_(-1) = 0, u_(-1) = 0); the reference gets the same from the
    theta rows of the dense system.
    """
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o
    e.loop("5. the torques the joints must give (stage 1)", indent=4)
    line(f"th0 = {o('qdd', 0)}")
    line(f"pdx = {o('qdd', n)}")
    line(f"pdy = {o('qdd', n + 1)}")
    line(f"gmx = -{o('centre', 1)}")
    line(f"gmy = {o('centre', 0)}")
    line(f"cmx = {o('centre', 2)}")
    line(f"cmy = {o('centre', 3)}")
    for name in ("px", "py", "ex", "ey", "beta", "fbx", "fby", "uu"):
        line(f"{name} = 0.0")
    for j in range(n - 1):
        _shape_chain_link(e, j)
        line("ajx = (pdx + th0 * (-py - gmx)) + (cx - cmx)")
        line("ajy = (pdy + th0 * (px - gmy)) + (cy - cmy)")
        line(f"m = {w('mass', j)}")
        line(f"munv = {w('mu', j)} * (c * ajy - s * ajx)")
        line(f"ffx = fbx + ((m * ajx - munv * s) + {o('fxn', j)})")
        line(f"ffy = fby + ((m * ajy + munv * c) + {o('fyn', j)})")
        line(f"uu = ((uu + {o('tqf', j)}) + h * (c * (ffy + fby) - s * (ffx + fbx)))"
             f" - {w('inertia', j)} * {o('qdd', j)}")
        line(f"{o('torque', j)} = uu")
        line("fbx = ffx")
        line("fby = ffy")


def _rk4_sums(e: _Emitter) -> None:
    """Emit loops 4a/4b: the accelerations (3 or 2s) and the RK4 sums (see _stage_body).

    The accelerations are computed in the sums' loop, the forward sweep after the sums of the
    rows whose derivative is a velocity (the angles, the position), the 3 x 3 balance's sums
    before them and its solve after them: the sweep and the solve are chains that leave the
    processor idle, and those sums fill the wait (as loops of their own the stage took 1.02-1.06
    times as long; docs/kernel_history.md, session 13). The sums' order per row is unchanged:
    the numbers are the same.
    """
    n = e.layout.n_links
    line, w, o = e.line, e.w, e.o

    def accelerations(i: int) -> None:
        if e.layout.joints.kinematic and i in (0, n + 2):
            _prescribed_shape(e, "sums" if i == 0 else "solve")
        elif i == n + 2:  # the first row whose derivative is an acceleration
            _forward_sweep(e)
    line("# RK4 bookkeeping of integrate.rk4_step, fused so that the state rows are touched once:")
    line("# stages 1-3: acc = k1, acc + 2 k2, acc + 2 k3 and the next stage's input y = x + a k;")
    line("# stage 4: the new state xn = x + dt/6 (acc + k4) only")
    deriv = [w("y", n + 2 + i) for i in range(n + 2)] + [o("qdd", i) for i in range(n + 2)]
    e.lines.append("    if last:")
    e.lines.append("        failing = 0.0")
    e.lines.append("        unkept = 0.0")
    e.loop("4b. the new state, its finiteness and which lanes commit it", indent=4)
    line("# v - v is 0 for finite v and NaN for NaN or +-inf: one NaN test per lane for all rows;")
    line("# fastest: the divergence test of the next step's x (the new state, if the lane goes on).")
    line("# Reduced row by row, so that no row's value waits in a register (or on the stack)")
    for i, d in enumerate(deriv):
        accelerations(i)
        line(f"v = {w('x', i)} + sixth * ({w('acc', i)} + wk * {d})")
        line(f"{w('xn', i)} = v")
        if i < n:
            offset = f"abs(v - {o('ang', i)})"
            line(f"offset = {offset}" if i == 0 else f"offset = max(offset, {offset})")
        line("nan = v - v" if i == 0 else "nan = nan + (v - v)")
        if i >= n + 2:
            line("fastest = abs(v)" if i == n + 2 else "fastest = max(fastest, abs(v))")
    line(f"{o('offset')} = offset")
    line(f"{o('xn_bad')} = nan")
    line(f"{o('fastest')} = fastest")
    line("# row keep: a live lane commits a finite new state whose solve had positive pivots")
    line("# (the driver's loop for this, over its bool array, had compiled to scalar code)")
    line(f"lv = {o('live')}")
    line(f"kp = (1.0 if nan == nan else 0.0) if {o('bad_pivot')} == 0.0 else 0.0")
    line("kp = kp if lv != 0.0 else 0.0")
    line(f"{o('keep')} = kp")
    line("failing = failing if kp != 0.0 else (1.0 if lv != 0.0 else failing)")
    line("unkept = unkept if kp != 0.0 else 1.0")
    verdict = (e.layout.work_rows + e.layout.out["step_verdict"]) * e.layout.lanes
    e.lines.append(f"        work[{verdict}] = failing")
    e.lines.append(f"        work[{verdict + 1}] = unkept")
    e.lines.append("    else:")
    e.loop("4a. RK4 accumulator and the next stage's input", indent=4)
    for i, d in enumerate(deriv):
        accelerations(i)
        line(f"d = {d}")
        line(f"{w('acc', i)} = {w('acc', i)} + wk * d")
        line(f"{w('y', i)} = {w('x', i)} + a * d")
    offsets = ", ".join(f"abs({w('y', i)} - {o('ang', i)})" for i in range(n))
    line(f"{o('offset')} = max({offsets})")


def _screen_body(layout: Layout) -> list[str]:
    n = layout.n_links
    e = _Emitter(layout)
    line, w, o = e.line, e.w, e.o
    line("lim = " + w("limit"))
    line("near = 0.0")
    for j in range(n - 1):
        line(f"near = 1.0 if abs({w('x', j + 1)} - {w('x', j)}) > lim else near")
    for i in range(n):
        line(f"s{i} = {o('sin', i)}")
        line(f"c{i} = {o('cos', i)}")
        line(f"h{i} = {w('half_length', i)}")
    # link centres relative to link 0's, along the chain (only differences matter here; they
    # differ from eelsim.flags' positions by rounding, far inside the screen's margin)
    line("px0 = 0.0")
    line("py0 = 0.0")
    for j in range(1, n):
        line(f"px{j} = px{j - 1} + (h{j - 1} * c{j - 1} + h{j} * c{j})")
        line(f"py{j} = py{j - 1} + (h{j - 1} * s{j - 1} + h{j} * s{j})")
    for pair, (i, k) in enumerate(screen_pairs(n)):
        line(f"dx = px{k} - px{i}")
        line(f"dy = py{k} - py{i}")
        line(f"near = 1.0 if dx * dx + dy * dy <= {w('reach', pair)} else near")
    line(f"{o('near')} = near")
    return e.lines


def _cond_body(layout: Layout) -> list[str]:
    """trace(M) trace(M^-1), an upper bound of cond(M) (within (N+2)^2 of it), at the state x.

    M is assembled densely (docs/model.md section 2, in the rotated form
    M_tt[i,k] = cos(th_i - th_k) sum_j m_j G_ji G_jk + sum_j mu_j b_ji b_jk, b_ji = G_ji
    cos(th_j - th_i)) and factored M = L D L^T; trace(M^-1) = sum_i |row i of L^-1|^2 / D_i.
    It runs only at control updates, where the reference computes np.linalg.cond(M): when the
    bound is far below the threshold the run is fine, otherwise the driver computes the exact
    value. sin and cos of the angles come from stage 1 (the out rows).
    """
    n = layout.n_links
    e = _Emitter(layout)
    line, w, o = e.line, e.w, e.o
    nq = n + 2
    for i in range(n):
        line(f"s{i} = {o('sin', i)}")
        line(f"c{i} = {o('cos', i)}")
        line(f"mu{i} = {w('mu', i)}")
    for i in range(n):
        for k in range(i + 1, n):
            line(f"cd{i}_{k} = c{i} * c{k} + s{i} * s{k}")

    def cd(a: int, b: int) -> str:
        return "1.0" if a == b else f"cd{min(a, b)}_{max(a, b)}"

    for j in range(n):
        for i in range(n):
            g = w("geometry", j * n + i)
            line(f"b{j}_{i} = {g}" if i == j else f"b{j}_{i} = {g} * {cd(j, i)}")
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
    line("pd = 1.0")  # stays 1 while every pivot is > 0 (a NaN pivot is not)
    for k in range(nq):
        d = " - ".join([f"a{k}_{k}"] + [f"l{k}_{j} * e{k}_{j}" for j in range(k)])
        line(f"dk = {d}")
        line("pd = pd if dk > 0.0 else 0.0")
        line(f"inv{k} = 1.0 / dk")
        for i in range(k + 1, nq):
            v = " - ".join([f"a{k}_{i}"] + [f"l{i}_{j} * e{k}_{j}" for j in range(k)])
            line(f"e{i}_{k} = {v}")
            line(f"l{i}_{k} = e{i}_{k} * inv{k}")
    line("# L^-1 (unit lower triangular) by columns; accumulate trace(M^-1)")
    line(f"tr_inv = {' + '.join(f'inv{i}' for i in range(nq))}")
    for col in range(nq - 1):
        for i in range(col + 1, nq):
            terms = [f"l{i}_{col}"] + [f"l{i}_{j} * y{j}_{col}" for j in range(col + 1, i)]
            line(f"y{i}_{col} = -({' + '.join(terms)})")
            line(f"tr_inv = tr_inv + y{i}_{col} * y{i}_{col} * inv{i}")
    line(f"tr = {' + '.join(f'a{i}_{i}' for i in range(nq))}")
    line(f"{o('cond_bound')} = tr * tr_inv if pd == 1.0 else np.inf")
    return e.lines


DRIVER_WORK_ROWS = ("y", "x", "acc", "xn", "gamma", "geometry", "mass", "mu")
"""The rows of ``work`` the driver (``kernel_template``) reads by name: all before the fluid law's and
the joint model's own rows (:func:`make_layout`), so the same for every law and model."""


def _constants(layout: Layout) -> dict[str, object]:
    """The generated module's constants (thresholds, codes, N, lanes, rows) by name, in order."""
    consts: dict[str, object] = {"ILL_CONDITION_THRESHOLD": ILL_CONDITION_THRESHOLD,
                                 "DIVERGENCE_RATE": float(DIVERGENCE_RATE)}
    consts |= {f"FAIL_{code.name}": int(code) for code in Failure}
    consts |= {f"REASON_{code.name}": int(code) for code in Reason}
    consts |= {"FLUID_LAW": layout.law.name, "JOINT_MODEL": layout.joints.name,
               "N_LINKS": layout.n_links, "LANES": layout.lanes, "ROTATE_LIMIT": _ROTATE_LIMIT,
               "RESYNC_STEPS": _RESYNC_STEPS, "WORK_ROWS": layout.work_rows,
               "OUT_ROWS": layout.out_rows}
    consts |= {f"W_{k.upper()}": v for k, v in layout.work.items()}
    consts |= {f"O_{k.upper()}": v for k, v in layout.out.items()}
    return consts


# the constants that move with the fluid law or the joint model (the driver gets none of them)
_VARIANT_CONSTANTS = ("FLUID_LAW", "JOINT_MODEL", "WORK_ROWS")


def _assignments(consts: dict[str, object]) -> list[str]:
    """One Python assignment a constant."""
    return [f"{name} = {value!r}" for name, value in consts.items()]


def driver_constants(n_links: int, lanes: int) -> str:
    """The constants of the driver module for N links and ``lanes``: those not of a law or model.

    The driver module (``eelsim.batch.loading.driver_module``) is the template with these and no
    generated functions: it serves every fluid law and joint model (what differs arrives at run
    time). Which constants those are: thresholds, codes, N, lanes, every row of ``out``, and the
    rows of ``work`` in :data:`DRIVER_WORK_ROWS`.

    Parameters
    ----------
    n_links, lanes : int
        N and the runs per block.

    Returns
    -------
    str
        Python text, one assignment a line.
    """
    keep = {f"W_{row.upper()}" for row in DRIVER_WORK_ROWS}
    lines = _assignments({name: value for name, value in _constants(make_layout(n_links, lanes))
                          .items() if name not in _VARIANT_CONSTANTS
                          and (not name.startswith("W_") or name in keep)})
    head = f"# ---- the driver's constants for N = {n_links}, {lanes} lanes (eelsim.batch.codegen)"
    return "\n".join(["", "", head, *lines, ""])


def generate_stage_source(layout: Layout) -> str:
    """Source of the generated functions and row constants of the kernel module.

    ``work`` is one buffer: the rows of ``work`` and after them those of ``out`` (so that LLVM
    sees one base and constant distances, and needs no runtime alias checks between the two).
    ``_stage(work, t_s, a, wk, first, last, sixth, rotate, advance, plain)``: one RK4 stage for
    every lane: the right-hand side f(t_s, y), then acc = f (``first``) or acc + wk f and
    y = x + a f, or for the ``last`` stage xn = x + sixth (acc + wk f) with its finiteness and
    fastest rate; ``rotate``: sin and cos of the angles by rotation of the previous stage's
    (rows ang, sin, cos) and of the gait phase advanced by dt/2 (``advance``) or not, else both
    in full at t_s; ``plain``: the backward sweep without servo line and current.
    ``_screen(work)``: the self-collision screen of x. ``_cond_bound(work)``: the
    condition-number bound at x.

    Parameters
    ----------
    layout : Layout
        Row assignment (and N, lanes).

    Returns
    -------
    str
        Python source defining ``_stage``, to be appended to the kernel module's text.
    """
    consts = _assignments(_constants(layout))
    head = [
        "",
        "",
        f"# ---- generated for N = {layout.n_links}, {layout.lanes} lanes, fluid law "
        f"{layout.law.name!r}, joint model {layout.joints.name!r} by eelsim.batch.codegen",
        *consts,
        "",
        "",
        "@numba.njit(cache=True, fastmath=_FASTMATH, error_model='numpy', boundscheck=False)",
        "def _stage(work, t_s, a, wk, first, last, sixth, rotate, advance, plain):  # noqa: C901",
        '    """One RK4 stage for every lane: the right-hand side at y, then the RK4 sums."""',
    ]
    screen = [
        "",
        "",
        "@numba.njit(cache=True, fastmath=_FASTMATH, error_model='numpy', boundscheck=False)",
        "def _screen(work):",
        '    """Flag lanes whose joints are past the limit or whose non-adjacent links are close."""',
        f"    for r in range({layout.lanes}):",
    ]
    cond = [
        "",
        "",
        "@numba.njit(cache=True, fastmath=_FASTMATH, error_model='numpy', boundscheck=False)",
        "def _cond_bound(work):",
        '    """Upper bound of the mass matrix condition number at x, for every lane."""',
        f"    for r in range({layout.lanes}):",
    ]
    body = head + _stage_body(layout) + screen + _screen_body(layout)
    body += cond + _cond_body(layout)
    return "\n".join(body) + "\n"
