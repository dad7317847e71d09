"""Fluid laws of test plants only: water the estimator has no candidate for (docs/estimation.md).

A test plant is a test of the estimator only if its physics is not one of the models the
estimator chooses among; these laws are registered for the virtual tank (``candidate = False``:
:func:`eelsim.fluid.candidate_laws` leaves them out, so no comparison fits them) and live here,
with the plants, not in the twin's own laws.

The ``foil`` law: each link a slender foil in the flow w = (w_t, w_n) relative to the water
(tangential and normal components), |w| its speed, alpha its angle of attack (sin alpha =
w_n / |w|, cos alpha = w_t / |w|). With q = rho / 2, the wetted area S_t = pi (a + b) l (the
paper's tangential area) and the lateral area S_n = 2 a 2 l:

- drag along -w with an angle-of-attack-dependent coefficient,
  D = q |w|^2 (S_t C_D0 + S_n C_D2 sin^2 alpha);
- lift across w (a flat plate's, peaking at 45 degrees), L = q |w|^2 S_n C_L sin alpha cos alpha,
  directed against the normal flow (it turns with the sign of alpha);

which in the link's frame, with k_0 = q S_t C_D0, k_2 = q S_n C_D2, k_L = q S_n C_L, is

    f_t = -(k_0 |w| + (k_2 - k_L) w_n^2 / |w|) w_t
    f_n = -(k_0 |w| + (k_2 w_n^2 + k_L w_t^2) / |w|) w_n

The lift does no work (f . w = -(k_0 |w| + k_2 w_n^2 / |w|) |w|^2 <= 0); at a small angle of
attack the normal force is k_L |w_t| w_n, linear in w_n with a slope that grows with the
swimming speed, where the Morison law's is c_n (w_n + |w_n| w_n) whatever the speed; the
tangential drag depends on the normal flow. Yaw damping: the cross-flow drag integrated along the
link turning about its centre, tau = -lambda_q |theta_dot| theta_dot, lambda_q = rho a C_D2 l^4 / 2.
Added mass mu_n and added inertia lambda_1 from C_a and C_m as the paper's, with the reactive
terms of the relative motion (:mod:`eelsim.fluid.relative`). With C_a = C_m = 0 the links carry no
water along: no added-mass inertia (the candidate laws' C_a reaches 0 since issue 32; it
stopped at 0.05 before).

Typical values (:data:`FOIL_DRAG`): C_D0 = 0.008 (table 3's C_f), C_D2 = 1.0 (a circular
cylinder's cross-flow drag), C_L = 1.0 (a flat plate's sin alpha cos alpha form with 2 pi alpha
at small alpha on the lateral area would give 2 pi; a slender body's is far smaller).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Annotated, ClassVar, TypeVar

import numpy as np
from numpy.typing import ArrayLike
from pydantic import Field

from eelsim.fluid import register_fluid_law
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

SPEED_FLOOR_M_S = 1e-9
"""|w| below which the direction of the flow is taken as undefined (the forces are then 0)."""

FOIL_DRAG = {"C_D0": 0.008, "C_D2": 1.0, "C_L": 1.0}
"""The foil plants' drag and lift (module docstring)."""


class FoilCoefficients(FluidCoefficients):
    """Coefficients of the foil law, dimensionless (module docstring).

    Attributes
    ----------
    C_D0 : float
        Drag at zero angle of attack, on the wetted area.
    C_D2 : float
        Angle-of-attack drag, times sin^2 alpha, on the lateral area.
    C_L : float
        Lift, times sin alpha cos alpha, on the lateral area.
    C_a, C_m : float
        Added mass and added yaw inertia, as the paper's.
    """

    law_name: ClassVar[str] = "foil"

    C_D0: _NonNegative
    C_D2: _NonNegative
    C_L: _NonNegative
    C_a: _NonNegative
    C_m: _NonNegative


