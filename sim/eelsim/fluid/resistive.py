"""Resistive-force drag: tangential and normal, linear and quadratic, integrated along each link.

docs/model.md section 2, "Resistive-force drag", has the equations and sources (resistive force
theory: Gray and Hancock, J. Exp. Biol. 32 (1955) 802-814; its quadratic, high-Reynolds form:
Taylor, Proc. R. Soc. Lond. A 214 (1952) 158-183). Each element ds of a link feels a force from its
own velocity relative to the water, with separate coefficients along and across the body:

    df_t = -(k_t1 u + k_t2 |u| u) ds           u = t . w (the same all along a rigid link)
    df_n = -(k_n1 w_n + k_n2 |w_n| w_n) ds     w_n(sigma) = w_n + sigma omega, sigma in [-l, l]

per unit length k_t1 = 1/2 rho pi C_t_lin (a + b)/2 U_0, k_t2 = 1/2 rho pi C_t_quad (a + b)/2,
k_n1 = 1/2 rho C_n_lin 2a U_0, k_n2 = 1/2 rho C_n_quad 2a (the paper's areas, U_0 = 1 m/s as in
:mod:`eelsim.fluid.linear_quadratic`). Integrated exactly over the link:

    f_t = -2l (k_t1 u + k_t2 |u| u)
    f_n = -k_n1 2l w_n - k_n2 I_0,       I_0 = int g(w_n + sigma omega) dsigma,  g(x) = |x| x
    tau = -k_n1 (2 l^3 / 3) omega - k_n2 I_1,   I_1 = int sigma g(w_n + sigma omega) dsigma

With the link-end velocities w_0 = w_n - l omega and w_1 = w_n + l omega:

    I_0 = 2l * 2 w_n / (|w_0| + |w_1|) * (w_0^2 + |w_0| |w_1| + w_1^2) / 3      (0 when both are 0)
    I_1 = (4/3) l^3 |w_n| omega                                  when w_0 w_1 >= 0 (no sign change)
    I_1 = [x |x|^3 / 4 - w_n |x|^3 / 3]_(w_0)^(w_1) / omega^2     when w_0 w_1 < 0 (then omega != 0)

(the first factor of I_0 is the sign of w_n without a sign change along the link and
(|w_1| - |w_0|) / (w_1 - w_0) with one). At omega = 0 the forces are those of the
``linear_quadratic`` law with the same coefficients (tested); the yaw damping is the normal drag's
moment, not the paper's lambda_2, lambda_3 from C_f. Purely resistive at C_a = 0 (every element's
force opposes its velocity: the law only dissipates, tested); with C_a > 0 it carries the lateral
added mass with the reactive terms of :mod:`eelsim.fluid.relative` and the added yaw inertia
mu_n l^2 / 3 of a slender link turning (as :mod:`eelsim.fluid.lighthill`). A candidate model for
fitting.
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
    law_coefficient_columns,
)
from eelsim.fluid.linear_quadratic import LINEAR_DRAG_SCALE_M_S
from eelsim.fluid.relative import RelativeMotionLaw

_NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class ResistiveCoefficients(FluidCoefficients):
    """Coefficients of the resistive-force law, dimensionless (see the module docstring).

    Attributes
    ----------
    C_t_lin, C_t_quad : float
        Tangential drag per unit length: linear (with U_0) and quadratic.
    C_n_lin, C_n_quad : float
        Normal drag per unit length: linear (with U_0) and quadratic.
    C_a : float
        Lateral added mass (0: pure resistive force theory).
    """

    law_name: ClassVar[str] = "resistive"

    C_t_lin: _NonNegative
    C_n_lin: _NonNegative
    C_t_quad: _NonNegative
    C_n_quad: _NonNegative
    C_a: _NonNegative


@dataclass(frozen=True)
class ResistiveLinkFluid(LinkFluid):
    """Per-link coefficients of the law (arrays of shape (..., N)).

    Attributes
    ----------
    k_t1, k_n1 : ndarray
        Linear drag per unit length, kg/(m s).
    k_t2, k_n2 : ndarray
        Quadratic drag per unit length, kg/m^2.
    half_length : ndarray
        l of each link, m.
    """

    k_t1: FloatArray
    k_n1: FloatArray
    k_t2: FloatArray
    k_n2: FloatArray
    half_length: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The rows ``rkt1``, ``rkn1``, ``rkt2``, ``rkn2``."""
        return {"rkt1": self.k_t1, "rkn1": self.k_n1, "rkt2": self.k_t2, "rkn2": self.k_n2}


