"""A plant law with Reynolds-number-dependent drag (docs/model.md section 2): for test tanks.

Not a candidate model for fitting: it exists so that virtual tanks can hold water whose drag has
another form than any fitted law's (issue 19, test plants). Each link is a cylinder of length 2 l
with an elliptic section (half-axes a, b); nu = ``KINEMATIC_VISCOSITY_M2_S`` (water at about
20 C), w = (w_t, w_n) the centre's velocity relative to the water:

- tangential: laminar skin friction (Blasius), C_f = C_f_lam / sqrt(Re_l), Re_l = |w_t| 2 l / nu,
  on the wetted area S_t = pi (a + b) 2 l:
  f_t = -1/2 rho S_t C_f |w_t| w_t = -k_t sqrt(|w_t|) w_t,  k_t = 1/2 rho S_t C_f_lam sqrt(nu / 2l);
- normal: cross-flow drag C_d = C_d_inf + C_d_visc / sqrt(Re_a), Re_a = |w_n| 2 a / nu, on the
  frontal area S_n = 2 a 2 l:
  f_n = -(k_n2 |w_n| + k_n15 sqrt(|w_n|)) w_n,  k_n2 = 1/2 rho S_n C_d_inf,
  k_n15 = 1/2 rho S_n C_d_visc sqrt(nu / 2a);
- yaw damping: the same normal drag integrated along the link turning about its centre
  (normal velocity s theta_dot at station s):
  tau = -(lambda_q |theta_dot| + lambda_v sqrt(|theta_dot|)) theta_dot,
  lambda_q = rho a C_d_inf l^4 / 2 (kg m^2), lambda_v = (4/7) rho a C_d_visc sqrt(nu / 2a) l^3.5;
- added mass mu_n and added inertia lambda_1 from C_a and C_m as the paper's, and the reactive
  terms of the relative motion (:mod:`eelsim.fluid.relative`): Galilean-consistent.

The tangential force grows as |w|^1.5 and the normal one between |w|^1.5 and w^2: neither the
paper's linear-plus-quadratic law nor the ``linear_quadratic`` law contains it. Typical values:
C_f_lam = 1.328 (Blasius), C_d_inf = 1.0 and C_d_visc = 5 (a circular cylinder's C_d from about
2.6 at Re = 10 to 1.16 at Re = 1000).
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
from eelsim.fluid.morison import MORISON
from eelsim.fluid.relative import RelativeMotionLaw

_NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]

KINEMATIC_VISCOSITY_M2_S = 1.0e-6
"""nu of the water (fresh water at about 20 C)."""


class ReynoldsCoefficients(FluidCoefficients):
    """Coefficients of the Reynolds-number law, dimensionless (see the module docstring).

    Attributes
    ----------
    C_f_lam : float
        Laminar skin friction: C_f = C_f_lam / sqrt(Re_l) (Blasius: 1.328).
    C_d_inf : float
        Cross-flow drag at high Reynolds number.
    C_d_visc : float
        Cross-flow drag's viscous part: C_d = C_d_inf + C_d_visc / sqrt(Re_a).
    C_a, C_m : float
        Added mass and added yaw inertia, as the paper's.
    """

    law_name: ClassVar[str] = "reynolds"

    C_f_lam: _NonNegative
    C_d_inf: _NonNegative
    C_d_visc: _NonNegative
    C_a: _NonNegative
    C_m: _NonNegative


@dataclass(frozen=True)
class ReynoldsLinkFluid(LinkFluid):
    """Per-link coefficients of the Reynolds-number law (arrays of shape (..., N)).

    Attributes
    ----------
    k_t : ndarray
        Tangential skin friction, kg/m (m/s)^-1/2.
    k_n2, k_n15 : ndarray
        Normal drag: quadratic (kg/m) and the |w|^1.5 part (kg/m (m/s)^-1/2).
    lambda_q, lambda_v : ndarray
        Yaw damping: quadratic (kg m^2) and the |theta_dot|^1.5 part (kg m^2 s^-1/2).
    """

    k_t: FloatArray
    k_n2: FloatArray
    k_n15: FloatArray
    lambda_q: FloatArray
    lambda_v: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The rows ``kt``, ``kn2``, ``kn15``, ``lamq``, ``lamv``."""
        return {"kt": self.k_t, "kn2": self.k_n2, "kn15": self.k_n15, "lamq": self.lambda_q,
                "lamv": self.lambda_v}


class ReynoldsLaw(RelativeMotionLaw):
    """Reynolds-number-dependent drag, for test plants (see the module docstring)."""

    name: ClassVar[str] = "reynolds"
    coefficients: ClassVar[type[FluidCoefficients]] = ReynoldsCoefficients
    candidate: ClassVar[bool] = False
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = (
        (0.0, 5.0), (0.05, 3.0), (0.0, 20.0), (0.05, 3.0), (0.0, 1.0))
    kernel_rows: ClassVar[tuple[str, ...]] = ("kt", "kn2", "kn15", "lamq", "lamv")

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> ReynoldsLinkFluid:
        """See the module docstring."""
        l_ = np.asarray(half_length_m, dtype=float)
        a = np.asarray(half_axis_vertical_m, dtype=float)
        b = np.asarray(half_axis_horizontal_m, dtype=float)
        rho = np.asarray(water_density_kg_m3, dtype=float)
        c_f, c_inf, c_visc, c_a, c_m = law_coefficient_columns(coefficients, 5)
        nu = KINEMATIC_VISCOSITY_M2_S
        paper = MORISON.link_coefficients(l_, a, b, np.stack([c_f, c_inf, c_a, c_m], axis=-1),
                                          rho)
        frontal = 0.5 * rho * (2.0 * a) * (2.0 * l_)
        viscous = np.sqrt(nu / (2.0 * a))
        return ReynoldsLinkFluid(
            mu_n=paper.mu_n,
            lambda_1=paper.lambda_1,
            k_t=0.5 * rho * np.pi * (a + b) * 2.0 * l_ * c_f * np.sqrt(nu / (2.0 * l_)),
            k_n2=frontal * c_inf,
            k_n15=frontal * c_visc * viscous,
            lambda_q=rho * a * c_inf * l_**4 / 2.0,
            lambda_v=4.0 / 7.0 * rho * a * c_visc * viscous * l_**3.5,
        )

    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Skin friction, cross-flow drag and yaw damping (module docstring)."""
        if not isinstance(fluid, ReynoldsLinkFluid):
            raise TypeError(f"the reynolds law needs its own link coefficients, got "
                            f"{type(fluid).__name__}")
        f = fluid
        return (-f.k_t * np.sqrt(np.abs(vt)) * vt,
                -(f.k_n2 * np.abs(vn) + f.k_n15 * np.sqrt(np.abs(vn))) * vn,
                -(f.lambda_q * np.abs(omega) + f.lambda_v * np.sqrt(np.abs(omega))) * omega)

    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The same, negated (``_vsqrt``: the kernel's square root that vectorises)."""
        w = code.w
        return (f"{w('kt', link)} * _vsqrt(abs(fl_vt)) * fl_vt",
                f"({w('kn2', link)} * abs(fl_vn) + {w('kn15', link)} * _vsqrt(abs(fl_vn))) * fl_vn",
                f"({w('lamq', link)} * abs(om) + {w('lamv', link)} * _vsqrt(abs(om))) * om")


REYNOLDS: ReynoldsLaw = register_fluid_law(
    ReynoldsLaw(), "drag with Reynolds-number-dependent coefficients (test plants only)"
)
"""Registered as ``"reynolds"`` (a plant law: not fitted by default)."""