@dataclass(frozen=True)
class FoilLinkFluid(LinkFluid):
    """Per-link coefficients of the foil law (arrays of shape (..., N)).

    Attributes
    ----------
    k_0, k_2, k_lift : ndarray
        q S_t C_D0, q S_n C_D2 and q S_n C_L, kg/m.
    lambda_q : ndarray
        Yaw damping, kg m^2.
    """

    k_0: FloatArray
    k_2: FloatArray
    k_lift: FloatArray
    lambda_q: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The rows ``fk0``, ``fk2``, ``fkl``, ``flamq``."""
        return {"fk0": self.k_0, "fk2": self.k_2, "fkl": self.k_lift, "flamq": self.lambda_q}


_Fluid = TypeVar("_Fluid", bound=LinkFluid)


def _own_fluid(fluid: LinkFluid, kind: type[_Fluid], law: str) -> _Fluid:
    """``fluid`` as the link coefficients of the law ``law`` (of type ``kind``).

    Raises
    ------
    TypeError
        When another law's coefficients are handed to this law.
    """
    if not isinstance(fluid, kind):
        raise TypeError(f"the {law} law needs its own link coefficients, got "
                        f"{type(fluid).__name__}")
    return fluid


def _foil_fields(foil: LinkFluid) -> dict[str, FloatArray]:
    """The foil law's link coefficients by field name, for a law built on them."""
    own = _own_fluid(foil, FoilLinkFluid, "foil")
    return {f.name: getattr(own, f.name) for f in fields(FoilLinkFluid)}


