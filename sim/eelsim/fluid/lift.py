"""A foil's lift, stall and drag rise on each link that any fluid law can carry: ``<law>_lift``.

docs/model.md section 2, "Lift", has the equations and their sources. A link moving through the
water with velocity w = w_t t + w_n n relative to it, at the angle of attack alpha (tan alpha =
w_n / w_t), feels besides its law's forces the quasi-steady forces of a flat plate (a blade
element): a lift perpendicular to w and a drag rise along -w,

    L = 1/2 rho S C_L sin(2 alpha) |w|^2 = rho S C_L w_t w_n,            S = 2a 2l (its side area)
    D = 1/2 rho S C_D_alpha sin^2(alpha) |w|^2
    f_lift = k_L w_t w_n (w_n t - w_t n) / |w|,                          k_L = rho S C_L
    f_rise = -k_D w_n^2 (w_t t + w_n n) / |w|,                           k_D = 1/2 rho S C_D_alpha
    tau_rise = -lambda_D |theta_dot| theta_dot,                          lambda_D = k_D l^3 / 4

(the flat plate's sin 2 alpha lift and its sin^2 alpha drag rise, measured together: Dickinson,
Lehmann and Sane, Science 284 (1999) 1954-1960; Wang, Birch and Dickinson, J. Exp. Biol. 207
(2004) 449-460: C_L = 1.2 sin 2 alpha, C_D = 1.4 - cos 2 alpha = 0.4 + 2 sin^2 alpha). The lift's
normal part opposes w_n, as a plate's pressure does; it acts at the link's centre and is
perpendicular to w, so it does no work. The drag rise is the same drag a link's own law may
already hold at alpha = 0 grown with the angle; at alpha = 90 degrees (pure cross-flow) it is a
cross-flow drag of coefficient C_D_alpha, and its moment on a link turning about its centre is
that cross-flow drag integrated along the link (lambda_D = rho a C_D_alpha l^4 / 2); it only
dissipates.

**Stall.** Past its stall angle alpha_s a section's flow separates and its lift falls to a flat
plate's, whose force is normal to it (Hoerner and Borst, *Fluid-Dynamic Lift*, 1985, ch. 4;
Sheldahl and Klimas, SAND80-2114, 1981, the post-stall data of symmetric sections through
180 degrees; Viterna and Corrigan, 1982, extrapolate post-stall coefficients the same way): a
normal force of coefficient C_N gives lift C_N sin alpha cos alpha and drag C_N sin^2 alpha, so
with the drag rise as the plate's normal-force coefficient the stalled lift has k_L' = k_D. The
variant blends the two lift coefficients over the stall band (alpha_s, alpha_s + STALL_BAND_RAD)
by a smooth step of sin alpha (sin alpha = |w_n| / |w|, so a slender link stalls alike heading or
tailing into the flow; a blend of attached and flat-plate coefficients as in Beard and McLain,
*Small Unmanned Aircraft*, 2012, ch. 4):

    s = clamp((sin alpha - sin alpha_s) / (sin min(alpha_s + band, pi/2) - sin alpha_s), 0, 1)
    sigma = s^2 (3 - 2 s)
    k_L(alpha) = k_L + (k_D - k_L) sigma

alpha_s = pi/2 (its default and upper bound) is no stall: sigma = 0 at every angle.
``with_lift(law)`` makes the variant ``<law>_lift``: the law's coefficients then ``C_L``,
``C_D_alpha`` (default 0: lift alone) and ``alpha_stall`` (default pi/2: no stall), its forces
plus the terms in both forms. Every
law registered before the variants has one (:mod:`eelsim.fluid`); a variant is a fitting
candidate when its base law is one (docs/estimation.md, "Model comparison").
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
_Angle = Annotated[float, Field(ge=0.0, le=np.pi / 2, allow_inf_nan=False)]

LIFT_BOUNDS = (0.0, float(np.pi))
"""Search bounds of C_L: none to the thin aerofoil's slope (2 pi alpha = pi sin 2 alpha at small
angles; flat plate 1.2)."""

STALL_BOUNDS = (0.0, float(np.pi / 2))
"""Search bounds of alpha_stall, rad: stalled at every angle to never stalled."""

STALL_BAND_RAD = float(np.radians(4.0))
"""Width of the stall's blend: a section's lift falls over a few degrees past its maximum."""

DRAG_RISE_BOUNDS = (0.0, 3.0)
"""Search bounds of C_D_alpha: none to a flat plate's 3.1 (Dickinson et al.; Wang et al.: 2)."""


