"""Lighthill's large-amplitude elongated-body (reactive) law, discretised over the links.

docs/model.md section 2, "Lighthill's elongated-body law", writes the equations out with their
sources: Lighthill, *Large-amplitude elongated-body theory of fish locomotion*, Proc. R. Soc.
Lond. B 179 (1971) 125-138, as used for eel-like robots by Boyer, Porez, Leroyer and Visonneau,
*Fast dynamics of an eel-like robot: comparisons with Navier-Stokes simulations*, IEEE T-RO 24
(2008) 1274-1288. In short, with s the arc length from the tail (s = 0) to the head, m(s) the
lateral added mass per unit length, u = t . w and w_n = n . w the tangential and normal velocity
of the section relative to the water, the water's reactive force on the body is

    F = -d/dt int_0^L m w_n n ds - [ m u w_n n - 1/2 m w_n^2 t ]_(s = 0)

(the first term is the rate of change of the lateral flow's momentum, the second the momentum that
the tail sheds into the wake) and its moment is the same with r x in front of each term.

Discretised over the N rigid links (constant m = mu_n / 2l on each), the first term is each
link's -dP_i/dt, P_i = mu_n w_n n: the mass matrix's added mass mu_n n n^T and the reactive terms
of :mod:`eelsim.fluid.relative` (with its Munk moment -mu_n w_t w_n, the part of
-d/dt (r x P) that comes from the link moving), plus the lateral flow's angular impulse of a link
turning about its centre, int sigma^2 m dsigma omega = mu_n l^2 / 3 omega, which is this law's
added yaw inertia lambda_1. The second term acts on the tail link (index 0) at its tip
r_tip = r_0 - l_0 t_0, whose velocity relative to the water has w_n,tip = w_n - l_0 omega_0 and
u_tip = w_t:

    F_tail = -m_0 u_tip w_n,tip n_0 + 1/2 m_0 w_n,tip^2 t_0,      m_0 = mu_n,0 / (2 l_0)
    tau_tail = (-l_0 t_0) x F_tail = l_0 m_0 u_tip w_n,tip           (about the tail link's centre)

The law's power on the tail tip is F_tail . v_tip = -1/2 m_0 u_tip w_n,tip^2: energy shed into the
wake while the body moves head first (u > 0). The reactive force alone has no viscous drag; as
Boyer et al. do, the law adds a resistive part, here the paper's drag and yaw damping from C_f and
C_d (:func:`eelsim.fluid.morison.paper_drag`). Galilean-consistent: every term is in the motion
relative to the water. A candidate model for fitting.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from pydantic import Field

from eelsim.fluid import register_fluid_law  # defined before this module is imported
from eelsim.fluid.base import (
    FloatArray,
    FluidCoefficients,
    KernelCode,
    LinkFluid,
    LinkForces,
    LinkMotion,
    law_coefficient_columns,
)
from eelsim.fluid.morison import MORISON, MorisonLinkFluid, emit_paper_drag, paper_drag
from eelsim.fluid.relative import RelativeMotionLaw

_NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class LighthillCoefficients(FluidCoefficients):
    """Coefficients of Lighthill's law, dimensionless.

    Attributes
    ----------
    C_f, C_d : float
        The resistive part: the paper's tangential and normal drag (and its yaw damping from C_f).
    C_a : float
        Lateral added mass per unit length m = rho pi C_a a^2 (C_a = 1: the potential-flow
        value of an elliptic section moving across its a axis); it sets the reactive force, the added yaw inertia and the tail
        term.
    """

    law_name: ClassVar[str] = "lighthill"

    C_f: _NonNegative
    C_d: _NonNegative
    C_a: _NonNegative


@dataclass(frozen=True)
class LighthillLinkFluid(MorisonLinkFluid):
    """Per-link coefficients of Lighthill's law (arrays of shape (..., N)).

    The paper's drag values (:class:`eelsim.fluid.morison.MorisonLinkFluid`) and:

    Attributes
    ----------
    half_length : ndarray
        l of each link, m (the tail term acts at the tail tip, l_0 behind the centre).
    """

    half_length: FloatArray  # not a kernel row: the kernel has the half-lengths already


def tail_shedding(mu_n_tail: FloatArray, half_length_tail: FloatArray, vt: FloatArray,
                  vn: FloatArray, omega: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Lighthill's tail-tip term on the tail link: force along t and n, torque about its centre.

    Parameters
    ----------
    mu_n_tail, half_length_tail : ndarray
        The tail link's added mass mu_n (kg) and half-length l (m).
    vt, vn, omega : ndarray
        Its centre's tangential and normal velocity relative to the water and its rate.

    Returns
    -------
    (f_t, f_n, torque) : ndarrays
        N, N and N m (module docstring).
    """
    m = mu_n_tail / (2.0 * half_length_tail)
    wn_tip = vn - half_length_tail * omega
    f_n = -m * vt * wn_tip
    return 0.5 * m * wn_tip * wn_tip, f_n, -half_length_tail * f_n