def _foil_forces(f: FoilLinkFluid, k_lift: FloatArray, vt: FloatArray, vn: FloatArray,
                 omega: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The foil water's drag, lift and yaw damping with the lift's coefficient ``k_lift``.

    The foil law passes its own; the stall law its own below the stall angle and the stalled
    plate's above it (module docstring), so both laws are one formula.
    """
    speed = np.sqrt(vt * vt + vn * vn)
    inv = 1.0 / np.maximum(speed, SPEED_FLOOR_M_S)
    return (-(f.k_0 * speed + (f.k_2 - k_lift) * vn * vn * inv) * vt,
            -(f.k_0 * speed + (f.k_2 * vn * vn + k_lift * vt * vt) * inv) * vn,
            -f.lambda_q * np.abs(omega) * omega)


class FoilLaw(RelativeMotionLaw):
    """Lift and angle-of-attack-dependent drag on each link, for test plants (module docstring)."""

    name: ClassVar[str] = "foil"
    coefficients: ClassVar[type[FluidCoefficients]] = FoilCoefficients
    candidate: ClassVar[bool] = False
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = (
        (0.0, 0.1), (0.0, 3.0), (0.0, 3.0), (0.0, 3.0), (0.0, 1.0))
    kernel_rows: ClassVar[tuple[str, ...]] = ("fk0", "fk2", "fkl", "flamq")

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> FoilLinkFluid:
        """See the module docstring."""
        l_ = np.asarray(half_length_m, dtype=float)
        a = np.asarray(half_axis_vertical_m, dtype=float)
        b = np.asarray(half_axis_horizontal_m, dtype=float)
        rho = np.asarray(water_density_kg_m3, dtype=float)
        c_d0, c_d2, c_l, c_a, c_m = law_coefficient_columns(coefficients, 5)
        # the added mass and inertia are the paper's (its drag terms are not used)
        paper = MORISON.link_coefficients(l_, a, b, np.stack([c_d0, c_d2, c_a, c_m], axis=-1),
                                          rho)
        lateral = 0.5 * rho * (2.0 * a) * (2.0 * l_)
        return FoilLinkFluid(
            mu_n=paper.mu_n,
            lambda_1=paper.lambda_1,
            k_0=0.5 * rho * np.pi * (a + b) * l_ * c_d0,
            k_2=lateral * c_d2,
            k_lift=lateral * c_l,
            lambda_q=rho * a * c_d2 * l_**4 / 2.0,
        )

    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Drag, lift and yaw damping (module docstring)."""
        foil = _own_fluid(fluid, FoilLinkFluid, self.name)
        return _foil_forces(foil, foil.k_lift, vt, vn, omega)

    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The same, negated, for the batched kernel."""
        w, line = code.w, code.line
        line("fl_sp = _vsqrt(fl_vt * fl_vt + fl_vn * fl_vn)")
        line(f"fl_inv = 1.0 / max(fl_sp, {SPEED_FLOOR_M_S!r})")
        k0, k2, kl = w("fk0", link), w("fk2", link), w("fkl", link)
        return (f"({k0} * fl_sp + ({k2} - {kl}) * fl_vn * fl_vn * fl_inv) * fl_vt",
                f"({k0} * fl_sp + ({k2} * fl_vn * fl_vn + {kl} * fl_vt * fl_vt) * fl_inv) * fl_vn",
                f"{w('flamq', link)} * abs(om) * om")


FOIL = register_fluid_law(FoilLaw(), "a slender foil's drag and lift (test plants only)")
"""The foil law (a plant law: never a candidate)."""


# The ``stall`` law (docs/estimation.md, "Test plants"): the foil water whose lift stalls. Below
# the stall angle alpha_s it is the foil law, force for force; above it the link is a stalled
# flat plate, whose force is normal to the plate (Hoerner & Borst 1985, ch. 4; Sheldahl & Klimas
# 1981's post-stall data): its lift is then q |w|^2 S_n C_D2 sin alpha cos alpha, the normal drag's
# own, and
#
#     f_t = -k_0 |w| w_t
#     f_n = -(k_0 |w| + k_2 |w|) w_n
#
# The angle is the acute one between the flow and the link's axis, sin alpha = |w_n| / |w|, so
# the link stalls alike heading or tailing into the flow (a slender link is fore-aft symmetric).
# Where C_L > C_D2 the lift drops at the stall angle, as an aerofoil's does.

STALL_WATER = {**FOIL_DRAG, "C_L": float(2.0 * np.pi), "alpha_stall": float(np.radians(16.0))}
"""The stall plant's drag, lift and stall angle (rad): thin-aerofoil lift (2 pi alpha at a small
angle) up to 16 degrees, about a NACA 0012's stall angle, then the stalled plate's C_D2 = 1.0
(docs/estimation.md, "Plant-only water: the stall law")."""


class StallCoefficients(FluidCoefficients):
    """Coefficients of the stall law: the foil law's and the stall angle (dimensionless).

    Attributes
    ----------
    C_D0, C_D2, C_L, C_a, C_m : float
        As the foil law's (:class:`FoilCoefficients`).
    alpha_stall : float
        The stall angle of attack, rad: beyond it the lift is the flat plate's, C_D2 sin alpha
        cos alpha.
    """

    law_name: ClassVar[str] = "stall"

    C_D0: _NonNegative
    C_D2: _NonNegative
    C_L: _NonNegative
    C_a: _NonNegative
    C_m: _NonNegative
    alpha_stall: Annotated[float, Field(ge=0.0, le=float(np.pi / 2), allow_inf_nan=False)]


@dataclass(frozen=True)
class StallLinkFluid(FoilLinkFluid):
    """Per-link coefficients of the stall law: the foil law's and sin alpha_s (shape (..., N))."""

    sin_stall: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The foil law's rows and ``fssin``."""
        return {**super().kernel_values(), "fssin": self.sin_stall}