@dataclass(frozen=True)
class LiftLinkFluid(LinkFluid):
    """Per-link coefficients of a lift variant: its base law's and the lift's.

    Attributes
    ----------
    base : LinkFluid
        The base law's per-link coefficients (mu_n and lambda_1 are the base's).
    k_lift : ndarray
        k_L = rho 2a 2l C_L, kg/m, shape (..., N).
    k_rise : ndarray
        k_D = 1/2 rho 2a 2l C_D_alpha, kg/m.
    lambda_rise : ndarray
        lambda_D = k_D l^3 / 4, kg m^2.
    stall_low : ndarray
        sin alpha_s, where the stall's blend starts (1: never).
    stall_scale : ndarray
        1 / (sin min(alpha_s + band, pi/2) - sin alpha_s), 0 when there is no stall.
    """

    base: LinkFluid
    k_lift: FloatArray
    k_rise: FloatArray
    lambda_rise: FloatArray
    stall_low: FloatArray
    stall_scale: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The base law's rows, ``klift``, ``krise``, ``lrise``, ``slow`` and ``sscale``."""
        return {**self.base.kernel_values(), "klift": self.k_lift, "krise": self.k_rise,
                "lrise": self.lambda_rise, "slow": self.stall_low, "sscale": self.stall_scale}