def quadratic_moments(vn: FloatArray, omega: FloatArray,
                      half_length: FloatArray) -> tuple[FloatArray, FloatArray]:
    """I_0 and I_1 of the module docstring: int g and int sigma g over the link, g(x) = |x| x.

    Parameters
    ----------
    vn, omega, half_length : ndarray
        The centre's normal velocity relative to the water, the rate and l.

    Returns
    -------
    (I_0, I_1) : ndarrays
        m^3/s^2 and m^4/s^2.
    """
    h = half_length
    w0, w1 = vn - h * omega, vn + h * omega
    a0, a1 = np.abs(w0), np.abs(w1)
    ends = a0 + a1
    with np.errstate(divide="ignore", invalid="ignore"):
        i0 = np.where(ends > 0.0, 2.0 * h * (vn + vn) * (w0 * w0 + a0 * a1 + w1 * w1)
                      / (3.0 * ends), 0.0)
        cubes = (w1 * a1**3 - w0 * a0**3) / 4.0 - vn * (a1**3 - a0**3) / 3.0
        i1 = np.where(w0 * w1 < 0.0, cubes / (omega * omega),
                      4.0 / 3.0 * h**3 * np.abs(vn) * omega)
    return i0, i1


class ResistiveLaw(RelativeMotionLaw):
    """Resistive-force drag integrated along each link (see the module docstring)."""

    name: ClassVar[str] = "resistive"
    candidate: ClassVar[bool] = True  # in the model comparison's default grid
    coefficients: ClassVar[type[FluidCoefficients]] = ResistiveCoefficients
    # as the linear_quadratic law's drag bounds; C_a may vanish (pure resistive force theory)
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = (
        (0.0, 0.1), (0.0, 3.0), (0.0, 0.1), (0.0, 3.0), (0.0, 3.0))
    kernel_rows: ClassVar[tuple[str, ...]] = ("rkt1", "rkn1", "rkt2", "rkn2")

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> ResistiveLinkFluid:
        """Per-unit-length drag from the paper's areas; mu_n as the paper's, lambda_1 mu_n l^2 / 3."""
        l_ = np.asarray(half_length_m, dtype=float)
        a = np.asarray(half_axis_vertical_m, dtype=float)
        b = np.asarray(half_axis_horizontal_m, dtype=float)
        rho = np.asarray(water_density_kg_m3, dtype=float)
        t_lin, n_lin, t_quad, n_quad, c_a = law_coefficient_columns(coefficients, 5)
        u0 = LINEAR_DRAG_SCALE_M_S
        along = 0.5 * rho * np.pi * (a + b) / 2.0
        across = 0.5 * rho * 2.0 * a
        mu_n = rho * np.pi * c_a * a**2 * 2.0 * l_
        return ResistiveLinkFluid(
            mu_n=mu_n, lambda_1=mu_n * l_**2 / 3.0,
            k_t1=along * t_lin * u0, k_n1=across * n_lin * u0,
            k_t2=along * t_quad, k_n2=across * n_quad,
            half_length=np.broadcast_to(l_, mu_n.shape).copy())

    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The drag integrated along each link (module docstring)."""
        if not isinstance(fluid, ResistiveLinkFluid):
            raise TypeError(f"the resistive law needs its own link coefficients, got "
                            f"{type(fluid).__name__}")
        f, h = fluid, fluid.half_length
        i0, i1 = quadratic_moments(vn, omega, h)
        return (-2.0 * h * (f.k_t1 * vt + f.k_t2 * np.abs(vt) * vt),
                -f.k_n1 * 2.0 * h * vn - f.k_n2 * i0,
                -f.k_n1 * (2.0 * h**3 / 3.0) * omega - f.k_n2 * i1)

    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The same, negated; the branches of I_0 and I_1 as conditional expressions."""
        line, w = code.line, code.w
        line("fl_w0 = fl_vn - h * om")
        line("fl_w1 = fl_vn + h * om")
        line("fl_a0 = abs(fl_w0)")
        line("fl_a1 = abs(fl_w1)")
        line("fl_ends = fl_a0 + fl_a1")
        line("fl_i0 = (2.0 * h * (fl_vn + fl_vn) * (fl_w0 * fl_w0 + fl_a0 * fl_a1 + fl_w1 * fl_w1)"
             " / (3.0 * fl_ends)) if fl_ends > 0.0 else 0.0")
        line("fl_c0 = fl_a0 * fl_a0 * fl_a0")
        line("fl_c1 = fl_a1 * fl_a1 * fl_a1")
        line("fl_i1 = (((fl_w1 * fl_c1 - fl_w0 * fl_c0) / 4.0 - fl_vn * (fl_c1 - fl_c0) / 3.0)"
             " / (om * om)) if fl_w0 * fl_w1 < 0.0 else 4.0 / 3.0 * h * h * h * abs(fl_vn) * om")
        return (f"2.0 * h * ({w('rkt1', link)} * fl_vt + {w('rkt2', link)} * abs(fl_vt) * fl_vt)",
                f"{w('rkn1', link)} * 2.0 * h * fl_vn + {w('rkn2', link)} * fl_i0",
                f"{w('rkn1', link)} * (2.0 * h * h * h / 3.0) * om + {w('rkn2', link)} * fl_i1")


RESISTIVE: ResistiveLaw = register_fluid_law(
    ResistiveLaw(), "resistive-force drag integrated along each link"
)
"""Registered as ``"resistive"``."""
