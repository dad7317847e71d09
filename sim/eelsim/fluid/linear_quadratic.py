"""Separate linear and quadratic drag coefficients, Galilean-consistent (docs/model.md section 2).

The paper's drag c (v + |v| v) uses one coefficient c (kg/m) for both terms, so its linear term
c v has the units of a force only with an implied velocity scale of 1 m/s (kg/m x m/s x m/s); its
yaw damping lambda_2 likewise. Here that scale is the explicit constant
``LINEAR_DRAG_SCALE_M_S`` = U_0 = 1 m/s and each term has its own coefficient:

    f_t = -(c_t1 v_t + c_t2 |v_t| v_t)      c_t1 = c_t(C_f_lin) U_0 (kg/s), c_t2 = c_t(C_f_quad) (kg/m)
    f_n = -(c_n1 v_n + c_n2 |v_n| v_n)      c_n1 = c_n(C_d_lin) U_0 (kg/s), c_n2 = c_n(C_d_quad) (kg/m)
    tau = -lambda_2 theta_dot - lambda_3 |theta_dot| theta_dot
          lambda_2 = lambda_2(C_f_lin) U_0 (N m s), lambda_3 = lambda_3(C_f_quad) (kg m^2)

with c_t(.), c_n(.), lambda_2(.), lambda_3(.) the paper's formulas (:mod:`eelsim.fluid.morison`),
mu_n and lambda_1 the paper's from C_a and C_m, and the reactive added-mass terms of the relative
motion (:mod:`eelsim.fluid.relative`). With C_f_lin = C_f_quad and C_d_lin = C_d_quad it is the
``galilean`` law (tested). A candidate model for fitting.
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

LINEAR_DRAG_SCALE_M_S = 1.0
"""U_0: the velocity scale of the linear drag terms (the paper's, implied; docs/model.md section 2)."""


class LinearQuadraticCoefficients(FluidCoefficients):
    """Linear and quadratic drag coefficients, added mass and added inertia, dimensionless.

    Attributes
    ----------
    C_f_lin, C_f_quad : float
        Tangential drag: linear (with U_0) and quadratic.
    C_d_lin, C_d_quad : float
        Normal drag: linear (with U_0) and quadratic.
    C_a, C_m : float
        Added mass (normal direction) and added yaw inertia, as the paper's.
    """

    law_name: ClassVar[str] = "linear_quadratic"

    C_f_lin: _NonNegative
    C_d_lin: _NonNegative
    C_f_quad: _NonNegative
    C_d_quad: _NonNegative
    C_a: _NonNegative
    C_m: _NonNegative


@dataclass(frozen=True)
class LinearQuadraticLinkFluid(LinkFluid):
    """Per-link coefficients of the law (arrays of shape (..., N)).

    Attributes
    ----------
    c_t1, c_n1 : ndarray
        Linear drag, kg/s.
    c_t2, c_n2 : ndarray
        Quadratic drag, kg/m.
    lambda_2 : ndarray
        Linear yaw damping, N m s.
    lambda_3 : ndarray
        Quadratic yaw damping, kg m^2.
    """

    c_t1: FloatArray
    c_n1: FloatArray
    c_t2: FloatArray
    c_n2: FloatArray
    lambda_2: FloatArray
    lambda_3: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The rows ``ct1``, ``cn1``, ``ct2``, ``cn2``, ``lambda2``, ``lambda3``."""
        return {"ct1": self.c_t1, "cn1": self.c_n1, "ct2": self.c_t2, "cn2": self.c_n2,
                "lambda2": self.lambda_2, "lambda3": self.lambda_3}


class LinearQuadraticLaw(RelativeMotionLaw):
    """Separate linear and quadratic drag (see the module docstring)."""

    name: ClassVar[str] = "linear_quadratic"
    candidate: ClassVar[bool] = True  # in the model comparison's default grid
    coefficients: ClassVar[type[FluidCoefficients]] = LinearQuadraticCoefficients
    # the paper's upper bounds for each drag term; either term may vanish: the quadratic one at
    # low speed (at 0.1 m/s the linear terms give about ten times the force) and the linear one
    # in the high-Reynolds-number limit, where a body's drag is quadratic (docs/model.md
    # section 6: a lower bound above 0 forced a linear drag ten times a foil's on every fit)
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = (
        (0.0, 0.1), (0.0, 3.0), (0.0, 0.1), (0.0, 3.0), (0.0, 3.0), (0.0, 1.0))
    kernel_rows: ClassVar[tuple[str, ...]] = ("ct1", "cn1", "ct2", "cn2", "lambda2", "lambda3")

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> LinearQuadraticLinkFluid:
        """The paper's formulas once with the linear, once with the quadratic coefficients."""
        f_lin, d_lin, f_quad, d_quad, c_a, c_m = law_coefficient_columns(coefficients, 6)
        geometry = (half_length_m, half_axis_vertical_m, half_axis_horizontal_m)
        lin = MORISON.link_coefficients(*geometry, np.stack([f_lin, d_lin, c_a, c_m], axis=-1),
                                        water_density_kg_m3)
        quad = MORISON.link_coefficients(*geometry, np.stack([f_quad, d_quad, c_a, c_m], axis=-1),
                                         water_density_kg_m3)
        u0 = LINEAR_DRAG_SCALE_M_S
        return LinearQuadraticLinkFluid(
            mu_n=lin.mu_n, lambda_1=lin.lambda_1, c_t1=lin.c_t * u0, c_n1=lin.c_n * u0,
            c_t2=quad.c_t, c_n2=quad.c_n, lambda_2=lin.lambda_2 * u0, lambda_3=quad.lambda_3)

    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Linear plus quadratic drag and yaw damping, each with its own coefficient."""
        if not isinstance(fluid, LinearQuadraticLinkFluid):
            raise TypeError(f"the linear_quadratic law needs its own link coefficients, got "
                            f"{type(fluid).__name__}")
        f = fluid
        return (-(f.c_t1 * vt + f.c_t2 * np.abs(vt) * vt), -(f.c_n1 * vn + f.c_n2 * np.abs(vn) * vn),
                -f.lambda_2 * omega - f.lambda_3 * np.abs(omega) * omega)

    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The same, negated, as expressions."""
        w = code.w
        return (f"{w('ct1', link)} * fl_vt + {w('ct2', link)} * abs(fl_vt) * fl_vt",
                f"{w('cn1', link)} * fl_vn + {w('cn2', link)} * abs(fl_vn) * fl_vn",
                f"{w('lambda2', link)} * om + {w('lambda3', link)} * abs(om) * om")


LINEAR_QUADRATIC: LinearQuadraticLaw = register_fluid_law(
    LinearQuadraticLaw(), "separate linear and quadratic drag, Galilean-consistent"
)
"""Registered as ``"linear_quadratic"``."""