def stall_blend(alpha_stall_rad: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Where the stall's blend starts in sin alpha and its scale (module docstring).

    Parameters
    ----------
    alpha_stall_rad : array_like
        alpha_s, 0 to pi/2.

    Returns
    -------
    (low, scale) : ndarrays
        sin alpha_s and 1 / (sin min(alpha_s + band, pi/2) - sin alpha_s); a band too narrow to
        resolve (alpha_s at pi/2) gives scale 0: no stall.
    """
    a = np.asarray(alpha_stall_rad, dtype=float)
    low = np.sin(a)
    width = np.sin(np.minimum(a + STALL_BAND_RAD, np.pi / 2)) - low
    scale = np.divide(1.0, width, out=np.zeros_like(width), where=width > 1e-9)
    return low, scale


def stalled_share(sin_alpha: FloatArray, low: FloatArray, scale: FloatArray) -> FloatArray:
    """sigma: 0 attached, 1 stalled, a smooth step between (module docstring)."""
    s = np.clip((sin_alpha - low) * scale, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def lift_force(k_lift: FloatArray, vt: FloatArray, vn: FloatArray,
               stall: tuple[FloatArray, FloatArray, FloatArray] | None = None,
               ) -> tuple[FloatArray, FloatArray]:
    """The lift along t and n on each link (module docstring).

    Parameters
    ----------
    k_lift : ndarray
        k_L per link, kg/m.
    vt, vn : ndarray
        Tangential and normal velocity of the centre relative to the water, m/s.
    stall : (k_rise, low, scale), optional
        The stalled plate's lift coefficient k_D and the blend (:func:`stall_blend`); none: the
        lift never stalls.

    Returns
    -------
    (f_t, f_n) : ndarrays
        N; zero where the link is at rest in the water.
    """
    speed = np.sqrt(vt * vt + vn * vn)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = np.where(speed > 0.0, 1.0 / speed, 0.0)
    k = k_lift
    if stall is not None:
        k_rise, low, scale = stall
        k = k_lift + (k_rise - k_lift) * stalled_share(np.abs(vn) * inverse, low, scale)
    q = k * vt * vn * inverse
    return q * vn, -q * vt


def drag_rise_force(k_rise: FloatArray, vt: FloatArray,
                    vn: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The angle-of-attack drag along t and n on each link (module docstring).

    Parameters
    ----------
    k_rise : ndarray
        k_D per link, kg/m.
    vt, vn : ndarray
        Tangential and normal velocity of the centre relative to the water, m/s.

    Returns
    -------
    (f_t, f_n) : ndarrays
        N, along -w; zero where the link is at rest in the water.
    """
    speed = np.sqrt(vt * vt + vn * vn)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(speed > 0.0, k_rise * vn * vn / speed, 0.0)
    return -q * vt, -q * vn


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
        """The base law's values from all but the last three; then C_L, C_D_alpha, alpha_stall."""
        c = np.asarray(coefficients, dtype=float)
        k = len(self.coefficient_names)
        if c.shape[-1:] != (k,):
            raise ValueError(f"expected {k} coefficients on the last axis, got shape {c.shape}")
        base = self.base.link_coefficients(half_length_m, half_axis_vertical_m,
                                           half_axis_horizontal_m, c[..., :-3],
                                           water_density_kg_m3)
        l_ = np.asarray(half_length_m, dtype=float)
        a = np.asarray(half_axis_vertical_m, dtype=float)
        rho = np.asarray(water_density_kg_m3, dtype=float)
        side = rho * (2.0 * a) * (2.0 * l_)
        k_lift = side * c[..., -3]
        k_rise = 0.5 * side * c[..., -2]
        low, scale = stall_blend(c[..., -1])
        shape = base.mu_n.shape
        zero = np.zeros_like(side)  # the stall's values broadcast as the lift's do
        return LiftLinkFluid(mu_n=base.mu_n, lambda_1=base.lambda_1, base=base,
                             k_lift=np.broadcast_to(k_lift, shape).copy(),
                             k_rise=np.broadcast_to(k_rise, shape).copy(),
                             lambda_rise=np.broadcast_to(k_rise * l_**3 / 4.0, shape).copy(),
                             stall_low=np.broadcast_to(low + zero, shape).copy(),
                             stall_scale=np.broadcast_to(scale + zero, shape).copy())

    def forces(self, fluid: LinkFluid, motion: LinkMotion, current_m_s: FloatArray) -> LinkForces:
        """The base law's forces plus the lift (part ``"lift"``) and the drag rise (``"rise"``)."""
        if not isinstance(fluid, LiftLinkFluid):
            raise TypeError(f"the {self.name} law needs its own link coefficients, got "
                            f"{type(fluid).__name__}")
        body = self.base.forces(fluid.base, motion, current_m_s)
        s, c = motion.sin, motion.cos
        vt = c * motion.rel_vx + s * motion.rel_vy
        vn = -s * motion.rel_vx + c * motion.rel_vy
        ft, fn = lift_force(fluid.k_lift, vt, vn,
                            (fluid.k_rise, fluid.stall_low, fluid.stall_scale))
        lift = (ft * c - fn * s, ft * s + fn * c)
        dt, dn = drag_rise_force(fluid.k_rise, vt, vn)
        rise = (dt * c - dn * s, dt * s + dn * c)
        om = motion.omega
        return LinkForces(fx=body.fx + lift[0] + rise[0], fy=body.fy + lift[1] + rise[1],
                          torque=body.torque - fluid.lambda_rise * np.abs(om) * om,
                          parts={**body.parts, "lift": lift, "rise": rise})

    def emit_link_forces(self, code: KernelCode, link: int, still_water: bool) -> None:
        """The base law's code, then the lift and drag rise added to its (negated) outputs."""
        self.base.emit_link_forces(code, link, still_water)
        line, w = code.line, code.w
        line("fl_lift_vt = c * lvx + s * lvy")
        line("fl_lift_vn = c * lvy - s * lvx")
        line("fl_lift_speed = _vsqrt(fl_lift_vt * fl_lift_vt + fl_lift_vn * fl_lift_vn)")
        line("fl_lift_inv = (1.0 / fl_lift_speed) if fl_lift_speed > 0.0 else 0.0")
        # the stall: the lift coefficient blends to the plate's k_D past alpha_s (a smooth step)
        line(f"fl_stall = min(max((abs(fl_lift_vn) * fl_lift_inv - {w('slow', link)})"
             f" * {w('sscale', link)}, 0.0), 1.0)")
        line("fl_stall = fl_stall * fl_stall * (3.0 - 2.0 * fl_stall)")
        line(f"fl_lift_k = {w('klift', link)} + ({w('krise', link)} - {w('klift', link)})"
             " * fl_stall")
        line("fl_lift_q = fl_lift_k * fl_lift_vt * fl_lift_vn * fl_lift_inv")
        line(f"fl_rise_q = {w('krise', link)} * fl_lift_vn * fl_lift_vn * fl_lift_inv")
        # the water's force on the link along t and n: lift (q_L w_n, -q_L w_t), rise -q_D w
        line("fl_lift_t = fl_lift_q * fl_lift_vn - fl_rise_q * fl_lift_vt")
        line("fl_lift_n = -fl_lift_q * fl_lift_vt - fl_rise_q * fl_lift_vn")
        line("fnn = fnn - fl_lift_n")
        line("fxn = fxn - fl_lift_t * c + fl_lift_n * s")
        line("fyn = fyn - fl_lift_t * s - fl_lift_n * c")
        line(f"tqn = tqn + {w('lrise', link)} * abs(om) * om")


def _free_name(preferred: str, law: str) -> str:
    """A module-level name for a lift variant's class that no other law's class holds.

    The classes are set on this module so that they pickle by name (the comparison's worker
    processes); a user's law derived from a bundled one shares its coefficients class, and
    its variant under the same name would replace the bundled variant's class, which then no
    longer pickles. Such a variant gets its law's name appended instead.
    """
    taken = getattr(sys.modules[__name__], preferred, None)
    if taken is None or getattr(taken, "law_name", getattr(taken, "name", None)) == f"{law}_lift":
        return preferred
    return f"{preferred}_{law}"


def with_lift(base: FluidLaw) -> LiftLaw:
    """The variant ``<base>_lift`` of ``base``: its coefficients, ``C_L``, ``C_D_alpha``, ``alpha_stall``.

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
    record = _free_name(f"{base.coefficients.__name__}Lift", base.name)
    namespace: dict[str, Any] = {
        "__annotations__": {"law_name": ClassVar[str], "C_L": _NonNegative,
                            "C_D_alpha": _NonNegative, "alpha_stall": _Angle},
        "law_name": name,
        "C_D_alpha": 0.0,  # lift alone unless given (records written before the drag rise)
        "alpha_stall": float(np.pi / 2),  # never stalls unless given (records before the stall)
        "__module__": __name__,
        "__qualname__": record,
        "__doc__": f"The coefficients of the ``{base.name}`` law, the lift's C_L, the drag "
                   "rise's C_D_alpha and the stall angle alpha_stall (rad).",
    }
    coefficients = type(record, (base.coefficients,), namespace)
    setattr(sys.modules[__name__], record, coefficients)  # importable by name: it pickles
    law_name = _free_name(f"{type(base).__name__}Lift", base.name)
    law_class = type(law_name, (LiftLaw,), {
        "name": name, "coefficients": coefficients, "base": base, "candidate": declared_candidate(base),
        "default_bounds": (*base.default_bounds, LIFT_BOUNDS, DRAG_RISE_BOUNDS, STALL_BOUNDS),
        "kernel_rows": (*base.kernel_rows, "klift", "krise", "lrise", "slow", "sscale"),
        "__module__": __name__,
        "__qualname__": law_name,
    })
    setattr(sys.modules[__name__], law_name, law_class)
    return law_class()