class StallLaw(RelativeMotionLaw):
    """The foil law whose lift stalls beyond an angle of attack, for test plants (see above)."""

    name: ClassVar[str] = "stall"
    coefficients: ClassVar[type[FluidCoefficients]] = StallCoefficients
    candidate: ClassVar[bool] = False
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = (
        *FoilLaw.default_bounds, (0.0, float(np.pi / 2)))
    kernel_rows: ClassVar[tuple[str, ...]] = (*FoilLaw.kernel_rows, "fssin")

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> StallLinkFluid:
        """The foil law's coefficients (the first five) and the sine of the stall angle."""
        columns = law_coefficient_columns(coefficients, 6)
        foil = _foil_fields(FOIL.link_coefficients(
            half_length_m, half_axis_vertical_m, half_axis_horizontal_m,
            np.stack(columns[:5], axis=-1), water_density_kg_m3))
        return StallLinkFluid(**foil, sin_stall=np.sin(columns[5]) + np.zeros_like(foil["k_0"]))

    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Drag, lift (the foil's below the stall angle, the flat plate's above) and yaw damping."""
        stall = _own_fluid(fluid, StallLinkFluid, self.name)
        speed = np.sqrt(vt * vt + vn * vn)
        # attached flow up to the stall angle; then the stalled plate's lift, C_L -> C_D2
        k_lift = np.where(np.abs(vn) <= stall.sin_stall * speed, stall.k_lift, stall.k_2)
        return _foil_forces(stall, k_lift, vt, vn, omega)

    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The same, negated, for the batched kernel."""
        w, line = code.w, code.line
        line("fl_sp = _vsqrt(fl_vt * fl_vt + fl_vn * fl_vn)")
        line(f"fl_inv = 1.0 / max(fl_sp, {SPEED_FLOOR_M_S!r})")
        k0, k2 = w("fk0", link), w("fk2", link)
        line(f"fl_kl = {w('fkl', link)} if abs(fl_vn) <= {w('fssin', link)} * fl_sp else {k2}")
        return (f"({k0} * fl_sp + ({k2} - fl_kl) * fl_vn * fl_vn * fl_inv) * fl_vt",
                f"({k0} * fl_sp + ({k2} * fl_vn * fl_vn + fl_kl * fl_vt * fl_vt) * fl_inv) * fl_vn",
                f"{w('flamq', link)} * abs(om) * om")


STALL = register_fluid_law(StallLaw(), "the foil water whose lift stalls (test plants only)")
"""The stall law (a plant law: never a candidate)."""


# The ``quarter_chord`` law (docs/estimation.md, "Plant-only water: the quarter_chord law"): the
# foil water whose lift is the quasi-steady thin aerofoil's. A pitching aerofoil's circulation is
# set by the flow at its three-quarter-chord point and its lift acts at the quarter-chord point
# (Pistolesi's theorem; T. Theodorsen, NACA Report 496, 1935, with C(k) = 1; Y. C. Fung, *An
# Introduction to the Theory of Aeroelasticity*, 1955, ch. 6). On a link of chord 2l moving
# with w_t (sign s = +1 head-first along t, -1 tail-first), the quarter-chord point lies
# d = s l / 2 ahead of the centre and the three-quarter-chord point d behind it, where the normal
# flow is w_n3 = w_n - d theta_dot. The foil law's lift taken in the flow w3 = (w_t, w_n3),
# perpendicular to it, and applied at the quarter chord, with k_L = q S_n C_L:
#
#     f_t^L = k_L w_n3^2 w_t / |w3|,   f_n^L = -k_L w_t^2 w_n3 / |w3|,   tau^L = d f_n^L
#
# besides the foil law's drag along -w and yaw damping. Its power is s l theta_dot f_n^L: zero
# on a link that does not turn (the lift is then across w, as the foil law's); a pitching foil
# exchanges energy with its wake (flutter, thrust of a pitching plate). At a small angle the
# pitch-rate part of the normal force is k_L |w_t| (l / 2) theta_dot, the rotational lift
# C_rot rho U c^2 theta_dot of S. P. Sane and M. H. Dickinson (J. Exp. Biol. 205, 2002,
# 1087-1096) with C_rot = C_L / 8 (pi / 4, theirs for a mid-chord axis, at the thin aerofoil's
# C_L = 2 pi). The one-panel lattice (bound vortex at the quarter chord, the flow taken at the
# three-quarter chord) is J. Weissinger's for finite wings (NACA TM 1120, 1947), so the slope
# C_L may be a finite wing's (the plant's: QUARTER_CHORD_WATER).

QUARTER_CHORD_WATER = {**FOIL_DRAG, "C_L": 0.73}
"""The pitching foil plant's drag and lift: the foil's drag; the lift slope of a wing of the
bundled links' aspect ratio A = 2a / 2l = 0.47, Helmbold's 2 pi A / (2 + sqrt(A^2 + 4)) = 0.73
per radian (docs/estimation.md, "Plant-only water: the quarter_chord law")."""


