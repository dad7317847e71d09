"""The paper's fluid law: Morison drag, normal added mass, added yaw inertia (docs/model.md section 2).

For link i with tangent t_i, normal n_i, centre velocity relative to the water w_i (v_t = t_i . w_i,
v_n = n_i . w_i), rate theta_dot_i and the uniform current v_c:

    drag        f_drag,i = -c_t (v_t + |v_t| v_t) t_i - c_n (v_n + |v_n| v_n) n_i
    current     f_cur,i  = -mu_n theta_dot_i (t_i . v_c) n_i      (added mass, paper eq. 6)
    torque      tau_i    = -lambda_2 theta_dot_i - lambda_3 |theta_dot_i| theta_dot_i
    added mass  mu_n n_i n_i^T and added yaw inertia lambda_1 (in the mass matrix)

with, from e = (C_f, C_d, C_a, C_m), the water density rho and the link's half-length l and
half-axes a (vertical) and b:

    c_t = 0.5 rho pi C_f (a + b)/2 * 2l          c_n = 0.5 rho C_d 2a * 2l
    mu_n = rho pi C_a a^2 * 2l                   lambda_1 = rho pi C_m (a^2 - b^2)^2 l^3 / 12
    lambda_2 = rho pi C_f (a + b) l^3 / 6        lambda_3 = rho pi C_f (a + b) l^4 / 8

The linear and quadratic drag share c_t and c_n, as the paper writes them.
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
    FluidLaw,
    KernelCode,
    LinkFluid,
    LinkForces,
    LinkMotion,
    law_coefficient_columns,
)

_NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class PaperCoefficients(FluidCoefficients):
    """The paper's hydrodynamic parameters e = (C_f, C_d, C_a, C_m), dimensionless.

    The fields of the laws that take the paper's coefficients (Morison, and the Galilean law of
    :mod:`eelsim.fluid.galilean`); each law's record subclasses this and names its law.

    Attributes
    ----------
    C_f : float
        Tangential (longitudinal) drag coefficient.
    C_d : float
        Normal (transverse) drag coefficient.
    C_a : float
        Added mass coefficient (normal direction).
    C_m : float
        Added yaw inertia coefficient.
    """

    C_f: _NonNegative
    C_d: _NonNegative
    C_a: _NonNegative
    C_m: _NonNegative


class HydroCoefficients(PaperCoefficients):
    """Hydrodynamic parameters e = (C_f, C_d, C_a, C_m) of the Morison law (the paper's)."""

    law_name: ClassVar[str] = "morison"


@dataclass(frozen=True)
class MorisonLinkFluid(LinkFluid):
    """Per-link coefficients of the Morison law (arrays of shape (..., N)).

    Attributes
    ----------
    c_t, c_n : ndarray
        Tangential and normal drag coefficients, kg/s (linear) and kg/m (quadratic).
    lambda_2, lambda_3 : ndarray
        Linear and quadratic fluid yaw damping.
    """

    c_t: FloatArray
    c_n: FloatArray
    lambda_2: FloatArray
    lambda_3: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The rows ``ct``, ``cn``, ``lambda2``, ``lambda3`` of the batched kernel."""
        return {"ct": self.c_t, "cn": self.c_n, "lambda2": self.lambda_2,
                "lambda3": self.lambda_3}


class MorisonLaw(FluidLaw):
    """The paper's law (see the module docstring)."""

    name: ClassVar[str] = "morison"
    candidate: ClassVar[bool] = True  # in the model comparison's default grid
    coefficients: ClassVar[type[FluidCoefficients]] = HydroCoefficients
    # Table 3 of the paper: C_f 0.008-0.009, C_d 0.78-0.98, C_a 0.62-1.17, C_m 0.001-0.007;
    # slender-body estimates (Kelasidi) put C_f near 0.03 and C_a, C_m near 1. Wide enough for
    # both; C_a and C_m from 0, a body that carries no water along being a model the data may
    # choose (docs/model.md section 6).
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = (
        (0.0005, 0.1), (0.05, 3.0), (0.0, 3.0), (0.0, 1.0))
    kernel_rows: ClassVar[tuple[str, ...]] = ("ct", "cn", "lambda2", "lambda3")

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> MorisonLinkFluid:
        """See :meth:`FluidLaw.link_coefficients` and the module docstring."""
        l_ = np.asarray(half_length_m, dtype=float)
        a = np.asarray(half_axis_vertical_m, dtype=float)
        b = np.asarray(half_axis_horizontal_m, dtype=float)
        rho = np.asarray(water_density_kg_m3, dtype=float)
        c_f, c_d, c_a, c_m = law_coefficient_columns(coefficients, 4)
        return MorisonLinkFluid(
            c_t=0.5 * rho * np.pi * c_f * (a + b) / 2.0 * 2.0 * l_,
            c_n=0.5 * rho * c_d * 2.0 * a * 2.0 * l_,
            mu_n=rho * np.pi * c_a * a**2 * 2.0 * l_,
            lambda_1=rho * np.pi * c_m * (a**2 - b**2) ** 2 * l_**3 / 12.0,
            lambda_2=rho * np.pi * c_f * (a + b) * l_**3 / 6.0,
            lambda_3=rho * np.pi * c_f * (a + b) * l_**4 / 8.0,
        )

    def forces(self, fluid: LinkFluid, motion: LinkMotion, current_m_s: FloatArray) -> LinkForces:
        """Drag, the added-mass current term and the yaw damping (module docstring)."""
        f = _morison(fluid)
        s, c, w = motion.sin, motion.cos, motion.omega
        vt = c * motion.rel_vx + s * motion.rel_vy
        vn = -s * motion.rel_vx + c * motion.rel_vy
        ft, fn, torque = paper_drag(f, vt, vn, w)
        drag_x = ft * c - fn * s
        drag_y = ft * s + fn * c
        cur_n = -f.mu_n * w * (c * current_m_s[0] + s * current_m_s[1])
        cur_x, cur_y = -cur_n * s, cur_n * c
        return LinkForces(
            fx=drag_x + cur_x,
            fy=drag_y + cur_y,
            torque=torque,
            parts={"drag": (drag_x, drag_y), "current": (cur_x, cur_y)},
        )

    def emit_link_forces(self, code: KernelCode, link: int, still_water: bool) -> None:
        """The same in the link's frame, negated so that no instruction is spent on signs."""
        line, w = code.line, code.w
        tangential, normal, torque = emit_paper_drag(code, link)
        line("fl_vt = c * lvx + s * lvy")
        line("fl_vn = c * lvy - s * lvx")
        line(f"fl_ftn = {tangential}")
        current = "" if still_water else f" + {w('mu', link)} * om * (c * {w('vcx')} + s * {w('vcy')})"
        line(f"fnn = {normal}{current}")
        line("fxn = fl_ftn * c - fnn * s")
        line("fyn = fl_ftn * s + fnn * c")
        line(f"tqn = {torque}")


def paper_drag(
    f: MorisonLinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The paper's linear plus quadratic drag and yaw damping (its eqs. 9-11), on each link.

    Parameters
    ----------
    f : MorisonLinkFluid
        The per-link values.
    vt, vn : ndarray
        Tangential and normal velocity of each link's centre relative to the water, m/s.
    omega : ndarray
        Link rates theta_dot, rad/s.

    Returns
    -------
    (f_t, f_n, torque) : ndarrays
        Force along t and n, N, and torque, N m, of the water on each link.
    """
    return (-f.c_t * (vt + np.abs(vt) * vt), -f.c_n * (vn + np.abs(vn) * vn),
            -f.lambda_2 * omega - f.lambda_3 * np.abs(omega) * omega)


def emit_paper_drag(code: KernelCode, link: int) -> tuple[str, str, str]:
    """:func:`paper_drag` negated, as the batched kernel's expressions (``fl_vt``, ``fl_vn``, ``om``)."""
    w = code.w
    return (f"{w('ct', link)} * (fl_vt + abs(fl_vt) * fl_vt)",
            f"{w('cn', link)} * (fl_vn + abs(fl_vn) * fl_vn)",
            f"{w('lambda2', link)} * om + {w('lambda3', link)} * abs(om) * om")


def _morison(fluid: LinkFluid) -> MorisonLinkFluid:
    if not isinstance(fluid, MorisonLinkFluid):
        raise TypeError(f"the Morison law needs its own link coefficients, got {type(fluid).__name__}")
    return fluid


MORISON: MorisonLaw = register_fluid_law(
    MorisonLaw(), "the paper's: Morison drag (C_f, C_d) and added mass (C_a, C_m)"
)
"""The Morison law, registered as ``"morison"`` (the default)."""
