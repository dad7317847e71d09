"""The paper's law made Galilean-consistent (docs/model.md section 2, "Galilean-consistent laws").

The same coefficients e = (C_f, C_d, C_a, C_m), the same per-link values (c_t, c_n, mu_n,
lambda_1..3 of :mod:`eelsim.fluid.morison`) and the same drag and yaw damping, with the paper's
added-mass current term replaced by the reactive terms of the link's fluid impulse relative to the
water (:mod:`eelsim.fluid.relative`):

    f_i = -c_t (v_t + |v_t| v_t) t - c_n (v_n + |v_n| v_n) n + mu_n theta_dot (w_t n + w_n t)
    tau_i = -lambda_2 theta_dot - lambda_3 |theta_dot| theta_dot - mu_n w_t w_n

(v_t = w_t, v_n = w_n: the velocity relative to the water). Swimming in a steady uniform current
is then swimming in still water plus the drift v_c t, to rounding (tested); with the Morison law
it is not (3.9 cm after 20 s in 0.03 m/s, issue 19). A candidate model for fitting.
"""

from __future__ import annotations

from typing import ClassVar

from numpy.typing import ArrayLike

from eelsim.fluid import register_fluid_law  # defined before this module is imported
from eelsim.fluid.base import FloatArray, FluidCoefficients, KernelCode, LinkFluid
from eelsim.fluid.morison import (
    MORISON,
    MorisonLinkFluid,
    PaperCoefficients,
    _morison,
    emit_paper_drag,
    paper_drag,
)
from eelsim.fluid.relative import RelativeMotionLaw


class GalileanCoefficients(PaperCoefficients):
    """e = (C_f, C_d, C_a, C_m) of the Galilean law: the paper's, with the same meaning."""

    law_name: ClassVar[str] = "galilean"


class GalileanLaw(RelativeMotionLaw):
    """The paper's drag and added mass, Galilean-consistent (see the module docstring)."""

    name: ClassVar[str] = "galilean"
    candidate: ClassVar[bool] = True  # in the model comparison's default grid
    coefficients: ClassVar[type[FluidCoefficients]] = GalileanCoefficients
    default_bounds = MORISON.default_bounds
    kernel_rows = MORISON.kernel_rows

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> MorisonLinkFluid:
        """The Morison law's per-link values (:meth:`eelsim.fluid.morison.MorisonLaw.link_coefficients`)."""
        return MORISON.link_coefficients(half_length_m, half_axis_vertical_m,
                                         half_axis_horizontal_m, coefficients,
                                         water_density_kg_m3)

    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The paper's drag and yaw damping (:func:`eelsim.fluid.morison.paper_drag`)."""
        return paper_drag(_morison(fluid), vt, vn, omega)

    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The same, negated, as expressions."""
        return emit_paper_drag(code, link)


GALILEAN: GalileanLaw = register_fluid_law(
    GalileanLaw(),
    "the paper's coefficients, forces from the motion relative to the water (Galilean-consistent)",
)
"""The Galilean-consistent paper law, registered as ``"galilean"``."""