class LighthillLaw(RelativeMotionLaw):
    """Lighthill's elongated-body law with the paper's drag (see the module docstring)."""

    name: ClassVar[str] = "lighthill"
    candidate: ClassVar[bool] = True  # in the model comparison's default grid
    coefficients: ClassVar[type[FluidCoefficients]] = LighthillCoefficients
    # the paper's drag bounds; C_a from none to three times the potential-flow value
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = (
        (0.0005, 0.1), (0.05, 3.0), (0.0, 3.0))
    kernel_rows: ClassVar[tuple[str, ...]] = MORISON.kernel_rows

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> LighthillLinkFluid:
        """The paper's drag values; added yaw inertia mu_n l^2 / 3 (module docstring)."""
        c_f, c_d, c_a = law_coefficient_columns(coefficients, 3)
        l_ = np.asarray(half_length_m, dtype=float)
        paper = MORISON.link_coefficients(l_, half_axis_vertical_m, half_axis_horizontal_m,
                                          np.stack([c_f, c_d, c_a, np.zeros_like(c_a)], axis=-1),
                                          water_density_kg_m3)
        return LighthillLinkFluid(
            mu_n=paper.mu_n, lambda_1=paper.mu_n * l_**2 / 3.0, c_t=paper.c_t, c_n=paper.c_n,
            lambda_2=paper.lambda_2, lambda_3=paper.lambda_3,
            half_length=np.broadcast_to(l_, paper.mu_n.shape).copy())

    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The paper's drag and yaw damping (the resistive part)."""
        return paper_drag(_lighthill(fluid), vt, vn, omega)

    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The same, negated, as expressions."""
        return emit_paper_drag(code, link)

    def forces(self, fluid: LinkFluid, motion: LinkMotion, current_m_s: FloatArray) -> LinkForces:
        """Drag and reactive terms on every link, and the tail-tip term on link 0."""
        f = _lighthill(fluid)
        body = super().forces(fluid, motion, current_m_s)
        s, c, om = motion.sin[0], motion.cos[0], motion.omega[0]
        vt = c * motion.rel_vx[0] + s * motion.rel_vy[0]
        vn = -s * motion.rel_vx[0] + c * motion.rel_vy[0]
        ft, fn, torque = tail_shedding(f.mu_n[0], f.half_length[0], vt, vn, om)
        tail_x = np.zeros_like(body.fx)
        tail_y = np.zeros_like(body.fy)
        tail_x[0], tail_y[0] = ft * c - fn * s, ft * s + fn * c
        tail_torque = np.zeros_like(body.torque)
        tail_torque[0] = torque
        return LinkForces(fx=body.fx + tail_x, fy=body.fy + tail_y,
                          torque=body.torque + tail_torque,
                          parts={**body.parts, "tail": (tail_x, tail_y)})

    def emit_link_forces(self, code: KernelCode, link: int, still_water: bool) -> None:
        """The relative-motion form, then on the tail link the tail-tip term (negated)."""
        super().emit_link_forces(code, link, still_water)
        if link != 0:
            return
        line = code.line
        line(f"fl_m = {code.w('mu', link)} * 0.5 / h")
        line("fl_wtip = fl_vn - h * om")
        line("fl_tt = -0.5 * fl_m * fl_wtip * fl_wtip")  # minus the tangential force
        line("fl_tn = fl_m * fl_vt * fl_wtip")  # minus the normal force
        line("fnn = fnn + fl_tn")
        line("fxn = fxn + fl_tt * c - fl_tn * s")
        line("fyn = fyn + fl_tt * s + fl_tn * c")
        line("tqn = tqn - h * fl_tn")


def _lighthill(fluid: LinkFluid) -> LighthillLinkFluid:
    if not isinstance(fluid, LighthillLinkFluid):
        raise TypeError(f"the lighthill law needs its own link coefficients, got "
                        f"{type(fluid).__name__}")
    return fluid


LIGHTHILL: LighthillLaw = register_fluid_law(
    LighthillLaw(), "Lighthill's elongated-body reactive law with the paper's drag"
)
"""Registered as ``"lighthill"``."""