class QuarterChordCoefficients(FoilCoefficients):
    """Coefficients of the quarter_chord law: the foil law's (:class:`FoilCoefficients`)."""

    law_name: ClassVar[str] = "quarter_chord"


@dataclass(frozen=True)
class QuarterChordLinkFluid(FoilLinkFluid):
    """Per-link coefficients of the quarter_chord law: the foil law's and the half-length l, m.

    The batched form reads l from the kernel's own ``half_length`` row.
    """

    half_length: FloatArray


def _leading_sign(vt: FloatArray) -> FloatArray:
    """+1 where the link moves head-first along t (w_t >= 0), -1 tail-first.

    At w_t = 0 the choice does not matter: the lift and its moment carry w_t.
    """
    return np.where(vt >= 0.0, 1.0, -1.0)


class QuarterChordLaw(RelativeMotionLaw):
    """The foil water with the thin aerofoil's pitching lift at the quarter chord (see above)."""

    name: ClassVar[str] = "quarter_chord"
    coefficients: ClassVar[type[FluidCoefficients]] = QuarterChordCoefficients
    candidate: ClassVar[bool] = False
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = FoilLaw.default_bounds
    kernel_rows: ClassVar[tuple[str, ...]] = FoilLaw.kernel_rows

    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> QuarterChordLinkFluid:
        """The foil law's coefficients and the links' half-lengths."""
        foil = _foil_fields(FOIL.link_coefficients(
            half_length_m, half_axis_vertical_m, half_axis_horizontal_m, coefficients,
            water_density_kg_m3))
        return QuarterChordLinkFluid(
            **foil, half_length=np.asarray(half_length_m, dtype=float) + np.zeros_like(foil["k_0"]))

    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Drag, yaw damping and the three-quarter-chord flow's lift at the quarter chord."""
        f = _own_fluid(fluid, QuarterChordLinkFluid, self.name)
        speed = np.sqrt(vt * vt + vn * vn)
        drag = f.k_0 * speed + f.k_2 * vn * vn / np.maximum(speed, SPEED_FLOOR_M_S)
        ahead = 0.5 * f.half_length * _leading_sign(vt)  # the quarter chord, from the centre
        vn3 = vn - ahead * omega  # the normal flow at the three-quarter chord
        inv3 = 1.0 / np.maximum(np.sqrt(vt * vt + vn3 * vn3), SPEED_FLOOR_M_S)
        lift_n = -f.k_lift * vt * vt * vn3 * inv3
        return (-drag * vt + f.k_lift * vn3 * vn3 * vt * inv3,
                -drag * vn + lift_n,
                -f.lambda_q * np.abs(omega) * omega + ahead * lift_n)

    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The same, negated, for the batched kernel."""
        w, line = code.w, code.line
        floor = repr(SPEED_FLOOR_M_S)
        k0, k2, kl = w("fk0", link), w("fk2", link), w("fkl", link)
        line("fl_sp = _vsqrt(fl_vt * fl_vt + fl_vn * fl_vn)")
        line(f"fl_dr = {k0} * fl_sp + {k2} * fl_vn * fl_vn / max(fl_sp, {floor})")
        line(f"fl_d = 0.5 * {w('half_length', link)} * (1.0 if fl_vt >= 0.0 else -1.0)")
        line("fl_w3 = fl_vn - fl_d * om")
        line(f"fl_i3 = 1.0 / max(_vsqrt(fl_vt * fl_vt + fl_w3 * fl_w3), {floor})")
        line(f"fl_ln = {kl} * fl_vt * fl_vt * fl_w3 * fl_i3")
        return (f"fl_dr * fl_vt - {kl} * fl_w3 * fl_w3 * fl_vt * fl_i3",
                "fl_dr * fl_vn + fl_ln",
                f"{w('flamq', link)} * abs(om) * om + fl_d * fl_ln")


QUARTER_CHORD = register_fluid_law(
    QuarterChordLaw(), "the foil water with a pitching thin aerofoil's lift at the quarter chord "
    "(test plants only)")
"""The quarter_chord law (a plant law: never a candidate)."""
