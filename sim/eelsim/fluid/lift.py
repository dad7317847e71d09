"""A lift force on each link that any fluid law can carry: the ``<law>_lift`` variants.

docs/model.md section 2, "Lift", has the equation and its source. A link moving through the water
with velocity w = w_t t + w_n n relative to it, at the angle of attack alpha (tan alpha =
w_n / w_t), feels besides its law's forces a quasi-steady lift perpendicular to w,

    L = 1/2 rho S C_L sin(2 alpha) |w|^2 = rho S C_L w_t w_n,       S = 2a 2l (its side area)
    f_lift = k_L w_t w_n (w_n t - w_t n) / |w|,                     k_L = rho S C_L

(the flat plate's sin 2 alpha lift, Dickinson, Lehmann and Sane, Science 284 (1999) 1954-1960;
Wang, Birch and Dickinson, J. Exp. Biol. 207 (2004) 449-460: C_L = 1.2 sin 2 alpha). Its normal
part opposes w_n, as a plate's pressure does; it acts at the link's centre (no torque) and is
perpendicular to w, so it does no work. ``with_lift(law)`` makes the variant
``<law>_lift``: the law's coefficients then ``C_L``, its forces plus f_lift in both forms. Every law
registered before the variants has one (:mod:`eelsim.fluid`); they are not fitting candidates by
default (docs/model.md: each would double the comparison's grid), but any is fitted when named
(``eelbot report --laws galilean_lift``) and they make test plants whose water no candidate holds.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from pydantic import Field

from eelsim.fluid.base import (
    FloatArray,
    FluidLaw,
    KernelCode,
    LinkFluid,
    LinkForces,
    LinkMotion,
    declared_candidate,
)

_NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]

LIFT_BOUNDS = (0.0, 3.0)
"""Search bounds of C_L: none to about the thin-airfoil slope's pi (flat plate 1.2)."""


@dataclass(frozen=True)
class LiftLinkFluid(LinkFluid):
    """Per-link coefficients of a lift variant: its base law's and the lift's.

    Attributes
    ----------
    base : LinkFluid
        The base law's per-link coefficients (mu_n and lambda_1 are the base's).
    k_lift : ndarray
        k_L = rho 2a 2l C_L, kg/m, shape (..., N).
    """

    base: LinkFluid
    k_lift: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The base law's rows and ``klift``."""
        return {**self.base.kernel_values(), "klift": self.k_lift}


def lift_force(k_lift: FloatArray, vt: FloatArray,
               vn: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The lift along t and n on each link (module docstring).

    Parameters
    ----------
    k_lift : ndarray
        k_L per link, kg/m.
    vt, vn : ndarray
        Tangential and normal velocity of the centre relative to the water, m/s.

    Returns
    -------
    (f_t, f_n) : ndarrays
        N; zero where the link is at rest in the water.
    """
    speed = np.sqrt(vt * vt + vn * vn)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(speed > 0.0, k_lift * vt * vn / speed, 0.0)
    return q * vn, -q * vt


class LiftLaw(FluidLaw):
    """A base law's forces plus the lift (see the module docstring); built by :func:`with_lift`."""

    base: FluidLaw

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> LiftLinkFluid:
        """The base law's values from all but the last coefficient; k_L from the last, C_L."""
        c = np.asarray(coefficients, dtype=float)
        k = len(self.coefficient_names)
        if c.shape[-1:] != (k,):
            raise ValueError(f"expected {k} coefficients on the last axis, got shape {c.shape}")
        base = self.base.link_coefficients(half_length_m, half_axis_vertical_m,
                                           half_axis_horizontal_m, c[..., :-1],
                                           water_density_kg_m3)
        l_ = np.asarray(half_length_m, dtype=float)
        a = np.asarray(half_axis_vertical_m, dtype=float)
        rho = np.asarray(water_density_kg_m3, dtype=float)
        k_lift = rho * (2.0 * a) * (2.0 * l_) * c[..., -1]
        return LiftLinkFluid(mu_n=base.mu_n, lambda_1=base.lambda_1, base=base,
                             k_lift=np.broadcast_to(k_lift, base.mu_n.shape).copy())

    def forces(self, fluid: LinkFluid, motion: LinkMotion, current_m_s: FloatArray) -> LinkForces:
        """The base law's forces plus the lift (part ``"lift"``)."""
        if not isinstance(fluid, LiftLinkFluid):
            raise TypeError(f"the {self.name} law needs its own link coefficients, got "
                            f"{type(fluid).__name__}")
        body = self.base.forces(fluid.base, motion, current_m_s)
        s, c = motion.sin, motion.cos
        vt = c * motion.rel_vx + s * motion.rel_vy
        vn = -s * motion.rel_vx + c * motion.rel_vy
        ft, fn = lift_force(fluid.k_lift, vt, vn)
        lift = (ft * c - fn * s, ft * s + fn * c)
        return LinkForces(fx=body.fx + lift[0], fy=body.fy + lift[1], torque=body.torque,
                          parts={**body.parts, "lift": lift})

    def emit_link_forces(self, code: KernelCode, link: int, still_water: bool) -> None:
        """The base law's code, then the lift added to its (negated) outputs."""
        self.base.emit_link_forces(code, link, still_water)
        line = code.line
        line("fl_lift_vt = c * lvx + s * lvy")
        line("fl_lift_vn = c * lvy - s * lvx")
        line("fl_lift_speed = _vsqrt(fl_lift_vt * fl_lift_vt + fl_lift_vn * fl_lift_vn)")
        line(f"fl_lift_q = ({code.w('klift', link)} * fl_lift_vt * fl_lift_vn / fl_lift_speed)"
             " if fl_lift_speed > 0.0 else 0.0")
        line("fl_lift_t = fl_lift_q * fl_lift_vn")  # the lift along t; along n it is -q w_t
        line("fnn = fnn + fl_lift_q * fl_lift_vt")
        line("fxn = fxn - fl_lift_t * c - fl_lift_q * fl_lift_vt * s")
        line("fyn = fyn - fl_lift_t * s + fl_lift_q * fl_lift_vt * c")


def with_lift(base: FluidLaw) -> LiftLaw:
    """The variant ``<base>_lift`` of ``base``: its coefficients then ``C_L``, its forces plus lift.

    Parameters
    ----------
    base : FluidLaw

    Returns
    -------
    LiftLaw
        Not registered (:func:`eelsim.fluid.register_fluid_law` does that); a candidate for the
        model comparison when its base law is one (the comparison tries every candidate with and
        without lift, docs/estimation.md).
    """
    name = f"{base.name}_lift"
    record = f"{base.coefficients.__name__}Lift"
    namespace: dict[str, Any] = {
        "__annotations__": {"law_name": ClassVar[str], "C_L": _NonNegative},
        "law_name": name,
        "__module__": __name__,
        "__qualname__": record,
        "__doc__": f"The coefficients of the ``{base.name}`` law and the lift's C_L.",
    }
    coefficients = type(record, (base.coefficients,), namespace)
    setattr(sys.modules[__name__], record, coefficients)  # importable by name: it pickles
    law_name = f"{type(base).__name__}Lift"
    law_class = type(law_name, (LiftLaw,), {
        "name": name, "coefficients": coefficients, "base": base, "candidate": declared_candidate(base),
        "default_bounds": (*base.default_bounds, LIFT_BOUNDS),
        "kernel_rows": (*base.kernel_rows, "klift"),
        "__module__": __name__,
        "__qualname__": law_name,
    })
    setattr(sys.modules[__name__], law_name, law_class)
    return law_class()
